"""solve_stokes(..., solver="petsc") on 1 and 2 ranks against the serial solvers:
SolCx at a viscosity contrast of 1e6, no-slip walls with an extra constraint row, the
options database, and the rows owned by each rank."""
import numpy as np
import pytest

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes, polyline_nodes
from skfem_nem.models.analytic import SolCx
from skfem_nem.models.stokes import outline_flux, solve_stokes, stokes_spaces
from agreement import rel

# agreement asked of the PETSc solution with the serial one (velocity and pressure,
# relative in the 2-norm); both solved to relative residuals far below it
AGREEMENT = 1e-8
# the serial reference: the default solver "schur", converged this tightly. At a
# contrast of 1e6 a relative residual of 1e-12 leaves its pressure 2e-8 from the
# converged one (FGMRES with single-precision factors; the Schur-complement CG it
# replaced: 3e-11), more than AGREEMENT; at 1e-14 it goes on in double precision and
# is 6e-10 from it
SERIAL_TOL = 1e-14
# the PETSc solve's relative residual (PETSc's norm of the whole system)
PETSC_TOL = 1e-11
# the true relative residual asked of the PETSc solution (solve_stokes' measure): at a
# contrast of 1e6 round-off leaves about 1e-10 whatever the tolerance (8e-11 measured
# for the serial "fgmres" and for "petsc" at tol 1e-12 with a constraint row)
RESIDUAL = 1e-9
# the pressure of the direct (LU) solve is itself only this accurate at a 1e6 jump
# (the serial "schur" and the PETSc solves differ from it by 4e-7 on this mesh, from
# each other by 2e-10): velocity is compared with AGREEMENT, pressure with this
DIRECT_PRESSURE_RTOL = 1e-5


@pytest.fixture(scope="module")
def square():
    """SolCx's square (seeded: the same mesh on every rank) with nodes on the interface
    and a small square outline on the weak side (for a flux constraint)."""
    sq = [[0.2, 0.3], [0.4, 0.3], [0.4, 0.5], [0.2, 0.5]]
    line = polyline_nodes(sq, 0.05, closed=True)
    z = np.linspace(0, 1, 21)
    mesh = delaunay_mesh(box_nodes(400, lines=[np.c_[0.5 + 0 * z, z], np.r_[line, line[:1]]],
                                   seed=3))
    idx = np.array([int(np.argmin(np.hypot(*(mesh.p.T - q).T))) for q in line])
    return stokes_spaces(mesh, "nem"), idx


@pytest.mark.parametrize("contrast", [1.0, 1e6])
def test_solcx_matches_the_serial_solution(square, comm, agree, contrast):
    spaces, _ = square
    ex = SolCx(1.0, contrast)
    serial = solve_stokes(spaces, ex.viscosity, ex.force, solver="schur", tol=SERIAL_TOL)
    direct = solve_stokes(spaces, ex.viscosity, ex.force, solver="direct")
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    got = agree((rel(s.u, serial.u), rel(s.p, serial.p), rel(s.u, direct.u),
                 rel(s.p, direct.p), s.residual, s.info["ranks"], float(s.u @ s.u)))
    for du, dp, du_lu, dp_lu, res, ranks, uu in got:
        assert du < AGREEMENT and dp < AGREEMENT, (du, dp)
        assert du_lu < AGREEMENT and dp_lu < DIRECT_PRESSURE_RTOL, (du_lu, dp_lu)
        assert res < RESIDUAL and ranks == comm.getSize()
        assert uu == got[0][-1]  # every rank holds the same solution
    assert s.info["pressure_mean"] and s.iterations > 1 and s.info["viscous_pc"] == "gamg"


