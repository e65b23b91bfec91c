"""Incompressible Stokes flow with natural-neighbour velocity.

Equations (creeping flow, viscosity ``eta`` > 0, body force ``f``, optional
prescribed stress ``tau0`` such as the elastic memory of a visco-elastic
material)::

    -div(2 eta eps(u) + tau0) + grad p = f,      div u = 0.

Weak form: find (u, p) with ``a(u, v) + b(v, p) = (f, v) - (tau0, eps(v))``
and ``b(u, q) - s(p, q) = 0``, where ``a(u, v) = (2 eta eps(u), eps(v))`` and
``b(v, q) = -(div v, q)``.

Spaces
------
``method="nem"`` (default)
    Vector Sibson (natural-neighbour) velocity on the nodes, enriched by one
    cubic bubble per triangle and component, and continuous piecewise-linear
    (P1) pressure on the same Delaunay triangles: the MINI element's
    construction with natural-neighbour functions in place of P1. The
    bubbles give the pair a uniform inf-sup constant (the MINI proof needs
    only an H1-stable quasi-interpolant in the base space, which
    natural-neighbour functions provide since they reproduce linear
    functions with local support); it is measured by
    :func:`inf_sup_constant` over mesh sequences in the tests (0.29-0.35 on
    100 to 900 random nodes). The bubbles are condensed triangle by
    triangle before the solve, so the unknowns are nodal only. No parameter
    to tune, and consistent.
``method="nem-projection"``
    The same velocity without bubbles, stabilised by the pressure projection
    of Dohrmann and Bochev (2004), ``s(p, q) = ((p - P0 p) / eta, q - P0 q)``
    (``P0``: L2 projection onto piecewise constants). Without ``s`` the
    pair counts like P1-P1 and has spurious pressure modes (measured inf-sup
    constant 0.0004-0.03). ``s`` is only weakly consistent: it resists the
    hydrostatic pressure gradient with weight 1/eta, so a weak buoyant
    inclusion (viscosity 1e-4 of its surroundings) sinks an order of magnitude too
    fast (15 times at 3000 nodes). Kept for comparison; prefer ``"nem"``.
``method="taylor-hood"``
    scikit-fem's ``ElementVector(ElementTriP2())`` velocity and
    ``ElementTriP1()`` pressure (inf-sup stable, no stabilisation): the
    classical baseline on the same triangles.

For the natural-neighbour methods the pressure term is written as
``b(v, q) = (v, grad q) - oint q v . n`` (``-(div v, q)`` integrated by
parts; the boundary term is exact, and vanishes for test functions of
free-slip and no-slip walls). The two agree for exact integration, but
natural-neighbour functions are not polynomials and Gauss quadrature is not
exact for them; in the gradient form a hydrostatic pressure balances a
piecewise-constant body force exactly at every quadrature point, so
spurious buoyancy-driven flow cannot arise (with ``-(div v, q)`` a block
1e4 times weaker than its surroundings sank 3.6 times too fast).

Natural-neighbour functions are C1 across element edges, so they cannot
follow the kink of the velocity at a viscosity jump: velocity errors at
material interfaces converge about like h (Taylor-Hood on triangles whose
edges follow the interface: h^3). On a mesh whose interface nodes are
joined as segments (``delaunay_mesh(points, segments=...)``) the velocity
basis is built from constrained natural neighbours, which may kink across
the segments: the velocity converges at rate 2 again and the pressure
spikes at the interface nodes disappear. See ``docs/stokes.md``.

Boundary conditions
-------------------
Free slip on axis-aligned walls (normal velocity zero, no tangential
traction) and no slip (both components zero) are imposed on the nodal
values; on convex-hull edges natural-neighbour functions reduce to the
linear 1D weights, so the conditions hold exactly along the walls. The
pressure is fixed by its mean (zero) through a Lagrange multiplier.

Solvers
-------
``solver="auto"`` (default: ``"fgmres"`` for a single large solve at a high
viscosity contrast, ``"schur"`` otherwise), ``"schur"``, ``"schur-amg"``, ``"direct"``,
``"minres"``, ``"fgmres"`` and ``"petsc"`` (MPI, ``docs/parallel.md``): see
:mod:`skfem_nem.models.stokes_solvers`. Iteration
counts are reported in :class:`StokesSolution`; a :class:`StokesCache`
carries the factorisation or AMG hierarchy and the last solution from one
solve to the next.

Module layout
-------------
This module holds the forms and the assembly (with the static condensation of
the bubbles) and the solve. The spaces live in
:mod:`skfem_nem.models.stokes_bases` (re-exported here), the walls and
constraints on the velocity dofs in :mod:`skfem_nem.models.stokes_walls`; the
solvers are plain linear algebra on the assembled blocks and live in
:mod:`skfem_nem.models.stokes_solvers`, which never imports this module.
:func:`solve_stokes` here imposes the walls, prescribed velocities and extra
constraints, hands the reduced saddle-point problem to the chosen solver and
maps its solution back.

Distributed assembly
--------------------
With ``solver="petsc"`` on several MPI ranks each rank assembles only its part
of the cells (:meth:`StokesSpaces.restricted`, the shares adding up to the
whole system) and PETSc sums the rows each rank owns; the mesh stays the same
on every rank (``docs/parallel.md``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Optional, Sequence, Union

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import BilinearForm, LinearForm
from skfem.helpers import ddot, div, dot, grad, sym_grad

from .condensation import condensed_divergence, condensed_viscous
from .block_rows import BlockSymmetricRows
from .condensation_tet import (TetDivergence, condensed_viscous_tet, divergence_tet,
                               loads_tet)
from .pressure_tet import bubble_stabilisation_tet, weighted_mass_tet
from .stokes_bases import StokesSpaces, stokes_spaces  # noqa: F401
from .stokes_walls import (boundary_flux, constraint_rows, fixed_velocity, free_columns,
                           outline_flux, wall_dofs, walls_fix_pressure)
from .saddle_problem import SaddlePointProblem, SaddlePointSolution
from .stokes_solvers import SOLVERS, StokesCache, check_solver
from .stokes_share import Share, distributed

__all__ = ["StokesSpaces", "StokesSolution", "StokesCache", "stokes_spaces", "solve_stokes",
           "outline_flux",
           "boundary_flux",
           "assemble_stokes", "inf_sup_constant", "quadrature_values", "takes_viscous_blocks",
           "wall_dofs"]

Field = Union[float, np.ndarray, Callable]


@dataclass
class StokesSolution:
    """Velocity and pressure dof vectors and how they were obtained."""

    spaces: StokesSpaces
    u: np.ndarray
    p: np.ndarray
    solver: str
    iterations: int = 0
    residual: float = 0.0
    info: dict = field(default_factory=dict)

    def velocity_at_nodes(self) -> np.ndarray:
        """(n, dim) velocity at the mesh nodes."""
        nd = self.spaces.ubasis.dofs.nodal_dofs
        return np.stack([self.u[nd[c]] for c in range(self.spaces.dim)], axis=1)

    def pressure_at_nodes(self) -> np.ndarray:
        """(n,) pressure at the mesh nodes (P1 pressure: its nodal values)."""
        return self.p[self.spaces.pbasis.dofs.nodal_dofs[0]]


# ---------------------------------------------------------------------------
# forms
# ---------------------------------------------------------------------------

@BilinearForm
def viscous(u, v, w):
    return 2.0 * w["eta"] * ddot(sym_grad(u), sym_grad(v))


@BilinearForm
def divergence(u, q, w):
    return -div(u) * q


@BilinearForm
def weak_divergence(u, q, w):
    # -(div u, q) integrated by parts, with u . n = 0 on the walls
    return dot(u, grad(q))


@BilinearForm
def weighted_mass(p, q, w):
    return w["c"] * p * q


@LinearForm
def body_force(v, w):
    return dot(w["f"], v)


@LinearForm
def stress_load(v, w):
    return -ddot(w["tau"], sym_grad(v))


@LinearForm
def _unit(q, w):
    return q


def quadrature_values(spaces: StokesSpaces, value: Field, name: str,
                      shape: tuple = (), positive: bool = False) -> np.ndarray:
    """A coefficient at the quadrature points, shape ``shape + (ne, nq)``.

    ``value`` may be a number, a callable of the quadrature points
    ``x`` (dim, ne, nq), an array already of that shape, or an array of nodal
    values (n,) + ... interpolated with the P1 functions of the mesh (the
    nodes carry the material, as in the paper). Raises ``ValueError`` naming
    ``name`` and the first offending element or node for non-finite values
    (and non-positive ones if ``positive``).
    """
    x = spaces.quadrature_points
    ne, nq = x.shape[1:]
    nn = spaces.mesh.p.shape[1]
    if spaces.elements is not None and not callable(value):
        value = _at_elements(np.asarray(value, dtype=float), spaces, shape)
    if callable(value):
        v = np.asarray(value(x), dtype=float)
        where = "quadrature point"
    else:
        v = np.asarray(value, dtype=float)
        where = "quadrature point"
        if v.shape[:1] == (nn,) and v.shape[1:] == shape and v.shape[-2:] != (ne, nq):
            bad = ~np.isfinite(v) | ((v <= 0) if positive else False)
            if bad.any():
                i = int(np.flatnonzero(bad.reshape(nn, -1).any(1))[0])
                raise ValueError(f"{name} at node {i} is {v[i].tolist()}: must be finite"
                                 + (" and positive" if positive else "")
                                 + f" ({int(bad.reshape(nn, -1).any(1).sum())} node(s))")
            flat = v.reshape(nn, -1)
            vals = [np.asarray(spaces.pbasis.interpolate(flat[:, k])) for k in range(flat.shape[1])]
            v = np.stack(vals).reshape(shape + (ne, nq))
            where = "quadrature point (interpolated from nodes)"
    v = np.broadcast_to(v, shape + (ne, nq)) if v.shape != shape + (ne, nq) else v
    if v.shape != shape + (ne, nq):
        raise ValueError(f"{name} has shape {v.shape}, expected {shape + (ne, nq)}")
    bad = ~np.isfinite(v)
    if positive:
        bad = bad | (v <= 0)
    if bad.any():
        e = int(np.flatnonzero(bad.reshape(-1, ne, nq).any(axis=(0, 2)))[0])
        raise ValueError(f"{name} is not finite" + (" and positive" if positive else "")
                         + f" at a {where} of element {e} (value "
                         f"{np.asarray(v)[..., e, :].min():.6g}; "
                         f"{int(bad.reshape(-1, ne, nq).any(axis=(0, 2)).sum())} element(s))")
    return np.ascontiguousarray(v)


def _at_elements(v: np.ndarray, spaces: StokesSpaces, shape: tuple) -> np.ndarray:
    """A coefficient given at the quadrature points of all triangles, taken at those of
    restricted ``spaces`` (other forms are returned as they are)."""
    full = shape + (spaces.mesh.nelements, spaces.pbasis.quadrature[1].size)
    return v[..., spaces.elements, :] if v.shape == full else v


def _stabilisation(spaces: StokesSpaces, inv_eta: np.ndarray) -> sp.csr_matrix:
    """Dohrmann-Bochev projection matrix ((p - P0 p)/eta, q - P0 q)."""
    pb, p0 = spaces.pbasis, spaces.p0basis
    Mw = weighted_mass.assemble(pb, c=inv_eta)
    Cw = weighted_mass.assemble(pb, p0, c=inv_eta)   # (ne, Np): int w p q0
    C = weighted_mass.assemble(pb, p0, c=np.ones_like(inv_eta))
    area = np.asarray(C.sum(axis=1)).ravel()         # |K|
    W0 = np.asarray(weighted_mass.assemble(p0, c=inv_eta).diagonal())  # int_K w
    # (restricted spaces: the other triangles have no area here, and no entries)
    inv_area = np.divide(1.0, area, out=np.zeros_like(area), where=area > 0)
    Di = sp.diags(inv_area)
    S = Mw - C.T @ Di @ Cw - Cw.T @ Di @ C + C.T @ sp.diags(W0 * inv_area ** 2) @ C
    return ((S + S.T) * 0.5).tocsr()


@dataclass
class StokesSystem:
    """The assembled blocks of the discrete Stokes problem."""

    A: sp.csr_matrix        # (nu, nu) viscous block (or its nodes' 3 x 3 blocks: viscous_blocks)
    B: sp.csr_matrix        # (np, nu) -(div u, q)
    S: sp.csr_matrix        # (np, np) pressure stabilisation (zero for Taylor-Hood)
    Mp: sp.csr_matrix       # (np, np) pressure mass weighted by 1 / eta
    m: np.ndarray           # (np,) integrals of the pressure basis functions
    f: np.ndarray           # (nu,) load
    eta: np.ndarray         # (ne, nq) viscosity at quadrature points
    g: Optional[np.ndarray] = None  # (np,) right side of the continuity equation
    bubble: Optional[tuple] = None  # (A_bb^-1, A_bb^-1 A_bn, B_b, f_b) of the bubbles


def divergence_form(spaces: StokesSpaces):
    """The form of the divergence block: ``-(div u, q)`` for the quadratic velocities
    (Taylor-Hood's, MINI's, and the quadratic natural-neighbour one, whose linear smoothed
    gradients integrate it by parts exactly themselves), its integration by parts
    ``(u, grad q)`` for the linear natural-neighbour velocity (with the exact boundary
    term of :func:`~skfem_nem.models.stokes_walls.boundary_flux` added)."""
    return (divergence if spaces.method in ("taylor-hood", "nem2", "mini")
            else weak_divergence)


def _blocks_once(spaces: StokesSpaces) -> dict:
    """The blocks independent of the coefficients, once per spaces: the divergence
    ``"B"`` (without bubbles; with them it is assembled with their condensation), the
    exact boundary term ``"flux"`` of its integration by parts (B is then -(div u, q)
    also where the normal wall velocity is not zero), the bubbles' divergence ``"Bb"``
    (on tetrahedra also ``"tet_divergence"``, the natural-neighbour part with what its
    condensation needs, :class:`~skfem_nem.models.condensation_tet.TetDivergence`) and the
    pressure functions' integrals ``"m"``."""
    cache = spaces.__dict__.setdefault("_cache", {})
    if "m" in cache:
        return cache
    ub, pb, bb = spaces.ubasis, spaces.pbasis, spaces.bubbles
    bform = divergence_form(spaces)
    if bform is weak_divergence:
        cache["flux"] = boundary_flux(spaces)
    # natural neighbours on tetrahedra: (u, grad q) by sparse products (condensation_tet)
    nem3 = spaces.dim == 3 and bform is weak_divergence
    if bb is None:
        B = divergence_tet(ub, pb) if nem3 else bform.assemble(ub, pb).tocsr()
        cache["B"] = (B - cache["flux"]).tocsr() if "flux" in cache else B
    else:
        cache["Bb"] = bb.bilinear(bform, pb)
        if nem3:  # the natural-neighbour part and the bubbles' blocks, for the condensation
            cache["tet_divergence"] = TetDivergence(divergence_tet(ub, pb), cache["Bb"], pb,
                                                    bb.element_dofs.T)
    cache["m"] = _unit.assemble(pb)
    return cache


