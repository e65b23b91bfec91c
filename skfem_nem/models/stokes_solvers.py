"""Solvers of the discrete Stokes saddle-point problem, one function per solver.

Kept apart from :mod:`skfem_nem.models.stokes` (spaces, forms, assembly and
wall conditions) because the solvers are linear algebra alone: they see the
assembled blocks restricted to the free velocity dofs
(:class:`~skfem_nem.models.saddle_problem.SaddlePointProblem`, a module of its own
with the product the solvers share) and know nothing of meshes, forms or walls.
The imports therefore go one way, ``stokes`` -> ``stokes_solvers``; this
module never imports ``stokes``, and a new solver is one function here plus
one entry of :data:`SOLVERS`. :func:`skfem_nem.models.stokes.solve_stokes`
is the dispatcher that builds the problem and calls the chosen solver.

The problem, with ``m`` the integrals of the pressure basis functions::

    [A   B^T] [u]   [f]
    [B   -S ] [p] = [g],     m . p = 0 if the mean pressure is fixed.

Solvers
-------
``"schur"`` factorises the viscous block (sparse LU in a symmetric
ordering, in single precision after a diagonal scaling; per velocity component,
in two threads, for large problems at moderate contrasts:
:mod:`skfem_nem.models.stokes_factors`) and runs flexible
GMRES on the whole system preconditioned by the block upper-triangular
``[[A, B^T], [0, -S_hat]]^-1`` with those factors for ``A`` and the lumped
1/eta-weighted pressure mass for ``S_hat``: with exact factors, the
iterations of conjugate gradients on the pressure Schur complement.
``"schur-amg"`` is conjugate gradients on the Schur complement with the
viscous block solved by AMG-preconditioned CG instead of a factorisation
(memory linear in the problem size). ``"direct"`` factorises the whole saddle-point system
(slower: natural-neighbour stencils are wide). ``"minres"`` uses MINRES with
a block-diagonal preconditioner: one smoothed-aggregation AMG V-cycle
(pyamg, rigid-body modes as near null space) for the viscous block and the
diagonal of the viscosity-scaled pressure mass matrix for the pressure.
``"fgmres"`` is flexible GMRES on the whole system with a block
upper-triangular preconditioner: AMG V-cycles for the viscous block, the
lumped 1/eta-weighted pressure mass for the Schur complement; no
factorisation, so its memory and the cost of an iteration grow linearly with
the unknowns (the iterations grow with the contrast like those of
``"schur"``; a single solve at a contrast above 1e3 is faster than ``"schur"``'s from
about 50,000 nodes, the sinking plate's steps are not; see ``docs/stokes.md``), and a
:class:`StokesCache` keeps its AMG hierarchy and last solution between solves
(Picard iterations, time steps). ``"auto"``, the default, is ``"fgmres"`` for a
single solve from :data:`AUTO_FGMRES_UNKNOWNS` natural-neighbour velocity unknowns on
at a viscosity contrast above :data:`SINGLE_CONTRAST`, and ``"schur"`` otherwise
(:func:`auto_solver`). The iterative solvers fix the mean
pressure by a rank-one term ``c m m^T`` of the size of 1/eta. ``"petsc"`` is
``"fgmres"``'s method on PETSc over MPI (optional petsc4py; the mean pressure as
PETSc's null space instead of the rank-one term; :mod:`skfem_nem.parallel`, imported
only when it is chosen).
"""
from __future__ import annotations

from typing import Callable, Dict, Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..basis import NaturalNeighbourBasis
from ..parallel.partition import Bisection
from .block_rows import BlockSymmetricRows
from .krylov import FGMRES_RESTART, MINRES_TOL_FACTOR, dot, fgmres, norm, restarted_minres
from .saddle_problem import SaddlePointProblem, SaddlePointSolution, saddle_matvec
from .stokes_amg import ViscousAMG, rigid_modes, velocity_components, viscous_amg
from .stokes_cache import REBUILD_GROWTH, REBUILD_SLACK, StokesCache
from .stokes_factors import ComponentFactors, ViscousFactor
from .stokes_two_level import ViscousTwoLevel

__all__ = ["SaddlePointProblem", "SaddlePointSolution", "SolverNotConverged", "SOLVERS",
           "CACHED_SOLVERS",
           "StokesCache", "auto_solver", "check_solver", "solve_auto", "solve_direct",
           "solve_schur", "solve_schur_amg", "solve_minres", "solve_fgmres", "solve_petsc",
           "part_order", "rigid_modes", "saddle_matvec"]

class SolverNotConverged(RuntimeError):
    """A Stokes solve stopped at its iteration limit above its tolerance. A time loop may
    retry with a shorter step (a smaller visco-elastic viscosity contrast): a 2D plate run
    (3,000 nodes, a weak lower layer under a thin plate broken in three) stopped at t = 860
    where the pressure CG stalled at a residual of 1.7e-6 against 1e-6."""


