"""Distances between polylines' segments: when two material lines carried by nodes come
closer than the mesh resolves (the film of fluid between a sinking plate's outline and a
layer interface), the evolving mesh's callers decide what to do from these distances."""
from __future__ import annotations

import numpy as np

__all__ = ["segment_distances", "segments_cross"]


def _point_segment_distance(x, a, b):
    """(k, m) distances of the points x (k, 2) to the segments a-b (m, 2)."""
    d = b - a
    L2 = np.maximum((d * d).sum(axis=1), 1e-300)
    w = x[:, None, :] - a[None]
    t = np.clip((w * d[None]).sum(axis=2) / L2, 0.0, 1.0)
    return np.hypot(*(w - t[..., None] * d[None]).transpose(2, 0, 1))


def segment_distances(a, b, c, d) -> np.ndarray:
    """(k,) distance of each segment a-b (k, 2 each) to the nearest of the segments c-d
    (m, 2 each): for segments that do not cross, the least of the distances of each
    end point to the other segment (0 for a crossing pair)."""
    dist = np.minimum(_point_segment_distance(a, c, d), _point_segment_distance(b, c, d))
    dist = np.minimum(dist, _point_segment_distance(c, a, b).T)
    dist = np.minimum(dist, _point_segment_distance(d, a, b).T)
    cross = segments_cross(a[:, None], b[:, None], c[None], d[None])
    return np.where(cross, 0.0, dist).min(axis=1)


def _orient_sign(p, q, r):
    return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                   - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))


def segments_cross(a, b, c, d) -> np.ndarray:
    """Whether the segments a-b and c-d (arrays of points (..., 2), broadcast) cross
    properly: each has the other's end points strictly on opposite sides."""
    return ((_orient_sign(a, b, c) * _orient_sign(a, b, d) < 0)
            & (_orient_sign(c, d, a) * _orient_sign(c, d, b) < 0))
