"""Freed arrays given back to the system at once: glibc's mmap of large blocks, on.

Why: importing petsc4py starts MPI, and Open MPI turns off glibc's mmap of large blocks
(``M_MMAP_MAX`` 0, for the memory registration of RDMA networks). From then on every array
of a Stokes solve (the blocks, the exchanged rows, PETSc's matrices and multigrid set-up)
is carved out of the heap, and what it frees stays there: the resident memory of a rank
only grows, and the next stage's arrays do not always fit in the holes. Measured in a
process that imported petsc4py: 200 arrays of 1 MB, every other one freed, left 409 MB
resident, where with mmap on again it fell to 314 MB. :func:`map_large_blocks` turns it
back on, with a fixed threshold of 128 kB (glibc's initial one, which otherwise grows with
the largest block freed): every array-sized block is a mapping of its own, returned when
freed. It costs time, as each fresh mapping is zeroed page by page: a step of the plate
on four ranks (195,857 nodes) took 16% longer for 12% less memory a rank (48.4-48.9 s at
1,360 MB against 41.4-42.1 s at 1,527-1,550 MB). A run over MPI, where memory per rank
is the point, calls it once MPI has started
(:class:`~skfem_nem.apps.sinking_plate.SinkingPlate` and the 3D plate with solver
``"petsc"``, ``benchmarks/mpi.py``); a script of one's own calls it after its first
PETSc solve or import. On an RDMA network whose MPI caches registered memory without
intercepting ``munmap`` (older MPI libraries), leave it off.
"""
from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["MMAP_THRESHOLD", "map_large_blocks"]

#: blocks of this many bytes and more get a mapping of their own (glibc's initial value,
#: here kept fixed instead of growing with the largest block freed)
MMAP_THRESHOLD = 128 * 1024
#: the most blocks mapped at once (glibc's default; Open MPI sets 0)
MMAP_MAX = 65536
# mallopt's parameter numbers (glibc's malloc.h)
_M_MMAP_THRESHOLD, _M_MMAP_MAX = -3, -4


def map_large_blocks(threshold: int = MMAP_THRESHOLD) -> bool:
    """Turn glibc's mmap of large blocks on (:data:`MMAP_MAX` of them) with the threshold
    fixed at ``threshold`` bytes, for the rest of the process; whether it was set (False
    where the C library is not glibc: nothing changes)."""
    if not (isinstance(threshold, int) and 0 < threshold <= 32 * 1024 * 1024):
        raise ValueError(f"threshold must be a number of bytes in (0, 32 MiB], got "
                         f"{threshold!r}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    return bool(mallopt(_M_MMAP_MAX, MMAP_MAX)) and bool(mallopt(_M_MMAP_THRESHOLD,
                                                                 threshold))
