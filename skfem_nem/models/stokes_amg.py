"""Smoothed-aggregation AMG of the viscous block: the hierarchy (pyamg, rigid-body
modes as near null space), new matrix values put into a kept one, and the V-cycle and
the few conjugate-gradient steps that solvers ``"schur-amg"``, ``"minres"`` and
``"fgmres"`` of :mod:`skfem_nem.models.stokes_solvers` apply as viscous preconditioner.

Kept apart from the solvers because it is one concern, the multigrid, which the
solvers and their :class:`~skfem_nem.models.stokes_cache.StokesCache` share; the
choices behind the constants are measured in ``docs/stokes.md``.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit, prange

from ..basis.multigrid import (AMG_SEED, K_CYCLE_TOL, k_cycle, polynomial_smoothers,
                               seeded_global_random, v_cycle)
from ..basis.rigid_modes import rigid_modes, velocity_components
from ..basis.symmetric_rows import SymmetricRows
from .amg_blocks import galerkin_of_blocks, hierarchy_of_blocks, plain_aggregation
from .block_rows import BlockSymmetricRows, node_positions
from .krylov import cg_steps, largest_eigenvalue

__all__ = ["AMG_COARSE_SOLVER", "AMG_MAX_COARSE", "AMG_SEED", "AMG_SMOOTHER", "AMG_STRENGTH",
           "CHEBYSHEV_INTERVAL", "COARSE_KEPT", "FINE_VALUES", "K_CYCLE_3D", "K_CYCLE_TOL",
           "ViscousAMG", "k_cycle", "rigid_modes", "scaled_block", "unit_scale", "v_cycle",
           "velocity_components", "viscous_amg"]

# coarsest AMG level size (pyamg's max_coarse): solved directly there
AMG_MAX_COARSE = 500
# solve on the coarsest AMG level: sparse LU (pyamg's default, a pseudo-inverse
# by dense SVD, took 0.8 s of a 1 s solve at 2,000 nodes)
AMG_COARSE_SOLVER = "splu"
# smoother of every AMG level: Chebyshev polynomials of degree 2 on the diagonally
# scaled block, so Jacobi-preconditioned Chebyshev (PETSc GAMG's default). SolCx at a
# contrast of 1e6, 80,550 viscous unknowns, CG to 1e-8 preconditioned by a V-cycle:
# 20 iterations and 0.63 s against 32 and 2.36 s with pyamg's symmetric block
# Gauss-Seidel on the unscaled block (docs/stokes.md); without the scaling Chebyshev
# diverges there (the diagonal spans the contrast)
AMG_SMOOTHER = ("chebyshev", {"degree": 2})
# the interval of the Chebyshev smoother as fractions of the estimated spectral radius of
# the scaled block (pyamg's defaults): the finest level's smoother, which ViscousAMG applies
# itself, is pyamg's on the coarser levels
CHEBYSHEV_INTERVAL = (1.0 / 30.0, 1.1)
# a refresh renews the finest level alone (the coarse levels keep their Galerkin products)
# while no diagonal entry of the block has changed by more than this factor since the
# coarse levels were made. The Picard iterations of a step change the viscosity by less:
# on the 3D plate at 9,956 nodes, solves 2 and 6 of a step (diagonal within a factor 1.7)
# took 22 FGMRES iterations either way, and the refresh 0.32 s against 0.64 s
COARSE_KEPT = 2.0
# precision of the finest level's entries in the smoothing and the CG steps of cg(), the
# preconditioner of the flexible FGMRES (sums in double precision): single. It is a
# perturbation of the block far larger than this rounding, and FGMRES multiplies with the
# block in double precision. cycle() and preconditioner() (MINRES, "schur-amg") stay in
# double precision: a fixed symmetric map to round-off. On
# the 3D plate's block at 9,956 nodes a product takes 4.5 ms against 7.8 ms in double
# precision (scipy, one thread: 21 ms), and its solves take the same iterations
FINE_VALUES = np.float32
# strength of connection: drop the entries below this fraction of the geometric mean
# of their diagonal entries before aggregating. Natural-neighbour rows have about 68
# entries, and keeping them all (pyamg's theta 0) coarsens 200,834 unknowns to 5,346 in
# one level; 0.02 coarsens to 15,927 and cuts the CG iterations from 38 to 24
AMG_STRENGTH = ("symmetric", {"theta": 0.02})
# Prolongator smoothing of the 3D natural-neighbour block: none (plain aggregation). Its
# rows have some 450 entries (three components of some 150 neighbours), so the smoothed
# prolongator A T is dense and the Galerkin product took most of the set-up: at 4,033
# nodes (unit cube, viscosity ratio 20) 2.59 s of set-up against 0.60 s unsmoothed, the
# same 23 FGMRES iterations; on the sinker (contrast 1e4) 2.15 s against 0.38 s, 95 both.
# The wide stencils already make the aggregates' basis smooth. 2D keeps pyamg's Jacobi.
AMG_SMOOTH_3D = None
# The rigid-body modes of the 3D block are taken as they are, not relaxed first (pyamg's
# default: four symmetric Gauss-Seidel sweeps on each of the six modes). On the 3D plate's
# block at 9,956 nodes the relaxation took 1.7 s of a 2.5 s build, and without it a solve
# from zero took 36 FGMRES iterations against 34, a warm-started one 22 both. A step of the
# plate builds one hierarchy (its tetrahedra are new) and refreshes it for the others
AMG_IMPROVE_3D = None
# The flexible solver's cycles of the 3D block are K-cycles (k_cycle; Notay & Vassilevski
# 2008): each coarse correction is two flexible CG steps on the coarse level, preconditioned
# by that level's own cycle. Plain aggregation coarsens the 3D block some 15 times a level,
# and with V-cycles FGMRES took 25, 28, 34 and 39 iterations from 1,484 to 109,916 nodes
# (viscosity ratio 1): the coarse levels' own error grew with their number. With K-cycles
# 25, 28, 31 and 31 (the sinker: 95 against 100 at 34,553 nodes), and the solve at 109,916
# nodes took 47 s against 69 s (docs/stokes_3d.md). The fixed preconditioners (MINRES,
# "schur-amg") keep the V-cycle: a K-cycle is not a linear map
K_CYCLE_3D = True
# The finest level of the 3D block keeps its nodes' 3x3 blocks (BlockSymmetricRows: one index
# a block, not one a value), where the velocity's dofs are all nodal. On a block of 100,000
# nodes a product took 28.6 ms in single and 31.8 ms in double precision, against 47 and 48
# ms entry by entry (SymmetricRows), and the triangles' indices 32 MB against 580 MB
FINE_BLOCKS_3D = True


def viscous_amg(problem, overwrite: bool = False):
    """The multigrid of the viscous block: smoothed-aggregation AMG (pyamg, the
    rigid-body modes as near null space, :class:`ViscousAMG`; with ``overwrite`` built
    over the values of ``problem.A``, which holds the scaled block afterwards), or for the
    quadratic natural-neighbour velocity the two-level method
    (:class:`~skfem_nem.models.stokes_two_level.ViscousTwoLevel`, which reads the block
    only)."""
    if getattr(problem.ubasis, "order", 1) == 2:
        from .stokes_two_level import ViscousTwoLevel
        return ViscousTwoLevel(problem.A, problem.ubasis, problem.free)
    three_d = problem.ubasis.mesh.dim() == 3
    positions = node_positions(problem.ubasis, problem.free) if three_d and FINE_BLOCKS_3D \
        and not isinstance(problem.A, BlockSymmetricRows) else None
    return ViscousAMG(problem.A, rigid_modes(problem.ubasis, problem.free),
                      k_cycles=three_d and K_CYCLE_3D, overwrite=overwrite,
                      positions=positions,
                      **({"smooth": AMG_SMOOTH_3D, "improve_candidates": AMG_IMPROVE_3D}
                         if three_d else {}))


class ViscousAMG:
    """Smoothed-aggregation AMG (pyamg) of a viscous block ``A``, built on the block
    scaled to a unit diagonal, ``D^-1/2 A D^-1/2``.

    Why scaled: the viscosity contrast of a problem (1e6 for SolCx) is on the diagonal,
    and the scaled block's smoother is then Jacobi-preconditioned, which is what a
    polynomial (Chebyshev) smoother needs; aggregation sees relative, not absolute,
    couplings. The methods take and return vectors of the unscaled problem.

    The finest level's products (the Chebyshev smoothing, the residual, the CG steps of
    :meth:`cg`) go through :class:`~skfem_nem.basis.symmetric_rows.SymmetricRows`, the
    block's upper triangle on numba's threads in single precision (:data:`FINE_VALUES`;
    in 3D its nodes' 3x3 blocks, :class:`~skfem_nem.models.block_rows.BlockSymmetricRows`),
    and its spectral radius is a Lanczos estimate
    (:func:`~skfem_nem.models.krylov.largest_eigenvalue`) on it; pyamg's levels below are
    unchanged. :meth:`matvec` is the product with the block in double precision on the
    same triangle.
    """

    def __init__(self, A: sp.spmatrix, modes: np.ndarray, k_cycles: bool = False,
                 overwrite: bool = False, positions: Optional[np.ndarray] = None, **options):
        """``A``: the viscous block, CSR, or the 3D condensed block as its nodes' 3 x 3
        blocks (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`, expanded to CSR
        for the set-up alone; with ``overwrite`` it is scaled in place and becomes the
        finest level). ``k_cycles``: :meth:`cg` cycles with :func:`k_cycle` below the finest level
        (:data:`K_CYCLE_3D`), else V-cycles. ``overwrite``: the scaled block is written
        over the values of ``A`` (a CSR matrix in double precision), which holds it
        afterwards: no second copy of the block while the hierarchy is made (at 100,000
        nodes 1.8 GB). ``positions``: each unknown's place ``3 * node + component`` in a
        3D vector field (:func:`~skfem_nem.models.block_rows.node_positions`): the finest
        level then keeps its nodes' 3x3 blocks
        (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`, :data:`FINE_BLOCKS_3D`);
        None: its entries (:class:`~skfem_nem.basis.symmetric_rows.SymmetricRows`).
        ``options``: more keywords of pyamg's
        ``smoothed_aggregation_solver`` (for the 3D block the prolongator smoothing
        ``smooth``, :data:`AMG_SMOOTH_3D`, and ``improve_candidates``,
        :data:`AMG_IMPROVE_3D`)."""
        self.k_cycles = bool(k_cycles)
        self.scale = unit_scale(A)
        # a block of 3 x 3 blocks makes its first level itself (amg_blocks) where that level
        # is pyamg's plain aggregation (the 3D block's: AMG_SMOOTH_3D, AMG_IMPROVE_3D) and
        # the hierarchy more than its coarsest level
        self._blocks = (isinstance(A, BlockSymmetricRows) and A.shape[0] > AMG_MAX_COARSE
                        and plain_aggregation(options))
        if self._blocks:
            self._set_up_blocks(A, modes, overwrite, options)
        else:
            if isinstance(A, BlockSymmetricRows):
                A, overwrite = A.tocsr(), True      # (a CSR of its own)
            self._set_up_csr(A, modes, overwrite, positions, options)
        self.coefficients = self._chebyshev()
        self._coarse_scale = self.scale     # the scaling the coarse levels were made with

    def _set_up_csr(self, A, modes, overwrite, positions, options) -> None:
        """The hierarchy by pyamg from the CSR block, and the finest level's products."""
        import pyamg
        scaled = scaled_block(_own_csr(A, overwrite), self.scale, overwrite=overwrite)
        with seeded_global_random():
            self.ml = pyamg.smoothed_aggregation_solver(
                scaled, B=modes / self.scale[:, None], symmetry="symmetric",
                strength=AMG_STRENGTH, max_coarse=AMG_MAX_COARSE,
                presmoother=[None, AMG_SMOOTHER], postsmoother=[None, AMG_SMOOTHER],
                coarse_solver=AMG_COARSE_SOLVER, **options)
        polynomial_smoothers(self.ml, [None, AMG_SMOOTHER], [None, AMG_SMOOTHER])
        self.fine = SymmetricRows(scaled, FINE_VALUES) if positions is None else \
            BlockSymmetricRows(scaled, positions, FINE_VALUES)
        self.exact = self.fine.twin(scaled)
        self._let_go_finest()

    def _set_up_blocks(self, A: BlockSymmetricRows, modes, overwrite, options) -> None:
        """The hierarchy from the block's 3 x 3 blocks
        (:func:`~skfem_nem.models.amg_blocks.hierarchy_of_blocks`), which are scaled (in
        place with ``overwrite``) and are the finest level."""
        self.fine, self.exact = None, A if overwrite else A.copy()
        self.exact.scale(self.scale)
        with seeded_global_random():
            self.ml = hierarchy_of_blocks(
                self.exact, modes / self.scale[:, None], AMG_STRENGTH, AMG_COARSE_SOLVER,
                max_coarse=AMG_MAX_COARSE, presmoother=AMG_SMOOTHER,
                postsmoother=AMG_SMOOTHER, **options)
        self.fine = self.exact.twin(self.exact, FINE_VALUES)

    def _scaled_blocks(self, A: BlockSymmetricRows, overwrite: bool, fine):
        """The finest level from a block of 3 x 3 blocks: the block scaled by
        :attr:`scale` (in place with ``overwrite``, else a copy) and its values in
        :data:`FINE_VALUES` (into ``fine``, or a new twin where None)."""
        exact = A if overwrite else A.copy()
        exact.scale(self.scale)
        if fine is None:
            return exact.twin(exact, FINE_VALUES), exact
        fine.refresh(exact)
        return fine, exact

    @property
    def n_levels(self) -> int:
        """Number of levels of the hierarchy."""
        return len(self.ml.levels)

    def same_pattern(self, A: sp.spmatrix) -> bool:
        """True if ``A`` has the pattern of the block this hierarchy was built for, so
        that :meth:`refresh` may take its values."""
        return self.fine.same_pattern(A if isinstance(A, BlockSymmetricRows) else
                                      sp.csr_matrix(A))

    def refresh(self, A: sp.spmatrix, coarse: Optional[bool] = None,
                overwrite: bool = False) -> None:
        """Put new values of the block ``A`` (same size) into the hierarchy: the
        coarse matrices are the Galerkin products with the kept prolongators, the
        smoothers and the coarse solve are set up again. Cheaper than a new
        hierarchy (no strength, aggregation or prolongator smoothing) and exact
        for the new block on the finest level. The first prolongator's rows are
        rescaled with the new diagonal, so that the coarse space stays the same
        in the unscaled unknowns. ``coarse``: renew the coarse levels too (True), or the
        finest level alone (False: its scaling, products and smoother; the coarse levels
        keep the Galerkin products of an earlier block); None: the finest alone while
        the block's diagonal stays within :data:`COARSE_KEPT` of the one the coarse
        levels were made from. ``overwrite``: as in the constructor."""
        if isinstance(A, BlockSymmetricRows) and not self._blocks:
            A, overwrite = A.tocsr(), True          # (a CSR of its own)
        elif self._blocks and not isinstance(A, BlockSymmetricRows):
            A, overwrite = BlockSymmetricRows(sp.csr_matrix(A), self.exact_position), True
        elif not self._blocks:
            A = _own_csr(A, overwrite)  # (checked before the hierarchy is touched)
        scale = unit_scale(A)
        if coarse is None:
            coarse = 2.0 * float(np.abs(np.log(scale / self._coarse_scale)).max()) > \
                np.log(COARSE_KEPT)
        levels = self.ml.levels
        if len(levels) > 1:
            levels[0].P = sp.csr_matrix(sp.diags(self.scale / scale) @ levels[0].P)
            levels[0].R = levels[0].P.T.tocsr()
        self.exact = None                   # (the old values go before the new are made)
        self.scale = scale
        if self._blocks:
            self.fine, self.exact = self._scaled_blocks(A, overwrite, self.fine)
            if coarse:
                self._galerkin(first=galerkin_of_blocks(self.exact, levels[0].P,
                                                        levels[0].B.shape[1]))
                self._coarse_scale = scale
        else:
            levels[0].A = scaled_block(A, scale, overwrite=overwrite)
            if coarse:
                self._galerkin()
                self._coarse_scale = scale
            self.fine.refresh(levels[0].A)
            self.exact = self.fine.twin(levels[0].A)
        self._let_go_finest()
        self.coefficients = self._chebyshev()

    @property
    def exact_position(self) -> np.ndarray:
        """The unknowns' places in the 3D field (a hierarchy made from blocks)."""
        return self.fine.position

    def _let_go_finest(self) -> None:
        """Drop the finest level's CSR matrix once its triangles (:attr:`fine`,
        :attr:`exact`) are made: the cycle multiplies through them, and a refresh makes the
        matrix again for the Galerkin products. On a 3D plate step at 10,000 nodes that is
        110 MB (13.7 million entries). A hierarchy of one level keeps it for its coarse
        solve."""
        levels = self.ml.levels
        if len(levels) > 1:
            levels[0].A = None

    def release_values(self) -> None:
        """Let go of the finest level's values (single and double precision) until the
        next :meth:`refresh`, keeping what was found from the block's pattern: between
        the Picard iterations of a step they are dead weight while the next block is
        assembled (0.9 GB at 100,000 nodes in 3D). Products and cycles need the refresh
        first (``RuntimeError``). A hierarchy of one level keeps its block."""
        if len(self.ml.levels) > 1:
            self.fine.release_values()
            self.exact = None

    def _finest(self, single: bool):
        """The finest level's product, single or double precision (``RuntimeError`` if
        its values were let go)."""
        F = self.fine if single else self.exact
        if F is None or F.data is None:
            raise RuntimeError("ViscousAMG: the finest level's values were let go "
                               "(release_values); refresh the hierarchy first")
        return F

    def _galerkin(self, first=None) -> None:
        """The coarse matrices from the finest (the first of them ``first`` where given),
        their smoothers and the coarse solve."""
        import pyamg
        from pyamg.relaxation.smoothing import change_smoothers
        levels = self.ml.levels
        for k, (fine, coarse) in enumerate(zip(levels[:-1], levels[1:])):
            Ac = first if k == 0 and first is not None else fine.R @ fine.A @ fine.P
            coarse.A = Ac.tobsr(blocksize=coarse.A.blocksize) if sp.issparse(coarse.A) and \
                coarse.A.format == "bsr" else sp.csr_matrix(Ac)
        with seeded_global_random():
            change_smoothers(self.ml, [None, AMG_SMOOTHER], [None, AMG_SMOOTHER])
        polynomial_smoothers(self.ml, [None, AMG_SMOOTHER], [None, AMG_SMOOTHER])
        self.ml.coarse_solver = pyamg.coarse_grid_solver(AMG_COARSE_SOLVER)

    def _chebyshev(self) -> np.ndarray:
        """The finest level's Chebyshev coefficients (pyamg's form, the constant term
        dropped) on :data:`CHEBYSHEV_INTERVAL` times its estimated spectral radius."""
        from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
        rho = largest_eigenvalue(self.fine.matvec, self.fine.shape[0], seed=AMG_SEED)
        low, high = CHEBYSHEV_INTERVAL
        degree = AMG_SMOOTHER[1]["degree"]
        return -chebyshev_polynomial_coefficients(low * rho, high * rho, degree)[:-1]

    def _smooth(self, F, x, b: np.ndarray) -> np.ndarray:
        """One Chebyshev step with the finest (scaled) level's product ``F`` for ``x``
        (None: zero)."""
        c = self.coefficients
        r = b if x is None else b - F @ x
        h = c[0] * r
        for ck in c[1:]:
            h = ck * r + F @ h
        return h if x is None else x + h

    def scaled_cycle(self, b: np.ndarray, single: bool = False) -> np.ndarray:
        """One cycle from zero for the scaled block; ``single``: for a flexible outer
        method, with the finest level's products in single precision
        (:data:`FINE_VALUES`) and, with ``k_cycles``, a K-cycle below it. In double
        precision the cycle is a fixed symmetric map to round-off, as MINRES and conjugate
        gradients need; in single precision it is symmetric to about 1e-7."""
        levels = self.ml.levels
        if len(levels) == 1:
            return self.ml.coarse_solver(levels[0].A, b)
        F = self._finest(single)
        below = k_cycle if single and self.k_cycles else v_cycle
        x = self._smooth(F, None, b)
        x += levels[0].P @ below(self.ml, levels[0].R @ (b - F @ x), level=1)
        return self._smooth(F, x, b)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``A @ x`` in double precision through the scaled block's upper triangle,
        ``diag(1/s) (S (x / s))``: the outer Krylov method's product, 2-3 times faster than
        scipy's on one thread; it differs from it by rounding."""
        s = self.scale
        return (self._finest(False) @ (np.asarray(x, dtype=float) / s)) / s

    def cycle(self, r: np.ndarray) -> np.ndarray:
        """One V-cycle from zero for ``A x = r``."""
        s = self.scale
        return s * self.scaled_cycle(s * np.asarray(r, dtype=float).ravel())

    def cg(self, r: np.ndarray, steps: int) -> np.ndarray:
        """``steps`` V-cycle-preconditioned CG steps from zero for ``A x = r``
        (:func:`~skfem_nem.models.krylov.cg_steps` on the scaled block)."""
        s = self.scale
        return s * cg_steps(self._finest(True), lambda v: self.scaled_cycle(v, single=True), s * r,
                            steps)

    def preconditioner(self) -> spla.LinearOperator:
        """One V-cycle as a linear operator approximating ``A^-1``."""
        n = self.scale.size
        return spla.LinearOperator((n, n), matvec=self.cycle, dtype=float)


def _own_csr(A: sp.spmatrix, overwrite: bool) -> sp.csr_matrix:
    """``A`` as CSR; for ``overwrite``, ``A`` itself, which must be CSR in double
    precision (a conversion would write over a copy)."""
    if not overwrite:
        return sp.csr_matrix(A)
    if not (sp.issparse(A) and A.format == "csr" and A.dtype == np.float64):
        raise ValueError(f"overwrite=True needs a CSR matrix of float64 values, got "
                         f"{getattr(A, 'format', type(A).__name__)} of {A.dtype}")
    return A


def unit_scale(A: sp.spmatrix) -> np.ndarray:
    """``diag(A)^-1/2``, the scaling to a unit diagonal; ``RuntimeError`` if a diagonal
    entry is not positive, as none of a viscous block is."""
    d = A.diagonal()
    if not (d > 0).all():
        raise RuntimeError(f"the viscous block has {int((d <= 0).sum())} diagonal "
                           f"entries <= 0: check the viscosity")
    return 1.0 / np.sqrt(d)


def scaled_block(A: sp.spmatrix, s: np.ndarray, dtype=np.float64,
                 overwrite: bool = False) -> sp.spmatrix:
    """``diag(s) A diag(s)`` of a CSR or CSC matrix ``A``, in its format (the index
    arrays shared, not copied), with values of ``dtype`` (rounded from the products in
    double precision). Each value is ``(a_ij s_j) s_i`` in that order (CSR; for CSC
    i and j swap), in a threaded kernel: at 13 million entries (a 3D viscous block of
    10,000 nodes) 0.7 s in numpy's vectorised form, which every AMG refresh repeats.
    ``overwrite``: the values are written over A's own (double precision only), and A
    is the scaled block afterwards."""
    if overwrite:
        if np.dtype(dtype) != A.data.dtype:
            raise ValueError(f"scaled_block(overwrite=True) keeps A's {A.data.dtype} values, "
                             f"got dtype {np.dtype(dtype)}")
        data = A.data
    else:
        data = np.empty(A.data.shape[0], dtype=dtype)
    _scaled_values(A.indptr, A.indices, A.data, np.asarray(s, dtype=np.float64), data)
    return type(A)((data, A.indices, A.indptr), shape=A.shape)


@njit(cache=True, parallel=True)
def _scaled_values(indptr, indices, values, s, out):
    """``out[k] = values[k] s[indices[k]] s[row of k]`` row by row (outer index)."""
    for i in prange(indptr.shape[0] - 1):
        si = s[i]
        for k in range(indptr[i], indptr[i + 1]):
            out[k] = values[k] * s[indices[k]] * si
