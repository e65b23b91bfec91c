"""Smoothed-aggregation AMG of the viscous block: the hierarchy (pyamg, rigid-body
modes as near null space), new matrix values put into a kept one, and the V-cycle and
the few conjugate-gradient steps that solvers ``"schur-amg"``, ``"minres"`` and
``"fgmres"`` of :mod:`skfem_nem.models.stokes_solvers` apply as viscous preconditioner.

Kept apart from the solvers because it is one concern, the multigrid, which the
solvers and their :class:`~skfem_nem.models.stokes_solvers.StokesCache` share; the
choices behind the constants are measured in ``docs/stokes.md``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["AMG_COARSE_SOLVER", "AMG_MAX_COARSE", "AMG_SMOOTHER", "amg_cg", "dot", "norm",
           "refresh_amg", "rigid_modes", "v_cycle", "viscous_amg"]

# coarsest AMG level size (pyamg's max_coarse): solved directly there
AMG_MAX_COARSE = 500
# solve on the coarsest AMG level: sparse LU (pyamg's default, a pseudo-inverse
# by dense SVD, took 0.8 s of a 1 s solve at 2,000 nodes)
AMG_COARSE_SOLVER = "splu"
# smoother of every AMG level (pyamg's default for smoothed aggregation, named so
# that a hierarchy refreshed for new matrix values gets the same one)
AMG_SMOOTHER = ("block_gauss_seidel", {"sweep": "symmetric"})


def viscous_amg(problem):
    """Smoothed-aggregation AMG hierarchy of the viscous block (pyamg), with
    the rigid-body modes as near null space."""
    import pyamg
    return pyamg.smoothed_aggregation_solver(
        problem.A.tocsr(), B=rigid_modes(problem.ubasis, problem.free),
        symmetry="symmetric", strength="symmetric", max_coarse=AMG_MAX_COARSE,
        presmoother=AMG_SMOOTHER, postsmoother=AMG_SMOOTHER, coarse_solver=AMG_COARSE_SOLVER)


def refresh_amg(ml, A: sp.spmatrix) -> None:
    """Put new values of the fine matrix ``A`` (same size) into the hierarchy
    ``ml``: the coarse matrices are the Galerkin products with the kept
    prolongators, the smoothers and the coarse solve are set up again.
    Cheaper than a new hierarchy (no strength, aggregation or prolongator
    smoothing) and exact for the new matrix on the finest level."""
    import pyamg
    from pyamg.relaxation.smoothing import change_smoothers
    levels = ml.levels
    levels[0].A = A.tocsr()
    for fine, coarse in zip(levels[:-1], levels[1:]):
        Ac = fine.R @ fine.A @ fine.P
        coarse.A = Ac.tobsr(blocksize=coarse.A.blocksize) if sp.issparse(coarse.A) and \
            coarse.A.format == "bsr" else sp.csr_matrix(Ac)
    change_smoothers(ml, AMG_SMOOTHER, AMG_SMOOTHER)
    ml.coarse_solver = pyamg.coarse_grid_solver(AMG_COARSE_SOLVER)


def amg_cg(ml, A: sp.spmatrix, b: np.ndarray, steps: int) -> np.ndarray:
    """``steps`` conjugate-gradient steps from zero for ``A x = b``, each
    preconditioned by one V-cycle of ``ml``: a better approximation of
    ``A^-1 b`` than as many stationary V-cycles for one product with ``A``
    more per step."""
    x = np.zeros_like(b)
    r = b.copy()
    z = v_cycle(ml, r)
    d = z.copy()
    rz = dot(r, z)
    for k in range(steps):
        Ad = A @ d
        dAd = dot(d, Ad)
        if not dAd > 0:
            break
        alpha = rz / dAd
        x += alpha * d
        if k == steps - 1:
            break
        r -= alpha * Ad
        z = v_cycle(ml, r)
        rz, rz_old = dot(r, z), rz
        d = z + (rz / rz_old) * d
    return x


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b`` without BLAS: inside the app a threaded BLAS waited for cores held
    by numba's threads (docs/stokes.md), ``einsum`` does not."""
    return float(np.einsum("i,i->", a, b))


def norm(a: np.ndarray) -> float:
    """Euclidean norm without BLAS (see :func:`dot`)."""
    return float(np.sqrt(dot(a, a)))


def v_cycle(ml, b: np.ndarray) -> np.ndarray:
    """One AMG V-cycle from zero for ``A x = b`` (pyamg's own preconditioner
    also computes two norms and a residual per cycle, which are not needed
    inside a Krylov method)."""
    levels = ml.levels

    def cycle(k, rhs):
        lv = levels[k]
        if k == len(levels) - 1:
            return ml.coarse_solver(lv.A, rhs)
        x = np.zeros_like(rhs)
        lv.presmoother(lv.A, x, rhs)
        x += lv.P @ cycle(k + 1, lv.R @ (rhs - lv.A @ x))
        lv.postsmoother(lv.A, x, rhs)
        return x

    return cycle(0, b)


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
