"""The flexible-GMRES Stokes solver and its cache: agreement with the direct
solve, reuse of the AMG hierarchy, warm starts and failures."""
import numpy as np
import pytest

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes, polyline_nodes
from skfem_nem.models.analytic import SolCx
from skfem_nem.models.stokes import StokesCache, outline_flux, solve_stokes, stokes_spaces
import scipy.sparse as sps

import skfem_nem.models.stokes_solvers as solvers
from skfem_nem.models.krylov import FGMRES_RESTART, fgmres
from skfem_nem.models.stokes_factors import ViscousFactor
from skfem_nem.models.stokes_solvers import SOLVERS

from helpers import plastic_inclusion


# the pressure of the direct solve itself is only this accurate at a 1e6 jump
# (the factorised Schur-complement solve differs from it by 9e-7 there)
PRESSURE_RTOL = 1e-5


def _close(s, ref, rtol, prtol=PRESSURE_RTOL):
    """Relative velocity difference below ``rtol``, pressure below ``prtol``."""
    du = np.linalg.norm(s.u - ref.u) / np.linalg.norm(ref.u)
    dp = np.linalg.norm(s.p - ref.p) / np.linalg.norm(ref.p)
    assert du < rtol and dp < prtol, (du, dp)


@pytest.fixture(scope="module")
def square():
    """A square with a row of nodes on the SolCx interface x = 0.5, and a
    small square outline on the weak side (for an area constraint)."""
    sq = [[0.2, 0.3], [0.4, 0.3], [0.4, 0.5], [0.2, 0.5]]
    line = polyline_nodes(sq, 0.05, closed=True)
    z = np.linspace(0, 1, 21)
    mesh = delaunay_mesh(box_nodes(500, lines=[np.c_[0.5 + 0 * z, z], np.r_[line, line[:1]]],
                                   seed=3))
    idx = np.array([int(np.argmin(np.hypot(*(mesh.p.T - q).T))) for q in line])
    return stokes_spaces(mesh, "nem"), idx


@pytest.mark.parametrize("contrast", [1.0, 1e6])
@pytest.mark.parametrize("walls", ["free-slip", "no-slip"])
def test_fgmres_agrees_with_direct(square, contrast, walls):
    sp_, _ = square
    ex = SolCx(1.0, contrast)
    kw = dict(free_slip=None, no_slip="all") if walls == "no-slip" else {}
    ref = solve_stokes(sp_, ex.viscosity, ex.force, solver="direct", **kw)
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", tol=1e-12, maxiter=3000, **kw)
    assert s.info["pressure_mean"] and s.iterations > 1
    _close(s, ref, 1e-8)
    assert s.residual < 1e-10


@pytest.mark.parametrize("contrast", [1.0, 1e6])
def test_fgmres_with_constraint_rows(square, contrast):
    """An outline-flux constraint with a right side (a pressure-like
    multiplier row of B, preconditioned by its Jacobi estimate)."""
    sp_, idx = square
    ex = SolCx(1.0, contrast)
    C = outline_flux(sp_, idx)
    ref = solve_stokes(sp_, ex.viscosity, ex.force, solver="direct", constraints=(C, [1e-3]))
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", constraints=(C, [1e-3]),
                     tol=1e-12, maxiter=3000)
    _close(s, ref, 1e-8)
    assert (C @ s.u)[0] == pytest.approx(1e-3, rel=1e-8)
    m, mref = s.info["multipliers"], ref.info["multipliers"]
    assert m == pytest.approx(mref, rel=1e-6)


def test_fgmres_without_fixed_mean_pressure(square):
    """An open top: the pressure is determined by the traction-free boundary
    (``pressure_mean`` False, no rank-one term)."""
    sp_, _ = square
    mesh = sp_.mesh.with_boundaries({"walls": lambda x: (x[0] < 1e-9) | (x[0] > 1 - 1e-9)
                                     | (x[1] < 1e-9)})
    sp2 = stokes_spaces(mesh, "nem")
    ex = SolCx(1.0, 1e3)
    ref = solve_stokes(sp2, ex.viscosity, ex.force, free_slip=["walls"], solver="direct")
    s = solve_stokes(sp2, ex.viscosity, ex.force, free_slip=["walls"], solver="fgmres",
                     tol=1e-12, maxiter=3000)
    assert not s.info["pressure_mean"]
    _close(s, ref, 1e-8)


