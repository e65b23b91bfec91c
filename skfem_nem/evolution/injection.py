"""Node injection for the Lagrangian mesh: where the flow spreads nodes apart, add nodes.

The mixin :class:`NodeInjection` of :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh`
refines where the mesh thins out, with only local changes (a triangle split in three, an
edge in two, then Lawson flips with the remap) and the integrals of the integration-point
fields kept:

* :meth:`NodeInjection.inject_nodes`: a node whose Voronoi area grew past ``factor`` times
  its reference gets a node at the centroid of its largest non-sliver triangle;
* :meth:`NodeInjection.split_segments`: a segment stretched past ``sqrt(factor)`` times its
  reference length is split at its midpoint (both halves stay segments);
* :meth:`NodeInjection.split_walls`: the same for an edge on a wall of the box, where the
  node areas do not show the stretching (nodes pressed towards the wall fill the gap).

:mod:`~skfem_nem.evolution.merging` does the opposite where the flow converges; the two
rules are kept apart by a margin (:data:`INJECT_MARGIN`) so that neither undoes the other.
"""
from __future__ import annotations

import numpy as np

from ..coordinates import sibson_coordinates
from ..geometry.constrained import pair_keys
from .merging import CLUSTER_FRACTION
from .quality import cross, min_angles
from .remap import child_values
from .spacing import EDGE_FACTOR, SPLIT_CLEARANCE

__all__ = ["NodeInjection", "INJECT_MARGIN", "SPLIT_PASSES"]

#: a node is injected only where its spacing (square root of its share, a third of the
#: triangle it splits) would be at least this multiple of the spacing below which
#: merge_nodes removes a node (CLUSTER_FRACTION of the reference): injection and removal
#: then never undo each other's work within a step or the next
INJECT_MARGIN = 2.0
#: at most this many passes of the quality bound's edge splits per step: each pass halves
#: the edges it splits, so an edge up to 2^8 bounds long is back within the bound
SPLIT_PASSES = 8


