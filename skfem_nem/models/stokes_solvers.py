"""Solvers of the discrete Stokes saddle-point problem, one function per solver.

Kept apart from :mod:`skfem_nem.models.stokes` (spaces, forms, assembly and
wall conditions) because the solvers are linear algebra alone: they see the
assembled blocks restricted to the free velocity dofs
(:class:`SaddlePointProblem`) and know nothing of meshes, forms or walls.
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
ordering) and solves the pressure Schur complement by preconditioned
conjugate gradients (preconditioner: the lumped 1/eta-weighted pressure
mass). ``"schur-amg"`` is the same outer iteration with the viscous block
solved by AMG-preconditioned CG instead of a factorisation (memory linear in
the problem size). ``"direct"`` factorises the whole saddle-point system
(slower: natural-neighbour stencils are wide). ``"minres"`` uses MINRES with
a block-diagonal preconditioner: one smoothed-aggregation AMG V-cycle
(pyamg, rigid-body modes as near null space) for the viscous block and the
diagonal of the viscosity-scaled pressure mass matrix for the pressure. The
iterative solvers fix the mean pressure by a rank-one term ``c m m^T`` of
the size of 1/eta.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["SaddlePointProblem", "SaddlePointSolution", "SOLVERS", "solve_direct",
           "solve_schur", "solve_schur_amg", "solve_minres", "rigid_modes"]

# relative tolerance of the inner AMG-CG solves of the viscous block
# ("schur-amg"): at most this, and two orders of magnitude below the outer tol
INNER_RTOL = 1e-3
# iteration limit of each inner AMG-CG solve of the viscous block
INNER_MAXITER = 1000
# coarsest AMG level size (pyamg's max_coarse): solved directly there
AMG_MAX_COARSE = 500
# MINRES stops when its preconditioned residual norm is below this factor
# times tol (its own estimate drifts from the true residual; see solve_minres)
MINRES_TOL_FACTOR = 10
# MINRES restart asks for at most this relative reduction of the residual
MINRES_MAX_RTOL = 0.5


@dataclass
class SaddlePointProblem:
    """The Stokes blocks on the free velocity dofs (walls and prescribed
    velocities moved to the right side), extra constraint rows appended to
    ``B`` as pressure-like multipliers."""

    A: sp.csc_matrix        # (n1, n1) viscous block, free dofs
    B: sp.csr_matrix        # (npr, n1) divergence (and constraint) rows
    S: sp.csr_matrix        # (npr, npr) pressure stabilisation
    f: np.ndarray           # (n1,) momentum right side
    g: np.ndarray           # (npr,) continuity right side
    m: np.ndarray           # (npr,) integrals of the pressure basis (zero on multipliers)
    dp: np.ndarray          # (npr,) diagonal pressure preconditioner
    mean_weight: float      # c of the rank-one term c m m^T fixing the mean pressure
    pressure_mean: bool     # fix the pressure by its mean (zero)
    ubasis: object          # velocity basis, for the rigid-body modes of AMG
    free: np.ndarray        # free velocity dofs of ubasis

    @property
    def n_velocity(self) -> int:
        """Number of free velocity unknowns."""
        return self.free.size

    @property
    def n_pressure(self) -> int:
        """Number of pressure unknowns and multipliers."""
        return self.B.shape[0]

    @property
    def area(self) -> float:
        """Integral of the pressure basis functions: the domain's area."""
        return float(self.m.sum())

    def residual(self, xu: np.ndarray, xp: np.ndarray) -> float:
        """Relative residual of the whole system (the mean-pressure
        multiplier's share removed from the continuity rows)."""
        r1 = self.A @ xu + self.B.T @ xp - self.f
        r2 = self.B @ xu - self.S @ xp - self.g
        if self.pressure_mean:
            r2 = r2 - self.m * ((self.m @ r2) / (self.m @ self.m))
        return float(np.sqrt(r1 @ r1 + r2 @ r2) / max(np.linalg.norm(self.f),
                                                      np.linalg.norm(self.g), 1e-300))

    def mean_free(self, p: np.ndarray) -> np.ndarray:
        """``p`` shifted to mean zero if the mean pressure is fixed."""
        return p - (self.m @ p) / self.area if self.pressure_mean else p