# relative tolerance of the inner AMG-CG solves of the viscous block
# ("schur-amg"): at most this, and two orders of magnitude below the outer tol
INNER_RTOL = 1e-3
# iteration limit of each inner AMG-CG solve of the viscous block
INNER_MAXITER = 1000
# conjugate-gradient steps (each preconditioned by one AMG V-cycle) per application
# of the viscous-block preconditioner. Two were the fastest of 1-4 steps and of 1-2
# stationary cycles at 4,000 and 16,000 nodes (SolCx, contrasts 1 and 1e6; the
# hierarchy on the unscaled block). With the scaled one (stokes_amg): 202, 156 and 129
# outer iterations for 1, 2 and 3 steps at 10,338 nodes (3.7, 3.9 and 4.7 s), 266 and
# 158 for 1 and 2 at 101,054 nodes, 144 for 3 (54 s against 43 s for 2)
VISCOUS_CG_STEPS = 2
# the same for the two-level method of the quadratic natural-neighbour velocity
# (models.stokes_two_level), whose application costs some seven products with a block of
# 211 entries a row: SolCx at a contrast of 1e6, 33,242 unknowns: 77 FGMRES iterations and
# 20 s with one step, 57 and 27 s with two
TWO_LEVEL_CG_STEPS = 1
# with the two-level method, a restart cycle of FGMRES that leaves the true residual above
# this fraction of the last one's has met the rounding of the residual itself: SolCx at a
# contrast of 1e6 and 145,820 unknowns went on for 685 iterations at a relative residual of
# 7.7e-10 against a tol of 1e-10 (at 33,242 unknowns it reached 1e-10 in 75)
TWO_LEVEL_STALL = 0.5
# "schur" keeps the viscous factorisation in its StokesCache for the next solves of the
# same pattern (False: factorise every solve, as before; benchmarks/scaling.py measures
# both). Kept, the later Picard iterations of a step take 16-32 FGMRES iterations with the
# old factors against 38-44 CG iterations after a new factorisation (sinking plate,
# 1,600-21,000 nodes): the linear solver's time of a step drops by 20-28% (docs/stokes.md)
REUSE_FACTOR = True
# precision in which "schur" first factorises the (diagonally scaled) viscous block: the
# factors precondition FGMRES on the whole system, so they need not be exact. At
# 178,497 velocity unknowns (sinking plate, 100,000 drawn nodes) single precision
# factorises in 4.6 s against 7.4 s, solves in 94 ms against 136 ms and keeps half the
# memory, for 23 FGMRES iterations against 22 with double-precision factors (SolCx at a
# contrast of 1e6, 16,430 nodes: 124 against 107 Schur-complement CG iterations, in the
# same time). A solve that has not converged after PRECISION_ITERATIONS, or stalls,
# goes on from where it stands with double-precision factors and conjugate gradients on
# the pressure Schur complement, the solve of "schur" before (docs/stokes.md)
FACTOR_DTYPE = np.float32
# the viscosity contrast up to which "schur" factorises in FACTOR_DTYPE; above it, in double
# precision from the start (factor_dtype). SolCx at a contrast of 1e6 with single-precision
# factors: 96, 123 and 260 iterations at 1,107, 10,338 and 101,054 nodes (the last fell
# back to double precision after 150, 112 s); with double-precision factors 66, 81 and 86
# (54.5 s). The sinking plate's contrasts are about 10 (docs/stokes.md)
SINGLE_CONTRAST = 1e3
# FGMRES iterations with the single-precision factors (one restart cycle)
PRECISION_ITERATIONS = FGMRES_RESTART
# a restart cycle of FGMRES preconditioned by factors that does not reduce the true
# residual below this fraction of the last one's has met the rounding of the residual
# itself (Taylor-Hood, a block 1e4 times stiffer: 1.1e-10 to 1.3e-10 for 500
# iterations): the solve stops there
FACTOR_STALL = 0.5
# from this many velocity unknowns on, "schur" preconditions FGMRES with the factors of
# the two velocity components' diagonal blocks, made and applied in two threads
# (stokes_factors.ComponentFactors), instead of the whole block's. SolCx with segments
# at 60,814 nodes: factorised in 0.87 s against 3.58 s, 42 against 24 iterations, 3.4 s
# against 6.5 s a solve (contrast 10). The sinking plate's linear solver at 88,528 nodes:
# 6.1-6.4 s a step against 8.0-8.7 s; at 5,577 and 21,367 nodes the same time as the
# whole block's (more iterations for a cheaper factorisation), so smaller problems keep
# the whole block. Above SINGLE_CONTRAST the whole block too (viscous_factor), and the
# double-precision fallback (Schur-complement CG, which needs exact solves) factorises
# the whole block (docs/stokes.md)
SPLIT_MIN_UNKNOWNS = 20_000
# "auto" solves a single system (no StokesCache) of at least this many velocity unknowns
# and a viscosity contrast above SINGLE_CONTRAST with "fgmres", everything else with
# "schur" (auto_solver). SolCx with the interface as segments, one solve to 1e-10,
# seconds of "schur" / "fgmres" at a contrast of 1e6 (whole-block double-precision
# factors): 61,000 velocity unknowns 3.9 / 3.8, 121,000: 17.9 / 8.1, 202,000: 25.8 /
# 14.0. At contrasts up to SINGLE_CONTRAST "schur" factorises per velocity component
# from SPLIT_MIN_UNKNOWNS on and wins: 121,000 unknowns 3.8 / 7.5 (contrast 1) and
# 7.3 / 9.5 (1e2), 202,000: 9.3 / 12.8 and 12.2 / 18.6. With a cache "schur" keeps its
# factorisation over the Picard iterations: the sinking plate at 88,528 nodes spends
# 6.1-6.4 s a step in its solves against 11.0 s with "fgmres". Natural-neighbour velocity
# only: Taylor-Hood's sparser P2 block factorises cheaply, and "fgmres" there took twice
# the time of "schur" at 81,000 velocity unknowns and did not converge in 3,000
# iterations at 242,000 and a contrast of 1e6 (docs/stokes.md)
AUTO_FGMRES_UNKNOWNS = 100_000
# In 3D the natural-neighbour viscous block has about 440 entries a row (three components
# of some 147 neighbours, smoothed Box 1 basis) and its factors fill in fast: at 8,379
# velocity unknowns (unit cube, viscosity ratio 20) "schur" solved in 9.4 s and
# "fgmres" in 5.3 s (31 iterations), so above this size "auto" takes "fgmres" in 3D at
# any contrast, with or without a cache
AUTO_FGMRES_UNKNOWNS_3D = 6_000
# The quadratic natural-neighbour viscous block (211 entries a row) factorises slowly, and
# "fgmres" with the two-level method (models.stokes_two_level) needs no factors: SolCx at a
# contrast of 1e6 (interface as segments), one solve to 1e-8, seconds and peak MB of
# "schur" / "fgmres" on quiet cores: 2,754 unknowns 0.22 / 0.24 s and 27 / 27 MB, 8,594:
# 1.15 / 0.73 s and 145 / 105 MB, 16,830: 3.49 / 1.50 s and 392 / 240 MB
# (benchmarks/quadratic_stokes.py). But asked for 1e-10, "fgmres" stalled at 1.04e-10 at
# a contrast of 1e6 (benchmarks/constrained_interfaces.py's SolCx, below 20,000 unknowns),
# where "schur" reaches it. So "auto" takes "fgmres" for it from this many velocity
# unknowns on, where factorising is out of reach
AUTO_FGMRES_UNKNOWNS_NEM2 = 20_000