def assemble_stokes(spaces: StokesSpaces, eta: Field, f: Field = 0.0,
                    tau0: Optional[Field] = None, viscous_blocks: bool = False) -> StokesSystem:
    """Assemble the Stokes blocks.

    Parameters
    ----------
    eta
        Viscosity (Pa s or nondimensional): number, callable of x (dim, ne, nq),
        (ne, nq) values at the quadrature points, or (n,) nodal values.
    f
        Body force per unit volume, shape (dim,) + that of ``eta`` (e.g.
        ``rho * g``); a callable returns (dim, ne, nq).
    tau0
        Optional known stress (dim, dim, ne, nq) (or callable) moved to the right
        side: the load gains ``-(tau0, eps(v))``.
    viscous_blocks
        The viscous block of the natural-neighbour velocity on tetrahedra as its nodes'
        upper 3 x 3 blocks (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`: half
        the entries made, the same values), which solver ``"fgmres"`` reads as they are;
        ``ValueError`` for other spaces.
    """
    if viscous_blocks and not takes_viscous_blocks(spaces):
        raise ValueError(f"viscous_blocks=True needs the natural-neighbour velocity on "
                         f"tetrahedra, got method {spaces.method!r} in {spaces.dim}D")
    d = spaces.dim
    e = quadrature_values(spaces, eta, "viscosity eta", positive=True)
    fv = quadrature_values(spaces, f, "body force f", shape=(d,))
    t = None if tau0 is None else quadrature_values(spaces, tau0, "stress tau0", shape=(d, d))
    ub, pb = spaces.ubasis, spaces.pbasis

    def loads(basis):
        b = body_force.assemble(basis, f=fv)
        if t is not None:
            b = b + stress_load.assemble(basis, tau=t)
        return b

    cache = _blocks_once(spaces)
    nem3 = spaces.dim == 3 and spaces.bubbles is not None and spaces.method == "nem"
    b = loads_tet(ub, fv, t) if nem3 else loads(ub)
    inv = 1.0 / e
    # (on tetrahedra from 4 x 4 blocks: models.pressure_tet)
    Mp = weighted_mass_tet(pb, inv) if d == 3 else weighted_mass.assemble(pb, c=inv).tocsr()
    m = cache["m"]
    g = np.zeros(pb.N)
    S = _stabilisation(spaces, inv) if spaces.stabilised else sp.csr_matrix((pb.N, pb.N))
    if spaces.bubbles is None:
        A = viscous.assemble(ub, eta=e).tocsr()
        return StokesSystem(0.5 * (A + A.T), cache["B"], 0.5 * (S + S.T), Mp, m, b, e, g,
                            None)
    # static condensation of the bubbles, triangle by triangle (models.condensation)
    bb, Bb = spaces.bubbles, cache["Bb"]                     # Bb (np, nb)
    if spaces.dim == 3:  # by sparse products (models.condensation_tet)
        cv = condensed_viscous_tet(ub, bb, e, blocks=viscous_blocks)
        div = cache["tet_divergence"]
        B = div.condensed(cv)
        S = bubble_stabilisation_tet(pb, div.local, cv.AiAbn.Q)
    else:
        cv = condensed_viscous(ub, bb, e)
        B = condensed_divergence(ub, pb, bb, cv)
        S = (Bb @ cv.Ainv @ Bb.T).tocsr()
    fb = bb.linear(body_force, f=fv)
    if t is not None:
        fb = fb + bb.linear(stress_load, tau=t)
    B = (B - cache["flux"]).tocsr()
    b = b - cv.AiAbn.T @ fb
    g = -(Bb @ (cv.Ainv @ fb))
    return StokesSystem(cv.A, B, 0.5 * (S + S.T), Mp, m, b, e, g,
                        (cv.Ainv, cv.AiAbn, Bb, fb))


