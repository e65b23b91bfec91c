"""scikit-fem idioms on natural-neighbour bases, each against the P1 result on the same problem.

A scikit-fem user swaps ``Basis(mesh, ElementTriP1())`` for ``NaturalNeighbourBasis(mesh)``
and keeps the rest of the script: plotting through scikit-fem's own functions, facet
projections, subdomain bases, P0/P1 companion bases on the same quadrature. What is drawn is
checked through the matplotlib artists (triangulation, arrays, value ranges).
"""
import inspect

import matplotlib
import numpy as np
import pytest
import skfem.visuals.matplotlib as skplot
from matplotlib.collections import PolyCollection, TriMesh
from skfem import (Basis, BilinearForm, CellBasis, ElementTriP0, ElementTriP1, ElementVector,
                   FacetBasis, Functional, LinearForm, MeshTri, condense, solve)
from skfem.helpers import dot, grad

from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, NaturalNeighbourFacetBasis

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from helpers import laplace, mass

#: round-off of sums over a few hundred quadrature points
ROUNDOFF = 1e-12


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def mesh():
    return MeshTri().refined(3)


@pytest.fixture(scope="module")
def basis(mesh):
    return NaturalNeighbourBasis(mesh)


@pytest.fixture(scope="module")
def vbasis(mesh):
    return NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))


def field(x, y):
    return np.sin(3 * x) * y + x


def tripcolor(ax):
    """The tripcolor of a plot (a TriMesh when Gouraud-shaded, else a PolyCollection)."""
    (tp,) = [c for c in ax.collections if isinstance(c, (TriMesh, PolyCollection))]
    return tp


# --------------------------------------------------------------------------
# plotting through scikit-fem's dispatch
# --------------------------------------------------------------------------

def test_skfem_plot_draws_the_nem_field(mesh, basis):
    u = field(*mesh.p)
    ax = skplot.plot(basis, u)
    tp = tripcolor(ax)
    tri = tp._triangulation
    M, v = basis.refinterp(u)
    # the refined triangles (16 per triangle) and the NEM values at their nodes
    assert tri.triangles.shape == (16 * mesh.nelements, 3)
    np.testing.assert_allclose(tri.x, M.p[0])
    np.testing.assert_allclose(np.asarray(tp.get_array()), v)
    np.testing.assert_allclose(v, basis.probes(M.p) @ u, atol=ROUNDOFF)
    # Gouraud shading by default (values at vertices, not per triangle)
    assert tp.get_array().size == M.nvertices
    # a convex combination of the nodal values that spans them
    assert u.min() - ROUNDOFF <= v.min() and v.max() <= u.max() + ROUNDOFF
    # nodes of the refined mesh that are mesh nodes carry the nodal values
    at_nodes = basis.probes(mesh.p) @ u
    np.testing.assert_allclose(at_nodes, u, atol=ROUNDOFF)


LATE_IMPORT = """
import sys
import numpy as np
from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
mesh = delaunay_mesh(box_nodes(60, seed=3))
basis = NaturalNeighbourBasis(mesh)
print("matplotlib" in sys.modules)
import matplotlib
matplotlib.use("Agg")
from skfem.visuals.matplotlib import plot
ax = plot(basis, mesh.p[0] ** 2)
M, v = basis.refinterp(mesh.p[0] ** 2)
tp = [c for c in ax.collections if hasattr(c, "_triangulation")][0]
print(tp._triangulation.triangles.shape[0] == 16 * mesh.nelements,
      np.allclose(np.asarray(tp.get_array()), v))
"""


