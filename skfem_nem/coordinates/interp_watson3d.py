"""Sibson's interpolant of a 3D batch of queries by Watson's signed decomposition.

Why: the 3D coordinates (:mod:`~skfem_nem.coordinates.lasserre`, the paper's Box 1) build
each query's second-order Voronoi cells face by face, which its exact derivatives need.
When only the values are wanted, the volume x's new Voronoi cell takes from each node has a
closed form per conflict tetrahedron, and the interpolant is a weighted mean of the
tetrahedra's linear interpolants: no polygon, no stored row of coordinates.

Watson's signed decomposition (1992) in 3D
    For a query x in the circumsphere (centre o, radius R) of the Delaunay tetrahedron
    T = (v0, v1, v2, v3), let D = R^2 - |x - o|^2 > 0 (the power of x), lambda_k(x) the
    barycentric coordinates of x in T and S = 6 |T|. The circumcentre of x with the face
    opposite v_k is ``o - D n_k / (2 n_k . (x - v))`` (n_k the face's normal, v on it), and
    the signed tetrahedron of o with the three such circumcentres of the faces at v_i
    (Watson's term of v_i; the terms telescope to the volume x takes from v_i's cell, as
    the signed triangles do in 2D, :mod:`~skfem_nem.coordinates.interp_scatter`) has the
    volume ``-D^3 S^2 / (48 e_a e_b e_c)``, where e_k = n_k . (x - v) = S lambda_k (the
    three normals at a vertex are the columns of the cofactor matrix, whose determinant is
    S^2). So T's term of v_i is ``lambda_i W_T`` with ``W_T = D^3 / (S lambda_0 lambda_1
    lambda_2 lambda_3)`` (the common -1/48 cancels), the terms of T sum to W_T, and

        phi_i(x) = sum_T lambda_i^T(x) W_T(x) / sum_T W_T(x),
        f(x) = sum_T W_T(x) (sum_k lambda_k^T(x) f_k) / sum_T W_T(x),

    over the tetrahedra whose circumsphere holds x. W_T vanishes as x reaches the sphere
    (D = 0), so the in-sphere test is the sign of D in floating point. A query is walked to
    a tetrahedron of its cavity (a visibility walk that stops at the first tetrahedron whose
    sphere holds it) and the cavity is traversed through faces; the queries go in Morton
    order, each walk starting from the last query's tetrahedron.

Flagged queries
    The terms grow as 1 / lambda_k near the plane of a face and those of the two
    tetrahedra at the face cancel: queries whose terms cancel too much (``DEN_MIN``), with
    a zero divisor (on a face, at a node), near a hull face (``HULL_LAMBDA``), outside the
    hull, or whose walk or cavity exceeds its bounds are returned as flagged; the caller
    gives them to the coordinates.
"""
from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from ..geometry.delaunay3d import Delaunay3D
from ..geometry.nodesets import morton_order

__all__ = ["SibsonWatson3D", "watson_applies"]

# A query is flagged when the sum of its terms (x's new cell) is at most DEN_MIN times the
# sum of their magnitudes (as in 2D, interp_scatter.DEN_MIN): its value then loses about
# log10(magnitudes / sum) digits to the cancellation; random queries have ratios of 2-10.
DEN_MIN = 1e-3
# a query whose barycentric coordinate opposite a hull face of its cavity is at most this is
# left to the coordinates, which apply the package's hull rule (HULL_TOLERANCE) there
HULL_LAMBDA = 1e-8
# the cavity is traversed on through tetrahedra whose D > -CAVITY_SLACK R^2: one whose
# sphere holds x by less than D's round-off must not cut off the tetrahedra beyond it
CAVITY_SLACK = 1e-12
# bounds of a query's work: steps of a walk, tetrahedra of a cavity (random queries among
# random nodes: ~25); past them the query is flagged
WALK_STEPS = 1 << 16
CAVITY_CAP = 4096
# queries per block of the parallel loop: blocks per thread
BLOCKS_PER_THREAD = 4
#: columns of a tetrahedron's record before its vertex values: v0 (3), o - v0 (3), and for
#: each face k (opposite v_k) its first vertex a_k (3) and normal n_k (3); S (1)
RECORD_VALUES = 31


def watson_applies(triangulation) -> bool:
    """True for the package's exact :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D`
    (every tetrahedron a Delaunay one, none flat: the cavity of a query is the tetrahedra
    whose sphere holds it)."""
    return isinstance(triangulation, Delaunay3D)


@njit(cache=True, inline="always", error_model="numpy")
def _face(R, t, k, x, y, z):
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
        S = _face(R, t, 0, P[v0, 0], P[v0, 1], P[v0, 2])     # e_0 at v0: 6 |T|
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
def _local(R, t, x, y, z):
    """``(D, e0, e1, e2, e3)``: the power of (x, y, z) in tetrahedron t's sphere (from v0:
    ``a . (2 (o - v0) - a)``, a = x - v0, error ~ |a| R ulps) and S times its
    barycentrics."""
    ax, ay, az = x - R[t, 0], y - R[t, 1], z - R[t, 2]
    D = ax * (2.0 * R[t, 3] - ax) + ay * (2.0 * R[t, 4] - ay) + az * (2.0 * R[t, 5] - az)
    return (D, _face(R, t, 0, x, y, z), _face(R, t, 1, x, y, z), _face(R, t, 2, x, y, z),
            _face(R, t, 3, x, y, z))