def solve_direct(problem: SaddlePointProblem, tol: float, maxiter: int,
                 info: dict) -> SaddlePointSolution:
    """Sparse LU of the whole saddle-point system (``tol``, ``maxiter``
    unused); the mean pressure by a Lagrange multiplier."""
    A, B, S, m = problem.A, problem.B, problem.S, problem.m
    if problem.pressure_mean:
        K = sp.bmat([[A, B.T, None],
                     [B, -S, sp.csr_matrix(m[:, None])],
                     [None, sp.csr_matrix(m[None, :]), None]], format="csc")
        rhs = np.concatenate([problem.f, problem.g, [0.0]])
    else:
        K = sp.bmat([[A, B.T], [B, -S]], format="csc")
        rhs = problem.rhs
    x = spla.spsolve(K, rhs)
    if not np.isfinite(x).all():
        raise RuntimeError("the Stokes system is singular: check the wall conditions "
                           "(a rigid-body motion left free?) and the viscosity")
    n1 = problem.n_velocity
    p = x[n1:n1 + problem.n_pressure]
    return SaddlePointSolution(x[:n1], p, 1, problem.residual(x[:n1], p))


def solve_schur(problem: SaddlePointProblem, tol: float, maxiter: int,
                info: dict, cache: Optional[StokesCache] = None) -> SaddlePointSolution:
    """Sparse LU of the viscous block in single precision (:class:`ViscousFactor`,
    :data:`FACTOR_DTYPE`; in double precision above a viscosity contrast of
    :data:`SINGLE_CONTRAST`, :func:`factor_dtype`), :func:`fgmres` on the whole system
    preconditioned by it (:func:`_factor_fgmres`): with exact factors, the iterations of conjugate
    gradients on the pressure Schur complement (hence the name). If that has not met
    ``tol`` after :data:`PRECISION_ITERATIONS` or stalls (:data:`FACTOR_STALL`), the
    viscous block is factorised in double precision and :func:`schur_pressure_cg`
    goes on from the pressure reached; ``info["factor_precision"]``,
    ``info["viscosity_contrast"]``, ``info["factors"]`` (``"components"`` or ``"whole"``:
    :func:`viscous_factor`).

    With a ``cache`` (a :class:`StokesCache`), the solve starts from the last solution
    where the sizes agree and it is a better start than zero (the Picard iterations
    of a time step), ``info["warm_start"]``. The cache also keeps the factorisation:
    a later solve whose viscous block has the same pattern (the next Picard
    iterations, with new viscosities) does not factorise again but is preconditioned
    by the kept factors (:func:`_reuse_factor`), and factorises only if that takes
    more than ``REBUILD_GROWTH`` times the iterations of the solve that factorised;
    ``info["factor_reused"]``."""
    if cache is not None and REUSE_FACTOR:
        lu = cache.kept_factor(problem.A)
        sol = None if lu is None else _reuse_factor(problem, lu, tol, maxiter, info, cache)
        if sol is not None:
            return sol
        cache.factor = None                # (freed before the next one is made)
    info["factor_reused"] = False
    matvec = saddle_matvec(problem)
    x0 = None if cache is None else _warm_start(cache, matvec, problem.rhs)
    info["warm_start"] = x0 is not None
    lu = viscous_factor(problem, info)
    x, its, res = _factor_fgmres(problem, lu, matvec, x0, tol,
                                 min(maxiter, PRECISION_ITERATIONS))
    if res <= tol:
        sol = _split(problem, x, its)
    elif its >= maxiter:
        raise SolverNotConverged(f"FGMRES with the factorised viscous block did not converge: "
                           f"{its} iterations, relative residual {res:.3e} > tol {tol:.1e} "
                           f"(raise maxiter)")
    else:                              # on in double precision from where it stands
        del lu                         # (freed before the next one is made)
        lu = ViscousFactor(problem.A, np.float64)
        info["factors"] = "whole"
        n1 = problem.n_velocity
        sol = schur_pressure_cg(problem, lu, tol, max(1, maxiter - its), x[n1:],
                                counted=its)
        x = np.concatenate([sol.u, sol.p])
    info["factor_precision"] = lu.dtype.name
    if cache is not None:
        cache.record(x, sol.iterations, False)
        if REUSE_FACTOR:
            cache.keep_factor(lu, problem.A, sol.iterations)
    return sol


