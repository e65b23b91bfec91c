"""Gradients of scattered data estimated at the data points (for the C1 interpolants).

The direct estimate fits, at each data point x_i, the quadratic Taylor polynomial
``f_j - f_i = g . u_j + u_j^T H u_j / 2`` (``u_j = x_j - x_i``) to the values at its
neighbours by weighted least squares (weights ``1 / |u_j|^8``) and returns ``g``: exact for
quadratic data, second-order accurate for smooth data. The neighbours are the Delaunay
neighbours (the natural neighbours of the data point), extended by their own neighbours (two
rings) where there are fewer than twice the unknowns (d + d(d + 1)/2: 5 in 2D, 9 in 3D):
hull points and the typical 2D point (about 6 Delaunay neighbours). On sparse 2D data a fit
to six neighbours is what limits the C1 interpolants; the global estimate
(:mod:`~skfem_nem.coordinates.interp_gradients_global`) couples the points along the Delaunay
edges, with the fits' Hessians as its curvature targets, and is the 2D default.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .interp_gradients_global import minimum_norm_gradients
from .interp_input import check_values, triangulated

__all__ = ["estimate_gradients", "nodal_gradients", "neighbour_matrix", "fit_gradients",
           "METHODS", "DEFAULT_METHOD"]

# gradient method -> the dimensions it works in
METHODS = {"direct": (2, 3), "global": (2,)}
# the estimate of the C1 interpolants per dimension: in 2D the global one (on Franke's six
# functions at 100 points the more accurate, benchmarks/interpolation.py); in 3D the direct fit
DEFAULT_METHOD = {2: "global", 3: "direct"}

# a quadratic fit whose (equilibrated) system is worse conditioned than this gives way to the
# linear fit: its error on linear data would be about this times the round-off
_ILL = 1e8
# the least-squares weights are 1 / |u|^WEIGHT_POWER: the nearest neighbours dominate
# (measured on 1,000 and 10,000 random points, a smooth function: rms gradient errors 1.7-1.9
# times below those of weights 1 / |u|^4 in 2D and in 3D; 6 and 10 give 1.3-1.4 and about
# 1.9; the fit stays exact for quadratics)
WEIGHT_POWER = 8
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


def fit_gradients(p, values, A, hessians: bool = False):
    """Least-squares gradients (n, K, d) of ``values`` (n, K) at the points p (n, d) from the
    neighbour pattern A (:func:`neighbour_matrix`); with ``hessians`` also the fits' Hessians
    (n, K, d(d + 1)/2: the upper triangle row by row, zero where the linear fit was used)."""
    n, d = p.shape
    K = values.shape[1]
    dtype = np.result_type(values.dtype, np.float64)
    out = np.empty((n, K, d + d * (d + 1) // 2), dtype=dtype)
    counts = np.diff(A.indptr)
    start = 0
    while start < n:
        stop = int(np.searchsorted(A.indptr, A.indptr[start] + _EDGES_PER_BLOCK, side="right"))
        stop = min(n, max(stop - 1, start + 1))
        out[start:stop] = _fit_block(p, values, A, start, stop, counts, d)
        start = stop
    return (out[..., :d], out[..., d:]) if hessians else out[..., :d]


def _fit_block(p, values, A, start, stop, counts, d):
    """Gradients and Hessians (B, K, P) at the points start..stop-1: each point's weighted
    least-squares problem (rows scaled by sqrt(w) = (h / |u|)^(WEIGHT_POWER / 2), columns
    equilibrated), padded to the block's largest neighbour count and solved by one stacked
    SVD; where the quadratic terms are not determined (fewer neighbours than unknowns, or a
    system conditioned worse than 1e8: a degenerate or very multi-scale neighbourhood) by
    the linear fit, exact for linear data."""
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
    sw = ((h[local] / r) ** (WEIGHT_POWER / 2))[:, None]            # sqrt of the weight
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
        sol[low, d:] = 0.0
    sol[:, :d] /= h[:, None, None]
    sol[:, d:] /= (h * h)[:, None, None]
    return np.swapaxes(sol, 1, 2)


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


def nodal_gradients(p, tri, values, method=None) -> np.ndarray:
    """Gradients (n, K, d) of ``values`` (n, K) at the points p (n, d) of the triangulation
    ``tri`` (a :class:`~skfem_nem.Triangulation` in 2D, a ``scipy.spatial.Delaunay`` in 3D) by
    ``method`` (None: the dimension's default, :data:`DEFAULT_METHOD`)."""
    d = p.shape[1]
    method = DEFAULT_METHOD[d] if method is None else method
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))} (or None for "
                         f"the default), got {method!r}")
    if d not in METHODS[method]:
        raise ValueError(f"gradient method {method!r} works in 2D only, the points are {d}D "
                         f"(3D: 'direct')")
    S = tri.triangles if d == 2 else tri.simplices
    if method == "direct":
        return fit_gradients(p, values, neighbour_matrix(p.shape[0], S))
    G, H = fit_gradients(p, values, neighbour_matrix(p.shape[0], S), hessians=True)
    return minimum_norm_gradients(p, S, values, G, H)


def estimate_gradients(points, values, method=None) -> np.ndarray:
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
        fewer than twice the unknowns), weights ``1 / distance^8``. ``"global"`` (2D): the
        gradients that minimise the bending of the cubic curves along all Delaunay edges
        beyond the bending the direct fits' Hessians predict (Nielson's minimum-norm
        network, corrected so that it is exact for quadratics), solved by Gauss-Seidel
        sweeps. None (default): ``"global"`` in 2D, ``"direct"`` in 3D, as the C1 methods of
        :class:`~skfem_nem.NaturalNeighbourInterpolator` use.

    Returns
    -------
    (n, ..., d) array: ``out[i, ..., k]`` estimates ``d values / d x_k`` at ``points[i]``.

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import estimate_gradients
    >>> p = np.random.default_rng(0).random((50, 2))
    >>> f = 1 + 2 * p[:, 0] - p[:, 1] + p[:, 0] * p[:, 1] + 3 * p[:, 1] ** 2
    >>> exact = np.c_[2 + p[:, 1], -1 + p[:, 0] + 6 * p[:, 1]]
    >>> [bool(np.abs(estimate_gradients(p, f, m) - exact).max() < 1e-9)
    ...  for m in ("direct", "global")]
    [True, True]
    """
    p, tri = triangulated(points, rescale=False)[:2]
    V, trailing = check_values(values, p.shape[0])
    G = nodal_gradients(p, tri, V, method)
    return G.reshape((p.shape[0],) + trailing + (p.shape[1],))
