"""Products with a symmetric matrix of a 3D vector field kept as its nodes' upper 3x3 blocks
(:class:`skfem_nem.models.block_rows.BlockSymmetricRows`), the positions that place a
basis's free dofs (:func:`~skfem_nem.models.block_rows.node_positions`), and the 3D
multigrid's finest level on them."""
import numpy as np
import pytest
import scipy.sparse as sps
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementTriP1, \
    ElementVector, MeshTet, MeshTri
from skfem.helpers import ddot, sym_grad

from skfem_nem.models.block_rows import BlockSymmetricRows, node_positions
from skfem_nem.models.stokes_amg import ViscousAMG


def _block_field(nodes, density, seed, fixed):
    """A random symmetric matrix of a 3-component field on ``nodes`` nodes (its entries in
    3x3 blocks, some structurally absent), restricted to the components left free after
    ``fixed`` random ones; and the positions of the free ones."""
    rng = np.random.default_rng(seed)
    G = sps.random(nodes, nodes, density=density, random_state=seed, format="csr")
    G = ((G + G.T + sps.identity(nodes)) != 0).astype(float)
    A = sps.csr_matrix(sps.kron(G, np.ones((3, 3))))
    A.data = rng.standard_normal(A.nnz)
    A = sps.csr_matrix(A + A.T + sps.diags(np.full(3 * nodes, 3.0 * nodes + 12.0)))
    keep = np.ones(A.shape[0], dtype=bool)
    keep[rng.choice(A.shape[0], min(fixed, A.shape[0] - 1), replace=False)] = False
    free = np.flatnonzero(keep)
    return sps.csr_matrix(A[free][:, free]), free


@settings(max_examples=40, deadline=None)
@given(nodes=st.integers(1, 40), density=st.floats(0.0, 0.3), seed=st.integers(0, 10_000),
       fixed=st.integers(0, 20))
def test_products_are_scipys(nodes, density, seed, fixed):
    A, free = _block_field(nodes, density, seed, fixed)
    x = np.random.default_rng(seed + 1).standard_normal(free.size)
    ref, scale = A @ x, (abs(A) @ abs(x)).max()
    S = BlockSymmetricRows(A, free)
    assert np.allclose(S @ x, ref, rtol=1e-13, atol=1e-13 * scale)
    assert np.array_equal(S @ x, S @ x)             # the same sums in the same order
    single = S.twin(A, np.float32)
    assert single.indices is S.indices               # the blocks found once
    assert np.allclose(single @ x, ref, rtol=1e-6, atol=1e-6 * scale)
    # the lower triangle is never read: the product is the one of the upper triangle's
    # symmetric matrix
    U = sps.triu(A, 1)
    lower_changed = sps.csr_matrix(U + sps.diags(A.diagonal()) + 2.0 * U.T)
    lower_changed.sort_indices()
    assert np.allclose(BlockSymmetricRows(lower_changed, free) @ x, ref, rtol=1e-13,
                       atol=1e-13 * scale)


