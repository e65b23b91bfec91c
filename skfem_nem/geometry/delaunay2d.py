"""Numba kernels of the 2D Delaunay triangulation: walks, cavities, insertion, flips.

Flat arrays in, flat arrays out: ``P`` (n, 2) nodes, ``T`` (nt, 3) counter-clockwise
triangles, ``N`` (nt, 3) neighbours (``N[t, k]`` across the edge opposite ``T[t, k]``, -1 on
the hull), ``S`` the sorted keys (:func:`segment_key`) of the constrained edges (segments),
empty for an unconstrained triangulation. A segment is a wall: cavities do not grow across
it and flips never remove it, so the same kernels build and query constrained Delaunay
triangulations (:mod:`skfem_nem.geometry.constrained`).
:class:`~skfem_nem.geometry.triangulation.Triangulation` orchestrates them; the 2D coordinates
walk and grow cavities with the same kernels, so there is one point location and
one conflict region for both. Every decision goes through the exact predicates.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .predicates import incircle_sign, orient2d, orient2d_sign

__all__ = ["adjacency", "cavity_boundary", "circumcircle_table", "conflict_cycle",
           "count_non_delaunay", "edge_violates", "exact_hull", "first_fold",
           "flip_edge", "grow_cavity", "in_cavity", "in_circumcircle", "insert_vertex",
           "is_segment", "lawson", "locate_many", "locate_walk", "orientations",
           "segment_key", "split_in_three"]


# ---------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------

@njit(cache=True, inline="always")
def segment_key(a, b):
    """The key of the edge {a, b} in a segment table: (min << 32) | max."""
    lo = min(a, b)
    hi = max(a, b)
    return (np.int64(lo) << 32) | np.int64(hi)


@njit(cache=True, inline="always")
def is_segment(S, a, b):
    """True if the edge {a, b} is in the sorted segment keys ``S``."""
    if S.shape[0] == 0:
        return False
    key = segment_key(a, b)
    i = np.searchsorted(S, key)
    return i < S.shape[0] and S[i] == key


@njit(cache=True, inline="always")
def locate_walk(P, T, N, qx, qy, start):
    """Visibility walk from triangle ``start`` towards (qx, qy).

    Returns ``(t, k)``: ``t >= 0`` is a triangle containing the point (closed),
    with ``k = -1``; if the point is outside the convex hull, ``t`` is the hull
    triangle whose edge opposite its vertex ``k`` has the point strictly on its
    outer side.

    (Inlined into its callers: numba reference-counts array arguments with
    atomic operations, which would cost more than the walk itself.)
    """
    nt = T.shape[0]
    t = start
    prev = -1
    seed = 12345 + start
    for step in range(4 * nt + 16):
        seed = (seed * 1103515245 + 12345) & 0x7FFFFFFF
        r = seed % 3
        moved = False
        for kk in range(3):
            k = (r + kk) % 3
            u = N[t, k]
            if u == prev and u >= 0:
                continue
            a = T[t, (k + 1) % 3]
            b = T[t, (k + 2) % 3]
            if orient2d_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy) < 0.0:
                if u < 0:
                    return t, k
                prev = t
                t = u
                moved = True
                break
        if not moved:
            # the edge back to prev was skipped: the point is strictly on this
            # side of it (that is why the walk crossed it), so t contains it
            return t, -1
    # the walk did not terminate (only possible on invalid triangulations):
    # fall back to a scan
    for t in range(nt):
        inside = True
        for k in range(3):
            a = T[t, (k + 1) % 3]
            b = T[t, (k + 2) % 3]
            if orient2d_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy) < 0.0:
                inside = False
                break
        if inside:
            return t, -1
    return -1, -1


@njit(cache=True, inline="always")
def in_cavity(P, T, t, qx, qy):
    a = T[t, 0]
    b = T[t, 1]
    c = T[t, 2]
    return incircle_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1], qx, qy) > 0.0


@njit(cache=True)
def grow_cavity(P, T, N, S, qx, qy, t0, cav, cnb, rej):
    """Collect the triangles whose circumcircle strictly contains (qx, qy) and that
    are reached from ``t0`` without crossing a segment of ``S``.

    ``t0`` must contain the point and the point must not be a node. Fills
    ``cav[:count]`` and the local adjacency ``cnb[c, k]`` (index in ``cav`` of
    the neighbour across edge k of ``cav[c]``, or -1 if that neighbour is not
    in the cavity); ``rej`` is scratch for the rejected neighbours (each is
    tested once). Returns ``count``, or ``-1`` if the buffers are too small.
    """
    cap = cav.shape[0]
    rcap = rej.shape[0]
    cav[0] = t0
    count = 1
    nrej = 0
    head = 0
    while head < count:
        t = cav[head]
        for k in range(3):
            u = N[t, k]
            cnb[head, k] = -1
            if u < 0 or is_segment(S, T[t, (k + 1) % 3], T[t, (k + 2) % 3]):
                continue
            found = False
            for j in range(count):
                if cav[j] == u:
                    cnb[head, k] = j
                    found = True
                    break
            if found:
                continue
            for j in range(nrej):
                if rej[j] == u:
                    found = True
                    break
            if found:
                continue
            if in_cavity(P, T, u, qx, qy):
                if count == cap:
                    return -1
                cav[count] = u
                cnb[head, k] = count
                count += 1
            else:
                if nrej == rcap:
                    return -1
                rej[nrej] = u
                nrej += 1
        head += 1
    return count


@njit(cache=True)
def cavity_boundary(T, N, cav, cnb, ncav, be_a, be_b, be_c, be_u):
    """Boundary edges of a cavity, ordered into a counter-clockwise cycle.

    Edge j runs from ``be_a[j]`` to ``be_b[j]``, lies in cavity triangle
    ``cav[be_c[j]]`` and has the triangle ``be_u[j]`` (or -1) outside;
    ``be_b[j] == be_a[j + 1]``. Returns the number of edges, or -1 if they do
    not fit.
    """
    cap = be_a.shape[0]
    nb = 0
    for c in range(ncav):
        tc = cav[c]
        for kk in range(3):
            if cnb[c, kk] < 0:
                if nb == cap:
                    return -1
                be_a[nb] = T[tc, (kk + 1) % 3]
                be_b[nb] = T[tc, (kk + 2) % 3]
                be_c[nb] = c
                be_u[nb] = N[tc, kk]
                nb += 1
    for i in range(nb - 1):
        want = be_b[i]
        for j in range(i + 1, nb):
            if be_a[j] == want:
                if j != i + 1:
                    be_a[i + 1], be_a[j] = be_a[j], be_a[i + 1]
                    be_b[i + 1], be_b[j] = be_b[j], be_b[i + 1]
                    be_c[i + 1], be_c[j] = be_c[j], be_c[i + 1]
                    be_u[i + 1], be_u[j] = be_u[j], be_u[i + 1]
                break
    return nb


@njit(cache=True, inline="always")
def conflict_cycle(P, T, N, S, CC, qx, qy, t0, cav, cpar, cpa, cpb, cedge, cstep, stk, nn, be_u,
                   be_c):
    """The Bowyer--Watson cavity of (qx, qy) and its boundary, in one traversal
    (not crossing the segments ``S``: the cavity of a constrained triangulation).

    ``t0`` must contain the point and the point must not be a node; ``CC``:
    :attr:`Triangulation.circumcircles`. In a Delaunay triangulation the
    cavity is a triangulated disc without interior vertices, so its
    triangles form a tree under edge adjacency: a
    depth-first traversal from ``t0`` that visits the edges of each triangle
    counter-clockwise, starting after the edge it came in by, meets the
    boundary edges in counter-clockwise order, and no triangle is reached
    twice (so no search is needed).

    Outputs (``ncav`` cavity triangles, ``nb = ncav + 2`` boundary edges):

    * ``cav[c]``: the cavity triangles, ``cav[0] = t0``, each after its parent;
    * ``cpar[c]`` (c >= 1): the parent's index in ``cav``; the shared edge runs
      from node ``nn[cpa[c]]`` to node ``nn[cpb[c]]`` as seen from the parent
      (counter-clockwise in the parent);
    * ``nn[j]``: boundary edge j runs from node ``nn[j]`` to ``nn[(j + 1) % nb]``,
      lies in triangle ``cav[be_c[j]]`` and has the triangle ``be_u[j]`` (-1 on
      the hull) outside;
    * ``cedge``, ``cstep``, ``stk``: scratch of the size of ``cav``.

    Returns ``(ncav, nb)``, or ``(-1, -1)`` if the buffers (``cav``: ccap,
    ``nn``: bcap) are too small -- also the only possible outcome if the
    triangulation is not Delaunay and the cavity is not a tree (the traversal
    then goes round a cycle): :func:`grow_cavity` handles that case.
    """
    ccap = cav.shape[0]
    bcap = nn.shape[0]
    cav[0] = t0
    cpar[0] = -1
    cedge[0] = 0
    cstep[0] = 0
    stk[0] = 0
    depth = 1
    ncav = 1
    nb = 0
    while depth > 0:
        c = stk[depth - 1]
        s = cstep[c]
        if s == (3 if c == 0 else 2):
            depth -= 1
            cpb[c] = nb
            continue
        cstep[c] = s + 1
        t = cav[c]
        k = cedge[c] + s
        if k >= 3:
            k -= 3
        u = N[t, k]
        if u >= 0 and in_circumcircle(P, T, CC, u, qx, qy) and not is_segment(
                S, T[t, k + 1 if k < 2 else 0], T[t, k - 1 if k > 0 else 2]):
            if ncav == ccap:
                return -1, -1
            l = 0 if N[u, 0] == t else (1 if N[u, 1] == t else 2)
            cav[ncav] = u
            cpar[ncav] = c
            cpa[ncav] = nb
            cedge[ncav] = l + 1 if l < 2 else 0
            cstep[ncav] = 0
            stk[depth] = ncav
            depth += 1
            ncav += 1
        else:
            if nb == bcap:
                return -1, -1
            nn[nb] = T[t, k + 1 if k < 2 else 0]
            be_u[nb] = u
            be_c[nb] = c
            nb += 1
    # the edge that closes the cycle ends where the first one starts
    for c in range(1, ncav):
        if cpb[c] == nb:
            cpb[c] = 0
    return ncav, nb


@njit(cache=True)
def insert_vertex(P, T, N, S, nt, i, t0, cav, cnb, rej, be_a, be_b, be_t, be_u, newt, extra):
    """Bowyer--Watson insertion of node i (inside the hull or on its boundary).

    The (up to) two triangles the insertion adds go to the slots ``extra[0]``,
    ``extra[1]`` (normally ``nt`` and ``nt + 1``). Returns how many extra slots
    were used, or a negative code: -1 outside the hull, -2 the node coincides
    with a vertex, -3 buffers too small.
    """
    qx = P[i, 0]
    qy = P[i, 1]
    t, k = locate_walk(P, T[:nt], N[:nt], qx, qy, t0)
    if k >= 0 or t < 0:
        return -1
    for j in range(3):
        a = T[t, j]
        if P[a, 0] == qx and P[a, 1] == qy:
            return -2
    ncav = grow_cavity(P, T, N, S, qx, qy, t, cav, cnb, rej)
    if ncav < 0:
        return -3
    nb = cavity_boundary(T, N, cav, cnb, ncav, be_a, be_b, be_t, be_u)
    if nb < 0 or nb > ncav + 2:
        return -3
    # skip a hull edge the node lies on (it would give a flat triangle)
    skip = -1
    for j in range(nb):
        if be_u[j] < 0:
            a = be_a[j]
            b = be_b[j]
            if orient2d_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], qx, qy) == 0.0:
                skip = j
    # slots for the new triangles: the cavity's, then appended ones
    m = 0
    for j in range(nb):
        if j == skip:
            newt[j] = -1
            continue
        newt[j] = cav[m] if m < ncav else extra[m - ncav]
        m += 1
    for j in range(nb):
        s = newt[j]
        if s < 0:
            continue
        T[s, 0] = i
        T[s, 1] = be_a[j]
        T[s, 2] = be_b[j]
        u = be_u[j]
        N[s, 0] = u
        N[s, 1] = newt[(j + 1) % nb]
        N[s, 2] = newt[(j - 1 + nb) % nb]
        if u >= 0:
            # the outer triangle's slot opposite the shared edge (matched by
            # vertex, since cavity slots are being reused)
            for jj in range(3):
                if T[u, jj] != be_a[j] and T[u, jj] != be_b[j]:
                    N[u, jj] = s
    return max(0, m - ncav)


@njit(cache=True)
def flip_edge(T, N, t, k):
    """Flip the edge opposite vertex k of triangle t. Returns the other triangle."""
    u = N[t, k]
    a = T[t, k]
    b = T[t, (k + 1) % 3]
    c = T[t, (k + 2) % 3]
    ntb = N[t, (k + 1) % 3]  # across edge c-a
    ntc = N[t, (k + 2) % 3]  # across edge a-b
    l = 0
    for j in range(3):
        if N[u, j] == t:
            l = j
    d = T[u, l]
    nuc = N[u, (l + 1) % 3]  # across edge b-d  (u = d, c, b)
    nub = N[u, (l + 2) % 3]  # across edge d-c
    T[t, 0] = a
    T[t, 1] = b
    T[t, 2] = d
    N[t, 0] = nuc
    N[t, 1] = u
    N[t, 2] = ntc
    T[u, 0] = a
    T[u, 1] = d
    T[u, 2] = c
    N[u, 0] = nub
    N[u, 1] = ntb
    N[u, 2] = t
    if nuc >= 0:
        for j in range(3):
            if N[nuc, j] == u:
                N[nuc, j] = t
    if ntb >= 0:
        for j in range(3):
            if N[ntb, j] == t:
                N[ntb, j] = u
    return u


@njit(cache=True)
def edge_violates(P, T, N, S, t, k):
    """True if the edge opposite vertex k of t is not a segment of ``S``, fails the
    strict in-circle test and its quadrilateral is strictly convex (so that it
    can be flipped)."""
    u = N[t, k]
    if u < 0:
        return False
    a = T[t, k]
    b = T[t, (k + 1) % 3]
    c = T[t, (k + 2) % 3]
    if is_segment(S, b, c):
        return False
    d = -1
    for j in range(3):
        if N[u, j] == t:
            d = T[u, j]
    if incircle_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1],
                     P[d, 0], P[d, 1]) <= 0.0:
        return False
    if orient2d_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[d, 0], P[d, 1]) <= 0.0:
        return False
    if orient2d_sign(P[a, 0], P[a, 1], P[d, 0], P[d, 1], P[c, 0], P[c, 1]) <= 0.0:
        return False
    return True


@njit(cache=True)
def lawson(P, T, N, S, stack, nstack, max_flips, log):
    """Lawson's algorithm: flip non-Delaunay edges (never a segment of ``S``)
    until none is left.

    ``stack[:nstack]`` holds the triangles to check. Each flip is recorded in
    ``log`` (if it has rows) as ``(t, u, k, l, a, b, c, d)``: triangle
    t = (a, b, c) (a at position k) was flipped across its edge b-c with
    triangle u = (d, c, b) (d at position l); afterwards t = (a, b, d) and
    u = (a, d, c). Returns
    ``(flips, done)``; ``done`` is False if the stack, the log or
    ``max_flips`` ran out first (the flips made so far are valid and logged;
    check all triangles again to finish).
    """
    flips = 0
    cap = stack.shape[0]
    logcap = log.shape[0]
    while nstack > 0:
        nstack -= 1
        t = stack[nstack]
        for k in range(3):
            if edge_violates(P, T, N, S, t, k):
                if flips == max_flips or nstack + 2 > cap or (logcap > 0 and flips == logcap):
                    return flips, False
                u = N[t, k]
                if logcap > 0:
                    l = 0
                    for j in range(3):
                        if N[u, j] == t:
                            l = j
                    log[flips, 0] = t
                    log[flips, 1] = u
                    log[flips, 2] = k
                    log[flips, 3] = l
                    log[flips, 4] = T[t, k]
                    log[flips, 5] = T[t, (k + 1) % 3]
                    log[flips, 6] = T[t, (k + 2) % 3]
                    log[flips, 7] = T[u, l]
                flip_edge(T, N, t, k)
                flips += 1
                stack[nstack] = t
                stack[nstack + 1] = u
                nstack += 2
                break
    return flips, True


@njit(cache=True)
def count_non_delaunay(P, T, N, S):
    """Interior edges, other than the segments ``S``, that fail the in-circle test."""
    bad = 0
    for t in range(T.shape[0]):
        for k in range(3):
            u = N[t, k]
            if u > t and not is_segment(S, T[t, (k + 1) % 3], T[t, (k + 2) % 3]):
                a = T[t, 0]
                b = T[t, 1]
                c = T[t, 2]
                d = -1
                for j in range(3):
                    if N[u, j] == t:
                        d = T[u, j]
                if incircle_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1],
                                 P[d, 0], P[d, 1]) > 0.0:
                    bad += 1
    return bad


# The cached circumcircles are used as a float filter for the in-circle test
# only while every coordinate difference is zero or within [2**-300, 2**300],
# the circumcentre offset below 2**400 and the doubled area above 2**-900:
# then nothing overflows or underflows and the error bounds below hold.
_CIRCLE_LO = 2.0 ** -300
_CIRCLE_HI = 2.0 ** 300
_CIRCLE_MAX = 2.0 ** 400
_CIRCLE_MIN_AREA = 2.0 ** -900
_CIRCLE_ABS = 2.0 ** -900


@njit(cache=True, inline="always")
def _filter_range(x):
    x = abs(x)
    return x == 0.0 or (x >= _CIRCLE_LO and x <= _CIRCLE_HI)


@njit(cache=True)
def circumcircle_table(P, T, out):
    """Circumcentre offsets, their error bounds and the first vertices, ``out`` (nt, 5).

    ``out[t, :2]`` is the circumcentre of triangle t minus its first vertex a
    (with b, c relative to a: ``(c_y |b|^2 - b_y |c|^2, b_x |c|^2 - c_x |b|^2)
    / (2 d)``, d = cross(b, c) from :func:`orient2d`, relative error 2**-42).
    ``out[t, 2]`` bounds the error of the two components together: the
    numerators carry at most 8 rounding errors relative to the sums of
    their terms' magnitudes, the division the error of d; both are doubled
    here. Triangles outside the range where these bounds hold get ``inf``.
    ``out[t, 3:]`` is the vertex a itself (so that the in-circle filter needs
    no second, dependent memory access).
    """
    for t in range(T.shape[0]):
        a = T[t, 0]
        b = T[t, 1]
        c = T[t, 2]
        bx = P[b, 0] - P[a, 0]
        by = P[b, 1] - P[a, 1]
        cx = P[c, 0] - P[a, 0]
        cy = P[c, 1] - P[a, 1]
        d = orient2d(P[b, 0], P[b, 1], P[c, 0], P[c, 1], P[a, 0], P[a, 1])
        b2 = bx * bx + by * by
        c2 = cx * cx + cy * cy
        f = 0.5 / d
        ox = (cy * b2 - by * c2) * f
        oy = (bx * c2 - cx * b2) * f
        out[t, 0] = ox
        out[t, 1] = oy
        err = np.inf
        if (_filter_range(bx) and _filter_range(by) and _filter_range(cx)
                and _filter_range(cy) and abs(d) >= _CIRCLE_MIN_AREA):
            err = (2.0 ** -49 * (abs(cy) * b2 + abs(by) * c2 + abs(bx) * c2 + abs(cx) * b2)
                   * abs(f) + 2.0 ** -41 * (abs(ox) + abs(oy)))
            if not (abs(ox) + abs(oy) < _CIRCLE_MAX and err < _CIRCLE_MAX):
                err = np.inf
        out[t, 2] = err
        out[t, 3] = P[a, 0]
        out[t, 4] = P[a, 1]


@njit(cache=True, inline="always")
def in_circumcircle(P, T, CC, t, qx, qy):
    """Strict in-circle test of (qx, qy) against triangle t, with the cached
    circumcircle ``CC[t]`` (see :func:`circumcircle_table`) as a float filter.

    With u = x - a (a the first vertex) and c the circumcentre offset, x is
    strictly inside iff D = u . (2 c - u) > 0. The computed D is within
    B = 2 |u|_1 err_c + 16 eps |u|_1 (|u|_1 + |c|_1) (+ a tiny absolute term
    for underflow) of the exact one; only when |D| <= B does the exact
    :func:`incircle_sign` decide. Same answer as :func:`in_cavity`, for a
    fraction of its cost.
    """
    ux = qx - CC[t, 3]
    uy = qy - CC[t, 4]
    cx = CC[t, 0]
    cy = CC[t, 1]
    s = abs(ux) + abs(uy)
    g = abs(cx) + abs(cy)
    if s < _CIRCLE_MAX and g < _CIRCLE_MAX:
        det = ux * (2.0 * cx - ux) + uy * (2.0 * cy - uy)
        bound = 2.01 * s * CC[t, 2] + 2.0 ** -49 * s * (s + g) + _CIRCLE_ABS
        if det > bound:
            return True
        if det < -bound:
            return False
    return in_cavity(P, T, t, qx, qy)


@njit(cache=True)
def orientations(P, T, out):
    for t in range(T.shape[0]):
        a = T[t, 0]
        b = T[t, 1]
        c = T[t, 2]
        out[t] = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1])


# ---------------------------------------------------------------------------
# adjacency from a triangle list
# ---------------------------------------------------------------------------

@njit(cache=True)
def first_fold(T, N):
    """First triangle whose neighbour lists their shared edge in the same
    direction (a fold, for counter-clockwise triangles), or -1."""
    for t in range(T.shape[0]):
        for k in range(3):
            u = N[t, k]
            if u < 0:
                continue
            b = T[t, (k + 1) % 3]
            c = T[t, (k + 2) % 3]
            ok = False
            for j in range(3):
                if T[u, j] == c and T[u, (j + 1) % 3] == b:
                    ok = True
            if not ok:
                return t
    return -1


@njit(cache=True)
def exact_hull(P, order):
    """Convex-hull vertices (no collinear ones) by Andrew's monotone chain
    with the exact orientation predicate; ``order`` sorts P by x, then y."""
    n = order.shape[0]
    h = np.empty(2 * n + 1, np.int64)
    k = 0
    for ii in range(n):
        i = order[ii]
        while k >= 2 and orient2d_sign(P[h[k - 2], 0], P[h[k - 2], 1], P[h[k - 1], 0],
                                       P[h[k - 1], 1], P[i, 0], P[i, 1]) <= 0.0:
            k -= 1
        h[k] = i
        k += 1
    lower = k + 1
    for ii in range(n - 2, -1, -1):
        i = order[ii]
        while k >= lower and orient2d_sign(P[h[k - 2], 0], P[h[k - 2], 1], P[h[k - 1], 0],
                                           P[h[k - 1], 1], P[i, 0], P[i, 1]) <= 0.0:
            k -= 1
        h[k] = i
        k += 1
    return h[:k - 1].copy()


def adjacency(triangles: np.ndarray, n: int) -> np.ndarray:
    """Neighbour array for (nt, 3) triangles; raises on non-manifold edges."""
    nt = triangles.shape[0]
    # edge opposite vertex k: (T[:, k+1], T[:, k+2])
    a = np.concatenate([triangles[:, 1], triangles[:, 2], triangles[:, 0]])
    b = np.concatenate([triangles[:, 2], triangles[:, 0], triangles[:, 1]])
    lo = np.minimum(a, b).astype(np.int64)
    hi = np.maximum(a, b).astype(np.int64)
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    nb = np.full(3 * nt, -1, dtype=np.int64)
    same = np.flatnonzero(ks[1:] == ks[:-1])
    if same.size and np.any(same[1:] == same[:-1] + 1):
        j = same[np.flatnonzero(same[1:] == same[:-1] + 1)[0]]
        e = order[j]
        raise ValueError(
            f"edge ({lo[e]}, {hi[e]}) is shared by more than two triangles")
    i1 = order[same]
    i2 = order[same + 1]
    nb[i1] = i2 % nt
    nb[i2] = i1 % nt
    # slot s = k * nt + t  ->  neighbours[t, k]
    return np.ascontiguousarray(nb.reshape(3, nt).T)


@njit(cache=True)
def locate_many(P, T, N, Q, start, out):
    for i in range(Q.shape[0]):
        t, k = locate_walk(P, T, N, Q[i, 0], Q[i, 1], start[i])
        out[i] = t if k < 0 else -1


@njit(cache=True)
def split_in_three(T, N, ts, n, nt):
    """Split the distinct triangles ``ts`` in three, one after the other, in arrays
    already grown by two rows per split: triangle t = (a, b, c) of ``ts[m]`` becomes
    ``(i, b, c)`` and rows ``nt + 2m``, ``nt + 2m + 1`` become ``(i, c, a)`` and
    ``(i, a, b)``, with i = n + m; the neighbours follow."""
    for m in range(ts.shape[0]):
        t, i, t1, t2 = ts[m], n + m, nt + 2 * m, nt + 2 * m + 1
        a, b, c = T[t, 0], T[t, 1], T[t, 2]
        nb, nc = N[t, 1], N[t, 2]
        T[t1, 0], T[t1, 1], T[t1, 2] = i, c, a
        T[t2, 0], T[t2, 1], T[t2, 2] = i, a, b
        T[t, 0] = i
        N[t1, 0], N[t1, 1], N[t1, 2] = nb, t2, t
        N[t2, 0], N[t2, 1], N[t2, 2] = nc, t, t1
        N[t, 1], N[t, 2] = t1, t2
        for nbr, child in ((nb, t1), (nc, t2)):
            if nbr >= 0:
                for k in range(3):
                    if N[nbr, k] == t:
                        N[nbr, k] = child
