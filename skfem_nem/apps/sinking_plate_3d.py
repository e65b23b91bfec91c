"""The sinking plate in three dimensions: a dense elasto-plastic slab sinking through a
two-layer fluid in a box, on nodes that move with the flow.

Past the paper's 3D programme, which was "restricted to problems requiring scalar-only
memory": the nodes carry the material (the plate indicator, the height they started at,
which picks the fluid layer) and the tetrahedra carry the plate's stress history, one
value per vertex cell (``LagrangianMesh3D(ip_fields=...)``: the Delaunay tetrahedra
repaired by exact flips after every step, the stress remapped across them). Each step is
one visco-elasto-plastic step (:func:`~skfem_nem.models.rheology.vep_step`: Maxwell
viscoelasticity, von Mises plasticity by Picard iterations, Jaumann rotation) on the
current tetrahedra (:func:`~skfem_nem.models.stokes.stokes_spaces`: natural-neighbour
velocity with condensed bubbles, P1 pressure; FGMRES with AMG), free slip on all six
walls. ``shear_modulus = inf`` and ``yield_stress = inf`` give the viscous plate of the
paper's programme (one Stokes solve a step).

Outputs (in the output folder), as the 2D plate's: ``plate_NNNNN.vtu`` per output time
and ``plate.pvd`` (ParaView; point data velocity, pressure, material, initial height,
plastic strain; cell data stress invariant and plastic strain), ``diagnostics.csv`` (one
row per step), ``slices.png`` (the material in a vertical and a horizontal slice through
the plate at the start and the end), ``plastic_strain.png`` (the plastic strain in the
same slices and on the slab's surface), ``diagnostics.png``, ``checkpoint.npz`` +
``checkpoint.json`` (restart, the stress history included).
"""
from __future__ import annotations

import gc
import json
import time as _time
from dataclasses import asdict
from pathlib import Path
from typing import Optional

import numpy as np

from ..coordinates import sibson_coordinates
from ..evolution.lagrangian3d import LagrangianMesh3D
from ..evolution.remap3d import from_quadrature, to_quadrature
from ..evolution.stepping import StepTooLong
from ..geometry.nodesets import morton_order
from ..geometry.nodesets3d import box_nodes_3d
from ..models.rheology import PicardNotConverged, second_invariant, vep_step
from ..models.stokes import stokes_spaces
from ..models.stokes_solvers import CACHED_SOLVERS, SolverNotConverged, StokesCache
from .last_solve import LastSolve
from .output import (CSVLog, PVDWriter, atomic_write_text, next_output_time,
                     progress_bar, write_vtu)
from .plate3d_config import Plate3DConfig, plate_box
from .plate3d_figures import plate3d_figures
from .plate3d_materials import plate_materials
from .plate_config import stored_config
from .plate_parts import check_same_mesh, over_parts, part_rows, start_ranks, whole_rows

__all__ = ["SinkingPlate3D", "plate_box"]

#: spacing of the nodes on the box faces, as a fraction of the box height (the far field)
WALL_SPACING = 0.25
#: halvings of a step's dt before the run stops (a move that makes two nodes coincide, a
#: predictor-corrector or Picard iterations that do not converge)
RETRIES = 6
#: a step's dt is chosen from the last step's velocity; a step whose own velocity asks
#: for a dt shorter by more than this factor is solved again at that dt
STABLE_SLACK = 1.25
# a try whose first Picard iterate already asks for a dt this many times shorter stops there
# and is solved again at that dt, without iterating to convergence first (the first step,
# from max_dt, always is: 9 Picard iterations at 9,956 nodes). The first iterate's velocity
# differs from the converged one by some 13% there, well inside this margin
FIRST_ITERATE_SLACK = 1.5
#: Picard tolerance of a midpoint step's first solve (the looser of this and
#: ``picard_tol``): its velocity only places the half-way nodes, so its error reaches the
#: step's end through the second solve's geometry. At 4,209 nodes, cfl 1, 1e-2 in place of
#: 1e-3 left the depth as it was to 2e-5 and took a quarter off the run; 1e-1, a further
#: 4%, moved the largest plastic strain by 5% (1e-2: 2%)
PREDICTOR_TOL = 1e-2
#: what a midpoint step reports as the sum of its two moves
MOVE_SUMS = ("iterations", "flips", "relocated", "rebuilt", "repair_seconds")