def test_no_slip_with_a_constraint_row(square, agree):
    """No-slip walls and an outline-flux constraint with a right side: a multiplier
    row in the pressure block, preconditioned by its Jacobi estimate."""
    spaces, idx = square
    ex = SolCx(1.0, 1e6)
    kw = dict(free_slip=None, no_slip="all", constraints=(outline_flux(spaces, idx), [1e-3]))
    serial = solve_stokes(spaces, ex.viscosity, ex.force, solver="schur", tol=SERIAL_TOL, **kw)
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL, **kw)
    m_serial, m = serial.info["multipliers"], s.info["multipliers"]
    got = agree((rel(s.u, serial.u), rel(s.p, serial.p), rel(m, m_serial)))
    assert all(max(g) < AGREEMENT for g in got), got


def test_options_database_overrides_the_defaults(square, PETSc, agree):
    """-stokes_fieldsplit_0_pc_type hypre replaces GAMG; -stokes_ksp_max_it 2 makes
    the solve fail, naming PETSc's reason."""
    spaces, _ = square
    ex = SolCx(1.0, 1e6)
    serial = solve_stokes(spaces, ex.viscosity, ex.force, solver="schur", tol=SERIAL_TOL)
    opts = PETSc.Options()
    opts.setValue("stokes_fieldsplit_0_pc_type", "hypre")
    try:
        s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    finally:
        opts.delValue("stokes_fieldsplit_0_pc_type")
    got = agree((s.info["viscous_pc"], rel(s.u, serial.u), rel(s.p, serial.p)))
    assert all(pc == "hypre" and du < AGREEMENT and dp < AGREEMENT for pc, du, dp in got), got
    opts.setValue("stokes_ksp_max_it", 2)
    try:
        with pytest.raises(RuntimeError, match="DIVERGED_MAX_IT after 2 iterations"):
            solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    finally:
        opts.delValue("stokes_ksp_max_it")
    # the option is gone again: the defaults hold
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    assert s.info["viscous_pc"] == "gamg" and s.iterations > 2


def test_open_top_without_a_pressure_null_space(square, agree):
    """Walls on three sides and an open top: the pressure is determined by the
    traction-free boundary (no null space handed to PETSc)."""
    spaces, _ = square
    mesh = spaces.mesh.with_boundaries({"walls": lambda x: (x[0] < 1e-9) | (x[0] > 1 - 1e-9)
                                        | (x[1] < 1e-9)})
    open_top = stokes_spaces(mesh, "nem")
    ex = SolCx(1.0, 1e3)
    kw = dict(free_slip=["walls"])
    serial = solve_stokes(open_top, ex.viscosity, ex.force, solver="schur", tol=SERIAL_TOL, **kw)
    s = solve_stokes(open_top, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL, **kw)
    got = agree((s.info["pressure_mean"], rel(s.u, serial.u), rel(s.p, serial.p)))
    assert all(not mean and du < AGREEMENT and dp < AGREEMENT for mean, du, dp in got), got


def test_each_rank_assembles_its_part_of_the_triangles(square, comm, agree):
    """Distributed assembly: the ranks' triangles partition the mesh in the parts of the
    recursive bisection of its nodes (quadrants on four ranks, halves on two), of nearly
    equal size, and the solution equals that of the whole system given on every rank."""
    from skfem_nem.models.stokes import assemble_stokes
    from skfem_nem.parallel.partition import Bisection
    from skfem_nem.parallel.petsc import owned_elements
    spaces, _ = square
    mesh = spaces.mesh
    ex = SolCx(1.0, 1e6)
    mine = owned_elements(mesh)
    mine = np.arange(mesh.nelements) if mine is None else mine
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    whole = assemble_stokes(spaces, ex.viscosity, ex.force)
    given = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL,
                         system=whole)
    got = agree((mine.tolist(), s.info["assembled_triangles"],
                 given.info["assembled_triangles"], rel(s.u, given.u), rel(s.p, given.p)))
    owned = [g[0] for g in got]
    assert sorted(sum(owned, [])) == list(range(mesh.nelements))  # a partition
    # the cuts balance the nodes (to a few: the interface's nodes share x = 0.5, where two
    # ranks are cut); the cells follow them (on this graded mesh within 12% on three
    # ranks, the most uneven split tried)
    cuts = Bisection(mesh.p, len(owned))
    nodes = np.bincount(cuts.part(mesh.p), minlength=len(owned))
    assert np.abs(nodes / (mesh.p.shape[1] / len(owned)) - 1).max() <= 0.05, nodes
    sizes = [len(a) for a in owned]
    assert max(sizes) - min(sizes) <= 0.15 * mesh.nelements / len(owned)
    part = cuts.part(mesh.p[:, mesh.t].mean(axis=1))
    for rank, (a, n, n_given, du, dp) in enumerate(got):
        assert np.array_equal(np.flatnonzero(part == rank), a)
        assert n == len(a) and n_given == 0
        assert du < AGREEMENT and dp < AGREEMENT, (du, dp)


