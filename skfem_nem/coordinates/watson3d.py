"""Watson's signed decomposition of 3D Sibson coordinates: the records of the tetrahedra and
whole rows of coordinates at points inside tetrahedra or on their faces.

Why: the Box 1 coordinates (:mod:`~skfem_nem.coordinates.lasserre`) build each query's
second-order Voronoi cells face by face, which their exact derivatives need. Values alone
have a closed form per conflict tetrahedron (the module docstring of
:mod:`~skfem_nem.coordinates.interp_watson3d` derives it): for a query x in the circumsphere
of T, with D its power and e_k = 6 |T| lambda_k (x) (six times the volume of T with v_k moved
to x), vertex v_i of T gets the term ``D^3 S^2 e_i / (e_0 e_1 e_2 e_3)`` (S = 6 |T|), and
``phi_i(x)`` is v_i's sum over the conflict tetrahedra over the sum of all terms. The smoothed
3D basis (:mod:`~skfem_nem.basis.smoothing`) asks for the coordinates at tetrahedra's
centroids and at the centroids of their faces; there a query lies on a face F, the terms of
the two tetrahedra at F are infinite, and their sum is its limit, taken here in closed form.

The limit on a face
    Let F = (a, b, c) be shared by T1 = (F, p) and T2 = (F, q), u the unit normal of F
    towards p and |n_F| twice F's area. p's term in T1 (and q's in T2) is finite:
    ``D^3 S1^2 / (e_a e_b e_c)``. For a vertex a of F the two terms are ``g / (|n_F| h)`` and
    ``-g / (|n_F| h)`` at the distance h from F, with ``g = D^3 / (lambda_b lambda_c)`` equal
    in both on F (the spheres meet in F's circle); their sum tends to the derivative along u:

        (g / |n_F|) [6 u.(o1 - o2) / D - sum_{v = b, c} (u.n_v^1 / e_v^1 - u.n_v^2 / e_v^2)],

    where o_j is T_j's circumcentre and n_v^j the normal of T_j's face opposite v (pointing
    to v), e_v^j its volume with x. A query on a hull face, or one whose terms cancel too much
    (``DEN_MIN``), is flagged: the caller gives it to the Box 1 coordinates.
"""
from __future__ import annotations

import weakref

import numba
import numpy as np
from numba import njit, prange

from ..geometry.nodesets import morton_order
from ..geometry.walls3d import WALL, through
from ..jit import sort_with

__all__ = ["RECORD_VALUES", "DEN_MIN", "ENTRY_MIN", "HULL_LAMBDA", "CAVITY_SLACK", "CAVITY_CAP",
           "conflict_tetrahedra", "face_volume", "power_and_volumes", "power_and_volumes_at",
           "records",
           "rows_3d", "TetrahedraRecords", "FLAT_SHAPE", "walk",
           "coordinates_3d", "records_of"]

# A query is flagged when the sum of its terms (x's new cell) is at most DEN_MIN times the
# sum of their magnitudes (per tetrahedron, and per part of the limit on a face): it would lose
# about log10(magnitudes / sum) digits to the cancellation. At the centroids of the 66,501
# tetrahedra of 10,000 random nodes and of their faces, 1% is flagged and the others agree with
# the Box 1 coordinates to 4e-12 (at 1e-3: 0.2% flagged, 4e-12 too, but 2e-12 at the centroids
# against 9e-13).
DEN_MIN = 1e-2
# ... and when one node's entry is at most ENTRY_MIN times the magnitudes of its own terms
# (relative to the sum): two cavity tetrahedra sharing a face whose plane passes near the
# query carry large terms of opposite signs, ~1/lambda, which cancel in the entries of that
# face's nodes but not in the sum. On a drawn set of 130 nodes (a face centroid; hypothesis
# found it) an entry was off by 1.1e-11 without this test, 2.4e-13 with it; the flagged share
# grows by 0.02-0.05% (6% at 1e-1)
ENTRY_MIN = 1e-2
# a query whose barycentric coordinate opposite a hull face of its cavity is at most this is
# left to the Box 1 coordinates, which apply the package's hull rule (HULL_TOLERANCE)
HULL_LAMBDA = 1e-8
# the cavity is traversed on through tetrahedra whose D > -CAVITY_SLACK R^2: one whose
# sphere holds x by less than D's round-off must not cut off the tetrahedra beyond it
CAVITY_SLACK = 1e-12
# tetrahedra of a cavity (random queries among random nodes: ~25), entries of a row; past
# them the query is flagged
CAVITY_CAP = 4096
ROW_CAP = 96
# steps of a walk; past them the query is flagged
WALK_STEPS = 1 << 16
# queries per pass of the row kernel (its padded rows take ROW_CAP * 16 bytes a query)
ROW_CHUNK = 1 << 15


