"""The MPI tests: run by every rank (``mpiexec -n N python -m pytest tests/mpi``), never
collected by the default test run (``norecursedirs`` in pyproject.toml), so a missing
petsc4py fails here instead of skipping.

Each rank runs the same tests in the same order; a check is decided on every rank from
the values of all ranks (:func:`agree`), so no rank fails alone and leaves the others
waiting in a collective call.
"""
import pytest

from skfem_nem.parallel import import_petsc


@pytest.fixture(scope="session")
def PETSc():
    """petsc4py's PETSc module (an error naming the installation route if missing)."""
    return import_petsc()


@pytest.fixture(scope="session")
def comm(PETSc):
    return PETSc.COMM_WORLD


@pytest.fixture(scope="session")
def agree(comm):
    """``agree(value)``: the list of ``value`` on every rank, the same on all ranks."""
    mpi = comm.tompi4py()
    return mpi.allgather
