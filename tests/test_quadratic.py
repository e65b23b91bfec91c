"""Quadratic natural-neighbour functions (``ElementNaturalNeighbour2``).

The coordinates in quadratic Bernstein form reproduce quadratic fields on any node
set, plain or constrained (:mod:`skfem_nem.basis.quadratic`); with the linear smoothed
gradients of :mod:`skfem_nem.basis.smoothing_quadratic` the Galerkin solution of a
problem whose solution is quadratic (on each side of an interface carried by segments)
is that solution to round-off, and Stokes flow with a quadratic (two-layer Poiseuille)
profile is reproduced exactly.
"""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import BilinearForm, LinearForm, MeshTet, condense, solve
from skfem.element import ElementVector
from skfem.helpers import dot, grad

from skfem_nem import ElementNaturalNeighbour2, NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.basis.quadratic import distinct_pairs, lift
from skfem_nem.coordinates import natural_neighbour_coordinates
from skfem_nem.models.stokes import solve_stokes, stokes_spaces

from test_constrained_stokes import layered_nodes


def quadratic(c):
    """The quadratic c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 and its gradient."""
    def f(x, y):
        return c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y

    def g(x, y):
        return np.stack([c[1] + 2 * c[3] * x + c[4] * y, c[2] + c[4] * x + 2 * c[5] * y])
    return f, g


def dof_values(basis, f):
    """The dofs of f: its values at the nodes and at the edges' midpoints."""
    return f(*basis.doflocs)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(8, 60))
def test_hypothesis_reproduces_quadratics(seed, n):
    rng = np.random.default_rng(seed)
    p = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((n, 2))]
    mesh = delaunay_mesh(p)
    f, g = quadratic(rng.normal(size=6))
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2(), npoints=7)
    u = dof_values(basis, f)
    field = basis.interpolate(u)
    x = basis.global_coordinates()
    assert np.abs(np.asarray(field) - f(*x)).max() < 1e-11
    # (the exact gradients of the coordinates themselves carry round-off up to 4e-10 next
    # to nearly co-circular nodes)
    assert np.abs(field.grad - g(*x)).max() < 1e-8
    # at random points (probes) and with the smoothed gradients (exact for quadratics)
    q = rng.random((2, 50))
    assert np.abs(basis.probes(q) @ u - f(*q)).max() < 1e-11
    smoothed = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    x = smoothed.global_coordinates()
    err = ((smoothed.interpolate(u).grad - g(*x)) ** 2).sum(axis=0)
    # a smoothed gradient is a boundary integral over the triangle's area: its round-off
    # is about eps max|u| L_T / |T|, so in L2 (as the forms see it) eps max|u| times
    # sqrt(sum_T L_T^2 / |T|); measured up to 830 times that on slivers of random points
    P = mesh.p[:, mesh.t]
    perimeter2 = sum(((P[:, i] - P[:, (i + 1) % 3]) ** 2).sum(axis=0) for i in range(3))
    roundoff = np.finfo(float).eps * np.abs(u).max() * np.sqrt(
        (perimeter2 / smoothed.dx.sum(axis=1)).sum())
    assert np.sqrt((err * smoothed.dx).sum()) < 1e4 * roundoff


def test_functions_partition_unity_and_numbering():
    rng = np.random.default_rng(3)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((40, 2))])
    Phi = natural_neighbour_coordinates(mesh.p.T, rng.random((30, 2)))
    Q, G = lift(mesh, Phi)
    assert Q.shape == (30, mesh.p.shape[1] + mesh.facets.shape[1]) and G.shape == (0, Q.nnz)
    assert np.allclose(Q.sum(axis=1), 1.0, atol=1e-13)
    vec = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()))
    nv = mesh.p.shape[1]
    assert vec.N == 2 * (nv + mesh.facets.shape[1])
    # scikit-fem's numbering of ElementVector(ElementTriP2()): nodes, then edges
    assert np.array_equal(vec.function_dofs[:, :nv], vec.dofs.nodal_dofs)
    assert np.array_equal(vec.function_dofs[:, nv:], vec.dofs.facet_dofs)


@BilinearForm
def diffusion(u, v, w):
    return w.k * dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return w.f * v


def interface_solution(x, y):
    """k = 1 for y < 1/2, 10 beyond: u quadratic on each side, continuous, with a
    continuous flux k du/dy at y = 1/2 (a kink); -div(k grad u) = -4 and -22."""
    return np.where(y <= 0.5, x * x + y * y, 0.25 + x * x + (y * y - 0.25) / 10)


@pytest.mark.parametrize("seed", [0, 1])
def test_interface_patch_test_quadratic(seed):
    pts, seg = layered_nodes(200, seed)
    mesh = delaunay_mesh(pts, segments={"interface": seg})
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    y = basis.global_coordinates()[1]
    k, f = np.where(y > 0.5, 10.0, 1.0), np.where(y > 0.5, -22.0, -4.0)
    A, b = diffusion.assemble(basis, k=k), load.assemble(basis, f=f)
    exact = interface_solution(*basis.doflocs)
    # the edges' dofs are midpoint values only on the boundary and the interface: the
    # solution's dofs are those of the interpolant, which reproduces it
    D = basis.get_dofs().all()
    u = solve(*condense(A, b, x=exact, D=D))
    probe = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2(), npoints=7)
    x = probe.global_coordinates()
    err = np.asarray(probe.interpolate(u)) - interface_solution(*x)
    assert np.abs(err).max() < 1e-10
    assert np.abs(u[: mesh.p.shape[1]] - exact[: mesh.p.shape[1]]).max() < 1e-10
    # without the segments the functions are smooth across the interface: no kink
    plain = NaturalNeighbourBasis(delaunay_mesh(pts), ElementNaturalNeighbour2())
    y = plain.global_coordinates()[1]
    A = diffusion.assemble(plain, k=np.where(y > 0.5, 10.0, 1.0))
    b = load.assemble(plain, f=np.where(y > 0.5, -22.0, -4.0))
    u = solve(*condense(A, b, x=interface_solution(*plain.doflocs),
                        D=plain.get_dofs().all()))
    nv = mesh.p.shape[1]
    assert np.abs(u[:nv] - interface_solution(*mesh.p)).max() > 1e-4