#: columns of a tetrahedron's record before its vertex values: v0 (3), o - v0 (3), and for
#: each face k (opposite v_k) its first vertex a_k (3) and normal n_k (3); S (1); v1, v2,
#: v3 (9)
RECORD_VALUES = 40


@njit(cache=True, inline="always", error_model="numpy")
def face_volume(R, t, k, x, y, z):
    """e_k = n_k . (x - a_k): 6 times the signed volume of tetrahedron t with v_k moved to
    (x, y, z), S lambda_k."""
    c = 6 + 6 * k
    return (R[t, c + 3] * (x - R[t, c]) + R[t, c + 4] * (y - R[t, c + 1])
            + R[t, c + 5] * (z - R[t, c + 2]))


def records(points, simplices, values):
    """(ntet, RECORD_VALUES + 4 K): the geometry of each tetrahedron (module docstring)
    followed by its four vertices' values (n, K)."""
    P = np.ascontiguousarray(points, dtype=np.float64)
    T = np.ascontiguousarray(simplices, dtype=np.int64)
    R = np.empty((T.shape[0], RECORD_VALUES + 4 * values.shape[1]))
    _records(P, T, values, R)
    return R


@njit(cache=True, parallel=True, error_model="numpy")
def _records(P, T, values, R):
    """Fills the records R (see :func:`records`). A face's point and normal come from its
    vertices in ascending node order, so that the two tetrahedra at a face compute the
    same e_k to the bit (with opposite signs) and their large terms cancel exactly."""
    K = values.shape[1]
    for t in prange(T.shape[0]):
        for k in range(4):
            i0, i1, i2 = (1, 0, 0, 0)[k], (2, 2, 1, 1)[k], (3, 3, 3, 2)[k]
            a, b, c = T[t, i0], T[t, i1], T[t, i2]
            if a > b:
                a, b = b, a
            if b > c:
                b, c = c, b
            if a > b:
                a, b = b, a
            ux, uy, uz = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
            wx, wy, wz = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
            nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
            v = T[t, k]
            if nx * (P[v, 0] - P[a, 0]) + ny * (P[v, 1] - P[a, 1]) + nz * (P[v, 2] - P[a, 2]) < 0:
                nx, ny, nz = -nx, -ny, -nz
            col = 6 + 6 * k
            R[t, col], R[t, col + 1], R[t, col + 2] = P[a, 0], P[a, 1], P[a, 2]
            R[t, col + 3], R[t, col + 4], R[t, col + 5] = nx, ny, nz
        v0 = T[t, 0]
        for d in range(3):
            R[t, d] = P[v0, d]
            for k in range(1, 4):
                R[t, 28 + 3 * k + d] = P[T[t, k], d]
        S = face_volume(R, t, 0, P[v0, 0], P[v0, 1], P[v0, 2])     # e_0 at v0: 6 |T|
        R[t, 30] = S
        # o - v0 = sum_k |v_k - v0|^2 n_k / (2 S): the normals of the faces at v0 (opposite
        # v_k) point towards v_k, as the cofactors of the edges from v0 do
        ox = oy = oz = 0.0
        for k in range(1, 4):
            vk = T[t, k]
            e2 = ((P[vk, 0] - P[v0, 0]) ** 2 + (P[vk, 1] - P[v0, 1]) ** 2
                  + (P[vk, 2] - P[v0, 2]) ** 2)
            ox += e2 * R[t, 9 + 6 * k]
            oy += e2 * R[t, 10 + 6 * k]
            oz += e2 * R[t, 11 + 6 * k]
        R[t, 3], R[t, 4], R[t, 5] = ox / (2.0 * S), oy / (2.0 * S), oz / (2.0 * S)
        for j in range(4):
            for c in range(K):
                R[t, RECORD_VALUES + j * K + c] = values[T[t, j], c]


