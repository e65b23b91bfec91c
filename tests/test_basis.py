"""NaturalNeighbourBasis inside scikit-fem: everything a P1 user does works."""

import numpy as np
import pytest
from skfem import (Basis, BilinearForm, ElementTriP1, ElementTriP2, ElementVector, Functional,
                   LinearForm, MeshTri, asm, condense, enforce, solve)
from skfem.helpers import dot, grad
from skfem.models.elasticity import lame_parameters, linear_elasticity

from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis, NaturalNeighbourFacetBasis,
                       delaunay_mesh, sibson_coordinates)
from skfem_nem.geometry.nodesets import box_nodes

from helpers import laplace, mass, square_nodes


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(square_nodes())


@pytest.fixture(scope="module")
def basis(mesh):
    return NaturalNeighbourBasis(mesh)


@pytest.fixture(scope="module")
def vbasis(mesh):
    return NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))


def test_stencils_and_groups(mesh, basis):
    sizes = basis.stencil_sizes
    assert sizes.shape == (mesh.nelements,)
    assert sizes.min() >= 3 and 5 < sizes.mean() < 12
    # each triangle's own vertices are in its stencil
    for e in range(0, mesh.nelements, 37):
        st = basis.stencil_nodes[basis.stencil_ptr[e]:basis.stencil_ptr[e + 1]]
        assert set(mesh.t[:, e]) <= set(st)
    # groups partition the elements, one stencil size each
    idx = np.sort(np.concatenate([g.tind for g in basis.groups]))
    np.testing.assert_array_equal(idx, np.arange(mesh.nelements))
    for g in basis.groups:
        assert g.Nbfun == sizes[g.tind[0]] and np.all(sizes[g.tind] == g.Nbfun)
    assert basis.nstencil_entries == int((sizes ** 2).sum())


def test_stiffness_exact_on_linear_fields(mesh, basis):
    A = laplace.assemble(basis)
    assert abs(A - A.T).max() < 1e-12
    np.testing.assert_allclose(A @ np.ones(basis.N), 0, atol=1e-12)
    # gradients of the interpolant of a linear field are exact at every point,
    # so the energy is exact whatever the quadrature: u^T A u = area |g|^2
    g = np.array([0.3, -1.7])
    u = g @ mesh.p
    assert abs(u @ A @ u - g @ g) < 1e-11
    M = mass.assemble(basis)
    one = np.ones(basis.N)
    assert abs(one @ M @ one - 1.0) < 1e-12
    assert abs(mesh.p[0] @ M @ one - 0.5) < 1e-12


def test_poisson_one_line_switch(mesh, basis):
    @LinearForm
    def load(v, w):
        x, y = w.x
        return 2 * np.pi ** 2 * np.sin(np.pi * x) * np.sin(np.pi * y) * v

    @Functional
    def l2(w):
        x, y = w.x
        return (w["u"] - np.sin(np.pi * x) * np.sin(np.pi * y)) ** 2

    errs = {}
    for name, b in [("nem", basis), ("p1", Basis(mesh, ElementTriP1()))]:
        A, f = laplace.assemble(b), load.assemble(b)
        u = solve(*condense(A, f, D=b.get_dofs()))
        errs[name] = np.sqrt(l2.assemble(b, u=u))
        # also with asm() and a DiscreteField keyword
        assert abs(np.sqrt(asm(l2, b, u=b.interpolate(u))) - errs[name]) < 1e-14
    assert errs["nem"] < 0.01
    assert errs["nem"] < 1.5 * errs["p1"]


def test_mixed_nem_and_p1(mesh, basis):
    p1 = Basis(mesh, ElementTriP1(), quadrature=basis.quadrature)
    A = laplace.assemble(basis)
    B = laplace.assemble(p1, basis)  # P1 trial, NEM test
    C = laplace.assemble(basis, p1)  # NEM trial, P1 test
    assert B.shape == (basis.N, p1.N) and C.shape == (p1.N, basis.N)
    u = np.array([0.7, 2.0]) @ mesh.p + 0.1  # linear: both spaces reproduce it
    np.testing.assert_allclose(B @ u, A @ u, atol=1e-12)
    np.testing.assert_allclose(C @ u, laplace.assemble(p1) @ u, atol=1e-12)
    with pytest.raises(ValueError, match="quadrature"):
        laplace.assemble(Basis(mesh, ElementTriP1(), intorder=4), basis)