def test_a_basis_draws_with_scikit_fem_imported_after_it():
    """A natural-neighbour basis imports no matplotlib (26 MB of every MPI rank's
    memory); scikit-fem's ``plot`` imported afterwards still draws its field refined
    (registered as its module is imported)."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", LATE_IMPORT], capture_output=True,
                         text=True, check=True).stdout.split("\n")
    assert out[0] == "False", out
    assert out[1] == "True True", out


def test_basis_plot_passes_scikit_fem_keywords(mesh, basis):
    u = field(*mesh.p)
    fig, ax = plt.subplots()
    out = basis.plot(u, ax=ax, shading="flat", vmin=-1.0, vmax=3.0, cmap="viridis",
                     colorbar="u", nrefs=1, levels=4)
    assert out is ax
    tp = tripcolor(ax)
    assert tp.get_clim() == (-1.0, 3.0)
    assert tp.get_cmap().name == "viridis"
    # flat shading: one value per refined triangle (4 per triangle with nrefs=1)
    assert tp.get_array().size == 4 * mesh.nelements
    assert len(fig.axes) == 2 and fig.axes[1].get_ylabel() == "u"   # the colorbar
    assert len(ax.collections) >= 2                                  # the contour lines
    # the same as scikit-fem's plot of the P1 field at the refined nodes, which for a
    # linear field is the field itself
    lin = 2 * mesh.p[0] - mesh.p[1]
    p1 = Basis(mesh, ElementTriP1())
    a1 = skplot.plot(p1, lin, nrefs=2, shading="gouraud")
    a2 = skplot.plot(basis, lin, nrefs=2)
    v1, v2 = tripcolor(a1).get_array(), tripcolor(a2).get_array()
    np.testing.assert_allclose(np.sort(v2), np.sort(v1), atol=ROUNDOFF)


def test_plot_keywords_are_checked(mesh, basis):
    u = field(*mesh.p)
    with pytest.raises(TypeError, match="shadin"):
        basis.plot(u, shadin="gouraud")
    with pytest.raises(TypeError, match="nrefz"):
        skplot.plot(basis, u, nrefz=1)
    with pytest.raises(TypeError, match="levels"):
        basis.plot3(u, levels=3)
    with pytest.raises(TypeError, match="vmin"):
        basis.draw(vmin=0)
    with pytest.raises(ValueError, match="nrefs=1 and Nrefs=2"):
        basis.plot(u, nrefs=1, Nrefs=2)
    with pytest.raises(ValueError, match="visuals='nothing'"):
        basis.plot(u, visuals="nothing")
    with pytest.raises(ValueError, match="shape"):
        basis.plot(u[:-1])


def test_plot3_and_draw(mesh, basis):
    u = field(*mesh.p)
    ax = skplot.plot3(basis, u)
    (surf,) = ax.collections
    # a surface of the refined triangles coloured by their mean height, which is the
    # mean of the NEM values at their corners
    M, v = basis.refinterp(u)
    heights = np.asarray(surf.get_array())
    assert heights.size == 16 * mesh.nelements
    np.testing.assert_allclose(np.sort(heights), np.sort(v[M.t].mean(axis=0)), atol=ROUNDOFF)
    ax = basis.plot3(u, nrefs=1)
    assert np.asarray(ax.collections[0].get_array()).size == 4 * mesh.nelements
    for ax in (basis.draw(), skplot.draw(basis)):
        (line,) = ax.lines
        xy = np.asarray(line.get_xydata(), dtype=float)
        xy = xy[np.isfinite(xy).all(axis=1)]
        # the outline of the unit square: boundary segments only
        assert len(xy) == 2 * mesh.boundary_facets().size
        on_side = np.isclose(xy, 0).any(axis=1) | np.isclose(xy, 1).any(axis=1)
        assert on_side.all()


def test_vector_basis_plots_as_scikit_fem(mesh, vbasis):
    # arrows for the whole vector, one component via split, as with a P1 vector basis
    u = np.zeros(vbasis.N)
    u[vbasis.nodal_dofs[0]] = mesh.p[1]
    u[vbasis.nodal_dofs[1]] = -mesh.p[0]
    ax = vbasis.plot(u, nrefs=0)
    (q,) = ax.collections
    M, v = vbasis.refinterp(u, nrefs=0)
    np.testing.assert_allclose(q.U, v[:M.nvertices], atol=ROUNDOFF)
    np.testing.assert_allclose(q.U, M.p[1], atol=ROUNDOFF)
    np.testing.assert_allclose(q.V, -M.p[0], atol=ROUNDOFF)
    (ux, bx), (uy, by) = vbasis.split(u)
    ax = bx.plot(ux)
    np.testing.assert_allclose(np.sort(tripcolor(ax).get_array()),
                               np.sort(bx.refinterp(ux)[0].p[1]), atol=ROUNDOFF)
    with pytest.raises(NotImplementedError, match="split"):
        vbasis.plot3(u)


def test_facet_basis_plot_names_the_alternative(mesh):
    fb = NaturalNeighbourFacetBasis(mesh)
    with pytest.raises(NotImplementedError, match="NaturalNeighbourBasis"):
        skplot.plot(fb, np.zeros(fb.N))


# --------------------------------------------------------------------------
# facet projection
# --------------------------------------------------------------------------

def test_facet_project_equals_p1_on_the_boundary(mesh):
    # on hull facets natural-neighbour functions are the linear 1D hats of the facet's
    # nodes, so the boundary L2 projection is P1's to round-off
    def f(x):
        return np.exp(x[0]) * np.cos(2 * x[1])

    fb = NaturalNeighbourFacetBasis(mesh)
    p1 = FacetBasis(mesh, ElementTriP1())
    u = fb.project(f)
    np.testing.assert_allclose(u, p1.project(f), atol=ROUNDOFF)
    boundary = np.unique(mesh.facets[:, mesh.boundary_facets()])
    assert np.all(u[np.setdiff1d(np.arange(mesh.nvertices), boundary)] == 0.0)
    # facets=: a subset of the basis' facets, the others' dofs zero, as scikit-fem
    left = mesh.facets_satisfying(lambda x: x[0] == 0)
    ul = fb.project(f, facets=left)
    np.testing.assert_allclose(ul, p1.project(f, facets=left), atol=ROUNDOFF)
    assert np.count_nonzero(ul) == np.unique(mesh.facets[:, left]).size
    # a number, an array at the quadrature points, and a facet basis on some facets
    np.testing.assert_allclose(fb.project(2.0)[boundary], 2.0, atol=ROUNDOFF)
    np.testing.assert_allclose(fb.project(f(fb.global_coordinates())), u, atol=ROUNDOFF)
    fl = NaturalNeighbourFacetBasis(mesh, facets=left)
    np.testing.assert_allclose(fl.project(f),
                               FacetBasis(mesh, ElementTriP1(), facets=left).project(f),
                               atol=ROUNDOFF)
    with pytest.raises(ValueError, match="facet .* is not one of the basis' facets"):
        fl.project(f, facets=mesh.boundary_facets())


def test_vector_facet_project(mesh):
    fb = NaturalNeighbourFacetBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    p1 = FacetBasis(mesh, ElementVector(ElementTriP1()))

    def f(x):
        return np.array([x[0] * x[1], np.sin(x[0])])

    np.testing.assert_allclose(fb.project(f), p1.project(f), atol=ROUNDOFF)
    # components as a tuple, too
    np.testing.assert_allclose(fb.project(lambda x: tuple(f(x))), p1.project(f), atol=ROUNDOFF)
    with pytest.raises(ValueError, match="shape"):
        fb.project(lambda x: x[0])


# --------------------------------------------------------------------------
# subdomain bases
# --------------------------------------------------------------------------



@Functional
def area(w):
    return 1.0 + 0.0 * w.x[0]


def test_subdomain_integrals_equal_p1(mesh):
    left = mesh.elements_satisfying(lambda x: x[0] < 0.5)
    sb = NaturalNeighbourBasis(mesh, elements=left)
    p1 = Basis(mesh, ElementTriP1(), elements=left)
    assert sb.N == mesh.nvertices and sb.nelems == left.size
    np.testing.assert_array_equal(sb.tind, left)
    np.testing.assert_allclose(sb.dx, p1.dx, atol=ROUNDOFF)
    assert area.assemble(sb) == pytest.approx(0.5, abs=ROUNDOFF)
    # a linear field: NEM reproduces it, so its energy and mass over the triangles are P1's
    lin = 2 * mesh.p[0] - 3 * mesh.p[1] + 1
    for form in (laplace, mass):
        A, A1 = form.assemble(sb), form.assemble(p1)
        assert lin @ A @ lin == pytest.approx(lin @ A1 @ lin, rel=ROUNDOFF)
    A = laplace.assemble(sb)
    np.testing.assert_allclose(A @ np.ones(sb.N), 0.0, atol=ROUNDOFF)
    # rows of nodes far from the subdomain are empty
    far = np.flatnonzero(mesh.p[0] > 0.75)
    assert abs(A[far]).sum() == 0.0
    # the two halves add up to the whole mesh
    sr = NaturalNeighbourBasis(mesh, elements=lambda x: x[0] >= 0.5)
    whole = NaturalNeighbourBasis(mesh)
    u = field(*mesh.p)
    assert u @ (laplace.assemble(sb) + laplace.assemble(sr)) @ u == pytest.approx(
        u @ laplace.assemble(whole) @ u, rel=ROUNDOFF)


def test_subdomain_selectors(mesh):
    left = mesh.elements_satisfying(lambda x: x[0] < 0.5)
    mask = np.zeros(mesh.nelements, bool)
    mask[left] = True
    named = mesh.with_subdomains({"left": lambda x: x[0] < 0.5})
    for sel, m in ((lambda x: x[0] < 0.5, mesh), (mask, mesh), (list(left[::-1]), mesh),
                   ("left", named), (["left"], named)):
        b = NaturalNeighbourBasis(m, elements=sel)
        np.testing.assert_array_equal(b.tind, left)
    b = NaturalNeighbourBasis(mesh, elements=left)
    np.testing.assert_array_equal(b.with_elements(mask).tind, left)
    assert b.with_elements().tind is None
    with pytest.raises(ValueError, match=r"element indices must lie in \[0, 128\)"):
        NaturalNeighbourBasis(mesh, elements=[0, 128])
    with pytest.raises(ValueError, match="mask must have 128 entries"):
        NaturalNeighbourBasis(mesh, elements=mask[:-1])
    with pytest.raises(ValueError, match="no such subdomain"):
        NaturalNeighbourBasis(mesh, elements="right")
    with pytest.raises(ValueError, match="selects no element"):
        NaturalNeighbourBasis(mesh, elements=lambda x: x[0] > 2)


def test_subdomain_project_and_plot(mesh):
    sb = NaturalNeighbourBasis(mesh, elements=lambda x: x[0] < 0.5)
    p1 = Basis(mesh, ElementTriP1(), elements=sb.tind)
    lin = lambda x: 1 + x[0] - 2 * x[1]    # noqa: E731
    u, u1 = sb.project(lin), p1.project(lin)
    # a linear field is in both spaces: both projections reproduce it on the subdomain
    inside = np.unique(mesh.t[:, sb.tind])
    np.testing.assert_allclose(u[inside], lin(mesh.p[:, inside]), atol=1e-10)
    np.testing.assert_allclose(u1[inside], lin(mesh.p[:, inside]), atol=1e-10)
    ax = sb.plot(u, nrefs=1)
    tri = tripcolor(ax)._triangulation
    assert tri.triangles.shape[0] == 4 * sb.nelems and tri.x.max() <= 0.5 + ROUNDOFF
    (line,) = sb.draw().lines
    xy = np.asarray(line.get_xydata(), dtype=float)
    assert np.nanmax(xy[:, 0]) == pytest.approx(0.5)


# --------------------------------------------------------------------------
# companion bases
# --------------------------------------------------------------------------

def test_with_element_companions_share_the_quadrature(mesh, basis):
    sb = NaturalNeighbourBasis(mesh, elements=lambda x: x[1] < 0.5)
    gauss = NaturalNeighbourBasis(mesh, npoints=6)
    for nn in (basis, sb, gauss):
        for e in (ElementTriP0(), ElementTriP1(), ElementVector(ElementTriP1()),
                  ElementVector(ElementTriP0())):
            c = nn.with_element(e)
            assert isinstance(c, CellBasis) and c.elem is e
            np.testing.assert_array_equal(c.X, nn.X)
            np.testing.assert_array_equal(c.W, nn.W)
            np.testing.assert_array_equal(c.dx, nn.dx)
            np.testing.assert_array_equal(np.asarray(c.global_coordinates()),
                                          np.asarray(nn.global_coordinates()))
            assert c.nelems == nn.nelems
    # natural-neighbour elements keep giving natural-neighbour bases
    v = basis.with_element(ElementVector(ElementNaturalNeighbour()))
    assert isinstance(v, NaturalNeighbourBasis) and v.N == 2 * mesh.nvertices
    s = sb.with_element(ElementNaturalNeighbour())
    np.testing.assert_array_equal(s.tind, sb.tind)
    from skfem import ElementTetP1
    with pytest.raises(ValueError, match="ElementTetP1"):
        basis.with_element(ElementTetP1())


def test_p0_conductivity_through_with_element(mesh, basis):
    # k = 1 left of x = 1/2, 10 right of it: a P0 field and a Python-coded coefficient
    p0 = basis.with_element(ElementTriP0())
    k = p0.zeros() + 1.0
    k[mesh.elements_satisfying(lambda x: x[0] > 0.5)] = 10.0

    @BilinearForm
    def conduction_p0(u, v, w):
        return w["k"] * dot(grad(u), grad(v))

    @BilinearForm
    def conduction_coded(u, v, w):
        return np.where(w.x[0] > 0.5, 10.0, 1.0) * dot(grad(u), grad(v))

    A0 = conduction_p0.assemble(basis, k=p0.interpolate(k))
    A1 = conduction_coded.assemble(basis)
    assert abs(A0 - A1).max() < ROUNDOFF * abs(A1).max()
    # the same with P1 on the same quadrature
    p1 = Basis(mesh, ElementTriP1(), quadrature=basis.quadrature)
    q0 = p1.with_element(ElementTriP0())
    B0 = conduction_p0.assemble(p1, k=q0.interpolate(k))
    B1 = conduction_coded.assemble(p1)
    assert abs(B0 - B1).max() < ROUNDOFF * abs(B1).max()
    # and the solutions of the two routes agree
    b = LinearForm(lambda v, w: v).assemble(basis)
    D = basis.get_dofs()
    np.testing.assert_allclose(solve(*condense(A0, b, D=D)), solve(*condense(A1, b, D=D)),
                               atol=ROUNDOFF)


def test_projection_onto_companions(mesh, basis):
    f = lambda x: np.sin(3 * x[0]) * x[1]    # noqa: E731
    p0 = basis.with_element(ElementTriP0())
    ref = Basis(mesh, ElementTriP0(), quadrature=basis.quadrature)
    np.testing.assert_allclose(p0.project(f), ref.project(f), atol=ROUNDOFF)
    # a P0 projection of the NEM solution's gradient: the element means of the
    # smoothed gradient
    u = field(*mesh.p)
    gx = p0.project(basis.interpolate(u).grad[0])
    g = basis.interpolate(u).grad[0]
    np.testing.assert_allclose(gx, (g * basis.dx).sum(1) / basis.dx.sum(1), atol=1e-12)
    # mixed mass matrix (P1 companion trial, NEM test) applied to a linear field equals
    # the NEM mass matrix applied to it
    c1 = basis.with_element(ElementTriP1())
    lin = 1 + mesh.p[0] + mesh.p[1]
    np.testing.assert_allclose(mass.assemble(c1, basis) @ lin, mass.assemble(basis) @ lin,
                               atol=ROUNDOFF)


def test_inherent_limits_name_the_alternative(mesh, basis):
    with pytest.raises(TypeError, match=r"Basis\(mesh, element\).*with_element"):
        NaturalNeighbourBasis(mesh, ElementVector(ElementTriP1()))
    with pytest.raises(AttributeError, match="stencil_nodes"):
        basis.element_dofs
    with pytest.raises(NotImplementedError, match="NaturalNeighbourBasis"):
        Basis(mesh, ElementNaturalNeighbour())
    with pytest.raises(NotImplementedError, match="probes"):
        NaturalNeighbourFacetBasis(mesh).trace(np.zeros(mesh.nvertices), lambda p: p)


# --------------------------------------------------------------------------
# no silently ignored keyword: every keyword of scikit-fem's signatures
# --------------------------------------------------------------------------

def _keywords(cls):
    """(method, keyword) of every public method of a scikit-fem basis class whose
    parameter has a default, and ("__init__", keyword) of its constructor."""
    out = set()
    for name in dir(cls):
        fn = getattr(cls, name)
        if (name.startswith("_") and name != "__init__") or not inspect.isfunction(fn):
            continue
        for p in list(inspect.signature(fn).parameters.values())[1:]:
            if p.default is not p.empty and p.kind is p.POSITIONAL_OR_KEYWORD:
                out.add((name, p.name))
    return out


def _cell_checks(mesh, basis):
    """For each keyword: a call with a non-default value and a check of its effect, or
    the error that must name it."""
    from skfem import ElementTriP0 as P0
    from skfem.assembly import Dofs
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTri
    u = field(*mesh.p)
    left = mesh.elements_satisfying(lambda x: x[0] < 0.5)
    X3, W3 = get_quadrature(RefTri, 3)
    p = basis.project(lambda x: x[0], elements=left)
    refuse = {"mapping": mesh.mapping(), "dofs": Dofs(mesh, ElementTriP1())}
    return {
        ("__init__", "intorder"): lambda: NaturalNeighbourBasis(mesh, intorder=3).X.shape[1] == 4,
        ("__init__", "quadrature"): lambda: np.array_equal(
            NaturalNeighbourBasis(mesh, quadrature=(X3, W3)).X, X3),
        ("__init__", "elements"): lambda: NaturalNeighbourBasis(mesh, elements=left).nelems
        == left.size,
        ("__init__", "disable_doflocs"): lambda: not hasattr(NaturalNeighbourBasis(
            mesh, disable_doflocs=True), "doflocs") and hasattr(basis, "doflocs"),
        ("__init__", "mapping"): lambda: _raises(
            lambda: NaturalNeighbourBasis(mesh, mapping=refuse["mapping"]), "mapping"),
        ("__init__", "dofs"): lambda: _raises(
            lambda: NaturalNeighbourBasis(mesh, dofs=refuse["dofs"]), "dofs"),
        ("project", "elements"): lambda: np.all(
            p[np.setdiff1d(np.arange(basis.N), basis.stencil_dofs(left))] == 0),
        ("project", "dtype"): lambda: basis.project(1.0, dtype=np.float32).dtype == np.float32
        and _raises(lambda: basis.project(1.0, dtype=np.complex128), "dtype"),
        ("refinterp", "nrefs"): lambda: basis.refinterp(u, nrefs=1)[0].nelements
        == 4 * mesh.nelements,
        ("refinterp", "Nrefs"): lambda: basis.refinterp(u, Nrefs=0)[0].nelements
        == mesh.nelements,
        ("plot", "visuals"): lambda: _raises(lambda: basis.plot(u, visuals="nothing"),
                                             "visuals"),
        ("plot3", "visuals"): lambda: _raises(lambda: basis.plot3(u, visuals="nothing"),
                                              "visuals"),
        ("draw", "visuals"): lambda: _raises(lambda: basis.draw(visuals="nothing"), "visuals"),
        ("with_elements", "elements"): lambda: basis.with_elements(left).nelems == left.size,
        ("boundary", "facets"): lambda: basis.boundary(facets=[0]).nelems == 1,
        ("boundary", "intorder"): lambda: basis.boundary(intorder=5).X.shape[1] == 3,
        ("boundary", "quadrature"): lambda: basis.boundary(
            quadrature=(np.array([[0.5]]), np.array([1.0]))).X.shape[1] == 1,
        ("get_dofs", "facets"): lambda: basis.get_dofs(facets=[0]).flatten().size == 2,
        ("get_dofs", "elements"): lambda: basis.get_dofs(elements=[0]).flatten().size == 3,
        ("get_dofs", "nodes"): lambda: np.array_equal(basis.get_dofs(nodes=np.array([4])).flatten(),
                                                      [4]),
        ("get_dofs", "skip"): lambda: basis.get_dofs(skip=["u"]).flatten().size == 0,
        ("zeros", "dtype"): lambda: basis.zeros(dtype=np.int32).dtype == np.int32,
        ("ones", "dtype"): lambda: basis.ones(dtype=np.int32).dtype == np.int32,
        ("zero_w", "dtype"): lambda: basis.zero_w(dtype=np.int32).dtype == np.int32,
        ("with_element", "elem"): lambda: isinstance(basis.with_element(P0()), CellBasis),
    }


def _raises(call, name):
    try:
        call()
    except (TypeError, ValueError, NotImplementedError) as err:
        return name in str(err)
    return False


def test_every_cell_basis_keyword_is_supported_or_named(mesh, basis):
    checks = _cell_checks(mesh, basis)
    missing = _keywords(CellBasis) - set(checks)
    assert not missing, f"scikit-fem keywords without a check: {sorted(missing)}"
    failed = [k for k, check in checks.items() if not check()]
    assert not failed, f"keywords ignored or errors not naming them: {failed}"


def _sides_differ(mesh):
    """side=1 takes the smoothed gradients from the cell on the other side of the facets."""
    inner = np.flatnonzero(mesh.f2t[1] >= 0)
    u = field(*mesh.p) ** 2
    g0, g1 = (NaturalNeighbourFacetBasis(mesh, facets=inner, side=s).interpolate(u).grad
              for s in (0, 1))
    return not np.allclose(g0, g1)


def test_every_facet_basis_keyword_is_supported_or_named(mesh):
    fb = NaturalNeighbourFacetBasis(mesh)
    left = mesh.facets_satisfying(lambda x: x[0] == 0)
    from skfem.assembly import Dofs
    checks = {
        ("__init__", "intorder"): lambda: NaturalNeighbourFacetBasis(
            mesh, intorder=5).X.shape[1] == 3,
        ("__init__", "quadrature"): lambda: NaturalNeighbourFacetBasis(
            mesh, quadrature=(np.array([[0.5]]), np.array([1.0]))).X.shape[1] == 1,
        ("__init__", "facets"): lambda: NaturalNeighbourFacetBasis(
            mesh, facets=left).nelems == left.size,
        ("__init__", "side"): lambda: _sides_differ(mesh),
        ("__init__", "disable_doflocs"): lambda: not hasattr(NaturalNeighbourFacetBasis(
            mesh, disable_doflocs=True), "doflocs") and hasattr(fb, "doflocs"),
        ("__init__", "mapping"): lambda: _raises(
            lambda: NaturalNeighbourFacetBasis(mesh, mapping=mesh.mapping()), "mapping"),
        ("__init__", "dofs"): lambda: _raises(
            lambda: NaturalNeighbourFacetBasis(mesh, dofs=Dofs(mesh, ElementTriP1())), "dofs"),
        ("project", "facets"): lambda: np.count_nonzero(fb.project(1.0, facets=left)) == 9,
        ("project", "dtype"): lambda: _raises(lambda: fb.project(1.0, dtype=complex),
                                              "dtype"),
        ("trace", "target_elem"): lambda: _raises(
            lambda: fb.trace(np.zeros(fb.N), lambda p: p, target_elem=ElementTriP1()),
            "probes"),
        ("plot", "visuals"): lambda: _raises(lambda: fb.plot(np.zeros(fb.N)),
                                             "NaturalNeighbourBasis"),
        ("plot3", "visuals"): lambda: _raises(lambda: fb.plot3(np.zeros(fb.N)),
                                              "NaturalNeighbourBasis"),
        ("draw", "visuals"): lambda: _raises(lambda: fb.draw(), "NaturalNeighbourBasis"),
        ("get_dofs", "facets"): lambda: fb.get_dofs(facets=left).flatten().size == 9,
        ("get_dofs", "elements"): lambda: fb.get_dofs(elements=[0]).flatten().size == 3,
        ("get_dofs", "nodes"): lambda: fb.get_dofs(nodes=np.array([4])).flatten().size == 1,
        ("get_dofs", "skip"): lambda: fb.get_dofs(skip=["u"]).flatten().size == 0,
        ("zeros", "dtype"): lambda: fb.zeros(dtype=np.int32).dtype == np.int32,
        ("ones", "dtype"): lambda: fb.ones(dtype=np.int32).dtype == np.int32,
        ("zero_w", "dtype"): lambda: fb.zero_w(dtype=np.int32).dtype == np.int32,
    }
    missing = _keywords(FacetBasis) - set(checks)
    assert not missing, f"scikit-fem keywords without a check: {sorted(missing)}"
    failed = [k for k, check in checks.items() if not check()]
    assert not failed, f"keywords ignored or errors not naming them: {failed}"


# --------------------------------------------------------------------------
# meshes as scikit-fem's examples build them: boundary nodes on the hull only to
# round-off, interfaces inside the mesh, meshes with nodes of other cells
# --------------------------------------------------------------------------

def quarter_annulus():
    """A tensor mesh in (r, theta) mapped to the quarter annulus 1 < r < 2: its straight
    sides are straight only to round-off, its inner arc is concave, and it is not Delaunay."""
    m = MeshTri.init_tensor(np.linspace(1, 2, 11), np.linspace(0, np.pi / 2, 24)).with_boundaries(
        {"ground": lambda x: x[1] == 0.0, "positive": lambda x: x[1] == np.pi / 2})
    return m.translated(m.p[0] * np.stack([np.cos(m.p[1]), np.sin(m.p[1])]) - m.p).refined()


def test_facet_basis_on_a_side_straight_to_round_off():
    # the facet points of the side x = 0 (nodes at x = 0 or a few 1e-16) are inside
    m = quarter_annulus()
    for name in ("ground", "positive"):
        fb = NaturalNeighbourFacetBasis(m, facets=name)
        p1 = FacetBasis(m, ElementTriP1(), facets=name)
        np.testing.assert_allclose(fb.project(lambda x: x[0] + 2 * x[1]),
                                   p1.project(lambda x: x[0] + 2 * x[1]), atol=1e-12)
    # Laplace with u = 2 theta / pi: the flux through the two ports balances, as P1's
    basis = NaturalNeighbourBasis(m)
    u = basis.zeros()
    u[basis.get_dofs("positive")] = 1.0
    A = BilinearForm(lambda u, v, w: dot(grad(u), grad(v))).assemble(basis)
    u = solve(*condense(A, x=u, D=basis.get_dofs({"positive", "ground"})))
    flux = Functional(lambda w: dot(w.n, grad(w["u"])))
    current = [flux.assemble(NaturalNeighbourFacetBasis(m, facets=n), u=u)
               for n in ("ground", "positive")]
    exact = 2 * np.log(2) / np.pi
    assert abs(current[0] + exact) < 0.02 and abs(current[1] - exact) < 0.02


def test_plot_and_probes_on_boundary_points_of_a_refined_disk():
    # refining a disk puts the new boundary nodes on the chords, to round-off; the
    # plotting mesh's boundary points are inside the domain
    m = MeshTri.init_circle(2).refined()
    basis = NaturalNeighbourBasis(m)
    u = basis.project(lambda x: x[0] * x[1])
    ax = skplot.plot(basis, u)
    tp = tripcolor(ax)
    assert np.isfinite(tp.get_array()).all()
    M, v = basis.refinterp(u, nrefs=2)
    np.testing.assert_allclose(v, M.p[0] * M.p[1], atol=0.05)
    b = m.facets[:, m.boundary_facets()]
    mid = m.p[:, b].mean(axis=1)
    np.testing.assert_allclose(basis.probes(mid) @ u, mid[0] * mid[1], atol=0.05)
    with pytest.raises(ValueError, match="outside"):
        basis.probes(np.array([[1.5], [0.0]]))


def test_facet_project_on_an_interface_gives_the_nodal_values():
    # interior facets (the surface of a conductor inside the mesh): functions of nodes off
    # the facets are non-zero there too; the facets' nodes get P1's values
    m = MeshTri().refined(3)
    inner = m.facets_satisfying(lambda x: np.isclose(x[0], 0.5))
    assert inner.size == 8 and np.all(m.f2t[1, inner] >= 0)      # interior facets
    fb = NaturalNeighbourFacetBasis(m, facets=inner)
    p1 = FacetBasis(m, ElementTriP1(), facets=inner)
    np.testing.assert_allclose(fb.project(0.5), p1.project(0.5), atol=1e-12)
    nodes = np.unique(m.facets[:, inner])
    np.testing.assert_allclose(fb.project(0.5)[nodes], 0.5, atol=1e-12)
    assert np.count_nonzero(fb.project(0.5)) == nodes.size


def test_unused_nodes_and_elementwise_quadrature_name_the_alternative():
    m = MeshTri().refined(2)
    extra = MeshTri(np.c_[m.p, [[2.0], [2.0]]], m.t)
    with pytest.raises(ValueError, match=r"node 25 .* belongs to no triangle.*remove_unused_nodes"):
        NaturalNeighbourBasis(extra)
    with pytest.raises(ValueError, match=r"belongs to no triangle"):
        NaturalNeighbourFacetBasis(extra)
    X = np.full((2, m.nelements, 3), 1 / 3)
    W = np.full((m.nelements, 3), 1 / 6)
    with pytest.raises(ValueError, match=r"rule per element.*interpolator"):
        NaturalNeighbourBasis(m, quadrature=(X, W))


def test_nonlinear_form_assembles_over_the_groups():
    # skfem.autodiff (JAX) linearises an energy; on a natural-neighbour basis it is assembled
    # group by group. The minimal-surface Jacobian and residual equal the ones of
    # hand-written forms.
    pytest.importorskip("jax")
    import jax.numpy as jnp
    from skfem.autodiff import NonlinearForm
    from skfem.autodiff.helpers import dot as jdot
    from skfem.autodiff.helpers import grad as jgrad

    @NonlinearForm(hessian=True)
    def energy(u, _):
        return jnp.sqrt(1.0 + jdot(jgrad(u), jgrad(u)))

    m = MeshTri().refined(3)
    basis = NaturalNeighbourBasis(m)
    x = np.sin(np.pi * m.p[0]) * m.p[1]
    J, F = energy.assemble(basis, x=x)

    @BilinearForm
    def jacobian(u, v, w):
        g = grad(w["x"])
        q = 1 + dot(g, g)
        return dot(grad(u), grad(v)) / np.sqrt(q) - dot(grad(u), g) * dot(g, grad(v)) / q ** 1.5

    @LinearForm
    def residual(v, w):
        g = grad(w["x"])
        return -dot(g, grad(v)) / np.sqrt(1 + dot(g, g))

    np.testing.assert_allclose(J.toarray(), jacobian.assemble(basis, x=x).toarray(), atol=1e-10)
    np.testing.assert_allclose(F, residual.assemble(basis, x=x), atol=1e-10)
