"""The multigrid cycles and flexible CG of basis.multigrid, and natural_neighbour_solver on the
linear natural-neighbour basis (basis.solvers): K-cycles against V-cycles, flexible CG against
scipy's CG, solutions against direct solves (Poisson in 2D and 3D, elasticity), iterations
that stay flat, and bad input refused by name."""
import numpy as np
import pyamg
import pytest
import scipy.sparse.linalg as spla
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import Basis, ElementTriP1, ElementVector, LinearForm, condense, solve
from skfem.models.elasticity import linear_elasticity
from skfem.models.poisson import laplace

import skfem_nem.basis.multigrid as mg
from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh,
                       natural_neighbour_solver)
from skfem_nem.geometry import box_nodes_3d
from skfem_nem.geometry.nodesets import box_nodes

CHEBYSHEV = ("chebyshev", {"degree": 2})


@LinearForm
def load(v, w):
    return np.sin(3 * w.x[0]) * np.exp(w.x[1]) * v


def _energy_error(A, x, exact):
    e = exact - x
    return float(np.sqrt(e @ (A @ e)))


def test_a_k_cycle_is_nearer_the_solution_than_a_v_cycle(monkeypatch):
    """On a hierarchy of four levels or more the K-cycle (two flexible CG steps on each
    coarse level, preconditioned by that level's cycle) leaves a smaller energy error than
    the V-cycle, with or without the steps on the finest level; on the coarsest level it is
    the coarse solve; where its first step always suffices (tolerance 1) it is the V-cycle
    scaled by its optimal step."""
    A = pyamg.gallery.poisson((60, 60), format="csr")
    ml = pyamg.smoothed_aggregation_solver(A, max_coarse=10, presmoother=CHEBYSHEV,
                                           postsmoother=CHEBYSHEV)
    assert len(ml.levels) >= 4
    b = np.random.default_rng(5).standard_normal(A.shape[0])
    exact = spla.spsolve(A.tocsc(), b)
    v, k = mg.v_cycle(ml, b), mg.k_cycle(ml, b)
    assert _energy_error(A, k, exact) < 0.8 * _energy_error(A, v, exact)
    last = len(ml.levels) - 1
    bc = np.random.default_rng(6).standard_normal(ml.levels[last].A.shape[0])
    np.testing.assert_array_equal(mg.k_cycle(ml, bc, level=last),
                                  ml.coarse_solver(ml.levels[last].A, bc))
    np.testing.assert_array_equal(mg.k_cycle(ml, bc, level=last, steps=False),
                                  ml.coarse_solver(ml.levels[last].A, bc))
    # without the steps on its own level: that level's cycle, the pairs below it
    top = mg.k_cycle(ml, b, steps=False)
    np.testing.assert_array_equal(
        top, mg.level_step(ml, 0, b, lambda k, r: mg.k_cycle(ml, r, level=k)))
    assert _energy_error(A, top, exact) < _energy_error(A, v, exact)
    assert not np.array_equal(top, k)
    monkeypatch.setattr(mg, "K_CYCLE_TOL", 1.0)
    Ak = ml.levels[last - 1].A
    bk = np.random.default_rng(7).standard_normal(Ak.shape[0])
    x = mg.v_cycle(ml, bk, level=last - 1)
    np.testing.assert_allclose(mg.k_cycle(ml, bk, level=last - 1),
                               (x @ bk) / (x @ (Ak @ x)) * x, rtol=1e-12, atol=1e-14)


@settings(max_examples=15, deadline=None)
@given(n=st.integers(20, 60), seed=st.integers(0, 10**6), start=st.booleans())
def test_flexible_cg_with_a_fixed_preconditioner_is_cg(n, seed, start):
    """With a fixed symmetric positive definite preconditioner (Jacobi) flexible CG makes
    the iterates of CG: the same solution to the tolerance, within an iteration of scipy's
    count; from a start vector too."""
    rng = np.random.default_rng(seed)
    Q = rng.standard_normal((n, n))
    A = Q @ Q.T + n * np.diag(rng.uniform(0.5, 5.0, n))
    b = rng.standard_normal(n)
    x0 = rng.standard_normal(n) if start else None
    d = np.diag(A)
    x, its, ok = mg.flexible_cg(A, b, lambda r: r / d, 1e-10, 500, x0=x0)
    assert ok
    assert np.linalg.norm(b - A @ x) <= 1e-10 * np.linalg.norm(b)
    count = [0]
    spla.cg(A, b, x0=x0, M=np.diag(1 / d), rtol=1e-10, atol=0.0,
            callback=lambda *_: count.__setitem__(0, count[0] + 1))
    assert abs(its - count[0]) <= 1, (its, count[0])


