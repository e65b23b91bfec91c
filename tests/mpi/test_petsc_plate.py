"""The sinking plate over MPI (``--solver petsc``) on 1 and 2 ranks: the first 20 steps
against the serial run, rank 0 alone writing, and the command line."""
import csv
from pathlib import Path

import numpy as np
import pytest

from skfem_nem.apps.cli import main
from skfem_nem.apps.sinking_plate import PlateConfig, SinkingPlate
from agreement import rel

# agreement asked of the MPI run with the serial one after STEPS steps (nodes, velocity
# and pressure, relative in the 2-norm)
AGREEMENT = 1e-8
# PETSc's relative residual in the comparison (the plate's default, 1e-10, gave a pressure
# 2e-9 to 8e-9 from the serial one after 20 steps: too close to AGREEMENT; 1e-12 gives
# 3e-10, and the serial "schur" at its default is then the limit). The serial reference
# factorises every solve: its pressure CG stops on the pressure's residual, where the
# FGMRES solves with kept factors stop on the whole system's (pressures 1e-8 apart)
PETSC_RTOL = 1e-12
STEPS = 20
NODES = 300


@pytest.fixture(scope="module")
def shared_dir(comm, tmp_path_factory):
    """A folder that every rank names the same (rank 0's): over MPI all ranks get the
    same ``-o``."""
    mine = str(tmp_path_factory.mktemp("plate"))
    return lambda name: Path(comm.tompi4py().bcast(mine, root=0)) / name


@pytest.fixture
def tight(PETSc):
    """The Stokes solves of solver "petsc" to PETSC_RTOL (PETSc's options database)."""
    opts = PETSc.Options()
    opts.setValue("stokes_ksp_rtol", PETSC_RTOL)
    yield
    opts.delValue("stokes_ksp_rtol")


def test_twenty_steps_match_the_serial_run(comm, agree, shared_dir, tmp_path, tight,
                                           monkeypatch):
    import skfem_nem.models.rheology as rheology
    import skfem_nem.models.stokes_solvers as solvers
    # both runs solve to the final solves' LINEAR_TOL in the Picard iterations too (by
    # default those stop at PICARD_LINEAR_FACTOR times the Picard tolerance, 1e-6 here)
    monkeypatch.setattr(rheology, "PICARD_LINEAR_FACTOR", 0.0)
    reuse = solvers.REUSE_FACTOR
    monkeypatch.setattr(solvers, "REUSE_FACTOR", False)
    serial = SinkingPlate(PlateConfig(nodes=NODES, solver="schur"), tmp_path / "serial")
    serial.run(progress=False, max_steps=STEPS)
    monkeypatch.setattr(solvers, "REUSE_FACTOR", reuse)
    sim = SinkingPlate(PlateConfig(nodes=NODES, solver="petsc"), shared_dir("petsc"))
    sim.run(progress=False, max_steps=STEPS)
    a, b = sim.solution, serial.solution
    same_mesh = np.array_equal(sim.lm.triangles, serial.lm.triangles)
    fields = [rel(sim.lm.ip_fields[k], serial.lm.ip_fields[k])
              for k in ("stress", "plastic_strain", "log_eta_eff")]
    # each rank held the bases of its part of the triangles alone
    got = agree((sim.lm.step, same_mesh, rel(sim.lm.nodes, serial.lm.nodes), rel(a.u, b.u),
                 rel(a.p, b.p), a.ranks, fields, a.cells, sim.root))
    for step, same, dx, du, dp, ranks, fields, _, _ in got:
        assert step == STEPS and same, (step, same)
        assert dx < AGREEMENT and du < AGREEMENT and dp < AGREEMENT, (dx, du, dp)
        assert max(fields) < AGREEMENT, fields
        assert ranks == comm.getSize()
    assert sum(g[-2] for g in got) == sim.lm.triangles.shape[0]
    assert [g[-1] for g in got] == [r == 0 for r in range(comm.getSize())]
    if sim.root:  # the step's sums and maxima over the parts: the serial run's
        rows = [list(csv.DictReader((d / "diagnostics.csv").read_text().splitlines()))[-1]
                for d in (sim.out, serial.out)]
        assert rows[0]["yielded_points"] == rows[1]["yielded_points"]
        for k in ("max_plate_stress", "max_plastic_strain"):
            assert abs(float(rows[0][k]) - float(rows[1][k])) <= 1e-6 * abs(float(rows[1][k]))