def takes_viscous_blocks(spaces: StokesSpaces) -> bool:
    """True for the natural-neighbour velocity on tetrahedra, whose viscous block can be
    assembled as its nodes' 3 x 3 blocks (``assemble_stokes(..., viscous_blocks=True)``)."""
    return spaces.dim == 3 and spaces.bubbles is not None and spaces.method == "nem"


def solve_stokes(spaces: StokesSpaces, eta: Field, f: Field = 0.0,
                 tau0: Optional[Field] = None,
                 free_slip: Union[str, Sequence[str], None] = "all",
                 no_slip: Union[str, Sequence[str], None] = None,
                 solver: str = "auto", tol: float = 1e-10, maxiter: int = 2000,
                 system: Optional[StokesSystem] = None,
                 prescribed: Optional[tuple] = None,
                 pressure_mean: Optional[bool] = None,
                 constraints: Optional[sp.spmatrix] = None,
                 cache: Optional[StokesCache] = None) -> StokesSolution:
    """Solve the Stokes problem (see the module docstring).

    Parameters
    ----------
    spaces
        From :func:`stokes_spaces`.
    eta, f, tau0
        Viscosity, body force and known stress (see :func:`assemble_stokes`).
    free_slip, no_slip
        Walls (see :func:`wall_dofs`); default free slip everywhere.
    solver
        ``"auto"`` (default: ``"fgmres"`` for a large single solve at a contrast above
        1e3, else ``"schur"``; ``info["solver"]``), ``"schur"`` (LU), ``"fgmres"``
        (AMG, linear memory), ``"schur-amg"``, ``"direct"``, ``"minres"`` or ``"petsc"``
        (MPI): see :mod:`skfem_nem.models.stokes_solvers`.
    tol, maxiter
        Relative tolerance and iteration limit of the iterative parts.
    system
        A :class:`StokesSystem` assembled before (then eta, f, tau0 are not
        read).
    prescribed
        ``(dofs, values)``: velocity dofs with given (non-zero) values, e.g.
        moving walls; they override the wall conditions on the same dofs.
    pressure_mean
        Fix the pressure by its mean (zero). Default: when every boundary
        node has a constrained velocity component (no open boundary, so the
        pressure is otherwise determined only up to a constant).
    constraints
        Optional (k, nu) sparse matrix C of extra linear constraints
        ``C u = 0`` on the velocity dofs, or a pair ``(C, c)`` for ``C u = c``,
        imposed by Lagrange multipliers (returned in ``info["multipliers"]``);
        e.g. the net flux through a material outline (:func:`outline_flux`).
    cache
        A :class:`StokesCache` shared by solves with ``"auto"``, ``"schur"`` (start
        vector, factors) or ``"fgmres"`` (and AMG hierarchy); ``ValueError`` with others.

    Returns
    -------
    StokesSolution
        Velocity dof vector (ordered as ``spaces.ubasis``), pressure dof
        vector (mean zero if fixed so), iteration count and relative
        residual; ``info["reaction"]`` (nu,) the forces the constrained dofs
        exert on the fluid (zero elsewhere), ``info["fixed"]`` those dofs,
        ``info["bubble"]`` the condensed bubble dofs (``spaces.bubbles``), and
        ``info["assembled_triangles"]`` the triangles this process assembled
        (all of them; with ``solver="petsc"`` on several MPI ranks its part; 0 for a
        given ``system``); ``info["assembly_seconds"]``, ``info["solver_seconds"]``.

    Raises
    ------
    RuntimeError
        If an iterative solver does not reach ``tol`` in ``maxiter``
        iterations (naming both), or the system is singular.
    """
    check_solver(solver, cache)
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive number, got {tol}")
    t0 = time.perf_counter()
    sys_, share, assembled = _system(spaces, solver, system, eta, f, tau0)
    D, uD = fixed_velocity(spaces, free_slip, no_slip, prescribed)
    if pressure_mean is None:
        pressure_mean = walls_fix_pressure(spaces, D)
    red, sys_ = _reduce(spaces, sys_, D, uD, pressure_mean, constraints, share, system is None)
    t1 = time.perf_counter()
    info = {"fixed_velocity_dofs": int(D.size), "fixed": D, "pressure_mean": pressure_mean,
            "assembled_triangles": assembled, "assembly_seconds": t1 - t0}
    x = SOLVERS[solver](red.problem, tol, maxiter, info,
                        **({} if cache is None else {"cache": cache}))
    info["solver_seconds"] = time.perf_counter() - t1
    return _stokes_solution(spaces, sys_, red, x, solver, info)


