"""Sibson and Laplace natural-neighbour coordinates in 2D, with exact gradients.

(The public functions also take 3D and 4D nodes, and ``method="lasserre"`` in
2D: those go to the paper's Box 1 method, :mod:`skfem_nem.lasserre`.)

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
    :func:`skfem_nem.predicates.orient2d`, accurate to a few ulps however flat
    the triangle. Nothing divides by a quantity that vanishes on an interior
    Delaunay edge, so values and gradients are exact there; co-circular nodes
    (structured grids) give the same result whichever diagonal the
    triangulation holds. A query on a convex-hull edge gets the linear 1D
    weights of the edge's two nodes, a query at a node the Kronecker delta.

Undefined gradients
    The gradient is undefined at a node (the coordinates have a cone-like
    kink there), and on a hull edge this module does not compute the
    one-sided limit. Asking for gradients at such a point raises
    ``ValueError`` naming the query (``undefined="raise"``, the default), or
    gives NaN rows for those queries only (``undefined="nan"``).
"""
from __future__ import annotations

from typing import Literal, Optional

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.spatial import Delaunay

from ._batch import (AT_NODE, OK, ON_HULL, OUTSIDE, OVERFLOW, check_queries, compress,
                     csr_family, raise_outside, raise_undefined)
from .lasserre import sibson_coordinates_nd
from .predicates import orient2d
from .triangulation import Triangulation, _cavity_boundary, _grow_cavity, _locate

__all__ = ["sibson_coordinates", "laplace_coordinates", "natural_neighbour_coordinates"]

SIBSON = 0
LAPLACE = 1

# relative distance below which a point counts as lying on a hull edge
_HULL_EPS = 1e-15


@njit(cache=True, inline="always")
def _circumcentre_rel(ax, ay, bx, by, d):
    """Circumcentre of (0, a, b) given d = cross(a, b) (twice the area)."""
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    f = 0.5 / d
    return (by * a2 - ay * b2) * f, (ax * b2 - bx * a2) * f


