"""Nodes added to the 3D evolving mesh where the flow stretches it (long edges split), and
taken away where it crowds them.

Why: nodes that move with a flow drift apart where it stretches, and the tetrahedra there
grow until a handful of nodes resolve a whole region (the 2D plate lost a third of its
resolution that way, docs/sinking_plate.md). The 3D mesh keeps a target spacing per node
for the whole run, the initial node set's own (its mean edge length, averaged over the
neighbours as in :mod:`.spacing`), carried with the material: an added node takes the
natural-neighbour interpolant of its neighbours' targets. An edge longer than ``factor``
target spacings (the larger of its two nodes') is split at its midpoint. A midpoint of two
nodes on one wall lies on that wall exactly, so the walls are refined too and the new node
slides along them like the others.

Each added node is inserted into the tetrahedralisation
(:meth:`~skfem_nem.geometry.delaunay3d.Delaunay3D.inserted`: only its conflict region
changes, the result is a fresh build's); its node fields are the Sibson interpolant of the
fields at its position (an indicator such as a material id becomes a fraction at a material
edge), the integration-point fields of the changed tetrahedra are remapped as after a flip
(:mod:`.remap3d`: the conservative rule keeps their integrals).

A node closer to a neighbour than ``fraction`` (default :data:`MERGE_FRACTION_3D`) of their
smaller target spacing is removed (the interior one of the pair where one is on a wall;
never a box corner, which holds the hull): its hole is filled by the Delaunay
tetrahedralisation of its neighbours (:meth:`~skfem_nem.geometry.delaunay3d.Delaunay3D.removed`),
the nodes after it are renumbered (``node_map``), and the integration-point fields of the
changed tetrahedra are remapped as above. The band between a fifth and three target
spacings keeps adding and removing from undoing each other.
"""
from __future__ import annotations

import numpy as np

from ..coordinates import sibson_coordinates
from ..geometry.entities import unique_ints
from ..geometry.meshes import triangulation_mesh, triangulation_of
from .remap3d import remap_fields
from .spacing import smoothed_spacing

__all__ = ["Injection3D", "MERGE_FRACTION_3D", "SPLIT_FACTOR_3D", "SPLIT_PASSES_3D",
           "tet_edges"]

#: an edge longer than this many target spacings is split. In the initial random 3D node
#: sets of the sinking plate (1,500 to 10,000 nodes, seeds 0 and 1) 99.9% of the edges are
#: below 2.6 smoothed spacings (the rest, up to 5.3, near the walls: the targets there are
#: raised to keep them, :func:`initial_spacing`)
SPLIT_FACTOR_3D = 3.0
#: a node closer to a neighbour than this fraction of their smaller target spacing is
#: removed (the 2D mesh's removal threshold, :mod:`.spacing`)
MERGE_FRACTION_3D = 0.2
#: rounds of splitting (and of removal) in one call (each splits a set of edges with no
#: node in common)
SPLIT_PASSES_3D = 3


