"""Two-dimensional Delaunay triangulation with adjacency.

The :class:`Triangulation` holds counter-clockwise triangles and their
edge-adjacency, and offers the local operations the natural element method is
built on: point location by walking, the conflict (Bowyer--Watson) cavity of a
point, Lawson edge flips and a Delaunay check.  All geometric decisions go
through the exact predicates of :mod:`skfem_nem.geometry.predicates`, so structured grids
(every quad co-circular), collinear runs on the hull and slivers are handled
consistently.

Conventions
-----------
``triangles[t] = (a, b, c)`` is counter-clockwise; ``neighbours[t, k]`` is the
triangle across the edge opposite vertex ``triangles[t, k]`` (that is, the edge
``(triangles[t, k+1], triangles[t, k+2])``, indices mod 3), or ``-1`` on the
convex hull.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import Delaunay, QhullError

from .predicates import incircle_sign, orient2d, orient2d_sign

__all__ = ["Triangulation", "validate_nodes"]


# ---------------------------------------------------------------------------
# input validation
# ---------------------------------------------------------------------------

def validate_nodes(nodes, dim: int = 2, name: str = "nodes") -> np.ndarray:
    """Check an (n, dim) array of node coordinates and return a float64 copy.

    Raises ``ValueError`` naming the offending node for NaN/inf coordinates,
    fewer than ``dim + 1`` nodes and duplicate nodes. The caller's array is
    never modified.
    """
    p = np.array(nodes, dtype=np.float64, copy=True)
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}), got {np.shape(nodes)}")
    bad = np.flatnonzero(~np.isfinite(p).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{name} contain {bad.size} non-finite coordinate row(s); first is "
            f"{name}[{bad[0]}] = {p[bad[0]].tolist()}")
    if p.shape[0] < dim + 1:
        raise ValueError(f"need at least {dim + 1} {name} in {dim}D, got {p.shape[0]}")
    order = np.lexsort(p.T[::-1])
    same = np.flatnonzero((p[order[1:]] == p[order[:-1]]).all(axis=1))
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        raise ValueError(
            f"{same.size} duplicate node(s) in {name}; first: {name}[{j}] coincides "
            f"with {name}[{i}] at {p[i].tolist()}")
    return p


# ---------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _locate(P, T, N, qx, qy, start):
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
def _in_cavity(P, T, t, qx, qy):
    a = T[t, 0]
    b = T[t, 1]
    c = T[t, 2]
    return incircle_sign(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1], qx, qy) > 0.0


@njit(cache=True)
def _grow_cavity(P, T, N, qx, qy, t0, cav, cnb, rej):
    """Collect the triangles whose circumcircle strictly contains (qx, qy).

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
            if u < 0:
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
            if _in_cavity(P, T, u, qx, qy):
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
def _cavity_boundary(T, N, cav, cnb, ncav, be_a, be_b, be_c, be_u):
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
def _conflict_cycle(P, T, N, CC, qx, qy, t0, cav, cpar, cpa, cpb, cedge, cstep, stk, nn, be_u,
                    be_c):
    """The Bowyer--Watson cavity of (qx, qy) and its boundary, in one traversal.

    ``t0`` must contain the point and the point must not be a node; ``CC``:
    :attr:`Triangulation.circumcircles`. In a Delaunay triangulation the cavity is a triangulated disc without interior
    vertices, so its triangles form a tree under edge adjacency: a
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
    then goes round a cycle): :func:`_grow_cavity` handles that case.
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
        if u >= 0 and _in_circumcircle(P, T, CC, u, qx, qy):
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
def _insert(P, T, N, nt, i, t0, cav, cnb, rej, be_a, be_b, be_t, be_u, newt, extra):
    """Bowyer--Watson insertion of node i (inside the hull or on its boundary).

    The (up to) two triangles the insertion adds go to the slots ``extra[0]``,
    ``extra[1]`` (normally ``nt`` and ``nt + 1``). Returns how many extra slots
    were used, or a negative code: -1 outside the hull, -2 the node coincides
    with a vertex, -3 buffers too small.
    """
    qx = P[i, 0]
    qy = P[i, 1]
    t, k = _locate(P, T[:nt], N[:nt], qx, qy, t0)
    if k >= 0 or t < 0:
        return -1
    for j in range(3):
        a = T[t, j]
        if P[a, 0] == qx and P[a, 1] == qy:
            return -2
    ncav = _grow_cavity(P, T, N, qx, qy, t, cav, cnb, rej)
    if ncav < 0:
        return -3
    nb = _cavity_boundary(T, N, cav, cnb, ncav, be_a, be_b, be_t, be_u)
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
def _flip(T, N, t, k):
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
def _edge_violates(P, T, N, t, k):
    """True if the edge opposite vertex k of t fails the strict in-circle test
    and its quadrilateral is strictly convex (so that it can be flipped)."""
    u = N[t, k]
    if u < 0:
        return False
    a = T[t, k]
    b = T[t, (k + 1) % 3]
    c = T[t, (k + 2) % 3]
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
def _lawson(P, T, N, stack, nstack, max_flips, log):
    """Lawson's algorithm: flip non-Delaunay edges until none is left.

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
            if _edge_violates(P, T, N, t, k):
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
                _flip(T, N, t, k)
                flips += 1
                stack[nstack] = t
                stack[nstack + 1] = u
                nstack += 2
                break
    return flips, True


