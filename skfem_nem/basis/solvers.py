"""``natural_neighbour_solver``: scikit-fem's ``solve`` for the natural-neighbour matrices.

Why: a direct factorisation of these matrices fills in fast (the linear basis has some 29
entries a row in 2D, the quadratic some 110, the 3D linear some 170), and pyamg's
smoothed aggregation with V-cycles takes more and more iterations as they grow. Each basis
gets its multigrid, the same for a scalar problem and for elasticity (the rigid-body modes
as near null space):

* the linear basis (triangles or tetrahedra): smoothed aggregation on the matrix, one cycle
  an iteration whose coarse corrections are K-cycles
  (:func:`~skfem_nem.basis.multigrid.k_cycle`);
* the quadratic basis: the two-level method of :mod:`.two_level`, the nodes as its coarse
  level and K-cycles of smoothed aggregation below them.

K-cycles are not linear maps, so the outer method is flexible CG
(:func:`~skfem_nem.basis.multigrid.flexible_cg`). Use it as::

    solve(*condense(A, b, x=x, D=D), solver=natural_neighbour_solver(basis, D))
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp

from .elements import element_order
from .multigrid import flexible_cg, k_cycle, smoothed_aggregation
from .rigid_modes import rigid_modes
from .two_level import (CHEBYSHEV_DEGREE, SOLVER_COARSE_SMOOTHER, TwoLevelPreconditioner,
                        TwoLevelSpace)

__all__ = ["AggregationSpace", "natural_neighbour_solver", "SOLVER_TOL", "SOLVER_MAXITER"]

# flexible CG's relative residual, and its iteration limit, by default
SOLVER_TOL = 1e-8
SOLVER_MAXITER = 5000


class AggregationSpace:
    """What smoothed aggregation takes from the linear natural-neighbour ``basis`` (scalar
    or vector) with only the dofs ``free`` unknown: for a vector basis the rigid-body modes
    of those dofs as near null space (``modes``; None for a scalar basis, whose near null
    space is the constants). :meth:`preconditioner` builds the hierarchy of a matrix on
    those dofs (pyamg's defaults: symmetric strength, Jacobi-smoothed prolongators,
    symmetric Gauss-Seidel) and returns its K-cycle."""

    def __init__(self, basis, free: np.ndarray):
        self.free = np.asarray(free, dtype=np.int64)
        vector = basis.N > basis.mesh.p.shape[1]
        self.modes = rigid_modes(basis, self.free) if vector else None
        self.levels = 0

    @property
    def size(self) -> int:
        """Number of free dofs."""
        return self.free.size

    def preconditioner(self, A: sp.spmatrix):
        """The K-cycle of the hierarchy of ``A`` (on the free dofs, in their order)."""
        if A.shape != (self.size, self.size):
            raise ValueError(f"the matrix is {A.shape[0]} x {A.shape[1]}, the basis has "
                             f"{self.size} free dofs: condense it with the same D")
        ml = smoothed_aggregation(sp.csr_matrix(A), self.modes)
        self.levels = len(ml.levels)
        # (the cycle of the finest level: flexible CG outside is its Krylov method)
        return lambda r: k_cycle(ml, r, steps=False)


def _space(basis, free: np.ndarray, degree: Optional[int]):
    """The multigrid space of ``basis``: :class:`TwoLevelSpace` (quadratic) or
    :class:`AggregationSpace` (linear); ``TypeError`` for a basis of other functions."""
    from .elements import ElementNaturalNeighbour
    elem = getattr(basis.elem, "elem", basis.elem)     # ElementVector's element
    if not isinstance(elem, ElementNaturalNeighbour):
        raise TypeError(f"natural_neighbour_solver needs a natural-neighbour basis "
                        f"(ElementNaturalNeighbour, ElementNaturalNeighbour2 or their "
                        f"ElementVector), got {type(elem).__name__}")
    if element_order(basis.elem) == 2:
        return TwoLevelSpace(basis, free, CHEBYSHEV_DEGREE if degree is None else degree)
    if degree is not None:
        raise ValueError(f"degree (the quadratic basis' Chebyshev smoother) does not apply to "
                         f"the linear basis, got degree={degree!r}")
    return AggregationSpace(basis, free)


def _preconditioner(space, A):
    """The multigrid of ``A`` on ``space``: the two-level method with K-cycles and
    :data:`~skfem_nem.basis.two_level.SOLVER_COARSE_SMOOTHER` below the nodes, or the
    aggregation's K-cycle."""
    if isinstance(space, TwoLevelSpace):
        # (components aggregated apart: with whole nodes these K-cycles took elasticity at
        # 101,456 unknowns in 38 iterations and 6.3 s, against 32 and 5.2 s)
        return space.preconditioner(A, cycle="K", coarse_smoother=SOLVER_COARSE_SMOOTHER,
                                    node_blocks=False)
    return space.preconditioner(A)


