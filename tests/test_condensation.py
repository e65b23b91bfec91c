"""The Stokes bubbles condensed triangle by triangle into the viscous block."""
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import square_nodes
from skfem_nem import delaunay_mesh
from skfem_nem.models.condensation import condensed_divergence, condensed_viscous
from skfem_nem.models.stokes import viscous, weak_divergence
from skfem_nem.models.stokes_bases import stokes_spaces


def _spaces(n, seed, **kw):
    return stokes_spaces(delaunay_mesh(square_nodes(n, seed=seed, jitter=0.3)), **kw)


def _reference(spaces, eta):
    """The condensation by global sparse products of scikit-fem assemblies."""
    ub, bb = spaces.ubasis, spaces.bubbles.vector_basis()
    A = viscous.assemble(ub, eta=eta).tocsr()
    Abb = viscous.assemble(bb, eta=eta).toarray()
    Abn = viscous.assemble(ub, bb, eta=eta).tocsr()
    d = bb.element_dofs
    Ainv = np.zeros_like(Abb)
    for e in range(d.shape[1]):
        Ainv[np.ix_(d[:, e], d[:, e])] = np.linalg.inv(Abb[np.ix_(d[:, e], d[:, e])])
    Ainv = sp.csr_matrix(Ainv)
    AiAbn = Ainv @ Abn
    return (A - Abn.T @ AiAbn).tocsr(), Ainv, AiAbn


def _relative(X, Y):
    return abs(X - Y).max() / abs(Y).max()


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10**6), st.sampled_from([None, 3]))
def test_condensed_block_is_the_global_products_and_exactly_symmetric(seed, npoints):
    spaces = _spaces(120, seed, npoints=npoints)
    eta = np.exp(np.random.default_rng(seed).normal(0.0, 2.0, spaces.ubasis.dx.shape))
    cv = condensed_viscous(spaces.ubasis, spaces.bubbles, eta)
    A, Ainv, AiAbn = _reference(spaces, eta)
    assert _relative(cv.A, A) < 1e-13
    assert _relative(cv.Ainv, Ainv) < 1e-13
    assert _relative(cv.AiAbn, AiAbn) < 1e-13
    assert (cv.A != cv.A.T).nnz == 0                    # bitwise, not to rounding
    assert cv.A.has_canonical_format
    B = condensed_divergence(spaces.ubasis, spaces.pbasis, spaces.bubbles, cv)
    Bb = weak_divergence.assemble(spaces.bubbles.vector_basis(), spaces.pbasis).tocsr()
    Bref = weak_divergence.assemble(spaces.ubasis, spaces.pbasis).tocsr() - Bb @ AiAbn
    assert _relative(B, Bref) < 1e-13 and B.has_canonical_format


def test_condensation_on_part_of_the_triangles_adds_up():
    spaces = _spaces(150, 3)
    eta = np.exp(np.random.default_rng(3).normal(0.0, 1.0, spaces.ubasis.dx.shape))
    ne = spaces.mesh.nelements
    parts = [np.arange(0, ne, 2), np.arange(1, ne, 2)]
    whole = condensed_viscous(spaces.ubasis, spaces.bubbles, eta)
    A = AiAbn = B = 0
    for idx in parts:
        sub = spaces.restricted(idx)
        cv = condensed_viscous(sub.ubasis, sub.bubbles, eta[idx])
        A, AiAbn = A + cv.A, AiAbn + cv.AiAbn
        B = B + condensed_divergence(sub.ubasis, sub.pbasis, sub.bubbles, cv)
    assert _relative(A, whole.A) < 1e-13
    assert _relative(AiAbn, whole.AiAbn) < 1e-14
    wholeB = condensed_divergence(spaces.ubasis, spaces.pbasis, spaces.bubbles, whole)
    assert _relative(B, wholeB) < 1e-13


def test_a_singular_bubble_block_is_named():
    spaces = _spaces(80, 1)
    eta = np.ones(spaces.ubasis.dx.shape)
    eta[7] = 0.0
    with pytest.raises(ValueError, match="degenerate triangle 7: its bubble block is "
                                         r"singular \(1 triangle"):
        condensed_viscous(spaces.ubasis, spaces.bubbles, eta)