@njit(cache=True)
def _query(P, T, N, C, qx, qy, t0, kind, want_grad, cap,
           cav, cnb, rej, be_b, be_t, be_u, nn, vx, vy, ox, oy, area, gax, gay,
           out_i, out_v, out_gx, out_gy):
    """Natural-neighbour coordinates of one point.

    Writes up to ``cap`` entries into ``out_*`` (sorted by node index) and
    returns ``(count, status, triangle)``.
    """
    t, k = _locate(P, T, N, qx, qy, t0)
    if k >= 0:
        return 0, OUTSIDE, t
    # at a node: Kronecker delta
    for j in range(3):
        a = T[t, j]
        if P[a, 0] == qx and P[a, 1] == qy:
            out_i[0] = a
            out_v[0] = 1.0
            out_gx[0] = np.nan
            out_gy[0] = np.nan
            return 1, AT_NODE, t
    ncav = _grow_cavity(P, T, N, qx, qy, t, cav, cnb, rej)
    if ncav < 0:
        return 0, OVERFLOW, t
    # boundary of the cavity, a counter-clockwise cycle nn[0..nb-1] around x
    nb = _cavity_boundary(T, N, cav, cnb, ncav, nn, be_b, be_t, be_u)
    if nb < 0:
        return 0, OVERFLOW, t
    for j in range(nb):
        if be_u[j] < 0:
            # hull edge on the cavity boundary: is the point (numerically) on it?
            a = nn[j]
            b = be_b[j]
            ex = P[b, 0] - P[a, 0]
            ey = P[b, 1] - P[a, 1]
            L2 = ex * ex + ey * ey
            o = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy)
            if o <= _HULL_EPS * L2:
                s = ((qx - P[a, 0]) * ex + (qy - P[a, 1]) * ey) / L2
                s = min(max(s, 0.0), 1.0)
                lo = min(a, b)
                out_i[0] = lo
                out_i[1] = a + b - lo
                out_v[0] = 1.0 - s if lo == a else s
                out_v[1] = 1.0 - out_v[0]
                for jj in range(2):
                    out_gx[jj] = np.nan
                    out_gy[jj] = np.nan
                return 2, ON_HULL, t
    # new Voronoi vertices v_i = circumcentre(x, p_i, p_{i+1}), relative to x
    for i in range(nb):
        a = nn[i]
        b = nn[(i + 1) % nb]
        d = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy)
        vx[i], vy[i] = _circumcentre_rel(P[a, 0] - qx, P[a, 1] - qy,
                                         P[b, 0] - qx, P[b, 1] - qy, d)
    # old Voronoi vertices: circumcentres of the cavity triangles, relative to x
    for c in range(ncav):
        tc = cav[c]
        a = T[tc, 0]
        ox[c] = (P[a, 0] - qx) + C[tc, 0]
        oy[c] = (P[a, 1] - qy) + C[tc, 1]
    # areas (Sibson) or weights (Laplace)
    for i in range(nb):
        p = nn[i]
        im = (i - 1 + nb) % nb
        px = P[p, 0] - qx
        py = P[p, 1] - qy
        h = np.sqrt(px * px + py * py)
        ex = vx[i] - vx[im]
        ey = vy[i] - vy[im]
        s = np.sqrt(ex * ex + ey * ey)
        if kind == SIBSON:
            # polygon o_t1 ... o_tr, v_{i-1}, v_i (counter-clockwise)
            acc = 0.0
            x0 = vx[i]
            y0 = vy[i]
            ci = be_t[i]
            for _ in range(ncav):
                acc += x0 * oy[ci] - y0 * ox[ci]
                x0 = ox[ci]
                y0 = oy[ci]
                tc = cav[ci]
                jp = 0 if T[tc, 0] == p else (1 if T[tc, 1] == p else 2)
                ci = cnb[ci, (jp + 1) % 3]
                if ci < 0:
                    break
            acc += x0 * vy[im] - y0 * vx[im]
            acc += vx[im] * vy[i] - vy[im] * vx[i]
            area[i] = 0.5 * acc
            if want_grad:
                f = s / h * 0.5
                gax[i] = f * (vx[im] + vx[i])
                gay[i] = f * (vy[im] + vy[i])
        else:
            area[i] = s / h
            if want_grad:
                # d s / dx = (e . m_i) (v_i - x) - (e . m_{i-1}) (v_{i-1} - x)
                dsx = 0.0
                dsy = 0.0
                if s > 0.0:
                    ex /= s
                    ey /= s
                    for sgn, jv in ((1.0, i), (-1.0, im)):
                        a = nn[jv]
                        b = nn[(jv + 1) % nb]
                        ax_ = P[a, 0] - qx
                        ay_ = P[a, 1] - qy
                        bx_ = P[b, 0] - qx
                        by_ = P[b, 1] - qy
                        d = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy)
                        mx = (by_ - ay_) / d
                        my = (ax_ - bx_) / d
                        em = sgn * (ex * mx + ey * my)
                        dsx += em * vx[jv]
                        dsy += em * vy[jv]
                # w = s / h,  dh/dx = (x - p) / h
                gax[i] = dsx / h + s * px / (h * h * h)
                gay[i] = dsy / h + s * py / (h * h * h)
    # The dominant neighbour d gets its gradient from complement sums,
    #   grad phi_d = (grad A_d (1 - phi_d) - phi_d sum_{j != d} grad A_j) / A,
    # which avoids the cancellation of two O(1/r) terms at distance r from
    # node d (the plain formula loses digits like eps * spacing / r there).
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
    gsx = gax[dom] + gcx
    gsy = gay[dom] + gcy
    # write out, sorted by node index (insertion sort, small)
    for i in range(nb):
        phi = area[i] / total
        out_i[i] = nn[i]
        out_v[i] = phi
        if want_grad:
            if i == dom:
                out_gx[i] = (gax[i] * (rest / total) - phi * gcx) / total
                out_gy[i] = (gay[i] * (rest / total) - phi * gcy) / total
            else:
                out_gx[i] = (gax[i] - phi * gsx) / total
                out_gy[i] = (gay[i] - phi * gsy) / total
        j = i
        while j > 0 and out_i[j - 1] > out_i[j]:
            out_i[j - 1], out_i[j] = out_i[j], out_i[j - 1]
            out_v[j - 1], out_v[j] = out_v[j], out_v[j - 1]
            out_gx[j - 1], out_gx[j] = out_gx[j], out_gx[j - 1]
            out_gy[j - 1], out_gy[j] = out_gy[j], out_gy[j - 1]
            j -= 1
    return nb, OK, t