def _system(spaces: StokesSpaces, solver: str, system: Optional[StokesSystem], eta, f, tau0):
    """The system to solve (``system``, or assembled: whole, or this rank's share), the
    :class:`Share` of a distributed assembly (or None) and the triangles assembled."""
    if system is not None:
        return system, None, 0
    part, share = distributed(spaces, solver)
    n = spaces.mesh.nelements if part.elements is None else int(part.elements.size)
    # (the solvers that factorise or hand the block on take it as CSR: "auto" converts
    # where it chooses one of them)
    blocks = solver in ("auto", "fgmres") and takes_viscous_blocks(spaces)
    return assemble_stokes(part, eta, f, tau0, viscous_blocks=blocks), share, n


@dataclass
class _Reduced:
    """The Stokes system with its fixed velocity dofs taken out."""

    problem: SaddlePointProblem     # on the free dofs, constraint rows appended
    A_fixed: sp.csr_matrix          # (fixed, nu) the viscous block's fixed rows
    B: sp.csr_matrix                # (np + k, nu) whole divergence and constraint rows
    fixed: np.ndarray               # fixed velocity dofs
    u0: np.ndarray                  # (nu,) their values (zero elsewhere)
    n_pressure: int                 # pressure dofs (without the k multipliers)
    share: Optional[Share] = None  # distributed assembly: the blocks are a share


