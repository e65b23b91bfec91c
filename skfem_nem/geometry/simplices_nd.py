"""Simplices in 2, 3 and 4 dimensions: circumspheres, point location and conflict regions.

The n-D counterpart of :mod:`skfem_nem.geometry.delaunay2d`, on Qhull's Delaunay
triangulation (:mod:`skfem_nem.geometry.delaunay_nd`): numba kernels over flat arrays
(``P`` nodes, ``S`` simplices, ``NB`` their neighbours) that Lasserre's volume recursion
(:mod:`skfem_nem.coordinates.lasserre`) calls for every query.

Natural neighbours
    The Delaunay triangulation comes from :class:`scipy.spatial.Delaunay`
    (Qhull). A query is located by a visibility walk (barycentric
    coordinates, tolerance ``_WALK`` of the coordinates) from a simplex at its nearest node;
    scipy's ``find_simplex`` is not used: its first call builds barycentric
    transforms through LAPACK, which with a multithreaded BLAS took 32 s for
    1.3e5 simplices. The natural neighbours of x are the vertices of the
    simplices whose circumsphere contains x (the conflict region, grown
    through ``neighbors``). In-sphere test: the circumcentre is solved
    relative to the simplex's first vertex (Gaussian elimination with
    partial pivoting); the power ``|w|^2 - 2 w.c`` (``w = x - v``, ``c`` the
    circumcentre relative to v, v that vertex; within its round-off bound
    the power is recomputed relative to the vertex nearest to x, whose bound
    shrinks with the distance to a node) is negative strictly inside.
    Simplices with a power below
    ``_INSPHERE * |w| (|w| + 2|c|)`` (a generous bound on its round-off),
    and (nearly) flat ones (Qhull's ``Qt`` makes them for co-spherical
    nodes, e.g. lattices), join the region too, so that it stays connected
    and no neighbour is lost; only the nodes of simplices strictly in
    conflict get cells (the others' cells are empty). Should the walk's
    tolerance have ended in a simplex whose circumsphere x is outside of
    (x within ~1e-12 of a vertex), the walk goes on without tolerance to the
    simplex that holds x. When a call has at
    least one query per ``_CACHE_QUERIES`` simplices, the circumcentres of
    all simplices are computed once beforehand (in parallel; each simplex
    is tested ~20 times by spatially sorted queries in 3D), with the same
    function and so the same bits as computing them per test.

"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..jit import serial_twin
from .status import AT_NODE, OK, ON_HULL, OUTSIDE, OVERFLOW
from .walls3d import WALL, through

__all__ = ["det_small", "circumcentre", "circumcentres", "in_conflict", "hull_distance",
           "barycentric", "locate_simplex", "locate_brute", "conflict_region",
           "circumcentre_cache", "facet_planes", "FLAT", "CACHE_QUERIES"]

# A simplex counts as flat when its volume determinant is below this times the
# product of its edge lengths from the first vertex.
FLAT = 1e-12
# A hull facet whose normal (generalised cross product of its edges) is
# shorter than this times the product of the edge lengths is degenerate.
HULL_FLAT = 1e-6
# The circumcentres of all simplices are computed once per call (in parallel)
# when there are at least 1/CACHE_QUERIES queries per simplex.
CACHE_QUERIES = 8


@njit(cache=True, _nrt=False)
def det_small(E, k):
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


@njit(cache=True, error_model="numpy", _nrt=False)
def circumcentre(P, S, s, d, E, rhs, flat):
    """Circumcentre of simplex s relative to its first vertex into ``rhs[:d]``
    (Gaussian elimination with partial pivoting; ``E`` (d, d) scratch).
    Returns the shape measure: the signed volume determinant over the
    product of the edge lengths from the first vertex (sign: the simplex's
    orientation), or 0.0 for a (nearly) flat simplex, at most ``flat`` in
    size (``rhs`` is then undefined)."""
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
            det = -det
        det *= E[c, c]
        if E[c, c] == 0.0:
            return 0.0
        for r in range(c + 1, d):
            f = E[r, c] / E[c, c]
            for j in range(c, d):
                E[r, j] -= f * E[c, j]
            rhs[r] -= f * rhs[c]
    if abs(det) <= flat * prod:
        return 0.0
    for c in range(d - 1, -1, -1):
        acc = rhs[c]
        for j in range(c + 1, d):
            acc -= E[c, j] * rhs[j]
        rhs[c] = acc / E[c, c]
    return det / prod


@njit(cache=True, parallel=True, error_model="numpy")
def circumcentres(P, S, flat, CC, SH):
    """:func:`circumcentre` of every simplex: ``CC`` (ns, d), ``SH`` (ns,)."""
    ns = S.shape[0]
    d = P.shape[1]
    nblocks = max(1, min(ns // 256, 64))
    for blk in prange(nblocks):
        E = np.empty((d, d))
        rhs = np.empty(d)
        for s in range(blk * ns // nblocks, (blk + 1) * ns // nblocks):
            SH[s] = circumcentre(P, S, s, d, E, rhs, flat)
            for k in range(d):
                CC[s, k] = rhs[k]


_circumcentres_serial = serial_twin(circumcentres)
#: below this many simplices circumcentres are computed on one thread: on a busy machine each
#: wake-up of the thread pool took ~7 ms, and a hull query's facets are triangulated anew
SERIAL_BELOW = 4096


@njit(cache=True, error_model="numpy", _nrt=False)
def in_conflict(P, S, s, x, d, E, rhs, tol, flat, cached, CC, SH):
    """Is x inside the circumsphere of simplex s? Returns ``(code, shape)``:
    code 2: strictly inside (the circumcentre is a vertex of x's Voronoi
    cell); 1: on it within the tolerance, or the simplex is flat; 0: outside.
    Unless flat, ``rhs[:d]`` holds the circumcentre relative to the first
    vertex; ``shape`` is :func:`circumcentre`'s, which is computed here or
    (``cached``) read from ``CC``, ``SH``."""
    if cached:
        shape = SH[s]
        for k in range(d):
            rhs[k] = CC[s, k]
    else:
        shape = circumcentre(P, S, s, d, E, rhs, flat)
    if shape == 0.0:
        return 1, 0.0
    v0 = S[s, 0]
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
    bound = tol * wn * (wn + 2.0 * np.sqrt(c2))
    if abs(power) < bound:
        # within the round-off bound: recompute relative to the vertex
        # nearest to x, where the bound shrinks with the distance (within
        # ~1e-11 of a node every simplex around it is then decided, not
        # borderline, and the region stays connected)
        vn = v0
        best = w2
        for j in range(1, d + 1):
            v = S[s, j]
            e2 = 0.0
            for k in range(d):
                e2 += (x[k] - P[v, k]) ** 2
            if e2 < best:
                best = e2
                vn = v
        if vn != v0:
            w2 = 0.0
            wc = 0.0
            c2 = 0.0
            for k in range(d):
                w = x[k] - P[vn, k]
                cn = rhs[k] - (P[vn, k] - P[v0, k])
                w2 += w * w
                wc += w * cn
                c2 += cn * cn
            power = w2 - 2.0 * wc
            wn = np.sqrt(w2)
            bound = tol * wn * (wn + 2.0 * np.sqrt(c2))
    if power < 0.0:
        return 2, shape
    if power < bound:
        return 1, shape
    return 0, shape


@njit(cache=True, _nrt=False)
def hull_distance(P, S, s, k, x, d, ctr, E, Mn):
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
        nc = det_small(Mn, d - 1) if d > 1 else 1.0
        if c % 2 == 1:
            nc = -nc
        nrm2 += nc * nc
        dist += nc * (x[c] - P[f0, c])
        side += nc * (ctr[c] - P[f0, c])
    if not np.sqrt(nrm2) > HULL_FLAT * prod:
        return np.inf, L
    if side < 0.0:
        dist = -dist
    return dist / np.sqrt(nrm2), L


@njit(cache=True, error_model="numpy", _nrt=False)
def barycentric(P, S, s, x, d, E, rhs, lam, flat_tol):
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


@njit(cache=True, error_model="numpy", _nrt=False)
def locate_simplex(P, S, NB, x, s, d, ctr, E, Mn, rhs, lam, tol, htol, flat_tol):
    """Visibility walk from simplex s to a simplex containing x (barycentric
    coordinates >= -tol). Returns ``(simplex, status)``: OK, OUTSIDE (beyond a
    hull facet by more than the hull tolerance; the simplex is that facet's)
    or OVERFLOW (the walk did not end; the caller searches exhaustively).
    A point just outside a hull facet, within the hull tolerance, is
    returned with that facet's simplex (the caller's hull test takes over)."""
    ns = S.shape[0]
    prev = -1
    for step in range(ns + 100):
        flat = barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            # a (nearly) flat simplex, whose barycentric coordinates mean
            # nothing (co-spherical nodes, slivers on the hull): step on
            k = step % (d + 1)
            for kk in range(d + 1):
                t = through(NB[s, (k + kk) % (d + 1)])
                if t >= 0 and t != prev:
                    break
            if t < 0:
                return s, OVERFLOW
            prev = s
            s = t
            continue
        k = np.int64(0)  # not a literal 0: one specialization of hull_distance
        for j in range(1, d + 1):
            if lam[j] < lam[k]:
                k = j
        if lam[k] >= -tol:
            return s, OK
        t = through(NB[s, k])           # (walks cross walls)
        if t < 0:
            dist, L = hull_distance(P, S, s, k, x, d, ctr, E, Mn)
            if dist == np.inf:
                # a degenerate hull facet: trust the barycentric coordinate
                dist = lam[k] * L
            if dist >= -htol * L:
                return s, OK
            return s, OUTSIDE
        prev = s
        s = t
    return s, OVERFLOW


@njit(cache=True, error_model="numpy", _nrt=False)
def locate_brute(P, S, x, d, E, rhs, lam, tol, flat_tol):
    """Exhaustive search for a simplex containing x (-1 if none)."""
    best = -1
    bestv = -np.inf
    for s in range(S.shape[0]):
        flat = barycentric(P, S, s, x, d, E, rhs, lam, flat_tol)
        if flat:
            continue
        mn = lam[0]
        for j in range(1, d + 1):
            mn = min(mn, lam[j])
        if mn > bestv:
            bestv = mn
            best = s
    return best, bestv


@njit(cache=True, error_model="numpy", _nrt=False)
def conflict_region(P, S, NB, ctr, x, hint, d, stamp_q, itol, flat, htol, wtol, cached, CC, SH,
                    smark, mark, cav, cst, live, bf, nn, Tc, zc, zq, E, Mn, rhs, lam, out_i, out_v,
                    out_g):
    """Locate x, grow its conflict region and collect the natural neighbours
    ``nn[:K]`` (``live`` marks those with cells of positive volume), the
    boundary faces ``bf[:nbf]`` and the conflict simplices ``cav[:ncav]``
    (``Tc[:ncav]``: in local indices; ``zc[:ncav]``: their circumcentres
    relative to x; ``zq[:ncav]``: their signed shape measures, see
    :func:`in_conflict`; ``smark[cav[c]] = stamp_q * (ccap + 1) + c``, ccap
    the length of ``cav``). Returns
    ``(status, info, ncav, K, nbf, degenerate)``; at a node writes the
    Kronecker delta into ``out_*``."""
    # Long kernel: location, the in-sphere growth and the neighbour bookkeeping update the
    # same stamps and buffers in one traversal; apart they would traverse the region twice.
    ccap = cav.shape[0]
    ncap = nn.shape[0]
    s0, st = locate_simplex(P, S, NB, x, hint, d, ctr, E, Mn, rhs, lam, wtol, htol, flat)
    if st == OUTSIDE:
        return OUTSIDE, 0, 0, 0, 0, False
    if st == OVERFLOW:
        s0, _ = locate_brute(P, S, x, d, E, rhs, lam, wtol, flat)
        if s0 < 0:
            return OUTSIDE, 0, 0, 0, 0, False
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
            return AT_NODE, 0, 0, 0, 0, False
    # conflict region by breadth-first search; smark: IN + c for the conflict
    # simplex c, OUT for a simplex tested and found out
    IN = stamp_q * (ccap + 1)
    OUT = IN + ccap
    code, shape = in_conflict(P, S, s0, x, d, E, rhs, itol, flat, cached, CC, SH)
    if code == 0:
        # x is outside the circumsphere of s0, so outside s0 itself, which the
        # walk's tolerance accepted (within ~1e-12 of a vertex, closer than
        # the in-sphere test's round-off bound): the region would not grow
        # from there; walk on with no tolerance to the simplex holding x
        s1, st = locate_simplex(P, S, NB, x, s0, d, ctr, E, Mn, rhs, lam, 0.0, htol, flat)
        if st == OVERFLOW:
            s1, _ = locate_brute(P, S, x, d, E, rhs, lam, 0.0, flat)
        if st != OUTSIDE and s1 >= 0 and s1 != s0:
            s0 = s1
            code, shape = in_conflict(P, S, s0, x, d, E, rhs, itol, flat, cached, CC, SH)
    cav[0] = s0
    cst[0] = max(1, code)
    zq[0] = shape
    for k in range(d):
        zc[0, k] = rhs[k] + (P[S[s0, 0], k] - x[k])
    smark[s0] = IN
    ncav = 1
    head = 0
    while head < ncav:
        s = cav[head]
        head += 1
        for k in range(d + 1):
            t = NB[s, k]
            if t <= WALL:
                # the region stops at a wall; x on a wall face of its own simplex is on
                # the wall (the caller's wall rule), beyond the plane of another is not
                # outside (the far side of a curved wall)
                if s == cav[0]:
                    dist, L = hull_distance(P, S, s, k, x, d, ctr, E, Mn)
                    if abs(dist) <= htol * L:
                        return ON_HULL, s * (d + 1) + k, 0, 0, 0, False
                continue
            if t < 0:
                dist, L = hull_distance(P, S, s, k, x, d, ctr, E, Mn)
                if dist < -htol * L:
                    return OUTSIDE, s * (d + 1) + k, 0, 0, 0, False
                if dist <= htol * L:
                    return ON_HULL, s * (d + 1) + k, 0, 0, 0, False
                continue
            if IN <= smark[t] <= OUT:
                continue
            code, shape = in_conflict(P, S, t, x, d, E, rhs, itol, flat, cached, CC, SH)
            if code > 0:
                if ncav == ccap:
                    return OVERFLOW, 0, 0, 0, 0, False
                cav[ncav] = t
                cst[ncav] = code
                zq[ncav] = shape
                for k in range(d):
                    zc[ncav, k] = rhs[k] + (P[S[t, 0], k] - x[k])
                smark[t] = IN + ncav
                ncav += 1
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
                    return OVERFLOW, 0, 0, 0, 0, False
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
            if t >= 0 and IN <= smark[t] < OUT:
                continue
            if nbf == bf.shape[0]:
                for jj in range(K):
                    mark[nn[jj]] = -1
                return OVERFLOW, 0, 0, 0, 0, False
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
    return OK, 0, ncav, K, nbf, degenerate


def circumcentre_cache(P, S, m):
    """``(cached, CC, SH)`` for the kernels: the circumcentres and shape
    measures of all simplices (:func:`circumcentres`) when m queries will
    probably test most of them (each tests ~40 in 3D), else empty arrays."""
    ns, d = S.shape[0], P.shape[1]
    if CACHE_QUERIES * m < ns:
        return False, np.empty((0, d)), np.empty(0)
    CC = np.empty((ns, d))
    SH = np.empty(ns)
    # (few simplices, hull facets' triangulations: waking the threads cost more than this)
    (circumcentres if ns >= SERIAL_BELOW else _circumcentres_serial)(P, S, FLAT, CC, SH)
    return True, CC, SH


def facet_planes(p, S, facets):
    """Unit normals (pointing out of the hull) and offsets, n . y = c, of the
    hull facets ``s * (d + 1) + k`` (the facet opposite vertex k of simplex s)."""
    d = p.shape[1]
    s, k = np.divmod(np.asarray(facets, np.int64), d + 1)
    keep = np.ones((s.size, d + 1), bool)
    keep[np.arange(s.size), k] = False
    F = S[s][keep].reshape(s.size, d)
    E = p[F[:, 1:]] - p[F[:, :1]]
    normal = np.linalg.svd(E)[2][:, -1]
    off = (normal * p[F[:, 0]]).sum(1)
    flip = normal @ p.mean(axis=0) > off
    normal[flip] *= -1
    off[flip] *= -1
    return normal, off, F