def test_cache_reuses_hierarchy_and_warm_starts(square):
    sp_, _ = square
    ex = SolCx(1.0, 1e4)
    cache = StokesCache()
    s1 = solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", cache=cache)
    ml = cache.hierarchy
    assert s1.info["amg_rebuilt"] and not s1.info["warm_start"]
    # a slightly different viscosity: same pattern, the hierarchy object is kept
    eta2 = lambda x: ex.viscosity(x) * (1 + 0.05 * np.sin(3 * x[1]))   # noqa: E731
    s2 = solve_stokes(sp_, eta2, ex.force, solver="fgmres", cache=cache)
    assert cache.hierarchy is ml and not s2.info["amg_rebuilt"]
    assert (cache.builds, cache.reuses) == (1, 1)
    # and the refreshed hierarchy solves the new problem, not the old one
    ref2 = solve_stokes(sp_, eta2, ex.force, solver="direct")
    _close(s2, ref2, 1e-7)
    # the warm start (from s1) needs fewer iterations than a cold one
    cold = solve_stokes(sp_, eta2, ex.force, solver="fgmres")
    assert s2.info["warm_start"] and not cold.info["warm_start"]
    assert s2.iterations < cold.iterations
    # another node set: other size and pattern, a new hierarchy, no warm start
    other = stokes_spaces(delaunay_mesh(box_nodes(300, seed=5)), "nem")
    s3 = solve_stokes(other, ex.viscosity, ex.force, solver="fgmres", cache=cache)
    assert cache.hierarchy is not ml and s3.info["amg_rebuilt"] and not s3.info["warm_start"]
    assert cache.builds == 2


def test_schur_warm_starts_from_the_cached_solution(square, monkeypatch):
    """``"schur"`` with a cache, factorising every solve: the pressure CG of a second,
    slightly different problem starts from the first solution, needs fewer iterations
    than a cold start and gives the direct solution; a start worse than zero (another
    problem's pressure scaled up) or of another size is not taken."""
    import skfem_nem.models.stokes_solvers as solvers
    monkeypatch.setattr(solvers, "REUSE_FACTOR", False)
    sp_, _ = square
    ex = SolCx(1.0, 1e4)
    cache = StokesCache()
    s1 = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", cache=cache)
    assert not s1.info["warm_start"] and cache.solution.size == sp_.n_velocity - s1.info[
        "fixed_velocity_dofs"] + s1.p.size + s1.info["multipliers"].size
    eta2 = lambda x: ex.viscosity(x) * (1 + 0.05 * np.sin(3 * x[1]))   # noqa: E731
    s2 = solve_stokes(sp_, eta2, ex.force, solver="schur", cache=cache)
    cold = solve_stokes(sp_, eta2, ex.force, solver="schur")
    assert s2.info["warm_start"] and not cold.info["warm_start"]
    assert s2.iterations < cold.iterations
    _close(s2, solve_stokes(sp_, eta2, ex.force, solver="direct"), 1e-7)
    cache.solution = 1e6 * cache.solution
    s3 = solve_stokes(sp_, eta2, ex.force, solver="schur", cache=cache)
    assert not s3.info["warm_start"] and s3.iterations == cold.iterations
    other = stokes_spaces(delaunay_mesh(box_nodes(300, seed=5)), "nem")
    s4 = solve_stokes(other, ex.viscosity, ex.force, solver="schur", cache=cache)
    assert not s4.info["warm_start"]