def test_vector_basis_elasticity(mesh, vbasis):
    assert vbasis.N == 2 * mesh.nvertices
    K = linear_elasticity(*lame_parameters(1.0, 0.3)).assemble(vbasis)
    assert abs(K - K.T).max() < 1e-12
    x, y = mesh.p
    dofs = vbasis.dofs.nodal_dofs
    for field in ([np.ones_like(x), 0 * x], [0 * x, np.ones_like(x)], [-y, x]):
        r = np.zeros(vbasis.N)
        r[dofs[0]], r[dofs[1]] = field
        np.testing.assert_allclose(K @ r, 0, atol=1e-12)  # rigid motions: no force
    D = vbasis.get_dofs()
    assert set(D.nodal.keys()) == {"u^1", "u^2"}
    left = vbasis.get_dofs(lambda x: np.isclose(x[0], 0.0))
    assert np.all(np.isclose(x[left.nodal["u^1"] // 2], 0.0))
    np.testing.assert_array_equal(left.nodal["u^1"] % 2, 0)
    np.testing.assert_array_equal(
        vbasis.get_dofs(lambda x: np.isclose(x[0], 0.0), skip=["u^2"]).flatten(),
                                  left.nodal["u^1"])
    # patch test: linear displacement imposed on the boundary
    lin = np.zeros(vbasis.N)
    lin[dofs[0]] = 0.01 * x + 0.02 * y
    lin[dofs[1]] = -0.03 * x + 0.005 * y
    u = solve(*condense(K, np.zeros(vbasis.N), x=lin, D=D))
    assert np.abs(u - lin).max() < 1e-3


def test_named_boundaries_and_enforce():
    m = delaunay_mesh(square_nodes(100, 8)).with_boundaries(
        {"left": lambda x: np.isclose(x[0], 0), "top": lambda x: np.isclose(x[1], 1)})
    b = NaturalNeighbourBasis(m)
    left = b.get_dofs("left").flatten()
    np.testing.assert_array_equal(np.sort(left), np.flatnonzero(np.isclose(m.p[0], 0)))
    A = laplace.assemble(b)
    f = np.zeros(b.N)
    D = b.get_dofs(["left", "top"]).flatten()
    x = b.zeros()
    x[D] = 1.0
    A2, f2 = enforce(A, f, x=x, D=D)
    u = solve(A2, f2)
    np.testing.assert_allclose(u[D], 1.0)


def test_project_on_elements(mesh, basis, vbasis):
    """``elements=`` projects on the functions of those triangles (their stencils'
    nodes), the other dofs are zero, as scikit-fem's ``project(elements=...)``."""
    def f(x):
        return np.sin(3 * x[0]) + x[1]

    def left(x):
        return x[0] < 0.5

    p = basis.project(f, elements=left)
    dofs = basis.stencil_dofs(left)
    outside = np.setdiff1d(np.arange(basis.N), dofs)
    assert dofs.size and outside.size
    assert np.all(p[outside] == 0.0) and np.all(p[dofs] != 0.0)
    mask = np.zeros(mesh.nelements, bool)
    mask[mesh.elements_satisfying(left)] = True
    np.testing.assert_array_equal(basis.project(f, elements=mask), p)
    np.testing.assert_allclose(basis.project(f, elements=np.arange(mesh.nelements)),
                               basis.project(f), atol=1e-12)
    # each stencil node's dof, for every component of a vector basis
    assert np.array_equal(basis.stencil_dofs(left), np.sort(basis.dofs.nodal_dofs[0][dofs]))
    assert vbasis.stencil_dofs(left).size == 2 * dofs.size
    with pytest.raises(ValueError, match="real"):
        basis.project(f, dtype=np.complex128)
    with pytest.raises(ValueError, match=rf"element indices must lie in \[0, {mesh.nelements}\)"):
        basis.project(f, elements=[mesh.nelements])
    with pytest.raises(ValueError, match="element mask"):
        basis.project(f, elements=np.ones(3, bool))
    with pytest.raises(TypeError):
        basis.project(f, I=[0])  # no keyword is swallowed


def test_interpolate_probes_project(mesh, basis, vbasis):
    u = 2 * mesh.p[0] - mesh.p[1] + 0.5
    f = basis.interpolate(u)
    X = basis.global_coordinates()
    np.testing.assert_allclose(f, 2 * X[0] - X[1] + 0.5, atol=1e-13)
    np.testing.assert_allclose(f.grad[0], 2, atol=1e-12)
    np.testing.assert_allclose(f.grad[1], -1, atol=1e-12)
    rng = np.random.default_rng(3)
    pts = rng.random((2, 50))
    val = basis.probes(pts) @ np.sin(mesh.p[0])
    np.testing.assert_allclose(val, sibson_coordinates(mesh.p.T, pts.T) @ np.sin(mesh.p[0]),
                               atol=1e-14)
    np.testing.assert_allclose(basis.interpolator(u)(pts), 2 * pts[0] - pts[1] + 0.5, atol=1e-13)
    # L2 projection of a function in the space returns it
    p = basis.project(lambda x: 2 * x[0] - x[1] + 0.5)
    np.testing.assert_allclose(p, u, atol=1e-10)
    # vector: interpolate and probes follow the ElementVector dof numbering
    w = np.zeros(vbasis.N)
    w[vbasis.dofs.nodal_dofs[0]] = mesh.p[1]
    w[vbasis.dofs.nodal_dofs[1]] = 3.0
    F = vbasis.interpolate(w)
    np.testing.assert_allclose(F[0], X[1], atol=1e-13)
    np.testing.assert_allclose(F.grad[0, 1], 1.0, atol=1e-12)
    np.testing.assert_allclose(F[1], 3.0, atol=1e-13)
    P = vbasis.probes(pts) @ w
    np.testing.assert_allclose(P[:50], pts[1], atol=1e-13)
    np.testing.assert_allclose(P[50:], 3.0, atol=1e-13)


def test_functional_parameters(mesh, basis):
    @Functional
    def area(w):
        return 1.0 + 0 * w.x[0]

    @Functional
    def hsum(w):
        return w.h ** 2

    assert abs(area.assemble(basis) - 1.0) < 1e-13
    p1 = Basis(mesh, ElementTriP1(), quadrature=basis.quadrature)
    assert abs(hsum.assemble(basis) - hsum.assemble(p1)) < 1e-13
    el = area.elemental(basis)
    assert el.shape == (mesh.nelements,)
    np.testing.assert_allclose(el, area.elemental(p1), atol=1e-15)


def test_facet_basis(mesh, basis):
    fb = NaturalNeighbourFacetBasis(mesh, facets=mesh.boundary_facets())

    @LinearForm
    def one(v, w):
        return v

    assert abs(one.assemble(fb).sum() - 4.0) < 1e-13

    @Functional
    def flux(w):
        return dot(w["u"].grad, w.n)

    # the gradient of the interpolant of x is (1, 0) up to the hull: net flux 0
    assert abs(flux.assemble(fb, u=mesh.p[0])) < 1e-8
    # Green: for linear u, the cell integral of grad u . grad v equals the
    # boundary integral of (grad u . n) v up to the cell quadrature error,
    # which falls as the rule gets richer (the paper's open question)
    g = np.array([1.0, 0.5])

    @LinearForm
    def neumann(v, w):
        return (g[0] * w.n[0] + g[1] * w.n[1]) * v

    b = neumann.assemble(fb)
    u = g @ mesh.p
    errs = {}
    for npts in (1, 3, 7, 13):
        A = laplace.assemble(NaturalNeighbourBasis(mesh, npoints=npts))
        errs[npts] = np.abs(A @ u - b).max()
    assert errs[13] < errs[3] < errs[1]
    assert errs[13] < 0.5 * errs[1]


def test_quadrature_choices(mesh):
    for npts in (1, 3, 4, 6, 7, 12, 13):
        b = NaturalNeighbourBasis(mesh, npoints=npts)
        assert b.X.shape == (2, npts) and abs(b.W.sum() - 0.5) < 1e-14
        assert abs(mass.assemble(b).sum() - 1.0) < 1e-12
    X = np.array([[1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
    b = NaturalNeighbourBasis(mesh, quadrature=(X, np.full(3, 1 / 6)))
    assert b.X.shape == (2, 3)
    with pytest.raises(ValueError, match="npoints"):
        NaturalNeighbourBasis(mesh, npoints=5)


def test_laplace_coordinates_basis(mesh):
    b = NaturalNeighbourBasis(mesh, coordinates="laplace")
    A = laplace.assemble(b)
    np.testing.assert_allclose(A @ np.ones(b.N), 0, atol=1e-12)
    u = np.array([1.0, 2.0]) @ mesh.p
    assert abs(u @ A @ u - 5.0) < 1e-11


def test_bad_meshes_and_elements():
    p = square_nodes(50, 4)
    m = delaunay_mesh(p)
    # flip one interior edge: still a valid mesh, no longer Delaunay
    from skfem_nem import Triangulation
    tri = Triangulation(p)
    from skfem_nem.geometry.delaunay2d import flip_edge
    T, N = tri.triangles.copy(), tri.neighbours.copy()
    t, k = np.argwhere(N >= 0)[0]
    flip_edge(T, N, t, k)
    bad = MeshTri(p.T, T.T)
    # its triangles carry the integration; the functions come from the nodes' Delaunay
    # triangulation, so they are those of the Delaunay mesh
    nb = NaturalNeighbourBasis(bad)
    x = np.random.default_rng(1).random((2, 50))
    assert abs(nb.probes(x) - NaturalNeighbourBasis(m).probes(x)).max() < 1e-14
    u = 1 + 2 * p[:, 0] - p[:, 1]
    A = laplace.assemble(nb)
    D = nb.get_dofs().all()
    assert np.abs(solve(*condense(A, 0 * u, x=u.copy(), D=D)) - u).max() < 1e-12
    with pytest.raises(ValueError, match=f"node {len(p)} at .* belongs to no triangle"):
        NaturalNeighbourBasis(MeshTri(np.c_[p.T, [[0.5], [0.5]]], m.t))
    with pytest.raises(TypeError, match="ElementNaturalNeighbour"):
        NaturalNeighbourBasis(m, ElementTriP1())
    with pytest.raises(NotImplementedError, match="NaturalNeighbourBasis"):
        Basis(m, ElementNaturalNeighbour())
    # a non-convex domain is no longer a warning: its boundary constrains the coordinates
    L = MeshTri.init_lshaped().refined(2)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        b = NaturalNeighbourBasis(L)
    assert b.triangulation.segments.shape[0] == L.boundary_facets().size


def test_save_and_plot(mesh, basis, tmp_path):
    import meshio
    u = np.sin(3 * mesh.p[0]) * mesh.p[1]
    path = tmp_path / "u.vtu"
    mesh.save(str(path), point_data={"u": u})
    back = meshio.read(path)
    np.testing.assert_allclose(back.point_data["u"], u)
    import matplotlib
    matplotlib.use("Agg")
    ax = basis.plot(u, nrefs=1)
    ax.figure.savefig(tmp_path / "u.png")
    # the natural-neighbour field on the refined triangles: within the nodal
    # values' range (a convex combination) and spanning it, over the whole square
    (tp,) = [c for c in ax.collections if c.get_array() is not None]
    v = np.asarray(tp.get_array())
    assert v.size > mesh.nvertices
    assert u.min() - 1e-12 <= v.min() and v.max() <= u.max() + 1e-12
    assert v.max() - v.min() > 0.95 * (u.max() - u.min())
    lim = ax.dataLim
    np.testing.assert_allclose([lim.x0, lim.y0, lim.x1, lim.y1], [0, 0, 1, 1], atol=1e-12)


def test_p2_on_same_mesh_for_comparison(mesh):
    # scikit-fem P2 on the NEM mesh: the comparison baseline works unchanged
    b2 = Basis(mesh, ElementTriP2())
    A = laplace.assemble(b2)
    np.testing.assert_allclose(A @ np.ones(b2.N), 0, atol=1e-11)


def test_stacked_assembly_equals_pairwise(mesh, basis, vbasis, monkeypatch):
    """The stacked assembly (few form calls) gives scikit-fem's per-pair result."""
    import skfem_nem.basis.assembly as assembly

    @BilinearForm
    def weighted(u, v, w):
        return (1 + w["k"] ** 2 + w.x[0]) * dot(grad(u), grad(v)) + w["k"].grad[0] * u * v

    @LinearForm
    def load(v, w):
        return w["k"] * v + w.h * grad(v)[1]

    k = np.sin(3 * mesh.p[0]) + mesh.p[1]
    results = []
    # per pair, stacked, stacked in tiny chunks (by groups), then over the
    # whole mesh at once
    for size, whole in ((0, False), (1 << 19, False), (7, False), (0, True)):
        monkeypatch.setattr(assembly, "STACK_SIZE", size)
        monkeypatch.setattr(assembly, "WHOLE", whole)
        A = weighted.assemble(basis, k=k)
        B = weighted.assemble(basis, k=basis.interpolate(k))
        f = load.assemble(basis, k=k)
        K = linear_elasticity(*lame_parameters(2.0, 0.25)).assemble(vbasis)
        results.append((A, B, f, K))
    for r in results[1:]:
        for x, y in zip(results[0], r):
            assert abs(x - y).max() < 1e-12 * max(1.0, abs(y).max())


def test_probed_assembly_equals_stacked_pairs():
    """Local matrices from the form's coefficients (read off on unit fields)
    equal the pairwise evaluation, for scalar and vector forms with
    coefficients, first-order terms and w.x."""
    from skfem import BilinearForm, ElementVector
    from skfem.helpers import ddot, div, dot, grad, sym_grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
    from skfem_nem.basis import assembly as _assembly
    rng = np.random.default_rng(3)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((300, 2))])
    sb = NaturalNeighbourBasis(mesh)
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    eta = 1 + np.asarray(vb.global_coordinates())[0]
    cases = [
        (BilinearForm(lambda u, v, w: dot(grad(u), grad(v)) + w.x[0] * u * v), sb, {}),
        (BilinearForm(lambda u, v, w: u.grad[0] * v + 2 * u * v.grad[1]), sb, {}),
        (linear_elasticity(*lame_parameters(1e3, 0.3)), vb, {}),
        (BilinearForm(lambda u, v, w: 2 * w["eta"] * ddot(sym_grad(u), sym_grad(v))
                      + div(u) * div(v) + dot(u, v)), vb, {"eta": eta}),
    ]
    try:
        _assembly.WHOLE = False
        for form, basis, kw in cases:
            _assembly.PROBE = False
            A1 = form.assemble(basis, **kw).tocsr()
            _assembly.PROBE = True
            A2 = form.assemble(basis, **kw).tocsr()
            assert abs(A1 - A2).max() <= 1e-13 * abs(A1).max()
    finally:
        _assembly.PROBE = True
        _assembly.WHOLE = True


def test_whole_mesh_assembly_equals_pairwise(monkeypatch):
    """Forms on bases that share their functions, assembled over the whole
    mesh at once (probed coefficients, numba contraction, entries summed row
    by row), equal scikit-fem's per-pair evaluation over the groups: forms
    with and without coefficients (constant coefficients are read off one
    element), w read in every way a dict offers, dof-vector and array
    arguments, mixed scalar/vector pairs, facet bases, linear forms; and
    the groups are never built."""
    from skfem import BilinearForm, ElementVector, LinearForm
    from skfem.helpers import ddot, div, dot, grad, sym_grad
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis,
                           NaturalNeighbourFacetBasis, delaunay_mesh)
    from skfem_nem.basis import assembly as _assembly
    rng = np.random.default_rng(5)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((250, 2))])
    vec = ElementVector(ElementNaturalNeighbour())

    def bases():
        return (NaturalNeighbourBasis(mesh), NaturalNeighbourBasis(mesh, vec),
                NaturalNeighbourFacetBasis(mesh, vec, facets=mesh.boundary_facets()),
                NaturalNeighbourBasis(mesh, npoints=6))

    k = np.cos(2 * mesh.p[0]) * mesh.p[1]
    eta = 1 + mesh.p[0] ** 2
    u0 = rng.standard_normal(2 * mesh.p.shape[1])

    def cases(sb, vb, fb, sb6):
        return [
            (laplace, (sb,), {}),
            (linear_elasticity(*lame_parameters(1e3, 0.3)), (vb,), {}),
            (BilinearForm(lambda u, v, w: u.grad[0] * v + 2 * u * v.grad[1] + u * v), (sb6,), {}),
            (BilinearForm(lambda u, v, w: (1 + w.x[0]) * dot(grad(u), grad(v))), (sb,), {}),
            (BilinearForm(lambda u, v, w: w["k"] * u * v + w["k"].grad[1] * u.grad[0] * v),
             (sb,), {"k": k}),
            (BilinearForm(lambda u, v, w: (2.0 if "k" in w else 1.0) * u * v), (sb,), {"k": 1.0}),
            (BilinearForm(lambda u, v, w: w.get("c", 3.0) * u * v), (sb,), {}),
            (BilinearForm(lambda u, v, w: 2 * w["eta"] * ddot(sym_grad(u), sym_grad(v))
                          + div(u) * div(v)), (vb,), {"eta": sb.interpolate(eta)}),
            (BilinearForm(lambda u, v, w: dot(w["u0"], u) * dot(w["u0"], v)
                          + ddot(grad(w["u0"]), grad(u)) * v[1]), (vb,), {"u0": u0}),
            (BilinearForm(lambda u, v, w: div(u) * v), (vb, sb), {}),
            (BilinearForm(lambda u, v, w: u * div(v) + u.grad[1] * v[0]), (sb, vb), {}),
            (BilinearForm(lambda u, v, w: dot(u, w.n) * dot(v, w.n) * w.h), (fb,), {}),
            (LinearForm(lambda v, w: w["k"] * v + w.x[1] * v.grad[0]), (sb,), {"k": k}),
            (LinearForm(lambda v, w: v.grad[1] - 2 * v), (sb6,), {}),
            (LinearForm(lambda v, w: dot(w.n, v) + div(v)), (fb,), {}),
            (LinearForm(lambda v, w: dot(w.x, v) + grad(v)[0, 1]), (vb,), {}),
        ]

    out = {}
    # by groups, pair by pair; whole mesh on one thread; whole mesh in parallel
    for road in ("groups", "serial", "parallel"):
        monkeypatch.setattr(_assembly, "WHOLE", road != "groups")
        monkeypatch.setattr(_assembly, "PROBE", False)
        monkeypatch.setattr(_assembly, "STACK_SIZE", 0)
        monkeypatch.setattr(_assembly, "PARALLEL_MIN", 0 if road == "parallel" else 1 << 40)
        bs = bases()
        out[road] = [form.assemble(*b, **kw) for form, b, kw in cases(*bs)]
        if road != "groups":
            assert all(b._groups is None for b in bs)
    for road in ("serial", "parallel"):
        for A, B in zip(out["groups"], out[road]):
            A = A.toarray() if hasattr(A, "toarray") else A
            B = B.toarray() if hasattr(B, "toarray") else B
            assert A.shape == B.shape
            np.testing.assert_allclose(B, A, rtol=0, atol=1e-13 * max(1.0, abs(A).max()))
    # the whole-mesh road hands scikit-fem each (row, column) entry once, in
    # row-major order, so its COO-to-CSR conversion has nothing to sort or add
    vb = NaturalNeighbourBasis(mesh, vec)
    (rows, cols), data, shape, _ = linear_elasticity(*lame_parameters(1.0, 0.3))._assemble(vb)
    key = rows.astype(np.int64) * shape[1] + cols
    assert np.all(np.diff(key) > 0)


def test_constant_coefficients_only_for_forms_that_never_touch_w():
    """A form is evaluated on one element and applied everywhere only when it
    provably ignores ``w``; any use of ``w`` (here through ``copy``, ``get``,
    ``len``, ``in`` and iteration, which a read-watcher could miss) gives the
    per-element probe, and the same matrix as reading ``w["eta"]`` directly."""
    from skfem_nem.basis import coefficients as _coefficients
    mesh = delaunay_mesh(box_nodes(120, seed=4))
    b = NaturalNeighbourBasis(mesh)
    eta = np.repeat(1.0 + np.arange(mesh.nelements)[:, None] % 3, b.dx.shape[1], axis=1)
    uses = [lambda w: w.copy()["eta"], lambda w: w.get("eta"),
            lambda w: w["eta"] * (len(w) > 0), lambda w: w["eta"] if "eta" in w else 1.0,
            lambda w: dict(w)["eta"]]
    direct = BilinearForm(lambda u, v, w: w["eta"] * dot(grad(u), grad(v))).assemble(b, eta=eta)
    which = np.arange(3)
    for use in uses:
        form = BilinearForm(lambda u, v, w, use=use: use(w) * dot(grad(u), grad(v)))
        assert _coefficients.constant_coefficients(form.form, 1, 1, 2, which, which, 3) is None
        assert abs(form.assemble(b, eta=eta) - direct).max() < 1e-12 * abs(direct).max()
    c = _coefficients.constant_coefficients(laplace.form, 1, 1, 2, which, which, 3)
    assert c is not None and c.tolist() == [0.0, 1.0, 1.0]


def test_scikit_fem_assembly_untouched_by_import_and_by_the_hook():
    """Importing the package changes nothing in scikit-fem; the assembly hook
    is installed by the first natural-neighbour basis, passes other bases
    through bit for bit, and can be taken out again."""
    import subprocess
    import sys

    from skfem import ElementTriP2, LinearForm, MeshTri
    from skfem.assembly.form import BilinearForm as BF

    from skfem_nem import restore_scikit_fem_assembly
    code = ("import skfem; f = skfem.BilinearForm._assemble; g = skfem.LinearForm._assemble; "
            "import skfem_nem; assert skfem.BilinearForm._assemble is f; "
            "assert skfem.LinearForm._assemble is g")
    subprocess.run([sys.executable, "-c", code], check=True)

    mesh = MeshTri.init_symmetric().refined(3)
    p1 = Basis(mesh, ElementTriP1(), intorder=4)
    p2 = Basis(mesh, ElementVector(ElementTriP2()), intorder=4)
    load = LinearForm(lambda v, w: w.x[0] * v)

    def plain():
        return [laplace.assemble(p1), linear_elasticity(*lame_parameters(1.0, 0.3)).assemble(p2),
                BilinearForm(lambda u, v, w: u * v[0]).assemble(p1, p2), load.assemble(p1)]

    mesh_nn = delaunay_mesh(box_nodes(40, seed=1))
    NaturalNeighbourBasis(mesh_nn)
    assert BF._assemble.__module__ == "skfem_nem.basis.assembly"
    on = plain()
    try:
        assert restore_scikit_fem_assembly() is True and restore_scikit_fem_assembly() is False
        assert BF._assemble.__module__.startswith("skfem.")
        off = plain()
    finally:
        NaturalNeighbourBasis(mesh_nn)          # installs it again (other tests need it)
    assert BF._assemble.__module__ == "skfem_nem.basis.assembly"
    for a, b in zip(on, off):
        if hasattr(a, "tocsr"):
            a, b = a.tocsr(), b.tocsr()
            assert (a.indptr == b.indptr).all() and (a.indices == b.indices).all()
            a, b = a.data, b.data
        assert np.array_equal(a, b)


def test_a_basis_is_freed_as_soon_as_it_is_dropped(mesh):
    """The groups refer to their basis weakly: with the cyclic collector off, dropping
    an assembled basis frees it (and its stencil arrays) at once; a group kept beyond
    its basis says so when asked for it."""
    import gc
    import weakref
    basis = NaturalNeighbourBasis(mesh)
    laplace.assemble(basis)
    group = basis.groups[0]
    assert group.parent is basis
    gone = weakref.ref(basis)
    enabled = gc.isenabled()
    gc.disable()
    try:
        del basis
        assert gone() is None
    finally:
        if enabled:
            gc.enable()
    with pytest.raises(ReferenceError, match="outlived its basis"):
        group.default_parameters()


def test_group_fields_are_built_for_scikit_fem_and_dropped_after_its_assembly(mesh, vbasis):
    """A group's per-function fields (scikit-fem's ``basis``) hold each stencil
    function's value and gradient in its own component, zeros elsewhere; a mixed
    assembly that needs them (natural-neighbour velocity, P1 pressure) leaves none
    built behind, and gives the same matrix again."""
    g = vbasis.groups[-1]
    V, G = g.stencil_values
    fields = g.basis
    assert len(fields) == g.Nbfun == 2 * V.shape[0]
    for j in (0, V.shape[0] - 1):
        for c in (0, 1):
            f = fields[2 * j + c][0]
            np.testing.assert_array_equal(f.value[c], V[j])
            np.testing.assert_array_equal(f.grad[c], G[:, j])
            assert not f.value[1 - c].any() and not f.grad[1 - c].any()
    g.release_fields()
    p1 = vbasis.with_element(ElementTriP1())
    div = BilinearForm(lambda u, q, w: q * (u.grad[0][0] + u.grad[1][1]))
    D = div.assemble(vbasis, p1)
    assert all(h._basis is None for h in vbasis.groups)
    np.testing.assert_array_equal(div.assemble(vbasis, p1).toarray(), D.toarray())
    u = np.zeros(vbasis.N)
    u[vbasis.nodal_dofs[0]] = mesh.p[0]          # u = (x, 0): divergence 1
    one = LinearForm(lambda q, w: q).assemble(p1)
    np.testing.assert_allclose(D @ u, one, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_element_matrices_summed_in_blocks_are_the_same_bits(dim, monkeypatch):
    """The whole-mesh assembly makes and sums its element matrices block by block of
    elements under a memory budget: a budget of a few elements gives the same matrix,
    bit for bit, as one block of all (elasticity, a coefficient varying in space)."""
    from skfem import BilinearForm, ElementVector
    from skfem.helpers import ddot, sym_grad

    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
    from skfem_nem.basis import assembly

    rng = np.random.default_rng(7)
    mesh = delaunay_mesh(rng.random((60 if dim == 3 else 150, dim)))
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))

    @BilinearForm
    def elastic(u, v, w):
        return (1 + w.x[0]) * ddot(sym_grad(u), sym_grad(v))

    whole = elastic.assemble(vb).tocsr()
    monkeypatch.setattr(assembly, "ELEMENT_MATRIX_BUDGET", 3000)
    blocks = list(assembly._budget_blocks(np.r_[0, np.cumsum(
        (dim * np.diff(vb.stencil_ptr)) ** 2)]))
    assert len(blocks) > 10
    parts = elastic.assemble(vb).tocsr()
    assert np.array_equal(whole.indptr, parts.indptr)
    assert np.array_equal(whole.indices, parts.indices)
    assert np.array_equal(whole.data, parts.data)