def tet_edges(t: np.ndarray) -> np.ndarray:
    """(k, 2) the edges of tetrahedra t (m, 4), each once, lower node first, in
    lexicographic order. Each edge is one integer key ``lo n + hi``, made distinct by one
    sort (:func:`~skfem_nem.geometry.entities.unique_ints`): ``np.unique``'s rows mode
    sorts the rows as opaque records, 1.14 s against 0.28 s on the 1.2 million edges of
    30,000 nodes (twice a plate step), and its 1D mode hashes, 0.6 s."""
    e = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
    e.sort(axis=1)
    n = int(t.max()) + 1 if t.size else 1
    key = unique_ints(e[:, 0].astype(np.int64) * n + e[:, 1])
    return np.stack([key // n, key % n], axis=1).astype(t.dtype, copy=False)


def initial_spacing(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n,) each node's target: its mean edge length averaged over its neighbours
    (:func:`~.spacing.smoothed_spacing`), and at least its longest edge over
    :data:`SPLIT_FACTOR_3D`, so that the default splitting leaves the initial node set as
    it is (random sets have a few edges of up to 5 smoothed spacings, near the walls)."""
    e = tet_edges(t)
    length = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
    n = p.shape[0]
    mean = (np.bincount(e[:, 0], length, n) + np.bincount(e[:, 1], length, n)) / \
        np.maximum(np.bincount(e.ravel(), minlength=n), 1)
    longest = np.zeros(n)
    np.maximum.at(longest, e[:, 0], length)
    np.maximum.at(longest, e[:, 1], length)
    return np.maximum(smoothed_spacing(mean, e), longest / SPLIT_FACTOR_3D)


class Injection3D:
    """Node injection of :class:`~skfem_nem.LagrangianMesh3D` (which provides the nodes,
    the mesh, node and integration-point fields, walls and ``_target``)."""

    @property
    def target_spacing(self) -> np.ndarray:
        """(n,) read-only: each node's target spacing (the initial node set's, carried by
        the material)."""
        h = self._target.view()
        h.flags.writeable = False
        return h

    def long_edges(self, factor: float = SPLIT_FACTOR_3D) -> np.ndarray:
        """(k, 2) the edges longer than ``factor`` target spacings, longest (relative to
        the target) first."""
        p, h = self.nodes, self._target
        e = tet_edges(self.mesh.t.T)
        ratio = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1) / np.maximum(h[e[:, 0]],
                                                                             h[e[:, 1]])
        long = np.flatnonzero(ratio > factor)
        return e[long[np.argsort(-ratio[long], kind="stable")]]

    def split_long_edges(self, factor: float = SPLIT_FACTOR_3D,
                         passes: int = SPLIT_PASSES_3D) -> int:
        """Split the edges longer than ``factor`` target spacings at their midpoints, in
        rounds of edges with no node in common (longest first); returns the nodes added.
        ``ValueError`` unless ``factor`` is a number above 1."""
        if not (isinstance(factor, (int, float)) and np.isfinite(factor) and factor > 1):
            raise ValueError(f"factor must be a number above 1, got {factor!r}")
        added = 0
        for _ in range(passes):
            e = self.long_edges(factor)
            if not e.size:
                break
            used = np.zeros(self.nodes.shape[0], bool)
            pick = []
            for a, b in e:              # a greedy set of edges with no node in common
                if not (used[a] or used[b]):
                    used[a] = used[b] = True
                    pick.append((a, b))
            pick = np.array(pick)
            p = self.nodes
            self.insert_nodes(0.5 * (p[pick[:, 0]] + p[pick[:, 1]]))
            added += pick.shape[0]
        return added

    def insert_nodes(self, x) -> None:
        """Add nodes at the points x (k, 3) inside the box: node fields and targets by
        Sibson interpolation there, the tetrahedralisation and the integration-point
        fields updated (module docstring). ``ValueError`` naming the point for one outside
        the box or on a node; nothing changes then."""
        x = np.array(x, dtype=float, ndmin=2)
        lo, hi = self._box
        out = np.flatnonzero(~((x >= lo) & (x <= hi)).all(axis=1))
        if out.size:
            raise ValueError(f"points[{out[0]}] = {x[out[0]].tolist()} lies outside the box "
                             f"{lo.tolist()} .. {hi.tolist()}")
        tri = triangulation_of(self._mesh).inserted(x)
        Phi = sibson_coordinates(triangulation_of(self._mesh), x)
        mesh = triangulation_mesh(tri)
        p = mesh.p.T
        if self.ip_fields:
            self.ip_fields = remap_fields(p, self._mesh.t.T, mesh.t.T, self.ip_fields,
                                          self.remap)[0]
        self.node_fields = {k: np.concatenate([f, (Phi @ f.reshape(f.shape[0], -1)).reshape(
            (x.shape[0],) + f.shape[1:])]) for k, f in self.node_fields.items()}
        self._target = np.concatenate([self._target, Phi @ self._target])
        if self._on_wall is not None:
            self._on_wall = np.concatenate([self._on_wall, (x == lo) | (x == hi)])
        self._mesh = mesh
        self._bases = {}

    def remove_nodes(self, indices) -> np.ndarray:
        """Remove the nodes ``indices`` (module docstring); returns the node map (n,): each
        old node's new index, -1 for a removed one. ``ValueError`` naming the node for an
        index out of range or repeated, a box corner, or a node that cannot be removed;
        nothing changes then."""
        idx = np.asarray(indices, dtype=np.int64).ravel()
        n = self.nodes.shape[0]
        if self._on_wall is not None and idx.size and np.all((idx >= 0) & (idx < n)):
            corner = idx[self._on_wall[idx].sum(axis=1) == 3]
            if corner.size:
                raise ValueError(f"node {int(corner[0])} is a corner of the box (it holds the "
                                 "hull) and cannot be removed")
        tri = triangulation_of(self._mesh).removed(idx)
        mesh = triangulation_mesh(tri)
        keep = np.ones(n, bool)
        keep[idx] = False
        kept = np.flatnonzero(keep)
        if self.ip_fields:
            self.ip_fields = remap_fields(self.nodes, self._mesh.t.T, kept[mesh.t.T],
                                          self.ip_fields, self.remap)[0]
        self.node_fields = {k: f[keep] for k, f in self.node_fields.items()}
        self._target = self._target[keep]
        if self._on_wall is not None:
            self._on_wall = self._on_wall[keep]
        self._mesh = mesh
        self._bases = {}
        node_map = np.full(n, -1, np.int64)
        node_map[kept] = np.arange(kept.size)
        return node_map

    def crowded_nodes(self, fraction: float = MERGE_FRACTION_3D) -> np.ndarray:
        """The nodes :meth:`remove_crowded` would remove: of each edge shorter than
        ``fraction`` of its nodes' smaller target spacing (closest first, no node in two
        such edges), the node on fewer walls (the higher index on a tie), never a corner."""
        p, h = self.nodes, self._target
        e = tet_edges(self.mesh.t.T)
        ratio = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1) / np.minimum(h[e[:, 0]],
                                                                             h[e[:, 1]])
        short = np.flatnonzero(ratio < fraction)
        walls = (np.zeros(p.shape[0], int) if self._on_wall is None
                 else self._on_wall.sum(axis=1))
        used = np.zeros(p.shape[0], bool)
        out = []
        for a, b in e[short[np.argsort(ratio[short], kind="stable")]]:
            if used[a] or used[b]:
                continue
            used[a] = used[b] = True
            v = a if walls[a] < walls[b] else b
            if walls[v] < 3:
                out.append(v)
        return np.array(out, dtype=np.int64)

    def remove_crowded(self, fraction: float = MERGE_FRACTION_3D,
                       passes: int = SPLIT_PASSES_3D) -> np.ndarray:
        """Remove the nodes of :meth:`crowded_nodes`, in up to ``passes`` rounds (a node in
        two short edges, or a short edge a removal made, waits for the next); returns the
        node map (as :meth:`remove_nodes`). ``ValueError`` unless ``fraction`` is in (0, 1)."""
        if not (isinstance(fraction, (int, float)) and 0 < fraction < 1):
            raise ValueError(f"fraction must be a number in (0, 1), got {fraction!r}")
        node_map = np.arange(self.nodes.shape[0])
        for _ in range(passes):
            idx = self.crowded_nodes(fraction)
            if not idx.size:
                break
            step = self.remove_nodes(idx)
            node_map = np.where(node_map >= 0, step[np.maximum(node_map, 0)], -1)
        return node_map
