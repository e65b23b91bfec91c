"""Sibson coordinates and their gradients in 2, 3 and 4 dimensions (the paper's Box 1).

This is the paper's "method 2": natural-neighbour (Sibson) coordinates from the
volumes of second-order Voronoi cells, each a convex polytope ``{y : A y <= b}``
whose volume is computed with Lasserre's recursive formula. The 2D area method
is :mod:`skfem_nem.coordinates.area2d`; this module works in any of d = 2, 3, 4.

The pieces: point location and conflict regions in
:mod:`skfem_nem.geometry.simplices_nd`; the volume recursion of one cell in
:mod:`skfem_nem.coordinates.lasserre_cell`; the 3D cells from the combinatorics in
:mod:`skfem_nem.coordinates.lasserre_tet`; here the query kernel that combines them, the
batches and the hull limits.

Special points
    At a node: the Kronecker delta (gradients undefined). On the convex hull
    (within :data:`~skfem_nem.geometry.hull.HULL_TOLERANCE` times the distance to
    the facet's nodes, else outside is an error): the limits from inside, see
    :func:`_on_hull` -- inside a hull facet the weights
    ``integral over C_i of (|y - p_i|^2 - |y - x|^2) dy`` over the
    (d-1)-dimensional second-order cells of the facet's nodes
    (not their (d-1)-dimensional Sibson coordinates), linear interpolation
    on hull edges. Points on interior Delaunay faces and edges need nothing
    special: nothing divides by a quantity that vanishes there. Gradients at
    nodes or on the hull raise ``ValueError`` (``undefined="raise"``) or
    give NaN rows (``undefined="nan"``).

Kernels
    Every numba function below the parallel batch kernel is compiled
    without reference counting (``_nrt=False``; they allocate nothing):
    numba otherwise increments and decrements the count of every array
    argument atomically on each call, which took a quarter of the 3D time.
    The batch kernel allocates one set of buffers per block of queries.

Accuracy (measured, see tests/test_lasserre.py)
    Values agree with the 2D area method to ~2e-15 and gradients to ~2e-13
    relative; in 3D the second-order volumes sum to the Voronoi cell volume
    (scipy/Qhull) to ~1e-15 relative; partition of unity and linear
    precision hold to ~5e-16 in 3D and 4D, also on lattices and within
    1e-12 of a node (to ~1e-14 down to 1e-15 from one). Gradients lose digits
    near a node like ``1e-17 / r``
    (r the distance to it), as the area method does. Node sets that are
    nearly but not exactly co-spherical (lattices jittered by 1e-9) get
    errors of that size: Qhull's triangulation is then not Delaunay to that
    precision.
"""
from __future__ import annotations

from typing import Literal

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .batch import check_queries, compress, index_dtype, raise_outside, raise_undefined
from ..geometry.hull import FACET_PLANE, HULL_TOLERANCE
from ..geometry.status import ON_HULL, OUTSIDE, OVERFLOW, UNBOUNDED
from ..geometry.delaunay_nd import (check_delaunay, check_nodes, delaunay_of, sealed_neighbours,
                                    triangulate)
from ..geometry.delaunay3d import Delaunay3D
from ..geometry.nodesets import morton_order
from ..geometry.simplices_nd import FLAT, circumcentre_cache, facet_planes
from ..geometry.walls3d import WALL
from .lasserre_query import query_batch, query_batch_serial
from .watson3d import coordinates_3d, records_of, rows_3d

__all__ = ["sibson_coordinates_nd"]


# A reduced (unit) constraint normal shorter than this is parallel to the facet.
_ZERO_ROW = 1e-13
# Parallel planes closer than this times the local length scale coincide.
_TIE = 1e-13
# Relative tolerance of the in-sphere test (tolerant: includes borderline simplices).
_INSPHERE = 1e-10
# Linear precision residual |sum_i V_i (p_i - x)| / (V L) above which a query is
# recomputed without the combinatorial facet filter (a safety net).
_LINEAR = 1e-9
# A vertex of a cell may violate its constraints by this times the local length
# scale (vertex check of the combinatorial filter in degenerate configurations).
_VERTEX = 1e-9
# Barycentric coordinates above -_WALK count as inside a simplex (point location).
_WALK = 1e-12
# 3D cells from the known combinatorics (general position): a cell vertex whose
# simplex has a shape measure (volume determinant over the product of its edge
# lengths) below _SHAPE, a linear precision residual above _LINEAR3 (relative, as
# _LINEAR) or a residual of its derivative sum_i q_i (x) grad V_i = V I above
# _GRAD3 (relative to sum_i |q_i| |grad V_i|) leaves the query to the recursion.
_SHAPE = 1e-6
_LINEAR3 = 1e-12
_GRAD3 = 1e-11
# ... and so does a query closer to a node than _NEAR3 times its largest
# distance to a natural neighbour.
_NEAR3 = 1e-4


