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

In 2D the smoothed gradients and the values at the integration points are
stored on one CSR sparsity pattern per row (an integration point), as the
Gauss path stores coordinates and their gradients, so stencils, groups and
the whole-mesh assembly are unchanged. In 3D the five points of a
tetrahedron share its gradient, which is kept once, beside the values
(:class:`~skfem_nem.basis.cell_rows.CellRows`).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..jit import serial_twin
from .cell_rows import CellRows, gradient_rows, two_pass

#: Gauss-Legendre points per cell edge (2D). Any rule exact for linear
#: functions passes the patch test. Measured on the Poisson problem of
#: docs/verification.md (250-16,000 nodes): 1, 2 and 3 points give the same
#: errors within 7 % (L2: 1 point 6 % lower; H1: 1 % higher) and the same
#: rates; 1 point needs half the evaluations and gives smaller stencils
SEGMENT_POINTS = 1
#: rows per block of the combination kernel (blocks go to threads)
_BLOCK = 1024

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
    other rules in docs/ndim.md)."""
    return _cells_3d(np.ascontiguousarray(p, dtype=np.float64),
                     np.ascontiguousarray(t, dtype=np.int64),
                     np.ascontiguousarray(t2f, dtype=np.int64),
                     np.ascontiguousarray(facets, dtype=np.int64),
                     np.ascontiguousarray(elems, dtype=np.int64))


@njit(cache=True)
def _cells_3d(p, t, t2f, facets, elems):
    """The kernel of :func:`cells_3d`. The faces are numbered in the order of the mesh's
    own numbering; a face shared by two of the tetrahedra is owned by the one met last
    going through the faces slot by slot (slot 3 after slot 0), each slot over ``elems``.
    At 100,000 nodes the same steps in numpy (a sort of the faces) took 2.3 s."""
    k = elems.shape[0]
    local = np.full(facets.shape[1], -1, np.int64)
    for i in range(4):
        for j in range(k):
            local[t2f[i, elems[j]]] = 0
    nf = 0
    for f in range(local.shape[0]):
        if local[f] == 0:
            local[f] = nf
            nf += 1
    points = np.empty((nf, 3))
    own = np.empty(nf, np.int64)
    slot = np.empty(nf, np.int64)
    pts = np.empty((k, 8), np.int64)
    coef = np.empty((k, 8, 3))
    opposite = np.empty((k, 4), np.int64)
    G, E = np.empty((4, 3)), np.empty((3, 3))
    for i in range(4):
        for j in range(k):
            e = elems[j]
            f = t2f[i, e]
            q = local[f]
            a, b, c = facets[0, f], facets[1, f], facets[2, f]
            for d in range(3):
                points[q, d] = (p[a, d] + p[b, d] + p[c, d]) / 3.0
            # the vertex opposite the face: the tetrahedron's node not on it
            o = 0
            while t[o, e] == a or t[o, e] == b or t[o, e] == c:
                o += 1
            opposite[j, i] = o
            own[q] = e
            slot[q] = o
            pts[j, i] = q
            pts[j, 4 + i] = nf + t[i, e]
    for j in range(k):
        _lambda_gradients(p, t, elems[j], E, G)
        for i in range(4):
            for d in range(3):
                coef[j, i, d] = -2.25 * G[opposite[j, i], d]
                coef[j, 4 + i, d] = 0.25 * G[i, d]
    return points, own, pts, coef, slot


@njit(cache=True, inline="always")
def _lambda_gradients(p, t, e, E, G):
    """``G[i]``: the gradient of tetrahedron e's barycentric coordinate i (zero for a flat
    one), as the cofactors of its edges from vertex 0 over their determinant."""
    v0 = t[0, e]
    for r in range(3):
        for d in range(3):
            E[r, d] = p[t[r + 1, e], d] - p[v0, d]
    for r in range(3):
        a, b = E[(r + 1) % 3], E[(r + 2) % 3]
        G[r + 1, 0] = a[1] * b[2] - a[2] * b[1]
        G[r + 1, 1] = a[2] * b[0] - a[0] * b[2]
        G[r + 1, 2] = a[0] * b[1] - a[1] * b[0]
    det = E[0, 0] * G[1, 0] + E[0, 1] * G[1, 1] + E[0, 2] * G[1, 2]
    scale = 0.0 if det == 0.0 else 1.0 / det
    for r in range(1, 4):
        for d in range(3):
            G[r, d] *= scale
    for d in range(3):
        G[0, d] = -((G[1, d] + G[2, d]) + G[3, d])


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


def _csr(M):
    M.sort_indices()
    return M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data


def combine(V, S, cell_of, pts, coef):
    """Values at the integration points and their cells' smoothed gradients,
    on one sparsity pattern.

    ``V`` is the CSR matrix of the functions' values at the integration points
    (one row each), ``S`` that of the cells' boundary points; ``cell_of`` names
    each integration point's cell (no two points share one: a cell of several points
    keeps its gradient row apart, :func:`~skfem_nem.basis.cell_rows.gradient_rows`), and
    the smoothed gradient of cell c is ``sum_j coef[c, j] * S[pts[c, j]]``. Returns
    (indptr, indices, values, grads (dim, nnz)) of len(cell_of) rows.
    """
    nrows, dim = cell_of.shape[0], coef.shape[2]
    cells = (np.ascontiguousarray(pts), np.ascontiguousarray(coef))
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), *cells, *_csr(V), *_csr(S))
    return two_pass(_smoothed_rows, _smoothed_rows_serial, nrows, args, dim)


def with_nodes(Q, nodal):
    """The CSR value rows of points some of which are nodes: row r is ``Q``'s next
    row where ``nodal[r] < 0`` (a queried point), else 1 at column ``nodal[r]``
    (every natural-neighbour function is 1 at its node and 0 at the others)."""
    import scipy.sparse as sp
    ptr, idx, val = node_rows(Q, nodal)
    return sp.csr_matrix((val, idx, ptr), shape=(nodal.size, Q.shape[1]))


def node_rows(Q, nodal):
    """:func:`with_nodes` as ``(indptr, indices (int64), data)``, no scipy matrix (whose
    constructor copies the indices to a smaller type)."""
    nodal = np.ascontiguousarray(nodal, dtype=np.int64)
    ask = nodal < 0
    lengths = np.ones(nodal.size, np.int64)
    lengths[ask] = np.diff(Q.indptr)
    ptr = np.zeros(nodal.size + 1, np.int64)
    np.cumsum(lengths, out=ptr[1:])
    idx = np.empty(ptr[-1], np.int64)
    val = np.empty(ptr[-1])
    source = np.full(nodal.size, -1, np.int64)
    source[ask] = np.arange(Q.shape[0])
    _node_rows(np.asarray(Q.indptr, np.int64), np.asarray(Q.indices, np.int64), Q.data, nodal,
               source, ptr, idx, val)
    return ptr, idx, val


@njit(cache=True, parallel=True)
def _node_rows(qptr, qidx, qval, nodal, source, ptr, idx, val):
    """Row r: 1 at ``nodal[r]``, or (``nodal[r] < 0``) row ``source[r]`` of Q."""
    for r in prange(nodal.shape[0]):
        d = ptr[r]
        if nodal[r] >= 0:
            idx[d] = nodal[r]
            val[d] = 1.0
            continue
        q = source[r]
        for k in range(qptr[q], qptr[q + 1]):
            idx[d + k - qptr[q]] = qidx[k]
            val[d + k - qptr[q]] = qval[k]


def _rows_3d(Phi, nodal, ne, nq, nf, cell_of, cp, coef):
    """3D: the values at the integration points (``nodal`` or all queried: the first rows
    of ``Phi``) and the cells' gradients from the face rows that follow, as
    :class:`~skfem_nem.basis.cell_rows.CellRows`. Node rows are appended after the face
    rows (:func:`cells_3d` numbers them so), all in one copy of ``Phi``."""
    n = Phi.shape[1]
    Phi.sort_indices()
    lead = np.full(ne * nq, -1, np.int64) if nodal is None else nodal
    ptr, idx, val = node_rows(Phi, np.concatenate([lead, np.full(nf, -1, np.int64),
                                                   np.arange(n)]))
    r0 = ne * nq
    grads = gradient_rows(cp, coef, (ptr[r0:], idx, val), n)
    # the points' rows alone are kept: the face and node rows after them were for the
    # gradients only (a third of the entries; 30 MB at 10,000 nodes)
    m = int(ptr[r0])
    return CellRows((ptr[:r0 + 1], idx[:m].copy(), val[:m].copy()), (r0, n), cell_of, *grads)


def smoothed_functions(mesh, coordinates, x, elems, cell_of, nodal=None):
    """Values at the (dim, ne, nq) points x (in the elements ``elems``) and smoothed
    gradients over the cells ``cell_of`` (ne * nq,) of the cells of ``np.unique(elems)``:
    2D ``(values CSR, gradients (dim, nnz) on its pattern)``, 3D (one cell per
    tetrahedron) the values and the cells' gradient rows apart, a
    :class:`~skfem_nem.basis.cell_rows.CellRows`. ``coordinates(points, hint=...)`` gives
    the natural-neighbour coordinates (CSR) at (k, dim) points; ``nodal`` (ne * nq,) names
    the node a point is (-1: none), whose values need no query."""
    import scipy.sparse as sp
    dim, ne, nq = x.shape
    pts = x.transpose(1, 2, 0).reshape(-1, dim)
    # (a whole mesh's or a subdomain's elements come sorted: no sort of them again)
    cells = elems if np.all(elems[1:] > elems[:-1]) else np.unique(elems)
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
    if dim == 3:
        return _rows_3d(Phi, nodal, ne, nq, points.shape[0], cell_of, cp, coef)
    V = Phi[:m] if nodal is None else with_nodes(Phi[:m], nodal)
    ptr, idx, val, grad = combine(V, Phi[m:], cell_of, cp, coef)
    return sp.csr_matrix((val, idx.astype(Phi.indices.dtype), ptr),
                         shape=(ne * nq, Phi.shape[1])), grad
