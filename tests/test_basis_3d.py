"""NaturalNeighbourBasis on Delaunay tetrahedra (MeshTet): the scikit-fem workflow in 3D."""

import numpy as np
import pytest
from skfem import (Basis, BilinearForm, ElementTetP1, ElementVector, FacetBasis, Functional,
                   LinearForm, MeshTet, asm, condense, solve)
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity
from scipy.spatial import Delaunay

from skfem_nem import (ElementNaturalNeighbour, ElementTetNaturalNeighbour, NaturalNeighbourBasis,
                       NaturalNeighbourFacetBasis, delaunay_mesh, sibson_coordinates)

from helpers import cube_nodes, laplace, mass


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(cube_nodes())


@pytest.fixture(scope="module")
def basis(mesh):
    return NaturalNeighbourBasis(mesh)


def test_delaunay_mesh_keeps_every_node(mesh):
    p = cube_nodes()
    assert isinstance(mesh, MeshTet)
    np.testing.assert_array_equal(mesh.p.T, p)
    assert np.unique(mesh.t).size == p.shape[0]
    vol = Functional(lambda w: 1.0 + 0 * w.x[0]).assemble(Basis(mesh, ElementTetP1()))
    assert abs(vol - 1.0) < 1e-12


def test_delaunay_mesh_bad_points():
    p = cube_nodes(60)
    with pytest.raises(ValueError, match=r"points\[8\]"):
        delaunay_mesh(np.r_[p[:8], [[np.nan, 0, 0]], p[8:]])
    with pytest.raises(ValueError, match="duplicate"):
        delaunay_mesh(np.r_[p, p[3:4]])
    flat = np.c_[np.random.default_rng(0).random((30, 2)), np.zeros(30)]
    with pytest.raises(ValueError, match="span only 2 of 3"):
        delaunay_mesh(flat)
    # nearly coincident points (which Qhull drops): both are vertices, as in 2D (exact
    # predicates decide their tetrahedra)
    near = np.r_[p, p[20:21] + 1e-15]
    assert np.unique(delaunay_mesh(near).t).size == near.shape[0]
    before = p.copy()
    delaunay_mesh(p)
    assert np.array_equal(p, before)


def test_non_delaunay_mesh_is_rejected():
    # two tetrahedra on a shared face, each vertex inside the other's circumsphere
    a = np.array([[np.cos(t), np.sin(t), 0.0] for t in (0, 2 * np.pi / 3, 4 * np.pi / 3)])
    p = np.r_[a, [[0, 0, 1.0], [0, 0, -0.1]]]
    bad = MeshTet(p.T, np.array([[0, 1, 2, 3], [0, 1, 2, 4]]).T)
    with pytest.raises(ValueError, match="not a Delaunay tetrahedralisation"):
        NaturalNeighbourBasis(bad)
    # the same points with Qhull's tetrahedra in another order are accepted
    from scipy.spatial import Delaunay
    t = Delaunay(p).simplices[::-1]
    NaturalNeighbourBasis(MeshTet(p.T, t.T))