@njit(cache=True, inline="always", error_model="numpy")
def power_and_volumes(R, t, x, y, z):
    """``(D, e0, e1, e2, e3)``: the power D = R^2 - |x - o|^2 of (x, y, z) in tetrahedron t's
    sphere and S times its barycentrics e_k. D is ``sum_k e_k |v_k - x|^2 / sum_k e_k`` (the
    barycentric mean of the squared distances to the vertices), accurate to a few ulps of
    |v - x|^2 where the query is near the tetrahedron, however flat: from the circumcentre,
    whose error grows as the tetrahedron flattens, D lost up to 9 digits in the spheres of
    slivers."""
    return power_and_volumes_at(R, t, x, y, z, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True, inline="always", error_model="numpy")
def power_and_volumes_at(R, t, x, y, z, c, nx, ny, nz):
    """:func:`power_and_volumes` at the point ``(x, y, z) - c n``, to first order in c (the
    second order, c^2 |n|^2, is kept too): a query on a face F is the nearest point of the
    plane of F, a distance ``c |n|`` (a few ulps) from its floating-point coordinates, and
    every term is taken there, where the limit of the two tetrahedra at F is (near slivers
    the terms vary a hundred thousand times faster than the coordinates, so mixing the two
    points lost 6e-11 in the coordinates)."""
    e0 = face_volume(R, t, 0, x, y, z) - c * _along(R, t, 0, nx, ny, nz)
    e1 = face_volume(R, t, 1, x, y, z) - c * _along(R, t, 1, nx, ny, nz)
    e2 = face_volume(R, t, 2, x, y, z) - c * _along(R, t, 2, nx, ny, nz)
    e3 = face_volume(R, t, 3, x, y, z) - c * _along(R, t, 3, nx, ny, nz)
    cn2 = c * c * (nx * nx + ny * ny + nz * nz)
    L0 = _shifted_square(R[t, 0] - x, R[t, 1] - y, R[t, 2] - z, c, nx, ny, nz, cn2)
    L1 = _shifted_square(R[t, 31] - x, R[t, 32] - y, R[t, 33] - z, c, nx, ny, nz, cn2)
    L2 = _shifted_square(R[t, 34] - x, R[t, 35] - y, R[t, 36] - z, c, nx, ny, nz, cn2)
    L3 = _shifted_square(R[t, 37] - x, R[t, 38] - y, R[t, 39] - z, c, nx, ny, nz, cn2)
    D = (e0 * L0 + e1 * L1 + e2 * L2 + e3 * L3) / (e0 + e1 + e2 + e3)
    return (D, e0, e1, e2, e3)


@njit(cache=True, inline="always")
def _shifted_square(ax, ay, az, c, nx, ny, nz, cn2):
    """|a + c n|^2 for a = v - x: the squared distance from v to x - c n."""
    return ax * ax + ay * ay + az * az + 2.0 * c * (ax * nx + ay * ny + az * nz) + cn2


@njit(cache=True, inline="always")
def _along(R, t, k, ux, uy, uz):
    """u . n_k: the normal of tetrahedron t's face opposite slot k along (ux, uy, uz)."""
    c = 9 + 6 * k
    return ux * R[t, c] + uy * R[t, c + 1] + uz * R[t, c + 2]




