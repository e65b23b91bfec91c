"""Node sets for natural-neighbour meshes: random nodes in a box, graded by a
density, and nodes along lines (material interfaces, walls).

All functions return plain ``(n, 2)`` float arrays; build the mesh with
:func:`skfem_nem.delaunay_mesh`.
"""
from __future__ import annotations

from typing import Callable, Optional, Sequence

import numpy as np
from numba import njit

__all__ = ["box_nodes", "draw_interior", "hilbert_order", "line_segments", "morton_order",
           "polyline_nodes", "remove_close"]

# random nodes closer than this fraction of the local spacing to a side or a
# line node are dropped (near-duplicates make slivers)
CLEARANCE = 0.25
# side and line nodes are merged when equal to this many decimals
MERGE_DECIMALS = 12
# density values up to 1 + this are accepted as 1 (round-off of the caller)
DENSITY_SLACK = 1e-12
# relative widening of a segment's diametral disc, so that points on its
# circle count as inside (round-off)
DISC_SLACK = 1e-9
# levels of the Hilbert curve of hilbert_order: a grid of 2^16 cells a side, finer than
# any node spacing of a mesh that fits in memory, its index within an int64
HILBERT_BITS = 16
# levels of morton_order's grid: 2^(MORTON_BITS * d) cells must fit in an int64 (d <= 4)
MORTON_BITS = 15


