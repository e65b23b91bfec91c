"""Node removal and merging for the Lagrangian mesh: where the flow converges, nodes crowd.

Injection adds nodes where the mesh thins out; where the flow converges (a stagnation point,
the tip of a horn drawn out of a body) nodes come ever closer, and with them the time step
that a CFL condition on the node spacing allows, and an outline folds onto itself. The
mixin :class:`NodeRemoval` of :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh`
takes nodes out for good:

* :meth:`NodeRemoval.remove_nodes` removes interior nodes: each vertex is taken out of the
  triangulation, its star refilled with Delaunay triangles, the integration-point fields
  of the refilled star are the L2 projection of the old piecewise linear fields onto
  linear fields per new triangle (exact intersections of old and new triangles, so the
  integrals of every component are conserved to round-off and linear fields are kept);
  a node that ends exactly two segments (a, v), (v, b) has them merged into (a, b) if no
  other node lies in or on the triangle (a, v, b) (then a-b crosses no segment and a
  polygon stays simple), and every per-node array is compacted (indices stay 0..n-1).
* :meth:`NodeRemoval.merge_nodes` is the policy ``advance(..., merge=True)`` runs after
  injection: crowded nodes and folds of segment polylines are removed.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..geometry.constrained import pair_keys
from ..geometry.delaunay2d import is_segment
from ..geometry.predicates import orient2d
from .quality import area_shares

__all__ = ["NodeRemoval", "conservative_fill", "CLUSTER_FRACTION", "FOLD_ANGLE",
           "WALL_GAP_FRACTION", "PAIR_GAP_FRACTION"]

#: a node whose spacing (square root of its share of the triangle areas) fell below this
#: fraction of its reference spacing (the square root of the largest target area, the
#: one injection compares with, of the node and its neighbours: evolution.spacing) is
#: removed. Injection adds a node where an area doubled past its target (spacing x 1.4);
#: nodes are removed only where the flow has
#: squeezed them 5-fold in length (25-fold in area), far from the injection threshold, so
#: the two rules never undo each other's work, while the clusters that set the time step
#: (spacing a hundredth of the reference) go. A wall node whose neighbour on the wall came
#: closer than this fraction of its reference spacing goes too: where a strained flow
#: brings two wall nodes together, their areas need not shrink. The same fraction of a
#: segment's reference length marks a segment node whose two segments were both squeezed
#: short.
CLUSTER_FRACTION = 0.2
#: an outline (segment polyline) node where its two segments meet at an angle below this
#: (degrees) is a fold about to close: merging its segments blunts the fold before the
#: outline can pass through itself within a step.
FOLD_ANGLE = 20.0
#: an interior node closer to a wall of the box than this fraction of its reference spacing
#: is removed too: a node pressed towards a wall is stopped short of it step after step
#: and its triangles with the wall flatten to nothing (angles of 1e-18 degrees) while its
#: share of the areas stays; a fraction well below CLUSTER_FRACTION leaves the nodes that
#: a drawn node set puts near the walls alone
WALL_GAP_FRACTION = 0.02
#: an interior node closer to another node than this fraction of its reference spacing is
#: removed too: two nodes that the flow brings on top of each other share one Voronoi
#: cell, so each keeps about half a normal area and the area rule never sees them, while
#: their velocities may differ by a tenth of the speed over a distance of 1e-9 and the
#: predictor-corrector cannot contract there (an old-grid run crawled at dt = 0.002 for
#: thousands of steps with such a pair 4e-9 apart); as small as WALL_GAP_FRACTION, it
#: leaves the close pairs of a drawn node set to the area rule
PAIR_GAP_FRACTION = 0.02


# ---------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------

@njit(cache=True)
def _clip_half(src, ns, px, py, qx, qy, dst):
    """Sutherland-Hodgman: the part of the convex polygon src[:ns] left of p->q."""
    m = 0
    for i in range(ns):
        x1, y1 = src[i, 0], src[i, 1]
        x2, y2 = src[(i + 1) % ns, 0], src[(i + 1) % ns, 1]
        s1 = (qx - px) * (y1 - py) - (qy - py) * (x1 - px)
        s2 = (qx - px) * (y2 - py) - (qy - py) * (x2 - px)
        if s1 >= 0.0:
            dst[m, 0], dst[m, 1] = x1, y1
            m += 1
        if (s1 > 0.0 and s2 < 0.0) or (s1 < 0.0 and s2 > 0.0):
            t = s1 / (s1 - s2)
            dst[m, 0], dst[m, 1] = x1 + t * (x2 - x1), y1 + t * (y2 - y1)
            m += 1
    return m


@njit(cache=True)
def _copy_points(src, ns, dst):
    """Copy the points src[:ns] to dst[:ns] and return ns (a loop: numba's slice
    assignment compiles a shape check with its error message, seconds on a first run)."""
    for i in range(ns):
        dst[i, 0] = src[i, 0]
        dst[i, 1] = src[i, 1]
    return ns


@njit(cache=True)
def _bary(x, y, X):
    ax, ay = X[0, 0], X[0, 1]
    d = (X[1, 0] - ax) * (X[2, 1] - ay) - (X[1, 1] - ay) * (X[2, 0] - ax)
    l1 = ((x - ax) * (X[2, 1] - ay) - (y - ay) * (X[2, 0] - ax)) / d
    l2 = ((X[1, 0] - ax) * (y - ay) - (X[1, 1] - ay) * (x - ax)) / d
    return 1.0 - l1 - l2, l1, l2


@njit(cache=True)
def _piece_moments(poly, ns, Xo, Vo, Xn, rhs):
    """Add the integrals over the polygon poly[:ns] (inside old triangle Xo with vertex
    values Vo (3, c)) of the old linear field times the new triangle's barycentrics."""
    for f in range(1, ns - 1):
        x0, y0 = poly[0, 0], poly[0, 1]
        x1, y1 = poly[f, 0], poly[f, 1]
        x2, y2 = poly[f + 1, 0], poly[f + 1, 1]
        sa = 0.5 * ((x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0))
        for e in range(3):  # edge midpoints: exact for quadratics
            if e == 0:
                mx, my = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            elif e == 1:
                mx, my = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
            else:
                mx, my = 0.5 * (x2 + x0), 0.5 * (y2 + y0)
            o0, o1, o2 = _bary(mx, my, Xo)
            n0, n1, n2 = _bary(mx, my, Xn)
            for c in range(Vo.shape[1]):
                fv = o0 * Vo[0, c] + o1 * Vo[1, c] + o2 * Vo[2, c]
                rhs[0, c] += sa / 3.0 * n0 * fv
                rhs[1, c] += sa / 3.0 * n1 * fv
                rhs[2, c] += sa / 3.0 * n2 * fv


