"""Constrained Delaunay triangulations: segments that must be edges.

Why
---
Sibson and Laplace functions are smooth across every edge, so a field built
from them cannot kink at a material interface, and on a non-convex domain
nodes across a notch are natural neighbours through the void. The remedy (the
constrained natural element method of Yvonnet, Ryckelynck, Lorong and
Chinesta, 2004) starts from a *constrained* Delaunay triangulation: given
segments (pairs of nodes: an interface, the outline of a body, the boundary
of a non-convex domain) are edges, and every other edge is Delaunay among
the nodes visible to each other (no segment in between). The cavity of a
point then stops at segments (:func:`~skfem_nem.geometry.delaunay2d.grow_cavity`),
so its natural neighbours are the nodes it sees.

How
---
Segments are inserted one at a time into the Delaunay triangulation of the
nodes by Sloan's flip algorithm (1993): walk from one end to the other
collecting the edges the segment crosses, flip each crossing edge whose
quadrilateral is convex (and queue it again if the new edge still crosses,
or if its quadrilateral was not convex), until the segment is an edge; then
Lawson flips, which never remove a segment, restore the constrained
Delaunay property. Every decision is an exact orientation or in-circle
test. A node lying exactly on a segment splits it in two (both halves are
segments); two segments that cross are an error naming both.

Regions
-------
:func:`flood_regions` labels the triangles by the connected regions the
segments cut the hull into, so that a mesh can drop the triangles of a hole
(the notch of an L-shaped domain) while the coordinates keep them as walls.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .delaunay2d import flip_edge, is_segment, lawson, locate_many, segment_key
from .predicates import orient2d, orient2d_sign

__all__ = ["CrossingSegments", "check_segments", "edge_keys", "flood_regions",
           "insert_segments", "keys_of", "pair_keys", "recover_segments", "segment_through",
           "segments_of", "sorted_segments", "split_key", "triangle_edge_keys"]

# codes of the segment insertion kernel
_DONE = 0
_ON_SEGMENT = 1      # a node lies on the open segment: split there
_CROSSES = 2         # the segment crosses another segment
_FAILED = 3          # no progress (only on invalid input triangulations)


class CrossingSegments(ValueError):
    """Two segments cross: ``first`` and ``second`` are their indices in the given
    segments (``second`` is -1 if it is not one of them); ``nodes``: their two node
    pairs, where known."""

    def __init__(self, message, first, second, nodes=None):
        super().__init__(message)
        self.first, self.second, self.nodes = first, second, nodes


def pair_keys(pairs) -> np.ndarray:
    """(k,) keys of (k, 2) node pairs, in their order (see
    :func:`~skfem_nem.geometry.delaunay2d.segment_key`)."""
    s = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    return (s[:, 0] << 32) | s[:, 1]


def keys_of(segments: np.ndarray) -> np.ndarray:
    """Sorted unique keys of (k, 2) segments."""
    return np.unique(pair_keys(segments))


def triangle_edge_keys(T) -> np.ndarray:
    """(3 nt,) keys of the edges of the triangles T (interior edges twice)."""
    return pair_keys(np.concatenate([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]]))


def sorted_segments(pairs, source):
    """``(keys, source)`` of the (k, 2) node pairs with their sources, sorted by key (the
    form :class:`~skfem_nem.geometry.triangulation.Triangulation` keeps them in)."""
    keys = pair_keys(pairs)
    order = np.argsort(keys)
    return keys[order], np.asarray(source, dtype=np.int64)[order]


def segments_of(keys: np.ndarray) -> np.ndarray:
    """(k, 2) segments ``(i, j)``, i < j, of sorted keys."""
    keys = np.asarray(keys, dtype=np.int64)
    return np.stack([keys >> 32, keys & 0xFFFFFFFF], axis=1)


def check_segments(segments, n: int, name: str = "segments") -> np.ndarray:
    """``segments`` as an (k, 2) int64 array of node pairs, checked: integer
    indices in [0, n), two different nodes each. Raises ``ValueError`` naming
    the first bad segment."""
    s = np.asarray(segments)
    if s.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2) (pairs of node indices), "
                         f"got {s.shape}")
    if not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"{name} must hold integer node indices, got dtype {s.dtype}")
    s = s.astype(np.int64)
    bad = np.flatnonzero((s < 0).any(axis=1) | (s >= n).any(axis=1))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {s[bad[0]].tolist()} refers to a node "
                         f"outside [0, {n})")
    bad = np.flatnonzero(s[:, 0] == s[:, 1])
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {s[bad[0]].tolist()} joins a node to itself")
    return s


def edge_keys(T, segments, n):
    """Sorted keys of ``segments`` (None: none), each checked to be an edge of T."""
    s = check_segments(segments if segments is not None else [], n)
    keys = keys_of(s)
    missing = np.flatnonzero(~np.isin(keys, triangle_edge_keys(T)))
    if missing.size:
        raise ValueError(f"segment {segments_of(keys[missing[:1]])[0].tolist()} is not an "
                         f"edge of the stored triangles")
    return keys


def segment_through(P, T, N, S, i, start):
    """The key of the segment of ``S`` whose interior node i lies on (found from the
    triangle containing it, walking from ``start``), or None."""
    if not S.size:
        return None
    out = np.empty(1, dtype=np.int64)
    locate_many(P, T, N, P[i:i + 1], np.array([start], dtype=np.int64), out)
    t = int(out[0])
    for k in range(3 if t >= 0 else 0):
        a, b = int(T[t, (k + 1) % 3]), int(T[t, (k + 2) % 3])
        if is_segment(S, a, b) and orient2d(*P[a], *P[b], *P[i]) == 0.0:
            return int(segment_key(a, b))
    return None


def split_key(keys, source, key, i):
    """``(keys, source)`` with the segment ``key`` replaced by its two pieces through
    node i (both from the same source)."""
    a, b = key >> 32, key & 0xFFFFFFFF
    at = int(np.flatnonzero(keys == key)[0])
    return sorted_segments(np.r_[np.delete(segments_of(keys), at, axis=0), [[a, i], [i, b]]],
                           np.r_[np.delete(source, at), source[at], source[at]])


@njit(cache=True)
def _vertex_triangles(T, vt):
    """``vt[v]``: a triangle with vertex v (flips later make some entries stale)."""
    for t in range(T.shape[0]):
        for j in range(3):
            vt[T[t, j]] = t


@njit(cache=True, inline="always")
def _slot(T, t, v):
    """Position of vertex v in triangle t."""
    return 0 if T[t, 0] == v else (1 if T[t, 1] == v else 2)


@njit(cache=True)
def _star_start(T, vt, v):
    """A triangle with vertex v: ``vt[v]`` if that is still one (flips make entries
    stale; then a scan, rare, refreshes it)."""
    t = vt[v]
    if t >= 0 and (T[t, 0] == v or T[t, 1] == v or T[t, 2] == v):
        return t
    for t in range(T.shape[0]):
        if T[t, 0] == v or T[t, 1] == v or T[t, 2] == v:
            vt[v] = t
            return t
    return -1


@njit(cache=True)
def _edge_slot(T, N, vt, c, d):
    """``(t, k)``: a triangle t with the edge {c, d} opposite its vertex k, found
    by turning around c; (-1, -1) if {c, d} is not an edge."""
    t0 = _star_start(T, vt, c)
    for direction in range(2):
        t = t0
        for _ in range(T.shape[0]):
            j = _slot(T, t, c)
            for k in range(3):
                if k != j and T[t, k] == d:
                    return t, 3 - j - k
            t = N[t, (j + 1) % 3] if direction == 0 else N[t, (j + 2) % 3]
            if t < 0 or t == t0:
                break
        if t == t0:
            break
    return -1, -1


@njit(cache=True, inline="always")
def _side(P, a, b, c):
    return orient2d_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1])


@njit(cache=True, inline="always")
def _ahead(P, a, b, v):
    """True if node v lies on the line a-b, on b's side of a."""
    return _side(P, a, b, v) == 0.0 and ((P[v, 0] - P[a, 0]) * (P[b, 0] - P[a, 0])
                                         + (P[v, 1] - P[a, 1]) * (P[b, 1] - P[a, 1])) > 0.0


