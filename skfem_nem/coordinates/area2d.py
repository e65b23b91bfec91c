"""Sibson and Laplace natural-neighbour coordinates in 2D, with exact gradients (the area method).

The public functions (:mod:`skfem_nem.coordinates.dispatch`) send 2D queries here by default;
3D and 4D nodes, and ``method="lasserre"`` in 2D, go to the paper's Box 1 method,
:mod:`skfem_nem.coordinates.lasserre`. :func:`area_coordinates` is this method's entry point.

For a query point x inside the convex hull of the nodes, the natural
neighbours of x are the vertices of the Delaunay triangles whose circumcircle
strictly contains x (the Bowyer--Watson cavity of x). Ordered
counter-clockwise around x, consecutive neighbours p_i, p_{i+1} give the
vertices ``v_i = circumcentre(x, p_i, p_{i+1})`` of the Voronoi cell x would
have if it were inserted; the circumcentres ``o_t`` of the cavity triangles are
the old Voronoi vertices that the insertion destroys.

Sibson (area) coordinates
    ``phi_i = A_i / A`` where ``A_i`` is the area of the polygon
    ``(o_t1, ..., o_tr, v_{i-1}, v_i)`` -- the part of node i's old Voronoi cell
    taken by x -- and ``A = sum_i A_i`` (so the coordinates sum to one to
    round-off). Gradient: with ``s_i = |v_i - v_{i-1}|`` (the new Voronoi edge
    between x and p_i), ``c_i`` its midpoint and ``h_i = |p_i - x|``,
    ``grad A_i = (s_i / h_i) (c_i - x)`` and
    ``grad phi_i = (grad A_i - phi_i sum_j grad A_j) / A``.

Laplace (non-Sibsonian) coordinates
    ``lambda_i = w_i / sum_j w_j`` with ``w_i = s_i / h_i``; the gradient
    follows from the derivative of the circumcentres ``v`` with respect to x,
    ``dv/dx = m (v - x)^T`` with ``[p_i - x; p_{i+1} - x] m = (1, 1)``.

Robustness
    Every quantity is computed in coordinates relative to x, and the
    denominators (twice the signed areas of the triangles (x, p_i, p_{i+1})
    and of the cavity triangles) come from the adaptive exact predicate
    :func:`skfem_nem.geometry.predicates.orient2d`, accurate to a few ulps however flat
    the triangle. Nothing divides by a quantity that vanishes on an interior
    Delaunay edge, so values and gradients are exact there; co-circular nodes
    (structured grids) give the same result whichever diagonal the
    triangulation holds. A query on a convex-hull edge gets the linear 1D
    weights of the edge's two nodes, a query at a node the Kronecker delta.

Cost
    Per query: a walk from the previous query's triangle (or a bucket-grid
    seed), one depth-first traversal that collects the cavity and orders its
    boundary counter-clockwise at the same time (the cavity of a Delaunay
    triangulation is a tree of triangles), in-circle tests decided by the
    cached circumcircles unless they are within round-off of the circle
    (then by the exact predicate), and the Sibson areas summed edge by edge
    over that tree. All of it is inlined into one kernel for a block of
    consecutive queries, compiled without reference counting, which a
    parallel loop runs over the blocks; they write their rows straight into
    staging buffers that are copied in parallel into the CSR arrays: numba
    reference-counts the arrays passed to a called function with atomic
    operations, which would cost more than the geometry and keep a second
    thread from helping.

Undefined gradients
    The gradient is undefined at a node (the coordinates have a cone-like
    kink there), and on a hull edge this module does not compute the
    one-sided limit. Asking for gradients at such a point raises
    ``ValueError`` naming the query (``undefined="raise"``, the default), or
    gives NaN rows for those queries only (``undefined="nan"``).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .batch import RowStore, check_queries, index_dtype, raise_outside, raise_undefined
from ..geometry.hull import HULL_TOLERANCE, OUTSIDE_ROUNDOFF
from ..geometry.status import AT_NODE, OK, ON_HULL, OUTSIDE, OVERFLOW
from ..geometry.predicates import orient2d
from ..geometry.triangulation import Triangulation
from ..geometry.delaunay2d import (cavity_boundary, conflict_cycle, grow_cavity, is_segment,
                                   locate_walk)

__all__ = ["area_coordinates"]

SIBSON = 0
LAPLACE = 1



@njit(cache=True, inline="always")
def _circumcentre_rel(ax, ay, bx, by, d):
    """Circumcentre of (0, a, b) given d = cross(a, b) (twice the area)."""
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    f = 0.5 / d
    return (by * a2 - ay * b2) * f, (ax * b2 - bx * a2) * f


@njit(cache=True, inline="always")
def _at_node(P, T, t, qx, qy, pos, s_i, s_v, s_gx, s_gy, want_grad):
    """1 (and the Kronecker-delta row, written from ``pos`` on) if the point
    is a vertex of triangle t, else 0."""
    for j in range(3):
        a = T[t, j]
        if P[a, 0] == qx and P[a, 1] == qy:
            s_i[pos] = a
            s_v[pos] = 1.0
            if want_grad:
                s_gx[pos] = np.nan
                s_gy[pos] = np.nan
            return 1
    return 0


@njit(cache=True, inline="always")
def _general_cavity(P, T, N, S, qx, qy, t, cav, cnb, rej, nn, be_b, be_c, be_u,
                    cpar, cchd, cpa, cpb):
    """The cavity by :func:`grow_cavity` (any triangulation), in the form
    :func:`conflict_cycle` gives: returns ``(ncav, nb, nedge)`` and the
    internal edges e = 1..nedge in ``cpar, cchd, cpa, cpb``; ncav < 0 if the
    buffers are too small."""
    ncav = grow_cavity(P, T, N, S, qx, qy, t, cav, cnb, rej)
    if ncav < 0:
        return -1, -1, 0
    nb = cavity_boundary(T, N, cav, cnb, ncav, nn, be_b, be_c, be_u)
    if nb < 0:
        return -1, -1, 0
    nedge = 0
    for c in range(ncav):
        tc = cav[c]
        for kk in range(3):
            d = cnb[c, kk]
            if d > c:
                a = T[tc, (kk + 1) % 3]
                b = T[tc, (kk + 2) % 3]
                ja = -1
                jb = -1
                for j in range(nb):
                    if nn[j] == a:
                        ja = j
                    if nn[j] == b:
                        jb = j
                if ja < 0 or jb < 0 or nedge + 1 == cav.shape[0]:
                    # a node inside the cavity: not a Delaunay triangulation
                    continue
                nedge += 1
                cpar[nedge] = c
                cchd[nedge] = d
                cpa[nedge] = ja
                cpb[nedge] = jb
    return ncav, nb, nedge


@njit(cache=True, inline="always")
def _on_hull(P, S, nn, be_u, nb, qx, qy, pos, s_i, s_v, s_gx, s_gy, want_grad):
    """2 (and the row of linear 1D weights, written from ``pos`` on) if the
    point lies, to round-off, on a hull edge or a segment of the cavity
    boundary; else 0."""
    for j in range(nb):
        a = nn[j]
        b = nn[j + 1 if j + 1 < nb else 0]
        if be_u[j] < 0 or is_segment(S, a, b):
            ex = P[b, 0] - P[a, 0]
            ey = P[b, 1] - P[a, 1]
            L2 = ex * ex + ey * ey
            o = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy)
            if o <= HULL_TOLERANCE * L2:
                s = ((qx - P[a, 0]) * ex + (qy - P[a, 1]) * ey) / L2
                s = min(max(s, 0.0), 1.0)
                lo = min(a, b)
                s_i[pos] = lo
                s_i[pos + 1] = a + b - lo
                v0 = 1.0 - s if lo == a else s
                s_v[pos] = v0
                s_v[pos + 1] = 1.0 - v0
                if want_grad:
                    for jj in range(2):
                        s_gx[pos + jj] = np.nan
                        s_gy[pos + jj] = np.nan
                return 2
    return 0


@njit(cache=True, inline="always")
def _new_vertices(P, nn, nb, qx, qy, vx, vy, dv):
    """The new Voronoi vertices v_j = circumcentre(x, p_j, p_{j+1}) relative to
    x into ``vx, vy``, and twice the areas of (p_j, p_{j+1}, x) into ``dv``."""
    for j in range(nb):
        a = nn[j]
        b = nn[j + 1 if j + 1 < nb else 0]
        d = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy)
        dv[j] = d
        vx[j], vy[j] = _circumcentre_rel(P[a, 0] - qx, P[a, 1] - qy,
                                         P[b, 0] - qx, P[b, 1] - qy, d)


@njit(cache=True, inline="always")
def _sibson_areas(CC, qx, qy, cav, ncav, be_c, nb, cpar, cchd, cpa, cpb, nedge,
                  vx, vy, ox, oy, area):
    """Twice the Sibson areas A_i, of the polygons (o_t1, ..., o_tr, v_{i-1}, v_i),
    into ``area[:nb]`` (every factor 1/2 cancels in phi and grad phi); the old
    Voronoi vertices o_t come from the circumcircles ``CC``.

    Summed edge by edge: the boundary edge j in cavity triangle c gives
    cross(v_j, o_c) to node j and its negative to node j + 1; the internal
    edge from node a to node b between the cavity triangles c -> d gives
    cross(o_c, o_d) to b and its negative to a; each node i also gets
    cross(v_{i-1}, v_i).
    """
    for c in range(ncav):
        tc = cav[c]
        ox[c] = (CC[tc, 3] - qx) + CC[tc, 0]
        oy[c] = (CC[tc, 4] - qy) + CC[tc, 1]
    for j in range(nb):
        jm = j - 1 if j > 0 else nb - 1
        area[j] = vx[jm] * vy[j] - vy[jm] * vx[j]
    for j in range(nb):
        c = be_c[j]
        w = vx[j] * oy[c] - vy[j] * ox[c]
        area[j] += w
        area[j + 1 if j + 1 < nb else 0] -= w
    for e in range(1, nedge + 1):
        c = cpar[e]
        d = cchd[e]
        w = ox[c] * oy[d] - oy[c] * ox[d]
        area[cpb[e]] += w
        area[cpa[e]] -= w


@njit(cache=True, inline="always")
def _sibson_gradients(P, nn, nb, qx, qy, vx, vy, gax, gay):
    """Twice grad A_i = 2 (s_i / h_i) (c_i - x), c_i the midpoint of v_{i-1}
    and v_i, into ``gax, gay``."""
    for i in range(nb):
        im = i - 1 if i > 0 else nb - 1
        p = nn[i]
        px = P[p, 0] - qx
        py = P[p, 1] - qy
        ex = vx[i] - vx[im]
        ey = vy[i] - vy[im]
        f = np.sqrt((ex * ex + ey * ey) / (px * px + py * py))
        gax[i] = f * (vx[im] + vx[i])
        gay[i] = f * (vy[im] + vy[i])


@njit(cache=True, inline="always")
def _laplace_weights(P, nn, nb, qx, qy, vx, vy, dv, want_grad, area, gax, gay):
    """Laplace weights w_i = s_i / h_i into ``area`` and, if ``want_grad``,
    their gradients into ``gax, gay``."""
    for i in range(nb):
        im = i - 1 if i > 0 else nb - 1
        p = nn[i]
        px = P[p, 0] - qx
        py = P[p, 1] - qy
        h = np.sqrt(px * px + py * py)
        ex = vx[i] - vx[im]
        ey = vy[i] - vy[im]
        s = np.sqrt(ex * ex + ey * ey)
        area[i] = s / h
        if want_grad:
            # d s / dx = (e . m_i) (v_i - x) - (e . m_{i-1}) (v_{i-1} - x)
            dsx = 0.0
            dsy = 0.0
            if s > 0.0:
                ex /= s
                ey /= s
                for side in range(2):
                    sgn = 1.0 if side == 0 else -1.0
                    jv = i if side == 0 else im
                    a = nn[jv]
                    b = nn[jv + 1 if jv + 1 < nb else 0]
                    mx = ((P[b, 1] - qy) - (P[a, 1] - qy)) / dv[jv]
                    my = ((P[a, 0] - qx) - (P[b, 0] - qx)) / dv[jv]
                    em = sgn * (ex * mx + ey * my)
                    dsx += em * vx[jv]
                    dsy += em * vy[jv]
            # w = s / h,  dh/dx = (x - p) / h
            gax[i] = dsx / h + s * px / (h * h * h)
            gay[i] = dsy / h + s * py / (h * h * h)


@njit(cache=True, inline="always")
def _write_row(nn, nb, area, gax, gay, want_grad, perm, pos, s_i, s_v, s_gx, s_gy):
    """phi_i = A_i / A and grad phi_i = (grad A_i - phi_i sum_j grad A_j) / A
    into the outputs from ``pos`` on, sorted by node index.

    The dominant neighbour d gets its gradient from complement sums,
    grad phi_d = (grad A_d (1 - phi_d) - phi_d sum_{j != d} grad A_j) / A,
    which avoids the cancellation of two O(1/r) terms at distance r from
    node d (the plain formula loses digits like eps * spacing / r there).
    """
    dom = 0
    for i in range(1, nb):
        if area[i] > area[dom]:
            dom = i
    rest = 0.0
    gcx = 0.0
    gcy = 0.0
    for i in range(nb):
        if i != dom:
            rest += area[i]
            if want_grad:
                gcx += gax[i]
                gcy += gay[i]
    total = area[dom] + rest
    inv = 1.0 / total
    gsx = gax[dom] + gcx
    gsy = gay[dom] + gcy
    # insertion sort of a permutation by node index (small)
    for i in range(nb):
        key = nn[i]
        j = i
        while j > 0 and nn[perm[j - 1]] > key:
            perm[j] = perm[j - 1]
            j -= 1
        perm[j] = i
    for r in range(nb):
        i = perm[r]
        phi = area[i] * inv
        s_i[pos + r] = nn[i]
        s_v[pos + r] = phi
        if want_grad:
            if i == dom:
                s_gx[pos + r] = (gax[i] * (rest * inv) - phi * gcx) * inv
                s_gy[pos + r] = (gay[i] * (rest * inv) - phi * gcy) * inv
            else:
                s_gx[pos + r] = (gax[i] - phi * gsx) * inv
                s_gy[pos + r] = (gay[i] - phi * gsy) * inv


@njit(cache=True, error_model="numpy", _nrt=False)
def _query_block(P, T, N, S, CC, Q, start, grid, nc, glo, gspan, kind, want_grad, general, width,
                 lo, hi, pos, end, s_i, s_v, s_gx, s_gy, count, status, tri, ib, fb, cnb):
    """Natural-neighbour coordinates of the points Q[lo:hi], one after another.

    ``start`` (m,): the triangle each walk starts from, or empty: then the
    bucket grid ``grid`` (nc * nc,) over the box ``glo`` (2,) + ``gspan`` (2,)
    gives one (see :meth:`Triangulation.seed_grid`) and consecutive queries also
    try the previous query's triangle. ``CC``: :attr:`Triangulation.circumcircles`.
    ``general``: find cavities with :func:`grow_cavity` (any triangulation)
    instead of the traversal :func:`conflict_cycle` (Delaunay
    triangulations; the fast path).

    Outputs: the rows, one after another from position ``pos`` on, in the
    flat arrays ``s_i`` (node indices, sorted within each row), ``s_v``
    (values), ``s_gx``, ``s_gy`` (gradients, if ``want_grad``); ``count[q]``
    entries, ``status[q]`` a status code and ``tri[q]`` a triangle containing
    the point, for q in [lo, hi). Rows with more than ``width`` natural
    neighbours, and all rows once fewer than ``width`` positions are left
    before ``end``, get status OVERFLOW and no entries. Returns the position
    after the last entry. Work space: ``ib`` (14, width + 4) int64, ``fb``
    (8, width + 2) float64 and ``cnb`` (width, 3) int64, from :func:`_work_space`.

    Everything it calls is inlined, and it is compiled without reference
    counting (it allocates nothing): numba reference-counts the array
    arguments of the functions it calls with atomic operations, which cost
    more than the geometry and keep threads from scaling. It is called once
    per block and not inlined into :func:`_query_all`: numba's parallel passes
    over the inlined code took most of a first run's compilation (34 s of 60).
    """
    # Long kernel: one pass over a block of queries keeps each query's walk, cavity, areas
    # and row in registers and reuses the block's buffers; split into calls, every stage
    # would pass the 25 buffers again per query.
    ccap = width
    cav, cpar, cchd, cpa = ib[0, :ccap], ib[1, :ccap], ib[2, :ccap], ib[3, :ccap]
    cpb, cedge, cstep, stk = ib[4, :ccap], ib[5, :ccap], ib[6, :ccap], ib[7, :ccap]
    rej = ib[8, :ccap + 4]
    nn, be_b, be_u = ib[9, :ccap + 2], ib[10, :ccap + 2], ib[11, :ccap + 2]
    be_c, perm = ib[12, :ccap + 2], ib[13, :ccap + 2]
    ox, oy = fb[0, :ccap], fb[1, :ccap]
    vx, vy, dv = fb[2, :ccap + 2], fb[3, :ccap + 2], fb[4, :ccap + 2]
    area, gax, gay = fb[5, :ccap + 2], fb[6, :ccap + 2], fb[7, :ccap + 2]
    prev = -1
    for q in range(lo, hi):
        count[q] = 0
        if end - pos < width:
            # out of room: left for a second pass
            status[q] = OVERFLOW
            tri[q] = prev if prev >= 0 else 0
            continue
        qx = Q[q, 0]
        qy = Q[q, 1]
        if start.shape[0]:
            t0 = start[q]
        else:
            f0 = min(max((qx - glo[0]) / gspan[0] * nc, 0.0), nc - 1.0)
            f1 = min(max((qy - glo[1]) / gspan[1] * nc, 0.0), nc - 1.0)
            t0 = grid[int(f0) * nc + int(f1)]
        if t0 < 0:
            t0 = 0
        # start the walk from the seed or from the previous query's
        # triangle, whichever is nearer (sorted queries walk ~1 step); a given
        # start is kept (on a hull convex only to round-off, a walk from
        # elsewhere may stop at a hull edge the point is beyond by an ulp)
        if prev >= 0 and not start.shape[0]:
            a = T[t0, 0]
            b = T[prev, 0]
            da = (P[a, 0] - qx) ** 2 + (P[a, 1] - qy) ** 2
            db = (P[b, 0] - qx) ** 2 + (P[b, 1] - qy) ** 2
            if db < da:
                t0 = prev
        t, k = locate_walk(P, T, N, qx, qy, t0)
        tri[q] = t
        cnt = 0
        st = OK
        if k >= 0 or t < 0:
            st = OUTSIDE
        else:
            prev = t
            cnt = _at_node(P, T, t, qx, qy, pos, s_i, s_v, s_gx, s_gy, want_grad)
            if cnt:
                st = AT_NODE
        if st == OK and cnt == 0:
            # the cavity, its boundary as a counter-clockwise cycle
            # nn[0..nb-1] around x, and its internal edges
            if general:
                ncav, nb, nedge = _general_cavity(P, T, N, S, qx, qy, t, cav, cnb, rej, nn,
                                                  be_b, be_c, be_u, cpar, cchd, cpa, cpb)
            else:
                ncav, nb = conflict_cycle(P, T, N, S, CC, qx, qy, t, cav, cpar, cpa, cpb,
                                          cedge, cstep, stk, nn, be_u, be_c)
                nedge = ncav - 1
                for e in range(1, ncav):
                    cchd[e] = e
            if ncav < 0 or nb > width:
                st = OVERFLOW
            else:
                cnt = _on_hull(P, S, nn, be_u, nb, qx, qy, pos, s_i, s_v, s_gx, s_gy, want_grad)
                if cnt:
                    st = ON_HULL
        if st == OK and cnt == 0:
            _new_vertices(P, nn, nb, qx, qy, vx, vy, dv)
            if kind == SIBSON:
                _sibson_areas(CC, qx, qy, cav, ncav, be_c, nb, cpar, cchd, cpa, cpb, nedge,
                              vx, vy, ox, oy, area)
                if want_grad:
                    _sibson_gradients(P, nn, nb, qx, qy, vx, vy, gax, gay)
            else:
                _laplace_weights(P, nn, nb, qx, qy, vx, vy, dv, want_grad, area, gax, gay)
            _write_row(nn, nb, area, gax, gay, want_grad, perm, pos, s_i, s_v, s_gx, s_gy)
            cnt = nb
        count[q] = cnt
        status[q] = st
        pos += cnt
    return pos


@njit(cache=True)
def _work_space(width):
    """The work space of :func:`_query_block` for rows of up to ``width`` entries."""
    return (np.empty((14, width + 4), np.int64), np.empty((8, width + 2)),
            np.empty((width, 3), np.int64))


# below this many queries a batch runs as one block per piece: waking the
# thread pool would cost more than it saves
_PARALLEL_MIN = 2000


@njit(cache=True, parallel=True)
def _query_all(P, T, N, S, CC, Q, start, grid, nc, glo, gspan, kind, want_grad, general, width,
               room, chunk, block, nthreads, index_proto, status, tri, indptr):
    """Natural-neighbour coordinates of the m points Q (m, 2) as CSR arrays.

    Pieces of ``chunk`` queries go in parallel blocks of consecutive queries
    (see :func:`_query_block`, which also describes ``start, grid, nc, glo,
    gspan, general, width`` and the status codes), each block writing its rows
    one after another into its own stretch of a staging buffer (``room``
    entries per query); then the blocks' stretches are copied, in parallel,
    to their places in the flat CSR arrays, which are allocated once from an
    estimate after the first piece (and grown if it falls short). Two
    parallel regions per piece; blocks go to threads as these come free (set
    ``numba.parallel_chunksize(1)`` around the call).

    Fills ``status``, ``tri`` (m,) and ``indptr`` (m + 1,); returns
    ``(ind0, ind1, ind2, val0, val1, val2, nnz)``: column indices (dtype of
    ``index_proto``) and values, then, if ``want_grad``, two more copies of
    the indices and the x and y gradients (else empty arrays), each holding
    ``nnz`` entries (and possibly some slack after them).
    """
    m = Q.shape[0]
    count = np.empty(m, np.int64)
    piece = max(1, min(m, chunk))
    maxblocks = max(1, piece // block) if m >= _PARALLEL_MIN and nthreads > 1 else 1
    scap = piece * room + maxblocks * width
    gcap = scap if want_grad else 0
    s_i = np.empty(scap, index_proto.dtype)
    s_v = np.empty(scap)
    s_gx = np.empty(gcap)
    s_gy = np.empty(gcap)
    bfill = np.empty(maxblocks, np.int64)
    ind0 = np.empty(0, index_proto.dtype)
    ind1 = np.empty(0, index_proto.dtype)
    ind2 = np.empty(0, index_proto.dtype)
    val0 = np.empty(0)
    val1 = np.empty(0)
    val2 = np.empty(0)
    indptr[0] = 0
    for c0 in range(0, m, piece):
        c1 = min(m, c0 + piece)
        mc = c1 - c0
        nblocks = max(1, min(mc // block, maxblocks))
        for blk in prange(nblocks):
            lo = c0 + blk * mc // nblocks
            hi = c0 + (blk + 1) * mc // nblocks
            base = (lo - c0) * room + blk * width
            end = (hi - c0) * room + (blk + 1) * width
            ib, fb, cnb = _work_space(width)
            bfill[blk] = _query_block(P, T, N, S, CC, Q, start, grid, nc, glo, gspan, kind,
                                      want_grad, general, width, lo, hi, base, end,
                                      s_i, s_v, s_gx, s_gy, count, status, tri, ib, fb,
                                      cnb) - base
        for r in range(c0, c1):
            indptr[r + 1] = indptr[r] + count[r]
        nnz = indptr[c0]
        need = indptr[c1]
        if need > ind0.shape[0]:
            # room for this piece and, estimated from the rows so far, the rest
            cap = need + int(1.02 * (m - c1) * need / c1) + 1024
            ind0 = _grown(ind0, cap, nnz)
            val0 = _grown(val0, cap, nnz)
            if want_grad:
                ind1 = _grown(ind1, cap, nnz)
                ind2 = _grown(ind2, cap, nnz)
                val1 = _grown(val1, cap, nnz)
                val2 = _grown(val2, cap, nnz)
        for blk in prange(nblocks):
            lo = c0 + blk * mc // nblocks
            base = (lo - c0) * room + blk * width
            off = indptr[lo] - base
            for j in range(base, base + bfill[blk]):  # not slices: see _grown
                ind0[off + j] = s_i[j]
                val0[off + j] = s_v[j]
                if want_grad:
                    ind1[off + j] = s_i[j]
                    ind2[off + j] = s_i[j]
                    val1[off + j] = s_gx[j]
                    val2[off + j] = s_gy[j]
    return ind0, ind1, ind2, val0, val1, val2, indptr[m]


@njit(cache=True)
def _grown(a, cap, n):
    """A copy of ``a[:n]`` with room for ``cap`` entries, its pages faulted
    in from this one thread (first touches of the same pages from several
    threads at once serialise in the kernel and cost far more). Copied in a
    loop: a slice assignment compiles numba's shape check with its error
    message, seconds of a first run."""
    b = np.empty(cap, a.dtype)
    step = max(1, 4096 // b.itemsize)
    for i in range(0, cap, step):
        b[i] = 0
    for i in range(n):
        b[i] = a[i]
    return b


def _threads() -> int:
    import numba
    return numba.get_num_threads()


# natural neighbours a query may have in the first pass (more: redone with
# larger buffers), and staging room per query (a block of queries averaging
# more than that is finished in a second pass)
_CAP = 24
_ROOM = 12
# queries per block: blocks go to threads as these come free, so that
# threads finish a piece together
_BLOCK = 1024


def _snap_to_hull(tri, q, rows, hull_tol, tri_out):
    """Move the points q[rows] that are outside the hull by round-off onto the
    nearest hull edge, in place, with ``tri_out`` their triangles (where a walk
    from any triangle finds them: on a hull convex only to round-off, the walk
    from the hull edge they were outside of need not); returns the rows moved."""
    if not rows.size or hull_tol <= 0:
        return rows[:0]
    P = tri.nodes
    tol = hull_tol * np.hypot(*np.ptp(P, axis=0))
    he = tri.hull_edges
    a, b = P[he[:, 0]], P[he[:, 1]]
    ab = b - a
    L2 = (ab ** 2).sum(1)
    moved = []
    for r in rows:
        s = np.clip(((q[r] - a) * ab).sum(1) / L2, 0.0, 1.0)
        proj = a + s[:, None] * ab
        d = np.hypot(*(proj - q[r]).T)
        k = int(np.argmin(d))
        if d[k] > tol:
            continue
        # the projection itself may round to the outside: nudge it inwards
        x = proj[k]
        inward = np.array([-ab[k, 1], ab[k, 0]]) / np.sqrt(L2[k])
        for _ in range(8):
            t = tri.locate(x[None])[0]
            if t >= 0:
                tri_out[r] = t
                break
            x = x + inward * np.spacing(np.abs(x).max() + 1e-300)
        q[r] = x
        moved.append(r)
    return np.array(moved, dtype=np.int64)


_NO_GRID = (np.zeros(2), np.ones(2), 1, np.zeros(1, dtype=np.int64))


def _run(tri, q, start, ikind, gradient, general, width, room, chunk, status, tri_out):
    """The kernel :func:`_query_all` on the points q (m, 2); returns a
    :class:`RowStore` of the rows and fills ``status``, ``tri_out`` (m,)."""
    import numba
    m = q.shape[0]
    n = tri.npoints
    # a walk from a given start needs no seed grid (an O(triangles) table)
    lo, span, nc, grid = tri.seed_grid() if not start.shape[0] else _NO_GRID
    indptr = np.empty(m + 1, dtype=np.int64)
    proto = np.empty(0, dtype=index_dtype(n, m * width))
    with numba.parallel_chunksize(1):
        *arrays, nnz = _query_all(tri.nodes, tri.triangles, tri.neighbours, tri.segment_keys,
                                  tri.circumcircles,
                                  q, start, grid, nc, lo, span, ikind, gradient, general, width,
                                  room, max(1, chunk), _BLOCK, _threads(), proto, status,
                                  tri_out, indptr)
    k = 3 if gradient else 1
    return RowStore(n, indptr, arrays[:3][:k], arrays[3:][:k], int(nnz))


def _check_status(status, q, offset, gradient, undefined, tri):
    """Raise for queries outside the hull and for undefined gradients."""
    raise_outside(status, q, offset)
    if gradient and undefined == "raise":
        raise_undefined(status, q, tri.nodes, "a convex-hull edge", offset)


def area_coordinates(tri: Triangulation, x, gradient: bool = False, kind: str = "sibson",
                     undefined: str = "raise", chunk: int = 1 << 15,
                     return_triangles: bool = False, hint=None,
                     hull_tol: float = OUTSIDE_ROUNDOFF):
    """The 2D area method on a triangulation; the options and results of
    :func:`~skfem_nem.coordinates.natural_neighbour_coordinates` (``method="area"``)."""
    if kind not in ("sibson", "laplace"):
        raise ValueError(f"kind must be 'sibson' or 'laplace', got {kind!r}")
    if undefined not in ("raise", "nan"):
        raise ValueError(f"undefined must be 'raise' or 'nan', got {undefined!r}")
    q = check_queries(x, 2)
    m = q.shape[0]
    ikind = SIBSON if kind == "sibson" else LAPLACE
    if hint is None:
        start = np.empty(0, dtype=np.int64)
    else:
        start = np.asarray(hint, dtype=np.int64).reshape(-1)
        if start.shape[0] != m or (m and (start.min() < 0 or start.max() >= tri.ntriangles)):
            raise ValueError(f"hint must hold {m} triangle indices in [0, {tri.ntriangles})")
    status = np.empty(m, dtype=np.int64)
    tri_out = np.empty(m, dtype=np.int64)
    rows = _rows_with_retries(tri, q, start, ikind, gradient, chunk, status, tri_out, hull_tol)
    _check_status(status, q, 0, gradient, undefined, tri)
    out = rows.matrices()
    result = (out[0], out[1:]) if gradient else out[0]
    if return_triangles:
        return result, tri_out
    return result


def _rows_with_retries(tri, q, start, ikind, gradient, chunk, status, tri_out, hull_tol):
    """Rows of all queries: a first pass with small buffers, then the few that
    overflowed (or were outside by round-off, moved onto the hull) again with
    more room. Fills ``status`` and ``tri_out``."""
    rows = _run(tri, q, start, ikind, gradient, False, _CAP, _ROOM, chunk, status, tri_out)
    # points outside by round-off only: move them onto the hull and redo
    redo = _snap_to_hull(tri, q, np.flatnonzero(status == OUTSIDE), hull_tol, tri_out)
    # rare: more natural neighbours than the buffers hold (co-circular
    # clusters, or a block of queries with more than _ROOM on average), or a
    # cavity that is not a tree (a triangulation that is not Delaunay): redo
    # with more room, from the second round on with the general cavity search
    redo = np.union1d(redo, np.flatnonzero(status == OVERFLOW))
    width, room, general = 4 * _CAP, 2 * _ROOM, False
    while redo.size:
        st2 = np.empty(redo.size, dtype=np.int64)
        t2 = np.empty(redo.size, dtype=np.int64)
        extra = _run(tri, q[redo], tri_out[redo], ikind, gradient, general, width, room, chunk,
                     st2, t2)
        done = st2 != OVERFLOW
        status[redo] = st2
        tri_out[redo] = t2
        rows.replace(redo[done], extra, np.flatnonzero(done))
        redo = redo[~done]
        width, room, general = 4 * width, min(4 * width, 2 * room), True
    return rows
