"""A failure of one rank ends every rank (``parallel.failures``): rank 0's output failing,
rank 1's computation failing, and a step stalled on every rank, each in a run on two ranks
of its own (``plate_failures.py``), started from the one-rank run of the MPI tests."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from skfem_nem.apps.sinking_plate import SinkingPlate
from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D

DRIVER = Path(__file__).with_name("plate_failures.py")
# a run of 4 steps of 300 nodes takes well under a minute; a hang would take for ever
TIMEOUT = 600


def run_two_ranks(mode: str, out: Path) -> subprocess.CompletedProcess:
    """``mpiexec -n 2`` of the driver, in an environment without this rank's MPI runtime
    variables (a launcher started inside a rank would take them as its own)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PRTE_"))}
    # Open MPI in containers (as in .ci/run): no cross-memory attach, ranks may share cores
    env.update(OMPI_MCA_btl_vader_single_copy_mechanism="none",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    cmd = ["mpiexec", "--allow-run-as-root", "-n", "2", sys.executable, str(DRIVER), mode,
           str(out)]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=TIMEOUT)


@pytest.fixture
def alone(comm):
    if comm.getSize() > 1:
        pytest.skip("starts two ranks of its own: run from the one-rank run of tests/mpi")


def failure_lines(stderr: str) -> list:
    return [line for line in stderr.splitlines() if "failed at t =" in line]


@pytest.mark.parametrize("mode, rank, reason, lag", [
    ("output", 0, "OSError: [Errno 28] No space left on device", 1),
    ("compute", 1, "RuntimeError: injected on rank 1", 0),
    ("compute3d", 1, "RuntimeError: injected on rank 1", 0)])
def test_one_rank_failing_ends_every_rank(alone, tmp_path, mode, rank, reason, lag):
    """Exit status 1 (MPI_Abort) on a failure of one rank, no hang, one line naming the rank
    and the reason, and the last checkpoint kept (one every step): rank 0's snapshot fails
    after a step was logged and before its checkpoint (``lag`` 1), rank 1's third step
    fails after the second step's checkpoint (in 2D, and in 3D: ``compute3d``)."""
    r = run_two_ranks(mode, tmp_path)
    lines = failure_lines(r.stderr)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert len(lines) == 1, r.stderr[-2000:]
    assert f"rank {rank} of 2 failed" in lines[0] and reason in lines[0], lines[0]
    assert "Traceback" not in r.stderr
    with open(tmp_path / "diagnostics.csv") as fh:
        logged = len(fh.read().splitlines()) - 1
    assert logged >= 1
    run = SinkingPlate3D if mode.endswith("3d") else SinkingPlate
    assert run.restart(tmp_path).lm.step == logged - lag


def test_a_step_stalled_on_every_rank_stops_as_in_serial(alone, tmp_path):
    """Every rank meets the same stall: no rank is aborted; rank 0 alone says why, in the
    serial run's line, and keeps the state of the last completed step."""
    r = run_two_ranks("stall", tmp_path)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert failure_lines(r.stderr) == []
    stops = [line for line in r.stderr.splitlines() if "sinking-plate stopped at" in line]
    assert len(stops) == 1 and "step 3 stalled" in stops[0], r.stderr[-2000:]
    assert SinkingPlate.restart(tmp_path).lm.step == 2
