"""The 3D sinking plate's configuration: a slab in a box, its parameters and their help.

Beside :mod:`skfem_nem.apps.plate_config` (the 2D plate) because the 3D plate is a
different model: a slab in a box, whose material (plate indicator, initial height) is
carried by the nodes and blended across the plate's edge, and whose stress history lives
at the vertex cells of the tetrahedra (``LagrangianMesh3D(ip_fields=...)``) instead of
the 2D plate's outline and integration points. The names the two share mean the
same: ``width`` is the box along x, ``height`` along z, and the plate's rheology
(``plate_viscosity``, ``shear_modulus``, ``yield_stress``) has the 2D defaults, ``inf``
turning elasticity or plasticity off; ``depth``, ``plate_width`` and
``plate_y`` are the third direction. Reading from TOML, the command line and a checkpoint
is :func:`~skfem_nem.apps.plate_config.load_config` with ``kind=Plate3DConfig``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..evolution.remap3d import REMAP_RULES
from ..models.stokes_solvers import SOLVERS
from .plate3d_materials import VISCOSITY_MEANS

__all__ = ["HELP_3D", "Plate3DConfig", "plate_box"]


@dataclass
class Plate3DConfig:
    """Parameters of the 3D sinking-plate run (nondimensional: box height 1, upper
    fluid viscosity 1, buoyancy scale ``plate_density * gravity * height`` = 1.5)."""

    #: what a checkpoint written before a parameter existed ran with: the viscous plate, no
    #: nodes added, one solve a step, the geometric blend (read by
    #: :func:`~skfem_nem.apps.plate_config.stored_config` on ``--restart``)
    OLDER_CHECKPOINTS: ClassVar[dict] = {"shear_modulus": math.inf, "yield_stress": math.inf,
                                         "split_edges": math.inf, "midpoint": False,
                                         "viscosity_mean": "geometric"}

    #: box height (z)
    height: float = 1.0
    #: box width (x)
    width: float = 4.0
    #: box depth (y)
    depth: float = 2.0
    #: height of the fluid layer interface above the bottom
    interface_z: float = 0.75
    #: fluid viscosity above the interface
    eta_upper: float = 1.0
    #: fluid viscosity below the interface
    eta_lower: float = 10.0
    #: plate length (x)
    plate_length: float = 1.5
    #: plate width (y)
    plate_width: float = 1.0
    #: plate thickness (z)
    plate_thickness: float = 0.1
    #: x of the plate centre
    plate_x: float = 2.0
    #: y of the plate centre
    plate_y: float = 1.0
    #: height of the plate centre above the bottom
    plate_z: float = 0.82
    #: density excess of the plate over the fluid
    plate_density: float = 1.5
    #: gravitational acceleration (downward)
    gravity: float = 1.0
    #: plate viscosity (Maxwell)
    plate_viscosity: float = 1e4
    #: plate shear modulus (``inf``: a viscous plate, no stress history)
    shear_modulus: float = 2.0
    #: plate von Mises yield stress, sqrt(J2) (``inf``: no plasticity)
    yield_stress: float = 0.12
    #: how the viscosity is blended across the plate's edge: "harmonic" (the Maxwell
    #: compliance linear in the plate indicator) or "geometric" (the log-viscosity linear in
    #: it, the default before); :mod:`~skfem_nem.apps.plate3d_materials`
    viscosity_mean: str = "harmonic"
    #: number of random interior nodes drawn (before thinning near the walls): 10,100 gives
    #: 10,032 nodes, and the elasto-plastic run takes about 9 and a half minutes on two
    #: cores, its kernels' compilation included (docs/stokes_3d.md)
    nodes: int = 10100
    #: random seed of the node set
    seed: int = 0
    #: node density ~ 1 / (1 + distance to the plate / density_length)^3
    density_length: float = 0.15
    #: end time
    end_time: float = 250.0
    #: largest time step
    max_dt: float = 50.0
    #: smallest time step: a step the nodes cannot make (two nodes would coincide) is
    #: retried with half the time step down to this one, then the run stops
    min_dt: float = 0.01
    #: largest node displacement per step, as a fraction of the node's mean edge length
    cfl: float = 1.0
    #: time between VTU outputs
    output_interval: float = 100.0
    #: relative residual of each Stokes solve; 0: from the Picard tolerance (a thousandth of
    #: it, 1e-10 for a step without plastic iterations: ``vep_step``'s ``linear_tol``)
    solver_tol: float = 0.0
    #: Picard tolerance of the plastic iterations (relative velocity change)
    picard_tol: float = 1e-3
    #: relative residual of a step's first Stokes solve, whose iterate only starts the
    #: Picard iterations (``vep_step``'s ``first_tol``); 0: solver_tol's
    first_solve_tol: float = 1e-3
    #: remap of the stress history on flips: "conservative" or "average"
    remap: str = "conservative"
    #: solve each step a second time on the nodes moved half a step (two solves a step, the
    #: first to a looser tolerance): the depth's time-step error more than halves, and at
    #: cfl 1 a run takes less time than the one-solve step at cfl 0.5 (docs/stokes_3d.md)
    midpoint: bool = True
    #: edges longer than this many target spacings (the initial node set's) are split after
    #: each step, a node added at the midpoint (``inf``: no nodes added)
    split_edges: float = 3.0
    #: Stokes solver (``solve_stokes``'s ``solver``; "auto": FGMRES with AMG in 3D)
    solver: str = "auto"
    #: write a checkpoint every this many steps
    checkpoint_every: int = 5

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad parameter."""
        for k in ("height", "width", "depth", "eta_upper", "eta_lower", "plate_length",
                  "plate_width", "plate_thickness", "plate_density", "gravity",
                  "plate_viscosity", "density_length", "end_time", "max_dt", "min_dt", "cfl",
                  "output_interval", "picard_tol"):
            v = getattr(self, k)
            number = isinstance(v, (int, float)) and not isinstance(v, bool)
            if not (number and v > 0 and math.isfinite(v)):
                raise ValueError(f"{k} must be a positive number, got {v!r}")
        for k in ("shear_modulus", "yield_stress"):   # inf: elasticity / plasticity off
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0):
                raise ValueError(f"{k} must be a positive number or inf, got {v!r}")
        v = self.split_edges
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 1):
            raise ValueError(f"split_edges must be a number above 1 or inf, got {v!r}")
        for k in ("nodes", "checkpoint_every"):
            v = getattr(self, k)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{k} must be a positive integer, got {v!r}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        if self.solver not in SOLVERS:
            choices = ", ".join(repr(s) for s in SOLVERS)
            raise ValueError(f"solver must be one of {choices} in 3D, got {self.solver!r}")
        if not 0 < self.interface_z < self.height:
            raise ValueError(f"interface_z must lie inside the box (0, {self.height}), got "
                             f"{self.interface_z!r}")
        if self.min_dt > self.max_dt:
            raise ValueError(f"min_dt must not exceed max_dt ({self.max_dt!r}), got "
                             f"{self.min_dt!r}")
        if self.cfl > 1:
            raise ValueError(f"cfl must not exceed 1, got {self.cfl!r}")
        if self.picard_tol >= 1:
            raise ValueError(f"picard_tol must be below 1, got {self.picard_tol!r}")
        v = self.solver_tol
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 1):
            raise ValueError(f"solver_tol must be 0 (from picard_tol) or a number in (0, 1), "
                             f"got {v!r}")
        v = self.first_solve_tol
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 1):
            raise ValueError(f"first_solve_tol must be 0 (solver_tol's) or a number in "
                             f"(0, 1), got {v!r}")
        if not isinstance(self.midpoint, bool):
            raise ValueError(f"midpoint must be true or false, got {self.midpoint!r}")
        if self.viscosity_mean not in VISCOSITY_MEANS:
            raise ValueError(f"viscosity_mean must be one of "
                             f"{', '.join(map(repr, VISCOSITY_MEANS))}, got "
                             f"{self.viscosity_mean!r}")
        if self.remap not in REMAP_RULES:
            raise ValueError(f"remap must be one of {', '.join(map(repr, REMAP_RULES))}, got "
                             f"{self.remap!r}")
        margin = 0.5 * self.plate_thickness
        for axis, centre, extent, box in (("x", "plate_x", "plate_length", "width"),
                                          ("y", "plate_y", "plate_width", "depth"),
                                          ("z", "plate_z", "plate_thickness", "height")):
            c, e, b = getattr(self, centre), getattr(self, extent), getattr(self, box)
            if c - e / 2 < margin or c + e / 2 > b - margin:
                raise ValueError(f"{centre} / {extent}: the plate spans {axis} = {c - e / 2:g} "
                                 f".. {c + e / 2:g}, which is not inside the box (0, {b:g}) "
                                 f"with a margin of {margin:g}")


