"""A plate run over MPI: its ranks, its cell fields between one process and the ranks'
parts, and the check that the ranks' meshes agree.

Why a module of its own: the 2D and the 3D sinking plate run over MPI the same way. Each
rank builds the bases of its part of the cells (``stokes_spaces(..., elements="owned")``)
and updates the integration-point fields (stress, plastic strain, effective viscosity)
there; the fields of all cells are then joined on every rank, where the replicated
evolution moves them with the mesh. A step's sums and maxima over the cells (yielded
points, the largest stress) are taken over the ranks. ``cells`` None means one process
holds all cells, and every function here is then the identity.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..parallel.failures import FailureChannel
from ..parallel.heap import map_large_blocks
from ..parallel.petsc import joined, maximum, ranks_differing, summed, world

__all__ = ["start_ranks", "check_same_mesh", "part_rows", "whole_rows", "over_parts"]


def start_ranks(solver: str):
    """``(rank, ranks, failures)`` of a run with ``solver``: over MPI (``"petsc"``) the
    world's, with the channel by which a failure of one rank ends every rank (built by all
    ranks here; None on one rank) and mmap of freed arrays back on (:mod:`..parallel.heap`);
    otherwise ``(0, 1, None)``."""
    if solver != "petsc":
        return 0, 1, None
    rank, ranks = world()
    map_large_blocks()
    return rank, ranks, FailureChannel() if ranks > 1 else None


def check_same_mesh(nodes: np.ndarray, cells: np.ndarray, time: float, step: int) -> None:
    """``RuntimeError`` if the ranks' meshes differ (nodes, cells or clock): the replicated
    evolution must stay the same on every rank."""
    differ = ranks_differing((nodes, cells, np.array([time])))
    if differ:
        raise RuntimeError(f"the mesh of rank(s) {differ} differs from rank 0's after "
                           f"step {step}: the evolution is no longer replicated")


def part_rows(field: Optional[np.ndarray], cells: Optional[np.ndarray]):
    """An integration-point field (one row per cell) at the cells ``cells`` (this rank's
    part; None: all of them; a missing field stays None)."""
    return field if field is None or cells is None else field[cells]


def whole_rows(part: np.ndarray, cells: Optional[np.ndarray], n: int) -> np.ndarray:
    """The field of all ``n`` cells from every rank's ``part`` on its ``cells``, on every
    rank (``part`` itself where ``cells`` is None)."""
    return part if cells is None else joined(part, cells, n)


def over_parts(value: float, cells: Optional[np.ndarray], largest: bool = False) -> float:
    """The sum (or with ``largest`` the largest) of ``value`` over the ranks holding parts
    of the cells (``value`` itself where ``cells`` is None)."""
    if cells is None:
        return value
    return float((maximum if largest else summed)(np.array([value], dtype=float))[0])