def viscous_factor(problem: SaddlePointProblem, info: dict):
    """The factors preconditioning the first FGMRES of ``"schur"``, in the precision of
    :func:`factor_dtype`: per velocity component from :data:`SPLIT_MIN_UNKNOWNS`
    velocity unknowns on up to a viscosity contrast of :data:`SINGLE_CONTRAST`, else of
    the whole viscous block (at higher contrasts the split needs more than twice the
    iterations: 172 against 65 at 1e6 on 500 nodes). Records ``info["factors"]``."""
    dtype = factor_dtype(problem, info)
    split = (problem.n_velocity >= SPLIT_MIN_UNKNOWNS
             and info["viscosity_contrast"] <= SINGLE_CONTRAST)
    info["factors"] = "components" if split else "whole"
    if split:
        comp = velocity_components(problem.ubasis)[problem.free]
        return ComponentFactors(problem.A, comp, dtype)
    return ViscousFactor(problem.A, dtype)


def viscosity_contrast(problem: SaddlePointProblem) -> float:
    """The largest over the smallest mean inverse viscosity of the pressure nodes' supports
    (the lumped 1/eta-weighted pressure mass over the plain one): the viscosity contrast
    the discretisation sees."""
    on = problem.m > 0                      # pressure nodes (not constraint multipliers)
    inv = problem.dp[on] / problem.m[on]
    return float(inv.max() / inv.min()) if inv.size else 1.0


def factor_dtype(problem: SaddlePointProblem, info: Optional[dict] = None):
    """:data:`FACTOR_DTYPE` up to a viscosity contrast of :data:`SINGLE_CONTRAST`, double
    precision above it; the contrast goes to ``info["viscosity_contrast"]``."""
    contrast = viscosity_contrast(problem)
    if info is not None:
        info["viscosity_contrast"] = contrast
    return FACTOR_DTYPE if contrast <= SINGLE_CONTRAST else np.float64


def _factor_fgmres(problem: SaddlePointProblem, lu, matvec: Callable,
                   x0: Optional[np.ndarray], tol: float, maxiter: int, schur: bool = True):
    """:func:`fgmres` on the whole system from ``x0`` with the block upper-triangular
    preconditioner, ``lu`` for the viscous block: solution, iterations, residual.

    ``schur``: the residual is relative to the right side of the pressure Schur
    complement, ``B A^-1 f - g`` (the continuity residual of the preconditioned right
    side), as that of the conjugate gradients of :func:`schur_pressure_cg`, not to
    ``[f, g]``. Where a large load is nearly balanced (a prestress, a hydrostatic
    pressure) ``|f|`` says nothing of the velocity's size: a first solve to ``tol``
    against it left errors of 6e-4 in the velocity (an elastic box turned by its
    walls). The solves with kept factors start from such a solution and are
    measured against ``[f, g]`` (``schur`` False), as before the single-precision
    factors: against the Schur complement's right side they took up to twice the
    iterations (6,000-node plate)."""
    precondition = _triangular_preconditioner(problem, lu.solve)
    rhs, n1 = problem.rhs, problem.n_velocity
    scale = (norm((rhs - matvec(precondition(rhs)))[n1:]) or None) if schur else None
    return fgmres(matvec, precondition, rhs, x0, tol, maxiter,
                  restart=max(1, min(FGMRES_RESTART, maxiter)), stall=FACTOR_STALL,
                  scale=scale)


