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

3D: the cell is the tetrahedron itself; its four faces (shared with the
neighbouring tetrahedra) are evaluated once each at ``FACE_POINTS`` points,
and the 4-point rule's points share the tetrahedron's smoothed gradient.

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


def value_rule(dim: int):
    """The reference-cell rule (X, W) whose points carry values and the
    smoothed gradients: 2D the 3-point rule (point i in vertex i's cell),
    3D the 4-point rule."""
    if dim == 2:
        return _X3.copy(), _W3.copy()
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTet
    return get_quadrature(RefTet, 2)


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
    """Face points of the tetrahedra ``elems`` (one cell each; the 3-point
    rule of degree 2 on each face); as :func:`cells_2d`, with cell j the
    tetrahedron elems[j]. Vectorised numpy: in 3D the coordinates, not the
    cells, are the cost."""
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTri
    X, W = get_quadrature(RefTri, 2)
    lam = np.vstack([1.0 - X.sum(axis=0), X])           # (3, nfp) barycentric
    w = 2.0 * W                                         # weights summing to 1
    nfp = w.size
    k = elems.size
    F = t2f[:, elems].T                                 # (k, 4)
    fac, finv = np.unique(F.ravel(), return_inverse=True)
    finv = finv.reshape(k, 4)
    FV = p[facets[:, fac].T]                            # (nf, 3, 3)
    points = np.einsum("fvd,vq->fqd", FV, lam).reshape(-1, 3)
    own = np.empty(fac.size, dtype=np.int64)
    own[finv.ravel()] = np.repeat(elems, 4)
    V = p[t[:, elems].T]                                # (k, 4, 3)
    vol = np.abs(np.einsum("kd,kd->k", V[:, 1] - V[:, 0],
                           np.cross(V[:, 2] - V[:, 0], V[:, 3] - V[:, 0]))) / 6.0
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(vol > 0, 1.0 / vol, 0.0)       # flat tetrahedra: no gradient
    pts = np.empty((k, 4, nfp), dtype=np.int64)
    coef = np.empty((k, 4, nfp, 3))
    g = V.mean(axis=1)
    for f in range(4):
        A = FV[finv[:, f]]                              # the facet's own vertex order
        nA = 0.5 * np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
        # outward: away from the tetrahedron's centroid
        out = np.einsum("kd,kd->k", nA, A.mean(axis=1) - g) > 0
        nA *= np.where(out, 1.0, -1.0)[:, None]
        pts[:, f] = finv[:, f][:, None] * nfp + np.arange(nfp)
        coef[:, f] = nA[:, None, :] * w[None, :, None]
    coef *= scale[:, None, None, None]
    return points, np.repeat(own, nfp), pts.reshape(k, 4 * nfp), coef.reshape(k, 4 * nfp, 3)


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


def combine(Phi, cell_of, pts, coef):
    """Values at the integration points and their cells' smoothed gradients,
    on one sparsity pattern.

    ``Phi`` is the CSR matrix of the coordinates at the integration points
    (rows 0 .. len(cell_of) - 1) and at the cells' boundary points (rows
    ``pts``); ``cell_of`` names each integration point's cell, and the
    smoothed gradient of cell c is ``sum_j coef[c, j] * Phi[pts[c, j]]``.
    Returns (indptr, indices, values, grads (dim, nnz)) of len(cell_of) rows.
    """
    nrows = cell_of.shape[0]
    kernel = _smoothed_rows if nrows >= _PARALLEL_MIN else _smoothed_rows_serial
    Phi.sort_indices()
    ip, ix = Phi.indptr.astype(np.int64), Phi.indices.astype(np.int64)
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), np.ascontiguousarray(pts),
            np.ascontiguousarray(coef), ip, ix, Phi.data, ip, ix, Phi.data)
    dim = coef.shape[2]
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