@njit(cache=True, parallel=True)
def _query_batch(P, T, N, C, Q, start, kind, want_grad, cap, nblocks,
                 out_i, out_v, out_gx, out_gy, count, status, tri):
    """Coordinates of m points into padded (m, cap) arrays, parallel over blocks."""
    m = Q.shape[0]
    for blk in prange(nblocks):
        lo = blk * m // nblocks
        hi = (blk + 1) * m // nblocks
        cav = np.empty(cap, np.int64)
        cnb = np.empty((cap, 3), np.int64)
        rej = np.empty(cap + 4, np.int64)
        be_u = np.empty(cap + 2, np.int64)
        be_b = np.empty(cap + 2, np.int64)
        be_t = np.empty(cap + 2, np.int64)
        nn = np.empty(cap + 2, np.int64)
        vx = np.empty(cap + 2)
        vy = np.empty(cap + 2)
        ox = np.empty(cap)
        oy = np.empty(cap)
        area = np.empty(cap + 2)
        gax = np.empty(cap + 2)
        gay = np.empty(cap + 2)
        oi = np.empty(cap + 2, np.int64)
        ov = np.empty(cap + 2)
        ogx = np.empty(cap + 2)
        ogy = np.empty(cap + 2)
        prev = -1
        for q in range(lo, hi):
            # start the walk from the seed or from the previous query's
            # triangle, whichever is nearer (sorted queries walk ~1 step)
            t0 = start[q]
            if prev >= 0:
                if t0 < 0:
                    t0 = prev
                else:
                    a = T[t0, 0]
                    b = T[prev, 0]
                    da = (P[a, 0] - Q[q, 0]) ** 2 + (P[a, 1] - Q[q, 1]) ** 2
                    db = (P[b, 0] - Q[q, 0]) ** 2 + (P[b, 1] - Q[q, 1]) ** 2
                    if db < da:
                        t0 = prev
            elif t0 < 0:
                t0 = 0
            cnt, st, t = _query(P, T, N, C, Q[q, 0], Q[q, 1], t0, kind, want_grad, cap,
                                cav, cnb, rej, be_b, be_t, be_u, nn, vx, vy, ox, oy, area,
                                gax, gay, oi, ov, ogx, ogy)
            if cnt > cap:
                st = OVERFLOW
                cnt = 0
            count[q] = cnt
            status[q] = st
            tri[q] = t
            if t >= 0:
                prev = t
            for j in range(cnt):
                out_i[q, j] = oi[j]
                out_v[q, j] = ov[j]
                if want_grad:
                    out_gx[q, j] = ogx[j]
                    out_gy[q, j] = ogy[j]


def _dimension(nodes_or_triangulation) -> int:
    """Space dimension of nodes, a Triangulation or a scipy Delaunay (2 if unclear:
    the 2D checks then name the problem)."""
    if isinstance(nodes_or_triangulation, Triangulation):
        return 2
    if isinstance(nodes_or_triangulation, Delaunay):
        return int(nodes_or_triangulation.points.shape[1])
    shape = np.shape(nodes_or_triangulation)
    return int(shape[1]) if len(shape) == 2 and shape[1] in (3, 4) else 2


def _as_triangulation(nodes_or_triangulation) -> Triangulation:
    if isinstance(nodes_or_triangulation, Triangulation):
        return nodes_or_triangulation
    if isinstance(nodes_or_triangulation, Delaunay):
        return Triangulation(nodes_or_triangulation.points)
    return Triangulation(nodes_or_triangulation)


def _threads() -> int:
    import numba
    return numba.get_num_threads()


