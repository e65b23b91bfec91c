"""Sibson coordinates and their gradients in 2, 3 and 4 dimensions (the paper's Box 1).

This is the paper's "method 2": natural-neighbour (Sibson) coordinates from the
volumes of second-order Voronoi cells, each a convex polytope ``{y : A y <= b}``
whose volume is computed with Lasserre's recursive formula.

Natural neighbours
    The Delaunay triangulation comes from :class:`scipy.spatial.Delaunay`
    (Qhull). The natural neighbours of x are the vertices of the simplices
    whose circumsphere contains x (the conflict region, grown from the
    simplex ``find_simplex`` returns through ``neighbors``). In-sphere test:
    the circumcentre ``c`` is solved relative to the simplex's first vertex
    ``v0`` (Gaussian elimination with partial pivoting) and x is in the
    sphere when its power ``|w|^2 - 2 w.c`` (``w = x - v0``) is below
    ``_INSPHERE * |w| (|w| + 2|c|)``, a bound on its round-off. The decision
    is tolerant on purpose: a simplex whose sphere passes (nearly) through x
    is included, which only adds valid constraints and neighbours whose
    volume is zero, while wrongly leaving a simplex out would drop a
    neighbour. Flat simplices (Qhull's ``Qt`` makes them for co-spherical
    nodes, e.g. lattices) are included when reached, so that the region stays
    connected.

Second-order cells
    In coordinates centred at x (x = 0), with ``q_j = p_j - x``, the cell of
    neighbour i is ``q_i . y <= |q_i|^2 / 2`` (row 0: closer to x than to
    p_i) and ``(q_j - q_i) . y <= (q_j - q_i).(q_j + q_i) / 2`` (closer to p_i
    than to p_j). Only the neighbours j joined to i by an edge of a conflict
    simplex are needed: the others give redundant constraints (a face between
    the old Voronoi cells of i and j meets x's new cell only if one of its
    vertices, the circumcentre of a simplex holding the edge (i, j), does).
    ``phi_i = V_i / V`` with ``V = sum_j V_j``.

Lasserre's recursion
    ``V_n(A, b) = (1/n) sum_i (b_i / |a_it|) V_{n-1}(facet i)``, where facet i
    is the system with ``a_i . u = b_i`` used to eliminate the variable t of
    largest ``|a_it|``. Every row is scaled to unit length, so ``b`` are
    signed distances. A reduced row whose normal has norm at most
    ``_ZERO_ROW`` is parallel to facet i: it is dropped if its plane lies
    beyond the facet (``b' > _TIE * L``), makes the facet empty if it lies
    before it (``b' < -_TIE * L``), and if the two planes coincide (within
    ``_TIE * L``, L the distance from x to its farthest natural neighbour)
    the facet is empty unless the two face the same way and the facet's
    constraint has the smaller index: each coincident facet is counted
    exactly once (this matters for lattices, where many bisectors pass
    through the same edges), and a slab of zero width has zero volume. The
    base case n = 1 is the length of the feasible interval. Redundant
    constraints need no special treatment: their facets are empty or
    lower-dimensional and their recursion returns zero.

Gradients
    Only row 0 depends on x. Moving x moves the bisector between x and p_i
    with normal speed ``(y - x) . dx / |p_i - x|`` at a point y of it, hence
    ``grad V_i = (1 / |p_i - x|) integral over facet 0 of (y - x) dS``
    (in 2D this is ``(s_i / h_i) (c_i - x)``: facet length times its
    midpoint). The first moment of facet 0 comes from the same recursion:
    for a function homogeneous of degree q,
    ``integral_P f = 1/(n+q) sum_i (b_i / |a_it|) integral_{facet i} f``,
    so volumes and first moments (q = 1) recurse together. Then
    ``grad phi_i = (grad V_i - phi_i sum_j grad V_j) / V``, with the
    dominant neighbour's gradient taken from complement sums (as in
    :mod:`skfem_nem.coordinates`) to avoid cancellation near a node.

Special points
    At a node: the Kronecker delta (gradients undefined). On the convex hull
    (within ``_HULL`` times the distance to the nodes of the hull facet):
    the coordinates are the (d-1)-dimensional Sibson coordinates of the
    point within the hull plane, with respect to the nodes on that plane
    (in 2D the linear weights of the hull edge), which is their limit from
    inside; gradients are not computed there. Points on interior Delaunay
    faces and edges need nothing special: nothing divides by a quantity that
    vanishes there. Asking for gradients at nodes or on the hull raises
    ``ValueError`` (``undefined="raise"``) or gives NaN rows
    (``undefined="nan"``).

Accuracy
    For nodes in general position, values agree with the 2D area method
    (:func:`skfem_nem.sibson_coordinates`) to about 1e-15 and gradients to
    about 1e-13, and in 3D the second-order volumes sum to the first-order
    Voronoi volume to about 1e-15 relative. Configurations within
    ``_ZERO_ROW`` of co-spherical (exactly co-spherical ones, like lattices,
    are fine) lose digits like ``eps / angle``, where angle is how far the
    nearly coincident planes are from coincidence.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.spatial import Delaunay, QhullError, cKDTree

from .triangulation import validate_nodes

__all__ = ["sibson_coordinates_nd"]

# status codes of the query kernel
OK = 0
OUTSIDE = 1
OVERFLOW = 2
AT_NODE = 3
ON_HULL = 4
UNBOUNDED = 5

# A reduced (unit) constraint normal shorter than this is parallel to the facet.
_ZERO_ROW = 1e-13
# Parallel planes closer than this times the local length scale coincide.
_TIE = 1e-13
# Relative tolerance of the in-sphere test (tolerant: includes borderline simplices).
_INSPHERE = 1e-10
# A simplex counts as flat when its volume determinant is below this times the
# product of its edge lengths from the first vertex.
_FLAT = 1e-12
# A point whose distance to a hull facet's plane is below this times its
# distance to the facet's nodes is on the hull.
_HULL = 1e-12
# A hull facet whose normal (generalised cross product of its edges) is
# shorter than this times the product of the edge lengths is degenerate.
_HULL_FLAT = 1e-6
# Linear precision residual |sum_i V_i (p_i - x)| / (V L) above which a query is
# recomputed without the combinatorial facet filter (a safety net).
_LINEAR = 1e-9
# A vertex of a cell may violate its constraints by this times the local length
# scale (vertex check of the combinatorial filter in degenerate configurations).
_VERTEX = 1e-9
# Barycentric coordinates above -_WALK count as inside a simplex (point location).
_WALK = 1e-12

# default buffer sizes (natural neighbours, conflict simplices) per dimension
_CAPS = {2: (32, 64), 3: (96, 384), 4: (256, 2048)}


# ---------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------

@njit(cache=True, error_model="numpy")
def _cell(d, m0, A, B, I, M, Tc, nT, act, nact, mrows, cur, tpiv, acc, wm, gs, gc, gp,
          gq, rep, gmark, stamp, sc, full, strict, want_grad, G, ztol, btol, flag, cell,
          tab):
    """Volume of the polytope {u in R^d : A[0, j] . u <= B[0, j], j < m0} by
    Lasserre's recursion, run iteratively with one buffer level per dimension
    (level l holds a system in d - l variables).

    Rows must have unit length; ``I[0, j]`` is row j's constraint id (0 for the
    bisector between x and the cell's node, whose facet's first moment
    ``integral y dS`` goes to ``G`` when ``want_grad``).

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

    (One function without array-passing helpers: numba reference-counts
    array arguments with atomic operations, which dominated the run time.)
    """
    for s in range(nT):
        act[0, s] = s
    nact[0] = nT
    mrows[0] = m0
    for j in range(m0):
        gs[0, j] = j
        gc[0, j] = 1
        gp[0, j] = I[0, j]
    cur[0] = -1
    acc[0] = 0.0
    wm[0] = False
    if want_grad:
        for k in range(d):
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
                        mk = M[l + 1, c]
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
        empty = False
        if n == 2:
            # the facet is a segment: reduce the rows straight to the
            # feasible interval lo <= w <= hi
            u = 1 - t
            lo = -np.inf
            hi = np.inf
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
            f = A[l, j, t] * inv_ait
            bj = B[l, j] - f * bi
            if n == 2:
                a = A[l, j, u] - f * A[l, i, u]
                nrm = abs(a)
            else:
                c = 0
                nrm2 = 0.0
                for k in range(n):
                    if k != t:
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
                elif r > lo:
                    lo = r
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
            if child_mom:
                M[nl, 0] = 0.5 * (hi - lo) * (hi + lo)
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
        mrows[nl] = mm
        cur[nl] = -1
        acc[nl] = 0.0
        wm[nl] = child_mom
        if child_mom:
            for k in range(n - 1):
                M[nl, k] = 0.0
        l = nl


@njit(cache=True)
def _det_small(E, k):
    """Determinant of the leading k x k block of E (destroyed), partial pivoting."""
    det = 1.0
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if E[p, c] == 0.0:
            return 0.0
        if p != c:
            for j in range(k):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            det = -det
        det *= E[c, c]
        for r in range(c + 1, k):
            f = E[r, c] / E[c, c]
            for j in range(c, k):
                E[r, j] -= f * E[c, j]
    return det


@njit(cache=True, error_model="numpy")
def _in_conflict(P, S, s, x, d, E, rhs, tol, flat):
    """Is x inside the circumsphere of simplex s? 2: strictly inside (the
    circumcentre is a vertex of x's Voronoi cell); 1: on it within the
    tolerance, or the simplex is flat; 0: outside."""
    v0 = S[s, 0]
    prod = 1.0
    for r in range(d):
        v = S[s, r + 1]
        e2 = 0.0
        for k in range(d):
            e = P[v, k] - P[v0, k]
            E[r, k] = e
            e2 += e * e
        rhs[r] = 0.5 * e2
        prod *= np.sqrt(e2)
    # solve E c = rhs by Gaussian elimination with partial pivoting
    det = 1.0
    for c in range(d):
        p = c
        for r in range(c + 1, d):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if p != c:
            for j in range(d):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            rhs[c], rhs[p] = rhs[p], rhs[c]
        det *= E[c, c]
        if E[c, c] == 0.0:
            return 1
        for r in range(c + 1, d):
            f = E[r, c] / E[c, c]
            for j in range(c, d):
                E[r, j] -= f * E[c, j]
            rhs[r] -= f * rhs[c]
    if abs(det) <= flat * prod:
        return 1
    for c in range(d - 1, -1, -1):
        acc = rhs[c]
        for j in range(c + 1, d):
            acc -= E[c, j] * rhs[j]
        rhs[c] = acc / E[c, c]
    w2 = 0.0
    wc = 0.0
    c2 = 0.0
    for k in range(d):
        w = x[k] - P[v0, k]
        w2 += w * w
        wc += w * rhs[k]
        c2 += rhs[k] * rhs[k]
    power = w2 - 2.0 * wc
    wn = np.sqrt(w2)
    if power < 0.0:
        return 2
    if power < tol * wn * (wn + 2.0 * np.sqrt(c2)):
        return 1
    return 0


@njit(cache=True)
def _hull_distance(P, S, s, k, x, d, ctr, E, Mn):
    """Signed distance of x from the plane of the hull facet opposite vertex k
    of simplex s (positive on the side of ``ctr``, the centroid of the nodes,
    which lies inside the hull; the simplex itself may be flat) and the
    largest distance from x to the facet's vertices. The distance is +inf
    for a (nearly) degenerate facet, whose plane is ill-determined: Qhull
    makes such slivers along hull ridges with collinear nodes, and the
    well-shaped facets around them decide instead."""
    f0 = -1
    r = 0
    L = 0.0
    prod = 1.0
    for j in range(d + 1):
        if j == k:
            continue
        v = S[s, j]
        dx2 = 0.0
        for c in range(d):
            dx2 += (P[v, c] - x[c]) ** 2
        L = max(L, np.sqrt(dx2))
        if f0 < 0:
            f0 = v
        else:
            e2 = 0.0
            for c in range(d):
                E[r, c] = P[v, c] - P[f0, c]
                e2 += E[r, c] * E[r, c]
            prod *= np.sqrt(e2)
            r += 1
    # normal by the generalised cross product: n_c = (-1)^c det(E without column c)
    nrm2 = 0.0
    dist = 0.0
    side = 0.0
    for c in range(d):
        for rr in range(d - 1):
            cc = 0
            for j in range(d):
                if j != c:
                    Mn[rr, cc] = E[rr, j]
                    cc += 1
        nc = _det_small(Mn, d - 1) if d > 1 else 1.0
        if c % 2 == 1:
            nc = -nc
        nrm2 += nc * nc
        dist += nc * (x[c] - P[f0, c])
        side += nc * (ctr[c] - P[f0, c])
    if not np.sqrt(nrm2) > _HULL_FLAT * prod:
        return np.inf, L
    if side < 0.0:
        dist = -dist
    return dist / np.sqrt(nrm2), L


@njit(cache=True, error_model="numpy")
def _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol):
    """Barycentric coordinates of x in simplex s into ``lam``; returns True
    (and leaves ``lam`` alone) if the simplex is (nearly) flat: its volume
    determinant is at most ``flat_tol`` times the product of its edge lengths
    from the first vertex."""
    v0 = S[s, 0]
    prod = 1.0
    for c in range(d):
        e2 = 0.0
        for r in range(d):
            E[r, c] = P[S[s, c + 1], r] - P[v0, r]
            e2 += E[r, c] * E[r, c]
        prod *= np.sqrt(e2)
    for r in range(d):
        rhs[r] = x[r] - P[v0, r]
    det = 1.0
    for c in range(d):
        p = c
        for r in range(c + 1, d):
            if abs(E[r, c]) > abs(E[p, c]):
                p = r
        if E[p, c] == 0.0:
            return True
        if p != c:
            for j in range(d):
                E[c, j], E[p, j] = E[p, j], E[c, j]
            rhs[c], rhs[p] = rhs[p], rhs[c]
        det *= E[c, c]
        for r in range(c + 1, d):
            f = E[r, c] / E[c, c]
            for j in range(c, d):
                E[r, j] -= f * E[c, j]
            rhs[r] -= f * rhs[c]
    if not abs(det) > flat_tol * prod:
        return True
    tot = 0.0
    for c in range(d - 1, -1, -1):
        acc = rhs[c]
        for j in range(c + 1, d):
            acc -= E[c, j] * lam[j + 1]
        lam[c + 1] = acc / E[c, c]
        tot += lam[c + 1]
    lam[0] = 1.0 - tot
    return False


@njit(cache=True, error_model="numpy")
def _locate(P, S, NB, x, s, d, ctr, E, Mn, rhs, lam, tol, htol, flat_tol):
    """Visibility walk from simplex s to a simplex containing x (barycentric
    coordinates >= -tol). Returns ``(simplex, status)``: OK, OUTSIDE (beyond a
    hull facet by more than the hull tolerance; the simplex is that facet's)
    or OVERFLOW (the walk did not end; the caller searches exhaustively).
    A point just outside a hull facet, within the hull tolerance, is
    returned with that facet's simplex (the caller's hull test takes over)."""
    ns = S.shape[0]
    prev = -1
    for step in range(ns + 100):
        flat = _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            # a (nearly) flat simplex, whose barycentric coordinates mean
            # nothing (co-spherical nodes, slivers on the hull): step on
            k = step % (d + 1)
            for kk in range(d + 1):
                t = NB[s, (k + kk) % (d + 1)]
                if t >= 0 and t != prev:
                    break
            if t < 0:
                return s, OVERFLOW
            prev = s
            s = t
            continue
        k = 0
        for j in range(1, d + 1):
            if lam[j] < lam[k]:
                k = j
        if lam[k] >= -tol:
            return s, OK
        t = NB[s, k]
        if t < 0:
            dist, L = _hull_distance(P, S, s, k, x, d, ctr, E, Mn)
            if dist == np.inf:
                # a degenerate hull facet: trust the barycentric coordinate
                dist = lam[k] * L
            if dist >= -htol * L:
                return s, OK
            return s, OUTSIDE
        prev = s
        s = t
    return s, OVERFLOW


@njit(cache=True, error_model="numpy")
def _locate_brute(P, S, x, d, E, rhs, lam, tol, flat_tol):
    """Exhaustive search for a simplex containing x (-1 if none)."""
    best = -1
    bestv = -np.inf
    for s in range(S.shape[0]):
        flat = _barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            continue
        mn = lam[0]
        for j in range(1, d + 1):
            mn = min(mn, lam[j])
        if mn > bestv:
            bestv = mn
            best = s
    return best, bestv


@njit(cache=True, error_model="numpy")
def _query(P, S, NB, ctr, x, hint, d, stamp_q, want_grad, tols, smark, mark,
           cav, cst, live, rowof, bf, nn, q, Tc, tab, A, B, I, M, act, nact, mrows, cur, tpiv, acc, wm,
           gs, gc, gp, gq, rep, gmark, stamp, sc, G, E, Mn, rhs, lam, vol, gv, out_i, out_v, out_g):
    """Sibson coordinates of one point x, searched for from simplex ``hint``.

    Writes up to ``nn.shape[0]`` entries into ``out_*`` (sorted by node
    index) and returns ``(count, status, info)``; ``info`` is
    ``s * (d + 1) + k`` for the hull facet (s, k) of an ON_HULL point.
    ``stamp_q > 0`` must differ between the queries sharing ``smark``.
    """
    ztol, btol, itol, flat, htol, lintol, wtol, vtol = (tols[0], tols[1], tols[2], tols[3],
                                                        tols[4], tols[5], tols[6], tols[7])
    ccap = cav.shape[0]
    ncap = nn.shape[0]
    s0, st = _locate(P, S, NB, x, hint, d, ctr, E, Mn, rhs, lam, wtol, htol, flat)
    if st == OUTSIDE:
        return 0, OUTSIDE, 0
    if st == OVERFLOW:
        s0, _ = _locate_brute(P, S, x, d, E, rhs, lam, wtol, flat)
        if s0 < 0:
            return 0, OUTSIDE, 0
    # at a node: Kronecker delta
    for j in range(d + 1):
        v = S[s0, j]
        same = True
        for k in range(d):
            if P[v, k] != x[k]:
                same = False
                break
        if same:
            out_i[0] = v
            out_v[0] = 1.0
            for k in range(d):
                out_g[0, k] = np.nan
            return 1, AT_NODE, 0
    # conflict region by breadth-first search; smark = 2 stamp (in), 2 stamp + 1 (out)
    IN = 2 * stamp_q
    OUT = IN + 1
    cav[0] = s0
    cst[0] = max(1, _in_conflict(P, S, s0, x, d, E, rhs, itol, flat))
    smark[s0] = IN
    ncav = 1
    head = 0
    while head < ncav:
        s = cav[head]
        head += 1
        for k in range(d + 1):
            t = NB[s, k]
            if t < 0:
                dist, L = _hull_distance(P, S, s, k, x, d, ctr, E, Mn)
                if dist < -htol * L:
                    return 0, OUTSIDE, s * (d + 1) + k
                if dist <= htol * L:
                    return 0, ON_HULL, s * (d + 1) + k
                continue
            if smark[t] == IN or smark[t] == OUT:
                continue
            code = _in_conflict(P, S, t, x, d, E, rhs, itol, flat)
            if code > 0:
                if ncav == ccap:
                    return 0, OVERFLOW, 0
                cav[ncav] = t
                cst[ncav] = code
                ncav += 1
                smark[t] = IN
            else:
                smark[t] = OUT
    # natural neighbours (local indices through mark); only the nodes of
    # simplices strictly in conflict have cells of positive volume ("live")
    K = 0
    for c in range(ncav):
        for j in range(d + 1):
            v = S[cav[c], j]
            if mark[v] < 0:
                if K == ncap:
                    for jj in range(K):
                        mark[nn[jj]] = -1
                    return 0, OVERFLOW, 0
                mark[v] = K
                nn[K] = v
                live[K] = 0
                K += 1
            if cst[c] == 2:
                live[mark[v]] = 1
    # boundary faces of the conflict region (the new simplices are x + face)
    nbf = 0
    for c in range(ncav):
        s = cav[c]
        for k in range(d + 1):
            t = NB[s, k]
            if t >= 0 and smark[t] == IN:
                continue
            if nbf == bf.shape[0]:
                for jj in range(K):
                    mark[nn[jj]] = -1
                return 0, OVERFLOW, 0
            r = 0
            for j in range(d + 1):
                if j != k:
                    bf[nbf, r] = mark[S[s, j]]
                    r += 1
            nbf += 1
    degenerate = False
    for c in range(ncav):
        if cst[c] != 2:
            degenerate = True
    # local indices of the conflict simplices, in place of node indices
    for c in range(ncav):
        for j in range(d + 1):
            Tc[c, j] = mark[S[cav[c], j]]  # scratch: rows 0..ncav-1 of Tc (d + 1 wide)
    for j in range(K):
        mark[nn[j]] = -1
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
    flag = np.zeros(1, np.int64)
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
            # simplices' local indices in Tc[:ncav]
            nT = 0
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
            # row 0: closer to x than to p_i; then closer to p_i than to p_j
            h = 0.0
            for k in range(d):
                h += q[i, k] * q[i, k]
            h = np.sqrt(h)
            for k in range(d):
                A[0, 0, k] = q[i, k] / h
            B[0, 0] = 0.5 * h
            I[0, 0] = 0
            m = 1
            for j in range(K):
                if j == i or (not full and stamp[j + 1] != sc[0]):
                    continue
                nrm2 = 0.0
                bb = 0.0
                for k in range(d):
                    a = q[j, k] - q[i, k]
                    A[0, m, k] = a
                    nrm2 += a * a
                    bb += a * (q[j, k] + q[i, k])
                nrm = np.sqrt(nrm2)
                for k in range(d):
                    A[0, m, k] /= nrm
                B[0, m] = 0.5 * bb / nrm
                I[0, m] = j + 1
                rowof[j + 1] = m
                m += 1
            if not full and degenerate:
                # Flat or borderline simplices in the conflict region can give
                # simplices whose circumcentre is no vertex of the cell, and
                # the filter needs every listed simplex to be one: keep those
                # whose d planes meet in a point that satisfies all the rows.
                rowof[0] = 0
                kept = 0
                for c in range(nT):
                    for r in range(d):
                        row = rowof[Tc[base + c, r]]
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
                            if viol > vtol * L:
                                ok = False
                                break
                    if ok:
                        for k in range(d):
                            Tc[base + kept, k] = Tc[base + c, k]
                        kept += 1
                nT = kept
            v = _cell(d, m, A, B, I, M, Tc[base:], nT, act, nact, mrows, cur, tpiv, acc,
                      wm, gs, gc, gp, gq, rep, gmark, stamp, sc, full, strict, want_grad, G,
                      ztol, btol * L, flag, i, tab)
            vol[i] = max(v, 0.0)
            if want_grad:
                for k in range(d):
                    gv[i, k] = G[k] / h
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
    # The dominant neighbour gets its gradient from complement sums,
    #   grad phi_d = (grad V_d (1 - phi_d) - phi_d sum_{j != d} grad V_j) / V,
    # which avoids cancelling two large terms close to node d.
    dom = 0
    for i in range(1, K):
        if vol[i] > vol[dom]:
            dom = i
    rest = 0.0
    gc = np.zeros(d)
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
        if want_grad:
            for k in range(d):
                if i == dom:
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


@njit(cache=True, parallel=True, error_model="numpy")
def _query_batch(P, S, NB, Q, start, want_grad, ncap, ccap, nblocks, tols,
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
        tab = np.empty((ncap, ncap))
        A = np.empty((d, ncap + 1, d))
        B = np.empty((d, ncap + 1))
        I = np.empty((d, ncap + 1), np.int64)
        M = np.empty((d, d))
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
        G = np.empty(d)
        E = np.empty((d, d))
        Mn = np.empty((d, d))
        rhs = np.empty(d)
        lam = np.empty(d + 1)
        vol = np.empty(ncap)
        gv = np.empty((ncap, d))
        oi = np.empty(ncap, np.int64)
        ov = np.empty(ncap)
        og = np.empty((ncap, d))
        for r in range(lo, hi):
            cnt, st, inf = _query(P, S, NB, ctr, Q[r], start[r], d, r + 1, want_grad, tols,
                                  smark, mark, cav, cst, live, rowof, bf, nn, q, Tc, tab, A, B, I, M, act,
                                  nact, mrows, cur, tpiv, acc, wm, gs, gc, gp, gq, rep,
                                  gmark, stamp, sc, G, E, Mn,
                                  rhs, lam, vol, gv, oi, ov, og)
            count[r] = cnt
            status[r] = st
            info[r] = inf
            for j in range(cnt):
                out_i[r, j] = oi[j]
                out_v[r, j] = ov[j]
                if want_grad:
                    for k in range(d):
                        out_g[r, j, k] = og[j, k]


@njit(cache=True)
def _compress(count, indptr, out_i, out_v, out_g, want_grad, indices, data, grads):
    """Padded (m, cap) rows -> flat CSR arrays."""
    d = grads.shape[0]
    for r in range(count.shape[0]):
        p0 = indptr[r]
        for j in range(count[r]):
            indices[p0 + j] = out_i[r, j]
            data[p0 + j] = out_v[r, j]
            if want_grad:
                for k in range(d):
                    grads[k, p0 + j] = out_g[r, j, k]


# ---------------------------------------------------------------------------
# Python orchestration
# ---------------------------------------------------------------------------

def _check_nodes(nodes):
    shape = np.shape(nodes)
    if len(shape) != 2 or shape[1] not in (2, 3, 4):
        raise ValueError(f"nodes must have shape (n, d) with d = 2, 3 or 4, got {shape}")
    return validate_nodes(nodes, dim=shape[1])


def _check_queries(x, d) -> np.ndarray:
    q = np.array(x, dtype=np.float64, copy=True)
    if q.ndim == 1 and q.shape[0] == d:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != d:
        raise ValueError(f"query points must have shape (m, {d}), got {np.shape(x)}")
    bad = np.flatnonzero(~np.isfinite(q).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{bad.size} query point(s) have non-finite coordinates; first is "
            f"x[{bad[0]}] = {q[bad[0]].tolist()}")
    return q


def _triangulate(p):
    d = p.shape[1]
    try:
        tri = Delaunay(p)
    except QhullError as err:
        rank = np.linalg.matrix_rank(p[1:] - p[0])
        if rank < d:
            raise ValueError(
                f"the {p.shape[0]} nodes are degenerate: they span only {rank} of "
                f"{d} dimensions (flat node set), so no {d}D triangulation exists") from None
        raise ValueError(f"Qhull failed to triangulate the nodes: {err}") from None
    return tri


def _check_delaunay(tri, p):
    if not isinstance(tri, Delaunay):
        raise ValueError(f"delaunay must be a scipy.spatial.Delaunay, got {type(tri).__name__}")
    if tri.points.shape != p.shape or not np.array_equal(tri.points, p):
        raise ValueError("delaunay was built on other points than nodes")
    used = np.zeros(p.shape[0], dtype=bool)
    used[tri.simplices.ravel()] = True
    if not used.all():
        i = int(np.flatnonzero(~used)[0])
        raise ValueError(
            f"node {i} at {p[i].tolist()} is not a vertex of any Delaunay simplex "
            f"({np.count_nonzero(~used)} such node(s); Qhull drops nodes that nearly "
            f"coincide with others)")


def _run(P, S, NB, Q, start, gradient, ncap, ccap):
    """Run the kernel on a batch; returns (CSR matrices, status, info)."""
    import numba
    m, d = Q.shape
    n = P.shape[0]
    out_i = np.empty((m, ncap), np.int64)
    out_v = np.empty((m, ncap))
    out_g = np.empty((m, ncap, d) if gradient else (1, 1, d))
    count = np.empty(m, np.int64)
    status = np.empty(m, np.int64)
    info = np.empty(m, np.int64)
    tols = np.array([_ZERO_ROW, _TIE, _INSPHERE, _FLAT, _HULL, _LINEAR, _WALK, _VERTEX])
    nblocks = max(1, min(m // 16, 4 * numba.get_num_threads()))
    _query_batch(P, S, NB, Q, start, gradient, ncap, ccap, nblocks, tols,
                 out_i, out_v, out_g, count, status, info)
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(count, out=indptr[1:])
    nnz = int(indptr[-1])
    indices = np.empty(nnz, dtype=np.int64)
    data = np.empty(nnz)
    grads = np.empty((d, nnz) if gradient else (d, 0))
    _compress(count, indptr, out_i, out_v, out_g, gradient, indices, data, grads)
    mats = [sp.csr_matrix((data, indices, indptr), shape=(m, n))]
    if gradient:
        mats += [sp.csr_matrix((grads[k], indices.copy(), indptr.copy()), shape=(m, n))
                 for k in range(d)]
    return mats, status, info


def _on_hull(P, S, Q, facets):
    """Coordinates of points on the convex hull: the (d-1)-dimensional Sibson
    coordinates within the hull plane, with respect to the nodes on it.

    ``facets[r] = s * (d + 1) + k`` names the hull facet (opposite vertex k of
    simplex s) whose plane query r lies on. Returns a CSR matrix."""
    m, d = Q.shape
    n = P.shape[0]
    rows, cols, vals = [], [], []
    groups = {}
    diam = np.ptp(P, axis=0).max()
    for r, f in enumerate(facets):
        s, k = divmod(int(f), d + 1)
        face = np.delete(S[s], k)
        f0 = P[face[0]]
        # unit normal from the facet's edges
        _, _, vt = np.linalg.svd(P[face[1:]] - f0)
        normal = vt[-1]
        offs = (P - f0) @ normal
        on = np.flatnonzero(np.abs(offs) <= _HULL * diam)
        key = tuple(on)
        if key not in groups:
            groups[key] = (f0, normal, [])
        groups[key][2].append(r)
    for on, (f0, normal, rs) in groups.items():
        on = np.asarray(on)
        rs = np.asarray(rs)
        # orthonormal basis of the plane: the complement of the normal
        basis = np.linalg.svd(normal[None, :])[2][1:].T
        pn = (P[on] - f0) @ basis
        qn = (Q[rs] - f0) @ basis
        if d == 2:
            u = pn[:, 0]
            order = np.argsort(u)
            us = u[order]
            t = qn[:, 0]
            j = np.clip(np.searchsorted(us, t, side="right") - 1, 0, us.size - 2)
            w = np.clip((t - us[j]) / (us[j + 1] - us[j]), 0.0, 1.0)
            a, b = on[order[j]], on[order[j + 1]]
            rows += [rs, rs]
            cols += [a, b]
            vals += [1.0 - w, w]
        else:
            F = sibson_coordinates_nd(pn, qn).tocoo()
            rows.append(rs[F.row])
            cols.append(on[F.col])
            vals.append(F.data)
    R = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(m, n))
    R.eliminate_zeros()
    R.sort_indices()
    return R


def sibson_coordinates_nd(nodes, x, gradient: bool = False, delaunay=None,
                          undefined: Literal["raise", "nan"] = "raise"):
    """Sibson natural-neighbour coordinates (and gradients) in 2, 3 or 4 dimensions.

    Volumes of second-order Voronoi cells by Lasserre's recursive formula
    (the paper's Box 1); see the module docstring for the method.

    Parameters
    ----------
    nodes
        (n, d) node coordinates, d = 2, 3 or 4.
    x
        (m, d) query points inside the convex hull of the nodes (its boundary
        included).
    gradient
        Also return the gradients.
    delaunay
        Optional :class:`scipy.spatial.Delaunay` of ``nodes`` to reuse.
    undefined
        What to do when gradients are requested at a node or on the convex
        hull, where they are not defined: ``"raise"`` a ``ValueError`` naming
        the query, or give that row NaN gradients.

    Returns
    -------
    Phi : scipy.sparse.csr_matrix, shape (m, n)
        ``Phi[q, i] = phi_i(x_q)``, rows sorted by column index.
    dPhi : list of d csr_matrix, shape (m, n)
        Only with ``gradient=True``: ``dPhi[k][q, i] = d phi_i / d x_k (x_q)``,
        same sparsity pattern as ``Phi``.

    Raises
    ------
    ValueError
        For non-finite, too few, duplicate or flat (degenerate) nodes,
        non-finite queries, queries outside the convex hull (naming the first
        and the count) and gradients at nodes or on the hull with
        ``undefined="raise"``.
    """
    p = _check_nodes(nodes)
    d = p.shape[1]
    if undefined not in ("raise", "nan"):
        raise ValueError(f"undefined must be 'raise' or 'nan', got {undefined!r}")
    q = _check_queries(x, d)
    tri = _triangulate(p) if delaunay is None else delaunay
    _check_delaunay(tri, p)
    m, n = q.shape[0], p.shape[0]
    S = np.ascontiguousarray(tri.simplices, dtype=np.int64)
    NB = np.ascontiguousarray(tri.neighbors, dtype=np.int64)
    # start each walk from a simplex at the nearest node (scipy's find_simplex
    # is avoided: its first call computes barycentric transforms through
    # LAPACK, which is very slow with a multithreaded BLAS)
    if m:
        near = cKDTree(p).query(q)[1]
        start = np.ascontiguousarray(tri.vertex_to_simplex[near], dtype=np.int64)
    else:
        start = np.zeros(0, np.int64)
    ok = np.arange(m)
    status = np.full(m, OUTSIDE, np.int64)
    info = np.zeros(m, np.int64)
    ncap, ccap = _CAPS[d]
    mats = None
    todo = ok
    while todo.size:
        part, st, inf = _run(p, S, NB, q[todo], start[todo], gradient, ncap, ccap)
        status[todo] = st
        info[todo] = inf
        done = todo[st != OVERFLOW]
        keep = np.flatnonzero(st != OVERFLOW)
        E = sp.csr_matrix((np.ones(keep.size), (done, keep)), shape=(m, todo.size))
        part = [E @ M for M in part]
        mats = part if mats is None else [a + b for a, b in zip(mats, part)]
        todo = todo[st == OVERFLOW]
        ncap, ccap = 4 * ncap, 4 * ccap
    if mats is None:
        mats = [sp.csr_matrix((m, n)) for _ in range(1 + d * gradient)]
    out = np.flatnonzero(status == OUTSIDE)
    if out.size:
        raise ValueError(
            f"{out.size} query point(s) lie outside the convex hull of the nodes; "
            f"first is x[{out[0]}] = {q[out[0]].tolist()}")
    bad = np.flatnonzero(status == UNBOUNDED)
    if bad.size:  # pragma: no cover - a bounded cell is guaranteed inside the hull
        raise ValueError(
            f"second-order Voronoi cells of {bad.size} query point(s) came out unbounded; "
            f"first is x[{bad[0]}] = {q[bad[0]].tolist()}")
    hull = np.flatnonzero(status == ON_HULL)
    if hull.size:
        H = _on_hull(p, S, q[hull], info[hull])
        E = sp.csr_matrix((np.ones(hull.size), (hull, np.arange(hull.size))),
                          shape=(m, hull.size))
        mats[0] = mats[0] + E @ H
        if gradient:
            G = E @ H
            G.data[:] = np.nan
            mats[1:] = [M + G for M in mats[1:]]
    if gradient and undefined == "raise":
        for code, what in ((AT_NODE, "coincide with a node"),
                           (ON_HULL, "lie on the convex hull")):
            bad = np.flatnonzero(status == code)
            if bad.size:
                i = int(bad[0])
                extra = ""
                if code == AT_NODE:
                    j = int(np.flatnonzero((p == q[i]).all(axis=1))[0])
                    extra = f" (node {j})"
                raise ValueError(
                    f"gradients are undefined at {bad.size} query point(s) that {what}; "
                    f"first is x[{i}] = {q[i].tolist()}{extra}. Pass undefined='nan' to "
                    f"get NaN rows there instead")
    for M in mats:
        M.sort_indices()
    return (mats[0], mats[1:]) if gradient else mats[0]