def test_flexible_cg_reports_what_stopped_it():
    """A start that already solves takes no step; too few steps, or an indefinite matrix,
    come back unconverged."""
    A = np.diag([1.0, 2.0, 3.0, 4.0])
    b = np.ones(4)
    x, its, ok = mg.flexible_cg(A, b, lambda r: r, 1e-12, 10, x0=b / np.diag(A))
    assert (its, ok) == (0, True)
    _, its, ok = mg.flexible_cg(A, b, lambda r: r, 1e-12, 2)
    assert (its, ok) == (2, False)
    _, its, ok = mg.flexible_cg(np.diag([1.0, -1.0]), np.array([1.0, 1.0]), lambda r: r,
                                1e-12, 10)
    assert not ok


def test_smoothed_aggregation_is_the_same_every_time_and_leaves_numpy_alone():
    """The hierarchy is built under a fixed seed (the same every call) and numpy's global
    generator continues as it would have."""
    A = pyamg.gallery.poisson((30, 30), format="csr")
    np.random.seed(3)
    before = np.random.random()
    np.random.seed(3)
    a, b = mg.smoothed_aggregation(A), mg.smoothed_aggregation(A)
    assert np.random.random() == before
    for la, lb in zip(a.levels, b.levels):
        assert (la.A != lb.A).nnz == 0


def test_scalar_levels_are_csr_and_cycle_as_pyamgs_bsr_ones():
    """With the constants as near null space pyamg makes the coarse levels BSR of 1 x 1
    blocks; smoothed_aggregation hands them back as CSR with the same entries, and a cycle
    (Gauss-Seidel and Chebyshev smoothers) on them is pyamg's own on the BSR levels to
    rounding. Levels of larger blocks (rigid modes) stay BSR."""
    A = pyamg.gallery.poisson((100, 100), format="csr")
    b = np.random.default_rng(8).standard_normal(A.shape[0])
    for smoother in (("gauss_seidel", {"sweep": "symmetric"}), CHEBYSHEV):
        # (copies: pyamg keeps a matrix's spectral radius on it, and the second hierarchy
        # would then draw fewer random starts)
        ours = mg.smoothed_aggregation(A.copy(), presmoother=smoother,
                                       postsmoother=smoother, max_levels=4)
        with mg.seeded_global_random():
            theirs = pyamg.smoothed_aggregation_solver(
                A.copy(), symmetry="symmetric", max_coarse=mg.MAX_COARSE, coarse_solver="splu",
                presmoother=smoother, postsmoother=smoother, max_levels=4)
        assert len(ours.levels) == len(theirs.levels) >= 3
        assert any(lv.A.format == "bsr" for lv in theirs.levels)
        for lo, lt in zip(ours.levels, theirs.levels):
            assert lo.A.format == "csr"
            assert abs(lo.A - lt.A.tocsr()).max() == 0
        np.testing.assert_allclose(mg.k_cycle(ours, b), mg.k_cycle(theirs, b), rtol=1e-10,
                                   atol=1e-12 * np.abs(b).max())
    E, modes = pyamg.gallery.linear_elasticity((40, 40), format="bsr")
    vector = mg.smoothed_aggregation(E.tocsr(), modes)
    assert vector.levels[1].A.format == "bsr" and vector.levels[1].A.blocksize == (3, 3)


def test_chebyshev_smoothers_are_pyamgs_without_its_blas_norm(monkeypatch):
    """polynomial_smoothers replaces the Chebyshev smoothers of the levels the options name
    (pyamg's list form: the last entry for the levels below) by the same polynomial, which
    gives pyamg's result bit for bit from zero and from a start, without pyamg's norm (the
    BLAS dot product); other smoothers and the levels given None are left as they were."""
    import pyamg.relaxation.relaxation as relaxation
    A = pyamg.gallery.poisson((60, 60), format="csr")
    pre, post = [None, CHEBYSHEV], [("gauss_seidel", {"sweep": "symmetric"}), CHEBYSHEV]
    with mg.seeded_global_random():
        ml = pyamg.smoothed_aggregation_solver(A, symmetry="symmetric", max_coarse=50,
                                               presmoother=pre, postsmoother=post)
    theirs = [(lv.presmoother, lv.postsmoother) for lv in ml.levels[:-1]]
    mg.polynomial_smoothers(ml, pre, post)
    assert len(ml.levels) >= 3
    assert ml.levels[0].presmoother is theirs[0][0]            # None: untouched
    assert ml.levels[0].postsmoother is theirs[0][1]           # Gauss-Seidel: untouched
    rng = np.random.default_rng(3)
    for lv, (tpre, tpost) in list(zip(ml.levels, theirs))[1:]:
        assert lv.presmoother is not tpre and lv.postsmoother is not tpost
        b = rng.standard_normal(lv.A.shape[0])
        for start in (np.zeros_like(b), rng.standard_normal(b.size)):
            x_ours, x_theirs = start.copy(), start.copy()
            lv.presmoother(lv.A, x_ours, b)
            tpre(lv.A, x_theirs, b)
            assert np.array_equal(x_ours, x_theirs)

    def no_blas(*args, **kwargs):
        raise AssertionError("pyamg's norm called")
    monkeypatch.setattr(relaxation, "norm", no_blas)
    x = np.zeros(ml.levels[1].A.shape[0])
    ml.levels[1].postsmoother(ml.levels[1].A, x, np.ones_like(x))
    with pytest.raises(AssertionError, match="norm called"):
        theirs[1][1](ml.levels[1].A, x, np.ones_like(x))


