"""Dof orders along a Hilbert curve and renumbered matrices (basis.locality), and the
two-level method that works in that order (basis.two_level): every dof once, a node's dofs
together with its edges' after them, renumbered matrices equal to scipy's fancy indexing,
the preconditioner symmetric across the renumbering, and a matrix that is not symmetric
refused by name."""
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import BilinearForm, ElementVector
from skfem.helpers import dot, grad

from skfem_nem import ElementNaturalNeighbour, ElementNaturalNeighbour2, NaturalNeighbourBasis
from skfem_nem import delaunay_mesh
from skfem_nem.basis.locality import dof_locality_order, inverse_order, renumbered
from skfem_nem.basis.symmetric_rows import SymmetricRows
from skfem_nem.basis.two_level import TwoLevelPreconditioner, TwoLevelSpace, nested_prolongation
from skfem_nem.geometry.nodesets import box_nodes, hilbert_order


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@settings(max_examples=15, deadline=None)
@given(n=st.integers(20, 300), seed=st.integers(0, 10 ** 6), vector=st.booleans(),
       quadratic=st.booleans(), cut=st.floats(0.0, 0.5))
def test_every_free_dof_once_each_node_with_its_edges(n, seed, vector, quadratic, cut):
    """A permutation of the free dofs (those with x >= cut: the Dirichlet dofs left out);
    along it the nodes come in Hilbert order, each node's components together, and an
    edge's dofs after its first node's and before the next node's."""
    mesh = delaunay_mesh(box_nodes(n, seed=seed))
    elem = ElementNaturalNeighbour2() if quadratic else ElementNaturalNeighbour()
    basis = NaturalNeighbourBasis(mesh, ElementVector(elem) if vector else elem)
    free = basis.get_dofs(lambda x: x[0] >= cut).all()
    order = dof_locality_order(basis, free)
    assert np.array_equal(np.sort(order), np.arange(free.size))
    rank = inverse_order(hilbert_order(mesh.p.T))
    nodal, facet = np.atleast_2d(basis.nodal_dofs), np.atleast_2d(basis.facet_dofs)
    owner = np.full(basis.N, -1)
    for c in range(nodal.shape[0]):
        owner[nodal[c]] = rank
    if quadratic:
        first = rank[mesh.facets].min(axis=0)
        for c in range(facet.shape[0]):
            owner[facet[c]] = first
    slots = owner[free[order]]
    assert (np.diff(slots) >= 0).all()                   # node by node, along the curve
    is_nodal = np.isin(free[order], nodal)
    for s in np.unique(slots):                           # a node's own dofs come first
        kinds = is_nodal[slots == s]
        assert not np.any(np.diff(kinds.astype(int)) > 0), kinds


def test_tetrahedra_are_ordered_along_a_z_curve():
    """On tetrahedra the nodes are taken along a Z-order curve, components together."""
    from skfem_nem.geometry import box_nodes_3d
    from skfem_nem.geometry.nodesets import morton_order
    mesh = delaunay_mesh(box_nodes_3d(300, seed=2))
    basis = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    free = basis.get_dofs(lambda x: x[2] > 1e-12).all()
    order = dof_locality_order(basis, free)
    assert np.array_equal(np.sort(order), np.arange(free.size))
    rank = inverse_order(morton_order(mesh.p.T))
    node = np.empty(basis.N, np.int64)
    for c in range(3):
        node[basis.nodal_dofs[c]] = np.arange(mesh.p.shape[1])
    assert (np.diff(rank[node[free[order]]]) >= 0).all()


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 60), density=st.floats(0.05, 0.6), seed=st.integers(0, 10 ** 6),
       sort=st.booleans(), part=st.floats(0.1, 1.0))
