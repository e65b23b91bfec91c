"""The query kernel of Lasserre's method: one query point from location to its row.

For a query, :func:`query` finds the conflict region
(:func:`~skfem_nem.geometry.simplices_nd.conflict_region`), builds the second-order cells
of its natural neighbours, takes their volumes from the 3D combinatorics
(:func:`~skfem_nem.coordinates.lasserre_tet.cells_3d`) or the general recursion
(:func:`~skfem_nem.coordinates.lasserre_cell.lasserre_cell`), checks linear precision and
writes the coordinates and gradients (:func:`finish_row`). :func:`query_batch` runs blocks
of queries in parallel, each block with its own buffers; the Python side
(:mod:`skfem_nem.coordinates.lasserre`) sizes the buffers and retries overflows.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..geometry.simplices_nd import conflict_region
from ..geometry.status import AT_NODE, OK, OVERFLOW, UNBOUNDED
from ..jit import serial_twin
from .lasserre_cell import lasserre_cell, vertex_simplices
from .lasserre_tet import cells_3d

__all__ = ["query", "query_block", "query_batch", "query_batch_serial", "finish_row"]


@njit(cache=True, error_model="numpy", _nrt=False)
def finish_row(K, d, nn, vol, gv, want_grad, raw, gc, out_i, out_v, out_g):
    """Coordinates (or raw volumes) and gradients of the K neighbours into
    ``out_*``, sorted by node index; returns ``(count, status, 0)``. ``gc``:
    scratch of length d."""
    # The dominant neighbour gets its gradient from complement sums,
    #   grad phi_d = (grad V_d (1 - phi_d) - phi_d sum_{j != d} grad V_j) / V,
    # which avoids cancelling two large terms close to node d.
    dom = 0
    for i in range(1, K):
        if vol[i] > vol[dom]:
            dom = i
    rest = 0.0
    for k in range(d):
        gc[k] = 0.0
    for i in range(K):
        if i != dom:
            rest += vol[i]
            if want_grad:
                for k in range(d):
                    gc[k] += gv[i, k]
    total = vol[dom] + rest
    if not total > 0.0:
        return 0, UNBOUNDED, 0
    cnt = 0
    for i in range(K):
        if vol[i] <= 0.0:
            continue
        phi = vol[i] / total
        out_i[cnt] = nn[i]
        out_v[cnt] = phi
        if raw:
            out_v[cnt] = vol[i]
        if want_grad:
            for k in range(d):
                if raw:
                    out_g[cnt, k] = gv[i, k]
                elif i == dom:
                    out_g[cnt, k] = (gv[i, k] * (rest / total) - phi * gc[k]) / total
                else:
                    out_g[cnt, k] = (gv[i, k] - phi * (gv[dom, k] + gc[k])) / total
        j = cnt
        while j > 0 and out_i[j - 1] > out_i[j]:
            out_i[j - 1], out_i[j] = out_i[j], out_i[j - 1]
            out_v[j - 1], out_v[j] = out_v[j], out_v[j - 1]
            for k in range(d):
                out_g[j - 1, k], out_g[j, k] = out_g[j, k], out_g[j - 1, k]
            j -= 1
        cnt += 1
    return cnt, OK, 0


@njit(cache=True, error_model="numpy", _nrt=False)
def query(P, S, NB, ctr, x, hint, d, stamp_q, want_grad, kind, tols, cached, CC, SH, smark, mark,
          cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf, pt, zf,
          a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
          gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, out_i, out_v, out_g):
    """Sibson coordinates of one point x, searched for from simplex ``hint``.

    Writes up to ``nn.shape[0]`` entries into ``out_*`` (sorted by node
    index) and returns ``(count, status, info)``. ``kind`` 0: Sibson
    coordinates; 1: the second-order volumes V_i and their gradients instead;
    2: coordinates from the hull-facet weights ``integral over the cell of
    (|y - p_i|^2 - |y - x|^2) dy`` (for a point on a hull facet, in the
    facet's own coordinates). ``info`` is
    ``s * (d + 1) + k`` for the hull facet (s, k) of an ON_HULL point.
    ``stamp_q > 0`` must differ between the queries sharing ``smark``.
    3D queries in general position are done by :func:`cells_3d`, the others
    (and those it gives up on) by the recursion of :func:`lasserre_cell`.
    """
    # Long kernel: the stages of one query (region, 3D combinatorics, recursion, safety
    # nets, row) share 60 working buffers; numba passes each as an argument, so a call per
    # stage costs more than the stage in 2D.
    ztol, btol, itol, flat, htol, lintol, wtol, vtol = (tols[0], tols[1], tols[2], tols[3],
                                                        tols[4], tols[5], tols[6], tols[7])
    shape, lintol3, gradtol3, near3 = tols[8], tols[9], tols[10], tols[11]
    raw = kind == 1
    hullw = kind == 2
    st, info, ncav, K, nbf, degenerate = conflict_region(
        P, S, NB, ctr, x, hint, d, stamp_q, itol, flat, htol, wtol, cached, CC, SH, smark, mark,
        cav, cst, live, bf, nn, Tc, zc, zq, E, Mn, rhs, lam, out_i, out_v, out_g)
    if st != OK:
        return (1 if st == AT_NODE else 0), st, info
    # coordinates relative to x
    L = 0.0
    for j in range(K):
        h2 = 0.0
        for k in range(d):
            q[j, k] = P[nn[j], k] - x[k]
            h2 += q[j, k] * q[j, k]
        L = max(L, np.sqrt(h2))
        if h2 == 0.0:
            # at a node after all (the walk ended in a simplex near it)
            out_i[0] = nn[j]
            out_v[0] = 1.0
            for k in range(d):
                out_g[0, k] = np.nan
            return 1, AT_NODE, 0
    # near a node (closer than _NEAR3 L) the cells of the other neighbours are
    # thin slabs: the recursion, with its origins on row 0 and vertices from
    # pairs of lines, keeps about twice the digits of their gradients there
    # (a test for the 3D path only: q has d columns, two in 2D)
    near = False
    if d == 3:
        for j in range(K):
            near = near or q[j, 0] * q[j, 0] + q[j, 1] * q[j, 1] + q[j, 2] * q[j, 2] < (
                near3 * L) ** 2
    if d == 3 and not hullw and not degenerate and not near:
        # general position: the cells' faces from the known combinatorics,
        # accepted if linear precision (and its derivative, sum_i q_i (x)
        # grad V_i = V I) hold tightly; otherwise the general recursion below
        if cells_3d(S, NB, cav, ncav, smark, stamp_q * (cav.shape[0] + 1), Tc, zc, zq, K, q, qq,
                    want_grad,
                    shape, pid, pu, pv, pS, pf, pt, zf, a0, vol, gv):
            # every neighbour has a cell of positive volume here (a vertex
            # of a simplex strictly in conflict); one that rounds to zero
            # or below is left to the recursion
            total = 0.0
            good = True
            for i in range(K):
                total += vol[i]
                if not vol[i] > 0.0:
                    good = False
            for k in range(d):
                s = 0.0
                for i in range(K):
                    s += vol[i] * q[i, k]
                if not abs(s) <= lintol3 * total * L:
                    good = False
            if good and want_grad:
                scale = 0.0
                for i in range(K):
                    scale += max(abs(q[i, 0]), abs(q[i, 1]), abs(q[i, 2])) * max(
                        abs(gv[i, 0]), abs(gv[i, 1]), abs(gv[i, 2]))
                for k in range(d):
                    for kk in range(d):
                        s = -total if k == kk else 0.0
                        for i in range(K):
                            s += q[i, k] * gv[i, kk]
                        if not abs(s) <= gradtol3 * scale:
                            good = False
            if good:
                return finish_row(K, d, nn, vol, gv, want_grad, raw, rhs, out_i, out_v, out_g)
    for mode in range(3):
        # strict combinatorial filter, relaxed filter, no filter (safety nets)
        full = mode == 2
        strict = mode == 0
        flag[0] = 0
        for i in range(K):
            if live[i] == 0:
                # an empty cell (the node is only on simplices whose sphere
                # passes through x, or flat ones)
                vol[i] = 0.0
                for k in range(d):
                    gv[i, k] = 0.0
                for j in range(K):
                    tab[i, j] = 0.0
                continue
            # the simplices whose circumcentres are vertices of cell i, as rows
            # of constraint ids (0: x, j + 1: neighbour j), after the conflict
            # simplices' local indices in Tc[:ncav] (counts start as np.int64: a plain 0
            # or 1 is typed Literal[int] on numba's first pass over the loop, which
            # compiles the kernels called with them a second time)
            nT = np.int64(0)
            base = ncav
            if not full:
                for c in range(ncav):
                    pos = -1
                    for j in range(d + 1):
                        if Tc[c, j] == i:
                            pos = j
                    if pos < 0:
                        continue
                    if base + nT == Tc.shape[0]:
                        return 0, OVERFLOW, 0
                    r = 0
                    for j in range(d + 1):
                        if j != pos:
                            Tc[base + nT, r] = Tc[c, j] + 1
                            r += 1
                    nT += 1
                for c in range(nbf):
                    pos = -1
                    for j in range(d):
                        if bf[c, j] == i:
                            pos = j
                    if pos < 0:
                        continue
                    if base + nT == Tc.shape[0]:
                        return 0, OVERFLOW, 0
                    Tc[base + nT, 0] = 0
                    r = 1
                    for j in range(d):
                        if j != pos:
                            Tc[base + nT, r] = bf[c, j] + 1
                            r += 1
                    nT += 1
                # the constraints: every id in those simplices
                sc[0] += 1
                for c in range(nT):
                    for j in range(d):
                        stamp[Tc[base + c, j]] = sc[0]
            # Row 0: closer to x than to p_i; then closer to p_i than to p_j.
            # The origin is the midpoint o = (x + p_i) / 2, on the plane of
            # row 0: near a node p_k the cells of the other neighbours are
            # slabs of width ~ |x - p_k| between two nearly parallel planes,
            # and an origin at x would make Lasserre's sum cancel terms of
            # size one down to that width.
            h = 0.0
            for k in range(d):
                h += q[i, k] * q[i, k]
            h = np.sqrt(h)
            for k in range(d):
                A[0, 0, k] = q[i, k] / h
            B[0, 0] = 0.0
            I[0, 0] = 0
            m = np.int64(1)
            for j in range(K):
                if j == i or (not full and stamp[j + 1] != sc[0]):
                    continue
                nrm2 = 0.0
                bb = 0.0
                for k in range(d):
                    a = q[j, k] - q[i, k]
                    A[0, m, k] = a
                    nrm2 += a * a
                    bb += a * q[j, k]
                nrm = np.sqrt(nrm2)
                for k in range(d):
                    A[0, m, k] /= nrm
                B[0, m] = 0.5 * bb / nrm
                I[0, m] = j + 1
                rowof[j + 1] = m
                # the plane x|p_j, about the same origin o = q_i / 2
                hj = 0.0
                ao = 0.0
                for k in range(d):
                    hj += q[j, k] * q[j, k]
                hj = np.sqrt(hj)
                for k in range(d):
                    AX[m, k] = q[j, k] / hj
                    ao += AX[m, k] * q[i, k]
                BX[m] = 0.5 * hj - 0.5 * ao
                m += 1
            if not full and degenerate:
                # Flat or borderline simplices in the conflict region can give
                # simplices whose circumcentre is no vertex of the cell, and
                # the filter needs every listed simplex to be one: keep those
                # whose d planes meet in a point that satisfies all the rows.
                nT = vertex_simplices(d, m, A, B, Tc[base:], nT, rowof, E, rhs, lam, ztol,
                                      vtol * L)
            cell = i
            if hullw:
                cell = -1
            v = lasserre_cell(d, m, A, B, I, AX, BX, M, W, Tc[base:], nT, act, nact, mrows, cur,
                              tpiv, acc, wm, gs, gc, gp, gq, rep, gmark, stamp, sc, full, strict,
                              want_grad, hullw, G, ztol, btol * L, flag, cell, tab)
            if hullw:
                # limit weight on a hull facet: integral over the cell of
                # |y - p_i|^2 - |y - x|^2 = -2 q_i . (y - o)
                v = 0.0
                for k in range(d):
                    v -= 2.0 * q[i, k] * M[0, k]
            vol[i] = max(v, 0.0)
            if want_grad:
                # grad V_i = (1 / h) integral over facet 0 of (y - x) dS, with
                # G = integral of (y - o) dS and G[d] the facet's area
                for k in range(d):
                    gv[i, k] = (G[k] + 0.5 * q[i, k] * G[d]) / h
        if flag[0] != 0:
            continue
        # check linear precision, sum_i V_i (p_i - x) = 0: a violated
        # combinatorial filter (never seen) would show here; redo unfiltered
        total = 0.0
        lin = 0.0
        for k in range(d):
            s = 0.0
            for i in range(K):
                s += vol[i] * q[i, k]
            lin = max(lin, abs(s))
        for i in range(K):
            total += vol[i]
        if total > 0.0 and lin <= lintol * total * L:
            break
    if flag[0] != 0:
        return 0, UNBOUNDED, 0
    return finish_row(K, d, nn, vol, gv, want_grad, raw, rhs, out_i, out_v, out_g)


@njit(cache=True, error_model="numpy", _nrt=False)
def query_block(lo, hi, P, S, NB, ctr, Q, start, d, want_grad, kind, tols, cached, CC, SH, smark,
                mark, cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf, pt,
           zf, a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
                gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov, og, out_i,
                out_v, out_g, count, status, info):
    """Queries lo..hi-1 of ``Q`` with one set of buffers (see :func:`query`)
    into rows of the padded outputs; a query with more entries than a row
    holds gets status OVERFLOW (redone with larger buffers)."""
    width = out_i.shape[1]
    for r in range(lo, hi):
        cnt, st, inf = query(P, S, NB, ctr, Q[r], start[r], d, r + 1, want_grad, kind, tols,
                             cached, CC, SH, smark, mark, cav, cst, live, rowof, bf, nn, q, Tc,
                             zc, zq, qq, pid, pu, pv, pS, pf, pt, zf, a0, tab, A, B, I,
                             AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp, gq,
                             rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov,
                             og)
        if cnt > width:
            cnt, st, inf = 0, OVERFLOW, 0
        count[r] = cnt
        status[r] = st
        info[r] = inf
        for j in range(cnt):
            out_i[r, j] = oi[j]
            out_v[r, j] = ov[j]
            if want_grad:
                for k in range(d):
                    out_g[k, r, j] = og[j, k]


@njit(cache=True, parallel=True, error_model="numpy")
def query_batch(P, S, NB, Q, start, want_grad, kind, ncap, ccap, nblocks, tols, cached, CC, SH,
                out_i, out_v, out_g, count, status, info):
    """Coordinates of m points into padded (m, ncap) arrays, parallel over blocks."""
    m = Q.shape[0]
    n = P.shape[0]
    d = P.shape[1]
    ns = S.shape[0]
    ctr = np.zeros(d)
    for v in range(n):
        for k in range(d):
            ctr[k] += P[v, k]
    for k in range(d):
        ctr[k] /= n
    for blk in prange(nblocks):
        lo = blk * m // nblocks
        hi = (blk + 1) * m // nblocks
        smark = np.zeros(ns, np.int64)
        mark = np.full(n, -1, np.int64)
        cav = np.empty(ccap, np.int64)
        cst = np.empty(ccap, np.int64)
        live = np.empty(ncap, np.int64)
        rowof = np.empty(ncap + 1, np.int64)
        bf = np.empty((2 * ccap, d), np.int64)
        nn = np.empty(ncap, np.int64)
        q = np.empty((ncap, d))
        Tc = np.empty((4 * ccap, d + 1), np.int64)
        zc = np.empty((ccap, d))
        zq = np.empty(ccap)
        qq = np.empty(ncap)
        pid = np.full((ncap, ncap), -1, np.int64)
        pu = np.empty(6 * ccap, np.int64)
        pv = np.empty(6 * ccap, np.int64)
        pS = np.empty((6 * ccap, d))
        pf = np.empty(6 * ccap, np.int64)
        pt = np.empty(6 * ccap)
        zf = np.empty((2 * ccap, d))
        a0 = np.empty(ncap)
        tab = np.empty((ncap, ncap))
        A = np.empty((d, ncap + 1, d))
        B = np.empty((d, ncap + 1))
        I = np.empty((d, ncap + 1), np.int64)
        AX = np.empty((ncap + 1, d))
        BX = np.empty(ncap + 1)
        M = np.empty((d, d))
        W = np.zeros((d, d))
        act = np.empty((d, 3 * ccap), np.int64)
        nact = np.empty(d, np.int64)
        mrows = np.empty(d, np.int64)
        cur = np.empty(d, np.int64)
        tpiv = np.empty(d, np.int64)
        acc = np.empty(d)
        wm = np.zeros(d, np.bool_)
        gs = np.empty((d, ncap + 1), np.int64)
        gc = np.empty((d, ncap + 1), np.int64)
        gp = np.empty((d, ncap + 1), np.int64)
        gq = np.empty(ncap + 1, np.int64)
        rep = np.empty(ncap + 1, np.int64)
        gmark = np.zeros(ncap + 1, np.int64)
        stamp = np.zeros(ncap + 1, np.int64)
        sc = np.zeros(1, np.int64)
        flag = np.zeros(1, np.int64)
        G = np.empty(d + 1)
        E = np.empty((d, d))
        Mn = np.empty((d, d))
        rhs = np.empty(d)
        lam = np.empty(d + 1)
        vol = np.empty(ncap)
        gv = np.empty((ncap, d))
        oi = np.empty(ncap, np.int64)
        ov = np.empty(ncap)
        og = np.empty((ncap, d))
        query_block(lo, hi, P, S, NB, ctr, Q, start, d, want_grad, kind, tols, cached, CC, SH,
                    smark,
                    mark, cav, cst, live, rowof, bf, nn, q, Tc, zc, zq, qq, pid, pu, pv, pS, pf,
               pt, zf, a0, tab, A, B, I, AX, BX, M, W, act, nact, mrows, cur, tpiv, acc, wm, gs,
               gc, gp, gq, rep, gmark, stamp, sc, flag, G, E, Mn, rhs, lam, vol, gv, oi, ov, og,
                    out_i, out_v, out_g, count, status, info)


query_batch_serial = serial_twin(query_batch, error_model="numpy")
