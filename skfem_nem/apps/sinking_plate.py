"""The paper's showcase (Fig. 6): an elasto-plastic plate sinking through a
layered viscous fluid, on a Lagrangian natural-neighbour mesh.

A box of height ``height`` and width ``width`` (default 1 x 10), free slip on
all walls. The fluid has viscosity ``eta_upper`` above ``interface_z`` and
``eta_lower`` below; the layer each node belongs to is carried by the node
(its initial height), so the interface moves with the flow. A plate denser
than the fluid by ``plate_density`` is a Maxwell visco-elastic, von Mises
plastic solid (``plate_viscosity``, ``shear_modulus``, ``yield_stress``) that
shares its boundary nodes with the fluid (no slip). Its outline nodes, in
order, bound the plate as a polygon that moves with them; quadrature points
inside it are plate. Initial nodes are random with density inversely
proportional to the distance from the plate, so some Delaunay triangles are
very elongated.

Each step: a visco-elasto-plastic Stokes solve on natural-neighbour velocity
(bubble-enriched, P1 pressure, gradients smoothed over three cells per
triangle, whose points are where the evolving mesh stores the stress), the
plate's stress history rotated (Jaumann)
and updated by return mapping, nodes moved by the iterative
predictor-corrector, the triangulation repaired by Lawson flips with the
stress remapped on every flip, and nodes injected where the mesh thins. No
regridding. By default the outline and a line of nodes on the layer interface
are segments (a constrained mesh and constrained natural neighbours), nodes the
flow crowds together are removed and folds of the outline merged, and the
plate's area is held: each step's outline flux gives back what the time steps
lost, a least-squares shift of the outline what a merge cut off.

Outputs (in the output folder): ``plate_NNNNN.vtu`` per output step and
``plate.pvd`` (ParaView), ``diagnostics.csv`` (one row per step),
``fig6.png`` (the mesh coloured by the nodes' initial depth at t = 1 and
at the end), ``plate_strain.png`` (the plate's plastic strain and stress at
the end), ``diagnostics.png``, ``checkpoint.npz`` +
``checkpoint.json`` (restart).
"""
from __future__ import annotations

import json
import time as _time
from dataclasses import asdict
from pathlib import Path
from typing import Optional

import numpy as np

from ..evolution.lagrangian import LagrangianMesh
from ..evolution.stepping import StepTooLong
from ..coordinates import sibson_coordinates
from ..geometry.nodesets import box_nodes, hilbert_order, polyline_nodes
from .plate_config import HELP, PlateConfig, load_config, stored_config  # noqa: F401
from .plate_figures import plate_figures
from .plate_films import on_interface, release_interface_film, release_near_outline
from .plate_outlines import PlateOutlines, polygon_area_centroid
from .plate_time_step import (FILM_FRACTION, WALL_FRACTION, ClosingFilm,  # noqa: F401
                              hold_off_walls, node_spacing, stable_dt)
from .output import (CSVLog, PVDWriter, atomic_write_text, next_output_time,
                     progress_bar, write_vtu)
from ..models.rheology import (Material, PicardNotConverged, from_ip_field, second_invariant,
                               to_ip_field, vep_step)
from ..models.stokes import outline_flux, stokes_spaces
from ..models.stokes_solvers import CACHED_SOLVERS, SolverNotConverged, StokesCache
from .last_solve import LastSolve
from .plate_parts import check_same_mesh, over_parts, part_rows, start_ranks, whole_rows

# (PlateConfig, load_config and stored_config are re-exported from plate_config)
__all__ = ["SinkingPlate", "StepStalled", "run"]


# the integration-point fields a step writes anew (new arrays) after its Picard iterations
STEP_FIELDS = ("stress", "plastic_strain", "log_eta_eff")


class StepStalled(RuntimeError):
    """A step that fails (a move the mesh cannot follow, an unconverged iteration) even
    when shortened below the configuration's ``min_dt``: the run stops there, its outputs
    and checkpoint kept."""


# ---------------------------------------------------------------------------
# geometry helpers
# ---------------------------------------------------------------------------

