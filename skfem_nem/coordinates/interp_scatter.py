"""Sibson's interpolant of a large 2D batch of queries, triangle by triangle (a scatter).

Why: the gather path (:class:`~skfem_nem.coordinates.interp_natural.NaturalInterpolant` over
the area method of :mod:`~skfem_nem.coordinates.area2d`) finds each query's cavity by a walk
and a traversal and stores its row of coordinates; on a million grid queries that is ten
times the cost of scipy's piecewise-linear interpolant. When only the values are wanted the
loop can be turned inside out: over the Delaunay triangles, and for each over the queries
inside its circumcircle (the triangles whose circumcircle holds a query are its cavity),
accumulating per query ``sum_i A_i f_i`` and ``sum_i A_i``, whose ratio is the interpolant.
No walk, no stored coordinates. The triangles are stored in spatial order, one record each;
the queries are sorted into a bucket grid (a regular grid of queries is its own), whose rows
are shared out in bands to the threads.

Watson's signed decomposition (1992)
    For a query x in the circumcircle (centre o, radius R) of the Delaunay triangle
    T = (a, b, c) (counter-clockwise), let g_ab, g_bc, g_ca be the circumcentres of
    (x, a, b), (x, b, c), (x, c, a). The area that x's new Voronoi cell takes from a's is
    the sum, over the cavity triangles T at a, of the signed areas [o, g_ca, g_ab] (for b:
    [o, g_ab, g_bc], for c: [o, g_bc, g_ca]): the Voronoi edges of a inside x's cell run
    between the o's, each through the g of its Delaunay edge, and all the g's of a lie on
    the bisector of x and a, so the signed triangles telescope to the polygon. As g_ab lies
    on the bisector of ab, g_ab - o = D / (2 e_ab) perp(b - a) with D = R^2 - |x - o|^2 and
    e_ab = cross(a - x, b - x), so [o, g_ca, g_ab] = S D^2 / (8 e_ca e_ab), S = cross(b - a,
    c - a): the term of a is ``A_a = S D^2 / (e_ab e_ca)`` (the common 1/8 cancels in the
    ratio), b's ``S D^2 / (e_bc e_ab)``, c's ``S D^2 / (e_ca e_bc)``. They vanish as x
    reaches the circumcircle (D = 0), so it does not matter on which side of the circle
    round-off puts a query: the in-circle test is the sign of D in floating point.

Flagged queries
    The terms grow as 1 / e_ab as x nears the line of the edge ab (within the circle: the
    edge itself, or a or b), and those of the two triangles at the edge cancel. Queries whose
    terms cancel too much (see ``DEN_MIN``), with a zero divisor (on an edge, at a data
    point) or on a hull edge by the package's rule (``HULL_TOLERANCE``: the area method
    gives them the edge's linear weights) are returned as flagged; the caller recomputes
    them by the area method.
"""
from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from ..geometry.triangulation import Triangulation
from .interp_scatter_layout import (RECORD_VALUES, TALL, TriangleRecords, query_layout,
                                    record_range)

__all__ = ["SibsonScatter", "scatter_applies"]

# A query is flagged when the sum of its terms (x's new cell) is at most DEN_MIN times the
# sum of their magnitudes: its value then loses ~ log10(magnitudes / sum) digits to the
# cancellation, each term being accurate to a few ulps (measured: within ~1e-13 of the area
# method's with 1e-3, which flags ~0.1% of random queries). A query on an edge or at a data
# point (a zero divisor: infinite or NaN terms) fails the test too.
DEN_MIN = 1e-3
# D = R^2 - |x - o|^2 is computed from vertex a, with an error of ~ |a - x| R ulps; its
# relative error near another vertex v is ~ |a - x| / |v - x| ulps, so within NEAR_VERTEX
# |a - x| of b or c (rarely) it is computed from that vertex instead (error <= 100 ulps).
NEAR_VERTEX = 1e-2
# bands of bucket rows per thread (the threads take bands as they come free)
BANDS_PER_THREAD = 4


def scatter_applies(triangulation) -> bool:
    """True for an unconstrained Delaunay :class:`~skfem_nem.Triangulation` (the scatter
    needs the cavities to be the triangles whose circumcircle holds the query)."""
    return (isinstance(triangulation, Triangulation) and not triangulation.segment_keys.size
            and triangulation.non_delaunay_edges() == 0)


