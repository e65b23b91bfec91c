"""Consistent integration (gradient smoothing, the default NEM): the
integration constraint, patch tests to round-off in 2D and 3D, optimal rates
for Poisson and Stokes, no spurious flow from a uniform prestress."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import (Basis, BilinearForm, ElementTriP1, ElementVector, Functional, LinearForm,
                   condense, solve)
from skfem.helpers import dot, grad
from skfem.models.elasticity import lame_parameters, linear_elasticity

from conftest import load_example
from helpers import cube_nodes, laplace
from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis,
                       NaturalNeighbourFacetBasis, delaunay_mesh)
from skfem_nem.models.analytic import DoneaHuerta
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.stokes import solve_stokes, stokes_spaces

#: patch-test bound on the largest nodal error relative to the largest value
PATCH_TOL = 1e-10


def graded(n, seed=0):
    """Density 1 / (|y - 1/2| + 0.01) + 2 (the paper's Fig. 6 grading), scaled to (0, 1]."""
    return box_nodes(n, density=lambda x: (1.0 / (np.abs(x[:, 1] - 0.5) + 0.01) + 2.0) / 102.0,
                     seed=seed)


def thin(nx=41, ny=5, seed=0):
    """A jittered nx x ny grid: needle and sliver triangles (aspect ratio ~10)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny))
    x, y = x.ravel(), y.ravel()
    dx = 1.0 / (nx - 1)
    x = x + ((x > 0) & (x < 1)) * 0.3 * dx * rng.uniform(-1, 1, x.size)
    y = y + ((y > 0) & (y < 1)) * 0.3 * dx * rng.uniform(-1, 1, y.size)
    return np.c_[x, y]


NODE_SETS = {"random": lambda: box_nodes(2000, seed=4), "graded": lambda: graded(2000),
             "thin": thin}


# ---------------------------------------------------------------------------
# the integration constraint and linear exactness, on random point sets
# ---------------------------------------------------------------------------

@settings(max_examples=15, deadline=None)
@given(n=st.integers(12, 80), seed=st.integers(0, 2 ** 31 - 1),
       coordinates=st.sampled_from(["sibson", "laplace"]))
def test_integration_constraint_and_linear_exactness(n, seed, coordinates):
    p = box_nodes(n, seed=seed)
    mesh = delaunay_mesh(p)
    b = NaturalNeighbourBasis(mesh, coordinates=coordinates)
    assert b.integration == "smoothed"
    interior = np.setdiff1d(np.arange(mesh.nvertices), mesh.boundary_nodes())
    for k in range(2):
        # sum_q w_q b_I(x_q) = boundary integral of phi_I n = 0 inside
        col = LinearForm(lambda v, w, k=k: v.grad[k]).assemble(b)
        assert np.abs(col[interior]).max() < 1e-12
        # smoothed gradients of the coordinate functions are exact
        for j in range(2):
            assert np.abs(b.interpolate(p[:, j]).grad[k] - (j == k)).max() < 1e-11
    x = np.asarray(b.global_coordinates())
    assert np.abs(np.asarray(b.interpolate(p[:, 0])) - x[0]).max() < 1e-12


# ---------------------------------------------------------------------------
# patch tests
# ---------------------------------------------------------------------------

def laplace_patch_error(basis, p, integration=None):
    lin = 1.0 + 2.0 * p[:, 0] + 3.0 * p[:, 1] - (p[:, 2] if p.shape[1] == 3 else 0.0)
    A = laplace.assemble(basis)
    u = solve(*condense(A, np.zeros(basis.N), x=lin, D=basis.get_dofs()))
    return np.abs(u - lin).max() / np.abs(lin).max()


def elasticity_patch_error(basis, p):
    d = p.shape[1]
    G = np.arange(1.0, d * d + 1).reshape(d, d) / (d * d)
    exact = (0.1 + p @ G.T)                                  # (n, d)
    x = np.zeros(basis.N)
    nd = basis.dofs.nodal_dofs
    for c in range(d):
        x[nd[c]] = exact[:, c]
    A = linear_elasticity(*lame_parameters(1e3, 0.3)).assemble(basis)
    u = solve(*condense(A, np.zeros(basis.N), x=x, D=basis.get_dofs()))
    return np.abs(u - x).max() / np.abs(x).max()


@pytest.mark.parametrize("nodes", sorted(NODE_SETS))
def test_patch_tests_2d_pass_to_round_off(nodes):
    p = NODE_SETS[nodes]()
    mesh = delaunay_mesh(p)
    assert laplace_patch_error(NaturalNeighbourBasis(mesh), p) < PATCH_TOL
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    assert elasticity_patch_error(vb, p) < PATCH_TOL
    # the Gauss 3-point rule does not pass (it is what smoothing replaces)
    gauss = NaturalNeighbourBasis(mesh, integration="gauss")
    assert gauss.integration == "gauss"
    assert laplace_patch_error(gauss, p) > 1e-5


def test_patch_tests_laplace_coordinates_and_box1():
    p = box_nodes(400, seed=2)
    mesh = delaunay_mesh(p)
    assert laplace_patch_error(NaturalNeighbourBasis(mesh, coordinates="laplace"), p) < PATCH_TOL
    assert laplace_patch_error(NaturalNeighbourBasis(mesh, method="lasserre"), p) < PATCH_TOL


def test_patch_tests_3d_pass_to_round_off():
    p = cube_nodes(300, per_face=25)
    mesh = delaunay_mesh(p)
    assert laplace_patch_error(NaturalNeighbourBasis(mesh), p) < PATCH_TOL
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    assert elasticity_patch_error(vb, p) < PATCH_TOL
    assert laplace_patch_error(NaturalNeighbourBasis(mesh, intorder=2), p) > 1e-4


def test_nitsche_patch_test_with_the_facet_basis():
    """Dirichlet data by Nitsche's method: the facet basis's gradients are the
    smoothed ones of the cells at the boundary, so the linear field is
    reproduced; with Gauss gradients on both it is not."""
    p = box_nodes(600, seed=7)
    mesh = delaunay_mesh(p)
    g = lambda x: 1.0 + 2.0 * x[0] + 3.0 * x[1]  # noqa: E731

    @BilinearForm
    def nitsche(u, v, w):
        return (-dot(grad(u), w.n) * v - dot(grad(v), w.n) * u + 10.0 / w.h * u * v)

    @LinearForm
    def data(v, w):
        return -dot(grad(v), w.n) * g(w.x) + 10.0 / w.h * g(w.x) * v

    def error(integration):
        rule = {"npoints": 3} if integration == "gauss" else {}
        b = NaturalNeighbourBasis(mesh, **rule)
        fb = NaturalNeighbourFacetBasis(mesh, facets=mesh.boundary_facets(),
                                        integration=integration)
        A = laplace.assemble(b) + nitsche.assemble(fb)
        u = solve(A, data.assemble(fb))
        return np.abs(u - g(p.T)).max() / np.abs(g(p.T)).max()

    assert error("smoothed") < PATCH_TOL
    assert error("gauss") > 1e-5


# ---------------------------------------------------------------------------
# convergence
# ---------------------------------------------------------------------------

def _u(x):
    return np.sin(np.pi * x[0]) * np.sin(np.pi * x[1])


@LinearForm
def _load(v, w):
    return 2.0 * np.pi ** 2 * _u(w.x) * v


@Functional
def _l2(w):
    return (w["uh"] - _u(w.x)) ** 2


@Functional
def _h1(w):
    x = w.x
    g = w["uh"].grad - np.pi * np.stack([np.cos(np.pi * x[0]) * np.sin(np.pi * x[1]),
                                         np.sin(np.pi * x[0]) * np.cos(np.pi * x[1])])
    return g[0] ** 2 + g[1] ** 2


def poisson_errors(mesh, basis):
    u = solve(*condense(laplace.assemble(basis), _load.assemble(basis), D=basis.get_dofs()))
    ref = (NaturalNeighbourBasis(mesh, npoints=7) if hasattr(basis, "integration")
           else Basis(mesh, basis.elem, intorder=6))
    uh = ref.interpolate(u)
    return np.sqrt(_l2.assemble(ref, uh=uh)), np.sqrt(_h1.assemble(ref, uh=uh))


def rates(n, e):
    return -2.0 * np.diff(np.log(e)) / np.diff(np.log(n))


@pytest.mark.parametrize("kind", ["uniform", "graded"])
def test_poisson_rates_optimal_and_errors_below_p1(kind):
    """The node sets of docs/verification.md (examples/ex04_nem_vs_fem.py)."""
    node_set = load_example("ex04_nem_vs_fem").node_set
    nem, p1, nodes = [], [], []
    for n in [250, 1000, 4000, 16000, 64000]:
        p = node_set(kind, n)
        mesh = delaunay_mesh(p)
        nodes.append(len(p))
        nem.append(poisson_errors(mesh, NaturalNeighbourBasis(mesh)))
        p1.append(poisson_errors(mesh, Basis(mesh, ElementTriP1())))
    nem, p1 = np.array(nem), np.array(p1)
    assert rates(nodes, nem[:, 0]).min() >= 1.9, nem[:, 0]
    assert rates(nodes, nem[:, 1]).min() >= 0.95, nem[:, 1]
    assert (nem <= p1).all(), (nem, p1)


@Functional
def _stokes_l2u(w):
    d = w["u"] - DoneaHuerta.velocity(w.x)
    return d[0] ** 2 + d[1] ** 2


@Functional
def _stokes_l2p(w):
    return (w["p"] - DoneaHuerta.pressure(w.x)) ** 2


def test_stokes_donea_huerta_rates():
    sizes, eu, ep = [], [], []
    for n in [500, 2000, 8000, 32000]:
        mesh = delaunay_mesh(box_nodes(n, seed=1))
        sizes.append(mesh.nvertices)
        s = solve_stokes(stokes_spaces(mesh), 1.0, DoneaHuerta.force, free_slip=None,
                         no_slip="all", tol=1e-12)
        vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()), npoints=7)
        pb = Basis(mesh, ElementTriP1(), intorder=4)
        eu.append(np.sqrt(_stokes_l2u.assemble(vb, u=vb.interpolate(s.u))))
        ep.append(np.sqrt(_stokes_l2p.assemble(pb, p=pb.interpolate(s.p))))
    assert rates(sizes, eu).min() >= 1.9, eu
    # P1 pressure of a MINI-type pair converges like h in theory; pairwise
    # rates on independent random node sets scatter by about 0.1 around it
    # (measured 0.94-1.24 over three seeds; scikit-fem's MINI on the same
    # meshes 0.94-1.20, with 3.5 times larger errors)
    assert rates(sizes, ep).min() >= 0.95, ep
    assert -2.0 * np.polyfit(np.log(sizes), np.log(ep), 1)[0] >= 1.0, ep


def test_uniform_prestress_drives_no_flow():
    mesh = delaunay_mesh(box_nodes(800, seed=3))
    sp_ = stokes_spaces(mesh)
    tau0 = np.array([[0.3, 0.2], [0.2, -0.1]])[:, :, None, None] + np.zeros(
        (2, 2) + sp_.ubasis.dx.shape)
    s = solve_stokes(sp_, 1.0, 0.0, tau0=tau0, free_slip=None, no_slip="all", tol=1e-13)
    assert np.abs(s.u).max() < 1e-10
    gauss = solve_stokes(stokes_spaces(mesh, npoints=3), 1.0, 0.0, tau0=tau0, free_slip=None,
                         no_slip="all", tol=1e-13)
    assert np.abs(gauss.u).max() > 1e-6


def test_integration_keywords_checked():
    mesh = delaunay_mesh(box_nodes(50, seed=0))
    with pytest.raises(ValueError, match="npoints"):
        NaturalNeighbourBasis(mesh, npoints=7, integration="smoothed")
    with pytest.raises(ValueError, match="integration"):
        NaturalNeighbourBasis(mesh, integration="nodal")
    with pytest.raises(ValueError, match="integration"):
        NaturalNeighbourFacetBasis(mesh, integration="exact")
    with pytest.raises(ValueError, match="Taylor-Hood"):
        stokes_spaces(mesh, "taylor-hood", integration="smoothed")
    assert NaturalNeighbourBasis(mesh, npoints=7).integration == "gauss"
    b = NaturalNeighbourBasis(mesh)
    assert b.with_element(ElementVector(ElementNaturalNeighbour())).integration == "smoothed"