def test_schur_reuses_its_factorisation_while_it_pays(square):
    """``"schur"`` with a cache keeps the viscous factorisation: a second solve with a
    slightly different viscosity (same pattern) runs FGMRES with the old factors, in
    fewer iterations than the first solve's CG, to the direct solution; a viscosity far
    from the factorised one (a contrast of 1e6 after a uniform one) takes more than
    the allowed growth, so it factorises again, still to the direct solution; another
    pattern factorises too."""
    sp_, _ = square
    ex = SolCx(1.0, 1e4)
    cache = StokesCache()
    s1 = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", cache=cache)
    lu = cache.factor
    assert not s1.info["factor_reused"] and cache.factorisations == 1 and lu is not None
    eta2 = lambda x: ex.viscosity(x) * (1 + 0.05 * np.sin(3 * x[1]))   # noqa: E731
    s2 = solve_stokes(sp_, eta2, ex.force, solver="schur", cache=cache)
    assert s2.info["factor_reused"] and cache.factor is lu and cache.factor_reuses == 1
    assert s2.iterations < s1.iterations
    _close(s2, solve_stokes(sp_, eta2, ex.force, solver="direct"), 1e-7)
    cache = StokesCache()
    solve_stokes(sp_, 1.0, ex.force, solver="schur", cache=cache)
    lu = cache.factor
    far = SolCx(1.0, 1e6)
    s3 = solve_stokes(sp_, far.viscosity, far.force, solver="schur", cache=cache)
    assert not s3.info["factor_reused"] and cache.factor is not lu
    assert (cache.factorisations, cache.factor_reuses) == (2, 0)
    _close(s3, solve_stokes(sp_, far.viscosity, far.force, solver="direct"), 1e-7)
    other = stokes_spaces(delaunay_mesh(box_nodes(300, seed=5)), "nem")
    s4 = solve_stokes(other, ex.viscosity, ex.force, solver="schur", cache=cache)
    assert not s4.info["factor_reused"] and cache.factorisations == 3


@pytest.mark.parametrize("contrast, precision", [(1.0, "float32"), (1e2, "float32"),
                                                 (1e6, "float64")])
def test_schur_factor_precision_follows_the_contrast(square, contrast, precision):
    """Single-precision factors up to a viscosity contrast of SINGLE_CONTRAST, double
    precision above it (forced single precision too, at 1e6); the solve meets tol on the
    true residual and agrees with the direct solve. The contrast the discretisation sees
    is SolCx's own."""
    sp_, _ = square
    ex = SolCx(1.0, contrast)
    ref = solve_stokes(sp_, ex.viscosity, ex.force, solver="direct")
    seen = []
    kinds = [precision] + (["float32"] if precision == "float64" else [])
    for kind in kinds:
        limit = np.inf if kind != precision else solvers.SINGLE_CONTRAST
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(solvers, "SINGLE_CONTRAST", limit)
            mp.setitem(SOLVERS, "schur", lambda pr, *a, **k: seen.append(
                solvers.viscosity_contrast(pr)) or solvers.solve_schur(pr, *a, **k))
            s = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", tol=1e-10,
                             maxiter=3000)
        assert s.info["factor_precision"] == kind and s.residual < 1e-10
        _close(s, ref, 1e-8)
    assert seen[0] == pytest.approx(contrast, rel=1e-9)
    assert s.info["viscosity_contrast"] == seen[0]


def test_schur_goes_on_in_double_precision(square, monkeypatch):
    """A solve not converged after ``PRECISION_ITERATIONS`` (here 3) with
    single-precision factors goes on from where it stands with double-precision ones
    and the Schur-complement CG, to the direct solution; the iterations of both
    count, and the double-precision factors are kept. Out of iterations it raises
    naming them."""
    sp_, _ = square
    ex = SolCx(1.0, 1e4)
    ref = solve_stokes(sp_, ex.viscosity, ex.force, solver="direct")
    made = []
    monkeypatch.setattr(solvers, "PRECISION_ITERATIONS", 3)
    monkeypatch.setattr(solvers, "SINGLE_CONTRAST", np.inf)
    monkeypatch.setattr(solvers, "ViscousFactor", lambda A, dtype: made.append(dtype)
                        or ViscousFactor(A, dtype))
    cache = StokesCache()
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", cache=cache)
    assert made == [np.float32, np.float64] and s.info["factor_precision"] == "float64"
    assert s.iterations > 3 and cache.factor.dtype == np.float64
    _close(s, ref, 1e-7)
    with pytest.raises(RuntimeError, match="pressure CG did not converge: 5 iterations"):
        solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", maxiter=5)


