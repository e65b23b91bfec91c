"""A plate run's cell fields between one process and the parts of MPI ranks.

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

from ..parallel.petsc import joined, maximum, summed

__all__ = ["part_rows", "whole_rows", "over_parts"]


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