def _with_constraints(sys_: StokesSystem, A: sp.csr_matrix, constraints, nu: int,
                      share: Optional[Share] = None):
    """``B``, ``g``, ``m``, ``S`` and the pressure preconditioner diagonal, with
    the rows of the extra constraints ``C u = c`` appended as multipliers (by rank
    0 alone in a distributed assembly: the others append zero rows)."""
    B = sys_.B.tocsr()
    g = np.zeros(sys_.B.shape[0]) if sys_.g is None else sys_.g
    m, S = sys_.m, sys_.S
    dp = np.asarray(sys_.Mp.sum(axis=1)).ravel()  # lumped 1/eta-weighted mass
    if constraints is None:
        return B, g, m, S, dp
    C, c = constraint_rows(constraints, nu)
    k = C.shape[0]
    # Jacobi estimate of C A^-1 C^T for the multipliers' preconditioner
    diag = A.diagonal() if share is None else share.total(A.diagonal())
    dcc = np.asarray(C.multiply(C) @ (1.0 / diag)).ravel()
    if share is not None and not share.root:
        C, c, dcc = sp.csr_matrix(C.shape), 0 * c, 0 * dcc
    return (sp.vstack([B, C]).tocsr(), np.concatenate([g, c]),
            np.concatenate([m, np.zeros(k)]), sp.block_diag([S, sp.csr_matrix((k, k))]).tocsr(),
            np.concatenate([dp, dcc]))


