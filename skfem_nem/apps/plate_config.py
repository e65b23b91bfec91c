"""The sinking plate's configuration: the parameters of a run, their help texts, and
reading them from a TOML file, the command line's overrides or a checkpoint.

Kept apart from :mod:`skfem_nem.apps.sinking_plate` (the run itself) because the
command line, the benchmarks and a restart read and check a configuration without
building a run; every bad value raises ``ValueError`` naming the key (and the file).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Dict, Optional

from ..models.stokes_solvers import SOLVERS

__all__ = ["HELP", "PlateConfig", "load_config", "stored_config", "stored_dim"]


@dataclass
class PlateConfig:
    """Parameters of the sinking-plate run (nondimensional: L = 1, eta0 = 1,
    buoyancy scale ``plate_density * gravity * L`` = 1 unless changed)."""

    #: box height L
    height: float = 1.0
    #: box width W
    width: float = 10.0
    #: height of the fluid layer interface above the bottom
    interface_z: float = 0.75
    #: fluid viscosity above the interface
    eta_upper: float = 1.0
    #: fluid viscosity below the interface
    eta_lower: float = 10.0
    #: plate length (horizontal)
    plate_length: float = 1.5
    #: plate thickness
    plate_thickness: float = 0.1
    #: horizontal position of the plate centre
    plate_x: float = 5.0
    #: height of the plate centre above the bottom
    plate_z: float = 0.82
    #: density excess of the plate over the fluid
    plate_density: float = 1.5
    #: gravitational acceleration (downward)
    gravity: float = 1.0
    #: plate viscosity (Maxwell)
    plate_viscosity: float = 1e4
    #: plate shear modulus
    shear_modulus: float = 2.0
    #: plate von Mises yield stress (second invariant of the deviatoric stress)
    yield_stress: float = 0.12
    #: number of random interior nodes drawn (before thinning near lines)
    nodes: int = 1500
    #: random seed of the node set
    seed: int = 0
    #: node density ~ 1 / (1 + distance to the plate / density_length)
    density_length: float = 0.15
    #: spacing of the nodes on the plate outline (relative to plate_thickness)
    outline_spacing: float = 0.25
    #: end time
    end_time: float = 1000.0
    #: largest time step
    max_dt: float = 5.0
    #: smallest time step: a step that fails (a move the mesh cannot follow, an unconverged
    #: iteration) is retried with half the time step down to this one, then the run stops
    min_dt: float = 1e-4
    #: largest node displacement per step, as a fraction of its local spacing
    cfl: float = 1.0
    #: time between VTU outputs
    output_interval: float = 100.0
    #: inject nodes where a node's Voronoi area grew past this factor of its target (the
    #: initial node set's spacing, carried by the material; 0: never), and split edges
    #: longer than the quality bound (evolution.spacing.EDGE_FACTOR target spacings)
    inject: float = 2.0
    #: remap of the stress on flips: "conservative" or "average"
    remap: str = "conservative"
    #: integration of the velocity gradients: "smoothed" (consistent) or "gauss"
    integration: str = "smoothed"
    #: Picard tolerance of the plastic iterations
    picard_tol: float = 1e-3
    #: Stokes solver of the Picard iterations (``solve_stokes``'s ``solver``)
    solver: str = "auto"
    #: write a checkpoint every this many steps
    checkpoint_every: int = 10
    #: keep the plate outline and the layer interface as segments (constrained mesh: no
    #: triangle straddles them, the velocity may kink there, the outline cannot cross
    #: itself; interface segments the plate comes too close to are released)
    segments: bool = True
    #: remove nodes the flow crowds together (spacing below a fifth of their reference;
    #: wall nodes too) and merge the segments at folds of the outline (docs/evolution.md,
    #: "Node removal")
    merge: bool = True
    #: hold the plate's area at its initial value: each step's outline-flux constraint
    #: asks for the area the time steps have lost so far to come back in that step
    #: (off: the flux is zero and the area drifts with the time-step error)
    keep_area: bool = True

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad parameter."""
        pos = ["height", "width", "eta_upper", "eta_lower", "plate_length", "plate_thickness",
               "plate_density", "gravity", "plate_viscosity", "shear_modulus", "yield_stress",
               "density_length", "outline_spacing", "end_time", "max_dt", "min_dt", "cfl",
               "output_interval", "picard_tol"]
        for k in pos:
            v = getattr(self, k)
            may_be_inf = k in ("shear_modulus", "yield_stress")
            number = isinstance(v, (int, float)) and not isinstance(v, bool)
            if not (number and v > 0 and (math.isfinite(v) or may_be_inf)):
                raise ValueError(f"{k} must be a positive number, got {v!r}")
        for k in ("nodes", "checkpoint_every"):
            v = getattr(self, k)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{k} must be a positive integer, got {v!r}")
        for name in ("segments", "merge", "keep_area"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        if not (isinstance(self.inject, (int, float)) and (self.inject == 0 or self.inject > 1)):
            raise ValueError(f"inject must be 0 (off) or a factor above 1, got {self.inject!r}")
        if self.remap not in ("conservative", "average"):
            raise ValueError(f"remap must be 'conservative' or 'average', got {self.remap!r}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(map(repr, SOLVERS))}, got "
                             f"{self.solver!r}")
        if self.integration not in ("smoothed", "gauss"):
            raise ValueError(f"integration must be 'smoothed' or 'gauss', got "
                             f"{self.integration!r}")
        if not 0 < self.interface_z < self.height:
            raise ValueError(f"interface_z must lie inside the box (0, {self.height}), got "
                             f"{self.interface_z!r}")
        if self.min_dt > self.max_dt:
            raise ValueError(f"min_dt must not exceed max_dt ({self.max_dt!r}), got "
                             f"{self.min_dt!r}")
        if self.cfl > 1:
            raise ValueError(f"cfl must not exceed 1, got {self.cfl!r}")
        x0, x1 = self.plate_x - self.plate_length / 2, self.plate_x + self.plate_length / 2
        z0, z1 = self.plate_z - self.plate_thickness / 2, self.plate_z + self.plate_thickness / 2
        margin = 0.5 * self.plate_thickness
        if x0 < margin or x1 > self.width - margin:
            raise ValueError(f"plate_x / plate_length: the plate spans x = {x0:g} .. {x1:g}, "
                             f"which is not inside the box (0, {self.width:g}) with a margin "
                             f"of {margin:g}")
        if z0 < margin or z1 > self.height - margin:
            raise ValueError(f"plate_z / plate_thickness: the plate spans z = {z0:g} .. {z1:g}, "
                             f"which is not inside the box (0, {self.height:g}) with a margin "
                             f"of {margin:g}")


#: one line of help per parameter (the command line shows them)
HELP = {
    'height': 'box height L',
    'width': 'box width W',
    'interface_z': 'height of the fluid layer interface above the bottom',
    'eta_upper': 'fluid viscosity above the interface',
    'eta_lower': 'fluid viscosity below the interface',
    'plate_length': 'plate length (horizontal)',
    'plate_thickness': 'plate thickness',
    'plate_x': 'horizontal position of the plate centre',
    'plate_z': 'height of the plate centre above the bottom',
    'plate_density': 'density excess of the plate over the fluid',
    'gravity': 'gravitational acceleration (downward)',
    'plate_viscosity': 'plate viscosity (Maxwell)',
    'shear_modulus': 'plate shear modulus',
    'yield_stress': 'plate von Mises yield stress (second invariant of the deviatoric stress)',
    'nodes': 'number of random interior nodes drawn (before thinning near lines)',
    'seed': 'random seed of the node set',
    'density_length': 'node density ~ 1 / (1 + distance to the plate / density_length)',
    'outline_spacing': 'spacing of the nodes on the plate outline (relative to plate_thickness)',
    'end_time': 'end time',
    'max_dt': 'largest time step',
    'min_dt': 'smallest time step: a failing step is retried with half the time step down '
              'to this one, then the run stops',
    'cfl': 'largest node displacement per step, as a fraction of its local spacing',
    'output_interval': 'time between VTU outputs',
    'inject': "inject nodes where a node's Voronoi area grew past this factor of its target "
              "(the initial node set's spacing, carried with the material; 0: never)",
    'remap': 'remap of the stress on flips: "conservative" or "average"',
    'integration': 'integration of the velocity gradients: "smoothed" (consistent) or "gauss" '
                   '(3-point rule)',
    'picard_tol': 'Picard tolerance of the plastic iterations',
    'solver': 'Stokes solver of the Picard iterations: "auto" ("schur" for the '
              'Picard iterations, which share its factorisation), "schur" (sparse LU of the '
              'viscous block, pressure CG), "fgmres" (AMG-preconditioned flexible GMRES, '
              'linear cost and memory), "schur-amg", "minres", "direct", or "petsc" (PETSc '
              'over MPI: mpiexec -n N skfem-nem sinking-plate --solver petsc; rank 0 writes)',
    'checkpoint_every': 'write a checkpoint every this many steps',
    'segments': 'keep the plate outline and the layer interface (a line of nodes) as edges '
                'of the mesh: a constrained Delaunay triangulation, constrained '
                'natural-neighbour functions, stretched segments split',
    'merge': 'remove nodes the flow crowds together and merge the segments at folds of the '
             'outline',
    'keep_area': "hold the plate's area at its initial value (the outline flux of each step "
                 "gives back what the time steps lost so far, and a least-squares shift of "
                 "the outline what merges at its folds cut off)",
}


def load_config(path: Optional[str] = None, overrides: Optional[Dict] = None,
                kind: type = PlateConfig):
    """A validated configuration of the class ``kind`` (:class:`PlateConfig`, or
    the 3D plate's :class:`~skfem_nem.apps.plate3d_config.Plate3DConfig`) from a TOML
    file (optional) and overrides. The file's keys stand at its top level or all
    under a ``[sinking-plate]`` table. Unknown keys, values of the wrong type, NaN
    and bad values raise ``ValueError`` naming the key (and the file)."""
    data: Dict = {}
    if path is not None:
        data = _read_toml(path)
    data.update({k: v for k, v in (overrides or {}).items() if v is not None})
    return _config_from(data, kind)


def stored_dim(out) -> int:
    """The dimension of the run whose checkpoint is in ``out`` (2 unless stored);
    ``FileNotFoundError`` without one."""
    out = Path(out)
    if not (out / "checkpoint.json").exists():
        raise FileNotFoundError(f"no checkpoint in {out} (checkpoint.json missing)")
    return int(json.loads((out / "checkpoint.json").read_text()).get("dim", 2))


def stored_config(out, overrides: Optional[Dict] = None, kind: type = PlateConfig):
    """The configuration (of the class ``kind``) of the run whose checkpoint is in
    ``out``, with ``overrides`` applied and validated; ``FileNotFoundError``
    without one."""
    out = Path(out)
    stored_dim(out)
    # parameters added since the checkpoint was written: the values it ran with
    data = dict(getattr(kind, "OLDER_CHECKPOINTS", {}))
    data.update(json.loads((out / "checkpoint.json").read_text())["config"])
    data.update(overrides or {})
    return _config_from(data, kind)


def _read_toml(path) -> Dict:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    with open(path, "rb") as fh:
        try:
            data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"{path}: not valid TOML ({err})") from None
    if "sinking-plate" in data:
        table, rest = data["sinking-plate"], sorted(k for k in data if k != "sinking-plate")
        if rest or not isinstance(table, dict):
            raise ValueError(f"{path}: key {rest[0] if rest else 'sinking-plate'!r} stands "
                             f"outside the [sinking-plate] table; put every parameter "
                             f"under the table or all at the top level")
        data = table
    return data


def _config_from(data: Dict, kind: type = PlateConfig):
    """Check names and types, coerce ints to floats where floats are meant
    (and "inf"), then validate."""
    known = {f.name: f for f in fields(kind)}
    kw = {}
    for k, v in data.items():
        if k not in known:
            raise ValueError(f"unknown configuration key {k!r} (known: {', '.join(known)})")
        default = getattr(kind, k)
        if isinstance(default, float) and isinstance(v, str) and v.lower() in ("inf", "infinity"):
            v = math.inf
        if isinstance(default, float) and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if type(v) is not type(default):
            raise ValueError(f"{k} must be {type(default).__name__} (like {default!r}), got "
                             f"{v!r}")
        if isinstance(v, float) and math.isnan(v):
            raise ValueError(f"{k} must be a number, got nan")
        kw[k] = v
    cfg = kind(**kw)
    cfg.validate()
    return cfg
