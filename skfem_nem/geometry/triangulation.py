"""Two-dimensional Delaunay triangulation with adjacency.

The :class:`Triangulation` holds counter-clockwise triangles and their
edge-adjacency, and offers the local operations the natural element method is
built on: point location by walking, the conflict (Bowyer--Watson) cavity of a
point, Lawson edge flips and a Delaunay check.  All geometric decisions go
through the exact predicates of :mod:`skfem_nem.geometry.predicates`, so structured grids
(every quad co-circular), collinear runs on the hull and slivers are handled
consistently.

Conventions
-----------
``triangles[t] = (a, b, c)`` is counter-clockwise; ``neighbours[t, k]`` is the
triangle across the edge opposite vertex ``triangles[t, k]`` (that is, the edge
``(triangles[t, k+1], triangles[t, k+2])``, indices mod 3), or ``-1`` on the
convex hull. ``segment_keys`` lists the constrained edges (segments), which
flips never remove and cavities never cross (a constrained Delaunay
triangulation, :mod:`skfem_nem.geometry.constrained`); empty by default.
"""
from __future__ import annotations

import numpy as np

from .constrained import (check_segments, edge_keys, insert_segments, pair_keys,
                          recover_segments, segment_through, segments_of, sorted_segments,
                          split_key, triangle_edge_keys)
from .delaunay2d import (adjacency, circumcircle_table, count_non_delaunay, grow_cavity,
                         insert_vertex, lawson, locate_many, orientations)
from .predicates import incircle_sign
from .qhull_start import qhull_start
from .triangulation_edits import VertexEdits

__all__ = ["Triangulation", "validate_nodes", "unused_nodes"]


# ---------------------------------------------------------------------------
# input validation
# ---------------------------------------------------------------------------

def validate_nodes(nodes, dim: int = 2, name: str = "nodes") -> np.ndarray:
    """Check an (n, dim) array of node coordinates and return a float64 copy.

    Raises ``ValueError`` naming the offending node for NaN/inf coordinates,
    fewer than ``dim + 1`` nodes and duplicate nodes. The caller's array is
    never modified.
    """
    p = np.array(nodes, dtype=np.float64, copy=True, order="C")
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}), got {np.shape(nodes)}")
    bad = np.flatnonzero(~np.isfinite(p).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{name} contain {bad.size} non-finite coordinate row(s); first is "
            f"{name}[{bad[0]}] = {p[bad[0]].tolist()}")
    if p.shape[0] < dim + 1:
        raise ValueError(f"need at least {dim + 1} {name} in {dim}D, got {p.shape[0]}")
    order = np.lexsort(p.T[::-1])
    same = np.flatnonzero((p[order[1:]] == p[order[:-1]]).all(axis=1))
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        raise ValueError(
            f"{same.size} duplicate node(s) in {name}; first: {name}[{j}] coincides "
            f"with {name}[{i}] at {p[i].tolist()}")
    return p


def unused_nodes(n: int, cells) -> np.ndarray:
    """Indices of the nodes 0..n-1 that are a vertex of none of ``cells`` (k, d + 1):
    such a node would get no trial function (Qhull drops nearly coincident nodes)."""
    used = np.zeros(n, dtype=bool)
    used[np.asarray(cells).ravel()] = True
    return np.flatnonzero(~used)


# ---------------------------------------------------------------------------
# the class
# ---------------------------------------------------------------------------

