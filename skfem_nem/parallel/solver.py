"""A PETSc Krylov solver that plugs into scikit-fem's ``solve``.

Why: a Poisson or elasticity problem assembled with scikit-fem (on a natural-neighbour
basis or any other) can then be solved by PETSc on one or several MPI ranks without
changing the script beyond the ``solver=`` argument::

    x = solve(*condense(A, b, D=D), solver=solver_petsc(near_nullspace=modes))

Every rank runs the same script and assembles the same matrix; each inserts its own block
of rows, PETSc solves, and every rank gets the whole solution back. Options are PETSc's:
the arguments of :func:`solver_petsc` are defaults that the options database (command
line, ``PETSC_OPTIONS``) overrides under the solver's prefix (``-skfem_ksp_type gmres``,
``-skfem_pc_type hypre``, ``-skfem_ksp_monitor``).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp

from .petsc import (check_replicated, csr_to_petsc, default_options, destroying, gather,
                    import_petsc, vector)

__all__ = ["PetscSolver", "solver_petsc", "null_space", "converged_or_raise"]

# the options prefix of solver_petsc's KSP (-skfem_ksp_type, -skfem_pc_type, ...)
DEFAULT_PREFIX = "skfem_"


class PetscSolver:
    """``solver(A, b) -> x``: a KSP solve of the scipy system ``A x = b`` (the same on
    every rank), the solution on every rank. ``iterations`` and ``reason`` (PETSc's
    converged reason) describe the last solve. Made by :func:`solver_petsc`."""

    def __init__(self, defaults: dict, prefix: str, modes: Optional[np.ndarray]):
        self.defaults, self.prefix, self.modes = defaults, prefix, modes
        self.iterations = 0
        self.reason = 0

    def __call__(self, A: sp.spmatrix, b: np.ndarray, **kwargs) -> np.ndarray:
        if kwargs:
            raise TypeError(f"solver_petsc's solver takes no keyword argument, got "
                            f"{sorted(kwargs)} (give PETSc options to solver_petsc(options=...) "
                            f"or on the command line with the prefix -{self.prefix})")
        PETSc = import_petsc()
        b = np.asarray(b, dtype=float)
        if A.shape != (b.size, b.size):
            raise ValueError(f"A has shape {A.shape}, b has {b.size} entries")
        check_replicated(A)
        with destroying(csr_to_petsc(A), vector(b)) as objs:
            M, rhs = objs
            x = rhs.duplicate()
            objs.append(x)
            if self.modes is not None:
                ns = null_space(self.modes)
                objs.append(ns)
                M.setNearNullSpace(ns)
            ksp = PETSc.KSP().create(comm=M.getComm())
            objs.append(ksp)
            ksp.setOptionsPrefix(self.prefix)
            ksp.setOperators(M)
            with default_options(self.prefix, self.defaults):
                ksp.setFromOptions()
                ksp.solve(rhs, x)
            self.iterations, self.reason = ksp.getIterationNumber(), int(ksp.getConvergedReason())
            converged_or_raise(ksp, "solver_petsc")
            return gather(x)


def null_space(modes: np.ndarray, owned=None):
    """A PETSc null space (or near null space) spanned by the columns of ``modes``
    ((n, k), the same on every rank, e.g. rigid-body modes), orthonormalised as PETSc
    asks; ``owned`` splits the rows as in :func:`~skfem_nem.parallel.petsc.row_range`."""
    PETSc = import_petsc()
    modes = np.asarray(modes, dtype=float)
    if modes.ndim != 2 or not np.isfinite(modes).all():
        raise ValueError(f"null space modes must be a finite (n, k) array, got shape "
                         f"{modes.shape}")
    q, _ = np.linalg.qr(modes)
    vecs = [vector(q[:, k], owned=owned) for k in range(q.shape[1])]
    try:
        return PETSc.NullSpace().create(vectors=vecs, comm=vecs[0].getComm())
    finally:
        for v in vecs:
            v.destroy()


def converged_or_raise(ksp, who: str) -> None:
    """``RuntimeError`` naming PETSc's reason, the iterations and the residual norm if
    ``ksp`` did not converge."""
    PETSc = import_petsc()
    reason = int(ksp.getConvergedReason())
    if reason > 0:
        return
    names = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
    raise RuntimeError(f"{who}: PETSc's {ksp.getType()} did not converge: "
                       f"{names.get(reason, reason)} after {ksp.getIterationNumber()} "
                       f"iterations, residual norm {ksp.getResidualNorm():.3e} (raise "
                       f"max_it, loosen rtol or change the preconditioner with the "
                       f"-{ksp.getOptionsPrefix() or ''}pc_type option)")


def solver_petsc(ksp_type: str = "cg", pc_type: str = "gamg", rtol: float = 1e-10,
                 maxiter: int = 10000, options: Optional[dict] = None,
                 near_nullspace: Optional[np.ndarray] = None,
                 prefix: str = DEFAULT_PREFIX) -> PetscSolver:
    """A PETSc solver for ``skfem.solve(A, b, solver=solver_petsc())``.

    Parameters
    ----------
    ksp_type, pc_type, rtol, maxiter
        Krylov method, preconditioner, relative tolerance and iteration limit
        (defaults: conjugate gradients with PETSc's algebraic multigrid, for symmetric
        positive definite systems such as Poisson and elasticity).
    options
        More PETSc options without the prefix, e.g. ``{"pc_gamg_threshold": 0.02}``.
    near_nullspace
        (n, k) vectors the preconditioner should treat as near null space (the
        rigid-body modes of elasticity for ``gamg``).
    prefix
        The options prefix: the options database overrides every default above with
        ``-<prefix><option>`` (command line or ``PETSC_OPTIONS``).
    """
    if not (np.isfinite(rtol) and rtol > 0):
        raise ValueError(f"rtol must be a positive number, got {rtol}")
    if int(maxiter) != maxiter or maxiter < 1:
        raise ValueError(f"maxiter must be a positive integer, got {maxiter}")
    defaults = {"ksp_type": ksp_type, "pc_type": pc_type, "ksp_rtol": rtol,
                "ksp_max_it": int(maxiter)}
    for key in options or {}:
        if key.startswith("-"):
            raise ValueError(f"PETSc option {key!r}: give it without the leading '-' "
                             f"and without the prefix")
    defaults.update(options or {})
    return PetscSolver(defaults, prefix, near_nullspace)
