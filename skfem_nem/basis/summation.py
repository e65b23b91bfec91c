"""Summing element matrices over natural-neighbour stencils into one global matrix.

Element e of a natural-neighbour basis couples all the functions of its stencil, so its
matrix is a dense (Dv S_e) x (Du S_e) block. Two users make such blocks: the whole-mesh
road of the assembly (:mod:`skfem_nem.basis.assembly`), and the static condensation of
the Stokes bubbles (:mod:`skfem_nem.models.condensation`), which corrects each block before
it is summed. Both sum here, row by row over the nodes, into the pattern of the stencils
(the union of the stencils of the elements around a node), which is kept with the basis.
With the dofs numbered ``D node + c`` (scikit-fem's vector numbering) the entries come out
in canonical CSR order, so :func:`sum_csr` builds the matrix with no sort or conversion, and
each entry sums its elements in ascending order: exactly symmetric element matrices give
an exactly symmetric sum.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..jit import serial_twin

__all__ = ["node_pattern", "sum_coo", "sum_csr"]


@njit(cache=True)
def _incidence(ptr, sten, n):
    """Node -> (element, local index) lists of the stencils: node v is
    function ``inc_l[k]`` of element ``inc_e[k]`` for k in
    ``inc_ptr[v]:inc_ptr[v + 1]``."""
    ne = ptr.shape[0] - 1
    inc_ptr = np.zeros(n + 1, np.int64)
    for k in range(ptr[ne]):
        inc_ptr[sten[k] + 1] += 1
    for v in range(n):
        inc_ptr[v + 1] += inc_ptr[v]
    fill = inc_ptr[:-1].copy()
    inc_e = np.empty(ptr[ne], np.int64)
    inc_l = np.empty(ptr[ne], np.int64)
    for e in range(ne):
        for s in range(ptr[e], ptr[e + 1]):
            v = sten[s]
            inc_e[fill[v]] = e
            inc_l[fill[v]] = s - ptr[e]
            fill[v] += 1
    return inc_ptr, inc_e, inc_l


_GAPS = (701, 301, 132, 57, 23, 10, 4, 1)  # Ciura's gaps, for the Shell sort below


@njit(cache=True)
def _sort_run(a, lo, hi):
    """Sort a[lo:hi] in place (Shell sort: rows of tens to hundreds of nodes; numba's
    quicksort would add a second or two to the first run's compilation)."""
    for g in _GAPS:
        for i in range(lo + g, hi):
            x = a[i]
            j = i
            while j - g >= lo and a[j - g] > x:
                a[j] = a[j - g]
                j -= g
            a[j] = x


@njit(cache=True, parallel=True)
def _node_pattern(ptr, sten, inc_ptr, inc_e, n, nblocks):
    """Sparsity pattern between nodes: node v couples with the (sorted)
    nodes ``cols[cptr[v]:cptr[v + 1]]``, the union of the stencils of the
    elements whose stencil holds v."""
    cnt = np.zeros(n, np.int64)
    for blk in prange(nblocks):
        mark = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            c = 0
            for k in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[k]
                for s in range(ptr[e], ptr[e + 1]):
                    if mark[sten[s]] != v:
                        mark[sten[s]] = v
                        c += 1
            cnt[v] = c
    cptr = np.zeros(n + 1, np.int64)
    for v in range(n):
        cptr[v + 1] = cptr[v] + cnt[v]
    cols = np.empty(cptr[n], np.int64)
    for blk in prange(nblocks):
        mark = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            c = cptr[v]
            for k in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[k]
                for s in range(ptr[e], ptr[e + 1]):
                    if mark[sten[s]] != v:
                        mark[sten[s]] = v
                        cols[c] = sten[s]
                        c += 1
            _sort_run(cols, cptr[v], cptr[v + 1])
    return cptr, cols


@njit(cache=True, parallel=True)
def _sum_rows(ptr, sten, off, K, inc_ptr, inc_e, inc_l, cptr, cols, Du, Dv, ndu, ndv,
              nblocks, rows_out, cols_out, data_out):
    """Sum the local matrices ``K`` into the global matrix, row by row:
    node v's rows (components cv) hold the entries with the nodes
    ``cols[cptr[v]:cptr[v + 1]]`` (components cu) at
    ``Dv Du cptr[v] + (cv n_v + k) Du + cu``; no two entries share a place,
    and with dofs numbered ``D node + c`` the entries come out row-major
    sorted (canonical CSR order)."""
    n = cptr.shape[0] - 1
    for blk in prange(nblocks):
        pos = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            nv = cptr[v + 1] - cptr[v]
            base = Dv * Du * cptr[v]
            for k in range(nv):
                pos[cols[cptr[v] + k]] = k
            for cv in range(Dv):
                for k in range(nv):
                    for cu in range(Du):
                        o = base + (cv * nv + k) * Du + cu
                        rows_out[o] = ndv[cv, v]
                        cols_out[o] = ndu[cu, cols[cptr[v] + k]]
                        data_out[o] = 0.0
            for t in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[t]
                j = inc_l[t]
                s0 = ptr[e]
                S = ptr[e + 1] - s0
                nc = Du * S
                for cv in range(Dv):
                    src = off[e] + (Dv * j + cv) * nc
                    dst = base + cv * nv * Du
                    for i in range(S):
                        k = pos[sten[s0 + i]]
                        for cu in range(Du):
                            data_out[dst + k * Du + cu] += K[src + Du * i + cu]


# Serial twins of the parallel kernels (small meshes: see assembly.PARALLEL_MIN)
_node_pattern_serial = serial_twin(_node_pattern)
_sum_rows_serial = serial_twin(_sum_rows)


def node_pattern(basis, parallel: bool = False) -> tuple:
    """The node incidence and node-node pattern of a basis' stencils, cached with the
    basis: ``(inc_ptr, inc_e, inc_l, cptr, cols)`` (see :func:`_incidence` and
    :func:`_node_pattern`)."""
    pat = basis.__dict__.get("_node_pattern")
    if pat is None:
        n = basis.mesh.p.shape[1]
        ptr, sten = basis.stencil_ptr, basis.stencil_nodes
        inc = _incidence(ptr, sten, n)
        kernel = _node_pattern if parallel else _node_pattern_serial
        pat = inc + kernel(ptr, sten, inc[0], inc[1], n, _blocks(n))
        basis.__dict__["_node_pattern"] = pat
    return pat


def _blocks(n):
    import numba
    return max(1, min(n // 256, 4 * numba.get_num_threads()))


def _index_dtype(n):
    return np.int32 if n < 2**31 - 1 else np.int64


def _summed(u, v, Du, Dv, off, K, parallel, idt):
    """Rows, columns and values of the summed element matrices, each entry once."""
    inc_ptr, inc_e, inc_l, cptr, cols = node_pattern(u, parallel)
    n = cptr.shape[0] - 1
    nnz = Du * Dv * int(cptr[-1])
    ind = np.empty((2, nnz), dtype=idt)
    data = np.empty(nnz)
    ndu = np.ascontiguousarray(u.dofs.nodal_dofs[:Du], dtype=np.int64)
    ndv = np.ascontiguousarray(v.dofs.nodal_dofs[:Dv], dtype=np.int64)
    kernel = _sum_rows if parallel else _sum_rows_serial
    kernel(u.stencil_ptr, u.stencil_nodes, off, K, inc_ptr, inc_e, inc_l, cptr, cols,
           Du, Dv, ndu, ndv, _blocks(n), ind[0], ind[1], data)
    return ind, data, cptr


def sum_coo(u, v, Du, Dv, off, K, parallel: bool = False):
    """COO arrays ``(rows and columns (2, nnz), values)`` of the element matrices ``K``
    (element e's, (Dv S) x (Du S) row-major, at ``K[off[e]:off[e + 1]]``) of the
    ``Du``-vector trial basis ``u`` and the ``Dv``-vector test basis ``v`` (sharing
    their stencils) summed: each entry once."""
    ind, data, _ = _summed(u, v, Du, Dv, off, K, parallel, _index_dtype(max(u.N, v.N)))
    return ind, data


def sum_csr(basis, D, off, K, parallel: bool = False) -> sp.csr_matrix:
    """The element matrices ``K`` (as in :func:`sum_coo`) of the ``D``-vector basis
    ``basis`` against itself summed into a CSR matrix (N, N), built in place where
    the dofs are numbered ``D node + c`` (else through COO)."""
    n = basis.mesh.p.shape[1]
    nodal = basis.dofs.nodal_dofs[:D]
    interleaved = basis.N == D * n and np.array_equal(
        nodal, D * np.arange(n)[None] + np.arange(D)[:, None])
    if not interleaved:
        ind, data = sum_coo(basis, basis, D, D, off, K, parallel)
        return sp.csr_matrix((data, (ind[0], ind[1])), shape=(basis.N, basis.N))
    nnz = D * D * int(node_pattern(basis, parallel)[3][-1])
    ind, data, cptr = _summed(basis, basis, D, D, off, K, parallel,
                              _index_dtype(max(nnz, basis.N)))
    nv = np.diff(cptr)
    indptr = np.empty(D * n + 1, dtype=ind.dtype)
    indptr[:-1] = (D * D * cptr[:-1, None] + D * nv[:, None] * np.arange(D)[None]).ravel()
    indptr[-1] = data.size
    return sp.csr_matrix((data, ind[1], indptr), shape=(basis.N, basis.N))

