"""What a sinking-plate step keeps of its Stokes solve between steps.

Why a record of its own: a :class:`~skfem_nem.models.stokes.StokesSolution` holds its
spaces (the natural-neighbour bases at every quadrature point) and its reduced system, a
gigabyte at 30,000 nodes in 3D and at 360,000 in 2D. Kept from one step to the next, they
would stand beside the next step's spaces and system at that step's peak. A step keeps
only the arrays the next step and the outputs read: the velocity dofs (the next Picard
start), the velocity and pressure at the nodes (the snapshots), and two counts.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np

__all__ = ["LastSolve"]


class LastSolve(NamedTuple):
    """The velocity dofs ``u`` and pressure dofs ``p`` of a step's last Stokes solve,
    the velocity (n, dim) and pressure (n,) at the n nodes it was solved on, the cells
    whose bases this process built for it (``cells``; over MPI its part of them) and the
    MPI ranks the solve ran on."""

    u: np.ndarray
    p: np.ndarray
    velocity: np.ndarray
    pressure: np.ndarray
    cells: int
    ranks: int

    @classmethod
    def of(cls, solution, cells: Optional[np.ndarray], ncells: int) -> "LastSolve":
        """The record of ``solution`` solved on the cells ``cells`` (None: all
        ``ncells``)."""
        return cls(solution.u, solution.p, solution.velocity_at_nodes(),
                   solution.pressure_at_nodes(), ncells if cells is None else int(cells.size),
                   int(solution.info.get("ranks", 1)))