@njit(cache=True)
def conservative_fill(Xo, Vo, Xn):
    """Values at the 3-point rule's points of the new triangles ``Xn`` (k, 3, 2): the L2
    projection onto linear fields of the piecewise linear field given by the old
    triangles ``Xo`` (m, 3, 2) (tiling the same region) with vertex values ``Vo``
    (m, 3, c). Conserves the integral of every component; keeps linear fields."""
    k, c = Xn.shape[0], Vo.shape[2]
    out = np.zeros((k, 3, c))
    a = np.empty((12, 2))
    b = np.empty((12, 2))
    for j in range(k):
        Y = Xn[j]
        area = 0.5 * ((Y[1, 0] - Y[0, 0]) * (Y[2, 1] - Y[0, 1])
                      - (Y[1, 1] - Y[0, 1]) * (Y[2, 0] - Y[0, 0]))
        rhs = np.zeros((3, c))
        for i in range(Xo.shape[0]):
            ns = _copy_points(Y, Y.shape[0], a)
            for e in range(3):
                p, q = Xo[i, e], Xo[i, (e + 1) % 3]
                ns = _copy_points(b, _clip_half(a, ns, p[0], p[1], q[0], q[1], b), a)
                if ns < 3:
                    break
            if ns >= 3:
                _piece_moments(a, ns, Xo[i], Vo[i], Y, rhs)
        for m in range(c):
            tot = rhs[0, m] + rhs[1, m] + rhs[2, m]
            nv0 = 12.0 / area * (rhs[0, m] - tot / 4.0)
            nv1 = 12.0 / area * (rhs[1, m] - tot / 4.0)
            nv2 = 12.0 / area * (rhs[2, m] - tot / 4.0)
            s3 = (nv0 + nv1 + nv2) / 6.0
            out[j, 0, m] = 0.5 * nv0 + s3
            out[j, 1, m] = 0.5 * nv1 + s3
            out[j, 2, m] = 0.5 * nv2 + s3
    return out


