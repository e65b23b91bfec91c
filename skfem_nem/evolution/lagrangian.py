"""The Lagrangian evolving mesh: nodes move with the flow, the triangulation
is repaired by local flips, never regridded.

:class:`LagrangianMesh` owns a 2D Delaunay :class:`~skfem_nem.Triangulation`,
named fields carried by the nodes (material id, viscosity, initial position,
...) and named fields stored at each triangle's quadrature points (stress
tensors: the paper's "tensorial memory"). Each :meth:`~LagrangianMesh.advance`

1. moves the nodes with a velocity field by an iterative predictor-corrector
   (trapezoidal) update, walls kept exact;
2. repairs the triangulation by Lawson flips, remapping the integration-point
   fields of the two triangles of every flip onto the two new ones;
3. if the move would invert a triangle (flips cannot repair that), splits the
   step into substeps until none inverts;
4. optionally holds the nodes to a target spacing fixed for the whole run
   (:mod:`~skfem_nem.evolution.spacing`): nodes injected where the mesh has thinned
   out, long edges split (inside, on walls, on segments), crowded nodes removed.

A step whose predictor-corrector does not converge is not accepted: it raises
:class:`~skfem_nem.evolution.stepping.StepTooLong` and leaves the mesh as it was.

Remap rules for the 3-point rule (points near the vertices), per flip of the
quadrilateral (a, b, d, c) from diagonal b-c to a-d:

``"average"`` (the paper's Fig. 5)
    a new point near a vertex that belonged to one old triangle copies that
    triangle's value (splitting); one near a vertex of both old triangles
    gets the mean of their two values (averaging).
``"conservative"``
    the three values of each old triangle define its linear field; each new
    triangle gets the L2 projection onto linear fields of the old piecewise
    linear field over the two sub-triangles (of the four cut by both
    diagonals) that it covers. Integrals of every component are conserved
    exactly, linear fields are kept exactly.
"""
from __future__ import annotations

import json
import os
from typing import Callable, Dict, Optional

import numpy as np

from ..geometry.meshes import triangulation_mesh
from ..geometry.triangulation import Triangulation
from .injection import NodeInjection
from .merging import NodeRemoval
from .quality import cross, inverted, min_angles
from .remap import remap_average, remap_conservative
from .spacing import SpacingTarget, spacing_from_areas
from .stepping import LagrangianStep, StepTooLong, check_node_fields, save_npz_atomically

__all__ = ["LagrangianMesh"]

