"""The AMG of the viscous block (:class:`skfem_nem.models.stokes_amg.ViscousAMG`):
convergence at a strong viscosity contrast because the block is scaled, and a
refresh with new values that keeps the coarse space and solves the new block."""
import numpy as np
import pyamg
import pytest
import scipy.sparse as sps
import scipy.sparse.linalg as spla

import skfem_nem.models.stokes_solvers as solvers
from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.analytic import SolCx
from skfem_nem.models.stokes import solve_stokes, stokes_spaces
from skfem_nem.models.stokes_amg import (AMG_SMOOTHER, ViscousAMG, rigid_modes,
                                         scaled_block, unit_scale, viscous_amg)

# CG iterations to 1e-8 with one V-cycle as preconditioner, at a contrast of 1e6:
# measured 40 on these 2,000 nodes (42 with the block Gauss-Seidel smoother before)
AMG_CG_LIMIT = 50


@pytest.fixture(scope="module")
def spaces():
    """SolCx's square with a row of nodes on the interface x = 0.5."""
    z = np.linspace(0, 1, 31)
    return stokes_spaces(delaunay_mesh(box_nodes(2000, lines=[np.c_[0.5 + 0 * z, z]],
                                                 seed=4)), "nem")


def _problem(spaces, eta, monkeypatch):
    """The saddle-point problem ``solve_stokes`` hands its solver (free slip)."""
    got = {}

    def grab(problem, tol, maxiter, info, **kw):
        got["problem"] = problem
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setitem(solvers.SOLVERS, "schur", grab)
        with pytest.raises(KeyboardInterrupt):
            solve_stokes(spaces, eta, SolCx(1.0, 1e6).force)
    return got["problem"]


def _cg_iterations(A, M, b):
    its = [0]
    x, flag = spla.cg(A, b, M=M, rtol=1e-8, maxiter=200,
                      callback=lambda *_: its.__setitem__(0, its[0] + 1))
    return its[0] if flag == 0 else None


def test_scaled_block_converges_at_high_contrast(spaces, monkeypatch):
    problem = _problem(spaces, SolCx(1.0, 1e6).viscosity, monkeypatch)
    A, b = problem.A, np.random.default_rng(0).standard_normal(problem.A.shape[0])
    amg = viscous_amg(problem)
    assert amg.n_levels >= 2
    its = _cg_iterations(A, amg.preconditioner(), b)
    assert its is not None and its <= AMG_CG_LIMIT, its
    # the same hierarchy on the unscaled block: the Chebyshev smoother diverges
    ml = pyamg.smoothed_aggregation_solver(
        A, B=rigid_modes(problem.ubasis, problem.free), symmetry="symmetric",
        presmoother=AMG_SMOOTHER, postsmoother=AMG_SMOOTHER)
    assert _cg_iterations(A, ml.aspreconditioner(), b) is None


def test_refresh_keeps_the_coarse_space_and_solves_the_new_block(spaces, monkeypatch):
    ex = SolCx(1.0, 1e6)
    p1 = _problem(spaces, ex.viscosity, monkeypatch)
    # the viscosity changed by up to 10 times (a Picard iteration): same pattern
    p2 = _problem(spaces, lambda x: ex.viscosity(x) * 10 ** np.sin(5 * x[0] * x[1]),
                  monkeypatch)
    amg = viscous_amg(p1)
    coarse_space = amg.scale[:, None] * amg.ml.levels[0].P.toarray()
    amg.refresh(p2.A)
    assert np.allclose(amg.scale[:, None] * amg.ml.levels[0].P.toarray(), coarse_space,
                       rtol=1e-12, atol=1e-14)
    # the finest level multiplies through the new scaled block's triangle (its CSR let go)
    assert amg.ml.levels[0].A is None and np.allclose(amg.exact.diagonal, 1.0)
    b = np.random.default_rng(1).standard_normal(p2.A.shape[0])
    scaled = scaled_block(p2.A.tocsr(), unit_scale(p2.A))
    assert np.allclose(amg.exact @ b, scaled @ b, rtol=1e-13, atol=1e-13 * abs(scaled).max())
    fresh = _cg_iterations(p2.A, viscous_amg(p2).preconditioner(), b)
    refreshed = _cg_iterations(p2.A, amg.preconditioner(), b)
    assert refreshed is not None and refreshed <= fresh + 5, (refreshed, fresh)


def test_cg_steps_are_in_unscaled_unknowns(spaces, monkeypatch):
    problem = _problem(spaces, 1.0, monkeypatch)
    amg = viscous_amg(problem)
    x = np.random.default_rng(2).standard_normal(problem.A.shape[0])
    b = problem.A @ x
    err = [np.linalg.norm(amg.cg(b, k) - x) / np.linalg.norm(x) for k in (1, 4, 12)]
    assert err[0] > err[1] > err[2] and err[2] < 1e-4, err