def test_factor_fgmres_stops_where_rounding_stalls_it(square, monkeypatch):
    """With a tolerance below what the rounding of the residual allows, FGMRES with
    the factors stops after a restart cycle that did not halve the residual instead
    of running on to its limit (here 2,000 iterations), and the Schur-complement CG
    takes over."""
    sp_, _ = square
    ex = SolCx(1.0, 1e6)
    runs = []

    def recorded(*args, **kw):
        out = fgmres(*args, **kw)
        runs.append(out[1:])
        return out

    monkeypatch.setattr(solvers, "fgmres", recorded)
    monkeypatch.setattr(solvers, "PRECISION_ITERATIONS", 2000)
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", tol=1e-17, maxiter=3000)
    [(its, res)] = runs
    assert res > 1e-17 and its < 4 * FGMRES_RESTART
    assert s.info["factor_precision"] == "float64" and s.iterations > its
    _close(s, solve_stokes(sp_, ex.viscosity, ex.force, solver="direct"), 1e-8)


def test_viscous_factor_precision_and_errors():
    """Scaled factors solve to their precision, from a CSC or a CSR block; a zero
    diagonal and a singular block are named."""
    rng = np.random.default_rng(0)
    n = 60
    L = sps.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    A = (sps.diags(10.0 ** rng.uniform(-3, 3, n)) @ L @ sps.diags(np.ones(n))).tocsc()
    # not symmetric: a CSR block is factorised as its transpose, which must not show
    A = (0.5 * (A + A.T) + sps.identity(n) * 1e-3 + 0.1 * sps.eye(n, k=1)).tocsc()
    b = rng.standard_normal(n)
    for dtype, rtol in ((np.float64, 1e-12), (np.float32, 1e-3)):
        for M in (A, A.tocsr()):
            x = ViscousFactor(M, dtype).solve(b)
            assert x.dtype == np.float64
            assert np.linalg.norm(A @ x - b) < rtol * np.linalg.norm(b)
    A0 = A.tolil()
    A0[4, 4] = 0.0
    with pytest.raises(RuntimeError, match="1 diagonal entries <= 0"):
        ViscousFactor(A0.tocsc())
    S = sps.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(RuntimeError, match="singular"):
        ViscousFactor(S)


def test_cache_rebuilds_when_iterations_grow(square, monkeypatch):
    """A rebuilt hierarchy replaces the old one, which is let go before the new one is
    built (two hierarchies are never held at once)."""
    import weakref

    import skfem_nem.models.stokes_cache as stokes_cache
    sp_, _ = square
    ex = SolCx(1.0, 1.0)
    cache = StokesCache()
    solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", cache=cache)
    old, build, held = weakref.ref(cache.hierarchy), stokes_cache.viscous_amg, []

    def watched(problem, *args):
        held.append(cache.hierarchy is None and old() is None)
        return build(problem, *args)

    monkeypatch.setattr(stokes_cache, "viscous_amg", watched)
    cache.solution = None                     # no warm start, as for a new problem
    cache.last_iterations = 10 * cache.base_iterations + 100
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", cache=cache)
    assert s.info["amg_rebuilt"] and held == [True] and cache.hierarchy is not None
    assert old() is None


def test_fgmres_failure_names_maxiter(square):
    sp_, _ = square
    ex = SolCx(1.0, 1e6)
    cache = StokesCache()
    with pytest.raises(RuntimeError, match=r"did not converge: 5 iterations \(maxiter\)"):
        solve_stokes(sp_, ex.viscosity, ex.force, solver="fgmres", maxiter=5, cache=cache)
    assert cache.solution is None             # a failed solve is no warm start


def test_solver_and_cache_keywords_checked(square):
    sp_, _ = square
    with pytest.raises(ValueError, match="'gmres'"):
        solve_stokes(sp_, 1.0, 0.0, solver="gmres")
    with pytest.raises(ValueError, match="cache.*'minres'"):
        solve_stokes(sp_, 1.0, 0.0, solver="minres", cache=StokesCache())
    with pytest.raises(ValueError, match="cache must be a StokesCache"):
        solve_stokes(sp_, 1.0, 0.0, solver="fgmres", cache={})
    assert "fgmres" in SOLVERS


