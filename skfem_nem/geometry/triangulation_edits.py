"""Vertex edits of a 2D :class:`~skfem_nem.geometry.triangulation.Triangulation`: the star
or fan of a node, a node taken out (its polygon refilled with Delaunay ears) and put back,
and a triangle or an edge split by a new node.

Why a module of its own: these are the local edits the evolving mesh makes between flips
(removal and merging of crowded nodes, relocation, injection, segment splits), a concept
apart from building, locating and flipping. :class:`VertexEdits` is mixed into
:class:`~skfem_nem.geometry.triangulation.Triangulation`, whose arrays (``nodes``,
``triangles``, ``neighbours``, segments) it edits in place.
"""
from __future__ import annotations

import numpy as np

from .constrained import split_key
from .delaunay2d import insert_vertex, segment_key, split_in_three
from .predicates import orient2d
from .stars import delaunay_ears, delete_rows, fan_of, link_star, star_of

__all__ = ["VertexEdits"]


class VertexEdits:
    """Star, fan, removal, re-insertion and splits of :class:`Triangulation` nodes."""

    def star(self, v: int) -> np.ndarray:
        """The triangles around the interior node v, counter-clockwise (``ValueError``
        if v is on the hull: its star is not closed; see :meth:`fan`)."""
        star, closed = self._around(v)
        if not closed:
            raise ValueError(f"node {v} is on the hull: its star is not closed")
        return star

    def fan(self, v: int) -> np.ndarray:
        """The triangles around the hull node v, counter-clockwise from the hull edge
        before v to the one after it."""
        return fan_of(self.triangles, self.neighbours, v, self._first_with(v))

    def _first_with(self, v: int) -> int:
        """A triangle with vertex v, from a hint per vertex checked on use and rebuilt
        when stale: removing vertices one by one costs no scan of the mesh each."""
        hint = getattr(self, "_hint", None)
        if hint is not None and v < hint.size:
            t = hint[v]
            if 0 <= t < self.ntriangles and (self.triangles[t] == v).any():
                return int(t)
        T = self.triangles
        hint = np.full(self.npoints, -1, dtype=np.int64)
        hint[T.ravel()[::-1]] = np.repeat(np.arange(T.shape[0]), 3)[::-1]
        self._hint = hint
        if v >= hint.size or hint[v] < 0:
            raise ValueError(f"node {v} is in no triangle")
        return int(hint[v])

    def _around(self, v: int):
        """``(triangles, closed)``: v's star, from its lowest-numbered triangle (the
        same whichever triangle the walk starts from), or its fan if v is on the hull."""
        t0 = self._first_with(v)
        star, closed = star_of(self.triangles, self.neighbours, v, t0)
        if closed:
            return np.roll(star, -int(np.argmin(star))), True
        return fan_of(self.triangles, self.neighbours, v, t0), False

    def _straight(self, v: int, fan) -> bool:
        """Whether the hull node v lies exactly between the two ends of its ``fan``."""
        T, P = self.triangles, self.nodes
        a = int(T[fan[0], (np.flatnonzero(T[fan[0]] == v)[0] + 1) % 3])
        b = int(T[fan[-1], (np.flatnonzero(T[fan[-1]] == v)[0] + 2) % 3])
        return orient2d(*P[a], *P[v], *P[b]) == 0 and np.dot(P[a] - P[v], P[b] - P[v]) < 0

    def removable(self, v: int) -> bool:
        """Whether :meth:`remove_vertex` can take node v out: an interior node, or a
        hull node exactly between its two hull neighbours on a straight line (a wall
        node that is not a corner), so that the hull stays the same."""
        tris, closed = self._around(v)
        return bool(closed or self._straight(v, tris))

    def remove_vertex(self, v: int, star=None):
        """Take node v out of the triangulation (it stays in :attr:`nodes`, in no
        triangle) and fill the polygon its triangles leave with Delaunay triangles
        (:mod:`~skfem_nem.geometry.stars`). v is interior, or on the hull exactly
        between its two hull neighbours (:meth:`removable`; ``ValueError`` otherwise).

        ``star``: :meth:`star` (or :meth:`fan`) of v if the caller has it already.
        Returns ``(slots, moves)``: the triangles that now cover the old star, and the
        row moves ``(src, dst)`` made, in order, to close the gaps of the triangles
        that disappear; apply the same moves to data stored per triangle, then cut it
        to :attr:`ntriangles` rows.
        """
        star = self._around(v)[0] if star is None else star
        T, N = self.triangles, self.neighbours
        at = [int(np.flatnonzero(T[t] == v)[0]) for t in star]
        link = [int(T[t, (j + 1) % 3]) for t, j in zip(star, at)]
        outer = [int(N[t, j]) for t, j in zip(star, at)]
        if N[star[-1], (at[-1] + 1) % 3] < 0:  # a fan: its last node, the hull edge back
            if not self._straight(v, star):
                raise ValueError(f"node {v} is a corner of the hull: it cannot be removed")
            link.append(int(T[star[-1], (at[-1] + 2) % 3]))
            outer.append(-1)
        slots = star[:len(link) - 2]
        for s_, tri_v in zip(slots, delaunay_ears(self.nodes, link, v)):
            T[s_] = tri_v
        link_star(T, N, slots, link, outer)
        dead = sorted(star[len(link) - 2:].tolist(), reverse=True)
        self.triangles, self.neighbours, moves = delete_rows(T, N, dead)
        final = slots.copy()
        for src, dst in moves:
            final[final == src] = dst
        self._changed()
        return final, moves

    def reinsert_vertex(self, v: int, cavity=None):
        """Put node v (in :attr:`nodes` but in no triangle, see :meth:`remove_vertex`)
        back by Bowyer--Watson insertion at its present position (``cavity``: its
        :meth:`cavity` if the caller has it already). Returns ``(cavity, new)``: the
        old triangles it replaced (their rows are reused) and the rows appended."""
        x = self.nodes[v]
        cav = self.cavity(x) if cavity is None else cavity
        nt = self.ntriangles
        T = np.vstack([self.triangles, np.zeros((2, 3), np.int64)])
        N = np.vstack([self.neighbours, np.zeros((2, 3), np.int64)])
        cap = max(64, 4 * cav.size)
        be = [np.empty(cap + 2, np.int64) for _ in range(5)]
        r = insert_vertex(self.nodes, T, N, self.segment_keys, nt, v, int(cav[0]),
                          np.empty(cap, np.int64),
                          np.empty((cap, 3), np.int64), np.empty(cap + 4, np.int64), *be,
                          np.array([nt, nt + 1], dtype=np.int64))
        if r < 0:
            raise ValueError(f"node {v} could not be re-inserted at {x.tolist()} (code {r})")
        self.triangles = np.ascontiguousarray(T[:nt + r])
        self.neighbours = np.ascontiguousarray(N[:nt + r])
        self._changed()
        return cav, np.arange(nt, nt + r)

    def split_triangle(self, t: int, x) -> int:
        """Append the node x (strictly inside triangle t) and split t in three:
        t becomes ``(i, b, c)``, and rows ``nt`` and ``nt + 1`` are appended as
        ``(i, c, a)`` and ``(i, a, b)`` for t = (a, b, c). Returns the new node i.
        Not Delaunay-repaired: call :meth:`make_delaunay` after a batch."""
        return int(self.split_triangles([t], np.asarray(x, dtype=np.float64)[None])[0])

    def split_triangles(self, ts, xs) -> np.ndarray:
        """:meth:`split_triangle` of the distinct triangles ``ts`` at the points ``xs``
        (k, 2) one after the other, the arrays grown once (triangle ``ts[m]`` gets node
        ``n + m`` and rows ``nt + 2m``, ``nt + 2m + 1``). Returns the new nodes."""
        ts = np.asarray(ts, dtype=np.int64).reshape(-1)
        xs = np.asarray(xs, dtype=np.float64).reshape(-1, 2)
        n, nt, k = self.npoints, self.ntriangles, ts.shape[0]
        if np.unique(ts).size != k or xs.shape[0] != k:
            raise ValueError(f"split_triangles needs distinct triangles and one point each, got "
                             f"{k} ({np.unique(ts).size} distinct) and {xs.shape[0]} point(s)")
        T = np.vstack([self.triangles, np.empty((2 * k, 3), dtype=self.triangles.dtype)])
        N = np.vstack([self.neighbours, np.empty((2 * k, 3), dtype=self.neighbours.dtype)])
        split_in_three(T, N, ts, n, nt)
        P = np.vstack([self.nodes, xs])
        P.flags.writeable = False
        self.nodes, self.triangles, self.neighbours = P, T, N
        self._changed()
        return np.arange(n, n + k)

    def split_edge(self, t: int, k: int, x) -> int:
        """Append the node x (strictly inside the edge b-c opposite vertex k of triangle
        t = (a, b, c)) and split the edge's triangles in two: t becomes ``(a, b, i)``
        and row ``nt`` is appended as ``(a, i, c)``; the neighbour u = (d, c, b), if
        any, becomes ``(d, i, b)`` and row ``nt + 1`` ``(d, c, i)``. A segment b-c is
        replaced by the segments b-i and i-c (same :attr:`segment_source`). Returns i.
        Not Delaunay-repaired: call :meth:`make_delaunay` after a batch."""
        T, N = self.triangles, self.neighbours
        nt = T.shape[0]
        i = self.npoints
        a, b, c = (int(T[t, (k + j) % 3]) for j in range(3))
        u, nca, nab = (int(N[t, (k + j) % 3]) for j in range(3))
        rows_t, rows_n = [[a, i, c]], [[-1 if u < 0 else nt + 1, nca, t]]
        T[t], N[t] = (a, b, i), (u, nt, nab)
        if u >= 0:
            ll = int(np.flatnonzero(N[u] == t)[0])
            d, nbd, ndc = int(T[u, ll]), int(N[u, (ll + 1) % 3]), int(N[u, (ll + 2) % 3])
            rows_t.append([d, c, i])
            rows_n.append([nt, u, ndc])
            T[u], N[u] = (d, i, b), (t, nbd, nt + 1)
            if ndc >= 0:
                N[ndc][N[ndc] == u] = nt + 1
        if nca >= 0:
            N[nca][N[nca] == t] = nt
        P = np.vstack([self.nodes, np.asarray(x, dtype=np.float64)[None]])
        P.flags.writeable = False
        self.nodes = P
        self.triangles, self.neighbours = np.vstack([T, rows_t]), np.vstack([N, rows_n])
        key = int(segment_key(b, c))
        if np.isin(key, self.segment_keys):
            self.segment_keys, self.segment_source = split_key(
                self.segment_keys, self.segment_source, key, i)
        self._changed()
        return i
