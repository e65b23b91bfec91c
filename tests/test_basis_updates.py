"""Local updates of a natural-neighbour basis: after flips, injection and moved nodes, the
updated basis equals a rebuilt one to round-off and recomputes only some triangles."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from skfem import BilinearForm, MeshTri
from skfem.helpers import dot, grad

from helpers import square_nodes
from skfem_nem import LagrangianMesh, NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.basis.updates import updated_matrix

TOL = 1e-12  # round-off: the recomputed rows may add the same terms in another order


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


def local_vortex(x, centre=(0.5, 0.5), radius=0.2):
    """A rotation whose angular speed falls to zero at ``radius``: divergence-free, and
    the nodes outside the disc stand still."""
    dx, dy = x[:, 0] - centre[0], x[:, 1] - centre[1]
    s = np.clip(1.0 - np.hypot(dx, dy) / radius, 0.0, None) ** 2
    return np.c_[-dy * s, dx * s]


def assert_same_functions(b, ref):
    """Values, gradients and the stiffness matrix of two bases on one mesh agree."""
    V, R = b.values_matrix, ref.values_matrix
    assert V.shape == R.shape
    np.testing.assert_array_equal(V.indptr, R.indptr)
    np.testing.assert_array_equal(V.indices, R.indices)
    assert np.abs(V.data - R.data).max() <= TOL
    # gradients scale with 1 / h
    assert np.abs(b.gradient_entries - ref.gradient_entries).max() <= TOL * 100
    np.testing.assert_array_equal(b.stencil_ptr, ref.stencil_ptr)
    np.testing.assert_array_equal(b.stencil_nodes, ref.stencil_nodes)
    A, B = laplace.assemble(b), laplace.assemble(ref)
    assert abs(A - B).max() <= TOL * 100 * abs(B).max()


@pytest.mark.parametrize("integration", ["smoothed", "gauss"])
def test_vortex_flow_updates_equal_rebuilt_bases(integration):
    lm = LagrangianMesh(square_nodes(700, 14, seed=3))
    lm.basis(integration=integration)
    reports, steps = [], []
    for _ in range(25):
        steps.append(lm.advance(local_vortex, 0.25, inject=1.3))
        b = lm.basis(integration=integration)
        rule = {"npoints": 3} if integration == "gauss" else {}
        assert_same_functions(b, NaturalNeighbourBasis(lm.mesh, **rule))
        reports.append(b.update_report)
    recomputed = np.array([r["recomputed"] for r in reports])
    kept = np.array([r["kept"] for r in reports])
    assert sum(s["flips"] for s in steps) > 50 and sum(s["injected"] for s in steps) > 0
    # the nodes outside the vortex stand still: their triangles keep their functions
    assert (recomputed > 0).all() and (kept > recomputed).all()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(10, 80), st.floats(0.02, 0.4), st.booleans())
def test_random_local_moves(seed, n, size, interface):
    """Some interior nodes moved by up to ``size`` of the mean spacing (flips follow), and
    nodes injected, with or without a line of segments: the update equals the rebuilt
    basis."""
    rng = np.random.default_rng(seed)
    P = square_nodes(n, 5, seed=seed, margin=0.05)
    segments = None
    if interface:
        P, segments = line_of_nodes(P, 0.5, 6)
    lm = LagrangianMesh(P, segments=segments)
    old = lm.basis()
    P = lm.nodes
    d = np.zeros_like(P)
    inside = np.flatnonzero(((P > 0) & (P < 1)).all(axis=1))
    moved = rng.choice(inside, size=max(1, inside.size // 5), replace=False)
    d[moved] = size / np.sqrt(n) * (rng.random((moved.size, 2)) - 0.5)
    lm.advance(lambda x: d, 1.0)
    lm.inject_nodes(1.0 + rng.random())
    new = old.updated(lm.mesh)
    assert_same_functions(new, NaturalNeighbourBasis(lm.mesh))
    assert new.update_report["recomputed"] + new.update_report["kept"] == lm.mesh.nelements


def test_unchanged_mesh_recomputes_nothing():
    mesh = delaunay_mesh(square_nodes(100, 6, seed=1))
    b = NaturalNeighbourBasis(mesh)
    same = MeshTri(mesh.p.copy(), mesh.t.copy(), sort_t=False)
    u = b.updated(same)
    assert (u.update_report["recomputed"], u.update_report["kept"]) == (0, mesh.nelements)
    assert_same_functions(u, b)


def test_what_cannot_be_updated_is_named():
    P = square_nodes(60, 5, seed=2)
    mesh = delaunay_mesh(P)
    cases = [(NaturalNeighbourBasis(mesh, elements=np.arange(10)), mesh,
              "all of its mesh's triangles"),
             (NaturalNeighbourBasis(mesh, method="lasserre"), mesh, "area method"),
             (NaturalNeighbourBasis(mesh), MeshTri.init_lshaped().refined(2),
              "the new mesh is not its own")]
    for basis, target, words in cases:
        assert words in basis.update_obstacle(target)
        with pytest.raises(ValueError, match=words):
            basis.updated(target)
    # a mesh whose triangles are not Delaunay gets its own triangulation: not updatable
    b = NaturalNeighbourBasis(mesh)
    skew = MeshTri(mesh.p, mesh.t[[1, 2, 0]], sort_t=False)
    assert b.update_obstacle(skew) is None  # a vertex rotation keeps the triangles
    refined = mesh.refined()
    assert "not its own" in b.update_obstacle(refined)


def line_of_nodes(P, y, k):
    """P with k nodes added on the line at height y, and the segments joining them."""
    x = np.linspace(0.05, 0.95, k)
    nodes = np.r_[P[np.abs(P[:, 1] - y) > 0.02], np.c_[x, np.full(k, y)]]
    first = nodes.shape[0] - k
    return nodes, np.c_[np.arange(first, first + k - 1), np.arange(first + 1, first + k)]


def test_vortex_across_an_interface_updates_the_constrained_basis():
    """Segments through the stirred disc: they move, stretch and are split (injection);
    every updated constrained basis equals the rebuilt one."""
    P, segments = line_of_nodes(square_nodes(600, 12, seed=4), 0.52, 25)
    lm = LagrangianMesh(P, segments=segments)
    lm.basis()
    recomputed = []
    for _ in range(15):
        lm.advance(local_vortex, 0.25, inject=1.3)
        b = lm.basis()
        assert_same_functions(b, NaturalNeighbourBasis(lm.mesh))
        recomputed.append(b.update_report["recomputed"] / b.nelems)
    assert lm.triangulation.segments.shape[0] > segments.shape[0]   # segments were split
    assert max(recomputed) < 0.5


def test_vortex_flow_updated_matrices_equal_assembled_ones():
    """Laplace and elasticity matrices carried through 20 steps by replacing the
    recomputed triangles' contributions only."""
    from skfem import ElementVector
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    from skfem_nem import ElementNaturalNeighbour
    elasticity = linear_elasticity(*lame_parameters(1e3, 0.3))
    lm = LagrangianMesh(square_nodes(500, 12, seed=5))
    vec = ElementVector(ElementNaturalNeighbour())
    b, v = lm.basis(), lm.basis(vec)
    A, K = laplace.assemble(b), elasticity.assemble(v)
    for _ in range(20):
        lm.advance(local_vortex, 0.25, inject=1.3)
        b_new, v_new = lm.basis(), lm.basis(vec)
        A, K = updated_matrix(laplace, A, b, b_new), updated_matrix(elasticity, K, v, v_new)
        b, v = b_new, v_new
        for M, form, basis in ((A, laplace, b), (K, elasticity, v)):
            ref = form.assemble(basis)
            assert M.shape == ref.shape
            assert abs(M - ref).max() <= TOL * abs(ref).max()
    assert lm.triangulation.npoints > 500 + 4 + 4 * 11  # nodes were injected