def natural_neighbour_coordinates(
    nodes_or_triangulation,
    x,
    gradient: bool = False,
    kind: Literal["sibson", "laplace"] = "sibson",
    undefined: Literal["raise", "nan"] = "raise",
    chunk: int = 1 << 15,
    return_triangles: bool = False,
    hint=None,
    hull_tol: float = 1e-13,
    method: Optional[Literal["area", "lasserre"]] = None,
):
    """Natural-neighbour coordinates (and gradients) of points in 2, 3 or 4 dimensions.

    Parameters
    ----------
    nodes_or_triangulation
        (n, d) nodes with d = 2, 3 or 4; or, to reuse a triangulation over
        many calls, a :class:`~skfem_nem.Triangulation` (2D) or a
        :class:`scipy.spatial.Delaunay` of the nodes (any d, Lasserre method).
    x
        (m, d) query points, inside the convex hull (its boundary included).
    gradient
        Also return the gradients.
    kind
        ``"sibson"`` (area) or ``"laplace"`` (non-Sibsonian) coordinates.
    undefined
        What to do when gradients are requested at a node or on a convex-hull
        edge, where this module does not define them: ``"raise"`` a
        ``ValueError`` naming the query, or set that row's gradients to NaN.
    chunk
        Queries are processed in chunks of this many points (bounds memory).
    return_triangles
        Also return the (m,) index of a triangle containing each point.
    hint
        Optional (m,) triangle indices to start each point's search from
        (e.g. the triangle known to contain it); a bucket grid otherwise.
    hull_tol
        Points outside the convex hull by less than ``hull_tol`` times the
        diagonal of the nodes' bounding box are round-off: they are moved onto
        the nearest hull edge. Farther points are an error. (Area method; the
        Lasserre method has its own relative tolerance, see
        :mod:`skfem_nem.lasserre`.)
    method
        ``"area"``: the 2D area method of this module (the paper's method 1;
        the default in 2D). ``"lasserre"``: volumes of second-order Voronoi
        cells by Lasserre's recursion, :func:`skfem_nem.lasserre.sibson_coordinates_nd`
        (the paper's Box 1, method 2; the default and only method in 3D and
        4D; Sibson coordinates only, no ``hint`` or ``return_triangles``).

    Returns
    -------
    Phi : scipy.sparse.csr_matrix, shape (m, n)
        ``Phi[q, i] = phi_i(x_q)``, so ``Phi @ f`` interpolates nodal values f.
    dPhi : list of d csr_matrix, shape (m, n)
        Only with ``gradient=True``: ``dPhi[k][q, i] = d phi_i / d x_k (x_q)``
        (units: 1 / length), with the same sparsity pattern as ``Phi``.

    Raises
    ------
    ValueError
        For bad nodes (see :class:`~skfem_nem.Triangulation`), non-finite
        queries, queries outside the convex hull (naming the first and the
        count), and gradients at nodes or hull edges with
        ``undefined="raise"``; for an unknown ``method``, or options the
        chosen method does not have.
    """
    d = _dimension(nodes_or_triangulation)
    if method is None:
        method = "area" if d == 2 else "lasserre"
    if method not in ("area", "lasserre"):
        raise ValueError(f"method must be 'area' or 'lasserre', got {method!r}")
    if method == "lasserre":
        if kind != "sibson":
            raise ValueError(f"the Lasserre method computes Sibson coordinates only, got "
                             f"kind={kind!r}")
        if hint is not None or return_triangles:
            raise ValueError("hint and return_triangles are options of the 2D area method "
                             "(method='area')")
        src = nodes_or_triangulation
        if isinstance(src, Triangulation):
            src = src.nodes
        if isinstance(src, Delaunay):
            return sibson_coordinates_nd(src.points, x, gradient=gradient, delaunay=src,
                                         undefined=undefined, chunk=chunk)
        return sibson_coordinates_nd(src, x, gradient=gradient, undefined=undefined,
                                     chunk=chunk)
    if d != 2:
        raise ValueError(f"the area method works in 2D only; {d}D nodes need "
                         f"method='lasserre'")
    tri = _as_triangulation(nodes_or_triangulation)
    if kind not in ("sibson", "laplace"):
        raise ValueError(f"kind must be 'sibson' or 'laplace', got {kind!r}")
    if undefined not in ("raise", "nan"):
        raise ValueError(f"undefined must be 'raise' or 'nan', got {undefined!r}")
    q = check_queries(x, 2)
    m = q.shape[0]
    n = tri.npoints
    P, T, N = tri.nodes, tri.triangles, tri.neighbours
    C = tri.circumcentre_offsets
    ikind = SIBSON if kind == "sibson" else LAPLACE
    if hint is None:
        start_all = tri.start_triangles(q)
    else:
        start_all = np.asarray(hint, dtype=np.int64).reshape(-1)
        if start_all.shape[0] != m or (m and (start_all.min() < 0 or
                                              start_all.max() >= tri.ntriangles)):
            raise ValueError(f"hint must hold {m} triangle indices in [0, {tri.ntriangles})")
    tri_out = np.empty(m, dtype=np.int64)
    nthreads = _threads()
    blocks = []
    buffers = _buffers(min(m, chunk), _CAP, gradient)
    for c0 in range(0, m, chunk):
        c1 = min(m, c0 + chunk)
        Qc = q[c0:c1]
        mats, status, tloc = _run_chunk(P, T, N, C, Qc, start_all[c0:c1], ikind, gradient,
                                        _CAP, nthreads, buffers)
        # points outside by round-off only: move them onto the hull and redo
        redo = _snap_to_hull(tri, Qc, np.flatnonzero(status == OUTSIDE), hull_tol)
        # rare: more natural neighbours than the buffer holds (co-circular
        # clusters): redo with buffers large enough
        redo = np.union1d(redo, np.flatnonzero(status == OVERFLOW))
        cap = 4 * _CAP
        while redo.size:
            extra, st2, t2 = _run_chunk(P, T, N, C, Qc[redo], tloc[redo], ikind,
                                        gradient, cap, 1)
            status[redo] = st2
            done = np.flatnonzero(st2 != OVERFLOW)
            # splice the recomputed rows in by row selection (sparse products
            # and sums would drop explicit zeros and break the shared pattern)
            src = np.arange(c1 - c0)
            src[redo[done]] = (c1 - c0) + done
            mats = [sp.vstack([M, X], format="csr")[src] for M, X in zip(mats, extra)]
            tloc[redo[done]] = t2[done]
            redo = redo[st2 == OVERFLOW]
            cap *= 4
        _check_status(status, q, c0, gradient, undefined, tri)
        tri_out[c0:c1] = tloc
        blocks.append(mats)
    nmat = 3 if gradient else 1
    out = []
    for j in range(nmat):
        M = sp.vstack([b[j] for b in blocks], format="csr") if blocks else \
            sp.csr_matrix((m, n))
        M.sort_indices()
        out.append(M)
    if gradient:
        for D in out[1:]:
            assert D.nnz == out[0].nnz and np.array_equal(D.indices, out[0].indices)
    result = (out[0], out[1:]) if gradient else out[0]
    if return_triangles:
        return result, tri_out
    return result


