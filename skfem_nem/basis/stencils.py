"""The stencils of natural-neighbour bases: numba kernels over the coordinate matrices.

A triangle's stencil is the union of the natural neighbours of its quadrature points (the
column indices of its rows of the sparse coordinate matrix); triangles of one stencil size
form a group whose values and gradients are copied into dense arrays
(:class:`~skfem_nem.basis.natural_neighbour.NaturalNeighbourBasis` builds the groups).
"""
import numpy as np
from numba import njit

from .assembly import stencil_position

__all__ = ["stencil_union", "fill_group"]


# ---------------------------------------------------------------------------
# stencils and groups
# ---------------------------------------------------------------------------

@njit(cache=True)
def stencil_union(indptr, indices, nq, ne):
    """Union of the column indices of rows e*nq .. e*nq+nq-1 of a CSR matrix.

    Returns (ptr, sten): element e's stencil is sten[ptr[e]:ptr[e+1]], sorted.
    """
    ptr = np.zeros(ne + 1, np.int64)
    sten = np.empty(indptr[ne * nq], np.int64)
    pos = 0
    for e in range(ne):
        start = pos
        for r in range(e * nq, e * nq + nq):
            for k in range(indptr[r], indptr[r + 1]):
                c = indices[k]
                # insert c into the sorted run sten[start:pos] if absent
                j = pos
                while j > start and sten[j - 1] > c:
                    j -= 1
                if j > start and sten[j - 1] == c:
                    continue
                for m in range(pos, j, -1):
                    sten[m] = sten[m - 1]
                sten[j] = c
                pos += 1
        ptr[e + 1] = pos
    return ptr, sten[:pos]


@njit(cache=True)
def fill_group(elems, ptr, sten, indptr, indices, data, grads, nq, V, G):
    """Dense values V (S, ne_g, nq) and gradients G (dim, S, ne_g, nq) of a group
    of equal-size stencils; ``grads`` is a tuple of dim arrays on the pattern
    of (indptr, indices)."""
    dim = len(grads)
    for k in range(elems.shape[0]):
        e = elems[k]
        s0 = ptr[e]
        S = ptr[e + 1] - s0
        for q in range(nq):
            r = e * nq + q
            for kk in range(indptr[r], indptr[r + 1]):
                lo = stencil_position(sten, s0, S, indices[kk])
                V[lo, k, q] = data[kk]
                for c in range(dim):
                    G[c, lo, k, q] = grads[c][kk]
