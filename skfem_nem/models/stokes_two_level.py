"""The viscous block of the quadratic natural-neighbour velocity, preconditioned by the
two-level method of :mod:`skfem_nem.basis.two_level`.

Why not the smoothed aggregation of :mod:`skfem_nem.models.stokes_amg`: the quadratic
functions are smooth and wide (some 110 entries a row per component), so a node's edge dofs
can oscillate at little cost in energy, and smoothed aggregation on the whole block needed 202
FGMRES iterations on SolCx at 33,242 unknowns and did not converge at 130,414
(docs/quadratic.md). The two-level method takes the nodes as its coarse level (the nested
prolongation, rigid-body modes of the nodal values as the coarse aggregation's near null
space) and solves each node's star as a block. :class:`ViscousTwoLevel` has the interface of
:class:`~skfem_nem.models.stokes_amg.ViscousAMG`, so the solvers ``"fgmres"``, ``"minres"``
and ``"schur-amg"`` and the :class:`~skfem_nem.models.stokes_cache.StokesCache` take either.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..basis.two_level import TwoLevelSpace
from .krylov import cg_steps
from .stokes_cache import pattern_of, same_pattern

__all__ = ["ViscousTwoLevel"]


class ViscousTwoLevel:
    """The two-level preconditioner of a viscous block ``A`` on the free dofs ``free`` of
    the quadratic natural-neighbour velocity basis ``ubasis``."""

    def __init__(self, A: sp.spmatrix, ubasis, free: np.ndarray):
        self.space = TwoLevelSpace(ubasis, free)
        self.refresh(A)

    @property
    def n_levels(self) -> int:
        """Number of levels: the quadratic dofs, then those of the coarse aggregation."""
        return self.M.levels

    def same_pattern(self, A: sp.spmatrix) -> bool:
        """True if ``A`` has the pattern of the block the method holds, so that
        :meth:`refresh` may take its values."""
        return same_pattern(pattern_of(self.matrix), pattern_of(sp.csr_matrix(A)))

    def refresh(self, A: sp.spmatrix) -> None:
        """New values of the block (the same dofs): the star blocks, the coarse matrix and
        its aggregation are made again (the prolongation and the stars are kept)."""
        self.matrix = sp.csr_matrix(A)
        self.M = self.space.preconditioner(self.matrix)

    def cycle(self, r: np.ndarray) -> np.ndarray:
        """One application of the two-level preconditioner (smooth, coarse, smooth)."""
        return self.M(np.asarray(r, dtype=float).ravel())

    def cg(self, r: np.ndarray, steps: int) -> np.ndarray:
        """``steps`` conjugate-gradient steps from zero for ``A x = r``, each preconditioned
        by :meth:`cycle`; all products in the preconditioner's renumbered order."""
        M = self.M
        return M.in_basis_order(lambda b: cg_steps(M.A, M.renumbered, b, steps),
                                np.asarray(r, dtype=float))

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``A x``, the product in the renumbered order (faster: a row's entries are near
        each other in memory)."""
        return self.M.in_basis_order(lambda y: self.M.A @ y, x)

    def preconditioner(self) -> spla.LinearOperator:
        """:meth:`cycle` as a linear operator approximating ``A^-1``."""
        n = self.space.size
        return spla.LinearOperator((n, n), matvec=self.cycle, dtype=float)