@njit(cache=True, inline="always")
def _power(vx, vy, ox, oy):
    """R^2 - |x - o|^2 from a vertex v of the triangle: -(v - x).((v - x) + 2 (o - v)), given
    v - x = (vx, vy) and o - v = (ox, oy); its error is ~ |v - x| R ulps."""
    return -(vx * (vx + 2 * ox) + vy * (vy + 2 * oy))


@njit(cache=True, inline="always", error_model="numpy")
def _terms(g, qx, qy, hull):
    """``(inside, A_a, A_b, A_c)``: whether the query (qx, qy) is in the circumcircle of the
    triangle of geometry g (``R[t, :16]`` as scalars) and, if so, its terms
    A_a = S D^2 / (e_ab e_ca) etc. (see the module's docstring); NaN terms (a flag) for a
    query on a hull edge by the package's rule (the area method gives it the edge's linear
    weights) if the triangle has one (``hull``: a loop invariant, which the compiler takes
    out of the loop). Scalars in and out: numba inlines this into the loop as well as hand-written
    code (not so a function that writes to arrays: the kernel ran at half the speed)."""
    ax, ay = g[0] - qx, g[1] - qy
    D = _power(ax, ay, g[6], g[7])
    if not D > 0:
        return False, 0.0, 0.0, 0.0
    bx, by = g[2] - qx, g[3] - qy
    cx, cy = g[4] - qx, g[5] - qy
    na, nb, nc = abs(ax) + abs(ay), abs(bx) + abs(by), abs(cx) + abs(cy)
    if nb < NEAR_VERTEX * na or nc < NEAR_VERTEX * na:  # rare: a branch, not a select
        D = _power(bx, by, g[8], g[9]) if nb <= nc else _power(cx, cy, g[10], g[11])
    # e_ab has the same bits in both triangles at the edge ab
    eab, ebc, eca = ax * by - ay * bx, bx * cy - by * cx, cx * ay - cy * ax
    if hull and (eab <= g[13] or ebc <= g[14] or eca <= g[15]):
        return True, np.nan, np.nan, np.nan
    qab, qbc, qca = D / eab, D / ebc, D / eca
    return True, g[12] * qab * qca, g[12] * qab * qbc, g[12] * qbc * qca


@njit(cache=True, inline="always", error_model="numpy")
def _triangle(R, t, Qs, start, lay, r0, r1, acc):
    """Scatters triangle t onto the queries of bucket rows r0..r1 in its circumcircle (per
    row, the buckets the disk's chord over the row's strip spans; ``lay`` = (x0, y0, hx, hy,
    nx, margin): the buckets' origin, sides and row length, and the margin that makes a
    bucket of a regular grid of queries the line through its row of queries, within
    GRID_SLACK): ``acc[s] = (sum A_i f_i, sum A_i, sum |A_i|)`` for the query at place s."""
    x0, y0, hx, hy, nx, gm = lay
    # the record as scalars, loaded once (stores to acc could alias R)
    g = (R[t, 0], R[t, 1], R[t, 2], R[t, 3], R[t, 4], R[t, 5], R[t, 6], R[t, 7], R[t, 8],
         R[t, 9], R[t, 10], R[t, 11], R[t, 12], R[t, 13], R[t, 14], R[t, 15])
    bx0, bx1, by0, by1 = R[t, 16], R[t, 17], R[t, 18], R[t, 19]
    hull = g[13] > -np.inf or g[14] > -np.inf or g[15] > -np.inf
    r2 = g[6] * g[6] + g[7] * g[7]
    cx, cy = g[0] + g[6], g[1] + g[7]
    K = acc.shape[1] - 2
    v = RECORD_VALUES
    fa, fb, fc = R[t, v], R[t, v + K], R[t, v + 2 * K]
    ihx, ihy = 1.0 / hx, 1.0 / hy
    for r in range(max(r0, int((by0 - y0) * ihy + gm)), min(r1, int((by1 - y0) * ihy - gm)) + 1):
        dy = max(0.0, y0 + (r + gm) * hy - cy, cy - y0 - (r + 1 - gm) * hy)
        if dy * dy >= r2:
            continue
        w = np.sqrt(r2 - dy * dy)
        c0 = max(0, int((max(bx0, cx - w) - x0) * ihx + gm))
        c1 = min(nx - 1, int((min(bx1, cx + w) - x0) * ihx - gm))
        if c0 > c1:
            continue
        for s in range(start[r * nx + c0], start[r * nx + c1 + 1]):
            inside, wa, wb, wc = _terms(g, Qs[s, 0], Qs[s, 1], hull)
            if not inside:
                continue
            if K == 1:  # scalar values (most calls): loaded once, out of the loop
                acc[s, 0] += wa * fa + wb * fb + wc * fc
            else:
                for k in range(K):
                    acc[s, k] += (wa * R[t, v + k] + wb * R[t, v + K + k]
                                  + wc * R[t, v + 2 * K + k])
            acc[s, K] += wa + wb + wc
            acc[s, K + 1] += abs(wa) + abs(wb) + abs(wc)