def _reduce(spaces: StokesSpaces, sys_: StokesSystem, D: np.ndarray, uD: np.ndarray,
            pressure_mean: bool, constraints, share: Optional[Share] = None,
            own: bool = False):
    """The saddle-point problem on the free velocity dofs (fixed values moved
    to the right side), and ``sys_`` without its blocks: the solve reads the blocks on
    the free dofs, the reactions the fixed rows, and the caller lets the whole blocks go
    (a 3D viscous block holds some 460 entries a row; the solution needs only the load and
    the bubbles' condensation). ``own``: ``sys_`` was assembled
    for this solve alone, and its block is reduced over its own arrays
    (:func:`~skfem_nem.models.stokes_walls.free_columns` with ``overwrite``)."""
    nu = spaces.n_velocity
    fixed_dof = np.zeros(nu, dtype=bool)
    fixed_dof[D] = True
    free = np.flatnonzero(~fixed_dof)
    blocks = isinstance(sys_.A, BlockSymmetricRows)
    Afull = sys_.A if blocks else sys_.A.tocsr()
    Bfull, g0, mvec, Sb, dp = _with_constraints(sys_, Afull, constraints, nu, share)
    mass = sys_.Mp.diagonal().sum()
    if share is not None:  # the pressure integrals whole, summed once for every use
        mvec, mass = share.total(mvec), share.total(np.array([mass]))[0]
    area = mvec.sum()
    # the mean pressure is fixed by a rank-one term c m m^T of the size of 1/eta
    c = float(mass) / area ** 2 if pressure_mean else 0.0
    fixed = np.zeros(nu)
    fixed[D] = uD[D]
    f = (sys_.f - Afull @ fixed)[free] if fixed.any() else sys_.f[free]
    A_fixed = Afull.tocsr(rows=D) if blocks else Afull[D]   # (before an own block changes)
    problem = SaddlePointProblem(
        A=Afull.restricted(free) if blocks else
        free_columns(Afull, free, rows=True, overwrite=own and Afull is sys_.A),
        B=free_columns(Bfull, free), S=Sb, f=f, g=g0 - Bfull @ fixed, m=mvec,
        dp=dp, mean_weight=c, pressure_mean=pressure_mean, ubasis=spaces.ubasis, free=free,
        total=None if share is None else share.total, owned=own)
    return (_Reduced(problem, A_fixed, Bfull, D, uD, spaces.n_pressure, share),
            replace(sys_, A=None, B=None, S=None, Mp=None))