@njit(cache=True)
def _occupied(P, alive, a, v, b):
    """True if a live node other than a, v, b lies in or on the triangle (a, v, b)."""
    o = orient2d(P[a, 0], P[a, 1], P[v, 0], P[v, 1], P[b, 0], P[b, 1])
    for i in range(P.shape[0]):
        if not alive[i] or i == a or i == v or i == b:
            continue
        s1 = orient2d(P[a, 0], P[a, 1], P[v, 0], P[v, 1], P[i, 0], P[i, 1])
        s2 = orient2d(P[v, 0], P[v, 1], P[b, 0], P[b, 1], P[i, 0], P[i, 1])
        s3 = orient2d(P[b, 0], P[b, 1], P[a, 0], P[a, 1], P[i, 0], P[i, 1])
        if o > 0.0 and s1 >= 0.0 and s2 >= 0.0 and s3 >= 0.0:
            return True
        if o < 0.0 and s1 <= 0.0 and s2 <= 0.0 and s3 <= 0.0:
            return True
        if o == 0.0 and s1 == 0.0 and s2 == 0.0 and \
                min(P[a, 0], P[b, 0]) <= P[i, 0] <= max(P[a, 0], P[b, 0]) and \
                min(P[a, 1], P[b, 1]) <= P[i, 1] <= max(P[a, 1], P[b, 1]):
            return True
    return False


# ---------------------------------------------------------------------------
# the mixin
# ---------------------------------------------------------------------------

