"""Gradients of natural-neighbour functions on the convex hull: one-sided limits.

On the hull the coordinates' gradients are undefined (the natural-neighbour cell of a
point on the hull is unbounded on one side), yet a facet basis integrates on boundary
facets, where forms such as a traction or a flux need them. The gradient there is the
limit from inside the domain: the coordinates' gradients at a point just inside along
the inward normal (1e-7 facet sizes in), on one sparsity pattern with the values. Kept
apart from the bases because it is a geometric fact about the coordinates at the hull,
not about a basis.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["INSIDE", "one_sided_gradients", "on_pattern"]

#: how far inside (in facet sizes) the one-sided limit is evaluated: far enough that the
#: point is strictly inside, near enough that the gradient is the limit's to round-off
INSIDE = 1e-7


def one_sided_gradients(coordinates, pts, Phi, D, normals, h, hint):
    """Values ``Phi`` and gradients ``D`` (CSR, one row per point of ``pts`` (m, dim))
    with the undefined gradient rows replaced by their limits from inside.

    ``coordinates(x, gradient=True, undefined="raise", hint=...)`` gives the coordinates
    at points x; ``normals`` (dim, nf, nq) the outward normals and ``h`` (nf, nq) the
    facet sizes at the points, ``hint`` (m,) an element holding each point. Returns
    ``(Phi, [D_k])`` on one sparsity pattern: the union of the neighbours of the point
    and of the point just inside."""
    dim = pts.shape[1]
    finite = np.ones(Phi.shape[0], dtype=bool)
    for Dk in D:
        finite &= np.isfinite(np.asarray(Dk.sum(axis=1)).ravel())
    bad = np.flatnonzero(~finite)
    nrm = normals.transpose(1, 2, 0).reshape(-1, dim)[bad]
    inner = pts[bad] - INSIDE * h.reshape(-1)[bad][:, None] * nrm
    _, D2 = coordinates(inner, gradient=True, undefined="raise", hint=hint[bad])
    keep = sp.diags(finite.astype(float))
    E = sp.csr_matrix((np.ones(bad.size), (bad, np.arange(bad.size))),
                      shape=(Phi.shape[0], bad.size))
    out = []
    for Dk, Dk2 in zip(D, D2):
        Dk = keep @ Dk
        Dk.data[~np.isfinite(Dk.data)] = 0.0
        out.append(Dk + E @ Dk2)
    pattern = (abs(Phi) + sum(abs(Dk) for Dk in out)).tocsr()
    pattern.data[:] = 1.0
    pattern.sort_indices()
    return on_pattern(Phi, pattern), [on_pattern(Dk, pattern) for Dk in out]


def on_pattern(A, pattern):
    """A's values on the (superset) sparsity pattern of ``pattern``, same index order."""
    A = A.tocsr()
    A.sort_indices()
    out = pattern.copy()
    out.data = np.zeros(out.nnz)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    # position of each entry of A inside the pattern (both sorted row-major)
    key_p = np.repeat(np.arange(out.shape[0]), np.diff(out.indptr)) * out.shape[1] + out.indices
    key_a = rows * A.shape[1] + A.indices
    pos = np.searchsorted(key_p, key_a)
    out.data[pos] = A.data
    return out