# the 3-point rule of scikit-fem (intorder <= 2): point k near vertex k
_X3 = np.array([[1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
_W3 = np.full(3, 1 / 6)
_A3 = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])



# ---------------------------------------------------------------------------
# the evolving mesh
# ---------------------------------------------------------------------------


class LagrangianMesh(SpacingTarget, NodeInjection, NodeRemoval, LagrangianStep):
    """A 2D node set carried by a flow, kept Delaunay by local flips.

    Parameters
    ----------
    nodes
        (n, 2) initial node positions.
    node_fields
        Named arrays with one row per node, shape (n, ...): carried with the
        nodes, interpolated with Sibson coordinates for injected nodes.
    ip_fields
        Named arrays with shape (nt, 3, ...) -- or (3, ...) to broadcast --
        values at the 3 quadrature points of each triangle (in
        ``triangles`` order), remapped on every flip.
    remap
        ``"conservative"`` (default: conserves integrals exactly, keeps linear
        fields; see the module docs and docs/evolution.md for the measured
        diffusion) or ``"average"`` (the paper's rule).
    segments
        Optional (k, 2) pairs of node indices that stay edges (material interfaces,
        the outline of a body): the triangulation is then the constrained Delaunay
        one, the segments move with their nodes, flips never remove them, relocation
        puts them back by flips, and with ``inject`` a segment stretched past
        ``sqrt(inject)`` times its initial length is split at its midpoint (both
        halves stay segments; ``triangulation.segment_source`` names the given
        segment each piece comes from). A step after which a segment would not be an
        edge (segments crossing) raises :class:`StepTooLong` ("reduce dt") and leaves the
        mesh as it was.
    walls
        ``"box"`` (default): nodes on the bounding box of the initial nodes
        keep their wall coordinate exactly (free slip: only the tangential
        velocity moves them); ``None``: no constraint.
    spacing
        The target node spacing that injection and removal hold the nodes to for the
        whole run (:mod:`~skfem_nem.evolution.spacing`). ``None`` (default): the
        initial node set's own spacing (the edge of the equilateral lattice with each
        node's Voronoi area, or its neighbourhood's where larger), carried by the
        material: an injected node gets the natural-neighbour interpolant of its
        material's targets. A callable
        ``spacing(x)`` -> (n,) positive: a target fixed in space, evaluated at the
        nodes' positions at every step.

    Attributes
    ----------
    triangulation, time, step, node_fields, ip_fields, history (a list of
    per-step dicts: step, time, dt, iterations (predictor-corrector),
    substeps, flips, relocated, injected (edges_split of them by the quality bound),
    min_angle (degrees), longest_edge, triangles_changed, stencils_affected).

    Examples
    --------
    A shear flow moves the interior node; the wall nodes keep their wall
    coordinate, node fields travel with the nodes:

    >>> import numpy as np
    >>> from skfem_nem import LagrangianMesh
    >>> nodes = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> lm = LagrangianMesh(nodes, node_fields={"height": nodes[:, 1]})
    >>> def shear(x):
    ...     return np.c_[0.2 * x[:, 1] * (1 - x[:, 1]), np.zeros(len(x))]
    >>> report = lm.advance(shear, dt=0.5)
    >>> lm.time, lm.step, lm.triangulation.is_delaunay()
    (0.5, 1, True)
    >>> lm.nodes[4].round(6).tolist(), lm.nodes[2].tolist()
    ([0.524, 0.4], [1.0, 1.0])
    >>> lm.node_fields["height"][4].item()
    0.4
    """

    def __init__(self, nodes, node_fields: Optional[Dict[str, np.ndarray]] = None,
                 ip_fields: Optional[Dict[str, np.ndarray]] = None,
                 remap: str = "conservative", walls: Optional[str] = "box", segments=None,
                 spacing: Optional[Callable[[np.ndarray], np.ndarray]] = None):
        if spacing is not None and not callable(spacing):
            raise TypeError(f"spacing must be None or a callable x (n, 2) -> (n,), got "
                            f"{type(spacing).__name__}")
        self.triangulation = Triangulation(nodes, segments=segments)
        n, nt = self.triangulation.npoints, self.triangulation.ntriangles
        if remap not in ("conservative", "average"):
            raise ValueError(f"remap must be 'conservative' or 'average', got {remap!r}")
        if walls not in ("box", None):
            raise ValueError(f"walls must be 'box' or None, got {walls!r}")
        self.remap = remap
        self.walls = walls
        self.node_fields = check_node_fields(node_fields, n)
        self.ip_fields = {}
        for name, a in (ip_fields or {}).items():
            a = np.array(a, dtype=float, copy=True)
            if a.shape[:1] == (3,):
                a = np.broadcast_to(a, (nt,) + a.shape).copy()
            if a.shape[:2] != (nt, 3):
                raise ValueError(f"integration-point field {name!r} has shape {a.shape}, "
                                 f"expected ({nt}, 3, ...)")
            self.ip_fields[name] = a
        P = self.triangulation.nodes
        lo, hi = P.min(axis=0), P.max(axis=0)
        self._box = (lo, hi)
        self._on_wall = np.zeros((n, 2), dtype=bool)
        if walls == "box":
            self._on_wall = (P == lo) | (P == hi)
        self._spacing_fn = spacing
        self._target = self._initial_spacing() if spacing is None else self._spacing_at_nodes()
        self._segment_ref = self._segment_lengths(np.asarray(segments).reshape(-1, 2).shape[0]
                                                  if segments is not None else 0)
        self.time = 0.0
        self.step = 0
        self.node_map = np.arange(n)
        self.history = []
        self._version = 0
        self._cache, self._previous = {}, {}
        self._touched = []

    # -- views ----------------------------------------------------------------
    @property
    def nodes(self) -> np.ndarray:
        return self.triangulation.nodes

    @property
    def on_walls(self) -> np.ndarray:
        """(n, 2) read-only: True where a node lies on a wall of the box normal to x
        (column 0) or to y (column 1); all False without walls."""
        out = self._on_wall.copy()
        out.flags.writeable = False
        return out

    @property
    def triangles(self) -> np.ndarray:
        return self.triangulation.triangles

    @property
    def mesh(self):
        """The current scikit-fem ``MeshTri`` (vertex order as ``triangles``,
        so quadrature point k of element t is the ip field's slot k)."""
        if "mesh" not in self._cache:
            tri = self.triangulation
            if tri.segment_keys.size:
                # the mesh keeps a copy of the constrained triangulation (this one moves on)
                self._cache["mesh"] = triangulation_mesh(Triangulation.from_arrays(
                    tri.nodes, tri.triangles, tri.neighbours, tri.segments, tri.segment_source))
            else:
                from skfem import MeshTri
                self._cache["mesh"] = MeshTri(np.ascontiguousarray(self.nodes.T),
                                              np.ascontiguousarray(self.triangles.T),
                                              sort_t=False)
        return self._cache["mesh"]

    def basis(self, elem=None, integration: str = "smoothed"):
        """A :class:`~skfem_nem.NaturalNeighbourBasis` on the current mesh (cached until the
        mesh changes, then the last one updated where it can be:
        :meth:`~skfem_nem.NaturalNeighbourBasis.updated`) whose integration points are the
        integration-point fields' slots: point k of triangle t near its
        vertex k. ``integration="smoothed"`` (default): gradients smoothed
        over the vertex cells of the triangles; ``"gauss"``: the 3-point rule."""
        from ..basis import NaturalNeighbourBasis
        key = ("basis", None if elem is None else repr(elem), integration)
        if key not in self._cache:
            old = self._previous.get(key)
            if old is not None and old.update_obstacle(self.mesh) is None:
                self._cache[key] = old.updated(self.mesh)
            else:
                rule = {"quadrature": (_X3, _W3)} if integration == "gauss" else {}
                self._cache[key] = NaturalNeighbourBasis(self.mesh, elem,
                                                         integration=integration, **rule)
        return self._cache[key]

    def node_areas(self) -> np.ndarray:
        """(n,) Voronoi-cell area of each node, from the cotangent formula.

        For a Delaunay triangulation this is the area of the node's Voronoi
        cell for interior nodes (and of the cell clipped by the normals through
        the hull edges' midpoints for hull nodes); unlike the triangle areas it
        does not jump when an edge flips, since flips happen where the two
        triangulations give the same cells. A hull edge whose opposite angle is
        obtuse (a flat triangle along a wall) counts as a right angle there: its
        cotangent term would be negative (the circumcentre lies outside), and a wall
        node between long, flat triangles would get a negative area and never trigger
        injection where the flow spreads the wall apart.
        """
        P, T = self.nodes, self.triangles
        N = self.triangulation.neighbours
        out = np.zeros(P.shape[0])
        for k in range(3):
            i, j, l = T[:, k], T[:, (k + 1) % 3], T[:, (k + 2) % 3]
            # angle at l opposite the edge (i, j)
            u, v = P[i] - P[l], P[j] - P[l]
            cot = (u * v).sum(1) / np.abs(cross(u, v))
            cot = np.where(N[:, (k + 2) % 3] < 0, np.maximum(cot, 0.0), cot)
            e2 = ((P[i] - P[j]) ** 2).sum(1)
            np.add.at(out, i, cot * e2 / 8.0)
            np.add.at(out, j, cot * e2 / 8.0)
        return out

    def longest_edge(self) -> float:
        """The longest edge of the triangulation."""
        E = self.triangulation.edges
        return float(np.hypot(*(self.nodes[E[:, 0]] - self.nodes[E[:, 1]]).T).max())

    def min_angle(self) -> float:
        """The smallest triangle angle, degrees."""
        out = np.empty(self.triangles.shape[0])
        min_angles(self.nodes, self.triangles, out)
        return float(np.degrees(out.min()))

    def replace_ip_fields(self, fields: Dict[str, np.ndarray]) -> None:
        """Replace the integration-point fields by copies of ``fields`` (one row per
        triangle each; fields not named are dropped), e.g. to undo what a failed solve
        had written into them, including a field it added. ``ValueError`` naming a field
        with the wrong number of rows, the fields then unchanged."""
        for k, v in fields.items():
            if np.shape(v)[:1] != (self.triangulation.ntriangles,):
                raise ValueError(f"ip field {k!r} has {np.shape(v)[:1]} rows, the mesh "
                                 f"{self.triangulation.ntriangles} triangles")
        self.ip_fields = {k: np.array(v, copy=True) for k, v in fields.items()}
        self._invalidate()

    def ip_integral(self, name: str) -> np.ndarray:
        """Integral over the domain of an integration-point field (weights ``|T|/3``:
        the 3-point rule, and the areas of the smoothing cells)."""
        P, T = self.nodes, self.triangles
        a = 0.5 * np.abs(cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]))
        return np.einsum("t,tk...->...", a / 3.0, self.ip_fields[name])

    # -- time step control -----------------------------------------------------
    def max_dt(self, velocity_values: np.ndarray, fraction: float = 0.1) -> float:
        """Largest dt keeping each node's displacement below ``fraction`` of its
        local spacing (the shortest edge at the node), for nodal velocities
        (n, 2)."""
        P, T = self.nodes, self.triangles
        e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
        L = np.hypot(*(P[e[:, 0]] - P[e[:, 1]]).T)
        h = np.full(P.shape[0], np.inf)
        np.minimum.at(h, e[:, 0], L)
        np.minimum.at(h, e[:, 1], L)
        speed = np.hypot(*np.asarray(velocity_values).T)
        with np.errstate(divide="ignore"):
            dt = fraction * h / speed
        return float(dt.min())

    # -- advection -------------------------------------------------------------
    def advance(self, velocity: Callable[[np.ndarray], np.ndarray], dt: float,
                tol: float = 1e-10, maxiter: int = 10, max_substeps: int = 8,
                inject: Optional[float] = None, merge: bool = False) -> dict:
        """Move the nodes by one time step and repair the triangulation.

        Parameters
        ----------
        velocity
            ``velocity(x)`` -> (n, 2) nodal velocities at node positions x (n, 2).
        dt
            Time step.
        tol, maxiter
            Predictor-corrector: iterate x = x0 + dt/2 (v(x0) + v(x)) until the
            largest change is below ``tol`` times the domain size, at most
            ``maxiter`` corrections.
        max_substeps
            If the move would invert a triangle, it is redone in this many
            substeps, and nodes still passing through each other in a substep
            are taken out and re-inserted (reported as ``relocated``).
        inject
            If given, hold the nodes to the target spacing: inject nodes where a
            node's area has grown past ``inject`` times its target area
            (:meth:`inject_nodes`), split segments and wall edges stretched past
            ``sqrt(inject)`` times their reference (:meth:`split_segments`,
            :meth:`split_walls`) and every edge longer than the quality bound
            (:meth:`split_long_edges`).
        merge
            If True, then remove crowded nodes and merge folded segments
            (:meth:`merge_nodes`; ``removed`` and ``merged`` in the report, the
            map of this step's node indices in :attr:`node_map`).

        Returns the step's report (also appended to ``history``). The
        arguments are checked before anything moves, and on any error (or
        interruption) in any stage -- velocity, move, relocation, injection --
        the mesh, its fields, clock and history are left exactly as they were.
        """
        if not isinstance(merge, (bool, np.bool_)):
            raise ValueError(f"merge must be True or False, got {merge!r}")
        return self.step_transaction(velocity, dt, tol, maxiter, max_substeps, inject,
                                     merge=bool(merge))

    def _repair(self, x0, x, dt, max_substeps, inject, merge=False):
        """Flips (and, where triangles would invert, substeps and relocation), then
        the clock, injection and the locality counts of the report."""
        self._touched = []
        flips, substeps, relocated = self._move(x0, x, max_substeps)
        self._invalidate()
        report = {"substeps": substeps, "flips": flips, "relocated": relocated}
        self.time += dt
        self.step += 1
        report.update(self._refine(inject))
        n = self.triangulation.npoints
        merged = self.merge_nodes() if merge else {"removed": 0, "merged": 0,
                                                   "node_map": np.arange(n)}
        report.update(removed=merged["removed"], merged=merged["merged"])
        if self.triangulation.segment_keys.size:
            self._check_segments()
        report["min_angle"] = self.min_angle()
        report["longest_edge"] = self.longest_edge()
        # locality: triangles changed by flips / injection / relocation, and those with
        # their edge neighbours (a basis update tests the stencils and recomputes more:
        # NaturalNeighbourBasis.updated)
        changed = (np.unique(np.concatenate(self._touched)) if self._touched
                   else np.zeros(0, np.int64))
        changed = changed[changed < self.triangles.shape[0]]
        nb = self.triangulation.neighbours[changed].ravel()
        report["triangles_changed"] = int(changed.size)
        report["stencils_affected"] = int(np.union1d(changed, nb[nb >= 0]).size)
        self.node_map = merged["node_map"]
        return report

    def _refine(self, inject):
        """Injection where nodes thinned out, segments and wall edges split where the
        flow stretched them, then every edge longer than the quality bound split
        (:meth:`split_long_edges`); the counts of the report."""
        self._refresh_target()     # (merging compares with it too)
        if not inject:
            return {"injected": 0, "segments_split": 0, "walls_split": 0, "edges_split": 0}
        inside = self.inject_nodes(inject)
        split = self.split_segments(inject)
        walls = self.split_walls(inject)
        edges = self.split_long_edges()
        return {"injected": inside + split + walls + edges, "segments_split": split,
                "walls_split": walls, "edges_split": edges}

    def _state(self):
        """Everything a step may change, copied."""
        return {"tri": self.triangulation.snapshot(),
                "ip_fields": {k: v.copy() for k, v in self.ip_fields.items()},
                "node_fields": {k: v.copy() for k, v in self.node_fields.items()},
                "on_wall": self._on_wall.copy(), "target": self._target.copy(),
                "time": self.time, "step": self.step, "history": len(self.history)}

    def _restore(self, state):
        self.triangulation.restore(state["tri"])
        self.ip_fields = {k: v.copy() for k, v in state["ip_fields"].items()}
        self.node_fields = {k: v.copy() for k, v in state["node_fields"].items()}
        self._on_wall, self._target = state["on_wall"].copy(), state["target"].copy()
        self.time, self.step = state["time"], state["step"]
        del self.history[state["history"]:]
        self._invalidate()

    def _set_positions(self, x):
        self.triangulation.move_nodes(x)

    def _move(self, x0, x1, max_substeps):
        """Move the nodes from x0 to x1, flipping (and remapping) after the
        move. If a triangle would invert (flips cannot repair that), redo the
        step in substeps; where a substep still inverts triangles (nodes
        passing very close to each other), remove their vertices before the
        substep and re-insert them after it (Bowyer--Watson), remapping the
        integration-point fields of the triangles involved by evaluating the
        old linear fields. Returns (flips, substeps, relocated nodes)."""
        self._set_positions(x1)
        if not inverted(self.nodes, self.triangles):
            return self.triangulation.make_delaunay(on_flips=self._on_flips), 1, 0
        self._set_positions(x0)
        nsub = max_substeps
        flips = relocated = 0
        xa = x0
        for s in range(1, nsub + 1):
            xb = x0 + (s / nsub) * (x1 - x0)
            self._set_positions(xb)
            if inverted(self.nodes, self.triangles):
                relocated += self._relocate(xa, xb)
            flips += self.triangulation.make_delaunay(on_flips=self._on_flips)
            xa = xb
        return flips, nsub, relocated

    def _relocate(self, xa, xb):
        """The triangulation is valid at positions xa and inverts at xb: take
        out the vertices of inverted triangles (at xa), move, flip, put them
        back (at xb). Returns how many vertices were relocated."""
        removed = []
        while True:
            self._set_positions(xb)
            T = self.triangles
            inv = np.flatnonzero(self.triangulation.orientation() <= 0)
            if not inv.size:
                break
            cand = self._relocation_candidates(inv, removed)
            if not cand:
                raise StepTooLong(f"triangle {inv[0]} ({T[inv[0]].tolist()}) inverts and none of "
                                  f"its vertices can be relocated: reduce dt")
            self._set_positions(xa)
            for v in cand:
                self._remove_vertex(int(v))
                removed.append(int(v))
        self.triangulation.make_delaunay(on_flips=self._on_flips)
        for v in removed:
            self._reinsert_vertex(v)
        if self.segment_nodes()[removed].any():
            self._recover_segments()
        return len(removed)

    def _relocation_candidates(self, inv, removed):
        """Vertices to take out for the inverted triangles ``inv``: not on a wall, not
        taken out already, and not ending a segment where the triangle has another."""
        on_seg = self.segment_nodes()
        pick = set()
        for t in inv:
            vs = [int(v) for v in self.triangles[t]
                  if not self._on_wall[v].any() and v not in removed]
            pick.update([v for v in vs if not on_seg[v]] or vs)
        return sorted(pick)

    def _recover_segments(self):
        """Segments of relocated nodes made edges again by flips; the ip fields of the
        triangles those flips changed filled from the old triangles' linear fields."""
        tri = self.triangulation
        T0 = tri.triangles.copy()
        try:
            tri.recover_segments()
        except ValueError as err:
            raise StepTooLong(f"{err}; the segments of relocated nodes cannot be edges "
                              f"again: reduce dt", getattr(err, "nodes", None)) from None
        changed = np.flatnonzero((tri.triangles != T0).any(axis=1))
        if changed.size:
            self._fill_from(self._snapshot(changed, T0), changed)
        self._touched.append(changed)

    def _check_segments(self):
        """:class:`StepTooLong` ("reduce dt") unless every segment is an edge and every
        triangle positive: a step never loses a segment silently."""
        missing = self.triangulation.missing_segments()
        if missing.size:
            raise StepTooLong(f"segment {missing[0].tolist()} is no longer an edge "
                              f"({missing.shape[0]} segment(s)): reduce dt")
        if inverted(self.nodes, self.triangles):
            raise StepTooLong("a triangle inverts after the repair: reduce dt")

    # -- local surgery (rare: relocation of colliding nodes) ---------------------
    def _snapshot(self, tris, T=None):
        """Geometry and linear ip fields of triangles ``tris`` (rows of T, by default the
        triangles; for re-evaluation)."""
        X = self.nodes[(self.triangles if T is None else T)[tris]].copy()
        vals = {k: 2.0 * F[tris].reshape(len(tris), 3, -1)
                - F[tris].reshape(len(tris), 3, -1).sum(axis=1, keepdims=True) / 3.0
                for k, F in self.ip_fields.items()}
        return X, vals

    def _fill_from(self, snap, tris):
        """Set the ip fields of ``tris`` by evaluating the snapshot's linear
        fields at their quadrature points (the most-inside old triangle)."""
        if not self.ip_fields:
            return
        X, vals = snap
        Y = self.nodes[self.triangles[tris]]
        pts = np.einsum("kj,tjd->tkd", _A3, Y).reshape(-1, 2)
        a, b, c = X[:, 0], X[:, 1], X[:, 2]
        d = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        rx = pts[:, None, 0] - a[None, :, 0]
        ry = pts[:, None, 1] - a[None, :, 1]
        l1 = (rx * (c[None, :, 1] - a[None, :, 1]) - ry * (c[None, :, 0] - a[None, :, 0])) / d
        l2 = ((b[None, :, 0] - a[None, :, 0]) * ry - (b[None, :, 1] - a[None, :, 1]) * rx) / d
        lam = np.stack([1 - l1 - l2, l1, l2], -1)  # (m, k, 3)
        best = np.argmax(lam.min(axis=2), axis=1)
        lb = lam[np.arange(pts.shape[0]), best]  # (m, 3)
        for k, F in self.ip_fields.items():
            v = np.einsum("mj,mjc->mc", lb, vals[k][best])
            flat = F.reshape(F.shape[0], 3, -1)
            flat[tris] = v.reshape(len(tris), 3, -1)

    def _remove_vertex(self, v):
        tri = self.triangulation
        try:
            star = tri.star(v)
        except ValueError:
            raise StepTooLong(f"node {v} is on the hull and cannot be relocated: "
                              f"reduce dt") from None
        snap = self._snapshot(star)
        slots, moves = tri.remove_vertex(v, star)
        for k, F in self.ip_fields.items():
            for src, dst in moves:
                F[dst] = F[src]
            self.ip_fields[k] = np.ascontiguousarray(F[:tri.ntriangles])
        self._fill_from(snap, slots)
        self._touched.append(star)

    def _reinsert_vertex(self, v):
        tri = self.triangulation
        cav = tri.cavity(tri.nodes[v])
        snap = self._snapshot(cav)
        cav, new = tri.reinsert_vertex(v, cav)
        for k, F in self.ip_fields.items():
            self.ip_fields[k] = np.concatenate([F, np.zeros((new.size,) + F.shape[1:])])
        self._fill_from(snap, np.r_[cav, new])
        self._touched.append(np.r_[cav, new].astype(np.int64))

    def _on_flips(self, log):
        self._touched.append(log[:, :2].ravel().copy())
        if not self.ip_fields:
            return
        for name, F in self.ip_fields.items():
            flat = F.reshape(F.shape[0], 3, -1)
            if self.remap == "average":
                remap_average(log, flat)
            else:
                remap_conservative(self.nodes, log, flat)
            self.ip_fields[name] = flat.reshape(F.shape)

    def _invalidate(self):
        # the bases of the last mesh stay until the next basis() call: updated to the new
        # mesh, they recompute only the triangles whose stencils may have changed
        self._previous = {**self._previous, **{k: v for k, v in self._cache.items()
                                               if k[0] == "basis"}}
        self._cache = {}
        self._version += 1

    # -- segments ----------------------------------------------------------------
    def segment_nodes(self) -> np.ndarray:
        """(n,) True for the nodes that end a segment."""
        on = np.zeros(self.triangulation.npoints, dtype=bool)
        on[self.triangulation.segments.ravel()] = True
        return on

    def _segment_lengths(self, nsources):
        """(nsources,) reference length of each given segment: its longest piece now."""
        tri = self.triangulation
        seg = tri.segments
        ref = np.zeros(nsources)
        np.maximum.at(ref, tri.segment_source, np.hypot(*(self.nodes[seg[:, 0]]
                                                          - self.nodes[seg[:, 1]]).T))
        return ref

    def polyline(self, nodes, closed: bool = False) -> np.ndarray:
        """The nodes of a polyline of segments, given by its nodes in order at an earlier
        time, with the nodes inserted on its segments since (:meth:`split_segments`) put
        in their places: e.g. the current outline of a body."""
        tri = self.triangulation
        nb: Dict[tuple, list] = {}
        for (i, j), s in zip(tri.segments.tolist(), tri.segment_source.tolist()):
            nb.setdefault((i, s), []).append(j)
            nb.setdefault((j, s), []).append(i)
        sources = {}
        for (i, s) in nb:
            sources.setdefault(i, set()).add(s)
        nodes = [int(v) for v in nodes]
        out = [nodes[0]]
        for a, b in zip(nodes, nodes[1:] + nodes[:1] if closed else nodes[1:]):
            for s in sorted(sources.get(a, set()) & sources.get(b, set())):
                path = self._walk(nb, a, b, s)
                if path is not None:
                    out += path[1:]
                    break
            else:  # pieces of other sources since a merge (merge_nodes)
                path = self.walk_segments(a, b, set(nodes))
                if path is None:
                    raise ValueError(f"nodes {a} and {b} are not joined by segments")
                out += path[1:]
        return np.array(out[:-1] if closed else out, dtype=np.int64)

    @staticmethod
    def _walk(nb, a, b, s):
        """The shortest path from a to b along the segments of source s, or None (both
        ways are tried: segments given the same source when a loop was cut or closed
        can close a loop of their own)."""
        best = None
        for first in nb.get((a, s), []):
            path = [a, first]
            while path[-1] != b and len(path) <= len(nb):
                step = [v for v in nb.get((path[-1], s), []) if v != path[-2]]
                if not step:
                    break
                path.append(step[0])
            if path[-1] == b and (best is None or len(path) < len(best)):
                best = path
        return best

    # -- checkpoints -------------------------------------------------------------
    def save(self, path) -> None:
        """Write the whole state to ``path`` (.npz), atomically (temporary file
        in the same folder, then rename)."""
        path = os.fspath(path)
        meta = {"time": self.time, "step": self.step, "remap": self.remap, "walls": self.walls,
                "node_fields": list(self.node_fields), "ip_fields": list(self.ip_fields),
                "history": self.history, "format": 1,
                "spacing": "carried" if self._spacing_fn is None else "callable"}
        arrays = {"nodes": self.nodes, "triangles": self.triangles,
                  "neighbours": self.triangulation.neighbours, "target_spacing": self._target,
                  "on_wall": self._on_wall, "box_lo": self._box[0], "box_hi": self._box[1],
                  "segments": self.triangulation.segments,
                  "segment_source": self.triangulation.segment_source,
                  "segment_ref": self._segment_ref, "meta": np.array(json.dumps(meta))}
        arrays.update({f"node__{k}": v for k, v in self.node_fields.items()})
        arrays.update({f"ip__{k}": v for k, v in self.ip_fields.items()})
        save_npz_atomically(path, arrays)

    @classmethod
    def load(cls, path, spacing: Optional[Callable[[np.ndarray], np.ndarray]] = None
             ) -> "LagrangianMesh":
        """Restore a mesh written by :meth:`save`; continuing from it gives
        bit-identical results to a run that never stopped. A mesh made with a callable
        ``spacing`` needs it again (a function is not stored); ``ValueError`` if it is
        missing."""
        if spacing is not None and not callable(spacing):
            raise TypeError(f"spacing must be None or a callable x (n, 2) -> (n,), got "
                            f"{type(spacing).__name__}")
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            self = cls.__new__(cls)
            seg = {k: z[k] for k in ("segments", "segment_source") if k in z.files}
            tri = Triangulation.from_arrays(z["nodes"], z["triangles"], z["neighbours"],
                                            **seg)
            self._segment_ref = z["segment_ref"].copy() if "segment_ref" in z.files \
                else np.zeros(0)
            self.triangulation = tri
            self.remap = meta["remap"]
            self.walls = meta["walls"]
            self.node_fields = {k: z[f"node__{k}"].copy() for k in meta["node_fields"]}
            self.ip_fields = {k: z[f"ip__{k}"].copy() for k in meta["ip_fields"]}
            self._spacing_fn = spacing
            if meta.get("spacing") == "callable" and spacing is None:
                raise ValueError(f"{os.fspath(path)!r} was written with a callable target "
                                 f"spacing: pass it again, load(path, spacing=...)")
            if spacing is not None:
                self._target = self._spacing_at_nodes()
            elif "target_spacing" in z.files:
                self._target = z["target_spacing"].copy()
            else:  # (checkpoints before the target spacing: the reference areas)
                self._target = spacing_from_areas(z["ref_area"], self._fractions())
            self._on_wall = z["on_wall"].copy()
            self._box = (z["box_lo"].copy(), z["box_hi"].copy())
            self.time = meta["time"]
            self.step = meta["step"]
            self.history = meta["history"]
            self.node_map = np.arange(tri.npoints)
            self._version = 0
            self._cache, self._previous = {}, {}
            self._touched = []
        return self
