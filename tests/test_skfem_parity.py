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
