"""The sinking plate in three dimensions: a dense viscous slab sinking through a
two-layer fluid in a box, on nodes that move with the flow.

The paper's 3D programme ("all the theory described is equally valid in three
dimensions"), with its restriction: scalar-only memory. The nodes carry their material
(the plate indicator, the height they started at, which picks the fluid layer) and move
with the flow (:class:`~skfem_nem.LagrangianMesh3D`: the iterative predictor-corrector,
the walls kept exactly, the Delaunay tetrahedra repaired by exact flips after every step).
Each step solves the Stokes problem on the current tetrahedra
(:func:`~skfem_nem.models.stokes.stokes_spaces`: natural-neighbour velocity with condensed
bubbles, P1 pressure; FGMRES with AMG) with the viscosity and the buoyancy interpolated
from the nodes, free slip on all six walls. The plate is viscous (``plate_viscosity``):
the tensor memory (``LagrangianMesh3D(ip_fields=...)``) and ``vep_step`` on tetrahedra
exist, but this run does not use them yet.

Outputs (in the output folder), as the 2D plate's: ``plate_NNNNN.vtu`` per output time
and ``plate.pvd`` (ParaView; point data velocity, pressure, material, initial height),
``diagnostics.csv`` (one row per step), ``slices.png`` (the material in a vertical and a
horizontal slice through the plate at the start and the end), ``diagnostics.png``,
``checkpoint.npz`` + ``checkpoint.json`` (restart).
"""
from __future__ import annotations

import json
import math
import time as _time
from dataclasses import asdict
from pathlib import Path
from typing import Optional

import numpy as np

from ..evolution.lagrangian3d import LagrangianMesh3D
from ..evolution.stepping import StepTooLong
from ..geometry.nodesets3d import box_nodes_3d
from ..models.stokes import solve_stokes, stokes_spaces
from ..models.stokes_solvers import CACHED_SOLVERS, StokesCache
from .output import (CSVLog, PVDWriter, atomic_write_text, next_output_time,
                     progress_bar, write_vtu)
from .plate3d_config import Plate3DConfig
from .plate3d_figures import plate3d_figures
from .plate_config import stored_config

__all__ = ["SinkingPlate3D"]

#: spacing of the nodes on the box faces, as a fraction of the box height (the far field)
WALL_SPACING = 0.25
#: halvings of a step's dt before the run stops (a move that makes two nodes coincide, or a
#: predictor-corrector that does not converge)
RETRIES = 6


def plate_box(c: Plate3DConfig):
    """The plate's lowest and highest corners (3,), (3,)."""
    centre = np.array([c.plate_x, c.plate_y, c.plate_z])
    half = 0.5 * np.array([c.plate_length, c.plate_width, c.plate_thickness])
    return centre - half, centre + half


def initial_nodes(c: Plate3DConfig) -> np.ndarray:
    """Nodes on the box faces and random inside, denser near the plate (density
    ``1 / (1 + d / density_length)^3``, d the distance to the plate's box)."""
    lo, hi = plate_box(c)

    def density(p):
        d = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
        return 1.0 / (1.0 + d / c.density_length) ** 3

    return box_nodes_3d(c.nodes, (c.width, c.depth, c.height), density=density, seed=c.seed,
                        boundary_spacing=WALL_SPACING * c.height)


