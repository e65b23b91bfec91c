"""The parts of the domain the MPI ranks own: recursive coordinate bisection.

A rank assembles the cells of its part and owns the rows of the unknowns that live there;
the rows its cells touch outside the part (the halo) are assembled in part and sent to
their owners. Strips along one axis have the most surface a part can have: in 3D a strip
of a quarter of 34,553 nodes is some eight nodes thick and its tetrahedra touched 23-38%
more nodes than it owns (natural-neighbour stencils hold about 21 nodes a tetrahedron).
Bisection halves the set along its longest extent, again and again, with the ranks split
in proportion, so four ranks own the four columns of a 2 x 2 cut and the largest halo
halves. The cuts are planes computed once from the mesh's nodes and then applied to any
points (cell centroids, unknowns' locations), the same on every rank; no PETSc here.

>>> import numpy as np
>>> from skfem_nem.parallel.partition import Bisection
>>> p = np.array([[0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
>>> Bisection(p, 4).part(p).tolist()
[0, 2, 1, 3]
"""
from __future__ import annotations

from typing import Union

import numpy as np

__all__ = ["Bisection"]

# a cut: (axis, value, below, above) with below and above a part number or another cut
Cut = Union[int, tuple]


class Bisection:
    """Recursive coordinate bisection of ``points`` (dim, n) into ``parts`` parts of
    nearly equal counts (parts ``0 .. parts - 1``): each cut puts its share of the points
    below it to within one where no two points share a coordinate there, so a part's
    count is ``n / parts`` to within the number of cuts above it, plus one."""

    def __init__(self, points: np.ndarray, parts: int):
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or not np.isfinite(points).all():
            raise ValueError(f"points must be a finite (dim, n) array, got shape "
                             f"{points.shape}")
        if int(parts) != parts or parts < 1:
            raise ValueError(f"parts must be a positive integer, got {parts}")
        self.parts = int(parts)
        self.root = _cut(points, np.arange(points.shape[1]), self.parts, 0)

    def part(self, x: np.ndarray) -> np.ndarray:
        """(n,) the part of each point of ``x`` (dim, n); points with a coordinate that
        is not finite (an unknown without a location) get ``parts``, after all others."""
        x = np.asarray(x, dtype=float)
        out = np.full(x.shape[1], self.parts, dtype=np.int64)
        placed = np.isfinite(x).all(axis=0)
        stack = [(self.root, np.flatnonzero(placed))]
        while stack:
            node, idx = stack.pop()
            if not isinstance(node, tuple):
                out[idx] = node
                continue
            axis, value, below, above = node
            low = x[axis, idx] < value
            stack += [(below, idx[low]), (above, idx[~low])]
        return out


def _cut(points: np.ndarray, idx: np.ndarray, parts: int, first: int) -> Cut:
    """The cuts of the points ``idx`` into ``parts`` parts numbered from ``first``: along
    the axis of their longest extent, halfway between the two points that put
    ``parts // 2`` parts' share below."""
    if parts == 1 or idx.size < 2:
        return first
    below = parts // 2
    sub = points[:, idx]
    axis = int(np.argmax(np.ptp(sub, axis=1)))
    x = np.sort(sub[axis])
    m = min(max(int(round(idx.size * below / parts)), 1), idx.size - 1)
    value = 0.5 * (x[m - 1] + x[m])
    low = sub[axis] < value
    return (axis, value, _cut(points, idx[low], below, first),
            _cut(points, idx[~low], parts - below, first + below))
