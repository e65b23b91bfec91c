"""Solvers on PETSc over MPI (optional: needs petsc4py and mpi4py, see docs/parallel.md).

Between the basis and the models: it turns scipy matrices assembled by scikit-fem (the
whole matrix on every rank, or each rank's share of a distributed assembly over its own
part of the cells) into distributed PETSc matrices, solves them with PETSc's Krylov
methods and multigrid, and gathers the solution to every rank. Importing this
package does not import petsc4py; the first solve does, and raises
:class:`PetscUnavailableError` naming the installation route if it is missing.
"""
from .petsc import PETSC_INSTALL_HINT, PetscUnavailableError, import_petsc
from .saddle import SaddleResult, solve_saddle_petsc
from .solver import PetscSolver, solver_petsc

__all__ = ["PETSC_INSTALL_HINT", "PetscUnavailableError", "import_petsc", "SaddleResult",
           "solve_saddle_petsc", "PetscSolver", "solver_petsc"]
