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

    over the tetrahedra whose circumsphere holds x (on a tetrahedralisation with walls,
    :mod:`~skfem_nem.geometry.walls3d`, those reached without crossing one). W_T vanishes
    as x reaches the sphere (D = 0), so the in-sphere test is the sign of D in floating
    point. A query is walked to the tetrahedron that holds it (a visibility walk) and its
    cavity traversed through faces; the queries go in Morton order, each walk starting from
    the last query's tetrahedron.

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
from ..geometry.walls3d import WALL
from .watson3d import (CAVITY_CAP, HULL_LAMBDA, RECORD_VALUES, conflict_tetrahedra, records,
                       walk)

__all__ = ["SibsonWatson3D", "watson_applies"]

# A query is flagged when the sum of its terms is at most DEN_MIN times the sum of their
# magnitudes (per tetrahedron). Values lose less to it than rows of coordinates
# (watson3d.DEN_MIN, 1e-2): on 100,000 random queries among 20,000 random nodes, 1.1% are
# flagged and the others agree with the Box 1 coordinates to 5e-13 (at 1e-2: 8.6%, 6e-14).
DEN_MIN = 1e-3
# queries per block of the parallel loop: blocks per thread
BLOCKS_PER_THREAD = 4


def watson_applies(triangulation) -> bool:
    """True for the package's exact :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D`
    (every tetrahedron a Delaunay one, none flat: the cavity of a query is the tetrahedra
    whose sphere holds it)."""
    return isinstance(triangulation, Delaunay3D)


@njit(cache=True, error_model="numpy")
def _cavity(R, NB, x, y, z, t0, stamp, mark, tets, E, acc):
    """Accumulates ``acc = (sum_T W_T f_T(x) (K), sum W_T, sum |W_T|)`` over the cavity of
    (x, y, z) reached from t0 (``stamp[t] == mark``: visited); False if the query is to be
    flagged (near a hull face, too large a cavity)."""
    K = acc.shape[0] - 2
    acc[:] = 0.0
    nc = conflict_tetrahedra(R, NB, x, y, z, t0, (0.0, 0.0, 0.0, 0.0), stamp, mark, tets, E)
    if nc < 0:
        return False
    v = RECORD_VALUES
    for i in range(nc):
        t = tets[i]
        D, l0, l1, l2, l3 = E[i, 0], E[i, 1], E[i, 2], E[i, 3], E[i, 4]
        for k in range(4):
            if NB[t, k] <= WALL:        # next to a wall face's plane: its terms explode
                if abs(E[i, 1 + k]) <= HULL_LAMBDA * R[t, 30]:
                    return False
            elif NB[t, k] < 0 and E[i, 1 + k] <= HULL_LAMBDA * R[t, 30]:
                return False
        S = R[t, 30]
        W = D * D * D * S * S / (l0 * l1 * l2 * l3)   # times e_i: the term of v_i
        for c in range(K):
            acc[c] += W * (l0 * R[t, v + c] + l1 * R[t, v + K + c]
                           + l2 * R[t, v + 2 * K + c] + l3 * R[t, v + 3 * K + c])
        w = W * (l0 + l1 + l2 + l3)
        acc[K] += w
        acc[K + 1] += abs(w)
    return True


@njit(cache=True, parallel=True, error_model="numpy")
def _queries(R, NB, Q, order, nblocks, out, bad):
    """Values ``out`` (m, K) of the queries Q (m, 3), taken in ``order`` in ``nblocks``
    blocks in parallel; ``bad[j]`` where query j is flagged (its row NaN)."""
    m = order.shape[0]
    K = out.shape[1]
    for b in prange(nblocks):
        stamp = np.full(R.shape[0], -1, np.int64)
        tets = np.empty(CAVITY_CAP, np.int64)
        E = np.empty((CAVITY_CAP, 5))
        acc = np.empty(K + 2)
        t = 0
        for s in range(b * m // nblocks, (b + 1) * m // nblocks):
            j = order[s]
            x, y, z = Q[j, 0], Q[j, 1], Q[j, 2]
            t1 = walk(R, NB, x, y, z, t)
            ok = t1 >= 0 and _cavity(R, NB, x, y, z, t1, stamp, s, tets, E, acc)
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
        walled = getattr(triangulation, "walled_neighbors", None)   # (geometry.walls3d)
        self.NB = np.ascontiguousarray(triangulation.neighbors if walled is None else walled,
                                       dtype=np.int64)
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