def poiseuille(y, ratio):
    """Two-layer Poiseuille profile U(y): viscosity 1 below y = 1/2, ``ratio`` above,
    body force (1, 0), U(0) = U(1) = 0; -(eta U')' = 1, U and eta U' continuous."""
    # U = -y^2 / (2 eta) + a y + b on each layer; unknowns a1, b1, a2, b2
    M = np.array([[0, 1, 0, 0], [0, 0, 1, 1], [0.5, 1, -0.5, -1], [1, 0, -ratio, 0]])
    r = np.array([0, 1 / (2 * ratio), 0.125 - 0.125 / ratio, 0.5 - 0.5])
    a1, b1, a2, b2 = np.linalg.solve(M, r)
    return np.where(y <= 0.5, -y * y / 2 + a1 * y + b1, -y * y / (2 * ratio) + a2 * y + b2)


@pytest.mark.parametrize("ratio", [1e3, 1e-3])
def test_two_layer_poiseuille_exact(ratio):
    pts, seg = layered_nodes(250, 0)
    mesh = delaunay_mesh(pts, segments={"interface": seg})
    spaces = stokes_spaces(mesh, "nem2")
    assert spaces.bubbles is None and not spaces.stabilised
    dofs = spaces.ubasis.get_dofs()
    ux, uy = dofs.all("u^1"), dofs.all("u^2")
    y = spaces.ubasis.doflocs[1]
    walls = (np.r_[ux, uy], np.r_[poiseuille(y[ux], ratio), 0 * uy])
    s = solve_stokes(spaces, lambda x: np.where(x[1] > 0.5, ratio, 1.0),
                     lambda x: np.stack([np.ones_like(x[0]), 0 * x[0]]),
                     free_slip=None, prescribed=walls, tol=1e-13)
    v = s.velocity_at_nodes()
    scale = np.abs(poiseuille(mesh.p[1], ratio)).max()
    assert np.abs(v[:, 0] - poiseuille(mesh.p[1], ratio)).max() < 1e-9 * scale
    assert np.abs(v[:, 1]).max() < 1e-9 * scale
    assert np.ptp(s.pressure_at_nodes()) < 1e-7 * max(1.0, ratio)


def test_quadratic_element_refusals():
    rng = np.random.default_rng(0)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((20, 2))])
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    with pytest.raises(ValueError, match="edges"):
        basis.updated(mesh)
    with pytest.raises(NotImplementedError, match="quadratic"):
        basis.boundary()
    with pytest.raises(ValueError, match="triangles only"):
        NaturalNeighbourBasis(MeshTet(), ElementNaturalNeighbour2())


def test_projection_and_plot_values_reproduce_a_quadratic():
    rng = np.random.default_rng(5)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((60, 2))])
    f, _ = quadratic(rng.normal(size=6))
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    u = basis.project(lambda x: f(*x))
    assert np.abs(u - dof_values(basis, f)).max() < 1e-9
    refined, values = basis.refinterp(u, nrefs=2)
    assert np.abs(values - f(*refined.p)).max() < 1e-10
    vec = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()))
    w = vec.project(lambda x: np.stack([f(*x), 2 * f(*x)]))
    field = vec.interpolate(w)
    x = vec.global_coordinates()
    assert np.abs(np.asarray(field) - np.stack([f(*x), 2 * f(*x)])).max() < 1e-9


def test_subdomain_bases_add_up_to_the_whole():
    rng = np.random.default_rng(7)
    mesh = delaunay_mesh(np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((50, 2))])
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    left = np.flatnonzero(mesh.p[0, mesh.t].mean(axis=0) < 0.5)
    right = np.setdiff1d(np.arange(mesh.nelements), left)
    k = np.ones(basis.dx.shape)
    whole = diffusion.assemble(basis, k=k)
    parts = sum(diffusion.assemble(basis.with_elements(e), k=np.ones((e.size, 3)))
                for e in (left, right))
    assert abs(whole - parts).max() < 1e-12 * abs(whole).max()


@settings(max_examples=40, deadline=None)
@given(rows=st.lists(st.lists(st.integers(0, 40), min_size=0, max_size=8), min_size=1,
                     max_size=30))
def test_distinct_pairs_are_numpys_unique(rows):
    """The node pairs of every two entries of each row of a coordinates matrix, numbered
    as np.unique numbers their keys lo * nodes + hi (the inverse too), rows of any length,
    repeated columns across rows."""
    nv = 41
    indptr = np.r_[0, np.cumsum([len(r) for r in rows])].astype(np.int64)
    indices = np.array([c for r in rows for c in r], dtype=np.int64)
    first, second = (np.array(e, dtype=np.int64).reshape(-1) for e in zip(
        *[(a, b) for r in range(len(rows)) for a in range(indptr[r], indptr[r + 1])
          for b in range(a, indptr[r + 1])] or [((), ())]))
    i, j = indices[first], indices[second]
    keys, inverse = distinct_pairs(indices, first, second, nv)
    want, want_inverse = np.unique(np.minimum(i, j) * nv + np.maximum(i, j),
                                   return_inverse=True)
    assert np.array_equal(keys, want) and np.array_equal(inverse, want_inverse)
