"""Node sets in three dimensions: random nodes in a box whose faces carry nodes.

Beside :mod:`skfem_nem.geometry.nodesets` (2D) because a 3D box needs its own
boundary: the eight corners, nodes along the twelve edges and random nodes on the six
faces, so that the convex hull is the box and each face is a plane of nodes. On a hull
face the 3D natural-neighbour functions reduce to the face's own 2D ones, so nodal wall
conditions (free slip, no slip) hold on the whole face. Each face is drawn by the 2D
:func:`~skfem_nem.geometry.nodesets.box_nodes` with the edges' spacing, so two faces
that meet share the nodes of their edge exactly.
"""
from __future__ import annotations

from typing import Callable, Optional, Sequence

import numpy as np

from .nodesets import CLEARANCE, MERGE_DECIMALS, box_nodes, draw_interior

__all__ = ["box_nodes_3d"]


def box_nodes_3d(n: int, size: Sequence[float] = (1.0, 1.0, 1.0),
                 density: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                 seed: int = 0, boundary_spacing: Optional[float] = None,
                 origin: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Random nodes in the box ``origin + [0, size[0]] x [0, size[1]] x [0, size[2]]``.

    The faces' nodes come first (corners, edges ``boundary_spacing`` apart, random
    nodes on each face at that spacing), then ``n`` random interior nodes drawn with
    probability proportional to ``density`` (a function of (m, 3) points with values
    in (0, 1]; uniform if None). Interior nodes closer than a quarter of the local
    spacing to a face are dropped, so fewer than ``n`` may remain.

    Parameters
    ----------
    n
        Number of random interior nodes drawn.
    size, origin
        The box's edge lengths and its lowest corner.
    density
        Relative node density, values in (0, 1].
    seed
        Random seed (the result is reproducible).
    boundary_spacing
        Spacing of the nodes on the faces; default the mean spacing
        ``(volume / n)^(1/3)``.

    Returns
    -------
    (m, 3) array of nodes, no duplicates.

    >>> p = box_nodes_3d(200, seed=1)
    >>> p.shape[1], bool((p.min(axis=0) == 0).all() and (p.max(axis=0) == 1).all())
    (3, True)
    """
    size, origin = _check_box3(n, size, origin)
    rng = np.random.default_rng(seed)
    h = float(np.prod(size) / n) ** (1.0 / 3.0)
    hb = h if boundary_spacing is None else float(boundary_spacing)
    if not (np.isfinite(hb) and hb > 0):
        raise ValueError(f"boundary_spacing must be a positive number, got {boundary_spacing}")
    faces = _face_nodes(size, origin, hb, seed)
    inner = draw_interior(rng, n, origin, size, density)
    loc = h if density is None else h / np.cbrt(np.asarray(density(inner)))
    rel = inner - origin
    margin = np.minimum(rel, size - rel).min(axis=1)
    inner = inner[margin > CLEARANCE * np.minimum(loc, hb)]
    return np.concatenate([faces, inner])


def _check_box3(n, size, origin):
    """The box as arrays; ``ValueError`` naming the first bad argument."""
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n}")
    size = np.asarray(size, dtype=float)
    origin = np.asarray(origin, dtype=float)
    if size.shape != (3,) or not np.all(np.isfinite(size) & (size > 0)):
        raise ValueError(f"size must be three positive numbers, got {np.asarray(size).tolist()}")
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"origin must be three finite numbers, got {origin.tolist()}")
    return size, origin


def _face_nodes(size: np.ndarray, origin: np.ndarray, hb: float, seed: int) -> np.ndarray:
    """The nodes of the six faces (corners and edges once), ``hb`` apart."""
    out = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        m = max(int(round(size[a] * size[b] / hb ** 2)), 1)
        p2 = box_nodes(m, size[a], size[b], seed=seed + 7 * axis, boundary_spacing=hb)
        for side in (0.0, size[axis]):
            p = np.empty((p2.shape[0], 3))
            p[:, a], p[:, b], p[:, axis] = p2[:, 0], p2[:, 1], side
            out.append(p + origin)
    p = np.concatenate(out)
    # edges belong to two faces: keep each node once (the 2D sides place them alike)
    _, first = np.unique(np.round(p, MERGE_DECIMALS), axis=0, return_index=True)
    return p[np.sort(first)]