@njit(cache=True, error_model="numpy")
def _walk(R, NB, x, y, z, t):
    """A tetrahedron whose sphere holds (x, y, z), walking from t across the face of the
    most negative barycentric; -1 outside the hull, -2 at a node, -3 too long a walk."""
    for _ in range(WALK_STEPS):
        D, l0, l1, l2, l3 = _local(R, t, x, y, z)
        if D > 0:
            return t
        k, lo = 0, l0
        if l1 < lo:
            k, lo = 1, l1
        if l2 < lo:
            k, lo = 2, l2
        if l3 < lo:
            k, lo = 3, l3
        if lo >= 0:
            return -2      # inside t, on its sphere: at a vertex
        t = NB[t, k]
        if t < 0:
            return -1
    return -3


@njit(cache=True, error_model="numpy")
def _cavity(R, NB, x, y, z, t0, stamp, mark, stack, acc):
    """Accumulates ``acc = (sum_T W_T f_T(x) (K), sum W_T, sum |W_T|)`` over the cavity of
    (x, y, z) reached from t0 (``stamp[t] == mark``: visited); False if the query is to be
    flagged (near a hull face, too large a cavity)."""
    K = acc.shape[0] - 2
    acc[:] = 0.0
    stamp[t0] = mark
    stack[0] = t0
    top = 1
    while top > 0:
        top -= 1
        t = stack[top]
        D, l0, l1, l2, l3 = _local(R, t, x, y, z)
        r2 = R[t, 3] * R[t, 3] + R[t, 4] * R[t, 4] + R[t, 5] * R[t, 5]
        if not D > -CAVITY_SLACK * r2:
            continue
        if D > 0:
            for k in range(4):
                if NB[t, k] < 0 and (l0, l1, l2, l3)[k] <= HULL_LAMBDA * R[t, 30]:
                    return False
            S = R[t, 30]
            W = D * D * D * S * S / (l0 * l1 * l2 * l3)   # times e_i: the term of v_i
            v = RECORD_VALUES
            for c in range(K):
                acc[c] += W * (l0 * R[t, v + c] + l1 * R[t, v + K + c]
                               + l2 * R[t, v + 2 * K + c] + l3 * R[t, v + 3 * K + c])
            w = W * (l0 + l1 + l2 + l3)
            acc[K] += w
            acc[K + 1] += abs(w)
        for k in range(4):
            nb = NB[t, k]
            if nb >= 0 and stamp[nb] != mark:
                if top == stack.shape[0]:
                    return False
                stamp[nb] = mark
                stack[top] = nb
                top += 1
    return True


@njit(cache=True, parallel=True, error_model="numpy")
def _queries(R, NB, Q, order, nblocks, out, bad):
    """Values ``out`` (m, K) of the queries Q (m, 3), taken in ``order`` in ``nblocks``
    blocks in parallel; ``bad[j]`` where query j is flagged (its row NaN)."""
    m = order.shape[0]
    K = out.shape[1]
    for b in prange(nblocks):
        stamp = np.full(R.shape[0], -1, np.int64)
        stack = np.empty(CAVITY_CAP, np.int64)
        acc = np.empty(K + 2)
        t = 0
        for s in range(b * m // nblocks, (b + 1) * m // nblocks):
            j = order[s]
            x, y, z = Q[j, 0], Q[j, 1], Q[j, 2]
            t1 = _walk(R, NB, x, y, z, t)
            ok = t1 >= 0 and _cavity(R, NB, x, y, z, t1, stamp, s, stack, acc)
            if t1 >= 0:
                t = t1
            ok = ok and abs(acc[K]) > DEN_MIN * acc[K + 1]
            bad[j] = not ok
            for c in range(K):
                out[j, c] = acc[c] / acc[K] if ok else np.nan


class SibsonWatson3D:
    """Sibson's interpolant of ``values`` (n, K), real or complex, on a
    :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` (see :func:`watson_applies`),
    evaluated by Watson's decomposition (module docstring)."""

    def __init__(self, triangulation, values):
        self.K = values.shape[1]
        self.complex = np.iscomplexobj(values)
        V = np.c_[values.real, values.imag] if self.complex else values
        self.width = V.shape[1]
        self.R = records(triangulation.points, triangulation.simplices,
                         np.ascontiguousarray(V, dtype=np.float64))
        self.NB = np.ascontiguousarray(triangulation.neighbors, dtype=np.int64)
        self.dtype = complex if self.complex else float

    @property
    def bytes_per_query(self) -> int:
        """Work space of a query (its order, its value, its flag)."""
        return 40 + 8 * self.width + (16 if self.complex else 8) * self.K

    def __call__(self, q):
        """``(values, flagged)``: the interpolant at the points q (m, 3), (m, K), and the
        indices of the queries it leaves to the caller (their rows are NaN)."""
        q = np.ascontiguousarray(q, dtype=np.float64)
        m = q.shape[0]
        out = np.empty((m, self.width))
        bad = np.empty(m, np.bool_)
        if m and self.width:
            order = morton_order(q) if m > 1 else np.zeros(1, np.int64)
            nblocks = max(1, min(m // 64, BLOCKS_PER_THREAD * numba.get_num_threads()))
            with numba.parallel_chunksize(1):
                _queries(self.R, self.NB, q, order, nblocks, out, bad)
        else:
            bad[:] = False
        if self.complex:
            out = out[:, :self.K] + 1j * out[:, self.K:]
        return out, np.flatnonzero(bad)
