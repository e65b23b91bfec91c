"""Gradients of scattered data estimated at the data points (for the C1 interpolants).

:func:`estimate_gradients` fits, at each data point x_i, the quadratic Taylor polynomial
``f_j - f_i = g . u_j + u_j^T H u_j / 2`` (``u_j = x_j - x_i``) to the values at its
neighbours by weighted least squares (weights ``1 / |u_j|^4``) and returns ``g``: exact for
quadratic data, second-order accurate for smooth data. The neighbours are the Delaunay
neighbours (the natural neighbours of the data point), extended by their own neighbours (two
rings) where there are fewer than twice the unknowns (d + d(d + 1)/2: 5 in 2D, 9 in 3D):
hull points and the typical 2D point (about 6 Delaunay neighbours).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .interp_input import check_values, triangulated

__all__ = ["estimate_gradients", "neighbour_matrix", "fit_gradients"]

# a quadratic fit whose (equilibrated) system is worse conditioned than this gives way to the
# linear fit: its error on linear data would be about this times the round-off
_ILL = 1e8
# neighbour pairs per block of the normal equations (each holds a terms x terms matrix)
_EDGES_PER_BLOCK = 1 << 17


def neighbour_matrix(n: int, simplices) -> sp.csr_matrix:
    """(n, n) CSR pattern of the data points' neighbours: the Delaunay neighbours, and the
    neighbours of neighbours for points with fewer than twice the Taylor unknowns."""
    S = np.asarray(simplices, dtype=np.int64)
    k = S.shape[1]
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    off = i != j
    a, b = S[:, i[off]].ravel(), S[:, j[off]].ravel()
    A = sp.csr_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    A.data[:] = 1.0
    d = k - 1
    unknowns = d + d * (d + 1) // 2
    few = np.flatnonzero(np.diff(A.indptr) < 2 * unknowns)
    if few.size:
        rows = A[few]
        two = (rows @ A + rows).tocsr()
        two.data[:] = 1.0
        pick = sp.csr_matrix((np.ones(few.size), (few, np.arange(few.size))),
                             shape=(n, few.size))
        keep = sp.diags((np.diff(A.indptr) >= 2 * unknowns).astype(float))
        A = (keep @ A + pick @ two).tocsr()
        A = (A - sp.diags(A.diagonal())).tocsr()
        A.eliminate_zeros()
        A.data[:] = 1.0
    A.sort_indices()
    return A


def _design(u, d):
    """Columns of the Taylor fit at offsets u (E, d): u, then u_k u_l (k <= l), halved on the
    diagonal, so the unknowns are g and the Hessian's upper triangle."""
    cols = [u[:, k] for k in range(d)]
    for k in range(d):
        for l in range(k, d):
            cols.append(u[:, k] * u[:, l] * (0.5 if k == l else 1.0))
    return np.stack(cols, axis=1)


def fit_gradients(p, values, A) -> np.ndarray:
    """Least-squares gradients (n, K, d) of ``values`` (n, K) at the points p (n, d) from the
    neighbour pattern A (:func:`neighbour_matrix`)."""
    n, d = p.shape
    K = values.shape[1]
    out = np.empty((n, K, d), dtype=np.result_type(values.dtype, np.float64))
    counts = np.diff(A.indptr)
    start = 0
    while start < n:
        stop = int(np.searchsorted(A.indptr, A.indptr[start] + _EDGES_PER_BLOCK, side="right"))
        stop = min(n, max(stop - 1, start + 1))
        out[start:stop] = _fit_block(p, values, A, start, stop, counts, d)
        start = stop
    return out