def initial_nodes(c: PlateConfig):
    """The initial node set: walls, the plate outline, random nodes with density
    ``1 / (1 + d / density_length)`` (d: distance to the plate) and, with
    ``c.segments``, a line of nodes along the layer interface whose spacing grows
    like the random nodes' from the outline's spacing under the plate. Returns
    the nodes and the node indices of the outline (in order) and of the interface
    (left to right; empty without segments)."""
    x0, x1 = c.plate_x - c.plate_length / 2, c.plate_x + c.plate_length / 2
    z0, z1 = c.plate_z - c.plate_thickness / 2, c.plate_z + c.plate_thickness / 2
    rect = [[x0, z0], [x1, z0], [x1, z1], [x0, z1]]
    h0 = c.outline_spacing * c.plate_thickness
    outline = polyline_nodes(rect, h0, closed=True)

    def dist(p):
        dx = np.maximum(np.maximum(x0 - p[:, 0], p[:, 0] - x1), 0)
        dz = np.maximum(np.maximum(z0 - p[:, 1], p[:, 1] - z1), 0)
        return np.hypot(dx, dz)

    def density(p):
        return 1.0 / (1.0 + dist(p) / c.density_length)

    lines = [np.r_[outline, outline[:1]]]
    if c.segments:
        xs = [0.0]
        while xs[-1] < c.width:
            at = np.array([[xs[-1], c.interface_z]])
            xs.append(xs[-1] + h0 / np.sqrt(density(at)[0]))
        xs = np.array(xs) * (c.width / xs[-1])
        xs[-1] = c.width
        lines.append(np.c_[xs, np.full(xs.size, c.interface_z)])
    nodes = box_nodes(c.nodes, c.width, c.height, density=density, seed=c.seed, lines=lines,
                      boundary_spacing=max(c.width, c.height) / 60)
    # numbered along a Hilbert curve: a stencil's nodes get nearby indices, so the
    # assembly and the solves touch nearby memory
    nodes = nodes[hilbert_order(nodes)]
    from scipy.spatial import cKDTree
    tree = cKDTree(nodes)
    idx = []
    for line in (outline, lines[1] if c.segments else np.empty((0, 2))):
        d, i = tree.query(line) if line.size else (np.zeros(1), np.empty(0, np.int64))
        if d.max() > 1e-12:
            raise RuntimeError("plate outline or interface nodes were not kept in the node set")
        idx.append(np.asarray(i, dtype=np.int64))
    return nodes, idx[0], idx[1]


def _inside(poly, pts):
    from matplotlib.path import Path as MPath
    return MPath(poly).contains_points(pts, radius=0.0)


