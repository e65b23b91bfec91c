"""The interpolants that need no natural-neighbour coordinates: ``"linear"`` and ``"nearest"``.

``"linear"`` is barycentric interpolation on the Delaunay simplices of the data (what
``scipy.interpolate.LinearNDInterpolator`` computes), continuous, with a gradient constant on
each simplex. In 2D the simplex containing a point comes from the 2D area method's walk
(:func:`~skfem_nem.coordinates.natural_neighbour_coordinates` with ``return_triangles``), so
it is a triangle of the same :class:`~skfem_nem.Triangulation` the natural-neighbour methods
use; in 3D from ``scipy.spatial.Delaunay.find_simplex``. ``"nearest"`` takes the value of the
nearest data point (a kd-tree), piecewise constant: its gradient is zero.

Both evaluate points already known to lie inside the hull (or on it);
:mod:`skfem_nem.coordinates.interpolator` fills the others.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .dispatch import natural_neighbour_coordinates

__all__ = ["LinearInterpolant", "NearestInterpolant"]


def barycentric(p, simplices, s, q):
    """Barycentric coordinates ``lam`` (m, d + 1) of the points q (m, d) in the simplices
    ``simplices[s]`` and their (constant) gradients ``dlam`` (m, d + 1, d)."""
    S = simplices[s]
    v0 = p[S[:, 0]]
    edges = p[S[:, 1:]] - v0[:, None, :]                  # (m, d, d), row k: edge to vertex k+1
    if p.shape[1] == 2:                                   # the 2 x 2 inverse in closed form
        (a, b), (c, e) = edges[:, 0].T, edges[:, 1].T     # columns of E^T: (a, b), (c, e)
        det = a * e - b * c
        inv = np.stack([np.stack([e, -c], 1), np.stack([-b, a], 1)], 1) / det[:, None, None]
    else:
        inv = np.linalg.inv(np.swapaxes(edges, 1, 2))     # mu = inv (q - v0)
    mu = np.einsum("mij,mj->mi", inv, q - v0)
    lam = np.concatenate([1.0 - mu.sum(axis=1, keepdims=True), mu], axis=1)
    dlam = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)
    return lam, dlam


class LinearInterpolant:
    """Barycentric interpolation of ``values`` (n, K) on the Delaunay simplices of the data:
    ``triangulation`` is a :class:`~skfem_nem.Triangulation` (2D) or a
    ``scipy.spatial.Delaunay`` (3D) of the points ``p``."""

    def __init__(self, p, triangulation, values):
        self.p = p
        self.triangulation = triangulation
        self.values = values
        self.two_d = p.shape[1] == 2
        self.simplices = np.asarray(triangulation.triangles if self.two_d
                                    else triangulation.simplices, dtype=np.int64)

    def _locate(self, q):
        if self.two_d:
            # the walk of the 2D area method (Laplace's coordinates: the cheaper kind)
            return natural_neighbour_coordinates(self.triangulation, q, kind="laplace",
                                                 undefined="nan", return_triangles=True)[1]
        s = np.asarray(self.triangulation.find_simplex(q), dtype=np.int64)
        lost = np.flatnonzero(s < 0)
        if lost.size:
            s[lost] = self._nearest_simplex(q[lost])
        return s

    def _nearest_simplex(self, q):
        """For points on the hull that ``find_simplex`` missed by round-off: the hull simplex
        whose smallest barycentric coordinate is largest."""
        hull = np.flatnonzero((self.triangulation.neighbors < 0).any(axis=1))
        out = np.empty(q.shape[0], dtype=np.int64)
        for k, x in enumerate(q):
            lam, _ = barycentric(self.p, self.simplices, hull, np.broadcast_to(x, (hull.size,
                                                                                  x.size)))
            out[k] = hull[lam.min(axis=1).argmax()]
        return out

    def __call__(self, q, gradient: bool):
        s = self._locate(q)
        lam, dlam = barycentric(self.p, self.simplices, s, q)
        vals = self.values[self.simplices[s]]               # (m, d + 1, K)
        out = np.einsum("mk,mkj->mj", lam, vals)
        grad = np.einsum("mkj,mki->mji", vals, dlam) if gradient else None
        return out, grad


class NearestInterpolant:
    """The value of the nearest data point; zero gradient."""

    def __init__(self, p, values):
        self.tree = cKDTree(p)
        self.values = values
        self.d = p.shape[1]

    def __call__(self, q, gradient: bool):
        idx = self.tree.query(q, workers=-1)[1]
        out = self.values[idx]
        grad = (np.zeros(out.shape + (self.d,), dtype=out.dtype) if gradient else None)
        return out, grad