def test_updated_matrix_needs_an_update():
    mesh = delaunay_mesh(square_nodes(40, 5, seed=6))
    b = NaturalNeighbourBasis(mesh)
    A = laplace.assemble(b)
    with pytest.raises(ValueError, match="not an update"):
        updated_matrix(laplace, A, b, NaturalNeighbourBasis(mesh))
    with pytest.raises(ValueError, match="A has shape"):
        updated_matrix(laplace, A[:5, :5], b, b.updated(mesh))
    other = NaturalNeighbourBasis(mesh)
    with pytest.raises(ValueError, match="an update of another basis"):
        updated_matrix(laplace, A, other, b.updated(mesh))
    with pytest.raises(ValueError, match="subset\\(\\) of a subdomain basis"):
        b.subset([1, 2]).subset([1])


def test_an_edge_made_a_segment_is_a_change():
    """The same triangles with an interior edge path made segments: the triangles along
    it change their functions (the walks no longer cross it), though none changed."""
    from skfem_nem import Triangulation
    from skfem_nem.geometry.meshes import triangulation_mesh
    tri = Triangulation(square_nodes(150, 8, seed=7))
    mesh = triangulation_mesh(Triangulation.from_arrays(tri.nodes, tri.triangles,
                                                        tri.neighbours))
    edges = tri.edges
    inner = edges[(tri.nodes[edges] % 1.0 != 0).all(axis=(1, 2))][:6]   # off the walls
    constrained = triangulation_mesh(Triangulation.from_arrays(
        tri.nodes, tri.triangles, tri.neighbours, inner))
    np.testing.assert_array_equal(constrained.t, mesh.t)
    b = NaturalNeighbourBasis(mesh).updated(constrained)
    ref = NaturalNeighbourBasis(constrained)
    assert b.update_report["recomputed"] > 0
    assert abs(ref.values_matrix - NaturalNeighbourBasis(mesh).values_matrix).max() > 1e-3
    assert_same_functions(b, ref)