@njit(cache=True)
def _first_crossing(P, T, N, vt, a, b):
    """Turn around node a to the triangle t = (a, c, d) whose edge (c, d) the
    segment a-b crosses. Returns ``(t, code, v)``: ``code`` -1 with that triangle,
    ``_DONE`` if a-b is an edge already, ``_ON_SEGMENT`` with the node v on the
    open segment, ``_FAILED`` if no triangle around a fits."""
    t0 = _star_start(T, vt, a)
    for direction in range(2):
        t = t0
        for _ in range(T.shape[0]):
            j = _slot(T, t, a)
            c = T[t, (j + 1) % 3]
            d = T[t, (j + 2) % 3]
            if c == b or d == b:
                return -1, _DONE, -1
            if _ahead(P, a, b, c):
                return -1, _ON_SEGMENT, c
            if _ahead(P, a, b, d):
                return -1, _ON_SEGMENT, d
            if _side(P, a, c, b) > 0.0 and _side(P, a, d, b) < 0.0:
                return t, -1, -1
            t = N[t, (j + 1) % 3] if direction == 0 else N[t, (j + 2) % 3]
            if t < 0 or t == t0:
                break
        if t == t0:
            break
    return -1, _FAILED, -1


@njit(cache=True)
def _crossed_edges(P, T, N, S, vt, a, b, out):
    """The edges the segment a-b crosses, in order from a, into ``out`` (rows c, d
    with c right of a->b). Returns ``(count, code, v)``: code ``_ON_SEGMENT`` with
    the node v on the open segment, ``_CROSSES`` with the crossed edge {c, d} that
    is itself a segment in ``out[count]``, ``_FAILED`` if ``out`` is too small, or
    ``_DONE``."""
    t, code, v = _first_crossing(P, T, N, vt, a, b)
    if t < 0:
        return 0, code, v
    k = _slot(T, t, a)
    count = 0
    while True:
        c = T[t, (k + 1) % 3]
        d = T[t, (k + 2) % 3]
        if count == out.shape[0]:
            return count, _FAILED, -1
        out[count, 0] = c
        out[count, 1] = d
        if is_segment(S, c, d):
            return count, _CROSSES, -1
        count += 1
        # across (c, d): the triangle u = (e, d, c)
        u = N[t, k]
        e = T[u, 0] + T[u, 1] + T[u, 2] - c - d
        if e == b:
            return count, _DONE, -1
        s = _side(P, a, b, e)
        if s == 0.0:
            return count, _ON_SEGMENT, e
        # the next crossed edge is (c, e) (opposite d) or (e, d) (opposite c)
        k = _slot(T, u, d) if s > 0.0 else _slot(T, u, c)
        t = u


