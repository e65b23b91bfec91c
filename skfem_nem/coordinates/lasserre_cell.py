"""Lasserre's volume recursion over the second-order Voronoi cell of one neighbour.

The kernel of the paper's Box 1: :func:`lasserre_cell` computes the volume (and the first
moment of facet 0, for the gradient) of the polytope ``{y : A y <= b}`` of natural
neighbour i of a query. It is one long numba kernel on purpose: numba cannot cache
recursive functions, so the recursion runs on an explicit stack of one buffer level per
dimension, and splitting the levels into functions would pass the 35 buffers through
every call in the innermost loop of the coordinates.

Second-order cells
    The cell of neighbour i is ``{y : |y - x| <= |y - p_i| <= |y - p_j|}``:
    row 0 ``q_i . y <= |q_i|^2 / 2`` (closer to x than to p_i, with
    ``q_j = p_j - x`` and x at the origin) and rows
    ``(q_j - q_i) . y <= (q_j - q_i).(q_j + q_i) / 2`` (closer to p_i than to
    p_j). Rows are scaled to unit normals, and the origin of each cell is
    moved to ``(x + p_i) / 2``, on the plane of row 0: near a node p_k the
    other cells are slabs of width ~|x - p_k| between nearly parallel
    planes, and an origin at x would make Lasserre's sum cancel terms of
    size one down to that width. ``phi_i = V_i / V``, ``V = sum_j V_j``.

Lasserre's recursion
    ``V_n(A, b) = (1/n) sum_i (b_i / |a_it|) V_{n-1}(facet i)``: facet i is
    the system with ``a_i . u = b_i`` used to eliminate the variable t of
    largest ``|a_it|``; the base case n = 1 is the length of the feasible
    interval. With unit rows, ``(b_i / |a_it|) V_{n-1}`` is the distance of
    the origin from facet i's plane times the facet's (n-1)-volume.

The general recursion
    It runs iteratively (an explicit stack of one buffer level per
    dimension, in a numba kernel; numba cannot cache recursive functions).

    - Combinatorial filter: the vertices of cell i are the circumcentres of
      the conflict simplices holding i and of the new simplices (x + a face
      of the region's boundary holding i), so the face of the cell on the
      constraints J is bounded only by constraints k that share such a
      simplex with J; the others are left out. This makes the recursion
      about linear in the number of faces (3D: ~21 facet visits and ~50 row
      reductions per cell instead of thousands). When the region holds flat
      or borderline simplices, listed simplices whose d planes do not meet
      in a point satisfying all rows (within ``_VERTEX``) are dropped first.
      Safety nets: a query whose cells come out unbounded or whose volumes
      violate linear precision (``sum_i V_i (p_i - x) = 0`` within
      ``_LINEAR``) is recomputed with a relaxed filter, then with none.
    - Coincident constraints (lattices put many bisectors through the same
      lines): when a facet's system is built, rows whose planes coincide
      (within ``_ZERO_ROW`` in direction, ``_TIE`` times the local length in
      offset) are merged, keeping the smallest id and the union of the ids
      for the filter; two that coincide facing each other leave a slab of
      zero width, so the facet has zero volume. A reduced row parallel to
      the facet (normal shorter than ``_ZERO_ROW``) is dropped if it lies
      beyond it, empties it if it lies before it. Redundant constraints need
      nothing else: their facets are empty or lower-dimensional and give 0.
    - Consistent vertices: in the last level (polygons) the two ends of
      each edge are recomputed from the pair of lines that meets there by a
      formula symmetric in the pair, so that both edges of a vertex use the
      same point: where two nearly parallel lines meet, independently
      rounded ends would not cancel in Lasserre's sum. Each facet's origin
      is likewise moved onto the trace of row 0.
    - The cells of neighbours i and j share the face on the bisector of
      p_i and p_j: its area is computed once.

Gradients
    Only row 0 depends on x. Moving x moves the bisector between x and p_i
    with normal speed ``(y - x) . dx / |p_i - x|`` at a point y of it, hence
    ``grad V_i = (1 / |p_i - x|) integral over facet 0 of (y - x) dS``
    (in 2D ``(s_i / h_i) (c_i - x)``: facet length times midpoint; this is
    the paper's ``-dV/da_0 - x dV/db_0`` written as a surface integral).
    The first moment of facet 0 comes from the same recursion: for f
    homogeneous of degree q,
    ``integral_P f = 1/(n+q) sum_i (b_i / |a_it|) integral_{facet i} f``,
    so volumes and first moments recurse together. On facet 0 the rows of
    the planes between x and p_m replace those between p_i and p_m (the same
    half-spaces there, and at good angles to it). Then
    ``grad phi_i = (grad V_i - phi_i sum_j grad V_j) / V``, with the
    dominant neighbour's gradient from complement sums (as in
    :mod:`skfem_nem.coordinates.area2d`).

"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["lasserre_cell", "vertex_simplices"]


@njit(cache=True, error_model="numpy", _nrt=False)
def lasserre_cell(d, m0, A, B, I, AX, BX, M, W, Tc, nT, act, nact, mrows, cur, tpiv, acc, wm,
                  gs, gc, gp, gq, rep, gmark, stamp, sc, full, strict, want_grad, want_mom, G,
                  ztol, btol, flag, cell, tab):
    """Volume of the polytope {u in R^d : A[0, j] . u <= B[0, j], j < m0} by
    Lasserre's recursion, run iteratively with one buffer level per dimension
    (level l holds a system in d - l variables).

    Rows must have unit length; ``I[0, j]`` is row j's constraint id (0 for the
    bisector between x and the cell's node, whose facet's first moment
    ``integral u dS`` goes to ``G[:d]`` and its area to ``G[d]`` when
    ``want_grad``). With ``want_mom`` the first moments ``integral u du`` of
    the cell go to ``M[0, :d]`` (then ``cell`` must be -1: no shared faces).

    Coincident rows. When a facet's system is built, rows whose planes
    coincide (within ``ztol`` in direction and ``btol`` in offset) are merged
    into one, which keeps the smallest id and the union of the ids as its
    group ``gp[l, gs[l, j]:gs[l, j] + gc[l, j]]``; two rows that coincide
    facing each other leave a slab of zero width, so the facet has zero
    volume. (Lattices put many bisectors through the same lines.)

    Combinatorial filter (unless ``full``). The face of the cell on the
    constraints J is only bounded by constraints k such that a simplex in
    ``Tc[:nT]`` (rows of d constraint ids: the Delaunay simplices whose
    circumcentres are the cell's vertices) holds J and k, counting every id
    of a merged group; the other constraints are redundant there and are
    left out. This holds for nodes in general position; where more than
    d + 1 nodes are co-spherical a face can be held by simplices that only
    share a lower-dimensional coincidence with it, so the ``strict=False``
    variant only asks for a simplex holding the last constraint of J and k.

    Shared faces. The cells of x's neighbours i < j share the face on the
    bisector between p_i and p_j, with opposite normals: cell ``cell`` stores
    the area of that face in ``tab[cell, j]`` for j > cell and reuses
    ``tab[j, cell]`` for j < cell (ids are j + 1).

    Origins. Each facet system below the top is translated by ``W[l]`` so
    that the trace of row 0 passes through its origin (moments are shifted
    back); on facet 0 the rows ``AX, BX`` (planes between x and the other
    neighbours) replace ``A[0], B[0]``. Polygon edges end at points
    computed symmetrically from the two lines meeting there.

    (One function without array-passing helpers: numba reference-counts
    array arguments with atomic operations, which dominated the run time.)
    """
    # Long kernel: the recursion runs on an explicit stack (numba cannot cache recursive
    # functions); each level's reduction, merging of coincident rows and filter share the
    # level buffers.
    for s in range(nT):
        act[0, s] = s
    nact[0] = nT
    for k in range(d):
        W[0, k] = 0.0
    mrows[0] = m0
    for j in range(m0):
        gs[0, j] = j
        gc[0, j] = 1
        gp[0, j] = I[0, j]
    cur[0] = -1
    acc[0] = 0.0
    wm[0] = want_mom
    if want_mom:
        for k in range(d):
            M[0, k] = 0.0
    if want_grad:
        for k in range(d + 1):
            G[k] = 0.0
    l = 0
    have = False   # a facet volume fv of facet cur[l] waits to be added to level l
    fv = 0.0
    while True:
        if have:
            # Lasserre's sum: (b_i / |a_it|) * (projected facet volume); and for
            # the first moments u_k = w_k (k != t), u_t = (b_i - sum a_ik w_k) / a_it
            have = False
            n = d - l
            i = cur[l]
            t = tpiv[l]
            ait = A[l, i, t]
            bi = B[l, i]
            coef = bi / abs(ait)
            acc[l] += coef * fv
            idc = I[l, i]
            if l == 0 and idc > 0:
                tab[cell, idc - 1] = fv / abs(ait)
            top = l == 0 and want_grad and idc == 0
            if wm[l] or top:
                c = 0
                s_ = 0.0
                for k in range(n):
                    if k != t:
                        mk = M[l + 1, c] + W[l + 1, c] * fv
                        s_ += A[l, i, k] * mk
                        if wm[l]:
                            M[l, k] += coef * mk
                        if top:
                            G[k] = mk / abs(ait)
                        c += 1
                mt = (bi * fv - s_) / ait
                if wm[l]:
                    M[l, t] += coef * mt
                if top:
                    G[t] = mt / abs(ait)
                    G[d] = fv / abs(ait)
        n = d - l
        cur[l] += 1
        i = cur[l]
        if i >= mrows[l]:
            v = acc[l] / n
            if wm[l]:
                for k in range(n):
                    M[l, k] /= n + 1
            if l == 0:
                return v
            l -= 1
            fv = v
            have = True
            continue
        idc = I[l, i]
        if B[l, i] == 0.0 and not wm[l] and (l > 0 or (idc == 0 and not want_grad)):
            continue  # the origin is on this facet's plane: no contribution
        if l == 0 and idc > 0:
            if idc - 1 < cell:
                # the face shared with an earlier cell: its area is known
                acc[0] += B[0, i] * tab[idc - 1, cell]
                continue
            tab[cell, idc - 1] = 0.0
        # facet i: pivot on its largest coefficient
        t = 0
        big = abs(A[l, i, 0])
        for k in range(1, n):
            if abs(A[l, i, k]) > big:
                big = abs(A[l, i, k])
                t = k
        tpiv[l] = t
        ait = A[l, i, t]
        inv_ait = 1.0 / ait
        bi = B[l, i]
        nl = l + 1
        if not full:
            # the simplices holding (a constraint of the group of) facet i,
            # and the ids they hold
            sc[0] += 1
            gstp = sc[0]
            for e in range(gs[l, i], gs[l, i] + gc[l, i]):
                gmark[gp[l, e]] = gstp
            sc[0] += 1
            na = 0
            pl = l if strict else 0
            for a in range(nact[pl]):
                s = act[pl, a]
                has = False
                for k in range(d):
                    if gmark[Tc[s, k]] == gstp:
                        has = True
                        break
                if has:
                    act[nl, na] = s
                    na += 1
                    for k in range(d):
                        stamp[Tc[s, k]] = sc[0]
            if na == 0:
                continue  # no vertex on this facet
            nact[nl] = na
        stp = sc[0]
        child_mom = wm[l] or (l == 0 and want_grad and idc == 0)
        # On facet 0 (|y - x| = |y - p_i|) "closer to p_i than to p_m" is
        # "closer to x than to p_m": reduce the rows of the planes x|m
        # (AX, BX) instead, which meet facet 0 at good angles even where
        # the planes p_i|p_m are nearly parallel to it (x close to a node).
        xm = l == 0 and idc == 0
        empty = False
        if n == 2:
            # the facet is a segment: reduce the rows straight to the
            # feasible interval lo <= w <= hi
            u = 1 - t
            lo = -np.inf
            hi = np.inf
            jlo = -1
            jhi = -1
            cnt = 0
        mm = 0
        pool = 0
        for j in range(mrows[l]):
            if j == i:
                continue
            if not full:
                cand = False
                for e in range(gs[l, j], gs[l, j] + gc[l, j]):
                    if stamp[gp[l, e]] == stp:
                        cand = True
                        break
                if not cand:
                    continue
            if xm:
                f = AX[j, t] * inv_ait
                bj = BX[j] - f * bi
            else:
                f = A[l, j, t] * inv_ait
                bj = B[l, j] - f * bi
            if n == 2:
                if xm:
                    a = AX[j, u] - f * A[l, i, u]
                else:
                    a = A[l, j, u] - f * A[l, i, u]
                nrm = abs(a)
            else:
                c = 0
                nrm2 = 0.0
                for k in range(n):
                    if k != t:
                        if xm:
                            v = AX[j, k] - f * A[l, i, k]
                        else:
                            v = A[l, j, k] - f * A[l, i, k]
                        A[nl, mm, c] = v
                        nrm2 += v * v
                        c += 1
                nrm = np.sqrt(nrm2)
            if nrm <= ztol:
                # the plane of row j is parallel to facet i
                if bj > btol:
                    continue          # it lies beyond the facet: redundant here
                if bj < -btol:
                    empty = True      # it cuts the whole facet away
                    break
                # coincident planes (not merged above): facing the same way,
                # the smaller id owns the facet; facing each other, they
                # bound a slab of zero width
                dot = 0.0
                for k in range(n):
                    if xm:
                        dot += AX[j, k] * A[l, i, k]
                    else:
                        dot += A[l, j, k] * A[l, i, k]
                if dot > 0.0 and I[l, j] > idc:
                    continue
                empty = True
                break
            if n == 2:
                r = bj / a
                cnt += 1
                if a > 0.0:
                    if r < hi:
                        hi = r
                        jhi = j
                elif r > lo:
                    lo = r
                    jlo = j
            else:
                inv = 1.0 / nrm
                for k in range(n - 1):
                    A[nl, mm, k] *= inv
                B[nl, mm] = bj * inv
                I[nl, mm] = I[l, j]
                gs[nl, mm] = pool
                gc[nl, mm] = gc[l, j]
                for e in range(gs[l, j], gs[l, j] + gc[l, j]):
                    gp[nl, pool] = gp[l, e]
                    pool += 1
                mm += 1
        if empty:
            continue
        if n == 2:
            if not hi > lo:
                continue
            if cnt == 0 or lo == -np.inf or hi == np.inf:
                flag[0] = 1
                continue
            # Recompute both ends as the intersection of the two lines by a
            # formula symmetric in the pair, so that the edge that ends at the
            # same vertex uses the very same point: at a vertex where two
            # nearly parallel lines meet, independently rounded ends would
            # not cancel in Lasserre's sum.
            for e in range(2):
                j = jhi if e == 0 else jlo
                if xm:
                    # facet 0 of a 2D cell: its ends from the planes x|m
                    a1x, a1y, b1 = A[0, i, 0], A[0, i, 1], B[0, i]
                    a2x, a2y, b2 = AX[j, 0], AX[j, 1], BX[j]
                else:
                    r1 = i
                    r2 = j
                    if I[l, j] < idc:
                        r1 = j
                        r2 = i
                    a1x, a1y, b1 = A[l, r1, 0], A[l, r1, 1], B[l, r1]
                    a2x, a2y, b2 = A[l, r2, 0], A[l, r2, 1], B[l, r2]
                det = a1x * a2y - a1y * a2x
                if u == 0:
                    w = (b1 * a2y - b2 * a1y) / det
                else:
                    w = (a1x * b2 - a2x * b1) / det
                if e == 0:
                    hi = w
                else:
                    lo = w
            if not hi > lo:
                continue
            if child_mom:
                M[nl, 0] = 0.5 * (hi - lo) * (hi + lo)
                W[nl, 0] = 0.0
            fv = hi - lo
            have = True
            continue
        if mm == 0:
            flag[0] = 1
            continue
        # merge coincident rows of the facet's system
        merged = False
        for b in range(mm):
            rep[b] = b
            for a in range(b):
                if rep[a] != a:
                    continue
                ds = 0.0
                do = 0.0
                for k in range(n - 1):
                    ds = max(ds, abs(A[nl, a, k] - A[nl, b, k]))
                    do = max(do, abs(A[nl, a, k] + A[nl, b, k]))
                if ds <= ztol and abs(B[nl, a] - B[nl, b]) <= btol:
                    rep[b] = a
                    merged = True
                    break
                if do <= ztol and abs(B[nl, a] + B[nl, b]) <= btol:
                    empty = True  # a slab of zero width: no volume
                    break
            if empty:
                break
        if empty:
            continue
        if merged:
            w = 0
            pool = 0
            for a in range(mm):
                if rep[a] != a:
                    continue
                start = pool
                idm = I[nl, a]
                for b in range(a, mm):
                    if rep[b] == a:
                        idm = min(idm, I[nl, b])
                        for e in range(gs[nl, b], gs[nl, b] + gc[nl, b]):
                            gq[pool] = gp[nl, e]
                            pool += 1
                for k in range(n - 1):
                    A[nl, w, k] = A[nl, a, k]
                B[nl, w] = B[nl, a]
                I[nl, w] = idm
                gs[nl, w] = start
                gc[nl, w] = pool - start
                w += 1
            for e in range(pool):
                gp[nl, e] = gq[e]
            mm = w
        # Put the facet's origin on the trace of row 0 (the bisector between
        # x and the cell's node), as at the top level: near a node the
        # facets are thin wedges along that plane.
        r0 = -1
        for j in range(mm):
            if I[nl, j] == 0:
                r0 = j
        for k in range(n - 1):
            W[nl, k] = 0.0
        if r0 >= 0 and B[nl, r0] != 0.0:
            for k in range(n - 1):
                W[nl, k] = B[nl, r0] * A[nl, r0, k]
            for j in range(mm):
                sh = 0.0
                for k in range(n - 1):
                    sh += A[nl, j, k] * W[nl, k]
                B[nl, j] -= sh
            B[nl, r0] = 0.0
        mrows[nl] = mm
        cur[nl] = -1
        acc[nl] = 0.0
        wm[nl] = child_mom
        if child_mom:
            for k in range(n - 1):
                M[nl, k] = 0.0
        l = nl


@njit(cache=True, error_model="numpy", _nrt=False)
def vertex_simplices(d, m, A, B, Tc, nT, rowof, E, rhs, lam, ztol, vtol):
    """Keep the rows of ``Tc[:nT]`` (d constraint ids each) whose d planes meet
    in a point that satisfies all m rows of ``A[0], B[0]`` within ``vtol``;
    returns their number."""
    rowof[0] = 0
    kept = 0
    for c in range(nT):
        for r in range(d):
            row = rowof[Tc[c, r]]
            for k in range(d):
                E[r, k] = A[0, row, k]
            rhs[r] = B[0, row]
        ok = True
        for cc in range(d):
            pv = cc
            for r in range(cc + 1, d):
                if abs(E[r, cc]) > abs(E[pv, cc]):
                    pv = r
            if not abs(E[pv, cc]) > ztol:
                ok = False
                break
            if pv != cc:
                for k in range(d):
                    E[cc, k], E[pv, k] = E[pv, k], E[cc, k]
                rhs[cc], rhs[pv] = rhs[pv], rhs[cc]
            for r in range(cc + 1, d):
                f = E[r, cc] / E[cc, cc]
                for k in range(cc, d):
                    E[r, k] -= f * E[cc, k]
                rhs[r] -= f * rhs[cc]
        if ok:
            for cc in range(d - 1, -1, -1):
                acc_ = rhs[cc]
                for k in range(cc + 1, d):
                    acc_ -= E[cc, k] * lam[k]
                lam[cc] = acc_ / E[cc, cc]
            for r in range(m):
                viol = -B[0, r]
                for k in range(d):
                    viol += A[0, r, k] * lam[k]
                if viol > vtol:
                    ok = False
                    break
        if ok:
            for k in range(d):
                Tc[kept, k] = Tc[c, k]
            kept += 1
    return kept
