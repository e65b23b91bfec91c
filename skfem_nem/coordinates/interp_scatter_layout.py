"""Where the scatter's triangles and queries lie in memory, so that they meet in cache.

:mod:`~skfem_nem.coordinates.interp_scatter` loops over the Delaunay triangles and, for each,
over the queries in its circumcircle. The triangles are stored as records (geometry, values
and the box of the disk's part that can hold queries), in the order of a grid of about one
triangle per cell, row by row; the queries are sorted into a bucket grid of about one query
per bucket (a regular grid of queries in ``np.meshgrid``'s order is its own and is not
sorted), whose rows the threads take in bands, each band looking at the triangles of the
records' grid rows near it.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..geometry.hull import HULL_TOLERANCE

__all__ = ["TriangleRecords", "bounds", "query_layout", "record_range", "RECORD_VALUES",
           "TALL"]

# the values at a record's vertices a, b, c start at this column (see :func:`_records`)
RECORD_VALUES = 20

# records of triangles whose clipped disk is more than TALL cells (of the records' grid)
# high are kept in a list of their own, so that the others of a band of queries are found
# from the grid rows near it
TALL = 8
# queries per bucket of the query grid (about one: a circle then tests few queries outside)
BUCKET_QUERIES = 1.0
# a regular grid of queries is taken as its own bucket grid if its points are within
# GRID_ROUNDOFF spacings of the lattice (linspace's are within ulps); the rows and columns of
# a disk are then found with a slack of GRID_SLACK spacings (> the round-off: no query in the
# circle is missed, and only queries that close to it are tested in vain)
GRID_ROUNDOFF = 1e-9
GRID_SLACK = 1e-6


@njit(cache=True)
def _circle_box(P, T, N, t, cx, cy, r, lo, hi):
    """(xmin, xmax, ymin, ymax) of triangle t's circumdisk (centre (cx, cy), radius r)
    clipped to the bounding box [lo, hi] of the data and, at a hull edge, to the hull's side
    of it (the disk's segment there: its chord's ends and the disk's extreme points on that
    side); empty (min > max) if nothing is left."""
    b0, b1, b2, b3 = max(lo[0], cx - r), min(hi[0], cx + r), max(lo[1], cy - r), \
        min(hi[1], cy + r)
    for k in range(3):
        if N[t, k] >= 0:
            continue
        a, b = T[t, (k + 1) % 3], T[t, (k + 2) % 3]
        ex, ey = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1]
        s0, s1 = min(P[a, 0], P[b, 0]), max(P[a, 0], P[b, 0])
        s2, s3 = min(P[a, 1], P[b, 1]), max(P[a, 1], P[b, 1])
        # the hull is to the left of a -> b; an extreme point counts if on that side
        if ex * (cy - P[a, 1]) - ey * (cx - r - P[a, 0]) >= 0:
            s0 = cx - r
        if ex * (cy - P[a, 1]) - ey * (cx + r - P[a, 0]) >= 0:
            s1 = cx + r
        if ex * (cy - r - P[a, 1]) - ey * (cx - P[a, 0]) >= 0:
            s2 = cy - r
        if ex * (cy + r - P[a, 1]) - ey * (cx - P[a, 0]) >= 0:
            s3 = cy + r
        b0, b1, b2, b3 = max(b0, s0), min(b1, s1), max(b2, s2), min(b3, s3)
    return b0, b1, b2, b3


@njit(cache=True)
def _records(P, T, N, CC, V, lo, hi):
    """``(R, rowstart, tall, side)``: one row of R per triangle whose clipped disk is not
    empty, in the order of their boxes' centres on a grid of cells of ``side`` from ``lo``,
    about one triangle per cell, row by row (so that consecutive triangles meet the same
    queries): vertices a, b, c (6), the circumcentre minus each (6), S = cross(b - a, c - a),
    for the edges ab, bc, ca the least cross(a - x, b - x) etc. of a query not on the hull
    (HULL_TOLERANCE |ab|^2 at a hull edge, the package's rule, else -inf) (3), the clipped
    box (4), the values at a, b, c (3 K). Rows ``rowstart[j]:rowstart[j + 1]`` are the grid
    row j; ``tall`` are the rows whose box is more than TALL cells high."""
    nt, K = T.shape[0], V.shape[1]
    box = np.empty((nt, 4))
    nc = max(1, int(np.sqrt(nt)))
    side = max(hi[0] - lo[0], hi[1] - lo[1]) / nc * (1 + 1e-9) + 1e-300
    cell = np.empty(nt, np.int64)
    count = np.zeros(nc * nc + 1, np.int64)
    for t in range(nt):
        cx, cy = P[T[t, 0], 0] + CC[t, 0], P[T[t, 0], 1] + CC[t, 1]
        box[t, 0], box[t, 1], box[t, 2], box[t, 3] = _circle_box(
            P, T, N, t, cx, cy, np.sqrt(CC[t, 0] ** 2 + CC[t, 1] ** 2), lo, hi)
        cell[t] = -1
        if box[t, 0] <= box[t, 1] and box[t, 2] <= box[t, 3]:
            i = min(nc - 1, int((0.5 * (box[t, 0] + box[t, 1]) - lo[0]) / side))
            j = min(nc - 1, int((0.5 * (box[t, 2] + box[t, 3]) - lo[1]) / side))
            cell[t] = j * nc + i
            count[cell[t] + 1] += 1
    for c in range(nc * nc):
        count[c + 1] += count[c]
    rowstart = count[::nc].copy()
    R = np.empty((count[nc * nc], RECORD_VALUES + 3 * K))
    for t in range(nt):
        if cell[t] < 0:
            continue
        r = count[cell[t]]
        count[cell[t]] += 1
        a = T[t, 0]
        for k in range(3):
            v = T[t, k]
            R[r, 2 * k], R[r, 2 * k + 1] = P[v, 0], P[v, 1]
            R[r, 6 + 2 * k] = CC[t, 0] + (P[a, 0] - P[v, 0])
            R[r, 7 + 2 * k] = CC[t, 1] + (P[a, 1] - P[v, 1])
            for j in range(K):
                R[r, RECORD_VALUES + k * K + j] = V[v, j]
            # edge k + 1, k + 2 of the record (ab, bc, ca) is opposite vertex k + 2
            u, w = T[t, k], T[t, (k + 1) % 3]
            R[r, 13 + k] = -np.inf if N[t, (k + 2) % 3] >= 0 else HULL_TOLERANCE * (
                (P[w, 0] - P[u, 0]) ** 2 + (P[w, 1] - P[u, 1]) ** 2)
        R[r, 12] = ((R[r, 2] - R[r, 0]) * (R[r, 5] - R[r, 1])
                    - (R[r, 3] - R[r, 1]) * (R[r, 4] - R[r, 0]))
        R[r, 16:20] = box[t]
    tall = np.flatnonzero(R[:, 19] - R[:, 18] > TALL * side)
    return R, rowstart, tall, side


@njit(cache=True)
def _bucket_sort(Q, x0, y0, h, nx, ny, order, start, Qs):
    """Counting sort of the queries Q (m, 2) into the nx * ny buckets of side h from
    (x0, y0), row by row: ``order[s]`` is the query at sorted place s, ``Qs[s]`` its point,
    bucket j holds the places ``start[j]:start[j + 1]``."""
    m = Q.shape[0]
    cell = np.empty(m, np.int64)
    start[:] = 0
    for i in range(m):
        cx = min(nx - 1, max(0, int((Q[i, 0] - x0) / h)))
        cy = min(ny - 1, max(0, int((Q[i, 1] - y0) / h)))
        cell[i] = cy * nx + cx
        start[cell[i] + 1] += 1
    for j in range(nx * ny):
        start[j + 1] += start[j]
    fill = start[:-1].copy()
    for i in range(m):
        s = fill[cell[i]]
        fill[cell[i]] = s + 1
        order[s] = i
        Qs[s, 0] = Q[i, 0]
        Qs[s, 1] = Q[i, 1]


@njit(cache=True)
def _regular_grid(Q, tol):
    """``(nx, ny, x0, y0, hx, hy)`` if the points Q (m, 2) are a grid in row-major order
    (x fastest, both increasing, as ``np.meshgrid`` gives), within ``tol`` spacings of the
    lattice; nx = 0 if not."""
    m = Q.shape[0]
    nx = 1
    while nx < m and Q[nx, 1] == Q[0, 1]:
        nx += 1
    ny = m // nx
    if nx < 2 or ny < 2 or ny * nx != m:
        return 0, 0, 0.0, 0.0, 0.0, 0.0
    x0, y0 = Q[0, 0], Q[0, 1]
    hx, hy = (Q[nx - 1, 0] - x0) / (nx - 1), (Q[m - 1, 1] - y0) / (ny - 1)
    ok = hx > 0 and hy > 0
    for c in range(nx):
        ok = ok and abs(Q[c, 0] - (x0 + c * hx)) <= tol * hx
    for r in range(ny):
        yr = Q[r * nx, 1]
        ok = ok and abs(yr - (y0 + r * hy)) <= tol * hy
        for c in range(nx):
            ok = ok and Q[r * nx + c, 1] == yr and Q[r * nx + c, 0] == Q[c, 0]
        if not ok:
            return 0, 0, 0.0, 0.0, 0.0, 0.0
    return nx, ny, x0, y0, hx, hy


@njit(cache=True)
def bounds(Q):
    """(xmin, ymin, xmax, ymax) of the points Q (m, 2), m > 0."""
    x0, y0, x1, y1 = Q[0, 0], Q[0, 1], Q[0, 0], Q[0, 1]
    for i in range(Q.shape[0]):
        x0, x1 = min(x0, Q[i, 0]), max(x1, Q[i, 0])
        y0, y1 = min(y0, Q[i, 1]), max(y1, Q[i, 1])
    return x0, y0, x1, y1


def query_layout(q):
    """``(Qs, start, order, lay, ny)``: the queries q (m, 2) in bucket order, the buckets'
    CSR starts (bucket j holds the places ``start[j]:start[j + 1]``), the sort (``Qs[s] =
    q[order[s]]``; empty: none), and the bucket grid: ``lay = (x0, y0, hx, hy, nx, margin)``
    with ny rows. A regular grid of queries is its own bucket grid, a bucket per query
    (margin 1/2 - GRID_SLACK: a row of buckets is the line of its queries to the scatter);
    any other set is sorted into about ``BUCKET_QUERIES`` to a bucket (margin 0)."""
    m = q.shape[0]
    nx, ny, x0, y0, hx, hy = _regular_grid(q, GRID_ROUNDOFF)
    if nx:
        lay = (x0 - 0.5 * hx, y0 - 0.5 * hy, hx, hy, nx, 0.5 - GRID_SLACK)
        return q, np.arange(m + 1), np.empty(0, np.int64), lay, ny
    x0, y0, x1, y1 = bounds(q)
    h = max(np.sqrt((x1 - x0) * (y1 - y0) * BUCKET_QUERIES / m),
            max(x1 - x0, y1 - y0) * BUCKET_QUERIES / m)
    h = h if h > 0 else 1.0
    nx, ny = int((x1 - x0) / h) + 1, int((y1 - y0) / h) + 1
    order, start, Qs = np.empty(m, np.int64), np.empty(nx * ny + 1, np.int64), np.empty((m, 2))
    _bucket_sort(q, x0, y0, h, nx, ny, order, start, Qs)
    return Qs, start, order, (x0, y0, h, h, nx, 0.0), ny


@njit(cache=True)
def record_range(rowstart, ylo, side, y0, y1):
    """``(j0, j1)``: the records' grid rows j0 <= j < j1 holding every record, not a tall
    one, whose box meets y0 <= y <= y1 (its centre is within TALL / 2 cells of the box's
    ends; a cell more for round-off)."""
    nc = rowstart.shape[0] - 1
    j0 = min(nc, max(0, int((y0 - ylo) / side) - TALL - 1))
    j1 = min(nc, max(0, int((y1 - ylo) / side) + TALL + 2))
    return j0, j1


class TriangleRecords:
    """The records of the triangles of a :class:`~skfem_nem.Triangulation` with the values V
    (n, K) (real) at its nodes: ``R`` (see :func:`_records`) and their grid (``rowstart``,
    ``tall``, ``side`` from ``ylo``)."""

    def __init__(self, triangulation, V):
        P = triangulation.nodes
        self.ylo = float(P[:, 1].min())
        self.R, self.rowstart, self.tall, self.side = _records(
            P, triangulation.triangles, triangulation.neighbours,
            np.ascontiguousarray(triangulation.circumcircles[:, :2]),
            np.ascontiguousarray(V, dtype=np.float64), P.min(axis=0), P.max(axis=0))

    def count_near(self, q) -> int:
        """How many records the scatter looks at for the points q (m, 2): those of the grid
        rows near their y range (see :func:`record_range`) and the tall ones."""
        _, lo, _, hi = bounds(q)
        j0, j1 = record_range(self.rowstart, self.ylo, self.side, lo, hi)
        return int(self.rowstart[j1] - self.rowstart[j0]) + self.tall.size