class NodeRemoval:
    """Node removal and segment merging for
    :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh` (which provides the state,
    the snapshot of linear ip fields and the segment recovery used here)."""

    def remove_nodes(self, idx) -> np.ndarray:
        """Take the nodes ``idx`` (interior, or on a wall but not at a corner) out of the
        mesh for good (see the module docs):
        stars refilled with (constrained) Delaunay triangles, ip fields remapped
        conservatively, a node ending two segments has them merged into one, and every
        per-node array compacted. Returns the map old -> new node index (-1: removed).
        ``ValueError`` for a corner of the hull, or a segment node whose segments cannot
        be merged; on any error the mesh is left exactly as it was."""
        return self._removal(self._node_indices(idx))

    def reconnect_segments(self, release, add, source, remove=()) -> np.ndarray:
        """Replace the segments ``release`` (rows of ``triangulation.segments``) by the
        node pairs ``add`` (k, 2) of the given segments ``source`` (k,), made edges by
        flips (the ip fields of the triangles they change refilled conservatively), then
        remove the nodes ``remove`` as :meth:`remove_nodes` does: how a material polygon
        is cut in two where its two faces meet. Returns the map old -> new node index.
        ``ValueError`` for rows, nodes or sources out of range, a new segment that would
        cross a kept one, or a node that cannot go; the mesh is then left exactly as it
        was."""
        tri = self.triangulation
        release, add, source = self._reconnection(release, add, source)

        def reconnect():
            keep = np.ones(tri.segments.shape[0], dtype=bool)
            keep[release] = False
            tri.set_segments(np.r_[tri.segments[keep], add],
                             np.r_[tri.segment_source[keep], source])
            self._recover_refilled()
            tri.make_delaunay(on_flips=self._on_flips)
        return self._removal(self._node_indices(remove), first=reconnect)

    def _removal(self, idx, first=None) -> np.ndarray:
        """One transaction: ``first()`` (if given), the nodes idx taken out, flips,
        compaction; returns the node map. On any error the state is restored."""
        state = self._state()
        try:
            if first is not None:
                first()
            self._remove_all(idx)
            self.triangulation.make_delaunay(on_flips=self._on_flips)
            new = self._compact()
        except BaseException:
            self._restore(state)
            raise
        self._invalidate()
        return new

    def _reconnection(self, release, add, source):
        """The arguments of :meth:`reconnect_segments` checked, as arrays."""
        tri = self.triangulation
        k, n = tri.segments.shape[0], tri.npoints
        release = np.unique(np.asarray(release, dtype=np.int64).reshape(-1))
        if release.size and (release[0] < 0 or release[-1] >= k):
            raise ValueError(f"segment rows must lie in [0, {k}), got {release.tolist()}")
        add = np.asarray(add, dtype=np.int64).reshape(-1, 2)
        source = np.asarray(source, dtype=np.int64).reshape(-1)
        if add.size and (add.min() < 0 or add.max() >= n or (add[:, 0] == add[:, 1]).any()):
            raise ValueError(f"new segments must join two different nodes in [0, {n}), got "
                             f"{add.tolist()}")
        nsrc = self._segment_ref.size
        if source.size != add.shape[0] or (source.size and (source.min() < 0
                                                             or source.max() >= nsrc)):
            raise ValueError(f"source must give one given segment in [0, {nsrc}) per new "
                             f"segment ({add.shape[0]}), got {source.tolist()}")
        return release, add, source

    def _node_indices(self, idx) -> np.ndarray:
        idx = np.unique(np.asarray(idx, dtype=np.int64).reshape(-1))
        n = self.triangulation.npoints
        if idx.size and (idx[0] < 0 or idx[-1] >= n):
            raise ValueError(f"node indices must lie in [0, {n}), got {idx.tolist()}")
        return idx

    def _remove_all(self, idx) -> None:
        """Take the nodes idx out one by one (:meth:`remove_nodes`, before compaction)."""
        alive = np.ones(self.triangulation.npoints, dtype=bool)
        for v in idx.tolist():
            if not self.triangulation.removable(v):
                raise ValueError(f"node {v} is a corner of the hull and cannot be "
                                 f"removed")
            merge = self.segment_merge(v, alive)
            if merge is False:
                raise ValueError(f"node {v} ends segments that cannot be merged into one "
                                 f"(not exactly two, or another node in their triangle)")
            self._take_out(v, merge)
            alive[v] = False

    def segment_merge(self, v: int, alive=None):
        """How node v's segments would merge if it were removed: None if v ends no
        segment; ``(a, b, source)`` if it ends exactly two, (a, v) and (v, b), that can
        become the segment (a, b) (of the source of (a, v)): no segment a-b yet and no
        other node (``alive``: the nodes still in the mesh) in or on the triangle
        (a, v, b); False otherwise."""
        tri = self.triangulation
        seg = tri.segments
        rows = np.flatnonzero((seg == v).any(axis=1))
        if not rows.size:
            return None
        if rows.size != 2:
            return False
        a, b = (int(seg[r, 0] if seg[r, 1] == v else seg[r, 1]) for r in rows)
        if is_segment(tri.segment_keys, a, b):
            return False
        alive = np.ones(tri.npoints, dtype=bool) if alive is None else alive
        if _occupied(tri.nodes, alive, a, v, b):
            return False
        return a, b, int(tri.segment_source[rows[0]])

    def _take_out(self, v, merge):
        """Remove vertex v from the triangulation (it stays a node until compaction),
        refill its star conservatively, and merge its segments (``merge``)."""
        tri = self.triangulation
        try:
            star = tri.star(v)
        except ValueError:  # a wall node between two of its wall: its open fan
            star = tri.fan(v)
        X, vals = self._snapshot(star)
        slots, moves = tri.remove_vertex(v, star)
        for k, F in self.ip_fields.items():
            for src, dst in moves:
                F[dst] = F[src]
            self.ip_fields[k] = np.ascontiguousarray(F[:tri.ntriangles])
        self._refill(X, vals, slots)
        self._touched.append(np.asarray(slots, dtype=np.int64))
        if merge is None:
            return
        a, b, s = merge
        seg, src = tri.segments, tri.segment_source
        keep = ~(seg == v).any(axis=1)
        tri.set_segments(np.r_[seg[keep], [[a, b]]], np.r_[src[keep], s])
        self._recover_refilled()

    def _recover_refilled(self):
        """Make every segment an edge by flips, the triangles they change refilled
        conservatively from the old ones (which tile the same region)."""
        tri = self.triangulation
        T0 = tri.triangles.copy()
        tri.recover_segments()
        changed = np.flatnonzero((tri.triangles != T0).any(axis=1))
        if changed.size:
            X, vals = self._snapshot(changed, T0)
            self._refill(X, vals, changed)
            self._touched.append(changed)

    def _refill(self, X, vals, tris):
        """ip fields of the triangles ``tris`` from the old triangles X (with linear
        fields ``vals``, vertex values) that tile the same region: conservative."""
        Y = self.nodes[self.triangles[tris]]
        for k, F in self.ip_fields.items():
            # in place, as the row moves of _take_out (a copy of every field per removed
            # node made the merges quadratic: 1 s a step at 88,000 nodes); the step's
            # snapshot (_state) holds the fields to restore
            F = self.ip_fields[k] = np.ascontiguousarray(F)
            flat = F.reshape(F.shape[0], 3, -1)
            flat[tris] = conservative_fill(X, np.ascontiguousarray(vals[k]), Y)

    def _compact(self):
        """Drop the nodes in no triangle from the triangulation and every per-node array;
        returns the map old -> new index (-1 for a dropped node)."""
        tri = self.triangulation
        used = np.zeros(tri.npoints, dtype=bool)
        used[tri.triangles.ravel()] = True
        new = np.full(tri.npoints, -1, dtype=np.int64)
        new[used] = np.arange(int(used.sum()))
        if used.all():
            return new
        P = np.ascontiguousarray(tri.nodes[used])
        P.flags.writeable = False
        seg = new[tri.segments]  # the map is increasing: the keys stay sorted
        tri.restore({"nodes": P, "triangles": new[tri.triangles], "neighbours": tri.neighbours,
                     "segment_keys": pair_keys(seg),
                     "segment_source": tri.segment_source.copy()})
        self.node_fields = {k: f[used].copy() for k, f in self.node_fields.items()}
        self._on_wall = self._on_wall[used].copy()
        self._target = self._target[used].copy()
        return new

    def walk_segments(self, a: int, b: int, listed=()):
        """The path of nodes from a to b along segments whatever their sources, through
        nodes that end exactly two segments and are not ``listed``, or None: how
        :meth:`polyline` joins two nodes after a merge joined pieces of two given
        segments (a node inserted on the one next to the merged node ends up between)."""
        nb = {}
        for i, j in self.triangulation.segments.tolist():
            nb.setdefault(i, []).append(j)
            nb.setdefault(j, []).append(i)
        for first in nb.get(a, []):
            path = [a, first]
            while path[-1] != b and path[-1] not in listed and len(nb[path[-1]]) == 2 \
                    and len(path) <= len(nb):
                path.append(next(w for w in nb[path[-1]] if w != path[-2]))
            if path[-1] == b:
                return path
        return None

    def release_segments(self, rows) -> int:
        """Stop keeping the segments ``rows`` (indices into ``triangulation.segments``) as
        edges: their nodes stay, the mesh becomes Delaunay across them by flips (with the
        remap of the ip fields). Where two material lines meet (a film between them
        squeezed to nothing) the line that ends there is released. Returns how many
        segments were released; on any error the mesh is left exactly as it was."""
        tri = self.triangulation
        rows = np.unique(np.asarray(rows, dtype=np.int64).reshape(-1))
        k = tri.segments.shape[0]
        if rows.size and (rows[0] < 0 or rows[-1] >= k):
            raise ValueError(f"segment rows must lie in [0, {k}), got {rows.tolist()}")
        if not rows.size:
            return 0
        state = self._state()
        try:
            keep = np.ones(k, dtype=bool)
            keep[rows] = False
            tri.set_segments(tri.segments[keep], tri.segment_source[keep])
            tri.make_delaunay(on_flips=self._on_flips)
        except BaseException:
            self._restore(state)
            raise
        self._invalidate()
        return int(rows.size)

    def shift_nodes(self, idx, dx) -> None:
        """Move the nodes ``idx`` by the small displacements ``dx`` (k, 2): a geometric
        correction between steps (not a flow step: the clock does not move), e.g. to give
        back to a material polygon the area a merge at one of its folds cut off. Refused
        with ``ValueError``, the mesh left as it was, for a wall node or if a triangle
        would invert; else flips with the remap restore the (constrained) Delaunay
        property."""
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        dx = np.asarray(dx, dtype=float).reshape(idx.size, 2)
        tri = self.triangulation
        if idx.size and (idx.min() < 0 or idx.max() >= tri.npoints):
            raise ValueError(f"node indices must lie in [0, {tri.npoints}), got {idx.tolist()}")
        if self._on_wall[idx].any():
            raise ValueError(f"node {int(idx[self._on_wall[idx].any(axis=1)][0])} is on a "
                             f"wall and cannot be shifted")
        if not np.isfinite(dx).all():
            raise ValueError("the shifts must be finite")
        state = self._state()
        try:
            x = np.array(self.nodes)
            x[idx] += dx
            self._set_positions(x)
            bad = np.flatnonzero(tri.orientation() <= 0)
            if bad.size:
                raise ValueError(f"shifting the nodes would invert triangle {int(bad[0])}")
            tri.make_delaunay(on_flips=self._on_flips)
        except BaseException:
            self._restore(state)
            raise
        self._invalidate()

    # -- the policy ----------------------------------------------------------------
    def merge_nodes(self, fraction: float = CLUSTER_FRACTION,
                    fold_angle: float = FOLD_ANGLE) -> dict:
        """Remove crowded nodes and folds (what ``advance(..., merge=True)`` runs after
        injection): a node off the hull, or on a wall but not at a corner, whose spacing
        (square root of its share of the triangle areas) fell below ``fraction`` of its
        reference spacing (for a wall node: or whose neighbour on the wall came closer
        than that);
        and a node ending two segments that meet at less than ``fold_angle`` degrees or
        are both shorter than ``fraction`` of their reference length, by merging them.
        Folds go first, the sharpest first (one about to close cannot wait for the next
        step, in which it may close through itself), then nodes off segments, the most
        crowded first; no two neighbours go in one call (a cluster keeps one node); a
        segment node goes only if its segments can merge (:meth:`segment_merge`). Returns
        ``{"removed": nodes off segments removed, "merged": segment nodes removed,
        "node_map": old -> new index}``."""
        order = self._merge_candidates(fraction, fold_angle)
        if not order.size:
            return {"removed": 0, "merged": 0, "node_map": np.arange(self.triangulation.npoints)}
        state = self._state()
        try:
            return self._merge(order)
        except BaseException:
            self._restore(state)
            raise

    def _merge(self, order):
        tri = self.triangulation
        n = tri.npoints
        ptr, adj = _neighbour_lists(tri.edges, n)
        blocked = np.zeros(n, dtype=bool)
        alive = np.ones(n, dtype=bool)
        removed = merged = 0
        for v in order.tolist():
            if blocked[v]:
                continue
            merge = self.segment_merge(v, alive)
            if merge is False:
                continue
            self._take_out(v, merge)
            alive[v] = False
            blocked[v] = True                       # and its neighbours before the merges
            blocked[adj[ptr[v]:ptr[v + 1]]] = True
            removed += merge is None
            merged += merge is not None
        tri.make_delaunay(on_flips=self._on_flips)
        new = self._compact()
        self._invalidate()
        return {"removed": removed, "merged": merged, "node_map": new}

    def _joins_short(self, v: int) -> bool:
        """Whether segment node v, crowded by area, may go: its two segments joined stay
        within the reference length of their source. A node in a film squeezed between two
        material lines is crowded by area while the lines keep their spacing; merging it
        would leave a segment that :meth:`split_segments` splits again the next step (in
        a run with a thin film of low-viscosity fluid around the plate this merge-and-split
        churn made up most of the thousands of merges and injections)."""
        tri = self.triangulation
        seg = tri.segments
        rows = np.flatnonzero((seg == v).any(axis=1))
        if rows.size != 2:
            return False
        a, b = (int(seg[r, 0] if seg[r, 1] == v else seg[r, 1]) for r in rows)
        ref = self._segment_ref[tri.segment_source[rows]].min()
        return bool(np.hypot(*(self.nodes[a] - self.nodes[b])) <= ref)

    def spacing_ratios(self) -> np.ndarray:
        """(n,) each node's spacing (square root of its share of the triangle areas) over
        its reference spacing (the square root of the largest target area,
        :meth:`reference_areas`, of the node and its neighbours), what
        :meth:`merge_nodes` compares with ``fraction``; for a
        wall node the smaller of that and its nearest neighbour on the wall over its
        reference spacing, for a node off the walls the smaller of its ratio and its
        distance to the nearest wall over :data:`WALL_GAP_FRACTION` of its reference
        spacing, times :data:`CLUSTER_FRACTION`, and of that and its distance to the nearest
        node over :data:`PAIR_GAP_FRACTION` of its reference spacing, times
        :data:`CLUSTER_FRACTION`; ``inf`` for the corners of
        the box and hull nodes off its walls (never removed)."""
        tri = self.triangulation
        P, T = self.nodes, self.triangles
        share = area_shares(P, T)
        free = ~self._on_wall.any(axis=1)
        free[tri.hull_edges.ravel()] = False
        # a node on one wall (not a corner) compares with its own reference: its
        # neighbours off the wall have whole areas where it has half of one
        wall = self._on_wall.sum(axis=1) == 1
        # the reference: the largest target area of the node and its neighbours (a
        # node with a fine target among coarse ones is compared with the density the
        # place had)
        own = self.reference_areas()
        ref = own.copy()
        E = tri.edges
        np.maximum.at(ref, E[:, 0], own[E[:, 1]])
        np.maximum.at(ref, E[:, 1], own[E[:, 0]])
        ref[wall] = own[wall]
        # a wall node also by its nearest neighbour on the wall: two wall nodes can
        # converge while their shares stay large (a strained flow keeps areas), and unlike
        # interior nodes they cannot be relocated past each other
        nearest = _nearest(P, tri.hull_edges)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.sqrt(share / ref)
            ratio[wall] = np.minimum(ratio[wall], nearest[wall] / np.sqrt(ref[wall]))
            if self.walls == "box":
                # an interior node pressed towards a wall (stopped short of it step after
                # step) by its distance to the wall: its triangles with the wall flatten
                # while its share of the areas stays
                lo, hi = self._box
                gap = np.minimum(P - lo, hi - P).min(axis=1) / np.sqrt(ref)
                gap *= CLUSTER_FRACTION / WALL_GAP_FRACTION  # removed below WALL_GAP_FRACTION
                ratio[free] = np.minimum(ratio[free], gap[free])
            # an interior node by its distance to the nearest node: a pair on top of each
            # other shares one cell and keeps its areas
            ratio[free] = np.minimum(ratio[free], (_nearest(P, E) / np.sqrt(ref)
                                                   * (CLUSTER_FRACTION / PAIR_GAP_FRACTION))[free])
        ratio[~(free | wall) | ~(ref > 0)] = np.inf
        return ratio

    def _merge_candidates(self, fraction, fold_angle):
        """Nodes to try, in order: folds (by angle: one about to close cannot wait for
        the next step), then crowded nodes off segments and crowded segment nodes (each
        by spacing ratio)."""
        tri = self.triangulation
        P = self.nodes
        ratio = self.spacing_ratios()
        on_seg = self.segment_nodes()
        free = ~self._on_wall.any(axis=1)
        free[tri.hull_edges.ravel()] = False
        crowded = np.array([v for v in np.flatnonzero(ratio < fraction).tolist()
                            if (free[v] or tri.removable(v))
                            and (not on_seg[v] or self._joins_short(v))], dtype=np.int64)
        crowded = crowded[np.lexsort((ratio[crowded], on_seg[crowded]))]
        seg, src = tri.segments, tri.segment_source
        count = np.bincount(seg.ravel(), minlength=P.shape[0])
        ends = np.flatnonzero(free & (count == 2))
        if not ends.size:
            return crowded
        length = np.hypot(*(P[seg[:, 0]] - P[seg[:, 1]]).T)
        short = length < fraction * self._segment_ref[src]
        fold = []
        for v in ends.tolist():
            rows = np.flatnonzero((seg == v).any(axis=1))
            u = P[seg[rows].ravel()[seg[rows].ravel() != v]] - P[v]
            cos = (u[0] @ u[1]) / (np.hypot(*u[0]) * np.hypot(*u[1]))
            ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
            if ang < fold_angle or short[rows].all():
                fold.append((ang, v))
        fold = np.array([v for _, v in sorted(fold)], dtype=np.int64)
        return np.r_[fold, crowded[~np.isin(crowded, fold)]]


def _nearest(P: np.ndarray, E: np.ndarray) -> np.ndarray:
    """(n,) each node's distance to its nearest neighbour along the edges E (k, 2)."""
    length = np.hypot(*(P[E[:, 0]] - P[E[:, 1]]).T)
    near = np.full(P.shape[0], np.inf)
    np.minimum.at(near, E[:, 0], length)
    np.minimum.at(near, E[:, 1], length)
    return near


def _neighbour_lists(E: np.ndarray, n: int):
    """CSR neighbour lists of the n nodes from the edges E (k, 2): node v's neighbours
    are ``adj[ptr[v]:ptr[v + 1]]``."""
    ends = np.r_[E[:, 0], E[:, 1]]
    order = np.argsort(ends, kind="stable")
    adj = np.r_[E[:, 1], E[:, 0]][order]
    return np.searchsorted(ends[order], np.arange(n + 1)), adj
