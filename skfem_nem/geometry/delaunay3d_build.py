"""Incremental 3D Delaunay insertion (Bowyer-Watson) on flat arrays, in numba.

Why our own: a moving 3D mesh must stay Delaunay by local flips, which needs an adjacency we
own, and Qhull's construction dominates the time of 3D Sibson interpolation. Every decision is
an exact sign (:mod:`.predicates3d`), so the result is the Delaunay tetrahedralisation of the
given doubles, not of a rounded version of them.

Data structure: tetrahedra ``T`` (m, 4) and neighbours ``N`` (m, 4), ``N[t, i]`` the tetrahedron
across the face opposite ``T[t, i]``. The hull is closed by *ghost* tetrahedra ``(a, b, c, G)``
with the ghost vertex ``G = n`` always in slot 3, so that every tetrahedron has four
neighbours. Finite tetrahedra are positively oriented (``orient3d > 0``); a ghost ``(a, b, c,
G)`` has ``orient3d(a, b, c, x) > 0`` for the points ``x`` beyond its hull face. Together they
form an oriented closed manifold, and Bowyer-Watson's "replace the vertex opposite each
cavity face by the new point" keeps that orientation, also for ghosts.

Cospherical points (a cubic lattice: every cell is cospherical) are resolved by the symbolic
perturbation of Devillers and Teillaud ("Perturbations for Delaunay and weighted Delaunay 3D
triangulations", CGAL's scheme): ties of ``insphere`` are broken as if the lifting of the
points were perturbed by infinitesimals ordered lexicographically by coordinates, which is a
consistent lifting, so the result is the Delaunay tetrahedralisation of the perturbed points:
unique, and with no flat tetrahedron (the perturbation moves no point, and each new
tetrahedron has the new point strictly on the far side of its cavity face). For a point on
the plane of a hull face the ghost is in conflict exactly when its finite neighbour is (the
sphere meets that plane in the face's circumcircle), so coplanar points on a box's faces give
flat-free hull triangulations too: four cocircular points on a face are split by the same
perturbation, consistently for the tetrahedra on both sides.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .predicates import orient2d
from .predicates3d import insphere_sign, orient3d_sign

OK, DUPLICATE, FLAT = 0, 1, 2  # build status codes
_GROW = 1.5  # growth factor of the flat arrays
_TETS_PER_POINT = 7  # initial capacity: a random 3D Delaunay has about 6.5 tets per point
_KEY_BASE = 1 << 31  # edge key lo * _KEY_BASE + hi (vertex indices below 2**31)
_HASH_MULT = 0x9E3779B97F4A7C15 >> 1  # Fibonacci hashing (odd, fits an int64)


@njit(cache=True, inline="always")
def o3(P, a, b, c, d):
    return orient3d_sign(P[a, 0], P[a, 1], P[a, 2], P[b, 0], P[b, 1], P[b, 2],
                         P[c, 0], P[c, 1], P[c, 2], P[d, 0], P[d, 1], P[d, 2])


@njit(cache=True)
def _lex_less(P, i, j):
    for k in range(3):
        if P[i, k] != P[j, k]:
            return P[i, k] < P[j, k]
    return False


@njit(cache=True)
def _perturbed_inside(P, a, b, c, d, q):
    """Tie-break of a zero ``insphere(a, b, c, d, q)`` (Devillers-Teillaud): the leading
    nonzero term of the perturbed determinant, looked up from the lexicographically largest
    point down; two steps suffice for a non-flat ``a, b, c, d``."""
    pts = np.empty(5, np.int64)
    pts[0], pts[1], pts[2], pts[3], pts[4] = a, b, c, d, q
    for i in range(1, 5):  # insertion sort, ascending lexicographic order
        j = i
        while j > 0 and _lex_less(P, pts[j], pts[j - 1]):
            pts[j], pts[j - 1] = pts[j - 1], pts[j]
            j -= 1
    for i in (4, 3):
        s = pts[i]
        if s == q:
            return False
        if s == d:
            o = o3(P, a, b, c, q)
        elif s == c:
            o = o3(P, a, b, q, d)
        elif s == b:
            o = o3(P, a, q, c, d)
        else:
            o = o3(P, q, b, c, d)
        if o != 0.0:
            return o > 0.0
    return False


@njit(cache=True, inline="always")
def finite_conflict(P, T, t, q):
    """Whether point q lies inside the (perturbed) circumsphere of the finite tet t."""
    a, b, c, d = T[t, 0], T[t, 1], T[t, 2], T[t, 3]
    s = insphere_sign(P[a, 0], P[a, 1], P[a, 2], P[b, 0], P[b, 1], P[b, 2],
                      P[c, 0], P[c, 1], P[c, 2], P[d, 0], P[d, 1], P[d, 2],
                      P[q, 0], P[q, 1], P[q, 2])
    if s != 0.0:
        return s > 0.0
    # q as int64 whichever width the caller's index has (an insertion's point index, or a
    # vertex read from T): one specialization of _perturbed_inside
    return _perturbed_inside(P, a, b, c, d, np.int64(q))


@njit(cache=True, inline="always")
def conflict(P, G, T, N, t, q):
    """Whether tet t (finite or ghost) is destroyed by inserting point q."""
    if T[t, 3] != G:
        return finite_conflict(P, T, t, q)
    o = o3(P, T[t, 0], T[t, 1], T[t, 2], q)
    if o != 0.0:
        return o > 0.0
    return finite_conflict(P, T, N[t, 3], q)


@njit(cache=True, inline="always")
def _substituted(P, T, t, i, q):
    """Orientation of the finite tet t with its vertex in slot i replaced by point q."""
    v0, v1, v2, v3 = T[t, 0], T[t, 1], T[t, 2], T[t, 3]
    if i == 0:
        return o3(P, q, v1, v2, v3)
    if i == 1:
        return o3(P, v0, q, v2, v3)
    if i == 2:
        return o3(P, v0, v1, q, v3)
    return o3(P, v0, v1, v2, q)


@njit(cache=True)
def locate(P, G, T, N, start, q, seed):
    """Visibility walk from tet ``start`` to a finite tet containing point q (closed) or a
    ghost whose hull face q sees strictly; the face to try first is random (a stochastic
    walk, which terminates), the face just crossed is not tested again."""
    t = start
    if T[t, 3] == G:
        t = N[t, 3]
    prev = -1
    while True:
        seed = (seed * 6364136223846793005 + 1442695040888963407) & 0x7FFFFFFFFFFFFFFF
        k0 = (seed >> 33) & 3
        moved = False
        for k in range(4):
            i = (k0 + k) & 3
            nb = N[t, i]
            if nb == prev:
                continue
            if _substituted(P, T, t, i, q) < 0.0:
                prev = t
                t = nb
                moved = True
                break
        if not moved or T[t, 3] == G:
            return t, seed


@njit(cache=True)
def _grow_rows(A, rows):
    B = np.empty((rows,) + A.shape[1:], A.dtype)
    B[:A.shape[0]] = A
    return B


@njit(cache=True)
def cavity(P, G, T, N, stamp, conf, it, t0, q, cav):
    """Breadth-first search of the tets in conflict with q from t0 (in conflict); ``stamp``
    marks the tets tested at insertion ``it``, ``conf`` their result."""
    stamp[t0] = it
    conf[t0] = True
    cav[0] = t0
    ncav = 1
    k = 0
    while k < ncav:
        t = cav[k]
        k += 1
        for i in range(4):
            nb = N[t, i]
            if stamp[nb] == it:
                continue
            stamp[nb] = it
            c = conflict(P, G, T, N, nb, q)
            conf[nb] = c
            if c:
                if ncav == cav.shape[0]:
                    cav = _grow_rows(cav, 2 * ncav)
                cav[ncav] = nb
                ncav += 1
    return cav, ncav


@njit(cache=True)
def _boundary_faces(N, stamp, conf, it, cav, ncav):
    n = 0
    for k in range(ncav):
        t = cav[k]
        for i in range(4):
            nb = N[t, i]
            if not (stamp[nb] == it and conf[nb]):
                n += 1
    return n


@njit(cache=True, inline="always")
def _edge_of(T, nt, i, j):
    """The two vertices of tet nt other than those in slots i and j, in increasing order."""
    u = -1
    v = -1
    for m in range(4):
        if m != i and m != j:
            if u < 0:
                u = T[nt, m]
            else:
                v = T[nt, m]
    return min(u, v), max(u, v)


@njit(cache=True)
def _link_around(T, N, new, qslot, nnew, keys, vals, used):
    """Neighbours among the new tets, all sharing the new point: the face of a new tet
    opposite slot j contains the point and an edge (u, v) of the cavity boundary, shared by
    exactly one other new tet. Matched through a small open-addressing table (``keys`` all
    -1 on entry and on return; its size a power of two above four times the entries), which
    stays in cache, unlike a table indexed by vertex."""
    mask = keys.shape[0] - 1
    nused = 0
    for k in range(nnew):
        nt = new[k]
        i = qslot[k]
        for j in range(4):
            if j == i:
                continue
            lo, hi = _edge_of(T, nt, i, j)
            key = np.int64(lo) * _KEY_BASE + hi
            h = ((key * _HASH_MULT) >> 20) & mask
            while keys[h] >= 0 and keys[h] != key:
                h = (h + 1) & mask
            if keys[h] == key:
                other = vals[h]
                N[nt, j] = other >> 2
                N[other >> 2, other & 3] = nt
            else:
                keys[h] = key
                vals[h] = 4 * nt + j
                used[nused] = h
                nused += 1
    for k in range(nused):
        keys[used[k]] = -1


@njit(cache=True)
def _retriangulate(T, N, stamp, conf, it, cav, ncav, q, free, nfree, ntet, new, qslot):
    """Replace the cavity by the tets joining q to its boundary faces (free slots first);
    return the updated ``nfree, ntet`` and the number of new tets."""
    nnew = 0
    for k in range(ncav):
        t = cav[k]
        for i in range(4):
            nb = N[t, i]
            if stamp[nb] == it and conf[nb]:
                continue
            if nfree > 0:
                nfree -= 1
                nt = free[nfree]
            else:
                nt = ntet
                ntet += 1
            for j in range(4):
                T[nt, j] = T[t, j]
            T[nt, i] = q
            N[nt, i] = nb
            for j in range(4):
                if N[nb, j] == t:
                    N[nb, j] = nt
                    break
            stamp[nt] = 0
            new[nnew] = nt
            qslot[nnew] = i
            nnew += 1
    for k in range(ncav):
        T[cav[k], 0] = -1
        free[nfree] = cav[k]
        nfree += 1
    return nfree, ntet, nnew


@njit(cache=True)
def coincident(P, T, t, q):
    """A vertex of the finite tet t at the position of point q, or -1."""
    for j in range(4):
        v = T[t, j]
        if P[v, 0] == P[q, 0] and P[v, 1] == P[q, 1] and P[v, 2] == P[q, 2]:
            return v
    return -1


@njit(cache=True)
def _collinear(P, a, b, c):
    return (orient2d(P[a, 0], P[a, 1], P[b, 0], P[b, 1], P[c, 0], P[c, 1]) == 0.0
            and orient2d(P[a, 1], P[a, 2], P[b, 1], P[b, 2], P[c, 1], P[c, 2]) == 0.0
            and orient2d(P[a, 0], P[a, 2], P[b, 0], P[b, 2], P[c, 0], P[c, 2]) == 0.0)


@njit(cache=True)
def _first_tet(P, order):
    """Positions in ``order`` of four affinely independent points (the first point, the
    next distinct one, the next not collinear, the next not coplanar), or -1s."""
    n = order.shape[0]
    a = order[0]
    k1 = 1
    while k1 < n and _coincident_pair(P, a, order[k1]):
        k1 += 1
    k2 = k1 + 1
    while k2 < n and _collinear(P, a, order[k1], order[k2]):
        k2 += 1
    k3 = k2 + 1
    while k3 < n and o3(P, a, order[k1], order[k2], order[k3]) == 0.0:
        k3 += 1
    if k3 >= n:
        return -1, -1, -1
    return k1, k2, k3


@njit(cache=True)
def _coincident_pair(P, i, j):
    return P[i, 0] == P[j, 0] and P[i, 1] == P[j, 1] and P[i, 2] == P[j, 2]


@njit(cache=True)
def _init_tets(P, G, T, N, a, b, c, d):
    """Tet 0 = (a, b, c, d), positive, and the four ghosts on its faces: the ghost of the
    face opposite slot i is tet 0 with slot i made G, G moved to slot 3 by an odd permutation
    (the oriented boundary of the 4-simplex a, b, c, d, G), as tets 1 to 4."""
    if o3(P, a, b, c, d) < 0.0:
        a, b = b, a
    v = (a, b, c, d)
    T[0, 0], T[0, 1], T[0, 2], T[0, 3] = a, b, c, d
    for i in range(4):
        f = [v[j] for j in range(4) if j != i]
        if i % 2 == 1:  # (others, G) has sign (-1)**i: an odd i needs one swap
            f[0], f[1] = f[1], f[0]
        T[1 + i, 0], T[1 + i, 1], T[1 + i, 2], T[1 + i, 3] = f[0], f[1], f[2], G
    for s in range(5):
        for i in range(4):
            for t in range(5):
                if t != s and _shares_face(T, s, i, t):
                    N[s, i] = t


@njit(cache=True)
def _shares_face(T, s, i, t):
    """Whether tet t contains the face of tet s opposite slot i."""
    for j in range(4):
        if j != i:
            found = False
            for k in range(4):
                if T[t, k] == T[s, j]:
                    found = True
            if not found:
                return False
    return True


@njit(cache=True)
def reserve(T, N, stamp, conf, free, need):
    """The flat arrays grown (by ``_GROW``) to at least ``need`` rows."""
    if need <= T.shape[0]:
        return T, N, stamp, conf, free
    rows = max(need, int(_GROW * T.shape[0]))
    return (_grow_rows(T, rows), _grow_rows(N, rows), _grow_rows(stamp, rows),
            _grow_rows(conf, rows), _grow_rows(free, rows))


@njit(cache=True)
def new_work():
    """Working buffers of one insertion (cavity, new tets, their slot of the new point, and
    the edge table of :func:`_link_around`), grown by :func:`insert_point` as needed."""
    return (np.empty(64, np.int32), np.empty(64, np.int32), np.empty(64, np.int32),
            np.full(256, -1, np.int64), np.empty(256, np.int64), np.empty(256, np.int64))


@njit(cache=True)
def insert_point(P, G, T, N, stamp, conf, free, nfree, ntet, it, t0, q, work):
    """Bowyer-Watson insertion of point q, whose conflict region contains tet t0, with
    ``it`` a stamp not used before. Returns the (possibly grown) arrays, ``nfree, ntet``, the
    work buffers and the number of new tets (``work[1][:nnew]``)."""
    cav, new, qslot, keys, vals, used = work
    cav, ncav = cavity(P, G, T, N, stamp, conf, it, t0, q, cav)
    nb = _boundary_faces(N, stamp, conf, it, cav, ncav)
    T, N, stamp, conf, free = reserve(T, N, stamp, conf, free, ntet + nb)
    if nb > new.shape[0]:
        new = np.empty(2 * nb, np.int32)
        qslot = np.empty(2 * nb, np.int32)
    if 8 * nb > keys.shape[0]:  # 3 nb / 2 entries, load factor below 1/5
        size = keys.shape[0]
        while size < 8 * nb:
            size *= 2
        keys = np.full(size, -1, np.int64)
        vals = np.empty(size, np.int64)
        used = np.empty(size, np.int64)
    nfree, ntet, nnew = _retriangulate(T, N, stamp, conf, it, cav, ncav, q, free,
                                       nfree, ntet, new, qslot)
    _link_around(T, N, new, qslot, nnew, keys, vals, used)
    return T, N, stamp, conf, free, nfree, ntet, (cav, new, qslot, keys, vals, used), nnew


@njit(cache=True)
def build(P, order):
    """Delaunay tetrahedralisation of the points ``P[order]`` (the other rows of P are not
    inserted; the ghost vertex is ``n = P.shape[0]``).

    Returns ``(T, N, ntet, status, i, j)``: the tets ``T[:ntet]`` (freed rows have
    ``T[t, 0] = -1``, ghosts ``T[t, 3] = n``) and their neighbours, and a status: OK,
    DUPLICATE (point i coincides with point j) or FLAT (all points coplanar).
    """
    n = P.shape[0]
    G = n
    cap = _TETS_PER_POINT * order.shape[0] + 64
    T = np.full((cap, 4), -1, np.int32)
    N = np.full((cap, 4), -1, np.int32)
    stamp = np.zeros(cap, np.int64)
    conf = np.zeros(cap, np.bool_)
    free = np.empty(cap, np.int32)
    k1, k2, k3 = _first_tet(P, order)
    if k1 < 0:
        return T, N, 0, FLAT, -1, -1
    _init_tets(P, G, T, N, order[0], order[k1], order[k2], order[k3])
    # counts and the start tet as int64s, not literals: the kernels below get the same
    # argument types from every caller and compile once
    ntet, nfree = np.int64(5), np.int64(0)
    skip = np.array([0, k1, k2, k3], np.int64)      # the first tet's
    return insert_all(P, G, T, N, stamp, conf, free, nfree, ntet, order, skip, np.int64(0))


@njit(cache=True)
def insert_all(P, G, T, N, stamp, conf, free, nfree, ntet, order, skip, last):
    """Insert the points ``order`` (but not those at the positions ``skip`` of it) one by
    one, each located from the last one's new tets (from tet ``last`` first); the stamps
    must be fresh. Returns ``(T, N, ntet, status, i, j)`` as :func:`build`."""
    work = new_work()
    seed = np.int64(12345)  # not a literal: one specialization of locate
    for k in range(order.shape[0]):
        skipped = False
        for j in range(skip.shape[0]):
            skipped = skipped or skip[j] == k
        if skipped:
            continue
        q = order[k]
        t0, seed = locate(P, G, T, N, last, q, seed)
        if T[t0, 3] != G:
            v = coincident(P, T, t0, q)
            if v >= 0:
                return T, N, ntet, DUPLICATE, q, v
        T, N, stamp, conf, free, nfree, ntet, work, nnew = insert_point(
            P, G, T, N, stamp, conf, free, nfree, ntet, k + 1, t0, q, work)
        last = work[1][0]
    return T, N, ntet, OK, -1, -1


@njit(cache=True)
def add_points(P, T, N, ntet, G0, order):
    """The tetrahedralisation ``T, N, ntet`` of the points ``P[:G0]`` (ghost vertex ``G0``)
    with the points ``P[order]`` inserted as well (the ghost vertex renumbered to
    ``G = P.shape[0]``; the arrays must have spare rows, :func:`reserve` grows them).
    Returns ``(T, N, ntet, status, i, j)`` as :func:`build`: DUPLICATE when point i
    coincides with point j. By the symbolic perturbation the result is the one a build of
    all the points gives."""
    G = P.shape[0]
    last = np.int64(-1)  # not a literal: insert_all compiles once (as for build)
    for t in range(ntet):
        if T[t, 0] >= 0:
            if last < 0:
                last = t
            if T[t, 3] == G0:
                T[t, 3] = G
    free, nfree = free_rows(T, ntet)
    stamp = np.zeros(T.shape[0], np.int64)
    conf = np.zeros(T.shape[0], np.bool_)
    return insert_all(P, G, T, N, stamp, conf, free, nfree, ntet, order,
                      np.empty(0, np.int64), last)


@njit(cache=True)
def free_rows(T, ntet):
    """The free list of the flat arrays (room for every row) holding the freed rows below
    ``ntet`` (``T[t, 0] < 0``), and how many there are."""
    free = np.empty(T.shape[0], np.int32)
    nfree = 0
    for t in range(ntet):
        if T[t, 0] < 0:
            free[nfree] = t
            nfree += 1
    return free, nfree