def test_refresh_takes_new_values_and_new_blocks():
    A, free = _block_field(30, 0.15, 1, 7)
    S = BlockSymmetricRows(A, free)
    x = np.random.default_rng(2).standard_normal(free.size)
    C = A.copy()
    C.data = 2 * C.data                              # new values
    S.refresh(C)
    assert np.allclose(S @ x, C @ x, rtol=1e-13)
    blocks = S.indices.size
    fewer = A.tolil()
    fewer[0, 1] = fewer[1, 0] = 0.0                  # an entry less: still in its block
    fewer = sps.csr_matrix(fewer)
    fewer.eliminate_zeros()
    Sf = BlockSymmetricRows(A, free)
    Sf.refresh(fewer)
    assert Sf.indices.size == blocks and np.allclose(Sf @ x, fewer @ x, rtol=1e-13)
    # a coupling between two nodes that had none: a new block, found afresh
    i, j = next((i, j) for i in range(free.size) for j in range(free.size)
                if free[j] // 3 > free[i] // 3 and A[free == free[i]].nnz
                and not np.isin(free[j] // 3, free[A[i].indices] // 3))
    new = A.tolil()
    new[i, j] = new[j, i] = 1.0
    new = sps.csr_matrix(new)
    assert not S.same_pattern(new)
    S.refresh(new)
    assert S.indices.size == blocks + 1 and np.allclose(S @ x, new @ x, rtol=1e-13)
    assert not S.same_pattern(new.tocsc())


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"square matrix and a position per row, got shape "
                                         r"\(2, 3\)"):
        BlockSymmetricRows(sps.csr_matrix(np.ones((2, 3))), np.arange(2))
    with pytest.raises(ValueError, match="positions must be >= 0 and increase"):
        BlockSymmetricRows(sps.identity(3, format="csr"), np.array([0, 2, 1]))
    with pytest.raises(ValueError, match="float32 or float64 values, got"):
        BlockSymmetricRows(sps.identity(3, format="csr"), np.arange(3), np.int32)
    S = BlockSymmetricRows(sps.identity(4, format="csr"), np.array([0, 1, 4, 5]))
    with pytest.raises(ValueError, match=r"x of shape \(4,\), got \(3,\)"):
        S @ np.ones(3)
    with pytest.raises(ValueError, match="fits the same blocks"):
        S.twin(sps.csr_matrix(np.ones((4, 4))))
    S.release_values()
    with pytest.raises(RuntimeError, match="values were let go"):
        S @ np.ones(4)


def test_node_positions_place_the_nodal_dofs():
    m = MeshTet().refined(1)
    basis = Basis(m, ElementVector(ElementTetP1()))
    free = basis.complement_dofs(basis.get_dofs(lambda x: x[0] == 0).nodal["u^1"])
    pos = node_positions(basis, free)
    comp, node = np.nonzero(np.isin(basis.nodal_dofs, free))
    at = np.argsort(basis.nodal_dofs[comp, node])      # (free is sorted)
    assert np.array_equal(pos, 3 * node[at] + comp[at])
    assert node_positions(Basis(m, ElementVector(ElementTetP2())), free) is None
    tri = Basis(MeshTri(), ElementVector(ElementTriP1()))
    assert node_positions(tri, np.arange(tri.N)) is None


def test_the_3d_multigrid_on_blocks_is_the_one_on_entries():
    """The finest level on its nodes' blocks multiplies and cycles as the one on its
    entries (to rounding): an elasticity-like block on tetrahedra, one wall fixed."""
    m = MeshTet().refined(3)
    basis = Basis(m, ElementVector(ElementTetP1()))

    @BilinearForm
    def viscous(u, v, w):
        return 2.0 * (1.0 + w.x[0]) * ddot(sym_grad(u), sym_grad(v))

    K = viscous.assemble(basis)
    free = basis.complement_dofs(basis.get_dofs(lambda x: x[0] == 0.0))
    A = sps.csr_matrix(K[free][:, free])
    pos = node_positions(basis, free)
    modes = np.zeros((free.size, 3))
    modes[np.arange(free.size), pos % 3] = 1.0
    entries, blocks = ViscousAMG(A, modes), ViscousAMG(A, modes, positions=pos)
    assert isinstance(blocks.fine, BlockSymmetricRows)
    b = np.random.default_rng(4).standard_normal(free.size)
    assert np.allclose(blocks.matvec(b), A @ b, rtol=1e-12, atol=1e-12 * abs(A @ b).max())
    xe, xb = entries.cg(b, 4), blocks.cg(b, 4)
    assert np.linalg.norm(xb - xe) <= 1e-5 * np.linalg.norm(xe)
    assert np.linalg.norm(A @ xb - b) < 0.1 * np.linalg.norm(b)
    blocks.refresh(sps.csr_matrix(2.0 * A))
    assert np.allclose(blocks.matvec(b), 2.0 * (A @ b), rtol=1e-12,
                       atol=1e-12 * abs(A @ b).max())


def _from_blocks(A):
    """The blocks of a CSR matrix ``A`` on all unknowns of its nodes, made directly."""
    S = BlockSymmetricRows(A, np.arange(A.shape[0]))
    return BlockSymmetricRows.from_blocks(S.indptr, S.indices, S.data.copy(),
                                          np.arange(A.shape[0]))


@settings(max_examples=30, deadline=None)
@given(nodes=st.integers(1, 30), density=st.floats(0.0, 0.3), seed=st.integers(0, 10_000),
       fixed=st.integers(0, 20))
def test_blocks_made_directly_restrict_expand_and_scale(nodes, density, seed, fixed):
    """A matrix of blocks made directly (as the 3D viscous block is assembled): its product,
    diagonal and CSR on all unknowns and on the free ones are the matrix's, its chosen rows
    are the rows, and scaled in place it is ``scaled_block``'s upper triangle bit for bit."""
    from skfem_nem.models.stokes_amg import scaled_block, unit_scale
    A, _ = _block_field(nodes, density, seed, 0)
    B = _from_blocks(A)
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(A.shape[0])
    assert np.allclose(B @ x, A @ x, rtol=1e-13, atol=1e-13 * (abs(A) @ abs(x)).max())
    full = B.tocsr()
    assert full.has_sorted_indices and (full != A).nnz == 0
    rows = np.flatnonzero(rng.random(A.shape[0]) < 0.3)
    assert (B.tocsr(rows) != A[rows]).nnz == 0
    free = np.sort(rng.choice(A.shape[0], A.shape[0] - min(fixed, A.shape[0] - 1),
                              replace=False))
    R = B.restricted(free)
    Af = sps.csr_matrix(A[free][:, free])
    assert (R.tocsr() != Af).nnz == 0 and np.array_equal(R.diagonal(), Af.diagonal())
    assert np.allclose(R @ x[:free.size], Af @ x[:free.size], rtol=1e-13,
                       atol=1e-13 * (abs(Af) @ abs(x[:free.size])).max())
    s = unit_scale(Af)
    C = R.copy()
    C.scale(s)
    assert np.array_equal(R.data, B.data)               # (a copy was scaled)
    want = scaled_block(Af, s).toarray()
    got = C.tocsr().toarray()
    assert np.array_equal(np.triu(got), np.triu(want))
    assert np.allclose(got, want, rtol=1e-15, atol=0)


def test_blocks_made_directly_name_bad_input():
    A, _ = _block_field(5, 0.3, 1, 0)
    B = _from_blocks(A)
    with pytest.raises(ValueError, match="blocks need .* values, got"):
        BlockSymmetricRows.from_blocks(B.indptr, B.indices, B.data[:-1], np.arange(15))
    with pytest.raises(ValueError, match="position 15 is past the 15 components of 5 nodes"):
        BlockSymmetricRows.from_blocks(B.indptr, B.indices, B.data, np.arange(1, 16))
    with pytest.raises(ValueError, match="must be among the matrix's own"):
        B.restricted(np.arange(1, 16)).restricted(np.array([0]))
    with pytest.raises(ValueError, match="rows must be among the unknowns"):
        B.restricted(np.arange(1, 15)).tocsr(rows=np.array([0]))
    with pytest.raises(ValueError, match="on other unknowns"):
        B.restricted(np.arange(1, 15)).refresh(B)
    B.release_values()
    for call in (B.diagonal, B.tocsr, B.copy, lambda: B.scale(np.ones(15))):
        with pytest.raises(RuntimeError, match="values were let go"):
            call()


def test_the_multigrid_of_blocks_made_directly_is_the_one_of_their_csr():
    """``ViscousAMG`` of a block of 3 x 3 blocks (the 3D plate's, as assembled) cycles as
    the one of its CSR to rounding; made and refreshed over the blocks' own values it scales
    them in place and multiplies through them; a refresh that renews the coarse levels
    still gives a cycle that reduces the residual."""
    m = MeshTet().refined(3)
    basis = Basis(m, ElementVector(ElementTetP1()))

    @BilinearForm
    def viscous(u, v, w):
        return 2.0 * (1.0 + w.x[0]) * ddot(sym_grad(u), sym_grad(v))

    K = sps.csr_matrix(viscous.assemble(basis))
    K.sort_indices()
    free = basis.complement_dofs(basis.get_dofs(lambda x: x[0] == 0.0))
    A = sps.csr_matrix(K[free][:, free])
    pos = node_positions(basis, free)
    modes = np.zeros((free.size, 3))
    modes[np.arange(free.size), pos % 3] = 1.0
    blocks = _from_blocks(K).restricted(free)
    kept = blocks.copy()
    plain = {"smooth": None, "improve_candidates": None}     # (the 3D block's)
    entries = ViscousAMG(A, modes, positions=pos, **plain)
    over = ViscousAMG(blocks, modes, overwrite=True, **plain)
    assert over.exact is blocks and over.ml.levels[0].A is None
    assert not np.array_equal(blocks.data, kept.data)          # scaled in place
    b = np.random.default_rng(4).standard_normal(free.size)
    assert np.allclose(over.matvec(b), A @ b, rtol=1e-12, atol=1e-12 * abs(A @ b).max())
    assert np.linalg.norm(over.cg(b, 4) - entries.cg(b, 4)) <= 1e-5 * np.linalg.norm(
        entries.cg(b, 4))
    assert over.same_pattern(kept) and not over.same_pattern(A)
    twice = kept.copy()
    twice.data *= 2.0
    over.release_values()
    over.refresh(twice, coarse=False, overwrite=True)
    assert np.allclose(over.matvec(b), 2.0 * (A @ b), rtol=1e-12,
                       atol=1e-12 * abs(A @ b).max())
    ramp = kept.copy()
    ramp.scale(np.linspace(1.0, 3.0, free.size))
    over.refresh(ramp.copy(), coarse=True)
    entries.refresh(ramp.tocsr(), coarse=True)
    assert over.ml.levels[0].A is None
    for k in range(1, over.n_levels):      # the coarse levels made from the same block
        assert abs(over.ml.levels[k].A - entries.ml.levels[k].A).max() <= 1e-12 * abs(
            entries.ml.levels[k].A).max()
    x, y = over.cycle(b), entries.cycle(b)
    assert np.linalg.norm(x - y) <= 1e-10 * np.linalg.norm(y)
    assert np.linalg.norm(ramp.tocsr() @ x - b) < 0.6 * np.linalg.norm(b)