def test_linear_fields_are_exact(mesh, basis):
    assert isinstance(basis.elem, ElementTetNaturalNeighbour)
    assert basis.X.shape == (3, 5)                      # the vertices and the centroid
    # the values at a tetrahedron's vertices are its nodes' (1 there, the others 0),
    # with no coordinate query
    V = basis.values_matrix[:20].toarray()
    for r in range(20):
        e, q = divmod(r, 5)
        if q < 4:
            assert V[r, mesh.t[q, e]] == 1.0 and np.count_nonzero(V[r]) == 1
        else:
            assert np.count_nonzero(V[r]) >= 4 and abs(V[r].sum() - 1) < 1e-14
    sizes = basis.stencil_sizes
    assert sizes.min() >= 4 and 10 < sizes.mean() < 30
    for e in range(0, mesh.nelements, 97):
        st = basis.stencil_nodes[basis.stencil_ptr[e]:basis.stencil_ptr[e + 1]]
        assert set(mesh.t[:, e]) <= set(st)
    A = laplace.assemble(basis)
    assert abs(A - A.T).max() < 1e-12
    np.testing.assert_allclose(A @ np.ones(basis.N), 0, atol=1e-11)
    g = np.array([0.3, -1.7, 0.9])
    u = g @ mesh.p
    assert abs(u @ A @ u - g @ g) < 1e-10              # volume 1
    M = mass.assemble(basis)
    one = np.ones(basis.N)
    assert abs(one @ M @ one - 1.0) < 1e-12
    assert abs(mesh.p[2] @ M @ one - 0.5) < 1e-12
    f = basis.interpolate(u)
    np.testing.assert_allclose(np.asarray(f), np.einsum("k,kij->ij", g,
                                                        np.asarray(basis.global_coordinates())),
                               atol=1e-12)
    np.testing.assert_allclose(f.grad, np.broadcast_to(g[:, None, None], f.grad.shape), atol=1e-9)
    x = np.array([[0.5, 0.2, 0.9], [0.5, 0.7, 0.1], [0.4, 0.4, 0.6]])
    np.testing.assert_allclose(basis.probes(x) @ u, g @ x, atol=1e-12)
    np.testing.assert_allclose(basis.interpolator(u)(x.reshape(3, 3, 1)).ravel(), g @ x,
                               atol=1e-12)
    with pytest.raises(ValueError, match=r"shape \(3, m\)"):
        basis.probes(x[:2])


def test_mixed_with_p1_and_one_line_poisson(mesh, basis):
    p1 = Basis(mesh, ElementTetP1(), quadrature=basis.quadrature)
    B = asm(BilinearForm(lambda u, v, w: u * v), basis, p1)   # NEM trial, P1 test
    np.testing.assert_allclose(B @ np.ones(basis.N), asm(mass, p1) @ np.ones(p1.N), atol=1e-12)

    @LinearForm
    def load(v, w):
        return 3 * np.pi ** 2 * np.prod(np.sin(np.pi * w.x), axis=0) * v

    D = basis.get_dofs().flatten()
    on = np.isclose(mesh.p, 0).any(0) | np.isclose(mesh.p, 1).any(0)
    assert set(D) == set(np.flatnonzero(on))
    u = solve(*condense(laplace.assemble(basis), load.assemble(basis), D=D))
    exact = np.prod(np.sin(np.pi * mesh.p), axis=0)
    p1 = Basis(mesh, ElementTetP1(), quadrature=basis.quadrature)
    u1 = solve(*condense(laplace.assemble(p1), load.assemble(p1), D=p1.get_dofs().flatten()))
    # the L2 errors by a rule of degree 6 (the functions evaluated at its points):
    # NEM's is below half of P1's on the same tetrahedra (measured 0.018 vs 0.048)
    fine = Basis(mesh, ElementTetP1(), intorder=6)
    x = np.asarray(fine.global_coordinates())
    uh = (basis.probes(x.reshape(3, -1)) @ u).reshape(x.shape[1:])
    sol = np.prod(np.sin(np.pi * x), axis=0)
    l2_nem = np.sqrt(((uh - sol) ** 2 * fine.dx).sum())
    l2_p1 = np.sqrt(((fine.interpolate(u1).value - sol) ** 2 * fine.dx).sum())
    assert l2_nem < 0.5 * l2_p1
    assert np.abs(u - exact).max() < 0.2