@njit(cache=True, error_model="numpy")
def conflict_tetrahedra(R, NB, x, y, z, t0, sc, stamp, m, tets, E):
    """The tetrahedra whose sphere holds the query ``(x, y, z) - c n`` (``sc = (c, nx, ny,
    nz)``; zeros: the point itself), reached through faces from t0, which holds it: their
    number k, ``tets[:k]`` and ``E[:k] = (D, e0, e1, e2, e3)``; -1 if the traversal needs
    more room than ``tets`` has. ``stamp[t] == m`` marks the tetrahedra seen. (The output
    overwrites the front of the queue, which is already read.)"""
    stamp[t0] = m
    tets[0] = t0
    head, tail, k = 0, 1, 0
    while head < tail:
        t = tets[head]
        head += 1
        # the sphere test first from the circumcentre (the record's first cache line; its
        # error, up to ~1e-9 of D in the spheres of slivers, decides only where the terms
        # vanish as D^3), then the accurate D and volumes
        ax, ay, az = x - R[t, 0], y - R[t, 1], z - R[t, 2]
        ox, oy, oz = R[t, 3], R[t, 4], R[t, 5]
        if not ax * (2.0 * ox - ax) + ay * (2.0 * oy - ay) + az * (2.0 * oz - az) > \
                -CAVITY_SLACK * (ox * ox + oy * oy + oz * oz):
            continue
        D, e0, e1, e2, e3 = power_and_volumes_at(R, t, x, y, z, sc[0], sc[1], sc[2], sc[3])
        for j in range(4):
            nb = NB[t, j]
            if nb >= 0 and stamp[nb] != m:
                if tail == tets.shape[0]:
                    return -1
                stamp[nb] = m
                tets[tail] = nb
                tail += 1
        if D > 0:
            tets[k] = t
            E[k, 0], E[k, 1], E[k, 2], E[k, 3], E[k, 4] = D, e0, e1, e2, e3
            k += 1
    return k


@njit(cache=True, error_model="numpy")
def walk(R, NB, x, y, z, t):
    """The tetrahedron that holds (x, y, z), walking from t across the face of the most
    negative barycentric; -1 outside the hull, -2 at a node (on the sphere of the tetrahedron
    that holds it), -3 too long a walk. (D far from a tetrahedron is too inaccurate to stop
    at the first sphere that holds the query.)"""
    for _ in range(WALK_STEPS):
        D, l0, l1, l2, l3 = power_and_volumes(R, t, x, y, z)
        k, lo = 0, l0
        if l1 < lo:
            k, lo = 1, l1
        if l2 < lo:
            k, lo = 2, l2
        if l3 < lo:
            k, lo = 3, l3
        if lo >= 0:
            return t if D > 0 else -2
        t = through(NB[t, k])           # (walks cross walls)
        if t < 0:
            return -1
    return -3


@njit(cache=True, inline="always")
def _add(node, term, size, mark, m, where, oi, ov, oa, cnt):
    """Adds ``term`` to node's entry of the row (a new entry if the node has none yet) and
    its magnitude ``size`` to the entry's in ``oa``; returns the row's length, -1 if it would
    exceed the row's capacity."""
    if mark[node] == m:
        ov[where[node]] += term
        oa[where[node]] += size
        return cnt
    if cnt == oi.shape[0]:
        return -1
    mark[node] = m
    where[node] = cnt
    oi[cnt] = node
    ov[cnt] = term
    oa[cnt] = size
    return cnt + 1


