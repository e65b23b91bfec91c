"""Nodal gradients of 2D scattered data from a curvature-corrected minimum-norm network.

Why a global estimate: on sparse data a local fit at a data point sees about six
neighbours, and its gradient errors set the accuracy of the C1 interpolants. Nielson's
minimum-norm network (Nielson 1983; the estimate behind scipy's Clough-Tocher interpolant)
couples all the gradients instead: along each Delaunay edge ``(i, j)`` of length ``L`` and
direction ``e``, the cubic Hermite curve through ``f_i, f_j`` with slopes ``d_i = e . g_i``,
``d_j = e . g_j`` has the bending energy

    int_0^L p''(s)^2 ds = (4 / L) (d_i^2 + d_i d_j + d_j^2 - 3 t (d_i + d_j) + 3 t^2),

``t = (f_j - f_i) / L``, and the gradients minimise its sum over the edges. That reproduces
linear data but not quadratics: for a quadratic, whose curves along the edges bend with
``c = e^T H e``, the exact gradients do not minimise the sum unless the edges around each
point balance. Here the energy measures the bending *beyond* a target ``c_ij``:
``int (p'' - c_ij)^2 ds``, with ``c_ij`` from the Hessians of the local quadratic fits at
``i`` and ``j`` (:mod:`~skfem_nem.coordinates.interp_gradients`, averaged with the
squared lengths of their shortest edges as weights, so that a tight cluster's Hessian, whose
round-off grows as 1 / h^2, does not set the bending of a long edge). Since ``int p''
ds = d_j - d_i``, the only change to the minimum-norm equations is a constant per edge; for
quadratic data (where the fits' Hessians are exact) the exact gradients make every term zero,
so the estimate is exact for quadratics as well as linear data. Setting the derivative with
respect to ``g_i`` to zero gives, at each point, the 2 x 2 system

    sum_j (2 / L) e e^T g_i = sum_j ((3 t - e . g_j) / L - c_ij / 2) e,

solved point by point in Gauss-Seidel sweeps (the system is block diagonally dominant: the
diagonal blocks carry twice the weight of the neighbours', so a sweep reduces the error by
about half), starting from the local fit's gradients.
"""
from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from numba import njit

__all__ = ["minimum_norm_gradients"]

# Gauss-Seidel stops when a sweep changes no gradient by more than this times the largest
# gradient (per value column): far below the estimate's own error, reached in some 30-40
# sweeps (each sweep about halves the change)
GLOBAL_TOL = 1e-10
# and after at most this many sweeps (a warning then names the change left)
GLOBAL_MAX_SWEEPS = 400


def minimum_norm_gradients(p, triangles, values, start, hessians) -> np.ndarray:
    """Gradients (n, K, 2) of ``values`` (n, K; real or complex) at the 2D points p (n, 2)
    minimising the curvature-corrected bending energy over the edges of ``triangles``;
    ``start`` (n, K, 2) the first guess, ``hessians`` (n, K, 3) the local fits' Hessians
    (``H_xx, H_xy, H_yy``)."""
    indptr, nbr = _adjacency(p.shape[0], np.asarray(triangles, dtype=np.int64))
    if np.iscomplexobj(values):
        re = minimum_norm_gradients(p, triangles, values.real, start.real, hessians.real)
        im = minimum_norm_gradients(p, triangles, values.imag, start.imag, hessians.imag)
        return re + 1j * im
    i = np.repeat(np.arange(p.shape[0]), np.diff(indptr))
    e = p[nbr] - p[i]
    L2 = (e * e).sum(axis=1)
    e /= np.sqrt(L2)[:, None]
    # the endpoints' Hessians weighted by the squared length of their shortest edge: the
    # round-off of a fit's Hessian grows as 1 / h^2 with its shortest distances, so a point
    # in a tight cluster must not set the bending of a long edge (measured: gradients of
    # linear data off by 1e-7 with plain means); any weighted mean is exact for quadratics
    area = np.minimum.reduceat(L2, indptr[:-1])
    wi = (area[i] / (area[i] + area[nbr]))[:, None, None]
    wj = 1.0 - wi
    H = wi * hessians[i] + wj * hessians[nbr]                       # (E, K, 3)
    c = (e[:, None, 0] ** 2 * H[..., 0] + 2 * e[:, None, 0] * e[:, None, 1] * H[..., 1]
         + e[:, None, 1] ** 2 * H[..., 2])
    G = np.array(start, dtype=np.float64, order="C")
    sweeps, change = _sweeps(indptr, nbr, np.ascontiguousarray(p, dtype=np.float64),
                             np.ascontiguousarray(values, dtype=np.float64),
                             np.ascontiguousarray(c), G, GLOBAL_TOL, GLOBAL_MAX_SWEEPS)
    if sweeps >= GLOBAL_MAX_SWEEPS:
        warnings.warn(f"the global gradient estimate stopped after {sweeps} sweeps with a "
                      f"relative change of {change:.1e} (tolerance {GLOBAL_TOL:.0e})",
                      RuntimeWarning, stacklevel=3)
    return G


def _adjacency(n, T):
    """CSR (indptr, neighbours) of the points' edge neighbours in the triangles T (m, 3)."""
    a = T[:, [0, 1, 2, 1, 2, 0]].ravel()
    b = T[:, [1, 2, 0, 0, 1, 2]].ravel()
    A = sp.csr_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    A.sum_duplicates()
    A.sort_indices()
    return A.indptr.astype(np.int64), A.indices.astype(np.int64)


@njit(cache=True)
def _sweeps(indptr, nbr, p, f, c, G, tol, max_sweeps):
    """Gauss-Seidel sweeps over the points on the 2 x 2 systems of the module docstring,
    in place on G (n, K, 2); c (E, K) the target bending per directed edge. Returns the
    sweeps done and the last relative change (largest over the value columns)."""
    n, K = G.shape[0], G.shape[1]
    dmax = np.zeros(K)
    gmax = np.zeros(K)
    rhs = np.zeros((K, 2))
    worst = np.inf
    for sweep in range(max_sweeps):
        dmax[:] = 0.0
        gmax[:] = 0.0
        for i in range(n):
            a11 = a12 = a22 = 0.0
            rhs[:, :] = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = nbr[k]
                ex = p[j, 0] - p[i, 0]
                ey = p[j, 1] - p[i, 1]
                L = np.sqrt(ex * ex + ey * ey)
                ex /= L
                ey /= L
                a11 += 2.0 * ex * ex / L
                a12 += 2.0 * ex * ey / L
                a22 += 2.0 * ey * ey / L
                for m in range(K):
                    t = (f[j, m] - f[i, m]) / L
                    s = (3.0 * t - ex * G[j, m, 0] - ey * G[j, m, 1]) / L - 0.5 * c[k, m]
                    rhs[m, 0] += s * ex
                    rhs[m, 1] += s * ey
            det = a11 * a22 - a12 * a12
            for m in range(K):
                gx = (a22 * rhs[m, 0] - a12 * rhs[m, 1]) / det
                gy = (a11 * rhs[m, 1] - a12 * rhs[m, 0]) / det
                dmax[m] = max(dmax[m], abs(gx - G[i, m, 0]), abs(gy - G[i, m, 1]))
                gmax[m] = max(gmax[m], abs(gx), abs(gy))
                G[i, m, 0] = gx
                G[i, m, 1] = gy
        worst = 0.0
        for m in range(K):
            if dmax[m] > 0.0:
                worst = max(worst, dmax[m] / gmax[m])
        if worst <= tol:
            return sweep + 1, worst
    return max_sweeps, worst
