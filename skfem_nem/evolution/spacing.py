"""The target node spacing of an evolving mesh: the resolution a run keeps from start to end.

Injection and removal compare the mesh with a target spacing h per node, fixed for the
whole run: by default the initial node set's own spacing, carried by the material (a node
keeps its value, an injected node gets the natural-neighbour interpolant of its material's
values), or a callable h(x) of the position. A reference that follows the mesh instead (a
node's area taken as its new reference after each injection it triggered) drifts: where
the flow stretches a region, the references grow with it, removal compares crowding with
the grown ones, and a stretched region ends up covered by fans of triangles a third of the
box long.

Three rules hold the nodes to the target, with a wide band between adding and removing so
that neither undoes the other (hysteresis):

* a node's Voronoi area above ``inject`` times its target area gets a node (injection);
* an edge longer than :data:`EDGE_FACTOR` target spacings is split at its midpoint (the
  quality bound: inside, on walls and on segments);
* a node whose spacing fell below a fifth of its target is removed (merging).
"""
from __future__ import annotations

import numpy as np

from ..coordinates import sibson_coordinates
from .quality import cross

__all__ = ["SpacingTarget", "AREA_PER_SPACING2", "EDGE_FACTOR", "SPLIT_CLEARANCE",
           "SMOOTHING_ROUNDS", "angle_fractions", "spacing_from_areas", "smoothed_spacing",
           "reference_areas", "check_spacing"]

#: Voronoi-cell area of a node of the equilateral lattice of edge h, over h^2: a target
#: spacing h means a target area of sqrt(3)/2 h^2 for an interior node
AREA_PER_SPACING2 = np.sqrt(3.0) / 2.0
#: the quality bound: an edge longer than this many target spacings (the larger of its two
#: nodes') is split. The initial random node sets of the sinking plate have edges up to
#: 2.3-2.6 of it (300 to 3,000 nodes, seeds 0 and 4): a bound above that leaves a drawn
#: node set as it is, and splitting an edge at it leaves halves of 1.5 target spacings,
#: far above the removal threshold (merging.CLUSTER_FRACTION)
EDGE_FACTOR = 3.0
#: a long edge is split only where its midpoint is at least this many target spacings from
#: the two nodes opposite the edge: across a flat triangle the opposite node already
#: resolves the edge (a node next to it would be crowded, and removed again)
SPLIT_CLEARANCE = 0.5
#: the initial spacing is averaged over each node's neighbours this many times: the
#: Voronoi cells of random nodes vary 3-4 fold in area, and a target that kept each
#: cell's own size would inject wherever the flow hands a small cell's node a typical one
SMOOTHING_ROUNDS = 2


def angle_fractions(P: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(n,) each node's share of a full turn: the sum of its triangles' angles over 2 pi
    (1 inside, 1/2 on a straight hull edge, 1/4 at a box corner): the part of a whole
    Voronoi cell that :meth:`~.lagrangian.LagrangianMesh.node_areas` gives it."""
    out = np.zeros(P.shape[0])
    for k in range(3):
        u = P[T[:, (k + 1) % 3]] - P[T[:, k]]
        v = P[T[:, (k + 2) % 3]] - P[T[:, k]]
        np.add.at(out, T[:, k], np.arctan2(np.abs(cross(u, v)), (u * v).sum(axis=1)))
    return out / (2.0 * np.pi)


def spacing_from_areas(areas: np.ndarray, fractions: np.ndarray) -> np.ndarray:
    """(n,) the spacing of the equilateral lattice whose cells have the nodes' ``areas``
    (parts ``fractions`` of whole cells on the hull)."""
    return np.sqrt(np.maximum(areas, 0.0) / (AREA_PER_SPACING2 * fractions))


def smoothed_spacing(h: np.ndarray, edges: np.ndarray, rounds: int = SMOOTHING_ROUNDS
                     ) -> np.ndarray:
    """(n,) the spacings ``h`` averaged (as areas, h^2) over each node and its neighbours
    along ``edges`` (k, 2), ``rounds`` times: the local density of a drawn node set rather
    than the size of each random cell."""
    h2 = np.asarray(h, dtype=float) ** 2
    count = 1.0 + np.bincount(edges.ravel(), minlength=h2.size)
    for _ in range(rounds):
        total = h2.copy()
        np.add.at(total, edges[:, 0], h2[edges[:, 1]])
        np.add.at(total, edges[:, 1], h2[edges[:, 0]])
        h2 = total / count
    return np.sqrt(h2)


def reference_areas(h: np.ndarray, fractions: np.ndarray) -> np.ndarray:
    """(n,) the node areas that the target spacings ``h`` mean (parts ``fractions`` of
    whole cells on the hull): what injection and removal compare the node areas with."""
    return AREA_PER_SPACING2 * fractions * h * h


def check_spacing(h, n: int, name: str = "spacing") -> np.ndarray:
    """A float copy of the target spacings ``h`` (n,), checked positive and finite
    (``ValueError`` naming the first bad node)."""
    a = np.array(h, dtype=float, copy=True)
    if a.shape != (n,):
        raise ValueError(f"{name} gave shape {a.shape}, expected ({n},): one spacing per node")
    bad = np.flatnonzero(~(np.isfinite(a) & (a > 0)))
    if bad.size:
        raise ValueError(f"{name} must be positive and finite: {a[bad[0]]!r} at node "
                         f"{bad[0]} ({bad.size} node(s))")
    return a


class SpacingTarget:
    """The target spacing of :class:`~skfem_nem.evolution.lagrangian.LagrangianMesh` (which
    provides the nodes, triangles, node areas and ``_target``, ``_spacing_fn``): the
    per-node targets, their areas, and the targets of new nodes."""

    @property
    def target_spacing(self) -> np.ndarray:
        """(n,) read-only: the target spacing of each node (the ``spacing`` given, or the
        initial node set's, carried by the material)."""
        out = self._target.copy()
        out.flags.writeable = False
        return out

    def reference_areas(self) -> np.ndarray:
        """(n,) the node areas (:meth:`node_areas`) that the target spacing means: the
        equilateral lattice's cell area, the part of it inside the hull on the hull."""
        return reference_areas(self._target, self._fractions())

    def _initial_spacing(self):
        """The default target: each node's own spacing, or its neighbourhood's where that
        is larger (a small random cell does not make a fine target: its node would get
        nodes injected wherever the flow hands it a typical cell; a drawn node set is
        within its own target, nothing is injected before the flow moves it)."""
        own = spacing_from_areas(self.node_areas(), self._fractions())
        return np.maximum(own, smoothed_spacing(own, self.triangulation.edges))

    def _fractions(self):
        return angle_fractions(self.nodes, self.triangles)

    def _spacing_at_nodes(self):
        return check_spacing(self._spacing_fn(self.nodes.copy()), self.triangulation.npoints,
                             "spacing(x)")

    def _refresh_target(self):
        """A callable target evaluated at the nodes where they are now (a carried one
        stays)."""
        if self._spacing_fn is not None:
            self._target = self._spacing_at_nodes()

    def _targets_at(self, x, Phi=None):
        """Target spacings for new nodes at x (k, 2): the callable's values, or the
        natural-neighbour interpolant ``Phi`` (k, n) of the carried ones."""
        if self._spacing_fn is not None:
            return check_spacing(self._spacing_fn(np.array(x)), x.shape[0], "spacing(x)")
        if Phi is None:
            Phi = sibson_coordinates(self.triangulation, x)
        return Phi @ self._target