@njit(cache=True, error_model="numpy")
def _pair(R, T, NB, t1, k1, x, y, z, sc, mark, m, where, oi, ov, oa, cnt):
    """The terms of the two tetrahedra at the face opposite slot k1 of t1, on which the
    query lies (the limit of the module docstring). Returns ``(cnt, sum of the terms, sum of
    the magnitudes of their parts)`` (the bracket of a face vertex's term cancels within
    itself near degenerate pairs), cnt -1 where the row is full."""
    t2 = NB[t1, k1]
    k2 = 0
    while NB[t2, k2] != t1:
        k2 += 1
    c, nx, ny, nz = sc
    D, a0, a1, a2, a3 = power_and_volumes_at(R, t1, x, y, z, c, nx, ny, nz)
    e1 = (a0, a1, a2, a3)
    D2, b0, b1, b2, b3 = power_and_volumes_at(R, t2, x, y, z, c, nx, ny, nz)
    e2 = (b0, b1, b2, b3)
    S1, S2 = R[t1, 30], R[t2, 30]
    c = 9 + 6 * k1
    nF = np.sqrt(R[t1, c] ** 2 + R[t1, c + 1] ** 2 + R[t1, c + 2] ** 2)
    ux, uy, uz = R[t1, c] / nF, R[t1, c + 1] / nF, R[t1, c + 2] / nF
    # 6 u.(o1 - o2) / D, the circumcentres from their records (o = v0 + (o - v0))
    do = (ux * (R[t1, 0] + R[t1, 3] - R[t2, 0] - R[t2, 3])
          + uy * (R[t1, 1] + R[t1, 4] - R[t2, 1] - R[t2, 4])
          + uz * (R[t1, 2] + R[t1, 5] - R[t2, 2] - R[t2, 5]))
    total = mag = 0.0
    for j in range(2):
        t, k, e, S, Dj = (t1, k1, e1, S1, D) if j == 0 else (t2, k2, e2, S2, D2)
        prod = 1.0
        for i in range(4):
            if i != k:
                prod *= e[i]
        term = Dj * Dj * Dj * S * S / prod          # the apex's term
        cnt = _add(T[t, k], term, abs(term), mark, m, where, oi, ov, oa, cnt)
        total += term
        mag += abs(term)
        if cnt < 0:
            return -1, 0.0, 0.0
    for i in range(4):
        if i == k1:
            continue
        v = T[t1, i]
        bracket = 6.0 * do / D
        parts = abs(bracket)
        g = D * D * D * S1 * S1
        for i1 in range(4):
            if i1 == k1 or i1 == i:
                continue
            w = T[t1, i1]
            i2 = 0
            while T[t2, i2] != w:
                i2 += 1
            g /= e1[i1]
            b1 = _along(R, t1, i1, ux, uy, uz) / e1[i1]
            b2 = _along(R, t2, i2, ux, uy, uz) / e2[i2]
            bracket += b2 - b1
            parts += abs(b1) + abs(b2)
        term = g * bracket / nF
        cnt = _add(v, term, abs(g * parts / nF), mark, m, where, oi, ov, oa, cnt)
        total += term
        mag += abs(g * parts / nF)
        if cnt < 0:
            return -1, 0.0, 0.0
    return cnt, total, mag




@njit(cache=True, error_model="numpy")
def _wall_row(R, T, t, k, x, y, z, oi, ov):
    """The row of a query on the wall face of tetrahedron t opposite slot k: the limit of
    the terms from either side, the face's barycentric coordinates (t's term divides by
    its volume with x in place of the vertex off the face, which vanishes there)."""
    D, e0, e1, e2, e3 = power_and_volumes(R, t, x, y, z)
    e = (e0, e1, e2, e3)
    total = 0.0
    for i in range(4):
        if i != k:
            total += max(e[i], 0.0)
    c = 0
    for i in range(4):
        if i != k:
            oi[c] = T[t, i]
            ov[c] = max(e[i], 0.0) / total
            c += 1
    return c


