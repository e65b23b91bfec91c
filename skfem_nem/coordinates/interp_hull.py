"""Which queries of a scattered-data interpolant lie inside the convex hull of the data.

The coordinates raise for a point outside the hull; an interpolant in scipy's style gives
those points a fill value instead. :class:`HullTest` decides by the half-spaces of the hull's
facets (``scipy.spatial.ConvexHull``, unit outward normals), in 2D and 3D alike, with the
package's hull policy (:mod:`skfem_nem.geometry.hull`): a point outside by less than
``OUTSIDE_ROUNDOFF`` times the diagonal of the data's bounding box is on the hull (round-off
of a point computed on it) and is moved onto it; farther points are outside. Points on the
hull interpolate.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import ConvexHull

from ..geometry.hull import OUTSIDE_ROUNDOFF

__all__ = ["HullTest"]


@njit(cache=True)
def _beyond(q, normals, offsets, tol, out):
    """``out[j]``: the largest signed distance of q[j] beyond a facet's plane, or the first
    one found above ``tol`` (then the point is outside, whatever the others)."""
    d = q.shape[1]
    for j in range(q.shape[0]):
        best = -np.inf
        for f in range(offsets.shape[0]):
            s = offsets[f]
            for k in range(d):
                s += normals[f, k] * q[j, k]
            if s > best:
                best = s
                if s > tol:
                    break
        out[j] = best


class HullTest:
    """Inside/outside tests against the convex hull of the (n, d) points ``p``."""

    def __init__(self, p: np.ndarray):
        eq = ConvexHull(p).equations
        # merged facets of a triangulated hull repeat their plane
        eq = np.unique(eq, axis=0)
        self.normals = np.ascontiguousarray(eq[:, :-1])
        self.offsets = eq[:, -1].copy()
        self.diagonal = float(np.linalg.norm(np.ptp(p, axis=0)))
        self.tol = OUTSIDE_ROUNDOFF * self.diagonal

    def distance(self, q: np.ndarray) -> np.ndarray:
        """(m,) signed distance of the points q (m, d) beyond the hull: the largest over the
        facets' planes (<= 0 inside), or, for points outside by more than the round-off
        tolerance, the first distance above it."""
        out = np.empty(q.shape[0])
        _beyond(np.ascontiguousarray(q, dtype=np.float64), self.normals, self.offsets,
                self.tol, out)
        return out

    def inside(self, q: np.ndarray):
        """``(rows, points, distances)``: the indices of the points q (m, d) that are inside
        the hull or on it (to round-off), those points (the ones just outside moved onto the
        hull) and their signed distances beyond it (<= 0, ~0 on the hull)."""
        dist = self.distance(q)
        rows = np.flatnonzero(dist <= self.tol)
        every = rows.size == q.shape[0]
        pts, dist = (q, dist) if every else (q[rows], dist[rows])
        near = np.flatnonzero(dist > 0.0)
        if near.size:
            pts = pts.copy() if every else pts
            pts[near] = self._onto_hull(pts[near])
        return rows, pts, dist

    def _onto_hull(self, q: np.ndarray) -> np.ndarray:
        """Points just outside moved onto the hull: projected onto the plane they are
        farthest beyond, repeated (near a hull edge or vertex a projection can leave the
        point beyond a neighbouring facet by round-off)."""
        q = q.copy()
        for _ in range(2 * q.shape[1]):
            dist = q @ self.normals.T + self.offsets
            f = dist.argmax(axis=1)
            d = dist[np.arange(q.shape[0]), f]
            beyond = d > 0.0
            if not beyond.any():
                break
            q[beyond] -= d[beyond, None] * self.normals[f[beyond]]
        return q
