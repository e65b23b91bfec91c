"""The 3D sinking plate over MPI (``--dim 3 --solver petsc``) on 1, 2 and 4 ranks: three
midpoint steps against the serial run (bases, stress update and Picard iterations on each
rank's part of the tetrahedra, the fields joined, the evolution on every rank), and rank
0 alone writing through the command line."""
import csv
from pathlib import Path

import numpy as np
import pytest

from skfem_nem.apps.cli import main
from skfem_nem.apps.plate3d_config import Plate3DConfig
from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
from agreement import rel

# agreement asked of the MPI run with the serial one after STEPS steps (nodes, fields,
# velocity and pressure, relative in the 2-norm): every linear solve of both runs to
# TIGHT, the serial ones direct
AGREEMENT = 1e-8
TIGHT = 1e-12
STEPS = 3
SMALL = dict(nodes=300, density_length=0.3, max_dt=30.0, end_time=90.0,
             output_interval=30.0, solver_tol=TIGHT, first_solve_tol=TIGHT)


@pytest.fixture(scope="module")
def shared_dir(comm, tmp_path_factory):
    """A folder that every rank names the same (rank 0's)."""
    mine = str(tmp_path_factory.mktemp("plate3d"))
    return lambda name: Path(comm.tompi4py().bcast(mine, root=0)) / name


def test_three_steps_match_the_serial_run(comm, agree, shared_dir, tmp_path):
    serial = SinkingPlate3D(Plate3DConfig(**SMALL, solver="direct"), tmp_path / "serial")
    serial.run(progress=False, max_steps=STEPS)
    sim = SinkingPlate3D(Plate3DConfig(**SMALL, solver="petsc"), shared_dir("petsc"))
    sim.run(progress=False, max_steps=STEPS)
    a, b = sim.solution(), serial.solution()
    same = np.array_equal(sim.lm.mesh.t, serial.lm.mesh.t)
    fields = [rel(sim.lm.ip_fields[k], serial.lm.ip_fields[k])
              for k in ("stress", "plastic_strain", "log_eta_eff")]
    held = sim._spaces_of[1].elements
    held = sim.lm.mesh.nelements if held is None else held.size
    got = agree((sim.lm.step, same, rel(sim.lm.nodes, serial.lm.nodes),
                 rel(a.velocity, b.velocity), rel(a.pressure, b.pressure), fields,
                 sim.root))
    for step, same, dx, du, dp, fields, _ in got:
        assert step == STEPS and same, (step, same)
        assert max(dx, du, dp, *fields) < AGREEMENT, (dx, du, dp, fields)
    assert [g[-1] for g in got] == [r == 0 for r in range(comm.getSize())]
    # each rank held the bases of its part of the last mesh alone
    parts = agree(held)
    assert comm.getSize() == 1 or max(parts) < sim.lm.mesh.nelements


def test_rank_zero_alone_writes(comm, agree, shared_dir):
    out = shared_dir("cli")
    code = main(["sinking-plate", "--dim", "3", "--solver", "petsc", "--nodes", "300",
                 "--density-length", "0.3", "--max-dt", "30", "--end-time", "60",
                 "--output-interval", "30", "--max-steps", "2", "-o", str(out), "--quiet"])
    comm.tompi4py().barrier()
    with open(out / "diagnostics.csv") as fh:
        rows = list(csv.DictReader(fh))
    vtus = sorted(p.name for p in out.glob("plate_*.vtu"))
    got = agree((code, [r["step"] for r in rows], vtus, (out / "checkpoint.json").is_file(),
                 (out / "slices.png").is_file()))
    for c, steps, files, checkpoint, figure in got:
        # one row per step (a second writer would append its own), one snapshot each
        assert c == 0 and steps == ["1", "2"], (c, steps)
        assert files == ["plate_00000.vtu", "plate_00001.vtu", "plate_00002.vtu"], files
        assert checkpoint and figure
