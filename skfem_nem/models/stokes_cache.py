"""The state the Stokes solvers keep from one solve to the next (:class:`StokesCache`).

Kept apart from :mod:`skfem_nem.models.stokes_solvers` (one function per solver) because it
is bookkeeping, not linear algebra: which AMG hierarchy or factorisation may be reused for a
new viscous block (the same sparsity pattern, iterations not grown too much), and the last
solution as the next start. A time loop passes one object to all its solves.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import scipy.sparse as sp

from .stokes_amg import ViscousAMG, viscous_amg

__all__ = ["StokesCache", "pattern_of", "same_pattern", "REBUILD_GROWTH", "REBUILD_SLACK"]

# a cached AMG hierarchy is rebuilt (a kept factorisation of "schur" made again) when a
# solve needs more than this factor times the iterations of the solve it was built for
# (plus REBUILD_SLACK)
REBUILD_GROWTH = 1.5
REBUILD_SLACK = 10


@dataclass
class StokesCache:
    """What solvers ``"fgmres"`` and ``"schur"`` keep from one solve to the next:
    the AMG hierarchy of the viscous block (``"fgmres"``), its factorisation
    (``"schur"``, :data:`REUSE_FACTOR`) and the last solution.

    Pass one object to a sequence of solves of similar problems (the Picard
    iterations of a time step, successive time steps). The hierarchy is
    reused, with the new matrix values put into it
    (:meth:`~skfem_nem.models.stokes_amg.ViscousAMG.refresh`), while the viscous
    block keeps its sparsity pattern, and rebuilt when the pattern changes or a
    solve needs more than ``REBUILD_GROWTH`` times the iterations of the solve it
    was built for. The last solution is the
    next solve's start where the sizes agree and it is a better start than
    zero. ``builds`` and ``reuses`` count what happened (``factorisations`` and
    ``factor_reuses`` for the factorisation, kept while the pattern is the same and a
    solve with it needs at most ``REBUILD_GROWTH`` times the iterations of the solve
    that made it).
    """

    hierarchy: object = None
    solution: Optional[np.ndarray] = None
    base_iterations: Optional[int] = None
    builds: int = 0
    reuses: int = 0
    last_iterations: Optional[int] = field(default=None, repr=False)
    factor: object = field(default=None, repr=False)
    factor_pattern: Optional[tuple] = field(default=None, repr=False)
    factor_iterations: Optional[int] = None
    factorisations: int = 0
    factor_reuses: int = 0

    def amg(self, problem, overwrite: bool = False):
        """The hierarchy for ``problem.A``: the kept one (refreshed) or a new one;
        ``overwrite``: made over the values of ``problem.A`` where the hierarchy scales it
        (:class:`~skfem_nem.models.stokes_amg.ViscousAMG`), which then holds the scaled
        block."""
        A = problem.A
        stale = (self.base_iterations is not None and self.last_iterations is not None
                 and self.last_iterations > REBUILD_GROWTH * self.base_iterations
                 + REBUILD_SLACK)
        # (the hierarchy knows its block's pattern: no copy of the indices is kept here)
        if self.hierarchy is not None and not stale and self.hierarchy.same_pattern(A):
            if isinstance(self.hierarchy, ViscousAMG):
                self.hierarchy.refresh(A, overwrite=overwrite)
            else:
                self.hierarchy.refresh(A)
            self.reuses += 1
            return self.hierarchy, False
        self.hierarchy = None       # (freed before the new one is built)
        self.hierarchy = viscous_amg(problem, overwrite)
        self.base_iterations = None
        self.builds += 1
        return self.hierarchy, True

    def release_operators(self) -> None:
        """Let go of the hierarchy and the factorisation, keeping the last solution as a
        start: for a time loop whose next block belongs to new spaces (moved nodes, a new
        pattern), which would rebuild them anyway. Without it they stay alive while the
        new spaces and blocks are built: 0.43 GB of a 3D plate step's peak at 30,000
        nodes."""
        self.hierarchy = None
        self.factor = self.factor_pattern = None

    def kept_factor(self, A: sp.spmatrix):
        """The kept factorisation (``"schur"``) if it was made for a viscous block of
        the pattern of ``A``, else None."""
        return self.factor if same_pattern(self.factor_pattern, pattern_of(A)) else None

    def keep_factor(self, lu, A: sp.spmatrix, iterations: int) -> None:
        """Keep the factorisation ``lu`` of ``A`` and the iterations of its solve."""
        self.factor, self.factor_pattern = lu, pattern_of(A, copy=True)
        self.factor_iterations = iterations
        self.factorisations += 1

    def start(self, n: int) -> Optional[np.ndarray]:
        """The last solution as a start vector of length ``n`` (None if the
        sizes differ)."""
        x = self.solution
        return x.copy() if x is not None and x.size == n else None

    def record(self, x: np.ndarray, iterations: int, rebuilt: bool) -> None:
        """Keep the solution and the iteration count of a finished solve."""
        self.solution = x.copy()
        self.last_iterations = iterations
        if rebuilt or self.base_iterations is None:
            self.base_iterations = iterations


def pattern_of(A: sp.spmatrix, copy: bool = False) -> tuple:
    """The sparsity pattern of the compressed matrix ``A``: shape, format, index arrays."""
    if copy:
        return A.shape, A.format, A.indptr.copy(), A.indices.copy()
    return A.shape, A.format, A.indptr, A.indices


def same_pattern(a: Optional[tuple], b: tuple) -> bool:
    """True if the patterns ``a`` (None: none kept) and ``b`` are equal."""
    if a is None:
        return False
    (s0, f0, p0, i0), (s1, f1, p1, i1) = a, b
    return (s0 == s1 and f0 == f1 and p0.shape == p1.shape and i0.shape == i1.shape
            and np.array_equal(p0, p1) and np.array_equal(i0, i1))