@njit(cache=True)
def _flip_until_edge(P, T, N, vt, a, b, queue, touched):
    """Sloan's flips: flip the crossing edges in ``queue`` (a ring) until none
    crosses a-b. The triangles of each flip go to ``touched`` while it has room.
    Returns the number of triangles touched, or -1 without progress."""
    size = queue.shape[0]
    head = 0
    left = size
    ntouch = 0
    stall = 0
    while left > 0:
        c = queue[head, 0]
        d = queue[head, 1]
        head = (head + 1) % size
        left -= 1
        t, k = _edge_slot(T, N, vt, c, d)
        u = N[t, k]
        x = T[t, k]
        p = T[t, (k + 1) % 3]
        q = T[t, (k + 2) % 3]
        y = T[u, 0] + T[u, 1] + T[u, 2] - p - q
        tail = (head + left) % size
        if _side(P, x, p, y) > 0.0 and _side(P, y, q, x) > 0.0:
            flip_edge(T, N, t, k)
            # now t = (x, p, y), u = (x, y, q)
            vt[x] = t
            vt[y] = t
            vt[p] = t
            vt[q] = u
            if ntouch + 2 <= touched.shape[0]:
                touched[ntouch] = t
                touched[ntouch + 1] = u
            ntouch += 2
            stall = 0
            if _side(P, a, b, x) * _side(P, a, b, y) < 0.0:
                # the new edge x-y still crosses: queue it again
                queue[tail, 0] = x
                queue[tail, 1] = y
                left += 1
        else:
            # not convex (yet): try again after the others
            queue[tail, 0] = c
            queue[tail, 1] = d
            left += 1
            stall += 1
            if stall > left + 1:
                return -1
    return ntouch


def insert_segments(P, T, N, segments):
    """Make every segment (k, 2) an edge of the Delaunay triangulation (P, T, N),
    in place, and restore the constrained Delaunay property.

    Returns ``(keys, source)``: the sorted keys of the segments as inserted (a
    segment with a node on it is replaced by its pieces) and, for each, the
    index of the input segment it comes from. Raises ``ValueError`` naming two
    segments that cross.
    """
    todo = [(int(a), int(b), i) for i, (a, b) in enumerate(segments)][::-1]
    S = keys_of(segments)
    origin = {}
    for a, b, i in todo[::-1]:
        origin.setdefault(int(segment_key(a, b)), i)
    vt = np.full(P.shape[0], -1, dtype=np.int64)
    _vertex_triangles(T, vt)
    while todo:
        a, b, i = todo.pop()
        cap = 64
        while True:
            out = np.empty((cap, 2), dtype=np.int64)
            count, code, v = _crossed_edges(P, T, N, S, vt, a, b, out)
            if code != _FAILED or count < cap:
                break
            cap *= 8
        if code == _ON_SEGMENT:
            S = _split(S, origin, a, b, int(v), i)
            todo += [(int(v), b, i), (a, int(v), i)]
            continue
        if code == _CROSSES:
            c, d = (int(x) for x in out[count])
            j = origin.get(int(segment_key(c, d)), -1)
            raise CrossingSegments(
                f"segments[{i}] = {segments[i].tolist()} crosses segments[{j}] = "
                f"{segments[j].tolist()}: segments may meet only at their end nodes (a node "
                f"on a segment splits it)", i, j)
        if code == _FAILED:
            raise RuntimeError(f"segments[{i}] = {[a, b]} could not be traced through the "
                               f"triangulation")
        if count:
            _make_edge(P, T, N, S, vt, a, b, i, out[:count])
    return S, np.array([origin[int(k)] for k in S], dtype=np.int64)