def polyline_nodes(vertices, spacing: float, closed: bool = False) -> np.ndarray:
    """Nodes along a polyline, about ``spacing`` apart, vertices included.

    Parameters
    ----------
    vertices
        (k, 2) corner points.
    spacing
        Target distance between consecutive nodes (length units); each
        segment is split into ``ceil(length / spacing)`` equal parts.
    closed
        Join the last vertex back to the first.

    Returns
    -------
    (m, 2) array, each vertex once.
    """
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 2:
        raise ValueError(f"vertices must have shape (k >= 2, 2), got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError(f"vertex {int(np.flatnonzero(~np.isfinite(v).all(1))[0])} is not finite")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a positive number, got {spacing}")
    segs = np.r_[v, v[:1]] if closed else v
    out = []
    for a, b in zip(segs[:-1], segs[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
        t = np.arange(k)[:, None] / k
        out.append(a + t * (b - a))
    if not closed:
        out.append(v[-1:])
    return np.concatenate(out)


def hilbert_order(points) -> np.ndarray:
    """The order of ``points`` (n, 2) along a Hilbert curve through their bounding square.

    Points close in space get close positions, so ``points[hilbert_order(points)]``
    numbers a node set such that a triangle's nodes, and a stencil's, have nearby
    indices: the rows of the matrices assembled over them touch nearby memory.

    >>> p = np.array([[0.9, 0.1], [0.1, 0.1], [0.9, 0.9], [0.1, 0.9]])
    >>> hilbert_order(p).tolist()
    [1, 3, 2, 0]
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or not np.isfinite(P).all():
        raise ValueError(f"points must be a finite (n, 2) array, got shape {P.shape}")
    if P.shape[0] == 0:
        return np.empty(0, dtype=np.int64)
    n = 1 << HILBERT_BITS
    lo = P.min(axis=0)
    span = float((P.max(axis=0) - lo).max()) or 1.0
    cell = np.minimum(((P - lo) / span * n).astype(np.int64), n - 1)
    x, y = cell[:, 0].copy(), cell[:, 1].copy()
    d = np.zeros(P.shape[0], dtype=np.int64)
    s = n >> 1
    while s:
        rx, ry = (x & s) > 0, (y & s) > 0
        d += s * s * ((3 * rx) ^ ry)
        # the quadrant's curve is the whole curve turned: reflect, then swap x and y
        flip = ~ry & rx
        x[flip], y[flip] = n - 1 - x[flip], n - 1 - y[flip]
        swap = ~ry
        x[swap], y[swap] = y[swap], x[swap]
        s >>= 1
    return np.argsort(d, kind="stable")


def morton_order(points) -> np.ndarray:
    """The order of ``points`` (n, d) along the Z-order (Morton) curve through their
    bounding box, any dimension up to 4.

    A batch of queries taken in this order walks the triangulation's memory a
    neighbourhood at a time: 3D coordinates of random queries among random nodes
    take about half the time (``docs/ndim.md``). The Hilbert curve of
    :func:`hilbert_order` keeps neighbours closer but a batch needs only locality.

    >>> p = np.array([[0.9, 0.1], [0.1, 0.1], [0.9, 0.9], [0.1, 0.9]])
    >>> morton_order(p).tolist()
    [1, 0, 3, 2]
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or not 1 <= P.shape[1] <= 4 or not np.isfinite(P).all():
        raise ValueError(f"points must be a finite (n, d <= 4) array, got shape {P.shape}")
    d = P.shape[1]
    bits = min(MORTON_BITS, 62 // d)
    lo = P.min(axis=0)
    span = np.where(P.max(axis=0) > lo, P.max(axis=0) - lo, 1.0)
    cell = np.minimum(((P - lo) / span * (1 << bits)).astype(np.int64), (1 << bits) - 1)
    return np.argsort(_morton_keys(cell, bits), kind="stable")


@njit(cache=True)
def _morton_keys(cell, bits):
    """The Z-order key of each row of the integer cells (n, d): their bits interleaved
    (in numpy, one pass over the array per bit and axis: 0.4 s for 2 million points)."""
    n, d = cell.shape
    key = np.zeros(n, np.int64)
    for i in range(n):
        x = 0
        for b in range(bits):
            for k in range(d):
                x |= ((cell[i, k] >> b) & 1) << (b * d + k)
        key[i] = x
    return key


def remove_close(points, keep, distance: float) -> np.ndarray:
    """``points`` without those closer than ``distance`` to any of ``keep``."""
    from scipy.spatial import cKDTree
    points = np.asarray(points, dtype=float)
    keep = np.asarray(keep, dtype=float)
    if points.size == 0 or keep.size == 0:
        return points
    d, _ = cKDTree(keep).query(points)
    return points[d >= distance]


def box_nodes(n: int, width: float = 1.0, height: float = 1.0,
              density: Optional[Callable[[np.ndarray], np.ndarray]] = None,
              seed: int = 0, boundary_spacing: Optional[float] = None,
              lines: Sequence[np.ndarray] = (), origin=(0.0, 0.0)) -> np.ndarray:
    """Random nodes in the box ``[x0, x0 + width] x [y0, y0 + height]``.

    The four corners and nodes along the four sides come first (so the
    convex hull is the box and nodal wall conditions are exact), then the
    nodes of ``lines`` (kept exactly), then ``n`` random interior nodes drawn
    with probability proportional to ``density`` (a function of (m, 2) points
    with values in (0, 1]; uniform if None). Random nodes closer than a
    quarter of the local spacing to a side or a line node are dropped, so
    fewer than ``n`` may remain.

    Parameters
    ----------
    n
        Number of random interior nodes drawn.
    width, height, origin
        The box (length units).
    density
        Relative node density, values in (0, 1].
    seed
        Random seed (the result is reproducible).
    boundary_spacing
        Spacing of the nodes on the sides; default the mean spacing
        ``sqrt(width * height / n)``.
    lines
        Arrays of (k, 2) nodes to include exactly (e.g. from
        :func:`polyline_nodes`), each read as a polyline: random nodes inside
        the diametral disc of one of its segments are dropped, so that every
        segment becomes an edge of the Delaunay triangulation (material
        interfaces along the lines are then not cut by triangles).

    Returns
    -------
    (m, 2) array of nodes, no duplicates.
    """
    _check_box(n, width, height)
    x0, y0 = map(float, origin)
    rng = np.random.default_rng(seed)
    h = np.sqrt(width * height / n)
    hb = h if boundary_spacing is None else float(boundary_spacing)
    fixed = _fixed_nodes(x0, y0, width, height, hb, lines)
    inner = draw_interior(rng, n, (x0, y0), (width, height), density)
    # local spacing ~ h / sqrt(density)
    loc = h if density is None else h / np.sqrt(np.asarray(density(inner)))
    margin = np.minimum.reduce([inner[:, 0] - x0, x0 + width - inner[:, 0],
                                inner[:, 1] - y0, y0 + height - inner[:, 1]])
    inner = inner[margin > CLEARANCE * np.minimum(loc, hb)]
    if len(lines):
        inner = _clear_lines(inner, lines, h, density)
    return np.concatenate([fixed, inner])


def line_segments(nodes, line, closed: bool = False) -> np.ndarray:
    """The polyline ``line`` (k, 2), whose points are nodes of ``nodes`` (n, 2) (as
    :func:`box_nodes` keeps the nodes of its ``lines``, rounded to ``MERGE_DECIMALS``
    decimals), as (k - 1, 2) segments of node indices (k with ``closed``), for
    ``delaunay_mesh(nodes, segments=...)``. Raises ``ValueError`` naming the first
    point of the line that is no node to that rounding.

    >>> import numpy as np
    >>> line = np.array([[0.5, 0.0], [0.5, 0.5], [0.5, 1.0]])
    >>> p = box_nodes(50, lines=[line], seed=1)
    >>> segs = line_segments(p, line)
    >>> segs.shape, bool((p[segs[:, 0], 0] == 0.5).all())
    ((2, 2), True)
    """
    from scipy.spatial import cKDTree
    line = np.asarray(line, dtype=np.float64).reshape(-1, 2)
    dist, idx = cKDTree(np.asarray(nodes, dtype=np.float64)).query(line)
    bad = np.flatnonzero(dist > 10.0 ** -MERGE_DECIMALS)
    if bad.size:
        raise ValueError(f"line point {bad[0]} at {line[bad[0]].tolist()} is not a node")
    nxt = np.roll(idx, -1) if closed else idx[1:]
    return np.c_[idx[:nxt.size], nxt]


def _check_box(n, width, height) -> None:
    """Raise ``ValueError`` naming the first bad size of :func:`box_nodes`."""
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n}")
    for name, val in (("width", width), ("height", height)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a positive number, got {val}")


def _fixed_nodes(x0: float, y0: float, width: float, height: float, hb: float,
                 lines: Sequence[np.ndarray]) -> np.ndarray:
    """Corners, side nodes ``hb`` apart and the nodes of ``lines`` (duplicates
    merged when there are lines)."""
    corners = np.array([[x0, y0], [x0 + width, y0], [x0 + width, y0 + height],
                        [x0, y0 + height]])
    walls = polyline_nodes(corners, hb, closed=True)
    fixed = [walls] + [np.asarray(l, dtype=float).reshape(-1, 2) for l in lines]
    fixed = np.concatenate(fixed)
    return np.unique(np.round(fixed, MERGE_DECIMALS), axis=0) if len(lines) else fixed


def draw_interior(rng: np.random.Generator, n: int, origin, size,
                  density: Optional[Callable]) -> np.ndarray:
    """``n`` random points in the box ``origin + [0, size]`` (any dimension), accepted with
    probability ``density``; ``ValueError`` if ``density`` is not one value in (0, 1] per
    point."""
    origin, size = np.asarray(origin, dtype=float), np.asarray(size, dtype=float)
    pts = []
    count = 0
    while count < n:
        c = rng.random((2 * n, size.size)) * size + origin
        if density is not None:
            d = np.asarray(density(c), dtype=float)
            if d.shape != (c.shape[0],) or not np.all((d > 0) & (d <= 1 + DENSITY_SLACK)):
                raise ValueError("density must return one value in (0, 1] per point")
            c = c[rng.random(c.shape[0]) < d]
        c = c[: n - count]
        pts.append(c)
        count += c.shape[0]
    return np.concatenate(pts)


def _clear_lines(inner: np.ndarray, lines: Sequence[np.ndarray], h: float,
                 density: Optional[Callable]) -> np.ndarray:
    """``inner`` without the points close to a line node or inside the
    diametral disc of a line segment."""
    from scipy.spatial import cKDTree
    extra = np.concatenate([np.asarray(l, dtype=float).reshape(-1, 2) for l in lines])
    d, _ = cKDTree(extra).query(inner)
    loc = h if density is None else h / np.sqrt(np.asarray(density(inner)))
    inner = inner[d > CLEARANCE * loc]
    for l in lines:
        inner = _clear_diametral_discs(inner, np.asarray(l, dtype=float).reshape(-1, 2))
    return inner


def _clear_diametral_discs(inner: np.ndarray, line: np.ndarray) -> np.ndarray:
    """``inner`` without the points in the diametral disc of a segment of the
    polyline ``line``: keeping the discs empty (Gabriel property) makes each
    segment an edge of the Delaunay triangulation, so material interfaces
    along the lines are not cut by triangles."""
    from scipy.spatial import cKDTree
    if line.shape[0] < 2:
        return inner
    mid = 0.5 * (line[1:] + line[:-1])
    rad = 0.5 * np.linalg.norm(line[1:] - line[:-1], axis=1)
    near = cKDTree(mid).query_ball_point(inner, r=rad.max() * (1 + DISC_SLACK))
    bad = np.array([any(np.linalg.norm(inner[i] - mid[j]) <= rad[j] * (1 + DISC_SLACK)
                        for j in js) for i, js in enumerate(near)], dtype=bool)
    return inner[~bad] if bad.size else inner
