"""Saddle-point systems on PETSc: FGMRES with a fieldsplit Schur-complement preconditioner.

Why here and in this form: the Stokes solver ``solve_stokes(..., solver="petsc")`` needs
PETSc's distributed Krylov methods and algebraic multigrid, but this layer sits below the
models and knows no Stokes problem. It solves the plain block system ::

    [A  B^T] [u]   [f]
    [B  C  ] [p] = [g]

given as scipy blocks (the same on every rank, or each rank's share of a distributed
assembly), with the preconditioner of the serial
``"fgmres"`` solver translated into PETSc's terms: the block upper triangle
``[[A, B^T], [0, S_hat]]^-1`` (``-pc_fieldsplit_schur_fact_type upper``), the viscous
block ``A`` approximated by two conjugate-gradient steps preconditioned by algebraic
multigrid (GAMG with the caller's near null space, e.g. the rigid-body modes) and the
Schur complement by a given diagonal (the lumped 1/eta-weighted pressure mass, negated:
PETSc's Schur complement is ``C - B A^-1 B^T``). A constant pressure that the walls leave
free is handed to PETSc as the null space of the whole matrix, in place of the serial
solvers' rank-one term (which would make a dense block).

The unknowns may be renumbered (``order``) before the rows are split between the ranks,
so that each rank owns a part of the domain with its velocity and pressure unknowns
together, its velocities first: the blocks then reach PETSc as a nest, which the
fieldsplit reads without copying them out (another outer preconditioner, such as
``-stokes_pc_type lu``, gets one AIJ matrix). Every default is a PETSc option under the
prefix (``-stokes_``), which the options database overrides: ``-stokes_fieldsplit_0_pc_type hypre``,
``-stokes_ksp_monitor``, ``-stokes_pc_type lu -stokes_pc_factor_mat_solver_type mumps``.
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import numpy as np
import scipy.sparse as sp

from ..basis.locality import inverse_order, renumbered
from .petsc import (check_replicated, csr_to_petsc, default_options, destroying,
                    first_block_first, gather, import_petsc, nest_blocks, nest_of, rows_to_petsc,
                    sent_rows, split_bounds, vector)
from .petsc import summed as summed_vector
from .solver import converged_or_raise, null_space

__all__ = ["SaddleResult", "solve_saddle_petsc", "saddle_defaults", "split_counts"]

# FGMRES restart length: as the serial "fgmres" (memory of two vectors per iteration)
FGMRES_RESTART = 150
# conjugate-gradient steps per application of the viscous-block preconditioner, each
# preconditioned by one multigrid V-cycle: the serial "fgmres" found two the fastest
VISCOUS_CG_STEPS = 2


class SaddleResult(NamedTuple):
    """The two blocks of the solution (whole, on every rank) and how they were found."""

    u: np.ndarray
    p: np.ndarray
    krylov_iterations: int  # FGMRES iterations
    reason: int
    ranks: int
    viscous_pc: str         # the preconditioner PETSc used on the first block
    residual: np.ndarray    # K x - [f, g] of the whole system (summed), whole on every rank


def saddle_defaults(tol: float, maxiter: int) -> dict:
    """The PETSc options (without prefix) :func:`solve_saddle_petsc` starts from."""
    return {"ksp_type": "fgmres", "ksp_gmres_restart": FGMRES_RESTART, "ksp_rtol": tol,
            "ksp_atol": 0.0, "ksp_max_it": int(maxiter),
            "fieldsplit_0_ksp_type": "cg", "fieldsplit_0_ksp_max_it": VISCOUS_CG_STEPS,
            "fieldsplit_0_ksp_norm_type": "none", "fieldsplit_0_pc_type": "gamg",
            "fieldsplit_1_ksp_type": "preonly", "fieldsplit_1_pc_type": "jacobi"}


def split_counts(mask: np.ndarray, size: int) -> list:
    """How many of the rows marked by ``mask`` each of ``size`` ranks owns under
    PETSc's default split of ``mask.size`` rows."""
    return [int(np.count_nonzero(mask[a:b])) for a, b in split_bounds(mask.size, size)]


