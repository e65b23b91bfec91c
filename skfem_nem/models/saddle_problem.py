"""The discrete Stokes saddle-point problem the solvers share: its blocks on the free
velocity dofs (:class:`SaddlePointProblem`), a solution (:class:`SaddlePointSolution`) and
the product with the whole matrix (:func:`saddle_matvec`).

Kept apart from :mod:`skfem_nem.models.stokes_solvers` (one function per solver) because
it is the solvers' common input, not a solver: :mod:`skfem_nem.models.stokes` builds it,
every solver reads it, and none of them needs another's code to do so.

The problem, with ``m`` the integrals of the pressure basis functions::

    [A   B^T] [u]   [f]
    [B   -S ] [p] = [g],     m . p = 0 if the mean pressure is fixed.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional

import numpy as np
import scipy.sparse as sp

__all__ = ["SaddlePointProblem", "SaddlePointSolution", "saddle_matvec"]


@dataclass
class SaddlePointProblem:
    """The Stokes blocks on the free velocity dofs (walls and prescribed
    velocities moved to the right side), extra constraint rows appended to
    ``B`` as pressure-like multipliers."""

    A: sp.csr_matrix        # (n1, n1) viscous block, free dofs
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
    # distributed assembly: the blocks, f, g and dp are this MPI rank's share (m is
    # whole), and this sums a vector over the ranks (only solver "petsc" takes such a
    # problem); None: all whole
    total: Optional[Callable[[np.ndarray], np.ndarray]] = None
    # A was assembled for this solve alone: a solver may write over its values ("fgmres"
    # makes its AMG over them, then reads the block through the hierarchy's product;
    # "petsc" lets A, B and S go once PETSc holds them)
    owned: bool = False

    def whole(self, v: np.ndarray) -> np.ndarray:
        """``v`` summed over the ranks if the problem is a share, else ``v``."""
        return v if self.total is None else self.total(v)

    @property
    def n_velocity(self) -> int:
        """Number of free velocity unknowns."""
        return self.free.size

    @property
    def rhs(self) -> np.ndarray:
        """Right side of the whole system, ``[f, g]``."""
        return np.concatenate([self.f, self.g])

    @property
    def n_pressure(self) -> int:
        """Number of pressure unknowns and multipliers."""
        return self.B.shape[0]

    @property
    def area(self) -> float:
        """Integral of the pressure basis functions: the domain's area."""
        return float(self.m.sum())

    def residual(self, xu: np.ndarray, xp: np.ndarray,
                 viscous: Optional[Callable] = None) -> float:
        """Relative residual of the whole system (the mean-pressure
        multiplier's share removed from the continuity rows); ``viscous``: the product
        with the viscous block, if not ``A @``."""
        Au = self.A @ xu if viscous is None else viscous(xu)
        r1 = self.whole(Au + self.B.T @ xp - self.f)
        r2 = self.whole(self.B @ xu - self.S @ xp - self.g)
        return self.relative(r1, r2)

    def relative(self, r1: np.ndarray, r2: np.ndarray) -> float:
        """The relative residual of :meth:`residual` from the residuals ``r1``, ``r2``
        of the two block rows (whole, summed over the ranks of a share)."""
        m = self.m
        if self.pressure_mean:
            r2 = r2 - m * ((m @ r2) / (m @ m))
        return float(np.sqrt(r1 @ r1 + r2 @ r2) / max(np.linalg.norm(self.whole(self.f)),
                                                      np.linalg.norm(self.whole(self.g)),
                                                      1e-300))

    def mean_free(self, p: np.ndarray) -> np.ndarray:
        """``p`` shifted to mean zero if the mean pressure is fixed (the pressures
        only: the constraint multipliers, where ``m`` is zero, keep their values)."""
        if not self.pressure_mean:
            return p
        return p - (self.m @ p) / self.area * (self.m != 0)


class SaddlePointSolution(NamedTuple):
    """Free velocity dofs, pressure (with multipliers) and how they were found."""

    u: np.ndarray
    p: np.ndarray
    iterations: int
    residual: float


def saddle_matvec(problem: SaddlePointProblem, viscous: Optional[Callable] = None,
                  inner: Callable = np.dot) -> Callable:
    """The product with the whole saddle-point matrix (mean-pressure term
    included); ``viscous``: the product with the viscous block, if not ``A @``;
    ``inner``: the dot product of the mean-pressure term. ``"fgmres"`` passes the BLAS-free
    :func:`~skfem_nem.models.krylov.dot`: from 10,000 entries OpenBLAS's dot wakes threads
    that then hold the cores numba's products need (they took twice as long); the other
    solvers keep numpy's, and their results bit for bit."""
    A, B, S, m, c = problem.A, problem.B, problem.S, problem.m, problem.mean_weight
    n1 = problem.n_velocity
    viscous = A.__matmul__ if viscous is None else viscous

    def matvec(x):
        xu, xp = x[:n1], x[n1:]
        return np.concatenate([viscous(xu) + B.T @ xp,
                               B @ xu - S @ xp - c * m * inner(m, xp)])

    return matvec