def test_vep_step_passes_solver_and_cache():
    """A plastic step with ``solver="fgmres"``: the same result as the default
    solver, and the AMG hierarchy built once and reused by the step's Picard
    iterations (a cache of the caller's is kept across steps)."""
    from skfem_nem.models.rheology import vep_step
    sp_, mat, f, tau = plastic_inclusion()
    ref = vep_step(sp_, mat, tau, 1.0, f=f, tol=1e-6)
    cache = StokesCache()
    r = vep_step(sp_, mat, tau, 1.0, f=f, tol=1e-6, solver="fgmres", cache=cache)
    # the Picard iterations (tol 1e-6) end within one of each other at the same field
    assert abs(r.iterations - ref.iterations) <= 1 and r.iterations > 2 and r.yielded.any()
    assert np.abs(r.solution.u - ref.solution.u).max() < 1e-5 * np.abs(ref.solution.u).max()
    assert cache.builds == 1 and cache.reuses == r.iterations - 1
    # the next step starts from this one's solution
    r2 = vep_step(sp_, mat, r.tau, 1.0, f=f, tol=1e-6, solver="fgmres", cache=cache)
    assert cache.builds == 1 and r2.solution.info["warm_start"]
    with pytest.raises(ValueError, match="'lu'"):
        vep_step(sp_, mat, tau, 1.0, f=f, solver="lu")
    with pytest.raises(ValueError, match="cache.*'direct'"):
        vep_step(sp_, mat, tau, 1.0, f=f, solver="direct", cache=StokesCache())


def test_sinking_plate_solver_option():
    from skfem_nem.apps.sinking_plate import HELP, load_config
    assert load_config(overrides={"solver": "fgmres"}).solver == "fgmres"
    assert "fgmres" in HELP["solver"]
    with pytest.raises(ValueError, match="solver must be one of .*got 'gmres'"):
        load_config(overrides={"solver": "gmres"})
    with pytest.raises(ValueError, match="solver must be str"):
        load_config(overrides={"solver": 3})


def test_mean_free_shifts_the_pressures_not_the_multipliers(square):
    """Fixing the mean pressure shifts every pressure by the same constant; the
    multipliers of extra constraints are no pressures and keep their values."""
    sp_, idx = square

    class Captured(Exception):
        pass

    def capture(problem, tol, maxiter, info):
        raise Captured(problem)

    SOLVERS["capture"] = capture
    try:
        with pytest.raises(Captured) as got:
            solve_stokes(sp_, 1.0, 0.0, solver="capture", constraints=outline_flux(sp_, idx))
    finally:
        del SOLVERS["capture"]
    problem = got.value.args[0]
    p = np.r_[np.full(sp_.n_pressure, 2.5), 7.0]
    q = problem.mean_free(p)
    assert problem.pressure_mean and np.abs(q[:-1]).max() < 1e-13 and q[-1] == 7.0


@pytest.mark.parametrize("threshold, cached, contrast, chosen", [
    (10, False, 1e6, "fgmres"), (10, True, 1e6, "schur"), (10 ** 9, False, 1e6, "schur"),
    (10, False, 1e2, "schur")])
def test_auto_chooses_by_size_contrast_and_cache(square, monkeypatch, threshold, cached,
                                                 contrast, chosen):
    """The default solver ``"auto"`` takes ``"fgmres"`` for a single solve from
    ``AUTO_FGMRES_UNKNOWNS`` velocity unknowns on above a viscosity contrast of
    ``SINGLE_CONTRAST``, and ``"schur"`` below either or with a cache, names its choice,
    and solves with it (the chosen solver's own records, the direct solve's velocity
    and pressure)."""
    sp_, _ = square
    ex = SolCx(1.0, contrast)
    monkeypatch.setattr(solvers, "AUTO_FGMRES_UNKNOWNS", threshold)
    cache = StokesCache() if cached else None
    s = solve_stokes(sp_, ex.viscosity, ex.force, tol=1e-12, maxiter=3000, cache=cache)
    assert s.info["solver"] == chosen
    assert ("amg_levels" in s.info) == (chosen == "fgmres")
    assert ("factor_precision" in s.info) == (chosen == "schur")
    if cached:
        assert cache.factorisations == 1 and cache.builds == 0
    _close(s, solve_stokes(sp_, ex.viscosity, ex.force, solver="direct"), 1e-8)