def solve_saddle_petsc(A: sp.spmatrix, B: sp.spmatrix, C: sp.spmatrix, f: np.ndarray,
                       g: np.ndarray, schur_diagonal: np.ndarray, tol: float, maxiter: int,
                       modes: Optional[np.ndarray] = None,
                       pressure_null: Optional[np.ndarray] = None,
                       order: Optional[np.ndarray] = None,
                       prefix: str = "stokes_", summed: bool = False,
                       release: Optional[Callable[[], None]] = None) -> SaddleResult:
    """Solve the block system of the module docstring on PETSc's ``COMM_WORLD``.

    ``schur_diagonal`` (len(g),) approximates the Schur complement ``C - B A^-1 B^T``
    (negative); ``modes`` (len(f), k) are the near null space of ``A``;
    ``pressure_null`` (len(g),) spans the null space of the whole matrix in the second
    block, if it has one; ``order`` renumbers the unknowns (new ``i`` is old
    ``order[i]``) before the rows are split. With ``summed``, the blocks and the vectors
    ``f``, ``g`` and ``schur_diagonal`` are this rank's share (its triangles' part of a
    distributed assembly), and the system is their sum over the ranks: each rank's
    rows are gathered from the others' shares (:func:`summed_rows`); otherwise they are
    the whole system, the same on every rank. Stops on the relative residual ``tol`` of
    the whole system; ``RuntimeError`` naming PETSc's reason if it does not converge.
    ``release``: called once the blocks are in one matrix here, for the caller to let its
    references to ``A``, ``B`` and ``C`` go (their memory then serves PETSc's). The
    result's ``residual`` is PETSc's ``K x - [f, g]``, so no block is needed after.
    """
    PETSc = import_petsc()
    comm = PETSc.COMM_WORLD
    n1, n2 = len(f), len(g)
    n = n1 + n2
    for name, v in (("schur_diagonal", schur_diagonal), ("pressure_null", pressure_null)):
        if v is not None and np.shape(v) != (n2,):
            raise ValueError(f"{name} has shape {np.shape(v)}, expected ({n2},) like g")
    perm = np.arange(n) if order is None else np.asarray(order)
    if perm.shape != (n,) or not np.array_equal(np.sort(perm), np.arange(n)):
        raise ValueError(f"order must be a permutation of the {n} unknowns")
    share = [sp.bmat([[A, B.T], [B, C]], format="csr")]     # (let go in _to_petsc)
    del A, B, C
    if release is not None:
        release()
    bounds = split_bounds(n, comm.getSize())
    nested = _nested(prefix)
    if nested:
        perm = first_block_first(perm, np.arange(n) < n1, bounds)
    if summed:
        f, g, schur_diagonal = (summed_vector(v, comm) for v in (f, g, schur_diagonal))
    velocity = perm < n1
    Kmat, sets = _to_petsc(share, perm, velocity, bounds, summed, nested, comm)
    with destroying(Kmat, vector(np.concatenate([f, g])[perm], comm), *sets) as objs:
        Kmat, rhs = objs[:2]
        x = rhs.duplicate()
        objs.append(x)
        ksp = _fieldsplit_ksp(comm, Kmat, objs, prefix, sets)
        _attach_spaces(Kmat, ksp.getPC(), sets[0], objs, perm, velocity, schur_diagonal,
                       modes, pressure_null, comm.getSize())
        with default_options(prefix, saddle_defaults(tol, maxiter)):
            ksp.setFromOptions()
            ksp.solve(rhs, x)
        its, reason = ksp.getIterationNumber(), int(ksp.getConvergedReason())
        converged_or_raise(ksp, "solver='petsc'")
        pc0 = ksp.getPC().getFieldSplitSubKSP()[0].getPC().getType() \
            if ksp.getPC().getType() == PETSc.PC.Type.FIELDSPLIT else ""
        whole = np.empty(n)
        whole[perm] = gather(x)
        r = rhs.duplicate()
        objs.append(r)
        Kmat.mult(x, r)
        r.axpy(-1.0, rhs)
        residual = np.empty(n)
        residual[perm] = gather(r)
    return SaddleResult(whole[:n1], whole[n1:], its, reason, comm.getSize(), pc0, residual)


