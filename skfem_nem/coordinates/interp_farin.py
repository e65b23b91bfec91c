"""Farin's C1 interpolant (Farin 1990): a cubic Bernstein-Bezier polynomial in the Sibson
coordinates, with its exact gradient.

With the Sibson coordinates ``lam_i`` of x and the data's values ``f_i`` and gradients ``g_i``
at its natural neighbours,

    f(x) = sum_{i,j,k} b_ijk lam_i lam_j lam_k          (all ordered triples)
    b_iii = f_i,   b_iij = f_i + (x_j - x_i) . g_i / 3
    b_ijk = (b_iij + b_iik + b_jji + b_jjk + b_kki + b_kkj) / 4 - (f_i + f_j + f_k) / 6
                                                        (i, j, k distinct)

interpolates the values and the gradients, is C1 inside the hull (at a data point too: the
derivatives of the cubic there, ``3 (b_iij - b_iii)``, combine the coordinates' derivatives
into ``g_i`` whatever their kink), and reproduces every quadratic when the gradients are
exact (Sibson's C1 interpolant, :mod:`~skfem_nem.coordinates.interp_sibson1`, only spherical
quadratics). The triple sum is never formed: with ``sum_i lam_i = 1`` it collapses to one sum
over the neighbours with the row sums ``S2 = sum lam_j^2``, ``X1 = sum lam_j x_j`` and
``X2 = sum lam_j^2 x_j``,

    f = sum_i f_i T_i + lam_i^2 g_i . (X1 - x_i) + lam_i g_i . W_i / 2
    Q_i = (1 - lam_i)^2 - S2 + lam_i^2,   T_i = lam_i^3 + 3 lam_i^2 (1 - lam_i) + lam_i Q_i
    W_i = (1 - lam_i)(X1 - lam_i x_i) - (X2 - lam_i^2 x_i) - x_i Q_i

(O(k) per query for k neighbours instead of O(k^3)); the gradient is its derivative along the
coordinates' exact derivatives, one direction at a time.
"""
from __future__ import annotations

import numpy as np

from .interp_natural import BlendedInterpolant, coordinates_of, row_sums

__all__ = ["FarinInterpolant"]



class FarinInterpolant(BlendedInterpolant):
    """Farin's C1 interpolant of ``values`` (n, K) with nodal ``gradients`` (n, K, d)."""

    def __call__(self, q, gradient: bool):
        K, d = self.values.shape[1], self.p.shape[1]
        if not q.shape[0]:
            return (np.zeros((0, K), self.values.dtype),
                    np.zeros((0, K, d), self.values.dtype) if gradient else None)
        co = coordinates_of(self.triangulation, q, gradient)
        Phi = co[0] if gradient else co
        indptr, cols, lam = Phi.indptr, Phi.indices, Phi.data
        rows = np.repeat(np.arange(q.shape[0]), np.diff(indptr))
        x, F, G = self.p[cols], self.values[cols], self.gradients[cols]
        S2 = row_sums(indptr, lam * lam)[rows]
        X1 = row_sums(indptr, lam[:, None] * x)[rows]
        X2 = row_sums(indptr, (lam * lam)[:, None] * x)[rows]
        Q = (1 - lam) ** 2 - S2 + lam * lam
        T = lam ** 3 + 3 * lam * lam * (1 - lam) + lam * Q
        W = ((1 - lam)[:, None] * (X1 - lam[:, None] * x) - (X2 - (lam * lam)[:, None] * x)
             - x * Q[:, None])
        terms = (F * T[:, None] + (lam * lam)[:, None] * np.einsum("ekd,ed->ek", G, X1 - x)
                 + 0.5 * lam[:, None] * np.einsum("ekd,ed->ek", G, W))
        f = row_sums(indptr, terms)
        if not gradient:
            return f, None
        grad = np.empty(f.shape + (d,), dtype=f.dtype)
        parts = dict(indptr=indptr, rows=rows, lam=lam, x=x, F=F, G=G, X1=X1, Q=Q, W=W)
        for k in range(d):
            grad[:, :, k] = _directional(ld=co[1][k].data, **parts)
        hit = np.flatnonzero((x == q[rows]).all(axis=1))     # queries at a data point
        grad[rows[hit]] = self.gradients[cols[hit]]
        return f, grad


def _directional(indptr, rows, lam, ld, x, F, G, X1, Q, W):
    """Derivative (m, K) of the interpolant when the coordinates change by ``ld`` (nnz,)."""
    S2d = row_sums(indptr, 2 * lam * ld)[rows]
    X1d = row_sums(indptr, ld[:, None] * x)[rows]
    X2d = row_sums(indptr, (2 * lam * ld)[:, None] * x)[rows]
    Qd = -2 * (1 - lam) * ld - S2d + 2 * lam * ld
    Td = 3 * lam * lam * ld + 3 * (2 * lam * ld * (1 - lam) - lam * lam * ld) + ld * Q + lam * Qd
    Wd = (-ld[:, None] * (X1 - lam[:, None] * x) + (1 - lam)[:, None] * (X1d - ld[:, None] * x)
          - (X2d - (2 * lam * ld)[:, None] * x) - x * Qd[:, None])
    terms = (F * Td[:, None]
             + (2 * lam * ld)[:, None] * np.einsum("ekd,ed->ek", G, X1 - x)
             + (lam * lam)[:, None] * np.einsum("ekd,ed->ek", G, X1d)
             + 0.5 * ld[:, None] * np.einsum("ekd,ed->ek", G, W)
             + 0.5 * lam[:, None] * np.einsum("ekd,ed->ek", G, Wd))
    return row_sums(indptr, terms)