# default buffer sizes (natural neighbours, conflict simplices, output entries
# per query) per dimension
_CAPS = {2: (32, 64, 24), 3: (96, 384, 64), 4: (256, 2048, 256)}


# queries from which a batch is taken in Z-order (morton_order): random 3D
# queries among 20,000 nodes take half the time; below a few thousand the
# triangulation's pieces the batch touches stay in cache anyway
_SORT_MIN = 4096


# 3D Sibson values (no gradient) of at least WATSON_MIN queries on the package's own
# tetrahedralisation come from Watson's decomposition (watson3d: a third of the time), the
# queries it flags from Box 1 (below, the records it builds cost a few hundred queries).
# On walls (geometry.walls3d) every batch: the walled coordinates are Watson's
WATSON_MIN = 1000


# queries per batch from which the parallel kernel is used (a 3D query costs
# ~50 us, a 2D one ~7 us: a few thousand amortise the thread pool's wake-up)
_PARALLEL_MIN = 2000


# ---------------------------------------------------------------------------
# Python orchestration
# ---------------------------------------------------------------------------


def _run(P, S, NB, Q, start, gradient, kind, caps, cache=None, out=None):
    """Run the kernel on a batch with buffer sizes ``caps`` (see ``_CAPS``);
    returns ((rows, cols, values, gradients), status, info). ``cache``:
    :func:`circumcentre_cache` (computed here if None); ``out``: padded
    output buffers ``(out_i, out_v, out_g)`` of at least m rows and the
    width ``caps[2]`` to reuse (allocated here if None)."""
    m, d = Q.shape
    ncap, ccap, width = caps
    if cache is None:
        cache = circumcentre_cache(P, S, m)
    if out is None or out[0].shape[0] < m or out[0].shape[1] != width:
        out = _out_buffers(m, d, width, gradient)
    out_i, out_v = out[0][:m], out[1][:m]
    out_g = out[2][:d * m * width].reshape(d, m, width) if gradient else out[2]
    count = np.empty(m, np.int64)
    status = np.empty(m, np.int64)
    info = np.empty(m, np.int64)
    tols = np.array([_ZERO_ROW, _TIE, _INSPHERE, FLAT, HULL_TOLERANCE, _LINEAR, _WALK, _VERTEX,
                     _SHAPE, _LINEAR3, _GRAD3, _NEAR3])
    nblocks = max(1, min(m // 16, 4 * numba.get_num_threads()))
    # small batches run serially: waking the thread pool costs more than it saves
    kernel = query_batch if m >= _PARALLEL_MIN else query_batch_serial
    kernel(P, S, NB, Q, start, gradient, kind, ncap, ccap, nblocks, tols, *cache,
           out_i, out_v, out_g, count, status, info)
    _, indices, data, grads = compress(count, out_i, out_v, out_g, gradient, P.shape[0])
    rows = np.repeat(np.arange(m), count)
    return (rows, indices, data, grads), status, info


def _out_buffers(m, d, width, gradient):
    """Padded kernel outputs for m queries of up to ``width`` entries (the
    gradients' flat, viewed as (d, m', width) for m' <= m queries)."""
    return (np.empty((m, width), np.int64), np.empty((m, width)),
            np.empty(d * m * width if gradient else (d, 1, 1)))


def _on_hull(p, tri, Q, facets):
    """Coordinates of points on the boundary of the convex hull, as the limits
    of the coordinates from inside. Returns a CSR matrix (m, n).

    ``facets[r]`` names a hull facet whose plane query r lies on (from the
    query kernel). On a face of the hull of codimension k only the nodes on
    that face get weights, ``integral over C_i of (|y - p_i|^2 - |y - x|^2)^k
    dy``, where C_i is the second-order Voronoi cell of x and p_i among the
    face's nodes in the face's own dimension: as x approaches the face, its
    Voronoi cell becomes a spike whose sections are power diagrams of the
    face's nodes, and integrating over the spike gives these weights. So

    - inside a facet (k = 1) the weights come from the Lasserre recursion
      with first moments (kind 2 of the query kernel), in the facet's
      coordinates; with only d nodes on the facet they are its barycentric
      coordinates;
    - on a hull edge (dimension 1) they reduce to linear interpolation
      between the two nodes around x, for every k (as on hull edges in 2D);
    - on a 2-face of a 4D hull (k = 2) the limit is extrapolated from two
      points just inside (Richardson; error about 1e-12).

    These are not the (d-1)-dimensional Sibson coordinates of the facet's
    nodes (those would weigh C_i by its area alone).
    """
    m, d = Q.shape
    n = p.shape[0]
    S = np.ascontiguousarray(tri.simplices, dtype=np.int64)
    normal, off, F = facet_planes(p, S, facets)
    diam = np.ptp(p, axis=0).max()
    tol = FACET_PLANE * diam
    key = np.round(np.c_[normal, off / diam] * 1e8).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    hull_nodes = np.unique(np.asarray(tri.convex_hull))
    rows, cols, vals = [], [], []
    for g, f in enumerate(first):
        rs = np.flatnonzero(inverse.ravel() == g)
        x = Q[rs]
        nodes = hull_nodes[np.abs(p[hull_nodes] @ normal[f] - off[f]) <= tol]
        f0 = p[nodes[0]]
        basis = np.linalg.svd(normal[f][None, :])[2][1:].T  # the plane's directions
        pn = np.ascontiguousarray((p[nodes] - f0) @ basis)
        xn = (x - f0) @ basis
        if d == 2:
            H = _linear_on_line(pn[:, 0], xn[:, 0])
        elif nodes.size == d:
            # a simplex facet: the limit has linear precision, so barycentric
            lam = np.linalg.solve((pn[1:] - pn[0]).T[None], (xn - pn[0])[..., None])[..., 0]
            lam = np.clip(np.c_[1.0 - lam.sum(1), lam], 0.0, None)
            H = sp.csr_matrix(lam / lam.sum(1, keepdims=True))
        else:
            ftri = triangulate(pn)
            H, status, info = _coordinates(pn, xn, False, ftri, "nan", 2, hull_status=True)
            edge = np.flatnonzero(status == ON_HULL)
            if edge.size:
                H = H.tolil()
                # on the boundary of the facet: in 3D an edge, linear along it;
                # in 4D extrapolated, on the nodes of the lower face only
                E = _on_hull(pn, ftri, xn[edge], info[edge])
                if d == 4:
                    R = _extrapolate_to_hull(p, tri, x[edge], nodes)[:, nodes].toarray()
                    R *= E.toarray() != 0.0
                    E = sp.csr_matrix(R / R.sum(axis=1, keepdims=True))
                H[edge] = E
                H = H.tocsr()
        H = H.tocoo()
        rows.append(rs[H.row])
        cols.append(nodes[H.col])
        vals.append(H.data)
    R = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(m, n))
    R.eliminate_zeros()
    R.sort_indices()
    return R


def _on_boundary(p, tri, NB, Q, facets):
    """:func:`_on_hull` for the points on hull facets, :func:`_on_wall` for those on walls
    (``facets`` as there, ``NB`` the adjacency the kernel read)."""
    d = p.shape[1]
    wall = NB[facets // (d + 1), facets % (d + 1)] <= WALL
    if not wall.any():
        return _on_hull(p, tri, Q, facets)
    out = sp.lil_matrix((Q.shape[0], p.shape[0]))
    for rows, rule in ((wall, _on_wall), (~wall, _on_hull)):
        if rows.any():
            out[np.flatnonzero(rows)] = rule(p, tri, Q[rows], facets[rows])
    return out.tocsr()


def _on_wall(p, tri, Q, facets):
    """Coordinates of points on wall faces (:mod:`~skfem_nem.geometry.walls3d`): the face's
    barycentric coordinates, the limit from either side, as Watson's rows give them there.
    ``facets[r] = s * 4 + k``: the face of tetrahedron s opposite slot k."""
    rec = records_of(tri)
    ptr, idx, val, _ = rows_3d(rec.R, rec.T, rec.NB, p.shape[0], Q, facets // 4,
                               facets % 4)
    return sp.csr_matrix((val, idx, ptr), shape=(Q.shape[0], p.shape[0]))


def _linear_on_line(u, t):
    """Linear interpolation weights at t between the nodes u on a line (CSR)."""
    order = np.argsort(u)
    us = u[order]
    j = np.clip(np.searchsorted(us, t, side="right") - 1, 0, us.size - 2)
    w = np.clip((t - us[j]) / (us[j + 1] - us[j]), 0.0, 1.0)
    r = np.arange(t.size)
    return sp.csr_matrix((np.r_[1.0 - w, w], (np.r_[r, r], np.r_[order[j], order[j + 1]])),
                         shape=(t.size, u.size))


def _extrapolate_to_hull(p, tri, x, nodes):
    """Coordinates on the hull by Richardson extrapolation from two points just
    inside, towards the centroid, keeping only the given face nodes."""
    n = p.shape[0]
    diam = np.ptp(p, axis=0).max()
    v = p.mean(axis=0) - x
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    t = 1e-8 * diam
    F1 = _coordinates(p, x + t * v, False, tri, "nan", 0)
    F2 = _coordinates(p, x + 2 * t * v, False, tri, "nan", 0)
    F = (2 * F1 - F2).toarray()[:, nodes]
    F = np.maximum(F, 0.0)
    F /= F.sum(axis=1, keepdims=True)
    F = sp.coo_matrix(F)
    return sp.csr_matrix((F.data, (F.row, nodes[F.col])), shape=(x.shape[0], n))


def _walk_starts(p, q, order, tri):
    """A simplex at the node nearest each query, where its walk starts, found on the
    kernels' threads (a tenth of a 3D call at 1e5 queries on one; one worker for a few
    queries, where starting threads costs more than the search). scipy's find_simplex is
    avoided: its first call computes barycentric transforms through LAPACK, very slow with
    a threaded BLAS."""
    start = np.zeros(q.shape[0], np.int64)
    if q.shape[0]:
        workers = numba.get_num_threads() if q.shape[0] >= _PARALLEL_MIN else 1
        near = cKDTree(p).query(q[order], workers=workers)[1]
        start[order] = tri.vertex_to_simplex[near]
    return start


def _coordinates(p, q, gradient, tri, undefined, kind, hull_status=False, chunk=1 << 15):
    """Coordinates (kind 0), second-order volumes (1) or hull-facet weights (2)
    of the points q; see :func:`sibson_coordinates_nd`."""
    d = p.shape[1]
    if tri is None:
        tri = triangulate(p)
    m, n = q.shape[0], p.shape[0]
    S = np.ascontiguousarray(tri.simplices, dtype=np.int64)
    NB = sealed_neighbours(p, tri)
    order = morton_order(q) if m >= _SORT_MIN else np.arange(m)
    start = _walk_starts(p, q, order, tri)
    status = np.full(m, OUTSIDE, np.int64)
    info = np.zeros(m, np.int64)
    parts = []
    cache = circumcentre_cache(p, S, m)
    # chunks bound the padded output buffers (d + 2 numbers per neighbour slot),
    # which the chunks reuse
    out = _out_buffers(min(m, chunk), d, _CAPS[d][2], gradient)
    for c0 in range(0, m, chunk):
        todo = order[c0:c0 + chunk]
        caps = _CAPS[d]
        while todo.size:
            (r, c, v, g), st, inf = _run(p, S, NB, np.ascontiguousarray(q[todo]), start[todo],
                                         gradient, kind, caps, cache, out)
            status[todo] = st
            info[todo] = inf
            parts.append((todo[r], c, v, g))
            # rare: more natural neighbours or conflict simplices than the buffers
            # hold (co-spherical clusters); redo those with larger buffers
            todo = todo[st == OVERFLOW]
            caps = tuple(4 * c for c in caps)
    raise_outside(status, q)
    bad = np.flatnonzero(status == UNBOUNDED)
    if bad.size:  # pragma: no cover - a bounded cell is guaranteed inside the hull
        raise ValueError(
            f"second-order Voronoi cells of {bad.size} query point(s) came out unbounded; "
            f"first is x[{bad[0]}] = {q[bad[0]].tolist()}")
    hull = np.flatnonzero(status == ON_HULL)
    if hull.size and not hull_status:
        H = _on_boundary(p, tri, NB, q[hull], info[hull]).tocoo()
        parts.append((hull[H.row], H.col, H.data, np.full((d, H.nnz), np.nan)))
    # one COO -> CSR conversion per matrix from the same (row, col) arrays:
    # all matrices get the same pattern, rows sorted by column index
    if not parts:
        parts = [(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((d, 0)))]

    def joined(k, axis=0):
        return parts[0][k] if len(parts) == 1 else np.concatenate([a[k] for a in parts], axis)

    rows, cols = joined(0), joined(1)
    vals = [joined(2)]
    if gradient:
        vals += list(joined(3, axis=1))
    indptr = np.zeros(m + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=m), out=indptr[1:])
    idx_dtype = index_dtype(n, rows.size)
    indptr = indptr.astype(idx_dtype)
    # every row comes from one part as one run, sorted by column: in query
    # order nothing moves, else each run is moved to its row's place
    if np.all(rows[1:] >= rows[:-1]):
        indices = cols.astype(idx_dtype, copy=False)
    else:
        runs = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
        lengths = np.diff(np.r_[runs, rows.size])
        dest = (np.arange(rows.size) - np.repeat(runs - indptr[rows[runs]], lengths))
        indices = np.empty(rows.size, idx_dtype)
        indices[dest] = cols
        vals = [_placed(v, dest) for v in vals]
    mats = [sp.csr_matrix((v, indices, indptr), shape=(m, n)) for v in vals]
    if hull_status:
        return mats[0], status, info
    if gradient and undefined == "raise":
        raise_undefined(status, q, p, "the convex hull")
    return (mats[0], mats[1:]) if gradient else mats[0]


def _placed(v, dest):
    out = np.empty_like(v)
    out[dest] = v
    return out


def sibson_coordinates_nd(nodes, x, gradient: bool = False, delaunay=None,
                          undefined: Literal["raise", "nan"] = "raise", chunk: int = 1 << 15,
                          *, _raw=False):
    """Sibson natural-neighbour coordinates (and gradients) in 2, 3 or 4 dimensions.

    Volumes of second-order Voronoi cells by Lasserre's recursive formula
    (the paper's Box 1); see the module docstring for the method. In 3D, the values
    alone (no gradients) of ``WATSON_MIN`` queries or more on the package's own
    tetrahedralisation come from Watson's decomposition
    (:mod:`~skfem_nem.coordinates.watson3d`, a third of the time, the same coordinates to
    ~1e-12), the queries it flags from Box 1.

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
    chunk
        Queries are processed in chunks of this many points (bounds memory).

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

    Notes
    -----
    ``_raw=True`` (for tests) returns the second-order volumes ``V_i`` and
    their gradients instead, for points inside the hull and off the nodes.
    """
    p = check_nodes(nodes)
    if undefined not in ("raise", "nan"):
        raise ValueError(f"undefined must be 'raise' or 'nan', got {undefined!r}")
    q = check_queries(x, p.shape[1])
    if delaunay is not None:
        check_delaunay(delaunay, p)
        tri = delaunay
    else:
        tri = delaunay_of(p)
    if not (isinstance(chunk, (int, np.integer)) and chunk > 0):
        raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
    walls = getattr(tri, "walled_neighbors", None) is not None
    if walls and (gradient or _raw):
        raise ValueError("the tetrahedralisation has walls (Delaunay3D.wall_off): their "
                         "coordinates are Watson's values on regions cut at the walls, "
                         "without gradients (the smoothed 3D basis needs none)")
    if not gradient and not _raw and isinstance(tri, Delaunay3D) and (
            q.shape[0] >= WATSON_MIN or walls):
        try:
            return coordinates_3d(tri, q, lambda x: _coordinates(p, x, False, tri, undefined,
                                                                  0, chunk=int(chunk)))
        except ValueError:
            pass    # a query outside the hull: the error below names it by its index in x
    return _coordinates(p, q, gradient, tri, undefined, 1 if _raw else 0, chunk=int(chunk))