def initial_nodes(c: Plate3DConfig) -> np.ndarray:
    """Nodes on the box faces and random inside, denser near the plate (density
    ``1 / (1 + d / density_length)^3``, d the distance to the plate's box), numbered
    along the Z-order curve.

    Why the order: a node's neighbours then have nearby numbers, and the rows of the
    viscous block and of the basis touch nearby memory. Faces first and the interior as
    drawn, the second step at 29,590 nodes (one solve, cfl 0.5, two runs each) took
    58.2-61.4 s, in Z-order 53.4-55.9 s; a product with the block alone at 97,595 nodes
    56.7 against 47.9 ms (docs/stokes_3d.md)."""
    lo, hi = plate_box(c)

    def density(p):
        d = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
        return 1.0 / (1.0 + d / c.density_length) ** 3

    p = box_nodes_3d(c.nodes, (c.width, c.depth, c.height), density=density, seed=c.seed,
                     boundary_spacing=WALL_SPACING * c.height)
    return p[morton_order(p)]


class _TooLong(Exception):
    """A step's own velocity asks for a shorter dt (:data:`STABLE_SLACK`)."""

    def __init__(self, stable: float):
        self.stable = stable


class SinkingPlate3D:
    """A 3D sinking-plate run (see the module docstring); ``run()`` advances it."""

    dim = 3

    def __init__(self, cfg: Plate3DConfig, out, _state=None):
        cfg.validate()
        self.cfg = cfg
        # over MPI (solver "petsc") every rank computes the whole run on its part of the
        # tetrahedra and rank 0 writes, as in 2D (apps.plate_parts)
        self.rank, self.ranks, self.failures = start_ranks(cfg.solver)
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self._last = None         # LastSolve of the last step
        self._spaces_of = None    # (mesh, its Stokes spaces)
        self._cache = StokesCache() if cfg.solver in CACHED_SOLVERS else None
        if _state is not None:
            self.lm, meta = _state
            self.next_output, self.dt_next = meta["next_output"], meta["dt_next"]
            self.outputs, self.volume0 = meta["outputs"], meta["volume0"]
            return
        p = initial_nodes(cfg)
        lo, hi = plate_box(cfg)
        plate = ((p > lo) & (p < hi)).all(axis=1).astype(float)
        self.lm = LagrangianMesh3D(p, {"plate": plate, "start": p.copy()}, remap=cfg.remap)
        self.lm.ip_fields = initial_ip_fields(self.lm.mesh.nelements)
        self.next_output, self.dt_next, self.outputs = 0.0, cfg.max_dt, 0
        self.volume0 = self.plate_volume()

    # -- state ------------------------------------------------------------------
    @property
    def cells(self) -> str:
        return f"{self.lm.mesh.nelements} tetrahedra"

    @property
    def root(self) -> bool:
        """True on the rank that writes outputs, checkpoints and figures (rank 0)."""
        return self.rank == 0

    def check_replicated(self) -> None:
        """``RuntimeError`` if the ranks' meshes differ (nodes, tetrahedra or clock)."""
        check_same_mesh(self.lm.nodes, self.lm.mesh.t, self.lm.time, self.lm.step)

    def plate_volume(self) -> float:
        """The volume of the plate: the integral of the nodes' plate indicator
        interpolated linearly on the tetrahedra."""
        m = self.lm.mesh
        P = m.p.T[m.t.T]
        vol = np.abs(np.einsum("kd,kd->k", P[:, 1] - P[:, 0],
                               np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 0]))) / 6.0
        return float((vol * self.lm.node_fields["plate"][m.t].mean(axis=0)).sum())

    def materials(self, spaces):
        """Material, body force and plate indicator at the quadrature points of
        ``spaces`` (:func:`~skfem_nem.apps.plate3d_materials.plate_materials`)."""
        return plate_materials(self.cfg, spaces, self.lm.node_fields)

    def solution(self) -> Optional["LastSolve"]:
        """What the last step kept of its Stokes solve (None before the first step)."""
        return self._last

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
        """Advance by at most ``dt``: solved again at a shorter dt where the step's own
        velocity asks for it (:data:`STABLE_SLACK`), halved where the move or the Picard
        iterations fail, down to ``min_dt`` (then :class:`StepStalled`); never accepted
        unconverged. The stress history is left as it was by a failed try. Returns the
        diagnostics row (``retries``: the tries before the one accepted)."""
        saved = dict(self.lm.ip_fields)
        for retry in range(RETRIES + 1):
            try:
                row = self._step(dt)
                row["retries"] = retry
                if retry:   # a step that had to be shortened: the next grows back gradually
                    self.dt_next = min(self.dt_next, 1.5 * dt)
                return row
            except _TooLong as short:
                dt = short.stable
            except (StepTooLong, PicardNotConverged, SolverNotConverged) as err:
                # the mesh leaves itself as it was on errors, with the stress the step
                # had set: the stress of the step's start comes back
                self.lm.ip_fields = dict(saved)
                if retry == RETRIES or dt / 2 < self.cfg.min_dt:
                    from .sinking_plate import StepStalled
                    raise StepStalled(f"step {self.lm.step + 1} at t = {self.lm.time:.6g} "
                                      f"failed at dt = {dt:.3g}: {err}") from None
                dt /= 2
        from .sinking_plate import StepStalled
        raise StepStalled(f"step {self.lm.step + 1} at t = {self.lm.time:.6g}: no dt "
                          f"down to {dt:.3g} passed")

    def _spaces(self):
        """The Stokes spaces of the current tetrahedra (built once per mesh: a step solved
        again at a shorter dt reuses them)."""
        if self._spaces_of is None or self._spaces_of[0] is not self.lm.mesh:
            self._release()
            self._spaces_of = (self.lm.mesh, stokes_spaces(
                self.lm.mesh, elements="owned" if self.ranks > 1 else None))
        return self._spaces_of[1]

    def _release(self) -> None:
        """Let go of the last spaces, their blocks and hierarchy before new ones are
        built. They sit in reference cycles that Python's collector, counting objects
        rather than bytes, frees late: at 4,000 nodes the process grew from 0.8 to 2.0 GB
        over 12 steps without a collection here. The step keeps only :class:`LastSolve`,
        and the cache its solution: at 30,300 nodes 1.6 GB of the last step were still
        held while the next built its spaces."""
        self._spaces_of = None
        if self._cache is not None:
            self._cache.release_operators()
        gc.collect()

    def _step(self, dt: float) -> dict:
        """One try at ``dt``: the visco-elasto-plastic solve, the new stress history set
        on the mesh, the move and repair (which carries it to the new tetrahedra); with
        ``midpoint``, :meth:`_midpoint_step`."""
        c, lm = self.cfg, self.lm
        t0 = _time.perf_counter()
        spaces = self._spaces()
        t_basis = _time.perf_counter() - t0
        tol = max(c.picard_tol, PREDICTOR_TOL) if c.midpoint else c.picard_tol
        r, s, v, stable = self._solve(spaces, dt, self._guesses(spaces),
                                      self._first_iterate(dt), tol)
        if c.midpoint:
            first = (r.solution.u, r.eta_eff, spaces.elements)
            del r, s, spaces        # (the first spaces go before the second are built)
            return self._midpoint_step(dt, first, v, stable, (t_basis, t0))
        t_solve = _time.perf_counter() - t0
        self._keep_stress(r, spaces.elements)
        P, u = spaces.ubasis, r.solution.u

        def velocity(x):
            return (P.probes(x.T) @ u).reshape(3, -1).T

        report = lm.advance(velocity, dt, tol=1e-8, inject=self._split())
        self._last = LastSolve.of(r.solution, spaces.elements, spaces.ubasis.mesh.nelements)
        self.dt_next = stable
        return self._row(report, r, v, s, stable, seconds=(t_basis, t_solve, t0),
                         cells=spaces.elements)

    def _midpoint_step(self, dt: float, first, v, stable, times) -> dict:
        """The rest of a midpoint try: the nodes moved half a step with the first solve's
        velocity ``v`` (the flips carry the stress there), the step solved again on them,
        and the nodes moved on to where that velocity takes them from the start; the
        mesh is as it was if a part fails. One step: one row, one count."""
        lm, (t_basis, t0) = self.lm, times
        start = lm.snapshot()
        try:
            # the first solve's viscosity goes along (the second solve's start)
            u1, eta1, cells1 = first
            lm.ip_fields = dict(lm.ip_fields, log_eta_eff=whole_rows(
                from_quadrature(np.log(eta1)), cells1, lm.mesh.nelements))
            half = lm.advance(lambda x: v, 0.5 * dt, tol=1e-8)
            spaces = self._spaces()     # (the first spaces go first: 1 GB at 10,000 nodes)
            guesses = {"u_guess": u1, "eta_guess": np.exp(to_quadrature(
                part_rows(lm.ip_fields["log_eta_eff"], spaces.elements)))}
            r2, s2, v2, stable2 = self._solve(spaces, dt, guesses, None, self.cfg.picard_tol)
            t_solve = _time.perf_counter() - t0
            self._keep_stress(r2, spaces.elements)
            w = 2.0 * v2 - v      # from the half-way nodes to x0 + dt v2
            report = lm.advance(lambda x: w, 0.5 * dt, tol=1e-8, inject=self._split())
        except BaseException:
            lm.restore(start)
            raise
        lm.step -= 1              # two moves, one step, one report
        report.update(step=lm.step, dt=dt, **{k: report[k] + half[k] for k in MOVE_SUMS})
        lm.history[-2:] = [report]
        self._last = LastSolve.of(r2.solution, spaces.elements, spaces.ubasis.mesh.nelements)
        self.dt_next = min(stable, stable2)
        return self._row(report, r2, v2, s2, min(stable, stable2),
                         seconds=(t_basis, t_solve, t0), cells=spaces.elements)

    def _solve(self, spaces, dt: float, guesses: dict, on_iterate, tol: float):
        """``vep_step`` on ``spaces`` with the mesh's stress history to the Picard tolerance
        ``tol``: ``(result, plate indicator, velocity at the nodes, its stable dt)``;
        :class:`_TooLong` if that dt is more than :data:`STABLE_SLACK` times shorter than
        ``dt``."""
        c, f, mine = self.cfg, self.lm.ip_fields, spaces.elements
        mat, force, s = self.materials(spaces)
        r = vep_step(spaces, mat, to_quadrature(part_rows(f["stress"], mine)), dt, f=force,
                     plastic_strain=to_quadrature(part_rows(f["plastic_strain"], mine)),
                     tol=tol,
                     solver=c.solver, cache=self._cache, linear_tol=c.solver_tol or None,
                     first_tol=c.first_solve_tol or None,
                     on_iterate=on_iterate, **guesses)
        v = r.solution.velocity_at_nodes()
        stable = self._stable_dt(v)
        if dt > STABLE_SLACK * stable:
            raise _TooLong(stable)
        return r, s, v, stable

    def _keep_stress(self, r, cells) -> None:
        """The step's new stress history on the mesh (the move carries it on), joined
        from the ranks' parts ``cells`` over MPI."""
        nt = self.lm.mesh.nelements
        self.lm.ip_fields = {
            k: whole_rows(from_quadrature(q), cells, nt)
            for k, q in (("stress", r.tau), ("plastic_strain", r.plastic_strain),
                         ("log_eta_eff", np.log(r.eta_eff)))}

    def _split(self):
        """``advance``'s ``inject``: the edges to split after a step (None: none)."""
        return self.cfg.split_edges if np.isfinite(self.cfg.split_edges) else None

    def _first_iterate(self, dt: float):
        """The check of a try's first Picard iterate: :class:`_TooLong` if its velocity
        asks for a dt :data:`FIRST_ITERATE_SLACK` times shorter than ``dt``."""
        seen = []

        def check(sol):
            if not seen:
                seen.append(True)
                stable = self._stable_dt(sol.velocity_at_nodes())
                if dt > FIRST_ITERATE_SLACK * stable:
                    raise _TooLong(stable)
        return check

    def _guesses(self, spaces) -> dict:
        """The last step's velocity (node i stays node i) and effective viscosity (carried
        by the mesh) as the Picard iterations' start."""
        out = {}
        if "log_eta_eff" in self.lm.ip_fields:
            out["eta_guess"] = np.exp(to_quadrature(part_rows(self.lm.ip_fields["log_eta_eff"],
                                                              spaces.elements)))
        sol = self.solution()
        if sol is not None and sol.u.shape == (spaces.ubasis.N,):
            out["u_guess"] = sol.u
        return out

    def _row(self, report, r, v, s, stable, seconds, cells=None) -> dict:
        f = self.lm.node_fields
        plate = f["plate"] > 0.5
        z = self.lm.nodes[plate, 2]
        moving = plate[:v.shape[0]]          # (nodes added after the solve come last)
        t_basis, t_solve, t0 = seconds
        in_plate = s >= 0.5
        tauII = second_invariant(r.tau)
        return {"step": report["step"], "time": report["time"], "dt": report["dt"],
                "stable_dt": stable,
                "plate_depth": float((f["start"][plate, 2] - z).mean()),
                "plate_bottom": float(z.min()),
                "plate_volume_change": self.plate_volume() / self.volume0 - 1.0,
                "max_speed": float(np.linalg.norm(v, axis=1).max()),
                "plate_velocity": float(v[moving, 2].mean()),
                "max_plastic_strain": over_parts(float(r.plastic_strain.max()), cells, True),
                "yielded_points": int(over_parts(int(r.yielded.sum()), cells)),
                "max_plate_stress": over_parts(float(tauII[in_plate].max()) if in_plate.any()
                                               else 0.0, cells, True),
                "picard_iterations": r.iterations,
                "solver_iterations": int(r.solution.iterations),
                "move_iterations": report["iterations"], "flips": report["flips"],
                "injected": report["injected"],
                "relocated": report["relocated"], "rebuilt": report["rebuilt"],
                "repair_seconds": report["repair_seconds"],
                "nodes": int(self.lm.nodes.shape[0]), "tetrahedra": report["tetrahedra"],
                "basis_seconds": t_basis, "assembly_seconds": r.seconds["assembly"],
                "solver_seconds": r.seconds["solver"], "solve_seconds": t_solve,
                "seconds": _time.perf_counter() - t0}

    # -- output -----------------------------------------------------------------
    def write_output(self) -> str:
        """``plate_NNNNN.vtu`` of the current state (added to ``plate.pvd``): velocity
        and pressure of the last step (none before the first), the nodes' material and
        plastic strain, the tetrahedra's stress invariant and plastic strain (rank 0 only;
        other ranks return ``""``)."""
        if not self.root:
            return ""
        lm, f = self.lm, self.lm.node_fields
        name = f"plate_{self.outputs:05d}.vtu"
        pd = {"material": self._material(), "initial_height": f["start"][:, 2],
              "plastic_strain": lm.ip_at_nodes("plastic_strain")}
        sol = self.solution()
        if sol is not None:
            pd["velocity"], pd["pressure"] = self._solved_at_nodes(sol)
        stress = to_quadrature(lm.ip_fields["stress"])
        cd = {"stress_invariant": second_invariant(stress).mean(axis=1),
              "plastic_strain": lm.ip_fields["plastic_strain"].mean(axis=1)}
        write_vtu(self.out / name, lm.nodes, lm.mesh.t.T, point_data=pd, cell_data=cd)
        self._pvd.add(lm.time, name)
        self.outputs += 1
        return name

    def _solved_at_nodes(self, sol):
        """Velocity (n, 3) and pressure (n,) of the last solve at the nodes; at nodes added
        after it, their Sibson interpolants from the others."""
        v, p = sol.velocity, sol.pressure
        x = self.lm.nodes
        if x.shape[0] > v.shape[0]:
            Phi = sibson_coordinates(x[:v.shape[0]], x[v.shape[0]:])
            v, p = np.concatenate([v, Phi @ v]), np.concatenate([p, Phi @ p])
        return v, p

    def _material(self) -> np.ndarray:
        """0 upper fluid, 1 lower fluid, 2 plate, per node."""
        f = self.lm.node_fields
        return np.where(f["plate"] > 0.5, 2.0, (f["start"][:, 2] <= self.cfg.interface_z) * 1.0)

    def checkpoint(self) -> None:
        """``checkpoint.npz`` (the whole evolving mesh, its stress history included:
        :meth:`~skfem_nem.LagrangianMesh3D.save`) and ``checkpoint.json`` (rank 0 only)."""
        if not self.root:
            return
        self.lm.save(self.out / "checkpoint.npz")
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
        return cls(cfg, out, _state=(load_checkpoint(out / "checkpoint.npz", cfg), meta))

    # -- the loop ---------------------------------------------------------------
    def run(self, progress: bool = True, max_steps: Optional[int] = None) -> Path:
        """Advance to ``end_time`` (or ``max_steps`` more steps); returns the
        diagnostics CSV path."""
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps < 0):
            raise ValueError(f"max_steps must be a non-negative integer, got {max_steps!r}")
        c, lm = self.cfg, self.lm
        keep = lm.time if lm.step else None
        log = CSVLog(self.out / "diagnostics.csv", keep_until=keep) if self.root else None
        self._pvd = PVDWriter(self.out / "plate.pvd", keep_until=keep) if self.root else None
        if lm.step == 0:
            self.write_output()
            self.next_output = c.output_interval
            self.checkpoint()
        bar = None
        if progress and self.root:
            bar = progress_bar(c.end_time, lm.time, "sinking plate 3D")
        steps = 0
        try:
            while lm.time < c.end_time * (1 - 1e-12):
                if max_steps is not None and steps >= max_steps:
                    break
                row = self.step(self._next_dt())
                if self.ranks > 1:
                    self.check_replicated()
                if log is not None:
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

    def _next_dt(self) -> float:
        """The next step's dt: the last step's stable one, to the next output in two
        equal steps rather than a step and a sliver, and not past the end."""
        c, t = self.cfg, self.lm.time
        dt = min(self.dt_next, c.max_dt)
        left = min(self.next_output, c.end_time) - t
        return left / 2 if dt < left < 2 * dt else min(dt, left)

    def figures(self) -> list:
        """slices.png, plastic_strain.png and diagnostics.png in the output folder;
        returns their paths (rank 0 only)."""
        return plate3d_figures(self) if self.root else []


def initial_ip_fields(ntetrahedra: int) -> dict:
    """A stress-free start: stress (m, 4, 3, 3) and plastic strain (m, 4) at the vertex
    cells."""
    return {"stress": np.zeros((ntetrahedra, 4, 3, 3)),
            "plastic_strain": np.zeros((ntetrahedra, 4))}


def load_checkpoint(path: Path, cfg: Plate3DConfig) -> LagrangianMesh3D:
    """The evolving mesh of a checkpoint: one of :meth:`~skfem_nem.LagrangianMesh3D.save`,
    or of a viscous run written before the plate had a stress history (nodes, plate,
    start, clock), which starts stress-free."""
    with np.load(path) as d:
        if "meta" in d.files:
            return LagrangianMesh3D.load(path)
        lm = LagrangianMesh3D(d["nodes"], {"plate": d["plate"], "start": d["start"]},
                              remap=cfg.remap)
        lm.time, lm.step = float(d["clock"][0]), int(d["clock"][1])
    lm.ip_fields = initial_ip_fields(lm.mesh.nelements)
    return lm