class NodeInjection:
    """Node injection for :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh` (which
    provides the state, the node areas, the flips with the remap and the segments)."""

    def inject_nodes(self, factor: float = 2.0) -> int:
        """Insert a node at the centroid of the largest triangle around every
        node whose Voronoi area (:meth:`node_areas`) exceeds ``factor``
        times its target area (:meth:`reference_areas`: fixed for the run, never
        raised by an injection), skipping slivers (smallest angle below 15 degrees)
        and places where the new node would be crowded at once
        (:data:`INJECT_MARGIN`). Only local changes: the triangle is split in
        three (integration-point fields evaluated from its linear field, which
        conserves their integrals), then Lawson flips with the remap. Node
        fields and target spacings of new nodes come from Sibson interpolation
        (constrained by the segments: never across an outline or interface).
        Returns the number of nodes inserted."""
        if factor <= 1:
            raise ValueError(f"the injection factor must exceed 1, got {factor}")
        area = self.node_areas()
        ref = self.reference_areas()
        grown = np.flatnonzero(area > factor * ref)
        if not grown.size:
            return 0
        P, T = self.nodes, self.triangles
        tri_area = 0.5 * np.abs(cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]))
        ang = np.empty(T.shape[0])
        min_angles(P, T, ang)
        # the largest incident triangle that is not a sliver (a centroid in a
        # sliver along a wall would stack nodes ever closer to the wall)
        score = np.where(ang > np.radians(15.0), tri_area, -1.0)
        best = np.full(P.shape[0], -1)
        order = np.argsort(score)
        for k in range(3):
            best[T[order, k]] = order  # the best incident triangle wins
        # skip where the new node would be crowded at once (a thin gap where the grown
        # node's area lies in slivers): merge_nodes would take it out again the same step
        share = tri_area[best[grown]] / 3.0
        near = ref[T[best[grown]]].max(axis=1)
        ok = (score[best[grown]] > 0) & (share >= (INJECT_MARGIN * CLUSTER_FRACTION) ** 2 * near)
        grown = grown[ok]
        if not grown.size:
            return 0
        targets = np.unique(best[grown])
        x_new = P[T[targets]].mean(axis=1)
        return self._insert_batch(x_new, lambda: self._split(targets, x_new))

    def _insert_batch(self, x_new, insert):
        """Insert the nodes x_new (k, 2) by ``insert()`` (which appends them to the
        triangulation), with node fields and target spacings interpolated where they
        land (Sibson, before the insertion: constrained by the segments), then Lawson
        flips with the remap. Returns k."""
        n_new = x_new.shape[0]
        Phi = sibson_coordinates(self.triangulation, x_new)
        fields = {k: Phi @ v.reshape(v.shape[0], -1) for k, v in self.node_fields.items()}
        target = self._targets_at(x_new, Phi)
        insert()
        for k, v in self.node_fields.items():
            self.node_fields[k] = np.concatenate([v, fields[k].reshape((n_new,) + v.shape[1:])])
        self._target = np.concatenate([self._target, target])
        self._on_wall = np.concatenate([self._on_wall, np.zeros((n_new, 2), dtype=bool)])
        self.triangulation.make_delaunay(on_flips=self._on_flips)
        self._invalidate()
        return n_new

    def _split(self, targets, x_new):
        """Split the triangles ``targets`` into three each at the interior points
        ``x_new`` (appended as nodes); the ip fields of the children are the parent's
        linear field at their points. Every array grows once for the batch (a copy of
        the fields per new node made injection cost nodes times injections)."""
        tri = self.triangulation
        nt, k = tri.ntriangles, targets.shape[0]
        parents = tri.nodes[tri.triangles[targets]]
        tri.split_triangles(targets, x_new)
        new_rows = nt + np.arange(2 * k).reshape(k, 2)
        children = np.c_[targets, new_rows]                  # (k, 3): t, nt + 2m, + 1
        self._touched.append(children.ravel())
        Y = tri.nodes[tri.triangles[children]]               # (k, 3 children, 3, 2)
        for name, F in self.ip_fields.items():
            flat = F.reshape(F.shape[0], 3, -1)
            flat = np.concatenate([flat, np.empty((2 * k,) + flat.shape[1:])])
            for m in range(k):
                flat[children[m]] = child_values(parents[m], flat[targets[m]], Y[m])
            self.ip_fields[name] = flat.reshape((flat.shape[0],) + F.shape[1:])

    def split_segments(self, factor: float = 2.0) -> int:
        """Insert a node at the midpoint of every segment longer than ``sqrt(factor)``
        times the initial length of the segment it comes from (the length scale of the
        node-area ``factor`` of :meth:`inject_nodes`); both halves become segments. The
        two triangles at the segment are split in two each (integration-point values
        from their linear fields), then Lawson flips with the remap. Node fields of a
        new node: the mean of the segment's two nodes (natural-neighbour functions are
        linear along a segment). Returns the number of nodes inserted."""
        if factor <= 1:
            raise ValueError(f"the injection factor must exceed 1, got {factor}")
        tri = self.triangulation
        seg = tri.segments
        if not seg.size:
            return 0
        P = self.nodes
        length = np.hypot(*(P[seg[:, 0]] - P[seg[:, 1]]).T)
        return self._split_pairs(seg[length > np.sqrt(factor)
                                     * self._segment_ref[tri.segment_source]])

    def split_walls(self, factor: float = 2.0) -> int:
        """Insert a node at the midpoint of every edge on a wall of the box longer than
        ``sqrt(factor)`` times the reference spacing of its nodes (the square root of
        twice the larger target area: a wall node has half a cell), as
        :meth:`split_segments` does for segments: where the flow spreads nodes apart
        along a wall, the node areas do not show it (nodes pressed towards the wall fill
        the gap), and the new nodes go on the wall, not next to it. Returns the number
        of nodes inserted."""
        if factor <= 1:
            raise ValueError(f"the injection factor must exceed 1, got {factor}")
        H = self.triangulation.hull_edges
        P, W = self.nodes, self._on_wall
        a, b = H[:, 0], H[:, 1]
        same = (W[a] & W[b] & (P[a] == P[b])).any(axis=1)
        ref = self.reference_areas()
        h = np.sqrt(2.0 * np.maximum(ref[a], ref[b]))
        return self._split_pairs(H[same & (np.hypot(*(P[a] - P[b]).T) > np.sqrt(factor) * h)])

    def split_long_edges(self, factor: float = EDGE_FACTOR, passes: int = SPLIT_PASSES) -> int:
        """The quality bound: split every edge longer than ``factor`` times the larger
        target spacing of its two nodes at its midpoint (inside, on the hull and on
        segments: a new node on a wall or a segment stays on it), the longest relative
        to its target first, one edge per triangle and pass, at most ``passes`` passes
        (each halves the edges it splits). An edge whose midpoint would come closer than
        :data:`~.spacing.SPLIT_CLEARANCE` target spacings to a node opposite it is left:
        across a flat triangle that node resolves it. Node fields and target spacings of
        new nodes inside come from Sibson interpolation (constrained by the segments),
        on the hull and on segments from the two ends. Returns the number of nodes
        inserted."""
        if not factor > 1:
            raise ValueError(f"the edge factor must exceed 1, got {factor}")
        total = 0
        for _ in range(passes):
            pairs = self._long_edges(factor)
            if not pairs.size:
                break
            total += self._split_pairs(pairs, inner=self._inner(pairs))
        return total

    def _inner(self, pairs):
        """(k,) True for the edges ``pairs`` that are neither on the hull nor segments."""
        tri = self.triangulation
        keys = pair_keys(pairs)
        border = np.r_[pair_keys(tri.hull_edges), tri.segment_keys]
        return ~np.isin(keys, border)

    def _long_edges(self, factor):
        """The edges to split in one pass of :meth:`split_long_edges`, (k, 2)."""
        tri = self.triangulation
        P, T, h = self.nodes, self.triangles, self._target
        a, b = T, np.roll(T, -1, axis=1)            # edge k of t: T[t, k] -> T[t, k + 1]
        length = np.hypot(*(P[a] - P[b]).transpose(2, 0, 1))
        ref = np.maximum(h[a], h[b])
        ratio = length / ref
        # the node opposite edge k is T[t, k + 2]: clearance from the midpoint
        mid = 0.5 * (P[a] + P[b])
        clear = np.hypot(*(mid - P[np.roll(T, -2, axis=1)]).transpose(2, 0, 1)) \
            >= SPLIT_CLEARANCE * ref
        # an edge is split where it is long and clear on both sides
        keys = pair_keys(np.c_[a.ravel(), b.ravel()])
        long_ = (ratio > factor).ravel()
        if not long_.any():
            return np.zeros((0, 2), dtype=np.int64)
        blocked = np.unique(keys[long_ & ~clear.ravel()])
        cand = np.flatnonzero(long_ & clear.ravel() & ~np.isin(keys, blocked))
        cand = cand[np.argsort(-ratio.ravel()[cand], kind="stable")]
        used = np.zeros(tri.ntriangles, dtype=bool)
        done = set()
        pick = []
        # the neighbour across edge k of t is N[t, (k + 2) % 3] (opposite vertex k + 2)
        across = tri.neighbours[:, [2, 0, 1]].ravel()
        for f in cand.tolist():
            t, other = f // 3, across[f]
            if keys[f] in done or used[t] or (other >= 0 and used[other]):
                continue
            used[t] = True
            if other >= 0:
                used[other] = True
            done.add(keys[f])
            pick.append((a.ravel()[f], b.ravel()[f]))
        return np.array(pick, dtype=np.int64).reshape(-1, 2)

    def _split_pairs(self, pairs, inner=None):
        """Split the edges ``pairs`` (k, 2) at their midpoints (a new node on a segment
        or a wall stays on it; node fields and target spacing: the mean of the two ends,
        or where ``inner`` (k,) the natural-neighbour interpolant there), then flip with
        the remap."""
        if not pairs.size:
            return 0
        P = self.nodes
        a, b = pairs[:, 0], pairs[:, 1]
        mid = 0.5 * (P[a] + P[b])
        inner = np.zeros(len(pairs), dtype=bool) if inner is None else inner
        Phi = sibson_coordinates(self.triangulation, mid[inner]) if inner.any() else None
        fields = {}
        for k, v in self.node_fields.items():
            f = 0.5 * (v[a] + v[b])
            if Phi is not None:
                f[inner] = (Phi @ v.reshape(v.shape[0], -1)).reshape((-1,) + v.shape[1:])
            fields[k] = f
        if self._spacing_fn is not None:
            target = self._targets_at(mid)
        else:
            target = 0.5 * (self._target[a] + self._target[b])
            if Phi is not None:
                target[inner] = Phi @ self._target
        for i, j in pairs:
            self._split_segment(int(i), int(j))
        for k, v in self.node_fields.items():
            self.node_fields[k] = np.concatenate([v, fields[k]])
        same = self._on_wall[a] & self._on_wall[b] & (P[a] == P[b])
        self._on_wall = np.concatenate([self._on_wall, same])
        self._target = np.concatenate([self._target, target])
        self.triangulation.make_delaunay(on_flips=self._on_flips)
        self._invalidate()
        return int(pairs.shape[0])

    def _split_segment(self, a, b):
        """Split the edge a-b (a segment, a wall edge) at its midpoint, with the ip fields
        of its triangles."""
        T = self.triangles
        t = int(np.flatnonzero((T == a).any(axis=1) & (T == b).any(axis=1))[0])
        k = int(np.flatnonzero((T[t] != a) & (T[t] != b))[0])
        self._split_edge(t, k, 0.5 * (self.nodes[a] + self.nodes[b]))

    def _split_edge(self, t, k, x):
        """Split the edge opposite vertex k of triangle t at its point x, with the ip
        fields of its one or two triangles (their linear fields at the children's points)."""
        tri = self.triangulation
        T, nt = tri.triangles, tri.ntriangles
        u = int(tri.neighbours[t, k])
        parents = [(t, T[t].copy(), [t, nt])] + ([(u, T[u].copy(), [u, nt + 1])] if u >= 0
                                                  else [])
        tri.split_edge(t, k, x)
        rows = [t, nt] + ([u, nt + 1] if u >= 0 else [])
        self._touched.append(np.array(rows, dtype=np.int64))
        for name, F in self.ip_fields.items():
            flat = F.reshape(F.shape[0], 3, -1)
            flat = np.concatenate([flat, np.zeros((tri.ntriangles - nt,) + flat.shape[1:])])
            for p, verts, children in parents:
                flat[children] = child_values(tri.nodes[verts], flat[p],
                                              tri.nodes[tri.triangles[children]])
            self.ip_fields[name] = flat.reshape((flat.shape[0],) + F.shape[1:])
