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
from .merging import CLUSTER_FRACTION
from .quality import cross, min_angles
from .remap import child_values

__all__ = ["NodeInjection", "INJECT_MARGIN"]

#: a node is injected only where its spacing (square root of its share, a third of the
#: triangle it splits) would be at least this multiple of the spacing below which
#: merge_nodes removes a node (CLUSTER_FRACTION of the reference): injection and removal
#: then never undo each other's work within a step or the next
INJECT_MARGIN = 2.0


class NodeInjection:
    """Node injection for :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh` (which
    provides the state, the node areas, the flips with the remap and the segments)."""

    def inject_nodes(self, factor: float = 2.0) -> int:
        """Insert a node at the centroid of the largest triangle around every
        node whose Voronoi area (:meth:`node_areas`) exceeds ``factor``
        times its reference area (initially its first area; raised to its
        area after each insertion it triggered), skipping slivers (smallest
        angle below 15 degrees) and places where the new node would be crowded at
        once (:data:`INJECT_MARGIN`). Only local changes: the triangle is split in
        three (integration-point fields evaluated from its linear field, which
        conserves their integrals), then Lawson flips with the remap. Node
        fields of new nodes come from Sibson interpolation. Returns the number
        of nodes inserted."""
        if factor <= 1:
            raise ValueError(f"the injection factor must exceed 1, got {factor}")
        area = self.node_areas()
        grown = np.flatnonzero(area > factor * self._ref_area)
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
        ref = self._ref_area[T[best[grown]]].max(axis=1)
        ok = (score[best[grown]] > 0) & (share >= (INJECT_MARGIN * CLUSTER_FRACTION) ** 2 * ref)
        # nodes whose growth triggered an insertion (or could not) restart
        # their reference from the area they will have now
        grown_all = grown
        grown = grown[ok]
        if not grown.size:
            self._ref_area[grown_all] = area[grown_all]
            return 0
        targets = np.unique(best[grown])
        x_new = P[T[targets]].mean(axis=1)
        fields = {}
        if self.node_fields:
            Phi = sibson_coordinates(self.triangulation, x_new)
            fields = {k: Phi @ v.reshape(v.shape[0], -1) for k, v in self.node_fields.items()}
        self._split(targets, x_new)
        n_new = x_new.shape[0]
        for k, v in self.node_fields.items():
            self.node_fields[k] = np.concatenate([v, fields[k].reshape((n_new,) + v.shape[1:])])
        self._on_wall = np.concatenate([self._on_wall, np.zeros((n_new, 2), dtype=bool)])
        self.triangulation.make_delaunay(on_flips=self._on_flips)
        area = self.node_areas()
        self._ref_area = np.concatenate([self._ref_area, area[-n_new:]])
        self._ref_area[grown_all] = np.maximum(self._ref_area[grown_all], area[grown_all])
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
        twice the larger reference area: a wall node has half a cell), as
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
        h = np.sqrt(2.0 * np.maximum(self._ref_area[a], self._ref_area[b]))
        return self._split_pairs(H[same & (np.hypot(*(P[a] - P[b]).T) > np.sqrt(factor) * h)])

    def _split_pairs(self, pairs):
        """Split the edges ``pairs`` (k, 2) at their midpoints (a new node on a segment
        or a wall stays on it; node fields: the mean of the two ends), then flip with the
        remap; the new nodes' reference areas are their areas now."""
        if not pairs.size:
            return 0
        for a, b in pairs:
            self._split_segment(int(a), int(b))
        a, b = pairs[:, 0], pairs[:, 1]
        P = self.nodes
        for k, v in self.node_fields.items():
            self.node_fields[k] = np.concatenate([v, 0.5 * (v[a] + v[b])])
        same = self._on_wall[a] & self._on_wall[b] & (P[a] == P[b])
        self._on_wall = np.concatenate([self._on_wall, same])
        self.triangulation.make_delaunay(on_flips=self._on_flips)
        area = self.node_areas()
        self._ref_area = np.concatenate([self._ref_area, area[-pairs.shape[0]:]])
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