def _reuse_factor(problem: SaddlePointProblem, lu, tol: float, maxiter: int,
                  info: dict, cache: StokesCache) -> Optional[SaddlePointSolution]:
    """The solve of :func:`solve_schur` with a kept factorisation ``lu`` of an earlier
    viscous block of the same pattern, from the cached start: exact where the
    viscosity has not changed; where it has, the Krylov space makes up the difference
    in a few more iterations. None if it does not converge within ``REBUILD_GROWTH``
    times the iterations of the solve that factorised, plus ``REBUILD_SLACK`` (the
    caller factorises again)."""
    limit = min(maxiter, int(REBUILD_GROWTH * cache.factor_iterations + REBUILD_SLACK))
    matvec = saddle_matvec(problem)
    x0 = _warm_start(cache, matvec, problem.rhs)
    x, its, res = _factor_fgmres(problem, lu, matvec, x0, tol, limit, schur=False)
    if not res <= tol:
        return None
    info.update(factor_reused=True, warm_start=x0 is not None,
                factor_precision=lu.dtype.name)
    cache.record(x, its, False)
    cache.factor_reuses += 1
    return _split(problem, x, its)


def _warm_start(cache: StokesCache, matvec: Callable, rhs: np.ndarray) -> Optional[np.ndarray]:
    """The cached solution as the start of a solve of the whole system, if it is a
    better start than zero (else None)."""
    x0 = cache.start(rhs.size)
    return x0 if x0 is not None and norm(rhs - matvec(x0)) < norm(rhs) else None


def _split(problem: SaddlePointProblem, x: np.ndarray, its: int,
           viscous: Optional[Callable] = None) -> SaddlePointSolution:
    """The solution of the whole system ``x`` as velocity and (mean-free) pressure
    (``viscous``: as in :meth:`SaddlePointProblem.residual`)."""
    n1 = problem.n_velocity
    p = problem.mean_free(x[n1:])
    return SaddlePointSolution(x[:n1], p, its, problem.residual(x[:n1], p, viscous))


def _triangular_preconditioner(problem: SaddlePointProblem, solve_A: Callable) -> Callable:
    """The block upper-triangular preconditioner ``[[A, B^T], [0, -S_hat]]^-1`` of the
    whole system, ``solve_A`` applying (an approximation of) ``A^-1`` and ``S_hat`` the
    lumped 1/eta-weighted pressure mass ``dp``."""
    n1, dp, B = problem.n_velocity, problem.dp, problem.B

    def precondition(r):
        zp = -r[n1:] / dp
        return np.concatenate([solve_A(r[:n1] - B.T @ zp), zp])

    return precondition