class Triangulation(VertexEdits):
    """A 2D triangulation of a node set with adjacency, kept Delaunay.

    Parameters
    ----------
    nodes
        (n, 2) node coordinates. Copied; the caller's array is not modified.
    triangles
        Optional (nt, 3) triangles to start from (any valid triangulation of
        the nodes' convex hull). If omitted, the Delaunay triangulation is
        built with Qhull. Either way the result is checked with exact
        predicates and repaired by Lawson flips into a Delaunay one, unless
        ``make_delaunay=False``.
    segments
        Optional (k, 2) pairs of node indices that must be edges (material
        interfaces, the boundary of a non-convex domain): the result is then the
        constrained Delaunay triangulation. A node lying on a segment splits it;
        crossing segments raise ``ValueError`` naming both.

    Attributes
    ----------
    nodes : (n, 2) float64
    triangles : (nt, 3) int64, counter-clockwise
    neighbours : (nt, 3) int64, ``neighbours[t, k]`` across the edge opposite
        ``triangles[t, k]``; ``-1`` on the hull.

    Raises
    ------
    ValueError
        For non-finite coordinates, fewer than 3 nodes, duplicate nodes, all
        nodes collinear, or nodes that Qhull would drop (naming the node).

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import Triangulation
    >>> nodes = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> tri = Triangulation(nodes)
    >>> tri.npoints, tri.ntriangles, tri.is_delaunay()
    (5, 4, True)
    >>> (tri.locate([[0.5, 0.1], [2.0, 2.0]]) >= 0).tolist()   # inside, outside the hull
    [True, False]
    >>> tri.insert([[0.8, 0.7]]).tolist()                       # index of the new node
    [5]
    >>> tri.ntriangles, tri.is_delaunay()
    (6, True)
    """

    def __init__(self, nodes, triangles=None, make_delaunay: bool = True, segments=None):
        p = validate_nodes(nodes)
        segments = check_segments(segments if segments is not None else [], p.shape[0])
        self.nodes = p
        self.nodes.flags.writeable = False
        self.segment_keys = np.empty(0, dtype=np.int64)
        self.segment_source = np.empty(0, dtype=np.int64)
        if triangles is None:
            T, N = qhull_start(p)
        else:
            T = np.array(triangles, dtype=np.int64, copy=True, order="C")
            if T.ndim != 2 or T.shape[1] != 3:
                raise ValueError(f"triangles must have shape (nt, 3), got {np.shape(triangles)}")
            if T.size and (T.min() < 0 or T.max() >= p.shape[0]):
                t = int(np.flatnonzero((T < 0).any(1) | (T >= p.shape[0]).any(1))[0])
                raise ValueError(f"triangle {t} has a vertex index out of range: {T[t].tolist()}")
            orient = np.empty(T.shape[0])
            orientations(p, T, orient)
            zero = np.flatnonzero(orient == 0.0)
            if zero.size:
                raise ValueError(f"triangle {zero[0]} ({T[zero[0]].tolist()}) has zero area")
            neg = orient < 0
            T[neg] = T[neg][:, [0, 2, 1]]
            N = adjacency(T, p.shape[0])
        self.triangles = T
        self.neighbours = N
        self._changed()
        unused = unused_nodes(p.shape[0], T)
        if triangles is None and unused.size:
            self.make_delaunay()
            self._insert_nodes(unused)
        elif unused.size:
            i = int(unused[0])
            raise ValueError(
                f"node {i} at {p[i].tolist()} is not a vertex of any triangle "
                f"({unused.size} such node(s))")
        self.last_flips = 0
        if make_delaunay:
            self.last_flips = self.make_delaunay()
        if segments.size:
            self.segment_keys, self.segment_source = insert_segments(
                self.nodes, self.triangles, self.neighbours, segments)
            self._changed()

    # -- construction -------------------------------------------------------
    @classmethod
    def from_triangles(cls, nodes, triangles, make_delaunay: bool = True) -> "Triangulation":
        """Build from an existing triangulation of the nodes (see class docs)."""
        return cls(nodes, triangles=triangles, make_delaunay=make_delaunay)

    # -- basic properties ---------------------------------------------------
    @property
    def npoints(self) -> int:
        return self.nodes.shape[0]

    @property
    def ntriangles(self) -> int:
        return self.triangles.shape[0]

    @property
    def edges(self) -> np.ndarray:
        """(ne, 2) unique edges, each sorted (i < j), lexicographically ordered."""
        T, N = self.triangles, self.neighbours
        # each edge once: from the triangle with the larger index (a hull edge has the
        # neighbour -1), so a sort of the keys, not a unique of all three per triangle
        # (which took 0.2 s at 180,000 triangles)
        pairs = np.stack([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]], axis=1)
        own = N < np.arange(T.shape[0])[:, None]
        return segments_of(np.sort(pair_keys(pairs[own])))

    @property
    def segments(self) -> np.ndarray:
        """(k, 2) the constrained edges ``(i, j)``, i < j (empty if unconstrained);
        ``segment_source[k]`` is the index of the given segment that edge k is
        (a piece of)."""
        return segments_of(self.segment_keys)

    def segment_rows(self, pairs) -> np.ndarray:
        """(k,) the rows of :attr:`segments` of the node pairs ``pairs`` (k, 2), either
        order; -1 for a pair that is not a segment."""
        keys = pair_keys(pairs)
        if not self.segment_keys.size:
            return np.full(keys.size, -1, dtype=np.int64)
        rows = np.searchsorted(self.segment_keys, keys).clip(0, self.segment_keys.size - 1)
        return np.where(self.segment_keys[rows] == keys, rows, -1)

    def reorder_triangles(self, order) -> None:
        """Renumber the triangles in place: new triangle r is old ``order[r]``."""
        order = np.asarray(order, dtype=np.int64)
        if not np.array_equal(np.sort(order), np.arange(self.ntriangles)):
            raise ValueError("order must be a permutation of the triangle indices")
        inv = np.empty_like(order)
        inv[order] = np.arange(order.size)
        N = self.neighbours[order]
        self.triangles = np.ascontiguousarray(self.triangles[order])
        self.neighbours = np.ascontiguousarray(np.where(N >= 0, inv[np.maximum(N, 0)], -1))
        self._changed()

    @property
    def hull_edges(self) -> np.ndarray:
        """(nh, 2) convex-hull edges ``(a, b)``, counter-clockwise around the hull."""
        t, k = np.nonzero(self.neighbours < 0)
        T = self.triangles
        return np.stack([T[t, (k + 1) % 3], T[t, (k + 2) % 3]], axis=1)

    # -- predicates ----------------------------------------------------------
    def orientation(self) -> np.ndarray:
        """(nt,) exact-sign orientation determinants (twice the signed areas)."""
        out = np.empty(self.ntriangles)
        orientations(self.nodes, self.triangles, out)
        return out

    def incircle(self, t: int, x) -> float:
        """Exact-sign in-circle test of point x against triangle t (> 0 inside)."""
        a, b, c = self.nodes[self.triangles[t]]
        return float(incircle_sign(a[0], a[1], b[0], b[1], c[0], c[1], float(x[0]), float(x[1])))

    def _changed(self):
        """Drop the caches derived from the triangles (after any change)."""
        self._seed_grid = None
        self._circumcentres = None

    @property
    def circumcircles(self) -> np.ndarray:
        """(nt, 5) circumcentre of each triangle minus its first vertex, a
        bound on the error of that offset (``inf`` where it is not used as a
        filter), and the first vertex; see :attr:`circumcentre_offsets`."""
        if self._circumcentres is None:
            out = np.empty((self.ntriangles, 5))
            circumcircle_table(self.nodes, self.triangles, out)
            self._circumcentres = out
        return self._circumcentres

    @property
    def circumcentre_offsets(self) -> np.ndarray:
        """(nt, 2) circumcentre of each triangle minus its first vertex.

        Stored relative to the vertex (computed with the accurate
        :func:`~skfem_nem.geometry.predicates.orient2d`) so that the circumcentre
        relative to a nearby point x is ``(nodes[T[t, 0]] - x) + offset``
        without cancellation, however far the nodes are from the origin.
        (A view of the first two columns of :attr:`circumcircles`.)
        """
        return self.circumcircles[:, :2]

    # -- queries -------------------------------------------------------------
    def seed_grid(self):
        """A bucket grid of triangles used to start walks near a query."""
        if self._seed_grid is None:
            P, T = self.nodes, self.triangles
            cen = P[T].mean(axis=1)
            lo = P.min(axis=0)
            span = np.maximum(P.max(axis=0) - lo, 1e-300)
            nc = max(1, int(np.sqrt(T.shape[0] / 2.0)))
            ij = np.minimum((nc * (cen - lo) / span).astype(np.int64), nc - 1)
            grid = np.full(nc * nc, -1, dtype=np.int64)
            grid[ij[:, 0] * nc + ij[:, 1]] = np.arange(T.shape[0])
            # fill empty buckets from the nearest filled one along rows
            filled = np.flatnonzero(grid >= 0)
            pos = np.searchsorted(filled, np.arange(nc * nc)).clip(0, filled.size - 1)
            grid = grid[filled[pos]]
            self._seed_grid = (lo, span, nc, grid)
        return self._seed_grid

    def start_triangles(self, x: np.ndarray) -> np.ndarray:
        """(m,) triangles near the points x (m, 2), to start walks from."""
        lo, span, nc, grid = self.seed_grid()
        ij = np.clip(((x - lo) / span * nc).astype(np.int64), 0, nc - 1)
        return grid[ij[:, 0] * nc + ij[:, 1]]

    def locate(self, x) -> np.ndarray:
        """Triangles containing the points x, shape (m, 2) -> (m,) int64.

        A point on an edge or at a node gets one of the triangles that
        contain it; a point outside the convex hull gets -1.
        """
        q = np.atleast_2d(np.asarray(x, dtype=np.float64))
        start = self.start_triangles(q)
        out = np.empty(q.shape[0], dtype=np.int64)
        locate_many(self.nodes, self.triangles, self.neighbours, q, start, out)
        return out

    def cavity(self, x) -> np.ndarray:
        """Triangles whose circumcircle strictly contains the point x (2,) and that
        x sees (reached without crossing a segment).

        This is the Bowyer--Watson conflict region of x; its vertices are the
        natural neighbours of x. Empty if x is a node; raises ``ValueError``
        if x is outside the convex hull.
        """
        q = np.asarray(x, dtype=np.float64).reshape(2)
        t = int(self.locate(q[None])[0])
        if t < 0:
            raise ValueError(f"point {q.tolist()} is outside the convex hull")
        if np.any((self.nodes[self.triangles[t]] == q).all(axis=1)):
            return np.empty(0, dtype=np.int64)
        cap = 64
        while True:
            cav = np.empty(cap, dtype=np.int64)
            cnt = grow_cavity(self.nodes, self.triangles, self.neighbours, self.segment_keys,
                              q[0], q[1], t, cav, np.empty((cap, 3), np.int64),
                              np.empty(cap + 4, np.int64))
            if cnt >= 0:
                return np.sort(cav[:cnt])
            cap *= 4

    # -- insertion -------------------------------------------------------------
    def insert(self, x) -> np.ndarray:
        """Insert new nodes x (k, 2) inside the convex hull (Bowyer--Watson).

        Only triangles whose circumcircle contains a new node change. Returns
        the (k,) indices of the new nodes. Raises ``ValueError`` (leaving the
        triangulation unchanged) for non-finite points, points outside the
        hull and points that coincide with a node.
        """
        q = np.array(np.atleast_2d(x), dtype=np.float64, copy=True)
        if q.ndim != 2 or q.shape[1] != 2:
            raise ValueError(f"inserted points must have shape (k, 2), got {np.shape(x)}")
        bad = np.flatnonzero(~np.isfinite(q).all(axis=1))
        if bad.size:
            raise ValueError(f"inserted point {bad[0]} is not finite: {q[bad[0]].tolist()}")
        n0 = self.npoints
        old = (self.nodes, self.triangles, self.neighbours, self.segment_keys,
               self.segment_source)
        nodes = np.vstack([self.nodes, q])
        nodes.flags.writeable = False
        self.nodes = nodes
        try:
            self._insert_nodes(np.arange(n0, n0 + q.shape[0]))
        except ValueError:
            (self.nodes, self.triangles, self.neighbours, self.segment_keys,
             self.segment_source) = old
            self._changed()
            raise
        return np.arange(n0, n0 + q.shape[0])

    def _insert_nodes(self, idx):
        P = self.nodes
        nt = self.ntriangles
        T = np.empty((nt + 2 * len(idx), 3), dtype=np.int64)
        N = np.empty_like(T)
        T[:nt] = self.triangles
        N[:nt] = self.neighbours
        cap = 64
        starts = self.start_triangles(P[idx])
        for i, start in zip(idx, starts):
            i = int(i)
            # a node on a segment splits it: the cavity may cross that segment
            cut = segment_through(P, T[:nt], N[:nt], self.segment_keys, i, int(start))
            S = self.segment_keys if cut is None else self.segment_keys[self.segment_keys != cut]
            while True:
                cav = np.empty(cap, np.int64)
                cnb = np.empty((cap, 3), np.int64)
                rej = np.empty(cap + 4, np.int64)
                be = [np.empty(cap + 2, np.int64) for _ in range(5)]
                r = insert_vertex(P, T, N, S, nt, i, int(start), cav, cnb,
                                  rej, *be, np.array([nt, nt + 1], dtype=np.int64))
                if r != -3:
                    break
                cap *= 4
            if r == -1:
                raise ValueError(f"node {i} at {P[i].tolist()} lies outside the convex hull "
                                 f"and cannot be inserted")
            if r == -2:
                raise ValueError(f"node {i} at {P[i].tolist()} coincides with an existing node")
            if cut is not None:
                self.segment_keys, self.segment_source = split_key(
                    self.segment_keys, self.segment_source, cut, i)
            nt += r
        self.triangles = np.ascontiguousarray(T[:nt])
        self.neighbours = np.ascontiguousarray(N[:nt])
        self._changed()

    # -- mutation: the evolving mesh changes a triangulation only through these -----
    def move_nodes(self, x) -> None:
        """Give the nodes the positions x (n, 2), keeping the triangles (a Lagrangian
        step). The triangles may then fail the in-circle test (repair with
        :meth:`make_delaunay`) or invert (see :meth:`orientation`). Copied; read-only."""
        x = np.array(x, dtype=np.float64, copy=True, order="C")
        if x.shape != self.nodes.shape:
            raise ValueError(f"moved nodes must have shape {self.nodes.shape}, got {x.shape}")
        x.flags.writeable = False
        self.nodes = x
        self._changed()

    def snapshot(self) -> dict:
        """The whole state (nodes, triangles, neighbours), for :meth:`restore`."""
        return {"nodes": self.nodes, "triangles": self.triangles.copy(),
                "neighbours": self.neighbours.copy(), "segment_keys": self.segment_keys,
                "segment_source": self.segment_source}

    def restore(self, snap: dict) -> None:
        """Return exactly to a :meth:`snapshot` (the nodes are read-only, so shared)."""
        self.nodes = snap["nodes"]
        self.triangles = snap["triangles"].copy()
        self.neighbours = snap["neighbours"].copy()
        self.segment_keys = snap.get("segment_keys", np.empty(0, dtype=np.int64))
        self.segment_source = snap.get("segment_source", np.empty(0, dtype=np.int64))
        self._changed()

    @classmethod
    def from_arrays(cls, nodes, triangles, neighbours, segments=None,
                    segment_source=None) -> "Triangulation":
        """A triangulation from stored arrays (a checkpoint), trusted as they are: only
        their shapes and index ranges are checked, nothing is flipped. ``segments``:
        its constrained edges (k, 2), which must be edges; ``segment_source``: their
        :attr:`segment_source` in the order of :attr:`segments` (default 0..k-1)."""
        p = np.array(nodes, dtype=np.float64, copy=True, order="C")
        T = np.ascontiguousarray(triangles, dtype=np.int64).copy()
        N = np.ascontiguousarray(neighbours, dtype=np.int64).copy()
        if p.ndim != 2 or p.shape[1] != 2 or T.ndim != 2 or T.shape[1] != 3 or N.shape != T.shape:
            raise ValueError(f"stored triangulation has inconsistent shapes: nodes {p.shape}, "
                             f"triangles {T.shape}, neighbours {N.shape}")
        if T.size and (T.min() < 0 or T.max() >= p.shape[0] or N.max() >= T.shape[0]):
            raise ValueError("stored triangulation has indices out of range")
        self = cls.__new__(cls)
        p.flags.writeable = False
        self.nodes, self.triangles, self.neighbours = p, T, N
        self.segment_keys = edge_keys(T, segments, p.shape[0])
        self.segment_source = np.arange(self.segment_keys.size)
        if segment_source is not None:
            src = np.asarray(segment_source, dtype=np.int64).reshape(-1)
            if src.size != self.segment_keys.size:
                raise ValueError(f"{src.size} segment sources for {self.segment_keys.size} "
                                 f"segments")
            self.segment_source = src.copy()
        self.last_flips = 0
        self._changed()
        return self

    def missing_segments(self) -> np.ndarray:
        """(k, 2) the segments that are not edges of the triangles (none, unless a node
        that ends segments is out of the triangulation: see :meth:`recover_segments`)."""
        keys = self.segment_keys
        return segments_of(keys[~np.isin(keys, triangle_edge_keys(self.triangles))])

    def set_segments(self, segments, source) -> None:
        """Replace the segments by the (k, 2) node pairs ``segments`` from the given
        segments ``source`` (k,), without changing the triangles (make them edges with
        :meth:`recover_segments`)."""
        self.segment_keys, self.segment_source = sorted_segments(segments, source)

    def recover_segments(self) -> None:
        """Make every segment an edge again by exact flips (Sloan's, as when segments are
        inserted), then restore the constrained Delaunay property around them: after
        :meth:`remove_vertex` and :meth:`reinsert_vertex` of a node that ends segments.
        ``ValueError`` naming two segments that would cross (the triangulation is then
        partly flipped: restore a :meth:`snapshot`)."""
        self.segment_keys, self.segment_source = recover_segments(
            self.nodes, self.triangles, self.neighbours, self.segment_keys,
            self.segment_source)
        self._changed()

    # -- Delaunay maintenance -------------------------------------------------
    def make_delaunay(self, triangles=None, max_flips: int | None = None,
                      on_flips=None) -> int:
        """Lawson flips until every interior edge passes the in-circle test.

        Parameters
        ----------
        triangles
            Optional indices of the triangles to start checking from (after a
            local change); all triangles by default.
        max_flips
            Safety cap; default ``10 * nt + 100``.
        on_flips
            Optional callback ``on_flips(log)`` receiving, in order, batches of
            flips as an (k, 8) int array of rows ``(t, u, k, l, a, b, c, d)``:
            triangle t = (a, b, c) (a at position k) was flipped across edge
            b-c with u = (d, c, b) (d at position l); afterwards t holds
            ``(a, b, d)`` and u ``(a, d, c)``. Used to remap data stored per
            triangle.

        Returns the number of flips performed.
        """
        nt = self.ntriangles
        start = (np.arange(nt, dtype=np.int64) if triangles is None
                 else np.unique(np.asarray(triangles, dtype=np.int64)))
        if max_flips is None:
            max_flips = 10 * nt + 100
        total = 0
        while True:
            stack = np.empty(start.size + 2 * min(max_flips, nt // 4 + 1024), dtype=np.int64)
            stack[:start.size] = start
            log = np.empty((min(max_flips, nt // 4 + 1024) if on_flips else 0, 8), np.int64)
            flips, done = lawson(self.nodes, self.triangles, self.neighbours,
                                 self.segment_keys, stack,
                                 start.size, max_flips - total, log)
            total += flips
            if flips:
                self._changed()
                if on_flips is not None:
                    on_flips(log[:flips])
            if done:
                return int(total)
            if total >= max_flips:
                raise RuntimeError(f"Lawson flips did not terminate within {max_flips} flips")
            start = np.arange(nt, dtype=np.int64)

    def is_delaunay(self) -> bool:
        """True if every interior edge passes the exact in-circle test and all
        triangles are strictly counter-clockwise."""
        if np.any(self.orientation() <= 0.0):
            return False
        return self.non_delaunay_edges() == 0

    def non_delaunay_edges(self) -> int:
        """Number of interior edges, segments excepted, that fail the exact in-circle
        test."""
        return int(count_non_delaunay(self.nodes, self.triangles, self.neighbours,
                                      self.segment_keys))

    def __repr__(self) -> str:
        return f"Triangulation({self.npoints} nodes, {self.ntriangles} triangles)"
