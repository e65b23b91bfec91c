"""The two-level solver of the quadratic natural-neighbour matrices (basis.two_level): the
nested prolongation reproduces the linear functions, the solver agrees with a direct solve
through scikit-fem's ``solve`` (scalar and vector), and bad input is refused by name."""
import numpy as np
import pytest
from skfem import BilinearForm, ElementVector, LinearForm, condense, solve
from skfem.helpers import dot, grad
from skfem.models.elasticity import linear_elasticity

from skfem_nem import (ElementNaturalNeighbour, ElementNaturalNeighbour2, NaturalNeighbourBasis,
                       delaunay_mesh, natural_neighbour_solver)
from skfem_nem.basis.two_level import TwoLevelPreconditioner, nested_prolongation
from skfem_nem.geometry.nodesets import box_nodes


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return np.sin(3 * w.x[0]) * np.exp(w.x[1]) * v


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(box_nodes(400, seed=2))


@pytest.fixture(scope="module")
def basis(mesh):
    return NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())


def test_the_prolongation_interpolates_and_reproduces_linear_fields(mesh, basis):
    """P times nodal values is a quadratic function through those values at the nodes, and
    the linear field itself where they are a linear field's (not the linear natural-neighbour
    function of any values: pairs of natural neighbours without an edge take their polar
    values through a triangle)."""
    P = nested_prolongation(basis)
    u = np.random.default_rng(0).normal(size=mesh.p.shape[1])
    assert np.abs(basis.probes(mesh.p) @ (P @ u) - u).max() < 1e-12 * np.abs(u).max()
    x = mesh.p[:, mesh.t].mean(axis=1)
    field = 0.3 + 1.7 * mesh.p[0] - 0.9 * mesh.p[1]
    q = basis.probes(x) @ (P @ field)
    assert np.abs(q - (0.3 + 1.7 * x[0] - 0.9 * x[1])).max() < 1e-12
    lin = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour())
    assert np.abs(basis.probes(x) @ (P @ u) - lin.probes(x) @ u).max() > 1e-3


def test_solves_poisson_through_scikit_fem_solve(basis):
    A, b = laplace.assemble(basis), load.assemble(basis)
    D = basis.get_dofs().all()
    x0 = np.zeros(basis.N)
    x0[D] = basis.doflocs[0, D]                  # nonzero Dirichlet data
    s = natural_neighbour_solver(basis, D, tol=1e-11)
    x = solve(*condense(A, b, x=x0, D=D), solver=s)
    ref = solve(*condense(A, b, x=x0, D=D))
    assert np.abs(x - ref).max() < 1e-8 * np.abs(ref).max()
    assert 0 < s.iterations < 60


def test_solves_elasticity(mesh):
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()))
    K = linear_elasticity(1.0, 0.5).assemble(vb)

    @LinearForm
    def gravity(v, w):
        return -v[1]

    f = gravity.assemble(vb)
    D = vb.get_dofs(lambda x: x[0] < 1e-12).all()
    s = natural_neighbour_solver(vb, D, tol=1e-11)
    x = solve(*condense(K, f, D=D), solver=s)
    ref = solve(*condense(K, f, D=D))
    assert np.abs(x - ref).max() < 1e-8 * np.abs(ref).max()
    assert s.iterations < 200


def test_the_coarse_level_of_the_preconditioner(basis):
    """With a direct coarse solve the preconditioner is symmetric: (M a) . b == a . (M b)."""
    A = laplace.assemble(basis)
    free = basis.complement_dofs(basis.get_dofs().all())
    P = nested_prolongation(basis)[free][:, np.isin(basis.nodal_dofs[0], free)]
    M = TwoLevelPreconditioner(A[free][:, free], P, coarse="direct")
    a, c = np.random.default_rng(1).normal(size=(2, free.size))
    assert abs(M(a) @ c - a @ M(c)) < 1e-10 * abs(M(a) @ c)


def test_refuses_bad_input_by_name(mesh, basis):
    with pytest.raises(ValueError, match="ElementNaturalNeighbour2"):
        nested_prolongation(NaturalNeighbourBasis(mesh, ElementNaturalNeighbour()))
    with pytest.raises(ValueError, match="cycle"):
        TwoLevelPreconditioner(laplace.assemble(basis), nested_prolongation(basis),
                               cycle="W")
    with pytest.raises(ValueError, match="tol"):
        natural_neighbour_solver(basis, tol=2.0)
    A, b = laplace.assemble(basis), load.assemble(basis)
    D = basis.get_dofs().all()
    s = natural_neighbour_solver(basis, D)
    with pytest.raises(ValueError, match="free dofs"):
        s(A, b)                                  # not condensed
    with pytest.raises(TypeError, match="atol"):
        solve(*condense(A, b, D=D), solver=s, atol=1e-3)
    with pytest.raises(ValueError, match="coarse"):
        TwoLevelPreconditioner(A, nested_prolongation(basis), coarse="lu")
    with pytest.raises(RuntimeError, match="did not converge"):
        solve(*condense(A, b, D=D), solver=natural_neighbour_solver(basis, D, maxiter=2))


def test_stars_cover_every_free_dof_and_beat_jacobi(mesh, basis):
    """Each free dof is in a star (a node's dof in its own star only, an edge's in its two
    nodes'), the star smoother is symmetric, and it takes CG to the tolerance in fewer
    iterations than Jacobi inside the same Chebyshev and coarse level."""
    import scipy.sparse.linalg as spla

    from skfem_nem.basis.two_level import star_dofs, star_smoother
    A, b = laplace.assemble(basis), load.assemble(basis)
    free = basis.complement_dofs(basis.get_dofs().all())
    ptr, idx = star_dofs(basis, free)
    seen = np.bincount(idx, minlength=free.size)
    where = np.full(basis.N, -1)
    where[free] = np.arange(free.size)
    nodal, facet = where[basis.nodal_dofs[0]], where[basis.facet_dofs[0]]
    assert (seen[nodal[nodal >= 0]] == 1).all() and (seen[facet[facet >= 0]] == 2).all()
    Af, bf = A[free][:, free].tocsr(), b[free]
    B = star_smoother(Af, ptr, idx)
    assert abs(B - B.T).max() == 0
    P = nested_prolongation(basis)[free][:, np.isin(basis.nodal_dofs[0], free)]
    its = []
    for smoother in (B, None):
        M = TwoLevelPreconditioner(Af, P, smoother=smoother)
        count = [0]
        spla.cg(Af, bf, M=spla.LinearOperator(Af.shape, matvec=M), rtol=1e-10,
                callback=lambda *_: count.__setitem__(0, count[0] + 1))
        its.append(count[0])
    assert its[0] < 0.8 * its[1], its