def plate_box(c: Plate3DConfig):
    """The plate's lowest and highest corners (3,), (3,) at the start."""
    centre = np.array([c.plate_x, c.plate_y, c.plate_z])
    half = 0.5 * np.array([c.plate_length, c.plate_width, c.plate_thickness])
    return centre - half, centre + half


#: one line of help per parameter (the command line shows them)
HELP_3D = {
    "height": "box height (z)",
    "width": "box width (x)",
    "depth": "box depth (y)",
    "interface_z": "height of the fluid layer interface above the bottom",
    "eta_upper": "fluid viscosity above the interface",
    "eta_lower": "fluid viscosity below the interface",
    "plate_length": "plate length (x)",
    "plate_width": "plate width (y)",
    "plate_thickness": "plate thickness (z)",
    "plate_x": "x of the plate centre",
    "plate_y": "y of the plate centre",
    "plate_z": "height of the plate centre above the bottom",
    "plate_density": "density excess of the plate over the fluid",
    "gravity": "gravitational acceleration (downward)",
    "plate_viscosity": "plate viscosity (Maxwell)",
    "shear_modulus": "plate shear modulus (inf: a viscous plate)",
    "yield_stress": "plate von Mises yield stress, sqrt(J2) (inf: no plasticity)",
    "viscosity_mean": 'viscosity across the plate\'s edge: "harmonic" (compliance linear in '
                      'the plate indicator) or "geometric" (log-viscosity linear in it)',
    "nodes": "number of random interior nodes drawn",
    "seed": "random seed of the node set",
    "density_length": "node density ~ 1 / (1 + distance to the plate / density_length)^3",
    "end_time": "end time",
    "max_dt": "largest time step",
    "min_dt": "smallest time step: a failing step is retried with half the time step down "
              "to this one, then the run stops",
    "cfl": "largest node displacement per step, as a fraction of the node's mean edge length",
    "output_interval": "time between VTU outputs",
    "solver_tol": "relative residual of each Stokes solve (0: a thousandth of picard_tol)",
    "picard_tol": "Picard tolerance of the plastic iterations",
    "first_solve_tol": "relative residual of a step's first Stokes solve, which only starts "
                       "the Picard iterations (0: solver_tol's)",
    "remap": 'remap of the stress history on flips: "conservative" or "average"',
    "midpoint": "solve each step again on the nodes moved half a step (two solves a step, "
                "the first to a looser Picard tolerance; --no-midpoint: one)",
    "split_edges": "edges longer than this many target spacings are split after each step "
                   "(inf: no nodes added)",
    "solver": 'Stokes solver: "auto" (FGMRES with AMG in 3D), "fgmres", "schur", '
              '"schur-amg", "minres" or "direct"',
    "checkpoint_every": "write a checkpoint every this many steps",
}
