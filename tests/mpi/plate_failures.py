"""A sinking-plate run over MPI with one failure injected: the program that
``test_petsc_failures.py`` starts on two ranks of its own (``mpiexec -n 2 python
plate_failures.py MODE OUT``), since a rank that fails alone ends every rank.

MODE ``output``: rank 0 cannot write its second snapshot (a full disk); ``compute``: the
third step raises on rank 1 alone; ``stall``: the third step stalls on every rank;
``compute3d``: the third step of the 3D plate raises on rank 1 alone."""
import sys

from skfem_nem.apps import cli
from skfem_nem.apps.sinking_plate import SinkingPlate, StepStalled
from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
from skfem_nem.parallel.petsc import world

MODE, OUT = sys.argv[1], sys.argv[2]
RANK = world()[0]
_write, _step = SinkingPlate.write_output, SinkingPlate.step
_step3d = SinkingPlate3D.step


def write_output(self, *args):
    if MODE == "output" and RANK == 0 and self.outputs >= 1:
        raise OSError(28, "No space left on device")
    return _write(self, *args)


def step(self, dt):
    if self.lm.step == 2 and MODE == "stall":
        raise StepStalled("step 3 stalled (injected on every rank)")
    if self.lm.step == 2 and MODE == "compute" and RANK == 1:
        raise RuntimeError("injected on rank 1")
    return _step(self, dt)


def step3d(self, dt):
    if self.lm.step == 2 and RANK == 1:
        raise RuntimeError("injected on rank 1")
    return _step3d(self, dt)


SinkingPlate.write_output, SinkingPlate.step, SinkingPlate3D.step = write_output, step, step3d
SMALL_3D = ["--dim", "3", "--density-length", "0.3", "--max-dt", "30", "--end-time", "150",
            "--output-interval", "30"]
sys.exit(cli.main(["sinking-plate", "--solver", "petsc", "--nodes", "300", "--max-steps", "4",
                   "--checkpoint-every", "1", "-o", OUT, "--quiet"]
                  + (SMALL_3D if MODE == "compute3d" else [])))