class AMGViscousSolve:
    """Solves with the viscous block by CG preconditioned with an AMG V-cycle
    (no factorisation); counts the inner iterations in ``inner["its"]``."""

    def __init__(self, A: sp.spmatrix, preconditioner, rtol: float, inner: dict):
        self.A, self.M, self.rtol, self.inner = A, preconditioner, rtol, inner

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` to the relative tolerance ``rtol``."""
        its = [0]
        y, fl = spla.cg(self.A, rhs, M=self.M, rtol=self.rtol, maxiter=INNER_MAXITER,
                        callback=lambda *_: its.__setitem__(0, its[0] + 1))
        self.inner["its"] += its[0]
        if fl != 0:
            raise RuntimeError(f"inner AMG-CG solve of the viscous block did not "
                               f"converge in {INNER_MAXITER} iterations")
        return y


def solve_schur_amg(problem: SaddlePointProblem, tol: float, maxiter: int,
                    info: dict) -> SaddlePointSolution:
    """The Schur-complement iteration with the viscous block solved by
    AMG-preconditioned CG, to a tolerance well below the outer one; the inner
    iteration count goes to ``info["inner_iterations"]``."""
    ml = viscous_amg(problem)
    inner = {"its": 0}
    lu = AMGViscousSolve(problem.A, ml.preconditioner(),
                         min(INNER_RTOL, tol * 1e-2), inner)
    info["inner_iterations"] = inner
    return schur_pressure_cg(problem, lu, tol, maxiter)


def schur_pressure_cg(problem: SaddlePointProblem, lu, tol: float, maxiter: int,
                      p0: Optional[np.ndarray] = None, info: Optional[dict] = None,
                      counted: int = 0) -> SaddlePointSolution:
    """Pressure CG on ``B A^-1 B^T + S + c m m^T`` with ``lu.solve`` applying
    ``A^-1``; preconditioner: ``1 / dp``. ``p0``: a start, taken if its residual is
    below the right side's (recorded in ``info["warm_start"]``). ``counted``: iterations
    done before (a solve this one goes on from), added to the count."""
    B, S, m, c = problem.B, problem.S, problem.m, problem.mean_weight
    npr, fu = problem.n_pressure, problem.f
    count = [counted]

    def schur(q):
        return B @ lu.solve(B.T @ q) + S @ q + c * m * (m @ q)

    Sop = spla.LinearOperator((npr, npr), matvec=schur, dtype=float)
    Pp = spla.LinearOperator((npr, npr), matvec=lambda q: q / problem.dp, dtype=float)
    g = B @ lu.solve(fu) - problem.g
    warm = p0 is not None and norm(g - schur(p0)) < norm(g)
    if info is not None:
        info["warm_start"] = warm
    p, flag = spla.cg(Sop, g, x0=p0 if warm else None, M=Pp, rtol=tol, maxiter=maxiter,
                      callback=lambda *_: count.__setitem__(0, count[0] + 1))
    if flag != 0:
        r = np.linalg.norm(schur(p) - g) / max(np.linalg.norm(g), 1e-300)
        raise SolverNotConverged(f"pressure CG did not converge: {count[0]} iterations, "
                           f"relative residual {r:.3e} > tol {tol:.1e} (raise maxiter)")
    xu = lu.solve(fu - B.T @ p)
    p = problem.mean_free(p)
    return SaddlePointSolution(xu, p, count[0], problem.residual(xu, p))


def solve_minres(problem: SaddlePointProblem, tol: float, maxiter: int,
                 info: dict) -> SaddlePointSolution:
    """MINRES with a block-diagonal preconditioner (AMG V-cycle on the viscous
    block, ``1 / dp`` on the pressure); records ``info["preconditioned_residual"]``,
    ``info["restarts"]`` and ``info["amg_levels"]``."""
    ml = viscous_amg(problem)
    n1 = problem.n_velocity
    matvec, K, M = minres_operators(problem, ml.preconditioner())
    x, res_m, restarts, its = restarted_minres(matvec, K, M, problem.rhs, tol,
                                               maxiter)
    res = problem.residual(x[:n1], x[n1:])
    info["preconditioned_residual"] = res_m
    info["restarts"] = restarts
    if not res_m <= MINRES_TOL_FACTOR * tol:
        raise SolverNotConverged(f"MINRES did not converge: {its} iterations, relative "
                           f"preconditioned residual {res_m:.3e} > "
                           f"{MINRES_TOL_FACTOR * tol:.1e} (raise maxiter, or use "
                           f"solver='schur' for strong viscosity contrasts)")
    p = problem.mean_free(x[n1:])
    info["amg_levels"] = ml.n_levels
    return SaddlePointSolution(x[:n1], p, its, res)


def minres_operators(problem: SaddlePointProblem, Pu):
    """The saddle-point product (as a function and an operator) and the
    block-diagonal preconditioner (``Pu`` on the velocity, ``1 / dp``)."""
    n1, npr, dp = problem.n_velocity, problem.n_pressure, problem.dp
    # numpy's dot: with the BLAS-free dot's rounding MINRES stalled at a relative
    # preconditioned residual of 1.1e-7 against the 1e-8 it stops at (tol 1e-9; SolCx at a
    # contrast of 1e6, the quadratic velocity, 3,000 iterations), a solver on the edge there
    # (docs/stokes.md)
    matvec = saddle_matvec(problem)
    K = spla.LinearOperator((n1 + npr, n1 + npr), matvec=matvec, dtype=float)
    M = spla.LinearOperator(K.shape, matvec=lambda x: np.concatenate([Pu @ x[:n1],
                                                                      x[n1:] / dp]),
                            dtype=float)
    return matvec, K, M


def solve_fgmres(problem: SaddlePointProblem, tol: float, maxiter: int, info: dict,
                 cache: Optional[StokesCache] = None) -> SaddlePointSolution:
    """Flexible GMRES on the whole system, preconditioned by the block upper
    triangle ``[[A, B^T], [0, -S_hat]]^-1``.

    ``A^-1`` is ``VISCOUS_CG_STEPS`` conjugate-gradient steps preconditioned by AMG V-cycles
    (rigid-body modes as near null space; for the quadratic natural-neighbour velocity
    ``TWO_LEVEL_CG_STEPS`` steps of the two-level method); ``S_hat`` is the lumped 1/eta-
    weighted pressure mass ``dp`` (on constraint multipliers the Jacobi estimate of ``C A^-1
    C^T``). With an exact ``A^-1`` the triangular form leaves the spectrum of the Schur
    complement against ``S_hat``, whose iterations ``"schur"`` shows to be flat in the mesh
    size; the consistent weighted mass in place of the lumped one did not lower them at
    contrasts of 1e4 and more. The CG steps are not a fixed linear map, hence the flexible
    variant. Stops on the true relative residual of the whole system. ``cache`` (a
    :class:`StokesCache`) supplies and keeps the hierarchy and the start vector. Records
    ``info["amg_levels"]``,
    ``info["amg_rebuilt"]`` and ``info["warm_start"]``.
    """
    cache = StokesCache() if cache is None else cache
    owned = problem.owned
    ml, rebuilt = cache.amg(problem, overwrite=owned)
    if owned:   # A holds the scaled block now: let it go (1.8 GB at 100,000 nodes in 3D),
        problem.A = None        # the solve reads the block through the hierarchy
    two_level = isinstance(ml, ViscousTwoLevel)
    matvec = saddle_matvec(problem, ml.matvec, inner=dot)
    steps = TWO_LEVEL_CG_STEPS if two_level else VISCOUS_CG_STEPS
    precondition = _triangular_preconditioner(problem, lambda r: ml.cg(r, steps))

    rhs = problem.rhs
    x0 = _warm_start(cache, matvec, rhs)
    x, its, res = fgmres(matvec, precondition, rhs, x0, tol, maxiter,
                         stall=TWO_LEVEL_STALL if two_level else None)
    info.update(amg_levels=ml.n_levels, amg_rebuilt=rebuilt, warm_start=x0 is not None)
    if not res <= tol:
        cache.last_iterations = its  # a failed solve asks for a new hierarchy next time
        why = "maxiter" if its >= maxiter else "stalled: the rounding of the residual"
        raise SolverNotConverged(f"FGMRES did not converge: {its} iterations ({why}), relative "
                           f"residual {res:.3e} > tol {tol:.1e} (raise maxiter, loosen tol, "
                           f"or use solver='schur', which factorises the viscous block)")
    cache.record(x, its, rebuilt)
    out = _split(problem, x, its, ml.matvec if owned else None)
    if isinstance(ml, ViscousAMG):  # (the next solve refreshes them: not kept meanwhile)
        ml.release_values()
    return out


def solve_petsc(problem: SaddlePointProblem, tol: float, maxiter: int,
                info: dict) -> SaddlePointSolution:
    """The preconditioned FGMRES of :func:`solve_fgmres` on PETSc over MPI
    (:func:`skfem_nem.parallel.solve_saddle_petsc`): the same block upper-triangular
    preconditioner, GAMG with the rigid-body modes on the viscous block, the lumped
    1/eta-weighted pressure mass for the Schur complement, the constant pressure as
    the null space when the mean is fixed. The problem is either the same on every
    rank or (``problem.total`` set) this rank's share of a distributed assembly; each
    rank owns the rows of a part of the domain (:func:`part_order`) and every rank
    gets the whole solution. Options: PETSc's,
    prefix ``-stokes_``. Records ``info["ranks"]``, ``info["ksp_reason"]`` and
    ``info["viscous_pc"]`` (the viscous block's preconditioner)."""
    from ..parallel import solve_saddle_petsc
    from ..parallel.petsc import world
    pressure = problem.m != 0                       # not the constraint multipliers

    def release():      # blocks assembled for this solve alone: PETSc holds them now
        if problem.owned:
            problem.A = problem.B = problem.S = None
    res = solve_saddle_petsc(
        problem.A, problem.B, -problem.S, problem.f, problem.g, -problem.dp, tol, maxiter,
        modes=rigid_modes(problem.ubasis, problem.free),
        pressure_null=pressure.astype(float) if problem.pressure_mean else None,
        order=part_order(problem, world()[1]), summed=problem.total is not None,
        release=release)
    info.update(ranks=res.ranks, ksp_reason=res.reason, viscous_pc=res.viscous_pc)
    p = problem.mean_free(res.p)
    n1 = res.u.size     # (the mean shift of p is in the null space: the residual stays)
    return SaddlePointSolution(res.u, p, res.krylov_iterations,
                               problem.relative(res.residual[:n1], res.residual[n1:]))


def part_order(problem: SaddlePointProblem, parts: int = 1) -> np.ndarray:
    """The unknowns (free velocity dofs, then pressures and multipliers) sorted by the
    part of the domain where they live (the recursive bisection of the mesh's nodes into
    ``parts``, :class:`~skfem_nem.parallel.partition.Bisection`, whose cells a rank
    assembles: :func:`~skfem_nem.parallel.petsc.owned_elements`), then by their first
    coordinate, multipliers last: split into consecutive blocks of equal count, each rank
    owns about its part's velocity and pressure unknowns. Pressure dofs are taken to be
    the mesh's nodes (P1); otherwise the pressures keep their place after the velocity.
    A cell's interior dofs without a location (scikit-fem's MINI bubbles, at NaN) are
    placed at its centroid, so the parts share them out and not all to the last rank."""
    ub = problem.ubasis
    nodes = np.asarray(ub.mesh.p)
    loc = np.array(np.asarray(ub.doflocs))                    # (dim, N)
    inner = np.asarray(ub.dofs.interior_dofs)
    if inner.size:
        centroid = nodes[:, ub.mesh.t].mean(axis=1)           # (dim, ne)
        unplaced = np.isnan(loc[0, inner])
        loc[:, inner[unplaced]] = np.broadcast_to(centroid[:, None], (nodes.shape[0],)
                                                  + inner.shape)[:, unplaced]
    m = problem.m
    npr = int(np.count_nonzero(m))
    xp = np.full((nodes.shape[0], problem.n_pressure), np.inf)
    if npr == nodes.shape[1] and np.all(m[:npr] != 0):
        xp[:, :npr] = nodes
    x = np.concatenate([loc[:, problem.free], xp], axis=1)
    part = Bisection(nodes, parts).part(x)
    return np.lexsort((x[0], part))


def auto_solver(problem: SaddlePointProblem, cached: bool) -> str:
    """The solver ``"auto"`` takes for ``problem``: ``"fgmres"`` for a single solve
    (``cached`` False) of at least :data:`AUTO_FGMRES_UNKNOWNS` natural-neighbour
    velocity unknowns at a viscosity contrast above :data:`SINGLE_CONTRAST`, where it is
    the faster and needs a fraction of the memory, else ``"schur"``: its factors per
    velocity component win at lower contrasts, its kept factorisation makes a sequence
    of solves with a :class:`StokesCache` (Picard iterations, time steps) the cheaper,
    (in 3D, natural-neighbour velocities take ``"fgmres"`` from
    :data:`AUTO_FGMRES_UNKNOWNS_3D` unknowns on, whatever the contrast and cache),
    and it is the robust one for Taylor-Hood's P2 (there ``"fgmres"`` did not converge at a
    contrast of 1e6). The quadratic natural-neighbour velocity takes ``"fgmres"`` (with the
    two-level method on its viscous block) from :data:`AUTO_FGMRES_UNKNOWNS_NEM2` unknowns
    on, whatever the contrast and cache."""
    if isinstance(problem.ubasis, NaturalNeighbourBasis) and problem.ubasis.order == 2:
        return "fgmres" if problem.n_velocity >= AUTO_FGMRES_UNKNOWNS_NEM2 else "schur"
    nem = isinstance(problem.ubasis, NaturalNeighbourBasis) and problem.ubasis.order == 1
    if nem and problem.ubasis.mesh.dim() == 3:
        return "fgmres" if problem.n_velocity >= AUTO_FGMRES_UNKNOWNS_3D else "schur"
    big = problem.n_velocity >= AUTO_FGMRES_UNKNOWNS
    if not big or not nem or cached:
        return "schur"
    return "fgmres" if viscosity_contrast(problem) > SINGLE_CONTRAST else "schur"


def solve_auto(problem: SaddlePointProblem, tol: float, maxiter: int, info: dict,
               cache: Optional[StokesCache] = None) -> SaddlePointSolution:
    """Solves with the solver :func:`auto_solver` chooses, named in ``info["solver"]``."""
    name = auto_solver(problem, cache is not None)
    info["solver"] = name
    if name != "fgmres" and isinstance(problem.A, BlockSymmetricRows):
        problem.A = problem.A.tocsr()       # (the others factorise it or hand it on)
    return SOLVERS[name](problem, tol, maxiter, info,
                         **({} if cache is None else {"cache": cache}))


SOLVERS: Dict[str, Callable[..., SaddlePointSolution]] = {
    "auto": solve_auto, "schur": solve_schur, "schur-amg": solve_schur_amg,
    "direct": solve_direct, "minres": solve_minres, "fgmres": solve_fgmres,
    "petsc": solve_petsc}
"""The solvers of :func:`skfem_nem.models.stokes.solve_stokes` by name, each
``(problem, tol, maxiter, info) -> SaddlePointSolution``."""

CACHED_SOLVERS = ("auto", "schur", "fgmres")
"""The solvers that take a ``cache=`` (:class:`StokesCache`) keyword."""


def check_solver(solver: str, cache) -> None:
    """``ValueError`` naming an unknown ``solver``, or a ``cache`` that is not a
    :class:`StokesCache` or that the solver does not use."""
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(map(repr, SOLVERS))}, got "
                         f"{solver!r}")
    if cache is not None and solver not in CACHED_SOLVERS:
        raise ValueError(f"cache is used by solver {' or '.join(map(repr, CACHED_SOLVERS))} "
                         f"only, not by solver={solver!r}")
    if cache is not None and not isinstance(cache, StokesCache):
        raise ValueError(f"cache must be a StokesCache, got {type(cache).__name__}")