@pytest.mark.parametrize("method", ["nem", "taylor-hood"])
def test_divided_spaces_give_the_solution_of_the_whole_ones(square, comm, agree, method):
    """Spaces built on this rank's part alone (``elements="owned"``: no whole-mesh basis
    on any rank) solve to the solution of the whole spaces, and hold that part only."""
    whole = square[0] if method == "nem" else stokes_spaces(square[0].mesh, method)
    mesh = whole.mesh
    ex = SolCx(1.0, 1e6)
    divided = stokes_spaces(mesh, method, elements="owned")
    s = solve_stokes(divided, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    ref = solve_stokes(whole, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    held = mesh.nelements if divided.elements is None else divided.elements.size
    points = divided.quadrature_points.shape[1]
    got = agree((held, points, s.info["assembled_triangles"], rel(s.u, ref.u),
                 rel(s.p, ref.p)))
    assert sum(g[0] for g in got) == mesh.nelements
    for held, points, assembled, du, dp in got:
        assert points == held == assembled
        assert du < AGREEMENT and dp < AGREEMENT, (du, dp)


def test_divided_spaces_must_partition_the_mesh(square, comm):
    """Every rank taking the same half of the triangles: on two ranks each triangle of it
    is in two ranks' spaces, the others in none; on one rank half are in none. Every rank
    raises, naming a triangle and its count."""
    mesh = square[0].mesh
    half = stokes_spaces(mesh, "nem", elements=np.arange(mesh.nelements // 2))
    with pytest.raises(ValueError, match="must be a partition of the mesh: triangle"):
        solve_stokes(half, 1.0, solver="petsc")
    with pytest.raises(ValueError, match="solve them with solver='petsc'"):
        solve_stokes(half, 1.0, solver="fgmres")


def test_the_fieldsplit_takes_the_nest_blocks_as_they_are(square, PETSc, agree, monkeypatch):
    """The default fieldsplit solves on a nest whose viscous block is the very matrix
    GAMG works on (no copy of it); ``-stokes_pc_type lu`` (MUMPS) takes one AIJ matrix
    and gives the same solution."""
    import skfem_nem.parallel.saddle as saddle
    spaces, _ = square
    ex = SolCx(1.0, 1e6)
    seen = []
    checked = saddle.converged_or_raise

    def spy(ksp, what):     # (called after the solve, before the objects are destroyed)
        K = ksp.getOperators()[0]
        if K.getType() == "nest":
            sub = ksp.getPC().getFieldSplitSubKSP()[0].getOperators()[0]
            seen.append(("nest", sub.handle == K.getNestSubMatrix(0, 0).handle))
        else:
            seen.append((K.getType(), ksp.getPC().getType()))
        return checked(ksp, what)
    monkeypatch.setattr(saddle, "converged_or_raise", spy)
    s = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    opts = PETSc.Options()
    opts.setValue("stokes_pc_type", "lu")
    opts.setValue("stokes_pc_factor_mat_solver_type", "mumps")
    try:
        lu = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    finally:
        opts.delValue("stokes_pc_type")
        opts.delValue("stokes_pc_factor_mat_solver_type")
    got = agree((seen, rel(lu.u, s.u), lu.iterations))
    for kinds, du, its in got:
        assert kinds[0] == ("nest", True) and kinds[1][1] == "lu", kinds
        assert kinds[1][0] in ("seqaij", "mpiaij") and du < AGREEMENT and its < 5, (du, its)
