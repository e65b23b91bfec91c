"""Ending every rank when one fails, over MPI.

A run over MPI computes the same time loop on every rank, and the ranks meet in collective
calls (the distributed Stokes solve, the check that their meshes agree). An exception that
only one rank meets (rank 0 writing an output file to a full disk, one rank out of memory)
would leave the others waiting in their next collective call for ever. So a rank that fails
asks the others, on a communicator of its own, whether they failed too:

* if every rank reports a failure within :data:`AGREEMENT_SECONDS` (the same step stopped
  on every rank, as a replicated computation does), the run stops as a serial one does:
  rank 0 keeps the state of the last completed step and explains;
* otherwise the failing rank names itself in one line on its standard error and ends every
  rank with ``MPI_Abort`` (exit status 1); the last checkpoint written stays as it was
  (checkpoints are written to a temporary file and renamed).

The communicator is a duplicate of the world's, so that the question never meets a
collective call of the computation that another rank is waiting in.
"""
from __future__ import annotations

import sys
import time

__all__ = ["AGREEMENT_SECONDS", "FailureChannel"]

# how long a failing rank waits for the others to report a failure too. Replicated steps
# fail at the same point within the ranks' skew: well under a second on two ranks sharing
# two cores at 300 nodes, but the work between two collective calls (a basis, a move) grows
# with the mesh and a rank may be descheduled; a rank that has not failed waits in a
# collective call and never answers, so this is also how long a lone failure takes to end
# the run
AGREEMENT_SECONDS = 30.0
# how often the failing rank looks whether the answer has come
POLL_SECONDS = 0.01


class FailureChannel:
    """The failure agreement of the ranks of ``comm`` (an mpi4py communicator, by default
    PETSc's world). Built collectively, by every rank at the same point."""

    def __init__(self, comm=None):
        if comm is None:
            from .petsc import import_petsc
            comm = import_petsc().COMM_WORLD.tompi4py()
        self.world = comm
        self.comm = comm.Dup()
        self.rank, self.size = comm.Get_rank(), comm.Get_size()

    def all_failed(self, seconds: float = AGREEMENT_SECONDS) -> bool:
        """Called by a failing rank: True if every rank reports a failure within
        ``seconds``, False if some rank does not answer in time (it has not failed)."""
        import numpy as np
        from mpi4py import MPI
        mine, total = np.ones(1, np.int64), np.zeros(1, np.int64)
        request = self.comm.Iallreduce(mine, total, op=MPI.SUM)
        deadline = time.monotonic() + seconds
        while not request.Test():
            if time.monotonic() > deadline:
                return False
            time.sleep(POLL_SECONDS)
        return int(total[0]) == self.size

    def abort(self, message: str, code: int = 1) -> None:
        """``message`` on this rank's standard error (even where the rank's output is
        silenced), then every rank ends with exit status ``code``."""
        print(message, file=sys.__stderr__, flush=True)
        self.world.Abort(code)