def _stokes_solution(spaces: StokesSpaces, sys_: StokesSystem, red: _Reduced,
                     x: SaddlePointSolution, solver: str, info: dict) -> StokesSolution:
    """Whole velocity, reactions of the fixed dofs, multipliers and condensed
    bubbles from the solution of the reduced problem."""
    u = red.u0.copy()
    u[red.problem.free] = x.u
    p = x.p
    whole = red.problem.whole
    reaction = np.zeros(spaces.n_velocity)
    fixed = red.fixed
    reaction[fixed] = (red.A_fixed @ u + (red.B.T @ p)[fixed]) - sys_.f[fixed]
    reaction = whole(reaction)
    info["reaction"] = reaction
    info["multipliers"] = p[red.n_pressure:]
    p = p[:red.n_pressure]
    if sys_.bubble is not None:
        Ainv, AiAbn, Bb, fb = sys_.bubble
        info["bubble"] = whole(Ainv @ (fb - Bb.T @ p) - AiAbn @ u)
    return StokesSolution(spaces, u, p, solver, x.iterations, x.residual, info)


def inf_sup_constant(spaces: StokesSpaces, stabilised: Optional[bool] = None,
                     eta: Field = 1.0) -> float:
    """Numerical inf-sup constant (Chapelle and Bathe 1993) with no-slip walls.

    The smallest nonzero eigenvalue ``mu_min`` of
    ``(B A^-1 B^T + S) q = mu M q`` (A: the H1 velocity norm ``(grad u,
    grad v) + (u, v)``, M: the pressure mass matrix, S: the stabilisation
    if ``stabilised``), over pressures of mean zero; returns
    ``sqrt(mu_min)``. For a stable pair it stays bounded away from zero as
    the mesh is refined. Dense eigen-solve: for meshes up to a few thousand
    nodes.
    """
    import scipy.linalg as sla
    stab = spaces.stabilised if stabilised is None else stabilised
    ub, pb = spaces.ubasis, spaces.pbasis

    @BilinearForm
    def h1(u, v, w):
        return ddot(grad(u), grad(v)) + dot(u, v)

    @BilinearForm
    def mass(p, q, w):
        return p * q

    D = wall_dofs(spaces, free_slip=None, no_slip="all")
    free = np.setdiff1d(np.arange(ub.N), D)
    A = h1.assemble(ub)[free][:, free]
    bform = divergence_form(spaces)
    B = bform.assemble(ub, pb)[:, free]
    if spaces.bubbles is not None:  # bubbles vanish on the walls: all free
        bb = spaces.bubbles.vector_basis()
        Hbn = h1.assemble(ub, bb)[:, free]
        A = sp.bmat([[A, Hbn.T], [Hbn, h1.assemble(bb)]])
        B = sp.hstack([B, bform.assemble(bb, pb)])
    A = sp.csc_matrix(A)
    B = sp.csr_matrix(B)
    M = mass.assemble(pb).toarray()
    lu = spla.splu(A)
    X = lu.solve(B.T.toarray())
    G = B @ X
    if stab:
        e = quadrature_values(spaces, eta, "viscosity eta", positive=True)
        G = G + _stabilisation(spaces, 1.0 / e).toarray()
    G = 0.5 * (G + G.T)
    # restrict to mean-zero pressures: basis of the M-orthogonal complement of 1
    m = M @ np.ones(M.shape[0])
    Q, _ = np.linalg.qr(np.c_[m, np.eye(M.shape[0])[:, :-1]])
    Z = Q[:, 1:]
    mu = sla.eigh(Z.T @ G @ Z, Z.T @ M @ Z, eigvals_only=True, subset_by_index=[0, 0])
    return float(np.sqrt(max(mu[0], 0.0)))