class SaddlePointSolution(NamedTuple):
    """Free velocity dofs, pressure (with multipliers) and how they were found."""

    u: np.ndarray
    p: np.ndarray
    iterations: int
    residual: float


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
        rhs = np.concatenate([problem.f, problem.g])
    x = spla.spsolve(K, rhs)
    if not np.isfinite(x).all():
        raise RuntimeError("the Stokes system is singular: check the wall conditions "
                           "(a rigid-body motion left free?) and the viscosity")
    n1 = problem.n_velocity
    p = x[n1:n1 + problem.n_pressure]
    return SaddlePointSolution(x[:n1], p, 1, problem.residual(x[:n1], p))


def solve_schur(problem: SaddlePointProblem, tol: float, maxiter: int,
                info: dict) -> SaddlePointSolution:
    """Sparse LU of the viscous block, pressure CG on the Schur complement."""
    try:
        lu = spla.splu(problem.A, permc_spec="MMD_AT_PLUS_A",
                       options=dict(SymmetricMode=True))
    except RuntimeError as err:
        raise RuntimeError(f"the viscous block is singular ({err}): check the wall "
                           f"conditions (a rigid-body motion left free?)") from None
    return schur_pressure_cg(problem, lu, tol, maxiter)


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
    lu = AMGViscousSolve(problem.A, ml.aspreconditioner(cycle="V"),
                         min(INNER_RTOL, tol * 1e-2), inner)
    info["inner_iterations"] = inner
    return schur_pressure_cg(problem, lu, tol, maxiter)