@njit(cache=True, error_model="numpy")
def _row(R, T, NB, x, y, z, t0, k0, stamp, m, tets, E, mark, where, oi, ov, oa):
    """The row of coordinates of the query (x, y, z) in tetrahedron t0 (on its face opposite
    slot k0 if k0 >= 0): its length, entries unnormalised in ``oi``, ``ov``; -1 if flagged."""
    if t0 < 0:
        return -1                      # not placed by a walk
    t2 = NB[t0, k0] if k0 >= 0 else -1
    if t2 <= WALL:
        return _wall_row(R, T, t0, k0, x, y, z, oi, ov)
    if k0 >= 0 and t2 < 0:
        return -1                      # on the hull
    sc = (0.0, 0.0, 0.0, 0.0)          # the shift to the plane of the face (c, n)
    if k0 >= 0:
        col = 9 + 6 * k0
        n2 = R[t0, col] ** 2 + R[t0, col + 1] ** 2 + R[t0, col + 2] ** 2
        sc = (face_volume(R, t0, k0, x, y, z) / n2, R[t0, col], R[t0, col + 1],
              R[t0, col + 2])
    nc = conflict_tetrahedra(R, NB, x, y, z, t0, sc, stamp, m, tets, E)
    if nc < 0:
        return -1
    # np.int64: a plain 0 is typed Literal[int](0) on numba's first pass over the loop,
    # which would compile _pair a second time
    cnt, total, mag = np.int64(0), 0.0, 0.0
    for c in range(nc):
        t = tets[c]
        if k0 >= 0 and (t == t0 or t == t2):
            continue
        S = R[t, 30]
        W = E[c, 0] ** 3 * S * S / (E[c, 1] * E[c, 2] * E[c, 3] * E[c, 4])
        s = 0.0
        for k in range(4):
            if NB[t, k] <= WALL and abs(E[c, 1 + k]) <= HULL_LAMBDA * S:
                # on (or next to) a wall face of its own tetrahedron: that face's limit;
                # next to the plane of another wall face (beside a fold of the wall),
                # where the terms of the two faces cancel: flagged
                if t == t0:
                    return _wall_row(R, T, t0, k, x, y, z, oi, ov)
                return -1
            if -1 <= NB[t, k] < 0 and E[c, 1 + k] <= HULL_LAMBDA * S:
                return -1
            term = W * E[c, 1 + k]
            cnt = _add(T[t, k], term, abs(term), mark, m, where, oi, ov, oa, cnt)
            if cnt < 0:
                return -1
            s += W * E[c, 1 + k]
        total += s
        mag += abs(s)
    if k0 >= 0:
        cnt, s, parts = _pair(R, T, NB, t0, k0, x, y, z, sc, mark, m, where, oi, ov, oa, cnt)
        if cnt < 0:
            return -1
        total += s
        mag += parts
    if not abs(total) > DEN_MIN * mag:
        return -1
    for j in range(cnt):
        if not abs(total) > ENTRY_MIN * oa[j]:
            return -1
    for j in range(cnt):
        ov[j] /= total
    return cnt


