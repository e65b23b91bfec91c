"""Distances between polylines' segments: when two material lines carried by nodes come
closer than the mesh resolves (the film of fluid between a sinking plate's outline and a
layer interface), the evolving mesh's callers decide what to do from these distances."""
from __future__ import annotations

import numpy as np

__all__ = ["segment_distances", "segment_gaps", "segments_cross", "close_segment_pairs"]


def _point_segment_distance(x, a, b):
    """Distances of the points x to the segments a-b (arrays (..., 2), broadcast)."""
    d = b - a
    L2 = np.maximum((d * d).sum(axis=-1), 1e-300)
    w = x - a
    t = np.clip((w * d).sum(axis=-1) / L2, 0.0, 1.0)
    r = w - t[..., None] * d
    return np.hypot(r[..., 0], r[..., 1])


def segment_gaps(a, b, c, d) -> np.ndarray:
    """Distance between the segments a-b and c-d (arrays (..., 2), broadcast): for
    segments that do not cross, the least of the distances of each end point to the
    other segment; 0 for a crossing pair."""
    dist = np.minimum(_point_segment_distance(a, c, d), _point_segment_distance(b, c, d))
    dist = np.minimum(dist, _point_segment_distance(c, a, b))
    dist = np.minimum(dist, _point_segment_distance(d, a, b))
    return np.where(segments_cross(a, b, c, d), 0.0, dist)


def segment_distances(a, b, c, d) -> np.ndarray:
    """(k,) distance of each segment a-b (k, 2 each) to the nearest of the segments c-d
    (m, 2 each) (:func:`segment_gaps`)."""
    return segment_gaps(a[:, None], b[:, None], c[None], d[None]).min(axis=1)


def _orient_sign(p, q, r):
    return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                   - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))


def segments_cross(a, b, c, d) -> np.ndarray:
    """Whether the segments a-b and c-d (arrays of points (..., 2), broadcast) cross
    properly: each has the other's end points strictly on opposite sides."""
    return ((_orient_sign(a, b, c) * _orient_sign(a, b, d) < 0)
            & (_orient_sign(c, d, a) * _orient_sign(c, d, b) < 0))


def close_segment_pairs(P, S, distance: float, apart: int = 2):
    """Pairs of the segments S (k, 2 node indices into the points P) closer than
    ``distance`` that are more than ``apart`` segments apart along the polylines they
    form (neighbours along a line are always that close); returns the rows (i, j),
    i < j, and their gaps (:func:`segment_gaps`). Candidates by a k-d tree on the
    segments' midpoints: linear in the number of segments for a bounded density."""
    from scipy.spatial import cKDTree

    S = np.asarray(S, dtype=np.int64).reshape(-1, 2)
    if S.shape[0] < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    A, B = P[S[:, 0]], P[S[:, 1]]
    reach = distance + np.hypot(*(B - A).T).max()
    pairs = cKDTree(0.5 * (A + B)).query_pairs(reach, output_type="ndarray")
    if not pairs.size:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    i, j = pairs.min(axis=1), pairs.max(axis=1)
    gap = segment_gaps(A[i], B[i], A[j], B[j])
    keep = (gap < distance) & ~_along(S, i, j, apart)
    return i[keep], j[keep], gap[keep]


def _along(S, i, j, apart):
    """Whether segments i and j of S are at most ``apart`` segments apart along the lines
    (sharing a node: 1)."""
    import scipy.sparse as sp

    n = int(S.max()) + 1
    G = sp.coo_matrix((np.ones(2 * S.shape[0]), (S.ravel(), S[:, ::-1].ravel())),
                      shape=(n, n)).tocsr() + sp.identity(n, format="csr")
    M = sp.coo_matrix((np.ones(S.size), (np.repeat(np.arange(S.shape[0]), 2), S.ravel())),
                      shape=(S.shape[0], n)).tocsr()
    reach = M
    for _ in range(apart - 1):
        reach = reach @ G
    near = (reach @ M.T).tocsr()
    return np.asarray(near[i, j] > 0).ravel()