def schur_pressure_cg(problem: SaddlePointProblem, lu, tol: float,
                      maxiter: int) -> SaddlePointSolution:
    """Pressure CG on ``B A^-1 B^T + S + c m m^T`` with ``lu.solve`` applying
    ``A^-1``; preconditioner: ``1 / dp``."""
    B, S, m, c = problem.B, problem.S, problem.m, problem.mean_weight
    npr, fu = problem.n_pressure, problem.f
    count = [0]

    def schur(q):
        return B @ lu.solve(B.T @ q) + S @ q + c * m * (m @ q)

    Sop = spla.LinearOperator((npr, npr), matvec=schur, dtype=float)
    Pp = spla.LinearOperator((npr, npr), matvec=lambda q: q / problem.dp, dtype=float)
    g = B @ lu.solve(fu) - problem.g
    p, flag = spla.cg(Sop, g, M=Pp, rtol=tol, maxiter=maxiter,
                      callback=lambda *_: count.__setitem__(0, count[0] + 1))
    if flag != 0:
        r = np.linalg.norm(schur(p) - g) / max(np.linalg.norm(g), 1e-300)
        raise RuntimeError(f"pressure CG did not converge: {count[0]} iterations, "
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
    matvec, K, M = minres_operators(problem, ml.aspreconditioner(cycle="V"))
    x, res_m, restarts, its = restarted_minres(matvec, K, M,
                                               np.concatenate([problem.f, problem.g]),
                                               tol, maxiter)
    res = problem.residual(x[:n1], x[n1:])
    info["preconditioned_residual"] = res_m
    info["restarts"] = restarts
    if not res_m <= MINRES_TOL_FACTOR * tol:
        raise RuntimeError(f"MINRES did not converge: {its} iterations, relative "
                           f"preconditioned residual {res_m:.3e} > "
                           f"{MINRES_TOL_FACTOR * tol:.1e} (raise maxiter, or use "
                           f"solver='schur' for strong viscosity contrasts)")
    p = problem.mean_free(x[n1:])
    info["amg_levels"] = len(ml.levels)
    return SaddlePointSolution(x[:n1], p, its, res)


def minres_operators(problem: SaddlePointProblem, Pu):
    """The saddle-point product (as a function and an operator) and the
    block-diagonal preconditioner (``Pu`` on the velocity, ``1 / dp``)."""
    A, B, S, m, c = problem.A, problem.B, problem.S, problem.m, problem.mean_weight
    n1, npr, dp = problem.n_velocity, problem.n_pressure, problem.dp

    def matvec(x):
        xu, xp = x[:n1], x[n1:]
        return np.concatenate([A @ xu + B.T @ xp,
                               B @ xu - S @ xp - c * m * (m @ xp)])

    K = spla.LinearOperator((n1 + npr, n1 + npr), matvec=matvec, dtype=float)
    M = spla.LinearOperator(K.shape, matvec=lambda x: np.concatenate([Pu @ x[:n1],
                                                                      x[n1:] / dp]),
                            dtype=float)
    return matvec, K, M


def restarted_minres(matvec: Callable, K, M, rhs: np.ndarray, tol: float, maxiter: int):
    """MINRES restarted on the true residual.

    MINRES's own residual estimate drifts from the true one on these badly
    conditioned systems: restart it on the true residual until the
    preconditioned residual norm (the norm MINRES minimises) meets
    ``MINRES_TOL_FACTOR * tol`` or ``maxiter`` iterations are spent. Returns
    the solution, that relative norm, the number of restarts and of
    iterations.
    """
    count = [0]
    bnorm = float(np.sqrt(abs(rhs @ M.matvec(rhs)))) or 1.0
    x = np.zeros_like(rhs)
    r = rhs.copy()
    res_m = 1.0
    restarts = 0
    while count[0] < maxiter:
        res_m = float(np.sqrt(abs(r @ M.matvec(r)))) / bnorm
        if res_m <= MINRES_TOL_FACTOR * tol:
            break
        dx, _ = spla.minres(K, r, M=M, rtol=min(MINRES_MAX_RTOL, MINRES_MAX_RTOL * tol / res_m),
                            maxiter=maxiter - count[0],
                            callback=lambda *_: count.__setitem__(0, count[0] + 1))
        x = x + dx
        r = rhs - matvec(x)
        restarts += 1
    return x, res_m, restarts, count[0]


def viscous_amg(problem: SaddlePointProblem):
    """Smoothed-aggregation AMG hierarchy of the viscous block (pyamg), with
    the rigid-body modes as near null space."""
    import pyamg
    return pyamg.smoothed_aggregation_solver(
        problem.A.tocsr(), B=rigid_modes(problem.ubasis, problem.free),
        symmetry="symmetric", strength="symmetric", max_coarse=AMG_MAX_COARSE)


def rigid_modes(ubasis, free: np.ndarray) -> np.ndarray:
    """(len(free), 3) rigid-body modes (two translations, one rotation) of a
    vector velocity basis, restricted to the dofs ``free``."""
    loc = ubasis.doflocs  # (2, nu)
    comp = np.zeros(ubasis.N, dtype=int)
    for dofs_ in (ubasis.dofs.nodal_dofs, ubasis.dofs.facet_dofs):  # rows: u^1, u^2
        comp[dofs_[1::2].ravel()] = 1
    Bm = np.zeros((ubasis.N, 3))
    Bm[comp == 0, 0] = 1.0
    Bm[comp == 1, 1] = 1.0
    Bm[comp == 0, 2] = -loc[1, comp == 0]
    Bm[comp == 1, 2] = loc[0, comp == 1]
    return Bm[free]


SOLVERS: Dict[str, Callable[..., SaddlePointSolution]] = {
    "schur": solve_schur, "schur-amg": solve_schur_amg, "direct": solve_direct,
    "minres": solve_minres}
"""The solvers of :func:`skfem_nem.models.stokes.solve_stokes` by name, each
``(problem, tol, maxiter, info) -> SaddlePointSolution``."""