def recover_segments(P, T, N, keys, source):
    """Make every segment (sorted ``keys`` with their ``source``) an edge of the valid
    triangulation (P, T, N) again, in place, by the flips of :func:`insert_segments`
    (after a node that ends segments was taken out and put back). Every segment takes
    part, so a missing one is checked against all the others. Returns the new
    ``(keys, source)`` (a node now lying on a segment splits it); ``ValueError``
    naming two segments that would cross."""
    if np.isin(keys, triangle_edge_keys(T)).all():
        return keys, source
    source = np.asarray(source, dtype=np.int64)
    pairs = segments_of(keys)
    try:
        S, src = insert_segments(P, T, N, pairs)
    except CrossingSegments as err:
        i, j = err.first, err.second
        raise CrossingSegments(
            f"segment {pairs[i].tolist()} (of given segment {source[i]}) would cross "
            f"segment {pairs[j].tolist()} (of given segment {source[j]})", i, j,
            (pairs[i].tolist(), pairs[j].tolist()) if j >= 0 else None) from None
    return S, source[src]


def _split(S, origin, a, b, v, i):
    """Replace the key of segment {a, b} by those of {a, v} and {v, b}."""
    keys = [int(segment_key(a, v)), int(segment_key(v, b))]
    for key in keys:
        origin.setdefault(key, i)
    S = S[S != segment_key(a, b)]
    return np.unique(np.concatenate([S, np.array(keys, dtype=np.int64)]))


def _make_edge(P, T, N, S, vt, a, b, i, crossing):
    """Flip the crossing edges away, then restore the constrained Delaunay property
    by Lawson flips from the triangles the flips touched (all, if too many)."""
    queue = np.ascontiguousarray(crossing)
    touched = np.empty(16 * queue.shape[0] + 64, dtype=np.int64)
    ntouch = _flip_until_edge(P, T, N, vt, a, b, queue, touched)
    if ntouch < 0:
        raise RuntimeError(f"segments[{i}] = {[a, b]}: the flips made no progress")
    if ntouch > touched.shape[0]:
        touched, ntouch = np.arange(T.shape[0], dtype=np.int64), T.shape[0]
    room = 16 * ntouch + 1024     # Lawson's stack: local first, everything if it runs out
    while True:
        stack = np.empty(ntouch + room, dtype=np.int64)
        stack[:ntouch] = touched[:ntouch]
        _, done = lawson(P, T, N, S, stack, ntouch, 10 * T.shape[0] + 100,
                         np.empty((0, 8), np.int64))
        if done:
            return
        touched, ntouch = np.arange(T.shape[0], dtype=np.int64), T.shape[0]
        room = 2 * T.shape[0] + 64


@njit(cache=True)
def _flood(T, N, S, label, seeds, first):
    """Label with ``first + s`` the triangles reached from ``seeds[s]`` without
    crossing a segment (triangles labelled already are kept)."""
    stack = np.empty(T.shape[0], dtype=np.int64)
    for s in range(seeds.shape[0]):
        t0 = seeds[s]
        if label[t0] >= 0:
            continue
        label[t0] = first + s
        top = 1
        stack[0] = t0
        while top:
            top -= 1
            t = stack[top]
            for k in range(3):
                u = N[t, k]
                if u >= 0 and label[u] < 0 and not is_segment(
                        S, T[t, (k + 1) % 3], T[t, (k + 2) % 3]):
                    label[u] = first + s
                    stack[top] = u
                    top += 1


def flood_regions(T, N, S, seeds) -> np.ndarray:
    """(nt,) label of each triangle: ``s`` for the region (bounded by segments and
    the hull) of the triangle ``seeds[s]``, -1 for triangles in none of them."""
    label = np.full(T.shape[0], -1, dtype=np.int64)
    _flood(T, N, S, label, np.asarray(seeds, dtype=np.int64), 0)
    return label