def _to_petsc(share: list, perm: np.ndarray, velocity: np.ndarray, bounds: list,
              summed: bool, nested: bool, comm):
    """The PETSc matrix of this rank's rows of the system (``share``: a list of the one
    matrix, this rank's share or the whole, emptied here so that each copy goes as soon
    as the next is made) renumbered by ``perm``, and its velocity and pressure row sets."""
    K = renumbered(share.pop(), perm, inverse_order(perm))   # (one copy of K at a time)
    if summed:
        received = sent_rows(K, comm)
        del K           # (sent: the share goes before the received rows are added up)
        rows = received.summed()
        del received
    else:
        check_replicated(K, comm, "saddle-point matrix")
        rows = K[slice(*bounds[comm.getRank()])]
        del K
    r0, r1 = bounds[comm.getRank()]
    if not nested:
        return rows_to_petsc(rows, perm.size, comm), _index_sets(comm, velocity, r0, r1)
    blocks = nest_blocks(rows, velocity, r0)
    del rows            # (split: the rows go before PETSc copies the blocks)
    return nest_of(blocks, comm)


def _nested(prefix: str) -> bool:
    """Whether the preconditioner is a fieldsplit (the default), whose blocks then come
    to PETSc as a nest (:func:`~skfem_nem.parallel.petsc.nest_from_rows`: no copies of
    them); another (``-stokes_pc_type lu``) takes one AIJ matrix."""
    PETSc = import_petsc()
    return PETSc.Options().getString(prefix + "pc_type", "fieldsplit") == "fieldsplit"


def _index_sets(comm, velocity: np.ndarray, r0: int, r1: int) -> list:
    """The index sets of this rank's rows ``[r0, r1)`` of both blocks."""
    PETSc = import_petsc()
    return [PETSc.IS().createGeneral((r0 + np.flatnonzero(m)).astype(PETSc.IntType),
                                     comm=comm)
            for m in (velocity[r0:r1], ~velocity[r0:r1])]


def _fieldsplit_ksp(comm, Kmat, objs: list, prefix: str, sets):
    """The KSP with the Schur fieldsplit on the two blocks' index sets ``sets`` (kept
    in ``objs`` for destruction)."""
    PETSc = import_petsc()
    ksp = PETSc.KSP().create(comm=comm)
    objs.append(ksp)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(Kmat)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.FIELDSPLIT)
    pc.setFieldSplitIS(("0", sets[0]), ("1", sets[1]))
    pc.setFieldSplitType(PETSc.PC.CompositeType.SCHUR)
    pc.setFieldSplitSchurFactType(PETSc.PC.SchurFactType.UPPER)
    return ksp


def _attach_spaces(Kmat, pc, is0, objs: list, perm: np.ndarray, velocity: np.ndarray,
                   schur_diagonal: np.ndarray, modes, pressure_null, size: int) -> None:
    """The Schur approximation, the near null space of the first block (composed on
    its index set, where the fieldsplit looks for it) and the null space of ``Kmat``."""
    PETSc = import_petsc()
    n1 = int(velocity.sum())
    pressure_order = perm[~velocity] - n1
    Sp = csr_to_petsc(sp.diags(np.asarray(schur_diagonal, dtype=float)[pressure_order]),
                      owned=split_counts(~velocity, size))
    objs.append(Sp)
    pc.setFieldSplitSchurPreType(PETSc.PC.SchurPreType.USER, Sp)
    if modes is not None:
        ns = null_space(np.asarray(modes)[perm[velocity]], owned=split_counts(velocity, size))
        objs.append(ns)
        is0.compose("nearnullspace", ns)
    if pressure_null is not None:
        z = np.zeros(perm.size)
        z[n1:] = pressure_null
        nsk = null_space(z[perm][:, None])
        objs.append(nsk)
        Kmat.setNullSpace(nsk)
        Kmat.setTransposeNullSpace(nsk)