@njit(cache=True)
def _count_non_delaunay(P, T, N):
    bad = 0
    for t in range(T.shape[0]):
        for k in range(3):
            u = N[t, k]
            if u > t:
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
def _circumcircles(P, T, out):
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
def _in_circumcircle(P, T, CC, t, qx, qy):
    """Strict in-circle test of (qx, qy) against triangle t, with the cached
    circumcircle ``CC[t]`` (see :func:`_circumcircles`) as a float filter.

    With u = x - a (a the first vertex) and c the circumcentre offset, x is
    strictly inside iff D = u . (2 c - u) > 0. The computed D is within
    B = 2 |u|_1 err_c + 16 eps |u|_1 (|u|_1 + |c|_1) (+ a tiny absolute term
    for underflow) of the exact one; only when |D| <= B does the exact
    :func:`incircle_sign` decide. Same answer as :func:`_in_cavity`, for a
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
    return _in_cavity(P, T, t, qx, qy)


@njit(cache=True)
def _orientations(P, T, out):
    for t in range(T.shape[0]):
        a = T[t, 0]
        b = T[t, 1]
        c = T[t, 2]
        out[t] = orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1])


# ---------------------------------------------------------------------------
# adjacency from a triangle list
# ---------------------------------------------------------------------------

@njit(cache=True)
def _first_fold(T, N):
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
def _exact_hull(P, order):
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


def _adjacency(triangles: np.ndarray, n: int) -> np.ndarray:
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


# ---------------------------------------------------------------------------
# the class
# ---------------------------------------------------------------------------

class Triangulation:
    """A 2D triangulation of a node set with adjacency, kept Delaunay.

    Parameters
    ----------
    nodes
        (n, 2) node coordinates. Copied; the caller's array is not modified.
    triangles
        Optional (nt, 3) triangles to start from (any valid triangulation of
        the nodes' convex hull). If omitted, the Delaunay triangulation is
        built with Qhull. Either way the result is checked with exact
        predicates and repaired by Lawson flips into a Delaunay one, unless
        ``make_delaunay=False``.

    Attributes
    ----------
    nodes : (n, 2) float64
    triangles : (nt, 3) int64, counter-clockwise
    neighbours : (nt, 3) int64, ``neighbours[t, k]`` across the edge opposite
        ``triangles[t, k]``; ``-1`` on the hull.

    Raises
    ------
    ValueError
        For non-finite coordinates, fewer than 3 nodes, duplicate nodes, all
        nodes collinear, or nodes that Qhull would drop (naming the node).

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import Triangulation
    >>> nodes = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> tri = Triangulation(nodes)
    >>> tri.npoints, tri.ntriangles, tri.is_delaunay()
    (5, 4, True)
    >>> (tri.locate([[0.5, 0.1], [2.0, 2.0]]) >= 0).tolist()   # inside, outside the hull
    [True, False]
    >>> tri.insert([[0.8, 0.7]]).tolist()                       # index of the new node
    [5]
    >>> tri.ntriangles, tri.is_delaunay()
    (6, True)
    """

    def __init__(self, nodes, triangles=None, make_delaunay: bool = True):
        p = validate_nodes(nodes)
        self.nodes = p
        self.nodes.flags.writeable = False
        if triangles is None:
            T, N = self._qhull(p)
        else:
            T = np.array(triangles, dtype=np.int64, copy=True)
            if T.ndim != 2 or T.shape[1] != 3:
                raise ValueError(f"triangles must have shape (nt, 3), got {np.shape(triangles)}")
            if T.size and (T.min() < 0 or T.max() >= p.shape[0]):
                t = int(np.flatnonzero((T < 0).any(1) | (T >= p.shape[0]).any(1))[0])
                raise ValueError(f"triangle {t} has a vertex index out of range: {T[t].tolist()}")
            orient = np.empty(T.shape[0])
            _orientations(p, T, orient)
            zero = np.flatnonzero(orient == 0.0)
            if zero.size:
                raise ValueError(f"triangle {zero[0]} ({T[zero[0]].tolist()}) has zero area")
            neg = orient < 0
            T[neg] = T[neg][:, [0, 2, 1]]
            N = _adjacency(T, p.shape[0])
        self.triangles = T
        self.neighbours = N
        self._changed()
        used = np.zeros(p.shape[0], dtype=bool)
        used[T.ravel()] = True
        if triangles is None and not used.all():
            self.make_delaunay()
            self._insert_nodes(np.flatnonzero(~used))
            used[:] = True
        if not used.all():
            i = int(np.flatnonzero(~used)[0])
            raise ValueError(
                f"node {i} at {p[i].tolist()} is not a vertex of any triangle "
                f"({np.count_nonzero(~used)} such node(s))")
        self.last_flips = 0
        if make_delaunay:
            self.last_flips = self.make_delaunay()

    # -- construction -------------------------------------------------------
    @staticmethod
    def _qhull(p):
        ctr = p.mean(axis=0)
        try:
            d = Delaunay(p - ctr)
        except QhullError as err:
            o = np.empty(1)
            q = p - ctr
            i = int(np.argmax(np.abs(q).sum(1)))
            # all collinear?  check exactly against the two extreme nodes
            j = int(np.argmax(((q - q[i]) ** 2).sum(1)))
            coll = True
            for k in range(p.shape[0]):
                _orientations(p, np.array([[i, j, k]], dtype=np.int64), o)
                if o[0] != 0.0:
                    coll = False
                    break
            if coll:
                raise ValueError(
                    f"all {p.shape[0]} nodes are collinear (e.g. nodes {i} and {j} "
                    f"span the line): no 2D triangulation exists") from None
            raise ValueError(f"Qhull failed to triangulate the nodes: {err}") from None
        # nodes Qhull dropped as "coplanar" (closer to another node than its
        # tolerance) are inserted afterwards with exact predicates
        T, N = Triangulation._checked(p, d.simplices, d.neighbors)
        if T is None:
            # Qhull folded triangles in a cluster of nearly coincident nodes:
            # triangulate a thinned node set (all hull vertices kept), insert
            # the rest exactly
            T, N = Triangulation._thinned(p)
        return T, N

    @staticmethod
    def _checked(p, simplices, neighbors):
        """Orient Qhull's triangles CCW, drop flat hull triangles, and check
        that the result is a valid (fold-free) triangulation; (None, None) if not."""
        T = np.ascontiguousarray(simplices, dtype=np.int64)
        N = np.ascontiguousarray(neighbors, dtype=np.int64)
        orient = np.empty(T.shape[0])
        _orientations(p, T, orient)
        keep = orient != 0.0
        neg = orient < 0
        T[neg] = T[neg][:, [0, 2, 1]]
        N[neg] = N[neg][:, [0, 2, 1]]
        if not keep.all():
            # Qhull can leave flat triangles along collinear hull runs: drop them
            # and rebuild the adjacency
            T = np.ascontiguousarray(T[keep])
            try:
                N = _adjacency(T, p.shape[0])
            except ValueError:
                return None, None
        if _first_fold(T, N) >= 0:
            return None, None
        return T, N

    @staticmethod
    def _thinned(p):
        from scipy.spatial import cKDTree
        n = p.shape[0]
        on_hull = np.zeros(n, dtype=bool)
        on_hull[_exact_hull(p, np.lexsort((p[:, 1], p[:, 0])))] = True
        delta = 1e-6 * np.hypot(*np.ptp(p, axis=0))
        drop = np.zeros(n, dtype=bool)
        for i, j in cKDTree(p).query_pairs(delta, output_type="ndarray"):
            if drop[i] or drop[j]:
                continue
            if not on_hull[j]:
                drop[j] = True
            elif not on_hull[i]:
                drop[i] = True
        kept = np.flatnonzero(~drop)
        ctr = p[kept].mean(axis=0)
        d = Delaunay(p[kept] - ctr)
        T, N = Triangulation._checked(p[kept], d.simplices, d.neighbors)
        if T is None:
            raise ValueError("Qhull could not triangulate the nodes even after thinning "
                             "clusters of nearly coincident nodes")
        return np.ascontiguousarray(kept[T]), N

    @classmethod
    def from_triangles(cls, nodes, triangles, make_delaunay: bool = True) -> "Triangulation":
        """Build from an existing triangulation of the nodes (see class docs)."""
        return cls(nodes, triangles=triangles, make_delaunay=make_delaunay)

    # -- basic properties ---------------------------------------------------
    @property
    def npoints(self) -> int:
        return self.nodes.shape[0]

    @property
    def ntriangles(self) -> int:
        return self.triangles.shape[0]

    @property
    def edges(self) -> np.ndarray:
        """(ne, 2) unique edges, each sorted (i < j), lexicographically ordered."""
        T = self.triangles
        e = np.concatenate([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]])
        e.sort(axis=1)
        return np.unique(e, axis=0)

    @property
    def hull_edges(self) -> np.ndarray:
        """(nh, 2) convex-hull edges ``(a, b)``, counter-clockwise around the hull."""
        t, k = np.nonzero(self.neighbours < 0)
        T = self.triangles
        return np.stack([T[t, (k + 1) % 3], T[t, (k + 2) % 3]], axis=1)

    # -- predicates ----------------------------------------------------------
    def orientation(self) -> np.ndarray:
        """(nt,) exact-sign orientation determinants (twice the signed areas)."""
        out = np.empty(self.ntriangles)
        _orientations(self.nodes, self.triangles, out)
        return out

    def incircle(self, t: int, x) -> float:
        """Exact-sign in-circle test of point x against triangle t (> 0 inside)."""
        a, b, c = self.nodes[self.triangles[t]]
        return float(incircle_sign(a[0], a[1], b[0], b[1], c[0], c[1], float(x[0]), float(x[1])))

    def _changed(self):
        """Drop the caches derived from the triangles (after any change)."""
        self._seed_grid = None
        self._circumcentres = None

    @property
    def circumcircles(self) -> np.ndarray:
        """(nt, 5) circumcentre of each triangle minus its first vertex, a
        bound on the error of that offset (``inf`` where it is not used as a
        filter), and the first vertex; see :attr:`circumcentre_offsets`."""
        if self._circumcentres is None:
            out = np.empty((self.ntriangles, 5))
            _circumcircles(self.nodes, self.triangles, out)
            self._circumcentres = out
        return self._circumcentres

    @property
    def circumcentre_offsets(self) -> np.ndarray:
        """(nt, 2) circumcentre of each triangle minus its first vertex.

        Stored relative to the vertex (computed with the accurate
        :func:`~skfem_nem.geometry.predicates.orient2d`) so that the circumcentre
        relative to a nearby point x is ``(nodes[T[t, 0]] - x) + offset``
        without cancellation, however far the nodes are from the origin.
        (A view of the first two columns of :attr:`circumcircles`.)
        """
        return self.circumcircles[:, :2]

    # -- queries -------------------------------------------------------------
    def _seeds(self):
        """A bucket grid of triangles used to start walks near a query."""
        if self._seed_grid is None:
            P, T = self.nodes, self.triangles
            cen = P[T].mean(axis=1)
            lo = P.min(axis=0)
            span = np.maximum(P.max(axis=0) - lo, 1e-300)
            nc = max(1, int(np.sqrt(T.shape[0] / 2.0)))
            ij = np.minimum((nc * (cen - lo) / span).astype(np.int64), nc - 1)
            grid = np.full(nc * nc, -1, dtype=np.int64)
            grid[ij[:, 0] * nc + ij[:, 1]] = np.arange(T.shape[0])
            # fill empty buckets from the nearest filled one along rows
            filled = np.flatnonzero(grid >= 0)
            pos = np.searchsorted(filled, np.arange(nc * nc)).clip(0, filled.size - 1)
            grid = grid[filled[pos]]
            self._seed_grid = (lo, span, nc, grid)
        return self._seed_grid

    def start_triangles(self, x: np.ndarray) -> np.ndarray:
        """(m,) triangles near the points x (m, 2), to start walks from."""
        lo, span, nc, grid = self._seeds()
        ij = np.clip(((x - lo) / span * nc).astype(np.int64), 0, nc - 1)
        return grid[ij[:, 0] * nc + ij[:, 1]]

    def locate(self, x) -> np.ndarray:
        """Triangles containing the points x, shape (m, 2) -> (m,) int64.

        A point on an edge or at a node gets one of the triangles that
        contain it; a point outside the convex hull gets -1.
        """
        q = np.atleast_2d(np.asarray(x, dtype=np.float64))
        start = self.start_triangles(q)
        out = np.empty(q.shape[0], dtype=np.int64)
        _locate_many(self.nodes, self.triangles, self.neighbours, q, start, out)
        return out

    def cavity(self, x) -> np.ndarray:
        """Triangles whose circumcircle strictly contains the point x (2,).

        This is the Bowyer--Watson conflict region of x; its vertices are the
        natural neighbours of x. Empty if x is a node; raises ``ValueError``
        if x is outside the convex hull.
        """
        q = np.asarray(x, dtype=np.float64).reshape(2)
        t = int(self.locate(q[None])[0])
        if t < 0:
            raise ValueError(f"point {q.tolist()} is outside the convex hull")
        if np.any((self.nodes[self.triangles[t]] == q).all(axis=1)):
            return np.empty(0, dtype=np.int64)
        cap = 64
        while True:
            cav = np.empty(cap, dtype=np.int64)
            cnt = _grow_cavity(self.nodes, self.triangles, self.neighbours,
                               q[0], q[1], t, cav, np.empty((cap, 3), np.int64),
                               np.empty(cap + 4, np.int64))
            if cnt >= 0:
                return np.sort(cav[:cnt])
            cap *= 4

    # -- insertion -------------------------------------------------------------
    def insert(self, x) -> np.ndarray:
        """Insert new nodes x (k, 2) inside the convex hull (Bowyer--Watson).

        Only triangles whose circumcircle contains a new node change. Returns
        the (k,) indices of the new nodes. Raises ``ValueError`` (leaving the
        triangulation unchanged) for non-finite points, points outside the
        hull and points that coincide with a node.
        """
        q = np.array(np.atleast_2d(x), dtype=np.float64, copy=True)
        if q.ndim != 2 or q.shape[1] != 2:
            raise ValueError(f"inserted points must have shape (k, 2), got {np.shape(x)}")
        bad = np.flatnonzero(~np.isfinite(q).all(axis=1))
        if bad.size:
            raise ValueError(f"inserted point {bad[0]} is not finite: {q[bad[0]].tolist()}")
        n0 = self.npoints
        old = (self.nodes, self.triangles, self.neighbours)
        nodes = np.vstack([self.nodes, q])
        nodes.flags.writeable = False
        self.nodes = nodes
        try:
            self._insert_nodes(np.arange(n0, n0 + q.shape[0]))
        except ValueError:
            self.nodes, self.triangles, self.neighbours = old
            self._changed()
            raise
        return np.arange(n0, n0 + q.shape[0])

    def _insert_nodes(self, idx):
        P = self.nodes
        nt = self.ntriangles
        T = np.empty((nt + 2 * len(idx), 3), dtype=np.int64)
        N = np.empty_like(T)
        T[:nt] = self.triangles
        N[:nt] = self.neighbours
        cap = 64
        starts = self.start_triangles(P[idx])
        for i, start in zip(idx, starts):
            i = int(i)
            while True:
                cav = np.empty(cap, np.int64)
                cnb = np.empty((cap, 3), np.int64)
                rej = np.empty(cap + 4, np.int64)
                be = [np.empty(cap + 2, np.int64) for _ in range(5)]
                r = _insert(P, T, N, nt, i, int(start), cav, cnb, rej, *be,
                            np.array([nt, nt + 1], dtype=np.int64))
                if r != -3:
                    break
                cap *= 4
            if r == -1:
                raise ValueError(f"node {i} at {P[i].tolist()} lies outside the convex hull "
                                 f"and cannot be inserted")
            if r == -2:
                raise ValueError(f"node {i} at {P[i].tolist()} coincides with an existing node")
            nt += r
        self.triangles = np.ascontiguousarray(T[:nt])
        self.neighbours = np.ascontiguousarray(N[:nt])
        self._changed()

    # -- Delaunay maintenance -------------------------------------------------
    def make_delaunay(self, triangles=None, max_flips: int | None = None,
                      on_flips=None) -> int:
        """Lawson flips until every interior edge passes the in-circle test.

        Parameters
        ----------
        triangles
            Optional indices of the triangles to start checking from (after a
            local change); all triangles by default.
        max_flips
            Safety cap; default ``10 * nt + 100``.
        on_flips
            Optional callback ``on_flips(log)`` receiving, in order, batches of
            flips as an (k, 8) int array of rows ``(t, u, k, l, a, b, c, d)``:
            triangle t = (a, b, c) (a at position k) was flipped across edge
            b-c with u = (d, c, b) (d at position l); afterwards t holds
            ``(a, b, d)`` and u ``(a, d, c)``. Used to remap data stored per
            triangle.

        Returns the number of flips performed.
        """
        nt = self.ntriangles
        start = (np.arange(nt, dtype=np.int64) if triangles is None
                 else np.unique(np.asarray(triangles, dtype=np.int64)))
        if max_flips is None:
            max_flips = 10 * nt + 100
        total = 0
        while True:
            stack = np.empty(start.size + 2 * min(max_flips, nt // 4 + 1024), dtype=np.int64)
            stack[:start.size] = start
            log = np.empty((min(max_flips, nt // 4 + 1024) if on_flips else 0, 8), np.int64)
            flips, done = _lawson(self.nodes, self.triangles, self.neighbours, stack,
                                  start.size, max_flips - total, log)
            total += flips
            if flips:
                self._changed()
                if on_flips is not None:
                    on_flips(log[:flips])
            if done:
                return int(total)
            if total >= max_flips:
                raise RuntimeError(f"Lawson flips did not terminate within {max_flips} flips")
            start = np.arange(nt, dtype=np.int64)

    def is_delaunay(self) -> bool:
        """True if every interior edge passes the exact in-circle test and all
        triangles are strictly counter-clockwise."""
        if np.any(self.orientation() <= 0.0):
            return False
        return self.non_delaunay_edges() == 0

    def non_delaunay_edges(self) -> int:
        """Number of interior edges that fail the exact in-circle test."""
        return int(_count_non_delaunay(self.nodes, self.triangles, self.neighbours))

    def __repr__(self) -> str:
        return f"Triangulation({self.npoints} nodes, {self.ntriangles} triangles)"


@njit(cache=True)
def _locate_many(P, T, N, Q, start, out):
    for i in range(Q.shape[0]):
        t, k = _locate(P, T, N, Q[i, 0], Q[i, 1], start[i])
        out[i] = t if k < 0 else -1
