"""The package's own 3D Delaunay tetrahedralisation, a drop-in for scipy's ``Delaunay`` in 3D.

Why not Qhull: Qhull's ``Delaunay`` of 2e4 random points takes longer than the natural-neighbour
coordinates that use it, gives flat tetrahedra for cospherical nodes (lattices), and leaves no
adjacency of our own to update by flips when nodes move. :class:`Delaunay3D` inserts the points
with exact predicates (:mod:`.delaunay3d_build`) in a spatially coherent order and exposes what
the 3D code paths read from scipy's object: ``points``, ``simplices``, ``neighbors``,
``vertex_to_simplex``, ``vertex_neighbor_vertices``, ``convex_hull`` and ``find_simplex``;
and, for nodes that move, :meth:`Delaunay3D.moved`, the local repair by flips
(:mod:`.delaunay3d_repair`), and for nodes added or taken away, :meth:`Delaunay3D.inserted`
and :meth:`Delaunay3D.removed`.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from .delaunay3d_build import DUPLICATE, FLAT, add_points, build
from .delaunay3d_repair import COINCIDENT, LOST, remove_points, repair, working
from .entities import unique_ints
from .nodesets import morton_order
from .predicates3d import orient3d_sign
from .walls3d import check_faces, wall_slots, walled

__all__ = ["Delaunay3D", "insertion_order"]

BRIO_MIN_ROUND = 1024  # the first (smallest) round of the biased randomised insertion order


def insertion_order(p, seed=0):
    """Biased randomised insertion order (Amenta, Choi and Rote): random rounds growing by a
    factor two, each round along the Morton curve, so that every insertion walks a short way
    from the last one while the rounds keep the cavities small on clustered input."""
    n = p.shape[0]
    perm = np.random.default_rng(seed).permutation(n)
    bounds = [n]
    while bounds[-1] > BRIO_MIN_ROUND:
        bounds.append(bounds[-1] // 2)
    bounds = [0] + bounds[::-1]
    parts = [perm[lo:hi][morton_order(p[perm[lo:hi]])] for lo, hi in zip(bounds, bounds[1:])]
    return np.concatenate(parts).astype(np.int64)


def _checked(points, fewest=4, rows="n"):
    """A float copy of ``points`` (``rows``, 3), finite, at least ``fewest`` rows."""
    p = np.array(points, dtype=np.float64, order="C", copy=True)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape ({rows}, 3), got {np.shape(points)}")
    bad = np.flatnonzero(~np.isfinite(p).all(axis=1))
    if bad.size:
        raise ValueError(f"points[{bad[0]}] = {p[bad[0]].tolist()} is not finite")
    if p.shape[0] < fewest:
        raise ValueError(f"need at least 4 points in 3D, got {p.shape[0]}")
    return p


def _compact(T, N, ntet, n):
    """Finite tets and their neighbours renumbered, -1 across the hull."""
    T, N = T[:ntet], N[:ntet]
    keep = (T[:, 0] >= 0) & (T[:, 3] != n)
    new = np.full(ntet + 1, -1, np.int32)  # new[-1] = -1 keeps -1 entries
    new[np.flatnonzero(keep)] = np.arange(int(keep.sum()), dtype=np.int32)
    nb = new[N[keep]]
    return np.ascontiguousarray(T[keep]), np.ascontiguousarray(nb)


class Delaunay3D:
    """Delaunay tetrahedralisation of points (n, 3), every point a vertex.

    ``simplices`` (m, 4) are positively oriented (``orient3d > 0``, no flat tetrahedra);
    ``neighbors[t, i]`` is the tetrahedron across the face opposite ``simplices[t, i]``, -1
    on the hull (scipy's convention). Ties between cospherical points are broken by a
    symbolic perturbation, so lattices get a valid, reproducible tetrahedralisation.
    Raises ``ValueError`` for fewer than 4 points, non-finite or duplicate points (naming the
    pair) and coplanar point sets.
    """

    def __init__(self, points, seed=0):
        p = _checked(points)
        T, N, ntet, status, i, j = build(p, insertion_order(p, seed))
        if status == DUPLICATE:
            i, j = sorted((int(i), int(j)))
            raise ValueError(f"duplicate points: points[{j}] coincides with points[{i}] "
                             f"at {p[i].tolist()}")
        if status == FLAT:
            rank = np.linalg.matrix_rank(p[1:] - p[0])
            raise ValueError(f"the {p.shape[0]} points are degenerate: they span only {rank} "
                             "of 3 dimensions (a flat point set: all coplanar or collinear), so no "
                             "tetrahedralisation exists")
        self._adopt(p, T, N, ntet)

    def _adopt(self, p, T, N, ntet):
        """Take the points and the ghost-closed tetrahedra of :mod:`.delaunay3d_build`."""
        self.points = p
        T.flags.writeable = N.flags.writeable = False
        self._raw = (T, N, ntet)  # the ghost-closed structure :meth:`moved` repairs
        self.simplices, self.neighbors = _compact(T, N, ntet, p.shape[0])
        self.ndim = 3
        self.npoints = p.shape[0]
        self.nsimplex = self.simplices.shape[0]
        self._v2s = None
        self.walled_neighbors = None

    def moved(self, points):
        """The Delaunay tetrahedralisation of the same nodes at new positions ``points``
        (n, 3), repaired locally from this one (:mod:`.delaunay3d_repair`; this one stays
        unchanged), and the repair's report: ``relocated`` (nodes removed and re-inserted),
        ``rebuilt`` (1 when the repair fell back to a build from scratch) and
        ``repair_seconds``. The result is the tetrahedralisation :class:`Delaunay3D` builds
        from ``points``, tetrahedron for tetrahedron. Raises ``ValueError`` for bad points
        (naming the point) and for two nodes at one position (naming both)."""
        start = time.perf_counter()
        p1 = _checked(points)
        if p1.shape != self.points.shape:
            raise ValueError(f"points must have the shape of the nodes, {self.points.shape}, "
                             f"got {p1.shape}")
        T, N, ntet, status, i, j, counts = repair(self._raw, self.points, p1)
        if status == COINCIDENT:
            i, j = sorted((int(i), int(j)))
            raise ValueError(f"points[{j}] coincides with points[{i}] at {p1[i].tolist()}")
        out = Delaunay3D.__new__(Delaunay3D)
        if status == LOST:  # counted, never silent
            out.__init__(p1)
        else:
            out._adopt(p1, T, N, ntet)
        report = dict(counts, rebuilt=int(status == LOST),
                      repair_seconds=time.perf_counter() - start)
        return out, report

    def inserted(self, points):
        """The Delaunay tetrahedralisation of these nodes and new ones ``points`` (k, 3),
        numbered after them: each inserted into this one (Bowyer-Watson; this one stays
        unchanged), so that only the tetrahedra in their conflict regions change. The
        result is the one :class:`Delaunay3D` builds from all the nodes. Raises
        ``ValueError`` for non-finite points and for a new point on a node or on another
        new point (naming both)."""
        q = _checked(points, fewest=0, rows="k")
        n = self.npoints
        p = np.concatenate([self.points, q])
        T, N = working(*self._raw)
        order = n + morton_order(q).astype(np.int64) if q.shape[0] > 1 else \
            np.arange(n, n + q.shape[0], dtype=np.int64)
        T, N, ntet, status, i, j = add_points(p, T, N, self._raw[2], n, order)
        if status == DUPLICATE:
            i, j = sorted((int(i), int(j)))
            what = f"node {i}" if i < n else f"new point {i - n}"
            raise ValueError(f"new point {j - n} at {p[j].tolist()} coincides with {what}")
        out = Delaunay3D.__new__(Delaunay3D)
        out._adopt(p, T, N, ntet)
        return out

    def removed(self, indices):
        """The Delaunay tetrahedralisation of these nodes without the nodes ``indices``
        (the others renumbered in order), each removed from this one (its hole filled by
        the conflict region of the node in the Delaunay tetrahedralisation of its
        neighbours; this one stays unchanged). The result is the one :class:`Delaunay3D`
        builds from the nodes kept. Raises ``ValueError`` for an index out of range or
        repeated, and where fewer than 5 nodes would be left."""
        n = self.npoints
        idx = np.asarray(indices, dtype=np.int64).ravel()
        bad = idx[(idx < 0) | (idx >= n)]
        if bad.size:
            raise ValueError(f"index {int(bad[0])} is out of range for {n} nodes")
        if np.unique(idx).size != idx.size:
            raise ValueError("indices must not repeat")
        if n - idx.size < 5:
            raise ValueError(f"removing {idx.size} of {n} nodes would leave fewer than 5")
        T, N = working(*self._raw)
        T, N, ntet, status, i = remove_points(self.points, T, N, self._raw[2], idx)
        if status == LOST:
            raise ValueError(f"node {int(i)} could not be removed (its neighbours leave no "
                             "tetrahedralisation of the hole)")
        keep = np.ones(n, bool)
        keep[idx] = False
        new = np.full(n + 1, -1, np.int32)
        new[np.flatnonzero(keep)] = np.arange(n - idx.size, dtype=np.int32)
        new[n] = n - idx.size                                    # the ghost vertex
        T, N = T[:ntet].copy(), N[:ntet].copy()
        live = T[:, 0] >= 0                                      # freed rows: T[t, 0] = -1
        T[live] = new[T[live]]
        out = Delaunay3D.__new__(Delaunay3D)
        out._adopt(np.ascontiguousarray(self.points[keep]), T, N, ntet)
        return out

    def wall_off(self, faces: dict) -> np.ndarray:
        """Make the triangles ``faces`` (name -> (k, 3) node indices) walls that natural
        neighbours do not see through (:mod:`.walls3d`), in place of any set before:
        ``walled_neighbors`` becomes ``neighbors`` with ``WALL - t`` across them, which the
        coordinates read. Returns the (m, 4) wall slots. Raises
        :class:`~.walls3d.MissingFace` (a ``ValueError``) for a triangle that is no face of
        the tetrahedra, naming it; the walls stay as they were. The tetrahedralisations
        :meth:`moved`, :meth:`inserted` and :meth:`removed` make have none."""
        checked = {name: check_faces(f, self.npoints, name=f"faces[{name!r}]")
                   for name, f in faces.items()}
        slots = wall_slots(self.simplices, self.npoints, checked)
        self.walled_neighbors = walled(self.neighbors, slots) if slots.any() else None
        return slots

    @property
    def vertex_to_simplex(self):
        """For each point, a tetrahedron of which it is a vertex (computed once: every 3D
        coordinate call reads it)."""
        if getattr(self, "_v2s", None) is None:
            out = np.full(self.npoints, -1, np.int32)
            out[self.simplices.ravel()] = np.repeat(np.arange(self.nsimplex, dtype=np.int32), 4)
            out.flags.writeable = False
            self._v2s = out
        return self._v2s

    @property
    def vertex_neighbor_vertices(self):
        """``(indptr, indices)``: the Delaunay neighbours of point k are
        ``indices[indptr[k]:indptr[k + 1]]`` (sorted), as in scipy."""
        S = self.simplices.astype(np.int64)
        pairs = np.array([(i, j) for i in range(4) for j in range(4) if i != j])
        a, b = S[:, pairs[:, 0]].ravel(), S[:, pairs[:, 1]].ravel()
        key = unique_ints(a * self.npoints + b)
        indptr = np.searchsorted(key // self.npoints, np.arange(self.npoints + 1))
        return indptr.astype(np.int32), (key % self.npoints).astype(np.int32)

    @property
    def convex_hull(self):
        """Hull triangles (k, 3), counter-clockwise seen from outside."""
        t, i = np.nonzero(self.neighbors < 0)
        faces = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])[i]
        return self.simplices[t[:, None], faces]

    def find_simplex(self, xi):
        """Index of a tetrahedron containing each point of xi (k, 3) (closed: points on shared
        faces get one of them), -1 outside the hull; decided by exact orientations."""
        q = np.ascontiguousarray(np.asarray(xi, dtype=np.float64).reshape(-1, 3))
        order = morton_order(q) if q.shape[0] > 1 else np.arange(q.shape[0])
        out = np.empty(q.shape[0], np.int64)
        _find(self.points, self.simplices, self.neighbors, q, order.astype(np.int64), out)
        return out.reshape(np.shape(xi)[:-1])


@njit(cache=True)
def _find(P, S, NB, q, order, out):
    """Visibility walks for the queries in ``order``, each from the last one's tet."""
    t = 0
    for k in range(order.shape[0]):
        j = order[k]
        t = _walk(P, S, NB, q[j, 0], q[j, 1], q[j, 2], max(t, 0))
        out[j] = t


@njit(cache=True)
def _beyond(P, S, t, i, x, y, z):
    """Whether (x, y, z) lies strictly beyond the face of tet t opposite slot i: the tet
    with that vertex replaced by the point is negatively oriented."""
    v0, v1, v2, v3 = S[t, 0], S[t, 1], S[t, 2], S[t, 3]
    if i == 0:
        o = orient3d_sign(x, y, z, P[v1, 0], P[v1, 1], P[v1, 2], P[v2, 0], P[v2, 1],
                          P[v2, 2], P[v3, 0], P[v3, 1], P[v3, 2])
    elif i == 1:
        o = orient3d_sign(P[v0, 0], P[v0, 1], P[v0, 2], x, y, z, P[v2, 0], P[v2, 1],
                          P[v2, 2], P[v3, 0], P[v3, 1], P[v3, 2])
    elif i == 2:
        o = orient3d_sign(P[v0, 0], P[v0, 1], P[v0, 2], P[v1, 0], P[v1, 1], P[v1, 2],
                          x, y, z, P[v3, 0], P[v3, 1], P[v3, 2])
    else:
        o = orient3d_sign(P[v0, 0], P[v0, 1], P[v0, 2], P[v1, 0], P[v1, 1], P[v1, 2],
                          P[v2, 0], P[v2, 1], P[v2, 2], x, y, z)
    return o < 0.0


@njit(cache=True)
def _walk(P, S, NB, x, y, z, t):
    """Visibility walk to a tet containing (x, y, z), -1 once it steps outside the hull
    (a point beyond a hull face's plane is outside the convex hull)."""
    prev = -1
    while True:
        moved = False
        for i in range(4):
            nb = NB[t, i]
            if nb == prev and nb >= 0:
                continue
            if _beyond(P, S, t, i, x, y, z):
                if nb < 0:
                    return -1
                prev, t, moved = t, nb, True
                break
        if not moved:
            return t