def test_vector_basis_elasticity(mesh):
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    assert vb.elem.dim == 3 and vb.N == 3 * mesh.nvertices
    K = linear_elasticity(*lame_parameters(1.0, 0.3)).assemble(vb)
    assert abs(K - K.T).max() < 1e-12
    x, y, z = mesh.p
    nd = vb.nodal_dofs
    # rigid motions (3 translations, 3 rotations) have zero energy
    for f in [(1 + 0 * x, 0 * x, 0 * x), (0 * x, 1 + 0 * x, 0 * x), (0 * x, 0 * x, 1 + 0 * x),
              (-y, x, 0 * x), (0 * x, -z, y), (z, 0 * x, -x)]:
        u = np.zeros(vb.N)
        for c in range(3):
            u[nd[c]] = f[c]
        assert np.abs(K @ u).max() < 1e-10
    # a uniform strain has the exact energy: u = (x, 0, 0) -> eps_xx = 1
    lam, mu = lame_parameters(1.0, 0.3)
    u = np.zeros(vb.N)
    u[nd[0]] = x
    assert abs(u @ K @ u - (lam + 2 * mu)) < 1e-9
    w = vb.interpolate(u)
    assert np.asarray(w).shape == (3,) + vb.dx.shape and w.grad.shape == (3, 3) + vb.dx.shape
    np.testing.assert_allclose(w.grad[0, 0], 1.0, atol=1e-9)
    assert vb.probes(np.array([[0.3], [0.4], [0.5]])).shape == (3, vb.N)


def test_facet_basis_on_boundary_triangles(mesh, basis):
    fb = NaturalNeighbourFacetBasis(mesh, facets=mesh.boundary_facets())
    assert fb.dx.shape[0] == mesh.boundary_facets().size
    area = Functional(lambda w: 1.0 + 0 * w.x[0]).assemble(fb)
    assert abs(area - 6.0) < 1e-12
    g = np.array([0.3, -1.7, 0.9])
    u = g @ mesh.p
    # boundary integral of a linear field and its normal flux (exact with P1 too)
    pf = FacetBasis(mesh, ElementTetP1(), facets=mesh.boundary_facets(),
                    quadrature=fb.quadrature)
    bu = Functional(lambda w: w["u"]).assemble(fb, u=u)
    assert abs(bu - Functional(lambda w: w["u"]).assemble(pf, u=u)) < 1e-12
    flux = Functional(lambda w: dot(w["u"].grad, w.n) * w.x[0]).assemble(fb, u=u)
    assert abs(flux - g[0]) < 1e-7      # divergence theorem: int g.n x dS = g_x
    # on the hull the values reduce to the facet's nodes
    F = fb.values_matrix.tocoo()
    bnodes = np.unique(mesh.facets[:, mesh.boundary_facets()])
    assert np.isin(F.col[np.abs(F.data) > 1e-14], bnodes).all()
    # a Neumann load assembles with the facet basis
    b = LinearForm(lambda v, w: v).assemble(fb)
    assert abs(b.sum() - 6.0) < 1e-12 and b.shape == (basis.N,)


def test_lasserre_basis_in_2d_matches_area_basis():
    rng = np.random.default_rng(3)
    s = np.linspace(0, 1, 9)[1:-1]
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], np.c_[s, 0 * s], np.c_[s, 1 + 0 * s],
              np.c_[0 * s, s], np.c_[1 + 0 * s, s], rng.random((150, 2))]
    m = delaunay_mesh(p)
    a = laplace.assemble(NaturalNeighbourBasis(m))
    b = laplace.assemble(NaturalNeighbourBasis(m, method="lasserre"))
    assert abs(a - b).max() < 1e-10 * abs(a).max()
    with pytest.raises(ValueError, match="Sibson coordinates only"):
        NaturalNeighbourBasis(m, method="lasserre", coordinates="laplace")
    with pytest.raises(ValueError, match="Lasserre method only"):
        NaturalNeighbourBasis(delaunay_mesh(cube_nodes(40)), method="area")