def _fit_block(p, values, A, start, stop, counts, d):
    """Gradients at the points start..stop-1: each point's weighted least-squares problem
    (rows scaled by sqrt(w) = (h / |u|)^2, columns equilibrated), padded to the block's largest
    neighbour count and solved by one stacked SVD; where the quadratic terms are not
    determined (fewer neighbours than unknowns, or a system conditioned worse than 1e8: a
    degenerate or very multi-scale neighbourhood) by the linear fit, exact for linear data."""
    e0, e1 = A.indptr[start], A.indptr[stop]
    cnt = counts[start:stop]
    ptr = A.indptr[start:stop] - e0
    local = np.repeat(np.arange(stop - start), cnt)
    pos = np.arange(e1 - e0) - np.repeat(ptr, cnt)
    cols = A.indices[e0:e1]
    u = p[cols] - p[local + start]
    r = np.sqrt((u * u).sum(axis=1))
    h = np.sqrt(np.add.reduceat(r * r, ptr) / cnt)                  # a length per point
    s = u / h[local, None]
    sw = ((h[local] / r) ** 2)[:, None]                              # sqrt of the weight
    B, P = stop - start, d + d * (d + 1) // 2
    M = np.zeros((B, int(cnt.max()), P))
    M[local, pos] = _design(s, d) * sw
    rhs = np.zeros((B, M.shape[1], values.shape[1]), dtype=values.dtype)
    rhs[local, pos] = (values[cols] - values[local + start]) * sw
    sol, cond = _solve(M, rhs)
    low = np.flatnonzero(cond > _ILL)
    if low.size:
        # too few or nearly degenerate neighbours for the quadratic terms: the linear fit
        sol[low, :d] = _solve(M[low, :, :d], rhs[low])[0]
    return np.swapaxes(sol[:, :d, :], 1, 2) / h[:, None, None]


def _solve(M, rhs):
    """Least-squares solutions (B, P, K) of the stacked systems M (B, k, P) x = rhs (B, k, K),
    columns equilibrated, by SVD with singular values below 1e-12 of the largest dropped;
    and the condition numbers (B,) of the equilibrated systems (inf if rank-deficient)."""
    c = np.sqrt((M * M).sum(axis=1))
    c[c == 0.0] = 1.0
    U, S, Vt = np.linalg.svd(M / c[:, None, :], full_matrices=False)
    keep = S > 1e-12 * S[:, :1]
    Sinv = np.where(keep, 1.0 / np.where(keep, S, 1.0), 0.0)
    sol = np.swapaxes(Vt, 1, 2) @ (Sinv[:, :, None] * (np.swapaxes(U, 1, 2) @ rhs))
    with np.errstate(divide="ignore"):
        cond = S[:, 0] / S[:, -1]
    return sol / c[:, :, None], np.where(keep.sum(axis=1) < M.shape[2], np.inf, cond)


def estimate_gradients(points, values, method: str = "direct") -> np.ndarray:
    """Gradients of scattered data at the data points, exact for quadratic data.

    Parameters
    ----------
    points
        (n, d) data points, d = 2 or 3; or their :class:`~skfem_nem.Triangulation` (2D) or
        ``scipy.spatial.Delaunay`` (reused).
    values
        (n, ...) data values (real or complex); trailing dimensions are fitted together.
    method
        ``"direct"``: at each point, the weighted least-squares fit of the quadratic Taylor
        polynomial to the values at its Delaunay neighbours (two rings of them where one has
        fewer than twice the unknowns), weights ``1 / distance^4``.

    Returns
    -------
    (n, ..., d) array: ``out[i, ..., k]`` estimates ``d values / d x_k`` at ``points[i]``.

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import estimate_gradients
    >>> p = np.random.default_rng(0).random((50, 2))
    >>> f = 1 + 2 * p[:, 0] - p[:, 1] + p[:, 0] * p[:, 1] + 3 * p[:, 1] ** 2
    >>> g = estimate_gradients(p, f)
    >>> exact = np.c_[2 + p[:, 1], -1 + p[:, 0] + 6 * p[:, 1]]
    >>> bool(np.abs(g - exact).max() < 1e-9)
    True
    """
    if method != "direct":
        raise ValueError(f"method must be 'direct' (the only gradient estimate), got {method!r}")
    p, tri = triangulated(points, rescale=False)[:2]
    V, trailing = check_values(values, p.shape[0])
    S = tri.triangles if p.shape[1] == 2 else tri.simplices
    G = fit_gradients(p, V, neighbour_matrix(p.shape[0], S))
    return G.reshape((p.shape[0],) + trailing + (p.shape[1],))
