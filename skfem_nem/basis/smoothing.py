"""Gradient smoothing: consistent integration of natural-neighbour functions.

Why
---
Natural-neighbour functions are not polynomials on the Delaunay triangles
(their gradients kink along the circumcircles of neighbouring triangles and
have cone points at the nodes), so no Gauss rule integrates them exactly.
The Galerkin method then violates the *integration constraint*, the discrete
divergence theorem ``sum_q w_q grad phi_I(x_q) = oint phi_I n`` for every
shape function, fails the linear patch test and stops converging once the
quadrature error dominates (``docs/verification.md``).

Gradient (strain) smoothing replaces the gradient at an integration point by
its mean over a *smoothing cell* C around it, written as a boundary integral
(the divergence theorem)::

    b_I(C) = (1 / |C|) oint_{dC} phi_I n ds,

which needs only values of phi_I on the cell's edges. Two properties follow
for cells that tile the domain:

* linear exactness: for a linear field u = a + g.x the interpolant is u
  itself (linear precision), and ``sum_I u_I b_I(C) = g`` for any edge rule
  exact for linear functions;
* the integration constraint: ``sum_C |C| b_I(C)`` is the boundary integral
  of phi_I n, since every inner edge is shared by two cells with opposite
  normals and the same points (the terms cancel to round-off).

Together they make the Galerkin solution reproduce linear fields to machine
precision (the patch test), and the smoothed gradient of the interpolant of
a smooth field is within O(h) of its gradient, so the rates are optimal
(measured in ``docs/verification.md``).

Cells
-----
2D: each triangle is cut into three quadrilaterals, one at each vertex
(vertex, the midpoints of its two edges, the centroid), each of area |T|/3.
A cell's integration point is the point of the paper's 3-point Gauss rule
that lies inside it (barycentric (2/3, 1/6, 1/6) from its vertex): values
there integrate mass terms and loads; stress history lives there as before.
The cells' edges are the half-edges of the triangle edges (shared with the
neighbouring triangle) and the segments midpoint-centroid (shared by two
cells of a triangle); each segment is evaluated once, at
``SEGMENT_POINTS`` Gauss-Legendre points.

3D: the cell is the tetrahedron itself; its faces (shared with the
neighbouring tetrahedra) are integrated by their centroids and their
vertices, where the values are known (:func:`cells_3d`). Values
are carried by the vertices and the centroid (:func:`value_rule`), which
share the tetrahedron's smoothed gradient; at a vertex the values are known,
so the centroid is the one coordinate query of a tetrahedron's own.

The smoothed gradients and the values at the integration points are stored
on one CSR sparsity pattern per row (an integration point), as the Gauss
path stores coordinates and their gradients, so stencils, groups and the
whole-mesh assembly are unchanged.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..jit import serial_twin

#: Gauss-Legendre points per cell edge (2D). Any rule exact for linear
#: functions passes the patch test. Measured on the Poisson problem of
#: docs/verification.md (250-16,000 nodes): 1, 2 and 3 points give the same
#: errors within 7 % (L2: 1 point 6 % lower; H1: 1 % higher) and the same
#: rates; 1 point needs half the evaluations and gives smaller stencils
SEGMENT_POINTS = 1
#: rows per block of the combination kernel (blocks go to threads)
_BLOCK = 1024
#: rows below which the serial kernel runs (waking threads costs more: about
#: 0.3 us per row serially, so from a few blocks on two threads gain)
_PARALLEL_MIN = 4096

# barycentric coordinates of the 3-point rule's points, point i nearest vertex i
_X3 = np.array([[1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
_W3 = np.full(3, 1 / 6)
# 3D: the tetrahedron's four vertices (1/20 of its volume each) and its centroid
# (4/5), the positive rule of degree 2 whose vertex values are known: one
# coordinate query a tetrahedron instead of four for scikit-fem's 4-point rule
_X5 = np.array([[0.0, 1.0, 0.0, 0.0, 0.25], [0.0, 0.0, 1.0, 0.0, 0.25],
                [0.0, 0.0, 0.0, 1.0, 0.25]])
_W5 = np.array([1 / 120] * 4 + [2 / 15])


def value_rule(dim: int):
    """The reference-cell rule (X, W) whose points carry values and the
    smoothed gradients: 2D the 3-point rule (point i in vertex i's cell),
    3D the vertices and the centroid (:data:`_X5`)."""
    if dim == 2:
        return _X3.copy(), _W3.copy()
    return _X5.copy(), _W5.copy()


def vertex_points(X) -> np.ndarray:
    """(nq,) the reference vertex each point of the rule X (dim, nq) is (vertex
    0 the origin, vertex i the unit vector i), -1 for the points that are none:
    there every natural-neighbour function is known (1 for the node, 0 for the
    others) and needs no coordinate query."""
    dim = X.shape[0]
    ref = np.vstack([np.zeros(dim), np.eye(dim)])       # (dim + 1, dim)
    hit = (X.T[:, None, :] == ref[None, :, :]).all(axis=2)   # (nq, dim + 1)
    return np.where(hit.any(axis=1), hit.argmax(axis=1), -1)


# ---------------------------------------------------------------------------
# cells and their boundary points
# ---------------------------------------------------------------------------

def cells_2d(p, t, t2f, facets, elems):
    """Boundary points of the vertex cells of the triangles ``elems``.

    ``p`` (n, 2) nodes; ``t``, ``t2f`` (3, nt) and ``facets`` (2, nf) as in a
    scikit-fem ``MeshTri`` (``t2f[i]`` is the edge from vertex i to vertex
    i + 1). Returns (points (m, 2), hint (m,) a triangle holding each point,
    pts (3 k, 4 s) point indices per cell, coef (3 k, 4 s, 2)): the smoothed
    gradient of a function over cell 3 j + i (vertex i of triangle
    elems[j]) is ``sum_r coef[c, r] * phi(points[pts[c, r]])``.
    """
    s, w = np.polynomial.legendre.leggauss(SEGMENT_POINTS)
    return _cells_2d(np.ascontiguousarray(p, dtype=np.float64),
                     np.ascontiguousarray(t, dtype=np.int64),
                     np.ascontiguousarray(t2f, dtype=np.int64),
                     np.ascontiguousarray(facets, dtype=np.int64),
                     np.ascontiguousarray(elems, dtype=np.int64), 0.5 * (s + 1.0), 0.5 * w)


def cells_2d_alone(p, t, elems):
    """:func:`cells_2d` for a few triangles ``elems`` of a large mesh, without the mesh's
    edge numbering (scikit-fem builds it for all triangles, a sort of all edges): the
    edges of ``elems`` alone, node pairs sorted as scikit-fem sorts a mesh's facets, so
    that every point is bitwise the one :func:`cells_2d` gives."""
    tl = np.asarray(t)[:, elems]
    ends = np.sort(np.stack([tl, np.roll(tl, -1, axis=0)]), axis=0)      # (2, 3, k)
    pairs = ends.reshape(2, -1).T
    facets, t2f = np.unique(pairs, axis=0, return_inverse=True)
    points, hint, pts, coef = cells_2d(p, tl, t2f.reshape(3, -1), facets.T,
                                       np.arange(tl.shape[1]))
    return points, np.asarray(elems)[hint], pts, coef


@njit(cache=True)
def _cells_2d(p, t, t2f, facets, elems, s, w):
    """The kernel of :func:`cells_2d`. Points: first two halves per edge of
    the triangles (from the edge's first node to its midpoint, then on to its
    second node), then the segments midpoint-centroid, three per triangle.
    Shared segments get bitwise equal points and exactly opposite
    coefficients (midpoints are computed once, from the edge's own node
    order), so the cells' contributions cancel to round-off."""
    k = elems.shape[0]
    ns = s.shape[0]
    local = np.full(facets.shape[1], -1, np.int64)
    fac = np.empty(3 * k, np.int64)
    owner = np.empty(3 * k, np.int64)
    nfl = 0
    for j in range(k):
        for i in range(3):
            f = t2f[i, elems[j]]
            if local[f] < 0:
                local[f] = nfl
                fac[nfl] = f
                owner[nfl] = elems[j]
                nfl += 1
    nh = 2 * nfl * ns
    points = np.empty((nh + 3 * k * ns, 2))
    hint = np.empty(nh + 3 * k * ns, np.int64)
    mid = np.empty((nfl, 2))
    for q in range(nfl):
        a, b = facets[0, fac[q]], facets[1, fac[q]]
        for d in range(2):
            mid[q, d] = 0.5 * (p[a, d] + p[b, d])
        for r in range(ns):
            for d in range(2):
                points[2 * q * ns + r, d] = p[a, d] + s[r] * (mid[q, d] - p[a, d])
                points[(2 * q + 1) * ns + r, d] = mid[q, d] + s[r] * (p[b, d] - mid[q, d])
            hint[2 * q * ns + r] = owner[q]
            hint[(2 * q + 1) * ns + r] = owner[q]
    pts = np.empty((3 * k, 4 * ns), np.int64)
    coef = np.empty((3 * k, 4 * ns, 2))
    g = np.empty(2)
    for j in range(k):
        e = elems[j]
        v0, v1, v2 = t[0, e], t[1, e], t[2, e]
        det = ((p[v1, 0] - p[v0, 0]) * (p[v2, 1] - p[v0, 1])
               - (p[v1, 1] - p[v0, 1]) * (p[v2, 0] - p[v0, 0]))
        area = abs(det) / 6.0                           # |T| / 3 per cell
        scale = 0.0 if area == 0.0 else (1.0 if det > 0 else -1.0) / area
        for d in range(2):
            g[d] = (p[v0, d] + p[v1, d] + p[v2, d]) / 3.0
        for i in range(3):
            q = local[t2f[i, e]]
            for r in range(ns):
                for d in range(2):
                    points[nh + (3 * j + i) * ns + r, d] = mid[q, d] + s[r] * (g[d] - mid[q, d])
                hint[nh + (3 * j + i) * ns + r] = e
        for i in range(3):
            c = 3 * j + i
            vi = t[i, e]
            qi = local[t2f[i, e]]                       # edge (i, i+1)
            qj = local[t2f[(i + 2) % 3, e]]             # edge (i-1, i)
            hi = 0 if facets[0, fac[qi]] == vi else 1
            hj = 0 if facets[0, fac[qj]] == vi else 1
            # the cell's boundary, counter-clockwise for a positive det:
            # vertex i -> mid(i, i+1) -> centroid -> mid(i-1, i) -> vertex i;
            # (dy, -dx) of each piece is its outward normal times its length
            for r in range(ns):
                wr = w[r] * scale
                pts[c, r] = (2 * qi + hi) * ns + r
                coef[c, r, 0] = (mid[qi, 1] - p[vi, 1]) * wr
                coef[c, r, 1] = -(mid[qi, 0] - p[vi, 0]) * wr
                pts[c, ns + r] = nh + (3 * j + i) * ns + r
                coef[c, ns + r, 0] = (g[1] - mid[qi, 1]) * wr
                coef[c, ns + r, 1] = -(g[0] - mid[qi, 0]) * wr
                pts[c, 2 * ns + r] = nh + (3 * j + (i + 2) % 3) * ns + r
                coef[c, 2 * ns + r, 0] = (mid[qj, 1] - g[1]) * wr
                coef[c, 2 * ns + r, 1] = -(mid[qj, 0] - g[0]) * wr
                pts[c, 3 * ns + r] = (2 * qj + hj) * ns + r
                coef[c, 3 * ns + r, 0] = (p[vi, 1] - mid[qj, 1]) * wr
                coef[c, 3 * ns + r, 1] = -(p[vi, 0] - mid[qj, 0]) * wr
    return points, hint, pts, coef


def cells_3d(p, t, t2f, facets, elems):
    """Face points of the tetrahedra ``elems`` (one cell each); as
    :func:`cells_2d`, with cell j the tetrahedron elems[j], except that an index
    ``pts >= len(points)`` names the node ``pts - len(points)``, and a fifth array
    ``slot``: the face point i lies on the face of tetrahedron ``own[i]`` opposite its
    vertex ``slot[i]``.

    Each face is integrated by its centroid (weight 3/4) and its vertices (1/12
    each), the positive rule of degree 2 on a triangle whose vertex values are
    known: one coordinate query a face (shared by its two tetrahedra). The face
    opposite vertex o has the outward area vector ``-3 |T| grad lambda_o``, so
    the smoothed gradient is ``sum_o -9/4 grad lambda_o phi(c_o) + sum_v 1/4
    grad lambda_v phi(x_v)``, exact for linear functions (measured against
    other rules in docs/ndim.md). Vectorised numpy: the coordinates, not the
    cells, are the cost."""
    k = elems.size
    T = np.asarray(t)[:, elems]                         # (4, k)
    F = np.asarray(t2f)[:, elems]                       # (4, k)
    fac, finv = np.unique(F.ravel(), return_inverse=True)
    finv = finv.reshape(F.shape)
    FV = np.asarray(facets)[:, fac]                     # (3, nf)
    points = (p[FV[0]] + p[FV[1]] + p[FV[2]]) / 3.0
    # the vertex opposite each face: the tetrahedron's node not on it
    opposite = T.sum(axis=0) - FV[:, finv].sum(axis=0)  # (4, k) node numbers
    o = (T[None, :, :] == opposite[:, None, :]).argmax(axis=1)   # (4, k) local vertex
    own = np.empty(fac.size, dtype=np.int64)
    own[finv.ravel()] = np.tile(elems, 4)
    slot = np.empty(fac.size, dtype=np.int64)
    slot[finv.ravel()] = o.ravel()
    V = p[T.T]                                          # (k, 4, 3)
    E = V[:, 1:] - V[:, :1]                             # (k, 3, 3) edges from vertex 0
    cof = np.stack([np.cross(E[:, 1], E[:, 2]), np.cross(E[:, 2], E[:, 0]),
                    np.cross(E[:, 0], E[:, 1])], axis=1)  # (k, 3, 3)
    det = np.einsum("kd,kd->k", E[:, 0], cof[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(det != 0, 1.0 / det, 0.0)      # flat tetrahedra: no gradient
    G = np.empty((k, 4, 3))                             # grad lambda_i
    G[:, 1:] = cof * scale[:, None, None]
    G[:, 0] = -G[:, 1:].sum(axis=1)
    pts = np.concatenate([finv.T, fac.size + T.T], axis=1)          # (k, 8)
    coef = np.concatenate([-2.25 * G[np.arange(k)[:, None], o.T], 0.25 * G], axis=1)
    return points, own, pts, np.ascontiguousarray(coef), slot


# ---------------------------------------------------------------------------
# values and smoothed gradients on one pattern
# ---------------------------------------------------------------------------

@njit(cache=True)
def _merge_row(r, c, pts, coef, v_ptr, v_idx, v_val, s_ptr, s_idx, s_val, head, stop, cur,
               base, fill, out_idx, out_val, out_grad):
    """Row r as a merge of its value row and its cell's segment rows, all of
    them sorted by column: the columns come out sorted and each once, with no
    work array of the size of the node set (that cost a cache miss per
    entry). Returns the row's length; writes it at ``base`` when filling.
    Source 0 is the value row, source 1 + j the row of point pts[c, j];
    ``cur`` holds each source's next column (-1: exhausted)."""
    m = pts.shape[1] + 1
    dim = coef.shape[2]
    head[0], stop[0] = v_ptr[r], v_ptr[r + 1]
    for j in range(1, m):
        q = pts[c, j - 1]
        head[j], stop[j] = s_ptr[q], s_ptr[q + 1]
    for j in range(m):
        idx = v_idx if j == 0 else s_idx
        cur[j] = idx[head[j]] if head[j] < stop[j] else -1
    n = 0
    while True:
        col = -1
        for j in range(m):
            if cur[j] >= 0 and (col < 0 or cur[j] < col):
                col = cur[j]
        if col < 0:
            return n
        if fill:
            out_idx[base + n] = col
            out_val[base + n] = 0.0
            for d in range(dim):
                out_grad[d, base + n] = 0.0
        for j in range(m):
            if cur[j] != col:
                continue
            h = head[j]
            if j == 0:
                if fill:
                    out_val[base + n] = v_val[h]
                cur[0] = v_idx[h + 1] if h + 1 < stop[0] else -1
            else:
                if fill:
                    for d in range(dim):
                        out_grad[d, base + n] += coef[c, j - 1, d] * s_val[h]
                cur[j] = s_idx[h + 1] if h + 1 < stop[j] else -1
            head[j] = h + 1
        n += 1


@njit(cache=True, parallel=True)
def _smoothed_rows(cell_of, pts, coef, v_ptr, v_idx, v_val, s_ptr, s_idx, s_val,
                   count, out_ptr, out_idx, out_val, out_grad, fill):
    """Rows of values and smoothed gradients, one per integration point.

    Row r joins the value row r of (v_ptr, v_idx, v_val) with the rows
    pts[cell_of[r]] of (s_ptr, s_idx, s_val) weighted by coef[cell_of[r]]
    (the boundary integral of each function over the cell); every input row
    is sorted by column. With ``fill=False`` it only counts each row's
    distinct columns into ``count``; with ``fill=True`` it writes the row at
    out_ptr[r], columns sorted.
    """
    nrows = cell_of.shape[0]
    nb = (nrows + _BLOCK - 1) // _BLOCK
    m = pts.shape[1] + 1
    for blk in prange(nb):
        head = np.empty(m, np.int64)
        stop = np.empty(m, np.int64)
        cur = np.empty(m, np.int64)
        for r in range(blk * _BLOCK, min(nrows, blk * _BLOCK + _BLOCK)):
            n = _merge_row(r, cell_of[r], pts, coef, v_ptr, v_idx, v_val, s_ptr, s_idx, s_val,
                           head, stop, cur, out_ptr[r] if fill else 0, fill, out_idx, out_val,
                           out_grad)
            if not fill:
                count[r] = n


_smoothed_rows_serial = serial_twin(_smoothed_rows)


@njit(cache=True, parallel=True)
def _joined_rows(cell_of, v_ptr, v_idx, v_val, c_ptr, c_idx, c_grad, count, out_ptr, out_idx,
                 out_val, out_grad, fill):
    """Row r as the merge of the value row r and the gradient row of its cell
    cell_of[r] (both sorted by column); counts (``fill=False``) or writes
    (``fill=True``) as :func:`_smoothed_rows`."""
    nrows = cell_of.shape[0]
    nb = (nrows + _BLOCK - 1) // _BLOCK
    dim = c_grad.shape[0]
    for blk in prange(nb):
        for r in range(blk * _BLOCK, min(nrows, blk * _BLOCK + _BLOCK)):
            c = cell_of[r]
            i, ie, j, je = v_ptr[r], v_ptr[r + 1], c_ptr[c], c_ptr[c + 1]
            n = 0
            at = out_ptr[r] if fill else 0
            while i < ie or j < je:
                vi = v_idx[i] if i < ie else -1
                cj = c_idx[j] if j < je else -1
                take_v = vi >= 0 and (cj < 0 or vi <= cj)
                take_c = cj >= 0 and (vi < 0 or cj <= vi)
                if fill:
                    out_idx[at + n] = vi if take_v else cj
                    out_val[at + n] = v_val[i] if take_v else 0.0
                    for d in range(dim):
                        out_grad[d, at + n] = c_grad[d, j] if take_c else 0.0
                i += take_v
                j += take_c
                n += 1
            if not fill:
                count[r] = n


_joined_rows_serial = serial_twin(_joined_rows)


def _run(kernel, serial, nrows, args, dim):
    """The two passes of a row kernel (count, then fill) into one CSR pattern."""
    kernel = kernel if nrows >= _PARALLEL_MIN else serial
    count = np.zeros(nrows, np.int64)
    ptr = np.zeros(nrows + 1, np.int64)
    kernel(*args, count, ptr, np.empty(0, np.int64), np.empty(0), np.empty((dim, 0)), False)
    np.cumsum(count, out=ptr[1:])
    nnz = int(ptr[-1])
    idx = np.empty(nnz, np.int64)
    val = np.empty(nnz)
    grad = np.empty((dim, nnz))
    kernel(*args, count, ptr, idx, val, grad, True)
    return ptr, idx, val, grad


def _csr(M):
    M.sort_indices()
    return M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data


def combine(V, S, cell_of, pts, coef):
    """Values at the integration points and their cells' smoothed gradients,
    on one sparsity pattern.

    ``V`` is the CSR matrix of the functions' values at the integration points
    (one row each), ``S`` that of the cells' boundary points; ``cell_of`` names
    each integration point's cell, and the smoothed gradient of cell c is
    ``sum_j coef[c, j] * S[pts[c, j]]``. Returns (indptr, indices, values,
    grads (dim, nnz)) of len(cell_of) rows. Where cells hold several points
    (3D: five), each cell's gradient row is merged once and then joined with
    its points' value rows.
    """
    nrows, ncells, dim = cell_of.shape[0], pts.shape[0], coef.shape[2]
    cells = (np.ascontiguousarray(pts), np.ascontiguousarray(coef))
    if nrows <= ncells:
        args = (np.ascontiguousarray(cell_of, dtype=np.int64), *cells, *_csr(V), *_csr(S))
        return _run(_smoothed_rows, _smoothed_rows_serial, nrows, args, dim)
    none = (np.zeros(ncells + 1, np.int64), np.empty(0, np.int64), np.empty(0))
    args = (np.arange(ncells), *cells, *none, *_csr(S))
    c_ptr, c_idx, _, c_grad = _run(_smoothed_rows, _smoothed_rows_serial, ncells, args, dim)
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), *_csr(V), c_ptr, c_idx, c_grad)
    return _run(_joined_rows, _joined_rows_serial, nrows, args, dim)


def with_nodes(Q, nodal):
    """The CSR value rows of points some of which are nodes: row r is ``Q``'s next
    row where ``nodal[r] < 0`` (a queried point), else 1 at column ``nodal[r]``
    (every natural-neighbour function is 1 at its node and 0 at the others)."""
    import scipy.sparse as sp
    ask = nodal < 0
    lengths = np.ones(nodal.size, np.int64)
    lengths[ask] = np.diff(Q.indptr)
    ptr = np.zeros(nodal.size + 1, np.int64)
    np.cumsum(lengths, out=ptr[1:])
    idx = np.empty(ptr[-1], np.int64)
    val = np.ones(ptr[-1])
    at = ptr[:-1][~ask]
    idx[at] = nodal[~ask]
    dest = np.repeat(ptr[:-1][ask] - Q.indptr[:-1], np.diff(Q.indptr)) + np.arange(Q.nnz)
    idx[dest] = Q.indices
    val[dest] = Q.data
    return sp.csr_matrix((val, idx, ptr), shape=(nodal.size, Q.shape[1]))


def smoothed_functions(mesh, coordinates, x, elems, cell_of, nodal=None):
    """Values at the (dim, ne, nq) points x (in the elements ``elems``) and smoothed
    gradients over the cells ``cell_of`` (ne * nq,) of the cells of ``np.unique(elems)``:
    ``(values CSR, gradients (dim, nnz) on its pattern)``. ``coordinates(points,
    hint=...)`` gives the natural-neighbour coordinates (CSR) at (k, dim) points;
    ``nodal`` (ne * nq,) names the node a point is (-1: none), whose values need no
    query."""
    import scipy.sparse as sp
    dim, ne, nq = x.shape
    pts = x.transpose(1, 2, 0).reshape(-1, dim)
    cells = np.unique(elems)
    faces = {}
    if dim == 3:
        points, hint, cp, coef, slot = cells_3d(mesh.p.T, mesh.t, mesh.t2f, mesh.facets, cells)
    elif elems.size < mesh.nelements:
        # a subdomain or an update: without numbering all the mesh's edges
        points, hint, cp, coef = cells_2d_alone(mesh.p.T, mesh.t, cells)
    else:
        points, hint, cp, coef = cells_2d(mesh.p.T, mesh.t, mesh.t2f, mesh.facets, cells)
    ask = slice(None) if nodal is None else nodal < 0
    # one batch: the integration points, then the cells' boundary points
    m = pts[ask].shape[0]
    if dim == 3:
        # the points in their tetrahedra (on the faces), for Watson's decomposition
        faces = {"faces": np.concatenate([np.full(m, -1, np.int64), slot])}
    Phi = coordinates(np.concatenate([pts[ask], points]),
                      hint=np.concatenate([np.repeat(elems, nq)[ask], hint]), **faces)
    V = Phi[:m] if nodal is None else with_nodes(Phi[:m], nodal)
    # 3D: rows past the boundary points are the nodes (cells_3d)
    S = Phi[m:] if dim == 2 else sp.vstack([Phi[m:], sp.identity(Phi.shape[1], format="csr")],
                                           format="csr")
    ptr, idx, val, grad = combine(V, S, cell_of, cp, coef)
    return sp.csr_matrix((val, idx.astype(Phi.indices.dtype), ptr),
                         shape=(ne * nq, Phi.shape[1])), grad