def test_tet_coordinates_match_the_public_function(mesh, basis):
    # values at the points (vertices and centroids), on the (wider) pattern of the
    # smoothed gradients; the centroids' by Watson's decomposition, equal to the Box 1
    # method's to round-off (~1e-13 where slivers make the terms cancel)
    x = np.asarray(basis.global_coordinates()).reshape(3, -1).T
    box1 = sibson_coordinates(mesh.p.T, x, gradient=True, undefined="nan")[0]
    assert abs(box1 - basis.values_matrix).max() < 1e-12
    gauss = NaturalNeighbourBasis(mesh, intorder=2)
    x = np.asarray(gauss.global_coordinates()).reshape(3, -1).T
    Phi, D = sibson_coordinates(mesh.p.T, x, gradient=True)
    assert abs(Phi - gauss.values_matrix).max() < 1e-14
    assert max(abs(a - b).max() for a, b in zip(D, gauss._D)) < 1e-10


def test_lattice_nodes_flat_tetrahedra_and_structured_meshes():
    # co-spherical nodes: Qhull glues its triangulations of the cubes with flat
    # tetrahedra, whose quadrature points carry no weight and are skipped; delaunay_mesh
    # (symbolic perturbation) makes none
    s = np.linspace(0, 1, 5)
    grid = MeshTet.init_tensor(s, s, s)
    m = delaunay_mesh(grid.p.T)
    qhull = MeshTet(grid.p, Delaunay(grid.p.T).simplices.T.astype(np.int64))
    for mesh, flat in ((m, False), (qhull, True)):
        P = mesh.p.T[mesh.t.T]
        vol = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / 6
        assert (np.count_nonzero(vol < 1e-14) > 0) == flat and abs(vol.sum() - 1) < 1e-12
    g = np.array([0.3, -1.7, 0.9])
    for mesh in (m, qhull, grid):   # ours, Qhull's, and scikit-fem's own (all Delaunay)
        b = NaturalNeighbourBasis(mesh)
        A = laplace.assemble(b)
        u = g @ mesh.p
        assert abs(u @ A @ u - g @ g) < 1e-12
        assert abs(np.ones(b.N) @ mass.assemble(b) @ np.ones(b.N) - 1) < 1e-12
        on = ((mesh.p == 0) | (mesh.p == 1)).any(axis=0)
        assert set(b.get_dofs().flatten()) == set(np.flatnonzero(on))


def test_constant_gradients_contracted_once(mesh, monkeypatch):
    """On tetrahedra the smoothed gradients are the same at an element's four points,
    and the assembly contracts gradient terms once per element: the same matrices as
    contracting them point by point, for forms with gradients, values and both."""
    from skfem import BilinearForm
    from skfem.helpers import ddot, dot, grad, sym_grad

    from skfem_nem import NaturalNeighbourBasis

    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    sb = NaturalNeighbourBasis(mesh)
    assert vb.gradients_constant_per_element and sb.gradients_constant_per_element
    assert not NaturalNeighbourBasis(mesh, intorder=2,
                                     integration="gauss").gradients_constant_per_element

    @BilinearForm
    def visc(u, v, w):
        return 2 * (1 + w.x[0]) * ddot(sym_grad(u), sym_grad(v)) + dot(u, v) * w.x[1]

    @BilinearForm
    def adv(u, v, w):
        return dot(grad(u), w.x) * v + u * v

    fast = [visc.assemble(vb).toarray(), adv.assemble(sb).toarray()]
    monkeypatch.setattr(NaturalNeighbourBasis, "gradients_constant_per_element", False)
    slow = [visc.assemble(vb).toarray(), adv.assemble(sb).toarray()]
    for a, b in zip(fast, slow):
        assert np.abs(a - b).max() < 1e-12 * np.abs(b).max()


