"""The 3D viscous block's first multigrid level made from its 3 x 3 node blocks
(:mod:`skfem_nem.models.amg_blocks`): the hierarchy pyamg makes from the CSR block, without
that block."""
import numpy as np
import pytest
import scipy.sparse as sps
from skfem import Basis, BilinearForm, ElementTetP1, ElementVector, MeshTet
from skfem.helpers import ddot, sym_grad

import skfem_nem.models.amg_blocks as amg_blocks
from skfem_nem.models.block_rows import BlockSymmetricRows
from skfem_nem.models.stokes_amg import (AMG_COARSE_SOLVER, AMG_SMOOTHER,
                                         AMG_STRENGTH, scaled_block, seeded_global_random,
                                         unit_scale)

PLAIN = {"smooth": None, "improve_candidates": None}


def _scaled_block():
    """A scaled viscous block on tetrahedra (viscosity ramp, one wall fixed) as CSR and as
    blocks, and its rigid translations scaled alike."""
    m = MeshTet().refined(3)
    basis = Basis(m, ElementVector(ElementTetP1()))

    @BilinearForm
    def viscous(u, v, w):
        return 2.0 * (1.0 + 9.0 * w.x[0]) * ddot(sym_grad(u), sym_grad(v))

    K = sps.csr_matrix(viscous.assemble(basis))
    K.sort_indices()
    free = basis.complement_dofs(basis.get_dofs(lambda x: x[0] == 0.0))
    whole = BlockSymmetricRows(K, np.arange(K.shape[0]))
    blocks = BlockSymmetricRows.from_blocks(whole.indptr, whole.indices, whole.data.copy(),
                                            np.arange(K.shape[0])).restricted(free)
    s = unit_scale(blocks)
    blocks.scale(s)
    modes = np.zeros((free.size, 3))
    modes[np.arange(free.size), free % 3] = 1.0
    return scaled_block(sps.csr_matrix(K[free][:, free]), s), blocks, modes / s[:, None]


def test_the_hierarchy_is_pyamgs_from_the_csr_block(monkeypatch):
    """Same levels, aggregates and prolongators as pyamg's from the CSR block, coarse
    matrices to rounding, with the Galerkin product taken in several slices."""
    import pyamg
    A, blocks, B = _scaled_block()
    monkeypatch.setattr(amg_blocks, "GALERKIN_SLICE", 20_000)       # some ten slices
    options = dict(max_coarse=4, presmoother=AMG_SMOOTHER,
                   postsmoother=AMG_SMOOTHER, **PLAIN)
    with seeded_global_random():
        ref = pyamg.smoothed_aggregation_solver(
            A, B=B, symmetry="symmetric", strength=AMG_STRENGTH,
            coarse_solver=AMG_COARSE_SOLVER, **options)
    with seeded_global_random():
        got = amg_blocks.hierarchy_of_blocks(blocks, B, AMG_STRENGTH, AMG_COARSE_SOLVER,
                                             **options)
    assert len(got.levels) >= 3 and got.levels[0].A is None
    assert (abs(got.levels[0].P - ref.levels[0].P) > 0).nnz == 0
    g, r = got.levels[1].A, ref.levels[1].A
    assert g.format == r.format and g.blocksize == r.blocksize and g.has_sorted_indices
    assert abs(g - r).max() <= 1e-13 * abs(r).max()
    # the levels below may aggregate otherwise (pyamg's order of the blocks): a cycle
    # reduces the error as much
    rng = np.random.default_rng(0)
    x = rng.standard_normal(A.shape[0])
    b = A @ x
    got.levels[0].A = A         # (and the finest smoothing of pyamg's, made for A)
    got.levels[0].presmoother = ref.levels[0].presmoother
    got.levels[0].postsmoother = ref.levels[0].postsmoother
    err = [np.linalg.norm(ml.solve(b, maxiter=3, tol=1e-30) - x) for ml in (got, ref)]
    assert err[0] <= 1.2 * err[1] and err[1] < 0.5 * np.linalg.norm(x), err


def test_another_first_level_is_refused_by_name():
    _, blocks, B = _scaled_block()
    with pytest.raises(ValueError, match="symmetric strength and plain aggregation"):
        amg_blocks.hierarchy_of_blocks(blocks, B, ("classical", {"theta": 0.25}),
                                       AMG_COARSE_SOLVER, **PLAIN)
    with pytest.raises(ValueError, match="smooth=None, improve_candidates=None"):
        amg_blocks.hierarchy_of_blocks(blocks, B, AMG_STRENGTH, AMG_COARSE_SOLVER,
                                       smooth="jacobi", improve_candidates=None)
    assert not amg_blocks.plain_aggregation({"smooth": None})


def test_the_galerkin_product_of_aggregates_is_the_sliced_product():
    """The kernel's ``T^T A T`` is scipy's product of the block's rows: for pyamg's
    tentative prolongator (BSR), the same rescaled as a refresh does (CSR, width given),
    one with rows in no aggregate; and a prolongator not of aggregates takes scipy's."""
    from pyamg.aggregation import fit_candidates, standard_aggregation
    A, blocks, B = _scaled_block()
    B = np.hstack([B, np.random.default_rng(1).standard_normal((B.shape[0], 3))])
    aggregates, _ = standard_aggregation(blocks.strong(AMG_STRENGTH[1]["theta"]))
    T, _ = fit_candidates(aggregates, B)
    dense = A.toarray()

    def check(P, width=None):
        got = amg_blocks.galerkin_of_blocks(blocks, P, width)
        want = sps.csr_matrix(P).T @ dense @ sps.csr_matrix(P).toarray()
        k = width or P.blocksize[1]
        assert got.format == "bsr" and got.blocksize == (k, k) and got.has_sorted_indices
        assert abs(got.toarray() - want).max() <= 1e-13 * abs(want).max()
        sliced = amg_blocks._galerkin_by_slices(blocks, P, k)
        assert abs(got - sliced).max() <= 1e-13 * abs(sliced).max()
        return got

    check(T)
    s = np.random.default_rng(2).uniform(0.5, 2.0, T.shape[0])
    check(sps.csr_matrix(sps.diags(s) @ T), width=6)
    some = sps.csr_matrix(T)
    some = sps.csr_matrix(sps.diags((np.arange(T.shape[0]) % 7 != 0).astype(float)) @ some)
    some.eliminate_zeros()
    check(some, width=6)
    assert amg_blocks._aggregate_rows(sps.csr_matrix(some), 6) is not None
    mixed = sps.csr_matrix(T) + sps.csr_matrix(
        (np.ones(3), ([0, 1, 2], [T.shape[1] - 1] * 3)), shape=T.shape)
    assert amg_blocks._aggregate_rows(mixed, 6) is None
    check(mixed, width=6)