def _solved(A, b, M, tol: float, maxiter: int) -> tuple:
    """Flexible CG for ``A x = b`` preconditioned by ``M``, run in the two-level method's
    own dof order where ``M`` is one (its products with the matrix are faster there:
    :mod:`.locality`): ``(x, iterations, converged)``."""
    if not isinstance(M, TwoLevelPreconditioner):
        return flexible_cg(A, b, M, tol, maxiter)
    x, its, converged = flexible_cg(M.A, M.to_own_order(np.asarray(b, dtype=float)),
                                    M.renumbered, tol, maxiter)
    return M.to_callers_order(x), its, converged


def natural_neighbour_solver(basis, D: Optional[np.ndarray] = None, tol: float = SOLVER_TOL,
                             maxiter: int = SOLVER_MAXITER, degree: Optional[int] = None):
    """A solver for scikit-fem's ``solve`` on the natural-neighbour ``basis`` (linear or
    quadratic, scalar or vector) with the Dirichlet dofs ``D`` condensed out: flexible CG
    preconditioned by the basis' multigrid (module docstring), to the relative residual
    ``tol``; ``degree``: the Chebyshev smoother's of the quadratic basis (default
    :data:`~skfem_nem.basis.two_level.CHEBYSHEV_DEGREE`).

    The solver records its iterations in ``solver.iterations`` and the multigrid's levels in
    ``solver.levels``. It raises ``RuntimeError`` if CG does not converge in ``maxiter``,
    ``ValueError`` on a matrix of another size than the free dofs, ``TypeError`` on keywords
    it does not take.

    >>> from skfem import BilinearForm, LinearForm, condense, solve
    >>> from skfem.helpers import dot, grad
    >>> from skfem_nem import NaturalNeighbourBasis, delaunay_mesh, natural_neighbour_solver
    >>> from skfem_nem.geometry.nodesets import box_nodes
    >>> basis = NaturalNeighbourBasis(delaunay_mesh(box_nodes(2000, seed=0)))
    >>> A = BilinearForm(lambda u, v, w: dot(grad(u), grad(v))).assemble(basis)
    >>> b = LinearForm(lambda v, w: v).assemble(basis)
    >>> D = basis.get_dofs().all()
    >>> s = natural_neighbour_solver(basis, D)
    >>> x = solve(*condense(A, b, D=D), solver=s)
    >>> s.iterations < 25, s.levels
    (True, 2)
    """
    if not (0 < tol < 1):
        raise ValueError(f"tol must be in (0, 1), got {tol!r}")
    D = np.zeros(0, np.int64) if D is None else np.asarray(D, dtype=np.int64).ravel()
    space = _space(basis, np.setdiff1d(np.arange(basis.N), D), degree)

    def solver(A, b, **kwargs):
        if kwargs:
            raise TypeError(f"natural_neighbour_solver takes no keywords, got {sorted(kwargs)}")
        M = _preconditioner(space, A)
        solver.levels = getattr(M, "levels", getattr(space, "levels", 0))
        x, its, converged = _solved(A, b, M, tol, maxiter)
        solver.iterations = its
        if not converged:
            res = np.linalg.norm(b - A @ x) / max(np.linalg.norm(b), 1e-300)
            raise RuntimeError(f"flexible CG with the natural-neighbour multigrid did not "
                               f"converge: {its} iterations, relative residual {res:.2e} > "
                               f"{tol:.0e}")
        return x

    solver.iterations = solver.levels = 0
    return solver