def test_non_positive_diagonal_is_named():
    A = sps.csr_matrix(np.diag([1.0, 0.0, -2.0]))
    with pytest.raises(RuntimeError, match="2 diagonal entries <= 0"):
        unit_scale(A)
    with pytest.raises(RuntimeError, match="2 diagonal entries <= 0"):
        ViscousAMG(A, np.ones((3, 1)))


def test_hierarchy_is_the_same_in_every_build_and_leaves_numpy_random_alone(spaces,
                                                                              monkeypatch):
    """pyamg estimates spectral radii (prolongator smoothing, Chebyshev bounds) from
    random starts of numpy's global generator: built and refreshed under a fixed seed,
    two hierarchies of the same block cycle bit for bit alike, and the caller's
    generator draws what it would have drawn without them."""
    ex = SolCx(1.0, 1e6)
    p1 = _problem(spaces, ex.viscosity, monkeypatch)
    p2 = _problem(spaces, lambda x: ex.viscosity(x) * 10 ** np.sin(5 * x[0] * x[1]),
                  monkeypatch)
    r = np.random.default_rng(3).standard_normal(p1.A.shape[0])
    np.random.seed(7)
    expected = np.random.rand(3)
    np.random.seed(7)
    a, b = viscous_amg(p1), viscous_amg(p1)
    assert np.array_equal(a.cycle(r), b.cycle(r))
    a.refresh(p2.A)
    b.refresh(p2.A)
    assert np.array_equal(a.cycle(r), b.cycle(r))
    assert np.array_equal(np.random.rand(3), expected)


def test_a_small_change_renews_the_finest_level_alone(spaces, monkeypatch):
    """A refresh with a block whose diagonal changed by less than COARSE_KEPT keeps the
    coarse levels' matrices and renews the finest level (its products are the new
    block's); a larger change renews the coarse levels too."""
    from skfem_nem.models.stokes_amg import COARSE_KEPT
    ex = SolCx(1.0, 1e6)
    p1 = _problem(spaces, ex.viscosity, monkeypatch)
    small = _problem(spaces, lambda x: ex.viscosity(x) * (1 + 0.2 * x[0]), monkeypatch)
    large = _problem(spaces, lambda x: ex.viscosity(x) * (1 + 2 * COARSE_KEPT * x[0]),
                     monkeypatch)
    amg = viscous_amg(p1)
    coarse = amg.ml.levels[1].A.copy()
    x = np.random.default_rng(4).standard_normal(p1.A.shape[0])
    amg.refresh(small.A)
    assert abs(amg.ml.levels[1].A - coarse).max() == 0
    assert np.allclose(amg.matvec(x), small.A @ x, rtol=1e-12)
    fine = scaled_block(small.A.tocsr(), unit_scale(small.A)) @ x      # single precision
    assert np.linalg.norm(amg.fine @ x - fine) <= 1e-6 * np.linalg.norm(fine)
    amg.refresh(large.A)
    assert abs(amg.ml.levels[1].A - coarse).max() > 0
    assert np.allclose(amg.matvec(x), large.A @ x, rtol=1e-12)


def test_the_3d_flexible_solver_k_cycles_and_takes_fewer_iterations(monkeypatch):
    """A 3D block coarsened to three levels or more (a small coarsest level forced): the
    preconditioner of ``"fgmres"`` cycles with k_cycle below the finest level (v_cycle
    without K_CYCLE_3D), and FGMRES takes no more iterations with K-cycles. (Fewer shows
    from some 30,000 nodes on, where a V-cycle of the first coarse level falls short of
    its solve: ``benchmarks/stokes_3d.py``.)"""
    import skfem_nem.models.stokes_amg as amg_mod
    from skfem_nem.geometry import box_nodes_3d
    from skfem_nem.models.analytic3d import Manufactured3D
    monkeypatch.setattr(amg_mod, "AMG_MAX_COARSE", 6)
    calls = {"k": 0, "v": 0}
    k0, v0 = amg_mod.k_cycle, amg_mod.v_cycle

    def counted(name, f):
        def g(*a, **kw):
            calls[name] += 1
            return f(*a, **kw)
        return g

    monkeypatch.setattr(amg_mod, "k_cycle", counted("k", k0))
    monkeypatch.setattr(amg_mod, "v_cycle", counted("v", v0))
    S = stokes_spaces(delaunay_mesh(box_nodes_3d(1500, seed=0)), "nem")
    ms = Manufactured3D(1.0)
    its = {}
    for flag in (True, False):
        monkeypatch.setattr(amg_mod, "K_CYCLE_3D", flag)
        calls.update(k=0, v=0)
        sol = solve_stokes(S, ms.viscosity, ms.force, solver="fgmres", tol=1e-8)
        its[flag] = sol.iterations
        assert sol.info["amg_levels"] >= 3
        assert (calls["k"] > 0) == flag and (calls["v"] > 0) == (not flag), calls
    assert its[True] <= its[False], its
