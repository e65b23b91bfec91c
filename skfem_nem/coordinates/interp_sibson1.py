"""Sibson's C1 interpolant (his "Z1", Sibson 1981): a blend of linear Taylor functions at the
natural neighbours, with its exact gradient.

With the Sibson coordinates ``lam_i`` of x, ``r_i = |x - x_i|``, the data ``f_i`` and
gradients ``g_i`` at the natural neighbours and their Taylor functions
``zeta_i(x) = f_i + g_i . (x - x_i)``:

    f0    = sum_i lam_i f_i                               (Sibson's C0 interpolant)
    Gamma = sum_i lam_i / r_i
    zeta  = sum_i (lam_i / r_i) zeta_i(x) / Gamma          (the blended Taylor functions)
    alpha = sum_i lam_i r_i / Gamma,   beta = sum_i lam_i r_i^2
    f(x)  = (alpha f0 + beta zeta) / (alpha + beta)

``f`` interpolates the data and the gradients (``f(x_i) = f_i``, ``grad f(x_i) = g_i``), is C1
everywhere inside the hull, including at the data points, and reproduces spherical quadratics
``a + b . x + c |x|^2`` exactly when the gradients are exact (not every quadratic: Farin's C1
interpolant does). The gradient below differentiates each factor with the coordinates' exact
derivatives ``grad lam_i`` and ``grad r_i = (x - x_i) / r_i``; at a data point it is ``g_i``;
on the hull (where ``grad lam_i`` is not defined) NaN.
"""
from __future__ import annotations

import numpy as np

from .interp_natural import BlendedInterpolant, coordinates_of, row_sums

__all__ = ["Sibson1Interpolant"]



class Sibson1Interpolant(BlendedInterpolant):
    """Sibson's C1 interpolant of ``values`` (n, K) with nodal ``gradients`` (n, K, d)."""

    def __call__(self, q, gradient: bool):
        if not q.shape[0]:
            K, d = self.values.shape[1], self.p.shape[1]
            return (np.zeros((0, K), self.values.dtype),
                    np.zeros((0, K, d), self.values.dtype) if gradient else None)
        co = coordinates_of(self.triangulation, q, gradient)
        Phi = co[0] if gradient else co
        indptr, cols, lam = Phi.indptr, Phi.indices, Phi.data
        if np.any(np.diff(indptr) == 0):  # pragma: no cover - a point inside has neighbours
            raise RuntimeError("a query point inside the hull got no natural neighbour")
        rows = np.repeat(np.arange(q.shape[0]), np.diff(indptr))
        u = q[rows] - self.p[cols]                                  # (nnz, d): x - x_i
        r = np.sqrt((u * u).sum(axis=1))
        hit = np.flatnonzero(r == 0.0)          # entries of a query at a data point
        at_node = rows[hit]
        r[hit] = 1.0                            # those rows are replaced below
        V, G = self.values[cols], self.gradients[cols]              # (nnz, K), (nnz, K, d)
        zeta_i = V + np.einsum("ekd,ed->ek", G, u)
        gam = lam / r
        Gam = row_sums(indptr, gam)
        f0 = row_sums(indptr, lam[:, None] * V)
        zeta = row_sums(indptr, gam[:, None] * zeta_i) / Gam[:, None]
        alpha = row_sums(indptr, lam * r) / Gam
        beta = row_sums(indptr, lam * r * r)
        wsum = alpha + beta
        wsum[at_node] = 1.0
        f = (alpha[:, None] * f0 + beta[:, None] * zeta) / wsum[:, None]
        f[at_node] = self.values[cols[hit]]     # the data point's value and gradient
        if not gradient:
            return f, None
        glam = np.stack([D.data for D in co[1]], axis=1)            # (nnz, d)
        parts = dict(indptr=indptr, u=u, r=r, lam=lam, glam=glam, V=V, G=G, zeta_i=zeta_i,
                     gam=gam, Gam=Gam, f0=f0, zeta=zeta, alpha=alpha, beta=beta, f=f,
                     wsum=wsum)
        grad = _gradient(**parts)
        grad[at_node] = self.gradients[cols[hit]]
        return f, grad


def _gradient(indptr, u, r, lam, glam, V, G, zeta_i, gam, Gam, f0, zeta, alpha, beta, f, wsum):
    """The gradient (m, K, d) of the blend, factor by factor (see the module docstring)."""
    ur = u / r[:, None]                                             # grad r_i
    dgam = glam / r[:, None] - (lam / r / r)[:, None] * ur          # grad (lam_i / r_i)
    dGam = row_sums(indptr, dgam)                                    # (m, d)
    dZ = row_sums(indptr, zeta_i[:, :, None] * dgam[:, None, :] + gam[:, None, None] * G)
    dzeta = (dZ - zeta[:, :, None] * dGam[:, None, :]) / Gam[:, None, None]
    dA = row_sums(indptr, glam * r[:, None] + lam[:, None] * ur)
    dalpha = (dA - alpha[:, None] * dGam) / Gam[:, None]            # (m, d)
    dbeta = row_sums(indptr, glam * (r * r)[:, None] + 2.0 * lam[:, None] * u)
    df0 = row_sums(indptr, V[:, :, None] * glam[:, None, :])         # (m, K, d)
    num = (f0[:, :, None] * dalpha[:, None, :] + alpha[:, None, None] * df0
           + zeta[:, :, None] * dbeta[:, None, :] + beta[:, None, None] * dzeta
           - f[:, :, None] * (dalpha + dbeta)[:, None, :])
    return num / wsum[:, None, None]
