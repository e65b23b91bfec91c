"""Visco-elasto-plastic (Maxwell + von Mises) solids on top of the Stokes solver.

The stress history ``tau`` (deviatoric, Pa) lives at the quadrature points of
the triangles, shape (2, 2, ne, nq): the paper's "tensorial memory"; on tetrahedra
(3D spaces) shape (3, 3, ne, nq), past the paper's scalar-only 3D memory. One time
step of length ``dt`` (s) is the velocity-based incremental formulation of
Moresi, Dufour and Muehlhaus (2003) and Gerya (2010):

* Maxwell body (viscosity ``eta``, shear modulus ``mu``), backward Euler::

      Z = mu dt / (mu dt + eta),   eta_ve = eta Z = 1 / (1/eta + 1/(mu dt)),
      tau_new = 2 eta_ve eps(u) + (1 - Z) tau_rot,

  so the Stokes solve takes ``eta = eta_ve`` and ``tau0 = (1 - Z) tau_rot``
  (``1 - Z = eta_ve / (mu dt)``). As ``eta / (mu dt)`` grows, ``eta_ve ->
  mu dt`` and ``1 - Z -> 1``: ``tau_new = tau_old + 2 mu eps(u dt)``,
  incremental linear elasticity with incompressibility.
* Objective (Jaumann) rotation of the old stress with the spin
  ``W = (grad u - grad u^T) / 2``: ``tau_rot = tau_old + dt (W tau_old -
  tau_old W)`` (``rotation="jaumann"``), or the exact rotation ``R tau_old
  R^T``, ``R = exp(W dt)``, which keeps the invariants exactly
  (``rotation="exact"``).
* Von Mises plasticity: with the effective strain rate ``edot_eff = eps(u) +
  tau_rot / (2 mu dt)`` the trial stress is ``2 eta_ve edot_eff``; where its
  second invariant exceeds the yield stress ``Y`` it is scaled back onto the
  yield surface (radial return), which is the same as the effective viscosity
  ``eta_vp = Y / (2 edot_eff_II)``. The Stokes solve is repeated with the
  updated viscosity (Picard iterations) until the velocity settles.

The stress is built from the full symmetric velocity gradient of the discrete
solution (its trace, the pointwise divergence, is zero only weakly), so that
the stored stress is exactly the one the discrete momentum balance used: an
elastic body under a constant load stays at rest in the next step.

Invariants: ``II(t) = sqrt(t_ij t_ij / 2)`` of the 2D deviatoric tensor
(``sqrt(t_xx^2 + t_xy^2)`` when traceless), equal to ``sqrt(J2)`` in plane
strain. The yield stress is therefore the shear yield stress ``k``; a von
Mises tensile yield stress ``sigma0`` corresponds to ``k = sigma0 / sqrt(3)``.

Prescribed non-zero wall velocities (pure shear, a punch) are handled here by
:func:`solve_stokes_bc`, which reuses :func:`skfem_nem.models.stokes.assemble_stokes`
and solves the saddle-point system directly with the prescribed values lifted
to the right side; it also returns the reaction forces on the prescribed
dofs, and fixes the pressure mean only where the walls confine the flow.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Callable, Optional, Sequence, Tuple, Union

import numpy as np

from .return_mapping import (ArrayLike, deviator, maxwell_coefficients, return_map,
                             rotate_stress, second_invariant, spin, strain_rate, vep_update)
from .stokes import (StokesCache, StokesSolution, StokesSpaces, quadrature_values,
                     solve_stokes)
from .stokes_share import check_divided, largest
from .stokes_solvers import CACHED_SOLVERS, check_solver

__all__ = ["Material", "combine_materials", "maxwell_coefficients", "strain_rate", "spin",
           "deviator", "second_invariant", "rotate_stress", "return_map",
           "prescribed_velocity", "solve_stokes_bc", "velocity_gradient", "VEPStep", "vep_step",
           "to_ip_field", "from_ip_field", "vep_update", "PicardNotConverged"]


class PicardNotConverged(RuntimeError):
    """The plastic (Picard) iterations of :func:`vep_step` did not settle: a caller that
    can shorten the step (the yielded region then changes less) may retry."""

# Picard iterations stop once the effective viscosity changes by less than
# this (max |log ratio|) in the first iteration, or after the second
VISCOSITY_SETTLED = 1e-12
# after this many Picard iterations without convergence, iterates that cycle (two
# successive velocity changes pointing opposite ways: the yielded region jumping back and
# forth, the change stuck at a few times tol; measured on a plate pressed onto the bottom)
# switch to a relaxed viscosity update for the rest of the step: each iterate moves only
# PICARD_RELAXATION of the way (in log viscosity), and the velocity change must fall
# below PICARD_RELAXATION * tol (a relaxed iterate changes by that fraction of the fixed
# point's residual). A slow, steady approach is left alone (relaxing would slow it). 40
# lies well past what converging steps take (at most 33 iterations over the sinking
# plate's robustness runs): they are untouched
PICARD_RELAX_AFTER = 40
PICARD_RELAXATION = 0.5
# default lower bound of the effective viscosity, relative to the smallest
# visco-elastic viscosity (keeps the Stokes system solvable where yielding)
MIN_VISCOSITY_FACTOR = 1e-8
# relative residual of a Stokes solve that is final: the one solve of a step without
# plastic iterations (the solvers' own default)
LINEAR_TOL = 1e-10
# the Stokes solves of Picard iterations stop at this factor times the Picard tolerance
# (on the relative velocity change), not below LINEAR_TOL: their error stays three orders
# below the change that ends the iterations (docs/stokes.md measures what it saves)
PICARD_LINEAR_FACTOR = 1e-3


# ---------------------------------------------------------------------------
# material
# ---------------------------------------------------------------------------

def _where(bad: np.ndarray) -> str:
    """Position of the first True of ``bad`` as words (element / point)."""
    idx = np.argwhere(bad)[0]
    if bad.ndim == 1:
        return f" at element {int(idx[0])}"
    if bad.ndim == 2:
        return f" at element {int(idx[0])}, quadrature point {int(idx[1])}"
    return f" at index {tuple(int(i) for i in idx)}"


def _check(name: str, value, allow_inf: bool, optional: bool = False):
    if value is None and optional:
        return None
    v = np.asarray(value, dtype=float)
    if v.ndim > 2:
        raise ValueError(f"{name} must be a number, a per-element (ne,) or a per-point (ne, nq) "
                         f"array, got shape {v.shape}")
    bad = np.isnan(v) | (v <= 0) | (np.isinf(v) if not allow_inf else False)
    if np.any(bad):
        first = v[tuple(np.argwhere(bad)[0])] if v.ndim else float(v)
        more = f" ({int(np.count_nonzero(bad))} bad value(s))" if v.ndim else ""
        raise ValueError(f"{name} must be positive" + ("" if allow_inf else " and finite")
                         + f", got {first}" + (_where(bad) if v.ndim else "") + more)
    return float(v) if v.ndim == 0 else v.copy()


@dataclass(frozen=True)
class Material:
    """A Maxwell visco-elastic, von Mises plastic material.

    Each parameter is a number, a per-element array (ne,) or a per-point
    array (ne, nq) matching :attr:`StokesSpaces.quadrature_points`.

    Parameters
    ----------
    viscosity
        Shear viscosity eta (Pa s), positive; ``inf`` for a purely elastic
        solid (then ``shear_modulus`` must be finite).
    shear_modulus
        Elastic shear modulus mu (Pa), positive; ``inf`` (default) for a
        viscous fluid.
    yield_stress
        Von Mises yield stress in shear, the limit of the second invariant
        of the deviatoric stress (Pa), positive; ``inf`` (default): no
        plasticity. (Tensile yield stress ``sigma0 = sqrt(3) * yield_stress``.)
    density
        Mass density (kg m^-3), positive, or None (no gravity load).

    Raises
    ------
    ValueError
        Naming the parameter (and element / point of an array) for NaN,
        zero, negative or (where not allowed) infinite values.
    """

    viscosity: ArrayLike
    shear_modulus: ArrayLike = np.inf
    yield_stress: ArrayLike = np.inf
    density: Optional[ArrayLike] = None

    def __post_init__(self):
        object.__setattr__(self, "viscosity", _check("viscosity", self.viscosity, True))
        object.__setattr__(self, "shear_modulus",
                           _check("shear_modulus", self.shear_modulus, True))
        object.__setattr__(self, "yield_stress", _check("yield_stress", self.yield_stress, True))
        object.__setattr__(self, "density", _check("density", self.density, False, True))
        both = np.isinf(self.viscosity) & np.isinf(self.shear_modulus)
        if np.any(both):
            raise ValueError("viscosity and shear_modulus are both infinite (a rigid body)"
                             + (_where(np.broadcast_to(both, np.broadcast(
                                 self.viscosity, self.shear_modulus).shape))
                                if np.ndim(both) else ""))

    def at_points(self, name: str, ne: int, nq: int) -> np.ndarray:
        """Parameter ``name`` broadcast to (ne, nq)."""
        v = np.asarray(getattr(self, name), dtype=float)
        if v.ndim == 1:
            if v.shape[0] != ne:
                raise ValueError(f"{name} has {v.shape[0]} per-element values, the mesh has "
                                 f"{ne} elements")
            v = v[:, None]
        elif v.ndim == 2 and v.shape != (ne, nq):
            raise ValueError(f"{name} has shape {v.shape}, expected ({ne}, {nq})")
        return np.ascontiguousarray(np.broadcast_to(v, (ne, nq)))


def combine_materials(materials: Sequence[Material], phase) -> Material:
    """One :class:`Material` with per-element (or per-point) arrays from a
    list of materials and a phase index per element (ne,) or point (ne, nq).

    Raises ``ValueError`` naming the element of a phase index out of range,
    or the material index whose parameters are not scalars.
    """
    phase = np.asarray(phase)
    if not np.issubdtype(phase.dtype, np.integer):
        raise ValueError(f"phase must be an integer array, got dtype {phase.dtype}")
    bad = (phase < 0) | (phase >= len(materials))
    if bad.any():
        raise ValueError(f"phase index {int(phase[tuple(np.argwhere(bad)[0])])} out of range "
                         f"0..{len(materials) - 1}" + _where(bad))
    out = {}
    for f in fields(Material):
        vals = []
        for i, m in enumerate(materials):
            v = getattr(m, f.name)
            if v is not None and np.ndim(v) != 0:
                raise ValueError(f"material {i}: {f.name} must be a number to combine materials")
            vals.append(v)
        if f.name == "density" and any(v is None for v in vals):
            if not all(v is None for v in vals):
                i = [v is None for v in vals].index(True)
                raise ValueError(f"material {i} has no density while others have one")
            out[f.name] = None
            continue
        out[f.name] = np.asarray(vals, dtype=float)[phase]
    return Material(**out)


# ---------------------------------------------------------------------------
# layouts (the pointwise update itself: :mod:`.return_mapping`)
# ---------------------------------------------------------------------------

def to_ip_field(tau: np.ndarray) -> np.ndarray:
    """(2, 2, ne, nq) -> (ne, nq, 2, 2): the layout of :class:`~skfem_nem.LagrangianMesh`
    integration-point fields (3 points per triangle: ``stokes_spaces(mesh)``)."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(tau), (0, 1), (2, 3)))