def test_condensed_tet_divergence_is_the_sparse_product():
    """On tetrahedra the bubbles' part of the divergence block is added row by row
    (``TetDivergence``): the same block as ``B_n - B_b A_bb^-1 A_bn`` by sparse products,
    for a first viscosity (the pattern found) and a second (the pattern kept)."""
    from skfem_nem.geometry.nodesets3d import box_nodes_3d
    from skfem_nem.models.condensation_tet import TetDivergence, condensed_viscous_tet
    from skfem_nem.models.stokes import _blocks_once
    spaces = stokes_spaces(delaunay_mesh(box_nodes_3d(300, seed=2)))
    cache = _blocks_once(spaces)
    td = cache["tet_divergence"]
    assert isinstance(td, TetDivergence)
    Bn = sp.csr_matrix((td.Bn[2], td.Bn[1], td.Bn[0]), shape=td.shape)
    ne, nq = spaces.ubasis.dx.shape
    rng = np.random.default_rng(0)
    for _ in range(2):
        cv = condensed_viscous_tet(spaces.ubasis, spaces.bubbles,
                                   np.exp(rng.standard_normal((ne, nq))))
        ref = (Bn - cache["Bb"] @ cv.AiAbn.tocsr()).tocsr()
        got = td.condensed(cv)
        assert got.has_sorted_indices
        assert abs(got - ref).max() <= 1e-14 * abs(ref).max()
    M = cv.AiAbn
    other = type(M)(M.ptr, M.sten[::-1].copy(), M.G, M.g, M.Q, M.shape[1])
    with pytest.raises(ValueError, match="another pattern"):
        td.condensed(type(cv)(cv.A, cv.Ainv, other, None))


def test_the_tetrahedra_bubbles_coupling_is_an_operator_of_its_entries():
    """``A_bb^-1 A_bn`` on tetrahedra is never stored (``TetCoupling``): its products and
    its transpose's are those of its entries (``tocsr``), on all threads and on one; a
    vector of the wrong length is named."""
    from skfem_nem.geometry.nodesets3d import box_nodes_3d
    from skfem_nem.models.condensation_tet import condensed_viscous_tet
    from skfem_nem.models.coupling_tet import TetCoupling
    spaces = stokes_spaces(delaunay_mesh(box_nodes_3d(300, seed=2)))
    ne, nq = spaces.ubasis.dx.shape
    rng = np.random.default_rng(1)
    M = condensed_viscous_tet(spaces.ubasis, spaces.bubbles,
                              np.exp(rng.standard_normal((ne, nq)))).AiAbn
    assert isinstance(M, TetCoupling) and M.shape == (3 * ne, spaces.ubasis.N)
    C = M.tocsr()
    assert C.nnz == 9 * M.ptr[-1]
    u, y = rng.standard_normal(M.shape[1]), rng.standard_normal(M.shape[0])
    ref, ref_t = C @ u, C.T @ y
    serial = TetCoupling(M.ptr, M.sten, M.G, M.g, M.Q, M.shape[1], parallel=False)
    for op in (M, serial):
        assert np.abs(op @ u - ref).max() <= 1e-13 * np.abs(ref).max()
        assert np.abs(op.T @ y - ref_t).max() <= 1e-13 * np.abs(ref_t).max()
    with pytest.raises(ValueError, match=rf"TetCoupling @ u needs u of shape \({M.shape[1]},"):
        M @ u[:-1]
    with pytest.raises(ValueError, match=rf"TetCoupling.T @ y needs y of shape \({M.shape[0]},"):
        M.T @ u


def test_the_tetrahedra_block_as_upper_blocks_is_the_csr_block_bit_for_bit():
    """``condensed_viscous_tet(..., blocks=True)`` makes the nodes' upper 3 x 3 blocks only
    (half the entries), each value as the CSR block's, bit for bit: expanded again it is
    the CSR block with its pattern, on all threads and on one."""
    import skfem_nem.models.condensation_tet as ct
    from skfem_nem.geometry.nodesets3d import box_nodes_3d
    from skfem_nem.models.block_rows import BlockSymmetricRows
    spaces = stokes_spaces(delaunay_mesh(box_nodes_3d(300, seed=2)))
    ne, nq = spaces.ubasis.dx.shape
    eta = np.exp(np.random.default_rng(2).standard_normal((ne, nq)))
    csr = ct.condensed_viscous_tet(spaces.ubasis, spaces.bubbles, eta).A
    up = ct.condensed_viscous_tet(spaces.ubasis, spaces.bubbles, eta, blocks=True).A
    assert isinstance(up, BlockSymmetricRows) and up.shape == csr.shape
    assert up.nnz < 0.6 * csr.nnz
    again = up.tocsr()
    assert np.array_equal(again.indptr, csr.indptr)
    assert np.array_equal(again.indices, csr.indices)
    assert np.array_equal(again.data, csr.data)
    G = np.ascontiguousarray(ct.stencil_gradients(spaces.ubasis, False)).reshape(-1)
    Wsum, gsum, det = np.empty(ne), np.empty((ne, 3)), np.empty(ne)
    Ainv = np.zeros((ne, 3, 3))
    ct._tet_blocks_serial(spaces.ubasis.stencil_ptr, nq, np.ascontiguousarray(
        eta * spaces.ubasis.dx), spaces.bubbles.gradient(), Wsum, gsum, Ainv, det)
    serial = ct._summed_tet(spaces.ubasis, G, Wsum, gsum, Ainv, False, True)
    assert np.array_equal(serial.data, up.data)