def test_renumbered_is_scipys_fancy_indexing(n, density, seed, sort, part):
    """The rows ``order[:k]`` of the renumbered matrix are ``A[order][:, order][:k]``,
    sorted or not."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng, format="csr")
    order = rng.permutation(n)
    k = max(1, int(part * n))
    got = renumbered(A, order[:k], inverse_order(order), sort=sort)
    want = A[order][:, order][:k]
    assert got.shape == want.shape and abs(got - want).max() == 0
    if sort:
        assert all((np.diff(got.indices[got.indptr[i]:got.indptr[i + 1]]) > 0).all()
                   for i in range(k))


@pytest.fixture(scope="module")
def quadratic():
    basis = NaturalNeighbourBasis(delaunay_mesh(box_nodes(300, seed=4)),
                                  ElementNaturalNeighbour2())
    free = basis.complement_dofs(basis.get_dofs().all())
    return basis, free, laplace.assemble(basis)[free][:, free].tocsr()


def test_the_renumbered_preconditioner_is_symmetric_in_the_callers_order(quadratic):
    """Built on a space's locality order, the V-cycle preconditioner answers in the
    caller's order and is symmetric there, and its products are the matrix's own on the
    upper triangle."""
    basis, free, A = quadratic
    M = TwoLevelSpace(basis, free).preconditioner(A)
    assert M.order is not None and not np.array_equal(M.order, np.arange(free.size))
    assert isinstance(M.A, SymmetricRows)
    a, c = np.random.default_rng(1).normal(size=(2, free.size))
    assert abs(M(a) @ c - a @ M(c)) < 1e-10 * abs(M(a) @ c)
    x = np.random.default_rng(2).normal(size=free.size)
    assert np.allclose(M.A @ x[M.order], (A @ x)[M.order], rtol=1e-12, atol=1e-12)


def test_a_matrix_not_symmetric_is_refused(quadratic):
    """The products read the upper triangle only: a matrix whose lower triangle differs
    is refused, naming the cause, and the caller's matrix is left as it was."""
    basis, free, A = quadratic
    skew = A + 1e-3 * sp.triu(A, 1)
    before = skew.copy()
    P = nested_prolongation(basis)[free][:, np.isin(basis.nodal_dofs[0], free)]
    with pytest.raises(ValueError, match="not symmetric"):
        TwoLevelPreconditioner(skew, P)
    assert abs(skew - before).max() == 0
    with pytest.raises(ValueError, match="order must number"):
        TwoLevelPreconditioner(A, P, order=np.arange(3))


@pytest.mark.parametrize("walls", [0, 1, 2])
def test_a_vector_coarse_level_comes_in_whole_nodes(walls):
    """The coarse unknowns of a vector basis clamped at x = 1: the nodes with both components
    free first, a node's two together, then the single free components of the wall nodes
    (x fixed on x = 0 with ``walls`` 1 or 2, y on y = 0 with 2). Blocks of two where the
    wall unknowns are even in number, else none (``walls`` 2: the corner's node is fixed
    whole); either way the V-cycle preconditioner is symmetric."""
    mesh = delaunay_mesh(box_nodes(200, seed=5))
    basis = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()))
    fixed = [basis.get_dofs(lambda x: x[0] > 1 - 1e-12).all()]      # clamped: whole nodes
    if walls >= 1:
        fixed.append(basis.get_dofs(lambda x: x[0] < 1e-12).nodal["u^1"])
    if walls == 2:
        fixed.append(basis.get_dofs(lambda x: x[1] < 1e-12).nodal["u^2"])
    D = np.unique(np.concatenate(fixed))
    free = np.setdiff1d(np.arange(basis.N), D)
    space = TwoLevelSpace(basis, free)
    nodal = basis.nodal_dofs
    node_of = np.full(basis.N, -1)
    node_of[nodal[0]] = node_of[nodal[1]] = np.arange(nodal.shape[1])
    # the coarse unknowns are the prolongation's columns: each copies one nodal dof (its
    # entry 1; the edge dofs get 1/2)
    P = space.prolongation.tocoo()
    ones = P.data == 1.0
    assert np.array_equal(np.sort(P.col[ones]), np.arange(P.shape[1]))
    copied = np.empty(P.shape[1], np.int64)
    copied[P.col[ones]] = free[space.order][P.row[ones]]
    nodes = node_of[copied]
    counts = np.bincount(nodes)[nodes]
    k = np.count_nonzero(counts == 2)
    assert (counts[:k] == 2).all() and (counts[k:] == 1).all()
    assert (nodes[:k:2] == nodes[1:k:2]).all()
    expect = 2 if (P.shape[1] - k) % 2 == 0 else 1
    assert space.blocksize == expect
    assert walls == 0 or P.shape[1] > k                    # wall unknowns exist
    A = linear_elasticity_matrix(basis)[free][:, free].tocsr()
    M = space.preconditioner(A)
    assert M.blocksize == expect
    a, c = np.random.default_rng(1).normal(size=(2, free.size))
    assert abs(M(a) @ c - a @ M(c)) < 1e-9 * abs(M(a) @ c)


def linear_elasticity_matrix(basis):
    from skfem.models.elasticity import linear_elasticity
    return linear_elasticity(1.0, 0.3).assemble(basis)