@njit(cache=True, inline="always")
def _finish(acc, s0, s1, order, out, bad):
    """``out[i] = acc[s, :K] / acc[s, K]`` for the places s0..s1 - 1 (query i = ``order[s]``;
    ``order`` empty: i = s), or NaN and ``bad[i] = 1`` for a flagged query."""
    K = out.shape[1]
    for s in range(s0, s1):
        i = order[s] if order.shape[0] else s
        den = acc[s, K]
        ok = den > DEN_MIN * acc[s, K + 1]
        for k in range(K):
            out[i, k] = acc[s, k] / den if ok else np.nan
        bad[i] = not ok


@njit(cache=True, parallel=True, error_model="numpy")
def _scatter(R, rowstart, tall, ylo, side, Qs, start, lay, ny, rows, order, acc, out, bad):
    """The triangles near each band of ``rows`` bucket rows onto its queries, then their
    values (bands in parallel: each writes only its own queries' rows of ``acc``, ``out``
    and ``bad``). A band looks at the tall records and those of the records' grid rows near
    it; a triangle spanning bands is scattered by each onto its own rows."""
    y0, hy, nx = lay[1], lay[3], lay[4]
    ntall = tall.shape[0]
    for bnd in prange(-(-ny // rows)):
        r0, r1 = bnd * rows, min(ny, (bnd + 1) * rows) - 1
        s0, s1 = start[r0 * nx], start[(r1 + 1) * nx]
        acc[s0:s1] = 0.0
        yb0, yb1 = y0 + r0 * hy, y0 + (r1 + 1) * hy
        j0, j1 = record_range(rowstart, ylo, side, yb0, yb1)
        for i in range(ntall + rowstart[j1] - rowstart[j0]):
            t = tall[i] if i < ntall else rowstart[j0] + i - ntall
            if R[t, 19] < yb0 or R[t, 18] > yb1 or \
                    (i >= ntall and R[t, 19] - R[t, 18] > TALL * side):
                continue    # not this band's, or listed among the tall ones
            _triangle(R, t, Qs, start, lay, r0, r1, acc)
        _finish(acc, s0, s1, order, out, bad)


class SibsonScatter:
    """Sibson's interpolant of ``values`` (n, K), real or complex, on the unconstrained
    Delaunay :class:`~skfem_nem.Triangulation` ``triangulation`` (see
    :func:`scatter_applies`), evaluated by the scatter of this module's docstring."""

    def __init__(self, triangulation, values):
        self.K = values.shape[1]
        self.complex = np.iscomplexobj(values)
        V = np.c_[values.real, values.imag] if self.complex else values
        self.records = TriangleRecords(triangulation, V)
        self.width = V.shape[1]
        self.dtype = complex if self.complex else float

    @property
    def bytes_per_query(self) -> int:
        """Work space of a query (its sort, its sums, its value)."""
        return 96 + 16 * self.width + (16 if self.complex else 8) * self.K

    def triangles_near(self, q) -> int:
        """How many triangles the scatter looks at for the points q (m, 2)."""
        return self.records.count_near(q)

    def __call__(self, q):
        """``(values, flagged)``: the interpolant at the points q (m, 2) inside the hull,
        (m, K), and the indices of the queries it leaves to the caller (their rows are
        NaN)."""
        q = np.ascontiguousarray(q, dtype=np.float64)
        if not (q.shape[0] and self.width):
            return np.zeros((q.shape[0], self.K), self.dtype), np.empty(0, np.int64)
        Qs, start, order, lay, ny = query_layout(q)
        rows = -(-ny // max(1, min(ny, BANDS_PER_THREAD * numba.get_num_threads())))
        m = q.shape[0]
        acc, out = np.empty((m, self.width + 2)), np.empty((m, self.width))
        bad = np.empty(m, np.bool_)
        with numba.parallel_chunksize(1):
            rec = self.records
            _scatter(rec.R, rec.rowstart, rec.tall, rec.ylo, rec.side, Qs, start, lay, ny,
                     rows, order, acc, out, bad)
        if self.complex:
            out = out[:, :self.K] + 1j * out[:, self.K:]
        return out, np.flatnonzero(bad)
