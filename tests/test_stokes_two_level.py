"""The quadratic natural-neighbour viscous block preconditioned by the two-level method
(models.stokes_two_level): the iterative Stokes solvers agree with the direct solve, and take
the two-level method, not smoothed aggregation, for that velocity."""
import sys
from pathlib import Path

import numpy as np
import pytest

from skfem_nem.models.analytic import SolCx
from skfem_nem.models.krylov import cg_steps
from skfem_nem.models.stokes import solve_stokes, stokes_spaces
from skfem_nem.models.stokes_solvers import SOLVERS
from skfem_nem.models.stokes_amg import ViscousAMG, viscous_amg
from skfem_nem.models.stokes_two_level import ViscousTwoLevel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import ex07_solcx  # noqa: E402


@pytest.fixture(scope="module")
def solcx():
    """SolCx at a contrast of 1e6 on the constrained triangles of 250 nodes (the interface
    x = 0.5 as segments), quadratic natural-neighbour velocity, and its direct solve."""
    spaces = stokes_spaces(ex07_solcx.make_mesh(250), "nem2")
    ex = SolCx(1.0, 1e6)
    return spaces, ex, solve_stokes(spaces, ex.viscosity, ex.force, solver="direct")


# MINRES's preconditioned residual (the norm it minimises) is a poor measure at a contrast
# of 1e6 (docs/stokes.md): it stops at a looser tolerance, and its solution is compared so
@pytest.mark.parametrize("solver, tol, close", [("fgmres", 1e-11, (1e-7, 1e-5)),
                                                ("schur-amg", 1e-11, (1e-7, 1e-5)),
                                                ("minres", 1e-9, (1e-5, 1e-3))])
def test_iterative_solvers_agree_with_direct(solcx, solver, tol, close):
    spaces, ex, ref = solcx
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver=solver, tol=tol, maxiter=3000)
    du = np.linalg.norm(s.u - ref.u) / np.linalg.norm(ref.u)
    dp = np.linalg.norm(s.p - ref.p) / np.linalg.norm(ref.p)
    assert du < close[0] and dp < close[1], (du, dp)
    if solver == "fgmres":
        assert s.info["amg_levels"] >= 2 and s.iterations < 150


def test_the_quadratic_velocity_takes_the_two_level_method(solcx, monkeypatch):
    spaces, ex, _ = solcx
    seen = {}
    direct = SOLVERS["direct"]

    def spy(problem, *args, **kwargs):
        seen["problem"] = problem
        return direct(problem, *args, **kwargs)

    monkeypatch.setitem(SOLVERS, "direct", spy)
    solve_stokes(spaces, ex.viscosity, ex.force, solver="direct")
    problem = seen["problem"]
    ml = viscous_amg(problem)
    assert isinstance(ml, ViscousTwoLevel) and not isinstance(ml, ViscousAMG)
    # its CG steps reduce the error of a viscous solve as a preconditioner should
    A = problem.A
    x = np.random.default_rng(0).normal(size=A.shape[0])
    b = A @ x
    err = [np.linalg.norm(cg_steps(A, ml.cycle, b, k) - x) / np.linalg.norm(x)
           for k in (1, 4, 12)]
    assert err[0] < 0.9 and err[2] < 1e-3 * err[0], err
    # new values, the same dofs: the kept space takes them
    ml.refresh(2.0 * A)
    assert np.allclose(2.0 * ml.cycle(b), ViscousTwoLevel(A, problem.ubasis,
                                                          problem.free).cycle(b))


def test_fgmres_stops_where_rounding_stalls_it(solcx):
    """Asked for a tolerance below the rounding of the residual, FGMRES with the two-level
    method stops after a restart cycle that did not halve the residual and says so, instead
    of running on to maxiter."""
    from skfem_nem.models.krylov import FGMRES_RESTART
    from skfem_nem.models.stokes_solvers import SolverNotConverged
    spaces, ex, _ = solcx
    with pytest.raises(SolverNotConverged, match="stalled") as err:
        solve_stokes(spaces, ex.viscosity, ex.force, solver="fgmres", tol=1e-17,
                     maxiter=20 * FGMRES_RESTART)
    its = int(str(err.value).split(": ")[1].split()[0])
    assert its < 5 * FGMRES_RESTART


def test_auto_takes_fgmres_for_the_quadratic_velocity_from_its_size(solcx, monkeypatch):
    import skfem_nem.models.stokes_solvers as solvers
    spaces, ex, ref = solcx
    small = solve_stokes(spaces, ex.viscosity, ex.force)
    assert small.info["solver"] == "schur"
    monkeypatch.setattr(solvers, "AUTO_FGMRES_UNKNOWNS_NEM2", 1)
    big = solve_stokes(spaces, ex.viscosity, ex.force, tol=1e-11)
    assert big.info["solver"] == "fgmres" and big.info["amg_levels"] >= 2
    assert np.linalg.norm(big.u - ref.u) < 1e-7 * np.linalg.norm(ref.u)
