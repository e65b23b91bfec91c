"""Freed arrays given back to the system at once: a fixed mmap threshold for glibc.

Why: glibc's ``malloc`` serves blocks below its mmap threshold from the heap, and raises
the threshold (up to 32 MB) each time a larger mapped block is freed. After the first
large array comes and goes, the arrays of a Stokes solve (blocks, exchanged rows, PETSc's
matrices and multigrid set-up) are carved out of the heap, and what they free stays there
in pieces: the resident memory keeps its high-water mark and the next stage's arrays do
not always fit in the holes. With the threshold fixed at 128 kB every array-sized block is
a mapping of its own, returned when freed. Measured on the first step of the sinking plate
(195,857 nodes, four ranks): the peak per rank fell from 1,654 to 1,542 MB (7%) at the
same seconds. A run over MPI, where memory per rank is the point, sets it
(:class:`~skfem_nem.apps.sinking_plate.SinkingPlate` with solver ``"petsc"``); a script of
one's own calls :func:`map_large_blocks` first, or sets ``MALLOC_MMAP_THRESHOLD_=131072``.
"""
from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["MMAP_THRESHOLD", "map_large_blocks"]

#: blocks of this many bytes and more get a mapping of their own (glibc's initial value,
#: here kept fixed instead of growing with the largest block freed)
MMAP_THRESHOLD = 128 * 1024
# mallopt's parameter number for the threshold (glibc's malloc.h)
_M_MMAP_THRESHOLD = -3


def map_large_blocks(threshold: int = MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes for the rest of the process;
    whether it was set (False where the C library is not glibc: nothing changes)."""
    if not (isinstance(threshold, int) and 0 < threshold <= 32 * 1024 * 1024):
        raise ValueError(f"threshold must be a number of bytes in (0, 32 MiB], got "
                         f"{threshold!r}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, threshold))