def from_ip_field(F: np.ndarray) -> np.ndarray:
    """(ne, nq, 2, 2) -> (2, 2, ne, nq), the inverse of :func:`to_ip_field`."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(F), (2, 3), (0, 1)))


# ---------------------------------------------------------------------------
# Stokes with prescribed wall velocities
# ---------------------------------------------------------------------------

def prescribed_velocity(spaces: StokesSpaces, facets, value: Union[Callable, Sequence[float]],
                        components: Optional[Sequence[int]] = None
                        ) -> Tuple[np.ndarray, np.ndarray]:
    """Velocity dofs and values on boundary facets.

    Parameters
    ----------
    facets
        Facet indices of ``spaces.mesh``, a boundary name, or ``"all"``.
    value
        Callable of points x (d, m) returning (d, m) velocities (m/s), or a
        constant (d,) velocity.
    components
        Which components to prescribe (0: x, 1: y, 2: z; default all).

    Returns
    -------
    (dofs, values), both (k,), for ``solve_stokes_bc(prescribed=...)``.
    """
    mesh, ub = spaces.mesh, spaces.ubasis
    if isinstance(facets, str):
        facets = mesh.boundary_facets() if facets == "all" else mesh.boundaries[facets]
    facets = np.asarray(facets, dtype=np.int64)
    dofs, vals = [], []
    for c in range(mesh.dim()) if components is None else components:
        d = ub.get_dofs(facets).all(f"u^{c + 1}")
        x = ub.doflocs[:, d]
        v = (np.asarray(value(x), dtype=float)[c] if callable(value)
             else np.full(d.size, float(np.asarray(value, dtype=float)[c])))
        dofs.append(d)
        vals.append(np.broadcast_to(v, d.shape))
    dofs, vals = np.concatenate(dofs), np.concatenate(vals)
    if not np.isfinite(vals).all():
        first = int(dofs[~np.isfinite(vals)][0])
        raise ValueError(f"prescribed velocity is not finite at dof {first}")
    return dofs, vals


def solve_stokes_bc(spaces: StokesSpaces, eta, f=0.0, tau0=None,
                    prescribed: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                    free_slip: Union[str, Sequence[str], None] = "all",
                    no_slip: Union[str, Sequence[str], None] = None,
                    pressure_mean: Optional[bool] = None, solver: str = "auto",
                    tol: float = 1e-10, constraints=None, maxiter: int = 2000,
                    cache: Optional[StokesCache] = None) -> StokesSolution:
    """Stokes solve with prescribed velocities: :func:`skfem_nem.models.stokes.solve_stokes`
    with ``prescribed`` (kept for its reaction forces and defaults).

    Parameters
    ----------
    eta, f, tau0
        Viscosity (Pa s), body force (N m^-3) and known stress (Pa), see
        :func:`skfem_nem.models.stokes.assemble_stokes`.
    prescribed
        ``(dofs, values)`` from :func:`prescribed_velocity` (m/s); they
        override the zero wall conditions on the same dofs.
    free_slip, no_slip
        Zero wall conditions (see :func:`skfem_nem.models.stokes.wall_dofs`).
    pressure_mean
        Fix the pressure by its mean (zero). Default: only if every boundary
        node has a constrained velocity component (no free surface).
    solver, tol, maxiter, constraints, cache
        As for :func:`skfem_nem.models.stokes.solve_stokes` (default solver
        ``"auto"``).

    Returns
    -------
    StokesSolution
        ``info["reaction"]``: (nu,) the boundary forces on the body at the
        constrained dofs (N/m in 2D; zero elsewhere), ``info["fixed"]`` those
        dofs, ``info["bubble"]`` the bubble dof vector where the velocity
        space has condensed bubbles.
    """
    return solve_stokes(spaces, eta, f, tau0, free_slip=free_slip, no_slip=no_slip,
                        prescribed=prescribed, pressure_mean=pressure_mean, solver=solver,
                        tol=tol, maxiter=maxiter, constraints=constraints, cache=cache)


def velocity_gradient(spaces: StokesSpaces, sol: StokesSolution) -> np.ndarray:
    """(2, 2, ne, nq) velocity gradient ``[i, j] = du_i/dx_j`` of a solution (1/s),
    including the condensed bubbles where the space has them."""
    G = np.asarray(spaces.ubasis.interpolate(sol.u).grad)
    ub = sol.info.get("bubble") if isinstance(sol.info, dict) else None
    bb = getattr(spaces, "bubbles", None)
    if ub is not None and bb is not None:
        G = G + bb.gradient_of(ub)
    return G


# ---------------------------------------------------------------------------
# one visco-elasto-plastic step
# ---------------------------------------------------------------------------

@dataclass
class VEPStep:
    """Result of :func:`vep_step` (arrays at the quadrature points).

    Attributes
    ----------
    tau
        New deviatoric stress (2, 2, ne, nq), Pa.
    solution
        The Stokes solution (velocity ``solution.u``, m/s; pressure, Pa).
    strain_rate
        Strain rate of the solution (2, 2, ne, nq), 1/s.
    plastic_strain_rate
        Plastic strain-rate tensor (2, 2, ne, nq), 1/s, and
        ``plastic_rate_II`` its second invariant (ne, nq).
    plastic_strain
        Accumulated plastic strain (ne, nq) (``plastic_strain_old + dt *
        plastic_rate_II``).
    eta_eff
        Effective viscosity used in the last solve (ne, nq), Pa s.
    yielded
        (ne, nq) bool, points on the yield surface.
    iterations, residual
        Picard iterations and the final relative velocity change.
    history
        Relative velocity change of each iteration.
    seconds
        Time the Picard iterations spent in the Stokes ``"assembly"`` and in the
        linear ``"solver"`` (summed over the iterations).
    """

    tau: np.ndarray
    solution: StokesSolution
    strain_rate: np.ndarray
    plastic_strain_rate: np.ndarray
    plastic_rate_II: np.ndarray
    plastic_strain: np.ndarray
    eta_eff: np.ndarray
    yielded: np.ndarray
    iterations: int
    residual: float
    history: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)


def vep_step(spaces: StokesSpaces, material: Material, tau_old: np.ndarray, dt: float,
             f=0.0, gravity: Optional[Sequence[float]] = None,
             prescribed: Optional[Tuple[np.ndarray, np.ndarray]] = None,
             free_slip: Union[str, Sequence[str], None] = "all",
             no_slip: Union[str, Sequence[str], None] = None,
             pressure_mean: Optional[bool] = None,
             plastic_strain: Optional[np.ndarray] = None,
             rotation: str = "jaumann", tol: float = 1e-6, maxiter: int = 100,
             min_viscosity: Optional[float] = None, u_guess: Optional[np.ndarray] = None,
             constraints=None, eta_guess: Optional[np.ndarray] = None,
             solver: str = "auto", cache: Optional[StokesCache] = None,
             linear_tol: Optional[float] = None, first_tol: Optional[float] = None,
             on_iterate: Optional[Callable[[StokesSolution], None]] = None) -> VEPStep:
    """One visco-elasto-plastic time step (see the module docstring).

    Parameters
    ----------
    spaces
        From :func:`skfem_nem.models.stokes.stokes_spaces`.
    material
        The :class:`Material` (per-element or per-point arrays allowed).
    tau_old
        Deviatoric stress at the start of the step, (d, d, ne, nq), Pa (d = 3 on
        tetrahedra; for :class:`~skfem_nem.LagrangianMesh` fields use :func:`from_ip_field`).
    dt
        Time step (s), positive and finite.
    f, gravity
        Body force (N m^-3, see ``assemble_stokes``) plus ``density *
        gravity`` if ``gravity`` (d,) (m s^-2) is given.
    prescribed, free_slip, no_slip, pressure_mean
        Boundary conditions, see :func:`solve_stokes_bc`.
    plastic_strain
        Accumulated plastic strain (ne, nq) at the start (default zero).
    rotation
        ``"jaumann"``, ``"exact"`` (see :func:`rotate_stress`) or ``"none"``; the spin is
        the current Picard iterate's (``u_guess``'s for the first solve, else zero).
    tol, maxiter, linear_tol, first_tol
        Picard iterations stop when the relative change of the velocity (max norm)
        falls below ``tol``; each Stokes solve at the relative residual ``linear_tol``,
        default ``PICARD_LINEAR_FACTOR * tol`` (at least ``LINEAR_TOL``), or
        ``LINEAR_TOL`` for a step without iterations (``docs/stokes.md``); the first solve
        at ``first_tol`` if given (never the iterate accepted: ``docs/rheology.md``).
    min_viscosity
        Lower bound of the effective plastic viscosity (Pa s); default
        ``1e-8`` times the smallest visco-elastic viscosity.
    u_guess, eta_guess
        Velocity dofs and effective viscosity (ne, nq; clipped to ``[min_viscosity,
        eta_ve]``, default ``eta_ve``) to start from, e.g. the previous step's.
    constraints
        Extra linear constraints on the velocity, ``C`` for ``C u = 0`` or ``(C, c)`` for
        ``C u = c`` (e.g. the net flux through a material outline), see :func:`solve_stokes_bc`.
    solver, cache
        Stokes solver of the Picard iterations (``"auto"``: ``"schur"``, as they share
        a cache) and a :class:`~skfem_nem.models.stokes.StokesCache` kept across steps
        (default: a new one per step, shared by its Picard iterations).
    on_iterate
        Called with each Picard iterate's Stokes solution; an exception it raises ends
        the step and reaches the caller (a step seen to be too long from its first).

    Raises
    ------
    ValueError
        For a bad ``dt``, ``solver``, ``cache``, ``linear_tol`` or ``first_tol`` (in
        (0, 1)), a stress of the wrong shape, or a non-finite stress (naming the element).
    RuntimeError
        If the Picard iterations do not converge in ``maxiter`` (naming both numbers).
    """
    check_solver(solver, cache), check_divided(spaces, solver)
    if cache is None and solver in CACHED_SOLVERS:
        cache = StokesCache()
    st = _step_setup(spaces, material, tau_old, dt, f, gravity, plastic_strain, rotation,
                     min_viscosity)
    u = None if u_guess is None else np.asarray(u_guess, dtype=float)
    G = None if u is None else np.asarray(spaces.ubasis.interpolate(u).grad)
    eta_eff = st.start_viscosity(eta_guess)
    walls = (prescribed, free_slip, no_slip, pressure_mean)
    floor, first = _linear_tol(linear_tol, tol, st), _first_tol(first_tol, st)
    pic = _picard(spaces, st, u, G, eta_eff, walls, constraints, tol, maxiter,
                  dict(solver=solver, cache=cache, tol=floor), on_iterate, first)
    return _vep_result(st, pic)


def _linear_tol(linear_tol, tol: float, st: _StepSetup) -> float:
    """The relative residual of the step's Stokes solves (see :func:`vep_step`);
    ``ValueError`` unless a given one is a number in (0, 1)."""
    if linear_tol is None:
        return max(LINEAR_TOL, PICARD_LINEAR_FACTOR * tol) if st.iterate else LINEAR_TOL
    _check_fraction("linear_tol", linear_tol)
    return float(linear_tol)


def _first_tol(first_tol, st: _StepSetup) -> Optional[float]:
    """The first solve's relative residual where the step iterates (see :func:`vep_step`);
    ``ValueError`` unless a given one is a number in (0, 1)."""
    if first_tol is None:
        return None
    _check_fraction("first_tol", first_tol)
    return float(first_tol) if st.iterate else None


def _check_fraction(name: str, v) -> None:
    """``ValueError`` naming ``name`` unless ``v`` is a number in (0, 1)."""
    if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < 1):
        raise ValueError(f"{name} must be a number in (0, 1), got {v!r}")


@dataclass
class _StepSetup:
    """The checked input of one :func:`vep_step` at the quadrature points."""

    tau_old: np.ndarray          # (2, 2, ne, nq) stress at the start
    dt: float
    rotation: str
    eta_ve: np.ndarray           # (ne, nq) visco-elastic viscosity
    chi: np.ndarray              # (ne, nq) 1 / (mu dt), zero for mu = inf
    yield_stress: np.ndarray     # (ne, nq)
    eta_min: float               # lower bound of the effective viscosity
    load: np.ndarray             # (2, ne, nq) body force
    plastic_strain: np.ndarray   # (ne, nq) at the start
    # the largest of a number over the MPI ranks (spaces of one rank's cells) or itself
    largest: Callable[[float], float] = float

    @cached_property
    def iterate(self) -> bool:
        """True if the viscosity or the stress depends on the velocity: a finite yield
        stress, or an old stress that the rotation turns (none without elasticity), at
        any point (of any rank's cells)."""
        here = bool(np.isfinite(self.yield_stress).any()) or (
            self.rotation != "none" and bool(np.any(self.chi * np.abs(self.tau_old))))
        return self.largest(float(here)) > 0

    def rotated(self, G: Optional[np.ndarray]) -> np.ndarray:
        """The old stress rotated with the spin of the velocity gradient ``G``."""
        if self.rotation == "none" or G is None:
            return self.tau_old
        return rotate_stress(self.tau_old, spin(G), self.dt, self.rotation)

    def start_viscosity(self, eta_guess: Optional[np.ndarray]) -> np.ndarray:
        """The effective viscosity of the first Picard iteration."""
        if eta_guess is None:
            return self.eta_ve.copy()
        ne, nq = self.eta_ve.shape
        eg = np.asarray(eta_guess, dtype=float)
        if eg.shape != (ne, nq) or not np.isfinite(eg).all():
            raise ValueError(f"eta_guess must be finite with shape ({ne}, {nq}), got "
                             f"{eg.shape}")
        return np.clip(eg, self.eta_min, self.eta_ve)


@dataclass
class _PicardResult:
    """The last Picard iterate of :func:`vep_step`."""

    solution: StokesSolution
    grad: np.ndarray             # (2, 2, ne, nq) velocity gradient
    strain_rate: np.ndarray      # (2, 2, ne, nq)
    eta_eff: np.ndarray          # (ne, nq) viscosity of the last solve
    iterations: int
    residual: float
    history: list
    seconds: dict
    rotated: np.ndarray          # (d, d, ne, nq) old stress rotated with grad's spin


def _checked_stress(spaces: StokesSpaces, tau_old, dt, rotation: str) -> np.ndarray:
    """``tau_old`` as a float array, after checking ``dt``, ``rotation`` and it."""
    if not (np.isscalar(dt) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"time step dt must be a positive finite number, got {dt!r}")
    if rotation not in ("jaumann", "exact", "none"):
        raise ValueError(f"rotation must be 'jaumann', 'exact' or 'none', got {rotation!r}")
    d, ne, nq = spaces.quadrature_points.shape
    tau_old = np.asarray(tau_old, dtype=float)
    if tau_old.shape != (d, d, ne, nq):
        raise ValueError(f"tau_old has shape {tau_old.shape}, expected ({d}, {d}, {ne}, {nq})")
    bad = ~np.isfinite(tau_old).all(axis=(0, 1))
    if bad.any():
        raise ValueError("tau_old is not finite" + _where(bad))
    return tau_old


def _step_setup(spaces: StokesSpaces, material: Material, tau_old, dt, f, gravity,
                plastic_strain, rotation: str, min_viscosity) -> _StepSetup:
    """Material coefficients, load and start state of one step at the
    quadrature points (raising ``ValueError`` for bad input)."""
    tau_old = _checked_stress(spaces, tau_old, dt, rotation)
    ne, nq = tau_old.shape[2:]
    eta = material.at_points("viscosity", ne, nq)
    mu = material.at_points("shear_modulus", ne, nq)
    Y = material.at_points("yield_stress", ne, nq)
    eta_ve, keep = maxwell_coefficients(eta, mu, dt)
    chi = keep / eta_ve           # 1 / (mu dt), zero for mu = inf
    def most(v: float) -> float:
        return largest(spaces, v)

    eta_min = (-MIN_VISCOSITY_FACTOR * most(-float(eta_ve.min())) if min_viscosity is None
               else float(min_viscosity))
    load = quadrature_values(spaces, f, "body force f", shape=(tau_old.shape[0],))
    if gravity is not None:
        if material.density is None:
            raise ValueError("gravity given but the material has no density")
        rho = material.at_points("density", ne, nq)
        load = load + rho[None] * np.asarray(gravity, dtype=float)[:, None, None]
    ps = np.zeros((ne, nq)) if plastic_strain is None else np.asarray(plastic_strain, dtype=float)
    if ps.shape != (ne, nq):
        raise ValueError(f"plastic_strain has shape {ps.shape}, expected ({ne}, {nq})")
    return _StepSetup(tau_old, dt, rotation, eta_ve, chi, Y, eta_min, load, ps, most)


def _plastic_viscosity(st: _StepSetup, eps: np.ndarray, rotated: np.ndarray) -> np.ndarray:
    """Effective viscosity: ``eta_ve``, or ``Y / (2 edot_eff_II)`` where the
    trial stress exceeds the yield stress; at least ``eta_min``. ``rotated``: the old
    stress rotated with the iterate's spin (``st.rotated(G)``)."""
    edot = eps + 0.5 * st.chi[None, None] * rotated
    IIe = second_invariant(edot)
    with np.errstate(divide="ignore", invalid="ignore"):
        eta_vp = np.where(2.0 * st.eta_ve * IIe > st.yield_stress,
                          st.yield_stress / (2.0 * IIe), st.eta_ve)
    return np.maximum(eta_vp, st.eta_min)


def _picard(spaces: StokesSpaces, st: _StepSetup, u: Optional[np.ndarray],
            G: Optional[np.ndarray], eta_eff: np.ndarray, walls: tuple, constraints,
            tol: float, maxiter: int, solve: dict, on_iterate=None,
            first_tol: Optional[float] = None) -> _PicardResult:
    """Stokes solves with the viscosity and rotated stress of the previous
    iterate until the relative velocity change is below ``tol``; ``solve``:
    the solver keywords of :func:`solve_stokes_bc`; ``on_iterate``, ``first_tol``: see
    :func:`vep_step`."""
    history = []
    seconds = {"assembly": 0.0, "solver": 0.0}
    res, weight, du_last = np.inf, 1.0, None
    rotated = st.rotated(G)    # once per iterate: the load and the viscosity share it
    floor = solve["tol"]
    for it in range(1, maxiter + 1):
        tau0 = (eta_eff * st.chi)[None, None] * rotated
        linear = first_tol if it == 1 and first_tol is not None else floor
        sol = solve_stokes_bc(spaces, eta_eff, st.load, tau0, *walls, constraints=constraints,
                              **dict(solve, tol=linear))
        for part in seconds:
            seconds[part] += sol.info[f"{part}_seconds"]
        if on_iterate is not None:
            on_iterate(sol)
        G = velocity_gradient(spaces, sol)
        eps = strain_rate(G)
        rotated = st.rotated(G)
        eta_new = _plastic_viscosity(st, eps, rotated)
        if u is None:
            res, du = (np.inf if st.iterate else 0.0), None
        else:
            du = sol.u - u
            res = float(np.abs(du).max() / max(np.abs(sol.u).max(), 1e-300))
            if it >= PICARD_RELAX_AFTER and du_last is not None and du @ du_last < 0:
                weight = PICARD_RELAXATION    # cycling (no slow, steady approach): relax
        history.append(res)
        u, du_last = sol.u, du
        d_eta = st.largest(float(np.abs(np.log(eta_new / eta_eff)).max()))
        resolved = linear <= floor      # (a loose first solve: one more, not accepted)
        if res <= tol * weight and (d_eta <= VISCOSITY_SETTLED or it > 1) and resolved:
            eta_eff = eta_new
            break
        eta_eff = eta_eff ** (1.0 - weight) * eta_new ** weight
        if not st.iterate:
            break
    else:
        raise PicardNotConverged(f"visco-elasto-plastic Picard iterations did not converge: "
                                 f"{maxiter} iterations, relative velocity change {res:.3e} > "
                                 f"tol {tol:.1e} (raise maxiter or min_viscosity, or shorten dt)")
    return _PicardResult(sol, G, eps, eta_eff, it, res, history, seconds, rotated)


def _vep_result(st: _StepSetup, pic: _PicardResult) -> VEPStep:
    """New stress by the radial return from the last iterate, and the plastic
    strain rate and strain."""
    edot = pic.strain_rate + 0.5 * st.chi[None, None] * pic.rotated
    tau_trial = 2.0 * st.eta_ve[None, None] * edot
    tau_new, factor = return_map(tau_trial, st.yield_stress)
    bad = ~np.isfinite(tau_new).all(axis=(0, 1))
    if bad.any():
        raise ValueError("the updated stress is not finite" + _where(bad)
                         + f" ({int(bad.any(axis=1).sum())} element(s))")
    # the plastic strain rate: what the stress does not take up where it yielded (zero
    # elsewhere, exactly rather than to round-off)
    pl = np.where(factor < 1.0, edot - tau_new / (2.0 * st.eta_ve[None, None]), 0.0)
    plII = second_invariant(pl)
    return VEPStep(tau=tau_new, solution=pic.solution, strain_rate=pic.strain_rate,
                   plastic_strain_rate=pl, plastic_rate_II=plII,
                   plastic_strain=st.plastic_strain + st.dt * plII, eta_eff=pic.eta_eff,
                   yielded=factor < 1.0, iterations=pic.iterations, residual=pic.residual,
                   history=pic.history, seconds=pic.seconds)