@pytest.fixture
def serial_like(monkeypatch):
    """The serial reference's settings of test_twenty_steps_match_the_serial_run: every
    solve of the Picard iterations to LINEAR_TOL, every serial solve factorised."""
    import skfem_nem.models.rheology as rheology
    import skfem_nem.models.stokes_solvers as solvers
    monkeypatch.setattr(rheology, "PICARD_LINEAR_FACTOR", 0.0)
    monkeypatch.setattr(solvers, "REUSE_FACTOR", False)


def test_restart_on_another_number_of_ranks(comm, agree, shared_dir, tmp_path, tight,
                                            serial_like):
    """A checkpoint written by one process continues on the ranks, and one written by
    the ranks continues in one process: after 2 + 2 steps, both give the nodes, velocity
    and pressure of an uninterrupted serial run of 4 steps."""
    cfg = {"nodes": NODES}
    ref = SinkingPlate(PlateConfig(**cfg, solver="schur"), tmp_path / "ref")
    ref.run(progress=False, max_steps=4)
    mpi = comm.tompi4py()
    one, many = shared_dir("one"), shared_dir("many")   # (collective: named on every rank)
    if comm.getRank() == 0:      # one process writes the checkpoint of step 2 ...
        SinkingPlate(PlateConfig(**cfg, solver="schur"), one).run(progress=False, max_steps=2)
    mpi.barrier()                # ... and the ranks go on from it
    on_ranks = SinkingPlate.restart(one, PlateConfig(**cfg, solver="petsc"))
    on_ranks.run(progress=False, max_steps=2)
    # the ranks write the checkpoint of step 2, and one process goes on from it
    SinkingPlate(PlateConfig(**cfg, solver="petsc"), many).run(progress=False, max_steps=2)
    mpi.barrier()
    diffs = []
    if comm.getRank() == 0:
        alone = SinkingPlate.restart(many, PlateConfig(**cfg, solver="schur"))
        alone.run(progress=False, max_steps=2)
        diffs = [alone.lm.step, rel(alone.lm.nodes, ref.lm.nodes),
                 rel(alone.solution.u, ref.solution.u), rel(alone.solution.p, ref.solution.p)]
    got = agree((on_ranks.lm.step, rel(on_ranks.lm.nodes, ref.lm.nodes),
                 rel(on_ranks.solution.u, ref.solution.u),
                 rel(on_ranks.solution.p, ref.solution.p), diffs))
    for step, dx, du, dp, alone in got:
        assert step == 4 and max(dx, du, dp) < AGREEMENT, (step, dx, du, dp)
    assert got[0][-1][0] == 4 and max(got[0][-1][1:]) < AGREEMENT, got[0][-1]


def test_rank_zero_alone_writes(comm, agree, shared_dir):
    out = shared_dir("cli")
    code = main(["sinking-plate", "--solver", "petsc", "--nodes", str(NODES),
                 "--max-steps", "3", "-o", str(out), "--quiet"])
    comm.tompi4py().barrier()
    with open(out / "diagnostics.csv") as fh:
        rows = list(csv.DictReader(fh))
    vtus = sorted(p.name for p in out.glob("plate_*.vtu"))
    got = agree((code, [r["step"] for r in rows], vtus, (out / "checkpoint.json").is_file(),
                 (out / "fig6.png").is_file()))
    for c, steps, files, checkpoint, figure in got:
        # one row per step (a second writer would append its own), one snapshot each
        assert c == 0 and steps == ["1", "2", "3"], (c, steps)
        assert files == ["plate_00000.vtu", "plate_00001.vtu"] and checkpoint and figure


def test_a_mesh_that_differs_between_ranks_stops_the_run(comm, agree, shared_dir):
    """The replicated evolution is checked after every step: a mesh advanced on the last
    rank alone (its clock ahead) is reported on every rank, naming that rank."""
    if comm.getSize() < 2:
        pytest.skip("needs two ranks: one rank always agrees with itself")
    sim = SinkingPlate(PlateConfig(nodes=NODES, solver="petsc"), shared_dir("differ"))
    sim.check_replicated()                            # the same mesh everywhere
    if comm.getRank() == comm.getSize() - 1:
        sim.lm.advance(lambda x: np.zeros_like(x), 1e-3)
    with pytest.raises(RuntimeError) as err:
        sim.check_replicated()
    got = agree(str(err.value))
    assert all(f"rank(s) [{comm.getSize() - 1}] differs from rank 0" in m for m in got)
