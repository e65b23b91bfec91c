"""Which part of the Stokes system this process assembles: all of it, or one MPI
rank's share of a distributed solve.

Kept apart from :mod:`skfem_nem.models.stokes` (forms, assembly, the solve) because it is
one concern of its own: spaces built whole are restricted to this rank's part of the cells
for ``solver="petsc"``; spaces built on some cells only (``stokes_spaces(...,
elements=...)``) are this rank's share as they are, checked once to partition the mesh
with the other ranks'; and the numbers every rank needs the same of are reduced over the
ranks (:func:`largest`). Nothing here imports petsc4py before a share is asked for.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from .stokes_bases import StokesSpaces

__all__ = ["Share", "distributed", "divided_share", "check_divided", "largest"]


class Share(NamedTuple):
    """A distributed assembly: this MPI rank's share of the system, whether it is rank
    0 (which alone adds what is not assembled over triangles: the constraint rows),
    and the sum of a vector over the ranks."""

    root: bool
    total: Callable[[np.ndarray], np.ndarray]


def distributed(spaces: StokesSpaces, solver: str):
    """The spaces to assemble on and the :class:`Share`: for solver ``"petsc"`` on
    several MPI ranks, this rank's part of the cells (distributed assembly); else
    all of ``spaces`` and None."""
    if spaces.elements is not None:
        return spaces, divided_share(spaces, solver)
    if solver != "petsc":
        return spaces, None
    from ..parallel.petsc import owned_elements, summed, world
    mine = owned_elements(spaces.mesh)
    if mine is None:
        return spaces, None
    # kept with the spaces: the Picard iterations of a step solve on the same part
    cache = spaces.__dict__.setdefault("_cache", {})
    key = ("part", mine.tobytes())
    if key not in cache:
        cache[key] = spaces.restricted(mine)
    return cache[key], Share(world()[0] == 0, summed)


def check_divided(spaces: StokesSpaces, solver: str) -> None:
    """``ValueError`` for spaces built on some cells only (one MPI rank's share,
    ``stokes_spaces(..., elements=...)``) with a solver other than ``"petsc"``."""
    if spaces.elements is not None and solver != "petsc":
        cells = "tetrahedra" if spaces.dim == 3 else "triangles"
        raise ValueError(f"these spaces hold {spaces.elements.size} of the mesh's "
                         f"{spaces.mesh.nelements} {cells} (one MPI rank's share): "
                         f"solve them with solver='petsc', got solver={solver!r}")


def largest(spaces: StokesSpaces, value: float) -> float:
    """The largest of ``value`` over the MPI ranks where ``spaces`` are one rank's share
    (built on some cells only), else ``value``: a number every rank needs the same of
    (the smallest viscosity of the mesh, whether a step iterates)."""
    if spaces.elements is None:
        return float(value)
    from ..parallel.petsc import maximum
    return float(maximum(np.array([value], dtype=float))[0])


def divided_share(spaces: StokesSpaces, solver: str) -> Share:
    """The :class:`Share` of spaces built on some cells only (``stokes_spaces(...,
    elements=...)``): a rank's part of a distributed solve, which needs ``"petsc"`` and
    the ranks' cells to be a partition of the mesh (checked once; ``ValueError`` naming
    the first cell assembled by no rank or by several)."""
    cells = "tetrahedra" if spaces.dim == 3 else "triangles"
    check_divided(spaces, solver)
    from ..parallel.petsc import summed, world
    if not spaces.__dict__.get("_partition_checked"):
        count = np.zeros(spaces.mesh.nelements)
        count[spaces.elements] = 1.0
        count = summed(count)
        bad = np.flatnonzero(count != 1.0)
        if bad.size:
            raise ValueError(f"the ranks' {cells} must be a partition of the mesh: "
                             f"{cells[:-1] if spaces.dim == 2 else 'tetrahedron'} "
                             f"{int(bad[0])} is in the spaces of {int(count[bad[0]])} "
                             f"rank(s) ({bad.size} such)")
        spaces._partition_checked = True
    return Share(world()[0] == 0, summed)