_CAP = 24


def _snap_to_hull(tri, q, rows, hull_tol):
    """Move the points q[rows] that are outside the hull by round-off onto the
    nearest hull edge, in place; returns the rows that were moved."""
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
            if tri.locate(x[None])[0] >= 0:
                break
            x = x + inward * np.spacing(np.abs(x).max() + 1e-300)
        q[r] = x
        moved.append(r)
    return np.array(moved, dtype=np.int64)


def _buffers(mc, cap, gradient):
    """Padded per-chunk output rows, reused across chunks (no page faults):
    indices, values (mc, cap) and gradients (2, mc, cap)."""
    return (np.empty((mc, cap), np.int64), np.empty((mc, cap)),
            np.empty((2, mc, cap) if gradient else (2, 1, 1)))


def _run_chunk(P, T, N, C, Qc, start, ikind, gradient, cap, nthreads, buffers=None):
    """Run the query kernel on one chunk; returns ([Phi, (dx, dy)], status, tri)."""
    mc = Qc.shape[0]
    n = P.shape[0]
    if buffers is None:
        buffers = _buffers(mc, cap, gradient)
    out_i, out_v, out_g = buffers
    count = np.empty(mc, np.int64)
    status = np.empty(mc, np.int64)
    tloc = np.empty(mc, np.int64)
    # small batches run serially: waking the thread pool costs more than it saves
    kernel = _query_batch if mc >= _PARALLEL_MIN else _query_batch_serial
    nblocks = max(1, min(mc // 64, 8 * nthreads))
    kernel(P, T, N, C, Qc, start, ikind, gradient, cap, nblocks,
           out_i, out_v, out_g[0], out_g[1], count, status, tloc)
    indptr, indices, data, grads = compress(count, out_i, out_v, out_g, gradient, n)
    mats = csr_family(indptr, indices, [data, *grads] if gradient else [data], (mc, n))
    return mats, status, tloc


_query_batch_serial = njit(cache=True)(_query_batch.py_func)
_PARALLEL_MIN = 20000


def _check_status(status, q, offset, gradient, undefined, tri):
    """Raise for queries outside the hull and for undefined gradients."""
    raise_outside(status, q, offset)
    if gradient and undefined == "raise":
        raise_undefined(status, q, tri.nodes, "a convex-hull edge", offset)


def sibson_coordinates(nodes_or_triangulation, x, gradient: bool = False, **kwargs):
    """Sibson natural-neighbour coordinates of points x (m, d), d = 2, 3, 4.

    Returns a CSR matrix ``Phi`` (m, n) with ``Phi[q, i] = phi_i(x_q)``; with
    ``gradient=True`` returns ``(Phi, [dPhi/dx_1, ..., dPhi/dx_d])``. In 2D
    the area method is the default (``method="lasserre"`` selects the paper's
    Box 1); 3D and 4D nodes use the Lasserre method. See
    :func:`natural_neighbour_coordinates` for all options and errors.
    """
    return natural_neighbour_coordinates(nodes_or_triangulation, x, gradient=gradient,
                                         kind="sibson", **kwargs)


def laplace_coordinates(nodes_or_triangulation, x, gradient: bool = False, **kwargs):
    """Laplace (non-Sibsonian) natural-neighbour coordinates of points x (m, 2).

    Same signature and outputs as :func:`sibson_coordinates`.
    """
    return natural_neighbour_coordinates(nodes_or_triangulation, x, gradient=gradient,
                                         kind="laplace", **kwargs)