def test_smoothed_values_at_a_chosen_rule(mesh, basis):
    # on tetrahedra a smoothed basis takes the points carrying values from intorder;
    # the smoothed gradient is the tetrahedron's either way
    b4 = NaturalNeighbourBasis(mesh, integration="smoothed", intorder=2)
    assert b4.integration == "smoothed" and b4.X.shape == (3, 4)
    assert b4.gradients_constant_per_element
    for e in (0, 101, mesh.nelements - 1):
        for k in range(3):
            g5 = basis._D[k][5 * e].toarray().ravel()
            g4 = b4._D[k][4 * e].toarray().ravel()
            np.testing.assert_allclose(g4, g5, atol=1e-12)
    x = np.asarray(b4.global_coordinates()).reshape(3, -1).T
    # (Watson's decomposition against Box 1: round-off, see the test above)
    box1 = sibson_coordinates(mesh.p.T, x, gradient=True, undefined="nan")[0]
    assert abs(box1 - b4.values_matrix).max() < 1e-12
    assert abs(laplace.assemble(b4) - laplace.assemble(basis)).max() < 1e-11
    # the points' rows alone are kept, not the face rows the gradients were made from
    ptr, idx, val = b4.cell_rows.V
    assert ptr[0] == 0 and idx.size == val.size == ptr[-1]
    # on triangles the smoothing cells fix the points: a rule is refused
    tri = delaunay_mesh(np.random.default_rng(0).random((30, 2)))
    with pytest.raises(ValueError, match="intorder chooses a Gauss rule"):
        NaturalNeighbourBasis(tri, integration="smoothed", intorder=2)


def test_gradient_rows_assembly_equals_the_element_matrices(mesh, monkeypatch):
    """On the smoothed tetrahedral basis (one gradient per element) forms are summed row by
    row from the gradients, no element matrix stored: the same matrices as the element
    matrices' road, for a Laplacian, elasticity, a form with values and gradients
    (mass + varying coefficient) and a non-symmetric convection form."""
    from skfem_nem.basis import summation
    vec = NaturalNeighbourBasis(mesh, ElementVector(ElementTetNaturalNeighbour()))
    sca = NaturalNeighbourBasis(mesh)

    @BilinearForm
    def mixed(u, v, w):
        return (1 + w.x[0] ** 2) * dot(u.grad, v.grad) + 3.0 * u * v + u.grad[0] * v

    forms = [(laplace, sca), (linear_elasticity(*lame_parameters(1e3, 0.3)), vec),
             (mixed, sca)]
    calls = []
    real = summation.sum_coo_gradients
    monkeypatch.setattr("skfem_nem.basis.assembly.sum_coo_gradients",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    new = [form.assemble(b) for form, b in forms]
    assert len(calls) == 3
    monkeypatch.setattr(type(sca), "gradients_constant_per_element", property(lambda s: False))
    for A, (form, b) in zip(new, forms):
        B = form.assemble(b)
        assert abs(A - B).max() <= 1e-12 * abs(B).max()
    assert len(calls) == 3


def test_one_set_of_watson_records_a_tetrahedralisation(monkeypatch):
    """The smoothed 3D basis takes its face points' values from Watson's records; the
    points those flag go to the triangulation's coordinates, which read records too. On a
    mesh of the package's (its triangulation holds its tetrahedra in their order) both
    read one set, made once, and the basis is the one built with two."""
    import skfem_nem.coordinates.watson3d as watson
    rng = np.random.default_rng(11)
    mesh = delaunay_mesh(rng.random((400, 3)))
    before = NaturalNeighbourBasis(delaunay_mesh(mesh.p.T.copy()))  # its own records
    made = []
    real = watson.TetrahedraRecords.__init__

    def counted(self, *args):
        made.append(self)
        real(self, *args)
    monkeypatch.setattr(watson.TetrahedraRecords, "__init__", counted)
    basis = NaturalNeighbourBasis(mesh)
    assert len(made) == 1 and watson.records_of(basis.triangulation) is made[0]
    A = BilinearForm(lambda u, v, w: dot(u.grad, v.grad)).assemble(basis)
    B = BilinearForm(lambda u, v, w: dot(u.grad, v.grad)).assemble(before)
    assert abs(A - B).max() == 0
