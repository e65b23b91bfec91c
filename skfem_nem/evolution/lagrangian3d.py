"""The evolving mesh in 3D: nodes carried by a flow, the Delaunay tetrahedra repaired locally.

The paper rebuilt the 3D Delaunay triangulation every step ("there is, as yet, no direct
extension of the 2D flip operation in three dimensions"). :class:`LagrangianMesh3D` keeps

* the node positions, moved by the same iterative predictor-corrector
  (trapezoidal) update as :class:`~skfem_nem.LagrangianMesh`, with the walls
  of the initial bounding box kept exactly (free slip), and a node that comes closer to
  a wall than :data:`WALL_SNAP` of the box put on it;
* named node fields (scalar-only memory: viscosity, density, material id,
  initial position, temperature, ...) that travel with their nodes unchanged:
  a node's row never moves to another node and is never interpolated (a node added where
  the flow stretches the mesh, :mod:`.injection3d`, takes their Sibson interpolant);
* the Delaunay tetrahedralisation of the current nodes, repaired after every step by
  :meth:`~skfem_nem.geometry.delaunay3d.Delaunay3D.moved` (exact flips, and nodes removed and
  re-inserted where flips cannot mend; the result is what a fresh build gives, with no flat
  tetrahedra, also where wall nodes slide into co-circular patterns) and checked: every node
  stays a vertex (a step after which two nodes coincide is refused with the nodes named and
  the state left as it was).

Integration-point fields (a stress history) go past the paper's scalar-only memory: one
value per vertex cell of each tetrahedron, carried across each step's repair by the
averaging or the conservative rule of :mod:`.remap3d`.
"""
from __future__ import annotations

import json
import os
from typing import Callable, Dict, Optional

import numpy as np

from ..basis import NaturalNeighbourBasis
from .injection3d import Injection3D, initial_spacing
from .remap3d import (REMAP_RULES, cell_points, cell_volumes, check_ip_fields, match_rows,
                      remap_fields)
from .stepping import LagrangianStep, StepTooLong, check_node_fields, save_npz_atomically
from ..geometry.meshes import delaunay_mesh, triangulation_mesh, triangulation_of

#: a node closer to a wall than this times the box's size is put on the wall (and stays
#: there, free slip). Nodes pushed towards a wall approach it geometrically
#: (:data:`~skfem_nem.evolution.stepping.WALL_REACH`); 1e-11 above it they made tetrahedra
#: nearly, not exactly, in its plane, whose coordinates and faces lose every digit (a 3D
#: plate pressed onto the bottom wall stopped there). 1e-8 of the box moves a node by far
#: less than any length the mesh resolves.
WALL_SNAP = 1e-8

__all__ = ["LagrangianMesh3D"]