class SinkingPlate3D:
    """A 3D sinking-plate run (see the module docstring); ``run()`` advances it."""

    dim = 3
    root = True

    def __init__(self, cfg: Plate3DConfig, out, _state=None):
        cfg.validate()
        self.cfg = cfg
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self._sol = None
        self._cache = StokesCache()
        if _state is not None:
            self.lm, meta = _state
            self.next_output, self.dt_next = meta["next_output"], meta["dt_next"]
            self.outputs, self.volume0 = meta["outputs"], meta["volume0"]
            return
        p = initial_nodes(cfg)
        lo, hi = plate_box(cfg)
        plate = ((p > lo) & (p < hi)).all(axis=1).astype(float)
        self.lm = LagrangianMesh3D(p, {"plate": plate, "start": p.copy()})
        self.next_output, self.dt_next, self.outputs = 0.0, cfg.max_dt, 0
        self.volume0 = self.plate_volume()

    # -- state ------------------------------------------------------------------
    @property
    def cells(self) -> str:
        return f"{self.lm.mesh.nelements} tetrahedra"

    def plate_volume(self) -> float:
        """The volume of the plate: the integral of the nodes' plate indicator
        interpolated linearly on the tetrahedra."""
        m = self.lm.mesh
        P = m.p.T[m.t.T]
        vol = np.abs(np.einsum("kd,kd->k", P[:, 1] - P[:, 0],
                               np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 0]))) / 6.0
        return float((vol * self.lm.node_fields["plate"][m.t].mean(axis=0)).sum())

    def materials(self, spaces):
        """Viscosity (ne, nq) and body force (3, ne, nq) at the quadrature points of
        ``spaces``: the nodes' plate indicator s and initial height interpolated linearly
        on the tetrahedra; the viscosity the geometric mean ``eta_fluid^(1 - s)
        eta_plate^s`` (the fluid's by the interpolated initial height), the buoyancy
        ``-plate_density gravity s``. Measured on the first solve at 5,166 and 9,953
        nodes (docs/stokes_3d.md): the plate's velocity changes by 13% between the two,
        against 40% for the nodes' viscosity interpolated by the velocity's functions
        and 36% for a sharp plate (s > 1/2), which also takes 3.5 times the FGMRES
        iterations."""
        c, f = self.cfg, self.lm.node_fields
        s = np.clip(np.asarray(spaces.pbasis.interpolate(f["plate"]).value), 0.0, 1.0)
        upper = np.asarray(spaces.pbasis.interpolate(f["start"][:, 2]).value) > c.interface_z
        fluid = np.where(upper, c.eta_upper, c.eta_lower)
        eta = np.exp((1.0 - s) * np.log(fluid) + s * math.log(c.plate_viscosity))
        force = np.zeros((3,) + eta.shape)
        force[2] = -c.plate_density * c.gravity * s
        return eta, force

    def solution(self):
        """The Stokes solution on the current nodes (solved once per configuration)."""
        if self._sol is None:
            t0 = _time.perf_counter()
            spaces = stokes_spaces(self.lm.mesh)
            eta, force = self.materials(spaces)
            # the cache starts the iterations from the last solution (node i stays node
            # i, so the unknowns keep their meaning from step to step)
            cache = {"cache": self._cache} if self.cfg.solver in CACHED_SOLVERS else {}
            self._sol = solve_stokes(spaces, eta, force,
                                     solver=self.cfg.solver, tol=self.cfg.solver_tol, **cache)
            self._solve_seconds = _time.perf_counter() - t0
        return self._sol

    def _stable_dt(self, v: np.ndarray) -> float:
        """cfl times each node's mean edge length over its speed, at most max_dt."""
        t = self.lm.mesh.t
        p = self.lm.nodes
        e = np.concatenate([t[[i, j]].T for i in range(4) for j in range(i + 1, 4)])
        length = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
        n = p.shape[0]
        mean = (np.bincount(e[:, 0], length, n) + np.bincount(e[:, 1], length, n)) / \
            np.maximum(np.bincount(e.ravel(), minlength=n), 1)
        speed = np.linalg.norm(v, axis=1)
        with np.errstate(divide="ignore"):
            return float(min(self.cfg.max_dt, (self.cfg.cfl * mean / speed).min()))

    # -- a step -----------------------------------------------------------------
    def step(self, dt: float) -> dict:
        """Advance by at most ``dt`` (less if the flow asks for it); retried with half the
        time step when the move fails, down to ``min_dt``. Returns the diagnostics row."""
        sol = self.solution()
        t0 = _time.perf_counter()
        v = sol.velocity_at_nodes()
        stable = self._stable_dt(v)
        # to the next output in two equal steps rather than a step and a sliver
        dt = dt / 2 if stable < dt < 2 * stable else min(dt, stable)
        P, u = sol.spaces.ubasis, sol.u

        def velocity(x):
            return (P.probes(x.T) @ u).reshape(3, -1).T

        for retry in range(RETRIES + 1):
            try:
                report = self.lm.advance(velocity, dt, tol=1e-8)
                break
            except StepTooLong as err:
                if retry == RETRIES or dt / 2 < self.cfg.min_dt:
                    from .sinking_plate import StepStalled
                    raise StepStalled(f"step {self.lm.step + 1} failed at dt = {dt:.3g}: "
                                      f"{err}") from None
                dt /= 2
        self._sol = None
        # a step that had to be shortened: the next starts from its time step, regrowing
        self.dt_next = self.cfg.max_dt if retry == 0 else min(self.cfg.max_dt, 1.5 * dt)
        seconds = self._solve_seconds + _time.perf_counter() - t0
        return self._row(report, retry, sol, v, stable, seconds)

    def _row(self, report, retries, sol, v, stable, seconds) -> dict:
        f = self.lm.node_fields
        plate = f["plate"] > 0.5
        z = self.lm.nodes[plate, 2]
        return {"step": report["step"], "time": report["time"], "dt": report["dt"],
                "retries": retries, "stable_dt": stable,
                "plate_depth": float((f["start"][plate, 2] - z).mean()),
                "plate_bottom": float(z.min()),
                "plate_volume_change": self.plate_volume() / self.volume0 - 1.0,
                "max_speed": float(np.linalg.norm(v, axis=1).max()),
                "plate_velocity": float(v[plate, 2].mean()),
                "solver_iterations": int(sol.iterations),
                "move_iterations": report["iterations"], "flips": report["flips"],
                "relocated": report["relocated"], "rebuilt": report["rebuilt"],
                "repair_seconds": report["repair_seconds"],
                "nodes": int(self.lm.nodes.shape[0]), "tetrahedra": report["tetrahedra"],
                "solve_seconds": self._solve_seconds, "seconds": seconds}

    # -- output -----------------------------------------------------------------
    def write_output(self) -> str:
        """``plate_NNNNN.vtu`` of the current state (added to ``plate.pvd``)."""
        sol = self.solution()
        f = self.lm.node_fields
        name = f"plate_{self.outputs:05d}.vtu"
        write_vtu(self.out / name, self.lm.nodes, self.lm.mesh.t.T,
                  point_data={"velocity": sol.velocity_at_nodes(), "pressure": sol.p,
                              "material": self._material(),
                              "initial_height": f["start"][:, 2]})
        self._pvd.add(self.lm.time, name)
        self.outputs += 1
        return name

    def _material(self) -> np.ndarray:
        """0 upper fluid, 1 lower fluid, 2 plate, per node."""
        f = self.lm.node_fields
        return np.where(f["plate"] > 0.5, 2.0, (f["start"][:, 2] <= self.cfg.interface_z) * 1.0)

    def checkpoint(self) -> None:
        """``checkpoint.npz`` (nodes, fields, clock) and ``checkpoint.json``."""
        f = self.lm.node_fields
        tmp = self.out / "checkpoint.tmp.npz"
        np.savez(tmp, nodes=self.lm.nodes, plate=f["plate"], start=f["start"],
                 clock=np.array([self.lm.time, self.lm.step]))
        tmp.replace(self.out / "checkpoint.npz")
        meta = {"dim": 3, "config": asdict(self.cfg), "next_output": self.next_output,
                "dt_next": self.dt_next, "outputs": self.outputs, "volume0": self.volume0}
        atomic_write_text(self.out / "checkpoint.json", json.dumps(meta))

    @classmethod
    def restart(cls, out, cfg: Optional[Plate3DConfig] = None) -> "SinkingPlate3D":
        """Continue from the checkpoint in ``out`` (its configuration unless ``cfg``)."""
        out = Path(out)
        if cfg is None:
            cfg = stored_config(out, kind=Plate3DConfig)
        meta = json.loads((out / "checkpoint.json").read_text())
        with np.load(out / "checkpoint.npz") as d:
            lm = LagrangianMesh3D(d["nodes"], {"plate": d["plate"], "start": d["start"]})
            lm.time, lm.step = float(d["clock"][0]), int(d["clock"][1])
        return cls(cfg, out, _state=(lm, meta))

    # -- the loop ---------------------------------------------------------------
    def run(self, progress: bool = True, max_steps: Optional[int] = None) -> Path:
        """Advance to ``end_time`` (or ``max_steps`` more steps); returns the
        diagnostics CSV path."""
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps < 0):
            raise ValueError(f"max_steps must be a non-negative integer, got {max_steps!r}")
        c, lm = self.cfg, self.lm
        keep = lm.time if lm.step else None
        log = CSVLog(self.out / "diagnostics.csv", keep_until=keep)
        self._pvd = PVDWriter(self.out / "plate.pvd", keep_until=keep)
        if lm.step == 0:
            self.write_output()
            self.next_output = c.output_interval
            self.checkpoint()
        bar = None
        if progress:
            bar = progress_bar(c.end_time, lm.time, "sinking plate 3D")
        steps = 0
        try:
            while lm.time < c.end_time * (1 - 1e-12):
                if max_steps is not None and steps >= max_steps:
                    break
                dt = min(self.dt_next, self.next_output - lm.time, c.end_time - lm.time)
                row = self.step(dt)
                log.append(row)
                steps += 1
                end = lm.time >= c.end_time * (1 - 1e-12)
                if lm.time >= self.next_output * (1 - 1e-12) or end:
                    self.write_output()
                    self.next_output = next_output_time(lm.time, c.output_interval)
                if lm.step % c.checkpoint_every == 0:
                    self.checkpoint()
                if bar is not None:
                    bar.update(lm.time - bar.n)
                    bar.set_postfix_str(f"step {lm.step}, depth {row['plate_depth']:.4f}, "
                                        f"{row['seconds']:.1f} s/step")
        finally:
            if bar is not None:
                bar.close()
        self.checkpoint()
        return self.out / "diagnostics.csv"

    def figures(self) -> list:
        """slices.png and diagnostics.png in the output folder; returns their paths."""
        return plate3d_figures(self)
