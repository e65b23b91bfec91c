"""The starting triangulation of :class:`~skfem_nem.geometry.triangulation.Triangulation`
from Qhull, checked with the exact predicates and repaired where Qhull's floating point
fails.

Qhull is fast but not exact: it can leave flat triangles along collinear hull runs and
fold triangles in clusters of nearly coincident nodes. Its output is only a start: the
triangles are oriented and checked for folds here (exactly), thinned or replaced by a fan
over the exact hull when they fail, and the triangulation then inserts the remaining
nodes and flips to Delaunay with exact predicates. Kept apart from the triangulation's
local operations, which never call Qhull.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError

from .delaunay2d import adjacency, exact_hull, first_fold, orientations

__all__ = ["qhull_start", "checked", "thinned", "hull_fan"]


def qhull_start(p):
    """Counter-clockwise triangles and their neighbours of a triangulation of the nodes p
    (n, 2) (every node a vertex, unless Qhull dropped some: the caller inserts those);
    ``ValueError`` naming two nodes if all are collinear."""
    ctr = p.mean(axis=0)
    try:
        d = Delaunay(p - ctr)
    except QhullError as err:
        o = np.empty(1)
        q = p - ctr
        i = int(np.argmax(np.abs(q).sum(1)))
        # all collinear?  check exactly against the two extreme nodes
        j = int(np.argmax(((q - q[i]) ** 2).sum(1)))
        coll = True
        for k in range(p.shape[0]):
            orientations(p, np.array([[i, j, k]], dtype=np.int64), o)
            if o[0] != 0.0:
                coll = False
                break
        if coll:
            raise ValueError(
                f"all {p.shape[0]} nodes are collinear (e.g. nodes {i} and {j} "
                f"span the line): no 2D triangulation exists") from None
        raise ValueError(f"Qhull failed to triangulate the nodes: {err}") from None
    # nodes Qhull dropped as "coplanar" (closer to another node than its
    # tolerance) are inserted afterwards with exact predicates
    T, N = checked(p, d.simplices, d.neighbors)
    if T is None:
        # Qhull folded triangles in a cluster of nearly coincident nodes:
        # triangulate a thinned node set (all hull vertices kept), insert
        # the rest exactly
        T, N = thinned(p)
    return T, N

def checked(p, simplices, neighbors):
    """Orient Qhull's triangles CCW, drop flat hull triangles, and check
    that the result is a valid (fold-free) triangulation; (None, None) if not."""
    T = np.ascontiguousarray(simplices, dtype=np.int64)
    N = np.ascontiguousarray(neighbors, dtype=np.int64)
    orient = np.empty(T.shape[0])
    orientations(p, T, orient)
    keep = orient != 0.0
    neg = orient < 0
    T[neg] = T[neg][:, [0, 2, 1]]
    N[neg] = N[neg][:, [0, 2, 1]]
    if not keep.all():
        # Qhull can leave flat triangles along collinear hull runs: drop them
        # and rebuild the adjacency
        T = np.ascontiguousarray(T[keep])
        try:
            N = adjacency(T, p.shape[0])
        except ValueError:
            return None, None
    if first_fold(T, N) >= 0:
        return None, None
    return T, N

def thinned(p):
    """A starting triangulation of a thinned node set (every hull node kept, nodes
    closer than 1e-6 of the diagonal dropped), in the indices of p."""
    from scipy.spatial import cKDTree
    n = p.shape[0]
    on_hull = np.zeros(n, dtype=bool)
    on_hull[exact_hull(p, np.lexsort((p[:, 1], p[:, 0])))] = True
    delta = 1e-6 * np.hypot(*np.ptp(p, axis=0))
    drop = np.zeros(n, dtype=bool)
    for i, j in cKDTree(p).query_pairs(delta, output_type="ndarray"):
        if drop[i] or drop[j]:
            continue
        if not on_hull[j]:
            drop[j] = True
        elif not on_hull[i]:
            drop[i] = True
    kept = np.flatnonzero(~drop)
    ctr = p[kept].mean(axis=0)
    d = Delaunay(p[kept] - ctr)
    T, N = checked(p[kept], d.simplices, d.neighbors)
    if T is None:
        # folds Qhull makes along hull runs collinear to round-off: a fan over the
        # exact hull's vertices; the caller inserts every other node exactly
        return hull_fan(p)
    return np.ascontiguousarray(kept[T]), N

def hull_fan(p):
    """Triangles fanning out from one vertex of the exact convex hull (strictly convex
    vertices only, counter-clockwise), and their neighbours."""
    h = exact_hull(p, np.lexsort((p[:, 1], p[:, 0])))
    T = np.ascontiguousarray(np.c_[np.full(h.size - 2, h[0]), h[1:-1], h[2:]])
    return T, adjacency(T, p.shape[0])