@pytest.fixture(scope="module")
def mesh():
    return delaunay_mesh(box_nodes(600, seed=4))


def _check_against_direct(basis, A, b, D, x0=None):
    s = natural_neighbour_solver(basis, D, tol=1e-11)
    x = solve(*condense(A, b, x=x0, D=D), solver=s)
    ref = solve(*condense(A, b, x=x0, D=D))
    assert np.abs(x - ref).max() < 1e-8 * np.abs(ref).max()
    return s


def test_the_linear_basis_solves_poisson_through_scikit_fem_solve(mesh):
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour())
    A, b = laplace.assemble(basis), load.assemble(basis)
    D = basis.get_dofs().all()
    x0 = np.zeros(basis.N)
    x0[D] = basis.doflocs[0, D]                  # nonzero Dirichlet data
    s = _check_against_direct(basis, A, b, D, x0)
    assert 0 < s.iterations < 25 and s.levels >= 2


def test_the_linear_basis_solves_elasticity_with_rigid_modes(mesh):
    """Clamped on one side: a vector basis' hierarchy takes the rigid-body modes (three
    columns in 2D) as its near null space."""
    vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
    K = linear_elasticity(1.0, 0.3).assemble(vb)

    @LinearForm
    def gravity(v, w):
        return -v[1]

    D = vb.get_dofs(lambda x: x[0] < 1e-12).all()
    s = _check_against_direct(vb, K, gravity.assemble(vb), D)
    assert 0 < s.iterations < 40


def test_the_linear_basis_solves_poisson_on_tetrahedra():
    basis = NaturalNeighbourBasis(delaunay_mesh(box_nodes_3d(800, seed=1)))
    A = laplace.assemble(basis)
    b = LinearForm(lambda v, w: np.cos(w.x[2]) * v).assemble(basis)
    s = _check_against_direct(basis, A, b, basis.get_dofs().all())
    assert 0 < s.iterations < 25


def test_the_iterations_stay_flat_as_the_nodes_grow():
    """From 2,000 to 32,000 nodes (the linear Laplacian, 16 times the unknowns, two levels and
    three) the K-cycles keep flexible CG's iterations within 1.35 times (16 and 21); pyamg's
    V-cycle with scipy's CG grows more on the same matrices (16 and 27)."""
    ours, vcycle = [], []
    for n in (2000, 32000):
        basis = NaturalNeighbourBasis(delaunay_mesh(box_nodes(n, seed=0)))
        A, b = laplace.assemble(basis), load.assemble(basis)
        D = basis.get_dofs().all()
        s = natural_neighbour_solver(basis, D)
        solve(*condense(A, b, D=D), solver=s)
        ours.append(s.iterations)
        Af, bf = condense(A, b, D=D)[:2]
        ml = mg.smoothed_aggregation(Af)
        count = [0]
        spla.cg(Af, bf, M=spla.LinearOperator(Af.shape, matvec=lambda r: mg.v_cycle(ml, r),
                                              dtype=float),
                rtol=1e-8, callback=lambda *_: count.__setitem__(0, count[0] + 1))
        vcycle.append(count[0])
    assert ours[1] <= 1.35 * ours[0], ours
    assert ours[1] / ours[0] < vcycle[1] / vcycle[0], (ours, vcycle)


def test_refuses_bad_input_by_name(mesh):
    """Another basis' functions, the quadratic basis' smoother degree, and a linear solve
    that does not converge (the wrong size and keywords: tests/test_two_level.py)."""
    basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour())
    with pytest.raises(TypeError, match="ElementTriP1"):
        natural_neighbour_solver(Basis(mesh, ElementTriP1()))
    with pytest.raises(ValueError, match="degree"):
        natural_neighbour_solver(basis, degree=3)
    D = basis.get_dofs().all()
    AI, bI = condense(laplace.assemble(basis), load.assemble(basis), D=D)[:2]
    with pytest.raises(RuntimeError, match="did not converge: 1 iterations"):
        natural_neighbour_solver(basis, D, maxiter=1)(AI, bI)