class LagrangianMesh3D(LagrangianStep, Injection3D):
    """A 3D node set carried by a flow, its Delaunay tetrahedra repaired every step.

    Parameters
    ----------
    nodes
        (n, 3) initial node positions (length units of the problem).
    node_fields
        Named arrays with one row per node, shape (n, ...): carried with the
        nodes, never interpolated.
    walls
        ``"box"`` (default): nodes on the bounding box of the initial nodes
        keep their wall coordinate exactly (free slip); ``None``: no
        constraint.
    ip_fields
        Named arrays of shape (ntetrahedra, 4, ...): one value per vertex cell of
        each tetrahedron of ``mesh`` (points: :meth:`ip_points`), carried across
        the repairs by :mod:`~skfem_nem.evolution.remap3d`.
    remap
        ``"conservative"`` (default: each changed region's integral kept to
        round-off) or ``"average"`` (values within the old ones' range).

    Attributes
    ----------
    nodes (n, 3), mesh (the current ``MeshTet``), node_fields, time, step,
    history (per-step dicts: step, time, dt, iterations, converged, the repair's
    flips, relocated, rebuilt and repair_seconds, tetrahedra,
    tetrahedra_changed: how many of the new tetrahedra were not
    in the previous triangulation, injected and removed: the nodes added and
    removed), target_spacing, node_map (the last step's: each node's index after it,
    -1 if removed; nodes added come after the others).

    Raises
    ------
    ValueError
        For bad nodes or fields (naming the node or the field), a velocity of
        the wrong shape or with non-finite values (naming the node), nodes
        leaving the box, and steps after which two nodes coincide.
    """

    def __init__(self, nodes, node_fields: Optional[Dict[str, np.ndarray]] = None,
                 walls: Optional[str] = "box",
                 ip_fields: Optional[Dict[str, np.ndarray]] = None,
                 remap: str = "conservative"):
        if walls not in ("box", None):
            raise ValueError(f"walls must be 'box' or None, got {walls!r}")
        if remap not in REMAP_RULES:
            raise ValueError(f"remap must be one of {REMAP_RULES}, got {remap!r}")
        self._mesh = delaunay_mesh(nodes)
        p = self.nodes
        self.walls = walls
        self.remap = remap
        self.node_fields = check_node_fields(node_fields, p.shape[0])
        self.ip_fields = check_ip_fields(ip_fields, self._mesh.t.shape[1])
        lo, hi = p.min(axis=0), p.max(axis=0)
        self._box = (lo, hi)
        self._on_wall = (p == lo) | (p == hi) if walls == "box" else None
        self._target = initial_spacing(p, self._mesh.t.T)
        self.node_map = np.arange(p.shape[0])
        self.time = 0.0
        self.step = 0
        self.history = []
        self._bases = {}

    @property
    def nodes(self) -> np.ndarray:
        """(n, 3) current node positions (a read-only view)."""
        p = self._mesh.p.T
        p.flags.writeable = False
        return p

    @property
    def mesh(self):
        """The current Delaunay ``MeshTet`` (node i is node i of the set)."""
        return self._mesh

    def basis(self, elem=None, **kwargs) -> NaturalNeighbourBasis:
        """A :class:`~skfem_nem.NaturalNeighbourBasis` on the current mesh
        (cached until the next step); ``kwargs`` go to the basis."""
        key = (repr(elem), tuple(sorted(kwargs.items())))
        if key not in self._bases:
            self._bases[key] = NaturalNeighbourBasis(self._mesh, elem, **kwargs)
        return self._bases[key]

    def ip_points(self) -> np.ndarray:
        """(ntetrahedra, 4, 3) the points of the integration-point fields: one per vertex
        cell of each tetrahedron (row t of ``mesh.t.T``, vertex order as there)."""
        return cell_points(self.nodes, self._mesh.t.T)

    def ip_integral(self, name: str) -> np.ndarray:
        """The integral of integration-point field ``name`` over the mesh (each value
        times its cell's volume, a quarter of its tetrahedron's)."""
        f = self.ip_fields[name]
        w = cell_volumes(self.nodes, self._mesh.t.T)
        return np.einsum("t,tk...->...", w, f)

    def ip_at_nodes(self, name: str) -> np.ndarray:
        """Integration-point field ``name`` at the nodes, (n, ...): the mean of the vertex
        cells around each node weighted by their volumes (for output and figures)."""
        f = self.ip_fields[name]
        t = self._mesh.t.T
        w = np.repeat(cell_volumes(self.nodes, t), 4)
        n = self.nodes.shape[0]
        flat = f.reshape(f.shape[0] * 4, -1)
        out = np.stack([np.bincount(t.ravel(), w * flat[:, k], n) for k in range(flat.shape[1])],
                       axis=-1) / np.bincount(t.ravel(), w, n)[:, None]
        return out.reshape((n,) + f.shape[2:])

    def interpolate(self, name: str, x) -> np.ndarray:
        """Values of node field ``name`` at points x (m, 3) by Sibson
        interpolation on the current mesh: (m, ...)."""
        f = self.node_fields[name]
        P = self.basis().probes(np.asarray(x, dtype=float).T)
        return (P @ f.reshape(f.shape[0], -1)).reshape((P.shape[0],) + f.shape[1:])

    def max_dt(self, velocity_values: np.ndarray, fraction: float = 0.1) -> float:
        """Largest dt keeping each node's displacement below ``fraction`` of the
        shortest edge at the node, for nodal velocities (n, 3)."""
        t = self._mesh.t.T
        p = self.nodes
        e = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
        L = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
        h = np.full(p.shape[0], np.inf)
        np.minimum.at(h, e[:, 0], L)
        np.minimum.at(h, e[:, 1], L)
        speed = np.linalg.norm(np.asarray(velocity_values, dtype=float), axis=1)
        with np.errstate(divide="ignore"):
            return float((fraction * h / speed).min())

    def advance(self, velocity: Callable[[np.ndarray], np.ndarray], dt: float,
                tol: float = 1e-10, maxiter: int = 10, inject: Optional[float] = None,
                remove: Optional[float] = None) -> dict:
        """Move the nodes by one step and repair the Delaunay tetrahedra.

        ``velocity(x)`` -> (n, 3) nodal velocities at positions x (n, 3) (for
        a NEM solution: ``basis.probes(x.T) @ u`` per component, or the nodal
        values themselves when the field is known at the moving nodes).
        ``tol``, ``maxiter``: the predictor-corrector, as in
        :meth:`skfem_nem.LagrangianMesh.advance`. ``inject``: after the repair, split the
        edges longer than this many target spacings (:meth:`split_long_edges`; None: no
        nodes added); ``remove``: then remove the nodes closer to a neighbour than this
        fraction of their target spacing (:meth:`remove_crowded`; None: none removed).
        Returns the step's report (also appended to ``history``; ``injected`` and
        ``removed``: the nodes added and removed; :attr:`node_map`: each node's index
        after the step); on error nothing changes.
        """
        return self.step_transaction(velocity, dt, tol, maxiter, inject=inject, remove=remove)

    def _state(self):
        return {"mesh": self._mesh, "bases": self._bases, "time": self.time,
                "step": self.step, "on_wall": self._on_wall, "ip_fields": self.ip_fields,
                "node_fields": self.node_fields, "target": self._target,
                "node_map": self.node_map}

    def _restore(self, state):
        self._mesh, self._bases = state["mesh"], state["bases"]
        self.ip_fields, self.node_fields = state["ip_fields"], state["node_fields"]
        self._target, self.node_map = state["target"], state["node_map"]
        self.time, self.step = state["time"], state["step"]
        self._on_wall = state["on_wall"]

    def save(self, path) -> None:
        """Write the whole state to ``path`` (.npz), atomically: nodes, tetrahedra, node and
        integration-point fields, walls, clock and history."""
        meta = {"time": self.time, "step": self.step, "remap": self.remap, "walls": self.walls,
                "node_fields": list(self.node_fields), "ip_fields": list(self.ip_fields),
                "history": self.history, "format": 1}
        arrays = {"nodes": self.nodes, "tetrahedra": self._mesh.t.T, "target": self._target,
                  "box_lo": self._box[0], "box_hi": self._box[1],
                  "meta": np.array(json.dumps(meta))}
        if self._on_wall is not None:
            arrays["on_wall"] = self._on_wall
        arrays.update({f"node__{k}": v for k, v in self.node_fields.items()})
        arrays.update({f"ip__{k}": v for k, v in self.ip_fields.items()})
        save_npz_atomically(path, arrays)

    @classmethod
    def load(cls, path) -> "LagrangianMesh3D":
        """Restore a mesh written by :meth:`save`. The tetrahedra are built again from the
        nodes (the same ones: the Delaunay tetrahedralisation is unique) and the
        integration-point values follow their tetrahedra and vertices."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            self = cls(z["nodes"], {k: z[f"node__{k}"] for k in meta["node_fields"]},
                       walls=meta["walls"], remap=meta["remap"])
            old = z["tetrahedra"]
            ip = {k: z[f"ip__{k}"].copy() for k in meta["ip_fields"]}
            self._box = (z["box_lo"].copy(), z["box_hi"].copy())
            self._on_wall = z["on_wall"].copy() if "on_wall" in z.files else None
            if "target" in z.files:  # (earlier files: the saved nodes' own spacing)
                self._target = z["target"].copy()
        self.ip_fields, moved = remap_fields(self.nodes, old, self._mesh.t.T, ip, self.remap)
        if moved:
            raise ValueError(f"{os.fspath(path)!r}: {moved} tetrahedra of the saved mesh are "
                             "not those of its nodes (not written by LagrangianMesh3D.save?)")
        self.time, self.step, self.history = meta["time"], meta["step"], meta["history"]
        return self

    def _snapped(self, x):
        """x with the nodes closer to a wall than :data:`WALL_SNAP` of the box put on it
        (wall nodes from now on), and how many were."""
        if self._on_wall is None:
            return x, 0
        lo, hi = self._box
        gap = WALL_SNAP * float(np.max(hi - lo))
        x = np.where(x - lo < gap, lo, np.where(hi - x < gap, hi, x))
        on_wall = (x == lo) | (x == hi)
        new = int(np.count_nonzero((on_wall & ~self._on_wall).any(axis=1)))
        self._on_wall = on_wall
        return x, new

    def _repair(self, x0, x, dt, max_substeps, inject, remove=None):
        """Repair the tetrahedra for the moved nodes (flips, and nodes relocated where flips
        cannot mend); every node must stay a vertex."""
        x, snapped = self._snapped(x)
        try:
            tri, report = triangulation_of(self._mesh).moved(x)
        except ValueError as err:
            raise StepTooLong(f"step {self.step + 1}: the moved nodes cannot be "
                              f"triangulated without losing a node ({err}); reduce dt") from None
        mesh = triangulation_mesh(tri)
        new = mesh.t.T
        kept = match_rows(self._mesh.t.T, new)[0]
        if self.ip_fields:
            self.ip_fields, report["remapped"] = remap_fields(
                x, self._mesh.t.T, new, self.ip_fields, self.remap)
        self._mesh = mesh
        self._bases = {}
        self.time += dt
        self.step += 1
        n = x.shape[0]
        injected = 0 if inject is None else self.split_long_edges(inject)
        node_map = np.arange(n) if remove is None else self.remove_crowded(remove)[:n]
        self.node_map = node_map
        return dict(report, tetrahedra=int(self._mesh.t.shape[1]),
                    tetrahedra_changed=int(np.count_nonzero(~kept)), snapped=snapped,
                    injected=injected, removed=int(np.count_nonzero(node_map < 0)))