def test_auto_keeps_schur_for_taylor_hood(square, monkeypatch):
    """Above the size threshold too, ``"auto"`` solves a Taylor-Hood problem with
    ``"schur"`` (its P2 block factorises cheaply; ``"fgmres"`` is the slower there)."""
    sp_, _ = square
    th = stokes_spaces(sp_.mesh, "taylor-hood")
    ex = SolCx(1.0, 1e6)
    monkeypatch.setattr(solvers, "AUTO_FGMRES_UNKNOWNS", 10)
    s = solve_stokes(th, ex.viscosity, ex.force)
    assert s.info["solver"] == "schur" and "factor_precision" in s.info


@pytest.mark.parametrize("contrast, factors", [(1.0, "components"), (1e2, "components"),
                                               (1e6, "whole")])
def test_schur_with_component_factors_agrees_with_direct(square, monkeypatch, contrast,
                                                         factors):
    """From SPLIT_MIN_UNKNOWNS on and up to SINGLE_CONTRAST, "schur" factorises the
    velocity components' blocks apart (``info["factors"]``), takes more FGMRES
    iterations than with the whole block's factors, and reaches the direct solution;
    kept in a cache, the component factors serve the next solve. Above the contrast it
    keeps the whole block's."""
    sp_, _ = square
    ex = SolCx(1.0, contrast)
    ref = solve_stokes(sp_, ex.viscosity, ex.force, solver="direct")
    whole = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", tol=1e-10)
    monkeypatch.setattr(solvers, "SPLIT_MIN_UNKNOWNS", 0)
    cache = StokesCache()
    s = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur", tol=1e-10, maxiter=3000,
                     cache=cache)
    assert whole.info["factors"] == "whole" and s.info["factors"] == factors
    assert (s.iterations > whole.iterations) == (factors == "components")
    _close(s, ref, 1e-8)
    if factors == "whole":
        return
    again = solve_stokes(sp_, lambda x: 2 * ex.viscosity(x), ex.force, solver="schur",
                         tol=1e-10, maxiter=3000, cache=cache)
    assert again.info["factor_reused"] and cache.factorisations == 1
    _close(again, solve_stokes(sp_, lambda x: 2 * ex.viscosity(x), ex.force,
                               solver="direct"), 1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_minres_steps_meet_their_preconditioned_residual(seed):
    """MINRES on a symmetric indefinite system (eigenvalues from -10 to -1 and 1 to 1e3):
    it stops where the preconditioned residual norm, recomputed from the result, is at
    ``rtol`` of the start's (to the gap between its recurrence and the true residual, some
    eps times the condition squared), and its solution is the system's to that accuracy."""
    from skfem_nem.models.krylov import minres_steps
    rng = np.random.default_rng(seed)
    n = 120
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    lam = np.concatenate([np.logspace(0, 3, n - 30), -np.logspace(0, 1, 30)])
    A = (Q * lam) @ Q.T
    A = (A + A.T) / 2
    d = 1.0 / np.abs(np.diag(A))                    # Jacobi: symmetric positive definite
    b = rng.standard_normal(n)
    count = [0]
    x = minres_steps(lambda v: A @ v, lambda v: d * v, b, 1e-9, 2000, count)
    r = b - A @ x
    assert np.sqrt(r @ (d * r)) <= 2e-9 * np.sqrt(b @ (d * b))
    assert 0 < count[0] <= 2000
    exact = np.linalg.solve(A, b)
    assert np.linalg.norm(x - exact) <= 1e-6 * np.linalg.norm(exact)
    # a looser rtol stops sooner
    fewer = [0]
    minres_steps(lambda v: A @ v, lambda v: d * v, b, 1e-3, 2000, fewer)
    assert fewer[0] < count[0]