class SinkingPlate:
    """State and time loop of a sinking-plate run (see the module docstring).

    ``SinkingPlate(cfg, out)`` builds the initial node set; :meth:`run`
    advances to ``cfg.end_time`` writing outputs; :meth:`restart` continues
    from the checkpoint in ``out``.
    """

    dim = 2

    def __init__(self, cfg: PlateConfig, out, _state=None):
        cfg.validate()
        self.cfg = cfg
        # over MPI (solver "petsc") every rank computes the whole run, rank 0 writes
        self.rank, self.ranks, self.failures = start_ranks(cfg.solver)
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        # a film that closes within any step (_stable_dt), dealt with before the next
        self._closing = None
        self._pinches = 0
        self._released = 0   # interface segments released before the step (a film closed)
        if _state is not None:
            closing = _state[1].get("closing")
            self._closing = None if closing is None else ClosingFilm(*closing)
            self._pinches = _state[1].get("pinches", 0)
        if _state is not None:
            self.lm, meta = _state
            # (checkpoints written before the area was stored: the initial rectangle)
            self.outlines = PlateOutlines.from_meta(
                meta, meta.get("plate_area0", cfg.plate_length * cfg.plate_thickness))
            self.next_output = meta["next_output"]
            self.dt_next = meta["dt_next"]
            self.outputs = meta["outputs"]
            self.first_output = meta.get("first_output")
            self.outline_segments = meta.get("outline_segments")
            if self.outline_segments is None:  # (older checkpoints) the drawn outline
                self.outline_segments = len(initial_nodes(cfg)[1])
            return
        nodes, outline, interface = initial_nodes(cfg)
        segs = None
        if cfg.segments:
            segs = np.r_[np.c_[outline, np.roll(outline, -1)],
                         np.c_[interface[:-1], interface[1:]]]
        fields_ = {"x0": nodes[:, 0].copy(), "z0": nodes[:, 1].copy()}
        lm = LagrangianMesh(nodes, node_fields=fields_, remap=cfg.remap, segments=segs)
        nt = lm.triangles.shape[0]
        lm.ip_fields["stress"] = np.zeros((nt, 3, 2, 2))
        lm.ip_fields["plastic_strain"] = np.zeros((nt, 3))
        self.lm = lm
        self.outlines = PlateOutlines([outline], [abs(polygon_area_centroid(nodes[outline])[0])])
        # given segments 0 .. outline_segments - 1 are the outline's, then the interface's
        self.outline_segments = len(outline)
        self.next_output = 0.0
        self.dt_next = cfg.max_dt
        self.outputs = 0
        self.first_output = None

    # -- state ------------------------------------------------------------------
    @property
    def cells(self) -> str:
        return f"{self.lm.triangles.shape[0]} triangles"

    @property
    def outline(self) -> np.ndarray:
        """The plate's outline nodes in order (after a breakup: piece after piece,
        :attr:`outlines`)."""
        return self.outlines.nodes

    @property
    def plate_polygon(self) -> np.ndarray:
        """(k, 2) the nodes of :attr:`outline`: the plate's polygon while it is whole."""
        return self.lm.nodes[self.outline]

    @property
    def plate_area0(self) -> float:
        """The plate's reference area (the sum of its pieces')."""
        return float(sum(self.outlines.areas0))

    def plate_area_centroid(self):
        """Area of the plate (all pieces) and its centroid."""
        return self.outlines.area_centroid(self.lm.nodes)

    def materials(self, spaces, polygon: Optional[np.ndarray] = None):
        """Per-point :class:`~skfem_nem.models.rheology.Material`, body force
        (2, ne, nq) and plate mask (ne, nq) at the quadrature points of
        ``spaces`` (plate: inside ``polygon``, default the current outline)."""
        c = self.cfg
        X = spaces.quadrature_points
        ne, nq = X.shape[1:]
        pts = X.reshape(2, -1).T
        plate = (self.outlines.inside(self.lm.nodes, pts) if polygon is None
                 else _inside(polygon, pts)).reshape(ne, nq)
        # P1 dofs are the node indices: the nodes' initial heights at the points
        z0 = np.asarray(spaces.pbasis.interpolate(self.lm.node_fields["z0"]))
        eta_fluid = np.where(z0 > c.interface_z, c.eta_upper, c.eta_lower)
        eta = np.where(plate, c.plate_viscosity, eta_fluid)
        mu = np.where(plate, c.shear_modulus, np.inf)
        Y = np.where(plate, c.yield_stress, np.inf)
        force = np.zeros((2, ne, nq))
        force[1] = -c.plate_density * c.gravity * plate
        return Material(viscosity=eta, shear_modulus=mu, yield_stress=Y), force, plate

    def step(self, dt: float, retries: int = 4, cuts: int = 3) -> dict:
        """One time step of length dt, halved until the step passes (counted in the row's
        ``retries``; never accepted with an unconverged predictor-corrector or plastic
        iteration); a step that still fails below ``min_dt`` stops the run
        (:class:`StepStalled`). Where a step fails ``retries`` times because two material
        lines would cross, the plate is cut there or the interface released, and the
        step tried again, at most ``cuts`` times. Returns the diagnostics row."""
        self._check_films()
        try:
            row = self._tries(dt, retries)
        except StepTooLong as err:
            if cuts < 1 or not self._resolve_crossing(err):
                raise
            return self.step(dt / 2 ** retries, retries, cuts - 1)
        row["segments_released"] += self._released    # (by a film closed before it)
        self._released = 0
        return row

    def _resolve_crossing(self, err: StepTooLong) -> bool:
        """Where a step failed because two material lines would cross (a film thinner
        than the mesh resolves, crossing within a relocation), deal with it as with a
        closing film (:meth:`_check_films`): cut the plate there, or release the
        interface; whether that was done."""
        if err.crossing is None:
            return False
        tri = self.lm.triangulation
        rows = tri.segment_rows(err.crossing)
        if (rows < 0).any():
            return False
        what = ("the interface released there" if on_interface(tri, rows, self.outline_segments)
                else "the plate cut there (a fold or a spike: closed)")
        why = self._close_film(int(rows[0]), int(rows[1]))
        if why is None:
            import warnings
            warnings.warn(f"step {self.lm.step + 1} at t = {self.lm.time:.6g}: {err}; {what} "
                          f"and the step tried again", RuntimeWarning, stacklevel=3)
        return why is None

    def _tries(self, dt: float, retries: int) -> dict:
        """:meth:`step` without cuts: dt halved until the step passes; a crossing of
        material lines goes back to :meth:`step` after ``retries`` halvings (or where the
        next would go below ``min_dt``), anything else stops the run below ``min_dt``
        (:class:`StepStalled`)."""
        # the fields the step replaces by new arrays before the evolution changes them in
        # place are kept by reference (a copy of each is whole-mesh memory on every rank);
        # any other field is copied
        saved = {k: v if k in STEP_FIELDS else v.copy() for k, v in self.lm.ip_fields.items()}
        attempt = 0
        while True:
            try:
                row = self._step(dt)
                row["retries"] = attempt
                if attempt:
                    # a step that had to be shortened: the next grows back gradually
                    # instead of failing at the full step again
                    self.dt_next = min(self.dt_next, 2.0 * dt)
                return row
            except (StepTooLong, PicardNotConverged, SolverNotConverged) as err:
                # the evolving mesh leaves itself unchanged on errors; restore the
                # integration-point fields that the solve had updated. The plastic
                # iterations can stall where the yielded region jumps between iterates,
                # the predictor-corrector where the velocity varies fast, a Stokes solve
                # at a large visco-elastic contrast: a shorter step changes less (and
                # lowers the contrast)
                self.lm.replace_ip_fields(saved)
                last = dt / 2 < self.cfg.min_dt
                if getattr(err, "crossing", None) is not None and (attempt >= retries or last):
                    raise                               # step() cuts or releases there
                if last:
                    raise StepStalled(
                        f"step {self.lm.step + 1} at t = {self.lm.time:.6g} fails at dt = "
                        f"{dt:.3g} (min_dt {self.cfg.min_dt:g}): {err}") from err
                dt = dt / 2
                attempt += 1

    def _step(self, dt: float) -> dict:
        c = self.cfg
        lm = self.lm
        t0 = _time.perf_counter()
        last, solved = self._solve(dt)
        v = hold_off_walls(lm, last.velocity, c)
        t_solve = _time.perf_counter() - t0

        def velocity(x):
            return sibson_coordinates(lm.triangulation, x) @ v

        rep = lm.advance(velocity, dt, tol=1e-8, maxiter=20,
                         inject=c.inject if c.inject else None, merge=c.merge)
        # removed nodes leave the outline (node_map: this step's old -> new indices),
        # nodes injected on the outline's segments take their places in it
        segments = bool(lm.triangulation.segment_keys.size)
        self.outlines.renumber(lm.node_map, lm if segments else None)
        released = release_near_outline(lm, self.outlines, self.outline_segments,
                                        self._spacing) if segments else 0
        if rep["merged"] and c.keep_area:
            self._give_back_area()
        # the next step's dt from this step's velocity
        self.dt_next = self._stable_dt(v)
        t_evolution = _time.perf_counter() - t0 - t_solve
        A, cen = self.plate_area_centroid()
        row = {"step": lm.step, "time": lm.time, "dt": dt,
               "plate_depth": c.height - cen[1], "plate_x": cen[0],
               "plate_area": A, "fluid_area": c.width * c.height - A,
               "outline_crossings": self.outlines.crossings(lm.nodes),
               "inverted_triangles": int(np.count_nonzero(lm.triangulation.orientation() <= 0)),
               "non_delaunay_edges": lm.triangulation.non_delaunay_edges(),
               "max_plastic_strain": float(lm.ip_fields["plastic_strain"].max()),
               "yielded_points": solved["yielded_points"],
               "max_plate_stress": solved["max_plate_stress"],
               "max_speed": float(np.hypot(*v.T).max()),
               "flips": rep["flips"], "injected": rep["injected"],
               "relocated": rep["relocated"], "substeps": rep["substeps"],
               "segments_split": rep["segments_split"], "outline_nodes": len(self.outline),
               "plate_pieces": len(self.outlines.loops), "pinches": self._pinches,
               "segments_released": released,
               "removed": rep["removed"], "merged": rep["merged"],
               "nodes": lm.nodes.shape[0], "min_angle": rep["min_angle"],
               "longest_edge": rep["longest_edge"], "edges_split": rep["edges_split"],
               "predictor_iterations": rep["iterations"],
               "predictor_converged": int(rep["converged"]),
               "picard_iterations": solved["picard_iterations"],
               "solver_iterations": solved["solver_iterations"],
               "factorisations": solved["factorisations"],
               "basis_seconds": solved["basis_seconds"],
               "assembly_seconds": solved["assembly_seconds"],
               "solver_seconds": solved["solver_seconds"], "solve_seconds": t_solve,
               "evolution_seconds": t_evolution, "step_seconds": _time.perf_counter() - t0}
        self._last = last
        return row

    def _solve(self, dt: float):
        """The step's Picard iterations on the current mesh: the fields updated, and what
        the step keeps of the solve (:class:`LastSolve`) with its counts and sums. The
        bases, the system and the solver's cache go when it returns, before the mesh
        moves (the solution holds its spaces: kept to the next step, they stood beside
        its own)."""
        c, lm = self.cfg, self.lm
        t0 = _time.perf_counter()
        gauss = c.integration == "gauss"
        # over MPI each rank builds the bases of its part of the triangles alone and updates
        # the integration-point fields there; the fields are then joined on every rank
        spaces = stokes_spaces(lm.mesh, "nem", npoints=3 if gauss else None,
                               integration=c.integration,
                               elements="owned" if self.ranks > 1 else None)
        mine, nt = spaces.elements, lm.triangles.shape[0]
        t_basis = _time.perf_counter() - t0
        mat, force, plate = self.materials(spaces)
        tau_old = from_ip_field(part_rows(lm.ip_fields["stress"], mine))
        ps_old = part_rows(lm.ip_fields["plastic_strain"], mine)
        # the plate is incompressible as a whole: zero net flux of the nodal
        # velocities through its outline (the polygon's area is kept)
        # Picard iterations start from the effective viscosity of the previous
        # step, carried (as its logarithm) by the mesh like the stress
        guess = part_rows(lm.ip_fields.get("log_eta_eff"), mine)
        # the step's Picard iterations share a cache (what it kept is counted below)
        cache = StokesCache() if c.solver in CACHED_SOLVERS else None
        r = vep_step(spaces, mat, tau_old, dt, f=force, plastic_strain=ps_old,
                     tol=c.picard_tol, solver=c.solver,
                     constraints=self._area_constraint(spaces, dt),
                     eta_guess=None if guess is None else np.exp(guess), cache=cache)
        lm.ip_fields["log_eta_eff"] = whole_rows(np.log(r.eta_eff), mine, nt)
        lm.ip_fields["stress"] = whole_rows(to_ip_field(r.tau), mine, nt)
        lm.ip_fields["plastic_strain"] = whole_rows(np.ascontiguousarray(r.plastic_strain),
                                                mine, nt)
        stress = float(second_invariant(r.tau)[plate].max()) if plate.any() else 0.0
        return LastSolve.of(r.solution, mine, nt), {
            "yielded_points": int(over_parts(np.count_nonzero(r.yielded), mine)),
            "max_plate_stress": over_parts(stress, mine, largest=True),
            "picard_iterations": r.iterations, "solver_iterations": r.solution.iterations,
            "factorisations": 0 if cache is None else cache.factorisations,
            "basis_seconds": t_basis, "assembly_seconds": r.seconds["assembly"],
            "solver_seconds": r.seconds["solver"]}

    def _area_constraint(self, spaces, dt: float):
        """The outline-flux constraint of a step: zero net flux, or with
        ``keep_area`` the flux that brings the plate's area back to its initial
        value over the step (the position-level form of the incompressibility
        of the plate as a whole, which keeps the time-step error from adding up)."""
        import scipy.sparse as sp
        C = sp.vstack([outline_flux(spaces, o) for o in self.outlines.loops], format="csr")
        if not self.cfg.keep_area:
            return C
        return C, self.outlines.deficits(self.lm.nodes) / dt

    def _give_back_area(self) -> None:
        """Give the plate back the area that merges at folds of its outline cut off this
        step: the outline nodes move by the smallest displacement (least squares) that
        restores the initial area to first order, s * grad A(x) with
        s = (A0 - A) / |grad A|^2 (the position form of the area constraint; a fraction
        of the node spacing: 7e-5 for a loss of 1.6e-3 of the area). Skipped if a
        triangle would invert (the next step's outline flux gives the area back then)."""
        shift = []
        for o, deficit in zip(self.outlines.loops, self.outlines.deficits(self.lm.nodes)):
            P = self.lm.nodes[o]
            A = polygon_area_centroid(P)[0]
            grad = 0.5 * np.sign(A) * np.c_[np.roll(P[:, 1], -1) - np.roll(P[:, 1], 1),
                                            np.roll(P[:, 0], 1) - np.roll(P[:, 0], -1)]
            shift.append(deficit / (grad * grad).sum() * grad)
        try:
            self.lm.shift_nodes(self.outline, np.concatenate(shift))
        except ValueError:
            pass

    def _stable_dt(self, v: np.ndarray) -> float:
        """The next step's dt from this step's nodal velocities v
        (:func:`~skfem_nem.apps.plate_time_step.stable_dt`); a film found closing within
        any step is kept for :meth:`_check_films`."""
        dt, self._closing = stable_dt(self.lm, v, self.cfg, self.outline_segments)
        return dt

    def _check_films(self) -> None:
        """What :meth:`_stable_dt` found at the end of the last step, before the next
        step changes anything: a film closing within any step is closed
        (:meth:`_close_film`), or, where that cannot be done, a ``RuntimeError`` saying
        where and why."""
        closing, self._closing = self._closing, None
        if closing is None:
            return
        why = self._close_film(closing.first, closing.second)
        if why is not None:
            self._closing = closing
            raise RuntimeError(f"{closing.message}: {why}")

    def _close_film(self, first: int, second: int):
        """Close the film between rows ``first`` and ``second`` of the mesh's segments:
        where both are the plate's outline (it necks, folds or spikes) cut it or close
        the fold (:meth:`PlateOutlines.pinch`, counted); where one is the interface,
        release the interface there (:func:`~.plate_films.release_interface_film`,
        counted in the next step's row). None, or why not."""
        if on_interface(self.lm.triangulation, [first, second], self.outline_segments):
            self._released += release_interface_film(
                self.lm, [first, second], self.outline_segments, self._spacing, self.cfg.cfl)
            return None
        why = self.outlines.pinch(self.lm, first, second, self._spacing)
        self._pinches += why is None
        return why

    @property
    def _spacing(self) -> float:
        """The plate outline's node spacing."""
        return self.cfg.outline_spacing * self.cfg.plate_thickness

    # -- outputs ----------------------------------------------------------------
    @property
    def solution(self) -> Optional[LastSolve]:
        """What the last step kept of its Stokes solve (None before the first step)."""
        return getattr(self, "_last", None)

    @property
    def root(self) -> bool:
        """True on the rank that writes outputs, checkpoints and figures (rank 0)."""
        return self.rank == 0

    def check_replicated(self) -> None:
        """``RuntimeError`` if the ranks' meshes differ (nodes, triangles or clock)."""
        check_same_mesh(self.lm.nodes, self.lm.triangles, self.lm.time, self.lm.step)

    def write_output(self, last: Optional[LastSolve] = None) -> str:
        """Write the next ``plate_NNNNN.vtu`` and add it to ``plate.pvd`` (rank 0
        only; other ranks return ``""``); returns its name."""
        if not self.root:
            return ""
        c = self.cfg
        lm = self.lm
        name = f"plate_{self.outputs:05d}.vtu"
        P, T = lm.nodes, lm.triangles
        pd = {"initial_depth": c.height - lm.node_fields["z0"],
              "initial_x": lm.node_fields["x0"]}
        on_plate = np.zeros(P.shape[0], dtype=bool)
        on_plate[self.outlines.inside(P, P)] = True
        on_plate[self.outline] = True
        eta_n = np.where(on_plate, c.plate_viscosity,
                         np.where(lm.node_fields["z0"] > c.interface_z, c.eta_upper, c.eta_lower))
        pd["viscosity"] = eta_n
        pd["density"] = np.where(on_plate, c.plate_density, 0.0)
        pd["material"] = on_plate.astype(float)
        if last is not None and last.velocity.shape[0] == P.shape[0]:
            pd["velocity"], pd["pressure"] = last.velocity, last.pressure
        S = lm.ip_fields["stress"]
        cd = {"stress_invariant": second_invariant(from_ip_field(S)).mean(axis=1),
              "plastic_strain": lm.ip_fields["plastic_strain"].mean(axis=1)}
        write_vtu(self.out / name, P, T, pd, cd)
        self._pvd.add(lm.time, name)
        if self.first_output is None and lm.time > 0:
            self.first_output = lm.time
            np.savez(self.out / "first_output.npz", nodes=P, triangles=T,
                     depth=pd["initial_depth"], time=lm.time)
        self.outputs += 1
        return name

    def checkpoint(self) -> None:
        """``checkpoint.npz`` and ``checkpoint.json`` (rank 0 only)."""
        if not self.root:
            return
        self.lm.save(self.out / "checkpoint.npz")
        meta = {"config": asdict(self.cfg), "next_output": self.next_output,
                "dt_next": self.dt_next, "outputs": self.outputs,
                "first_output": self.first_output, "plate_area0": self.plate_area0,
                "outline_segments": self.outline_segments, "pinches": self._pinches,
                "closing": None if self._closing is None else list(self._closing),
                **self.outlines.to_meta()}
        atomic_write_text(self.out / "checkpoint.json", json.dumps(meta))

    @classmethod
    def restart(cls, out, cfg: Optional[PlateConfig] = None) -> "SinkingPlate":
        """Continue from the checkpoint in ``out`` (its configuration unless
        ``cfg`` is given)."""
        out = Path(out)
        if cfg is None:
            cfg = stored_config(out)   # (json keeps inf as Infinity)
        meta = json.loads((out / "checkpoint.json").read_text())
        lm = LagrangianMesh.load(out / "checkpoint.npz")
        return cls(cfg, out, _state=(lm, meta))

    # -- the loop ---------------------------------------------------------------
    def run(self, progress: bool = True, max_steps: Optional[int] = None) -> Path:
        """Advance to ``end_time`` (or ``max_steps`` more steps); returns the
        diagnostics CSV path. ``ValueError`` for a negative ``max_steps``."""
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps < 0):
            raise ValueError(f"max_steps must be a non-negative integer, got {max_steps!r}")
        c = self.cfg
        lm = self.lm
        keep = lm.time if lm.step else None
        log = CSVLog(self.out / "diagnostics.csv", keep_until=keep) if self.root else None
        self._pvd = PVDWriter(self.out / "plate.pvd", keep_until=keep) if self.root else None
        if lm.step == 0:
            self.write_output()
            # an early snapshot (t = 1, the paper's first panel), then every interval
            self.next_output = min(1.0, c.output_interval)
            self.checkpoint()
        bar = None
        if progress and self.root:
            bar = progress_bar(c.end_time, lm.time, "sinking plate")
        steps = 0
        try:
            while lm.time < c.end_time * (1 - 1e-12):
                if max_steps is not None and steps >= max_steps:
                    break
                dt = min(self.dt_next, self.next_output - lm.time, c.end_time - lm.time)
                if self.next_output - lm.time - dt < 1e-9 * c.max_dt:
                    dt = self.next_output - lm.time
                row = self.step(dt)
                if self.ranks > 1:
                    self.check_replicated()
                if log is not None:
                    log.append(row)
                steps += 1
                if lm.time >= self.next_output * (1 - 1e-12) or lm.time >= c.end_time * (1 - 1e-12):
                    self.write_output(self._last)
                    self.next_output = next_output_time(lm.time, c.output_interval)
                if lm.step % c.checkpoint_every == 0:
                    self.checkpoint()
                if bar is not None:
                    bar.update(lm.time - bar.n)
                    bar.set_postfix_str(f"step {lm.step}, flips {row['flips']}, "
                                        f"depth {row['plate_depth']:.3f}")
        finally:
            if bar is not None:
                bar.close()
        self.checkpoint()
        return self.out / "diagnostics.csv"

    # -- figures ----------------------------------------------------------------
    def figures(self) -> list:
        """fig6.png, plate_strain.png and diagnostics.png in the output folder
        (:func:`~skfem_nem.apps.plate_figures.plate_figures`; rank 0 only); returns
        their paths."""
        return plate_figures(self) if self.root else []


def run(cfg: PlateConfig, out="out/sinking-plate", restart: bool = False,
        progress: bool = True, max_steps: Optional[int] = None) -> SinkingPlate:
    """Run (or continue) a sinking-plate simulation; writes all outputs."""
    sim = SinkingPlate.restart(out, cfg) if restart else SinkingPlate(cfg, out)
    sim.run(progress=progress, max_steps=max_steps)
    sim.figures()
    return sim