@njit(cache=True, parallel=True, error_model="numpy")
def _rows(R, T, NB, n, Q, start, slot, nblocks, out_i, out_v, count):
    """Rows of the queries Q (m, 3): query j in tetrahedron start[j], on its face opposite
    slot[j] if slot[j] >= 0; ``count[j]`` entries at ``out_i[j]``, ``out_v[j]`` sorted by
    node, -1 where flagged."""
    m = Q.shape[0]
    for b in prange(nblocks):
        stamp = np.full(R.shape[0], -1, np.int64)
        tets = np.empty(CAVITY_CAP, np.int64)
        E = np.empty((CAVITY_CAP, 5))
        mark = np.full(n, -1, np.int64)
        where = np.empty(n, np.int64)
        oa = np.empty(out_i.shape[1])
        for j in range(b * m // nblocks, (b + 1) * m // nblocks):
            c = _row(R, T, NB, Q[j, 0], Q[j, 1], Q[j, 2], start[j], slot[j], stamp, j, tets, E,
                     mark, where, out_i[j], out_v[j], oa)
            if c > 0:
                sort_with(out_i[j], out_v[j], c)
            count[j] = c


def rows_3d(R, T, NB, n, q, start, slot):
    """Sibson's coordinates at the points q (m, 3) of the tetrahedra ``start`` (m,) (on their
    faces opposite the vertex slots ``slot``, -1: inside), on the Delaunay tetrahedra T (nt,
    4) of n nodes with neighbours NB and records R: ``(indptr, indices, values, flagged)``, the
    flagged queries' rows empty. The queries are taken in Z-order (consecutive queries
    traverse the same tetrahedra: at 100,000 nodes, in the order of a mesh's faces, the
    records came from memory at random) and their rows put back in order."""
    m = q.shape[0]
    order = morton_order(q) if m > 1 else np.zeros(m, np.int64)
    q = np.ascontiguousarray(q[order], dtype=np.float64)
    start = np.asarray(start, np.int64)[order]
    slot = np.asarray(slot, np.int64)[order]
    count = np.empty(m, np.int64)
    chunks = []
    out_i = np.empty((min(m, ROW_CHUNK), ROW_CAP), np.int64)
    out_v = np.empty((min(m, ROW_CHUNK), ROW_CAP))
    for c0 in range(0, m, ROW_CHUNK):
        c1 = min(m, c0 + ROW_CHUNK)
        nblocks = max(1, min((c1 - c0) // 64, 4 * numba.get_num_threads()))
        _rows(R, T, NB, n, q[c0:c1], start[c0:c1], slot[c0:c1], nblocks, out_i, out_v,
              count[c0:c1])
        cptr = np.zeros(c1 - c0 + 1, np.int64)
        np.cumsum(np.maximum(count[c0:c1], 0), out=cptr[1:])
        chunks.append((c0, cptr, np.empty(cptr[-1], np.int64), np.empty(cptr[-1])))
        _compact(out_i, out_v, cptr, chunks[-1][2], chunks[-1][3])
    flagged = order[count < 0]
    count[count < 0] = 0
    back = np.empty(m, np.int64)
    back[order] = np.arange(m)
    ptr = np.zeros(m + 1, np.int64)
    np.cumsum(count[back], out=ptr[1:])
    I, V = np.empty(ptr[-1], np.int64), np.empty(ptr[-1])
    for c0, cptr, idx, val in chunks:
        _unsort(idx, val, cptr, order[c0:c0 + cptr.shape[0] - 1], ptr, I, V)
    return ptr, I, V, np.sort(flagged)


@njit(cache=True, parallel=True)
def _splice(wptr, widx, wval, flagged, fptr, fidx, fval, ptr, idx, val):
    """Rows of (wptr, widx, wval) with the flagged ones (empty there) replaced by the rows
    of (fptr, fidx, fval), in order, into (ptr, idx, val)."""
    for r in prange(wptr.shape[0] - 1):
        d = ptr[r]
        for k in range(wptr[r], wptr[r + 1]):
            idx[d + k - wptr[r]] = widx[k]
            val[d + k - wptr[r]] = wval[k]
    for j in prange(flagged.shape[0]):
        d = ptr[flagged[j]]
        for k in range(fptr[j], fptr[j + 1]):
            idx[d + k - fptr[j]] = fidx[k]
            val[d + k - fptr[j]] = fval[k]


@njit(cache=True, parallel=True)
def _unsort(idx, val, sptr, order, ptr, I, V):
    """Row s of (sptr, idx, val) is row order[s] of (ptr, I, V)."""
    for s in prange(order.shape[0]):
        d = ptr[order[s]]
        for k in range(sptr[s + 1] - sptr[s]):
            I[d + k] = idx[sptr[s] + k]
            V[d + k] = val[sptr[s] + k]


@njit(cache=True, parallel=True)
def _compact(out_i, out_v, cptr, idx, val):
    """The padded rows' entries, row after row (row r's ``cptr[r + 1] - cptr[r]`` first)."""
    for r in prange(cptr.shape[0] - 1):
        for k in range(cptr[r + 1] - cptr[r]):
            idx[cptr[r] + k] = out_i[r, k]
            val[cptr[r] + k] = out_v[r, k]


@njit(cache=True)
def _flat(P, T, S, shape):
    """How many tetrahedra have ``S < shape * (longest edge)^3``."""
    bad = 0
    for t in range(T.shape[0]):
        longest = 0.0
        for i in range(4):
            for j in range(i + 1, 4):
                e = 0.0
                for d in range(3):
                    e += (P[T[t, i], d] - P[T[t, j], d]) ** 2
                longest = max(longest, e)
        if not abs(S[t]) > shape * longest ** 1.5:
            bad += 1
    return bad


# a tetrahedron flatter than this (6 |T| / longest edge^3) leaves the whole mesh to the Box 1
# coordinates: Watson's terms divide by volumes (Qhull gives flat tetrahedra on co-spherical
# nodes; the package's own tetrahedralisation never does; a regular tetrahedron has 0.71)
FLAT_SHAPE = 1e-9


class TetrahedraRecords:
    """The state of Watson's decomposition on a Delaunay tetrahedralisation: the tetrahedra T
    (nt, 4) of the nodes p (n, 3), their neighbours ``NB`` across the face opposite each
    vertex slot (the triangulation's, walls marked as in :mod:`~skfem_nem.geometry.walls3d`,
    or the mesh's) and records; ``usable`` is False where a tetrahedron is flat
    (``FLAT_SHAPE``)."""

    def __init__(self, p, T, NB):
        self.p = np.ascontiguousarray(p, dtype=np.float64)
        self.T = np.ascontiguousarray(T, dtype=np.int64)
        self.NB = np.ascontiguousarray(NB, np.int64)
        self.R = records(self.p, self.T, np.empty((self.p.shape[0], 0)))
        self.usable = _flat(self.p, self.T, self.R[:, 30], FLAT_SHAPE) == 0
        self.source = None          # the neighbour array these were made from (records_of)

    def describes(self, p, T) -> bool:
        """Are these the records of the nodes p and tetrahedra T (a mesh whose nodes moved
        in place has other records)?"""
        return (p.shape == self.p.shape and T.shape == self.T.shape
                and np.array_equal(p, self.p) and np.array_equal(T, self.T))

    def coordinates(self, q, start, slot, fallback):
        """CSR (m, n) of Sibson's coordinates at the points q (m, 3) in the tetrahedra
        ``start`` (on their faces opposite the slots ``slot``, -1: inside); the queries
        Watson's decomposition flags get ``fallback(points)``'s rows (a CSR of as many
        rows)."""
        import scipy.sparse as sp
        m, n = q.shape[0], self.p.shape[0]
        wptr, widx, wval, flagged = rows_3d(self.R, self.T, self.NB, n, q, start, slot)
        if not flagged.size:
            return sp.csr_matrix((wval, widx, wptr), shape=(m, n))
        F = fallback(q[flagged]).tocsr()
        F.sort_indices()
        count = np.diff(wptr)
        count[flagged] = np.diff(F.indptr)
        ptr = np.zeros(m + 1, np.int64)
        np.cumsum(count, out=ptr[1:])
        idx = np.empty(ptr[-1], np.int64)
        val = np.empty(ptr[-1])
        _splice(wptr, widx, wval, flagged, F.indptr.astype(np.int64),
                F.indices.astype(np.int64), F.data, ptr, idx, val)
        return sp.csr_matrix((val, idx, ptr), shape=(m, n))


@njit(cache=True, parallel=True, error_model="numpy")
def _locate(R, NB, Q, order, nblocks, out):
    """``out[j]``: the tetrahedron that holds query j (:func:`walk`; negative where the walk
    fails), the queries taken in ``order`` in ``nblocks`` blocks, each walk from the last."""
    m = order.shape[0]
    for b in prange(nblocks):
        t = np.int64(0)  # not a literal 0: one specialization of walk
        for s in range(b * m // nblocks, (b + 1) * m // nblocks):
            j = order[s]
            t1 = walk(R, NB, Q[j, 0], Q[j, 1], Q[j, 2], t)
            out[j] = t1
            if t1 >= 0:
                t = t1


_RECORDS = weakref.WeakKeyDictionary()


def records_of(tri) -> TetrahedraRecords:
    """The :class:`TetrahedraRecords` of the package's
    :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` ``tri``, made once and kept while
    ``tri`` lives: one set of records a tetrahedralisation, whoever asks (some 40 numbers a
    tetrahedron, 210 MB at 100,000 nodes), its walls (``walled_neighbors``) included."""
    rec = _RECORDS.get(tri)
    nb = getattr(tri, "walled_neighbors", None)
    nb = tri.neighbors if nb is None else nb
    if rec is None or rec.source is not nb:         # (none yet, or walls set since)
        rec = _RECORDS[tri] = TetrahedraRecords(tri.points, tri.simplices, nb)
        rec.source = nb
    return rec


def coordinates_3d(tri, q, fallback):
    """CSR (m, n) of Sibson's coordinates at the points q (m, 3) on the package's
    :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` ``tri`` by Watson's decomposition
    (records kept while ``tri`` lives); points the walk does not place inside a
    tetrahedron (outside the hull, at a node) and flagged points get ``fallback(points)``'s
    rows."""
    rec = records_of(tri)
    q = np.ascontiguousarray(q, dtype=np.float64)
    start = np.empty(q.shape[0], np.int64)
    if q.shape[0]:
        nblocks = max(1, min(q.shape[0] // 64, 4 * numba.get_num_threads()))
        _locate(rec.R, rec.NB, q, morton_order(q), nblocks, start)
    return rec.coordinates(q, start, np.full(q.shape[0], -1, np.int64), fallback)
