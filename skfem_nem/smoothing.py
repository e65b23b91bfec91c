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

from ._numba import serial_twin

#: Gauss-Legendre points per cell edge (2D). Any rule exact for linear
#: functions passes the patch test; 2 points measured as accurate as 3
#: (errors within 0.3 % on 250-16,000 nodes), 1 point is not tested
SEGMENT_POINTS = 2
#: points of the triangle rule on each face of a tetrahedron (3D): degree 2
FACE_POINTS = 3
#: rows per block of the combination kernel (one scratch array per block)
_BLOCK = 4096
#: rows below which the serial kernel runs (waking threads costs more)
_PARALLEL_MIN = 20000

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

def _rot(d):
    """(..., 2) vectors turned by -90 degrees: the outward normal times length
    of an edge traversed counter-clockwise."""
    return np.stack([d[..., 1], -d[..., 0]], axis=-1)


def cells_2d(p, t, t2f, facets, elems):
    """Boundary points of the vertex cells of the triangles ``elems``.

    Returns (points (m, 2), hint (m,) triangle of each point, pts (3 k, 4 s)
    point indices per cell, coef (3 k, 4 s, 2)): the smoothed gradient of a
    function over cell 3 j + i (vertex i of triangle elems[j]) is
    ``sum_r coef[c, r] * phi(points[pts[c, r]])``.
    """
    s, w = np.polynomial.legendre.leggauss(SEGMENT_POINTS)
    s, w = 0.5 * (s + 1.0), 0.5 * w
    ns = s.size
    k = elems.size
    T = t[:, elems].T                                   # (k, 3)
    F = t2f[:, elems].T                                 # (k, 3): edge (i, i+1)
    fac, finv = np.unique(F.ravel(), return_inverse=True)
    finv = finv.reshape(k, 3)
    a, b = p[facets[0, fac]], p[facets[1, fac]]
    m = 0.5 * (a + b)
    # half-edges: half 0 from a to m, half 1 from m to b
    half = np.stack([a[:, None] + s[None, :, None] * (m - a)[:, None],
                     m[:, None] + s[None, :, None] * (b - m)[:, None]], axis=1)  # (nf, 2, ns, 2)
    V = p[T]                                            # (k, 3, 2)
    g = V.mean(axis=1)
    mid = m[finv]                                       # (k, 3, 2) midpoint of edge (i, i+1)
    inner = mid[:, :, None] + s[None, None, :, None] * (g[:, None, None] - mid[:, :, None])
    nh = fac.size * 2 * ns
    points = np.concatenate([half.reshape(-1, 2), inner.reshape(-1, 2)])
    # a triangle to start each point's search from
    hint = np.concatenate([np.repeat(_first_owner(finv, elems, fac.size), 2 * ns),
                           np.repeat(elems, 3 * ns)])
    det = ((V[:, 1, 0] - V[:, 0, 0]) * (V[:, 2, 1] - V[:, 0, 1])
           - (V[:, 1, 1] - V[:, 0, 1]) * (V[:, 2, 0] - V[:, 0, 0]))
    sgn = np.sign(det)
    area = np.abs(det) / 6.0                            # |T| / 3 per cell
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(area > 0, sgn / area, 0.0)
    pts = np.empty((k, 3, 4, ns), dtype=np.int64)
    coef = np.empty((k, 3, 4, ns, 2))
    r = np.arange(ns)
    for i in range(3):
        j = (i + 2) % 3                                 # edge (i - 1, i)
        vi, mi, mj = V[:, i], mid[:, i], mid[:, j]
        # 1. half of edge (i, i+1) at vertex i, from vertex i to its midpoint
        hi = np.where(facets[0, fac[finv[:, i]]] == T[:, i], 0, 1)
        pts[:, i, 0] = (finv[:, i] * 2 + hi)[:, None] * ns + r
        coef[:, i, 0] = _rot(mi - vi)[:, None, :] * w[None, :, None]
        # 2. midpoint of edge (i, i+1) to the centroid
        pts[:, i, 1] = nh + (np.arange(k) * 3 + i)[:, None] * ns + r
        coef[:, i, 1] = _rot(g - mi)[:, None, :] * w[None, :, None]
        # 3. centroid to the midpoint of edge (i - 1, i)
        pts[:, i, 2] = nh + (np.arange(k) * 3 + j)[:, None] * ns + r
        coef[:, i, 2] = _rot(mj - g)[:, None, :] * w[None, :, None]
        # 4. half of edge (i - 1, i) at vertex i, from its midpoint to vertex i
        hj = np.where(facets[0, fac[finv[:, j]]] == T[:, i], 0, 1)
        pts[:, i, 3] = (finv[:, j] * 2 + hj)[:, None] * ns + r
        coef[:, i, 3] = _rot(vi - mj)[:, None, :] * w[None, :, None]
    coef *= scale[:, None, None, None, None]
    return (points, hint, pts.reshape(3 * k, 4 * ns),
            coef.reshape(3 * k, 4 * ns, 2))


def _first_owner(finv, elems, nf):
    """For each of nf facets a triangle of ``elems`` that has it."""
    own = np.empty(nf, dtype=np.int64)
    own[finv.ravel()] = np.repeat(elems, 3)
    return own


# local vertices of the faces of a tetrahedron in scikit-fem's t2f order,
# and the vertex opposite each
_TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
_TET_OPPOSITE = np.array([3, 2, 1, 0])


def cells_3d(p, t, t2f, facets, elems):
    """Face points of the tetrahedra ``elems`` (one cell each); as
    :func:`cells_2d`, with cell j the tetrahedron elems[j]."""
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
    for f in range(4):
        A = FV[finv[:, f]]                              # the facet's own vertex order
        nA = 0.5 * np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
        out = np.einsum("kd,kd->k", nA, V[:, _TET_OPPOSITE[f]] - A[:, 0]) < 0
        nA *= np.where(out, 1.0, -1.0)[:, None]
        pts[:, f] = finv[:, f][:, None] * nfp + np.arange(nfp)
        coef[:, f] = nA[:, None, :] * w[None, :, None]
    coef *= scale[:, None, None, None]
    return points, np.repeat(own, nfp), pts.reshape(k, 4 * nfp), coef.reshape(k, 4 * nfp, 3)


# ---------------------------------------------------------------------------
# values and smoothed gradients on one pattern
# ---------------------------------------------------------------------------

@njit(cache=True, parallel=True)
def _smoothed_rows(cell_of, pts, coef, v_ptr, v_idx, v_val, s_ptr, s_idx, s_val, n,
                   count, out_ptr, out_idx, out_val, out_grad, fill):
    """Rows of values and smoothed gradients, one per integration point.

    Row r joins the value row r of (v_ptr, v_idx, v_val) with the rows
    pts[cell_of[r]] of (s_ptr, s_idx, s_val) weighted by coef[cell_of[r]]
    (the boundary integral of each function over the cell). With
    ``fill=False`` it only counts each row's distinct columns into
    ``count``; with ``fill=True`` it writes the row at out_ptr[r], columns
    sorted. A dense marker per block of rows (size n) finds repeated columns.
    """
    nrows = cell_of.shape[0]
    dim = coef.shape[2]
    nb = (nrows + _BLOCK - 1) // _BLOCK
    for blk in prange(nb):
        mark = np.full(n, -1, np.int64)
        where = np.empty(n, np.int64)
        gi = np.empty(dim)
        for r in range(blk * _BLOCK, min(nrows, blk * _BLOCK + _BLOCK)):
            c = cell_of[r]
            cnt = 0
            base = out_ptr[r] if fill else 0
            for kk in range(v_ptr[r], v_ptr[r + 1]):
                col = v_idx[kk]
                if mark[col] != r:
                    mark[col] = r
                    where[col] = base + cnt
                    if fill:
                        out_idx[base + cnt] = col
                        out_val[base + cnt] = 0.0
                        for d in range(dim):
                            out_grad[d, base + cnt] = 0.0
                    cnt += 1
                if fill:
                    out_val[where[col]] += v_val[kk]
            for j in range(pts.shape[1]):
                q = pts[c, j]
                for kk in range(s_ptr[q], s_ptr[q + 1]):
                    col = s_idx[kk]
                    if mark[col] != r:
                        mark[col] = r
                        where[col] = base + cnt
                        if fill:
                            out_idx[base + cnt] = col
                            out_val[base + cnt] = 0.0
                            for d in range(dim):
                                out_grad[d, base + cnt] = 0.0
                        cnt += 1
                    if fill:
                        pos = where[col]
                        for d in range(dim):
                            out_grad[d, pos] += coef[c, j, d] * s_val[kk]
            if not fill:
                count[r] = cnt
                continue
            # sort the row by column (insertion sort: rows hold ~10-30 entries)
            for a in range(base + 1, base + cnt):
                ci, vi = out_idx[a], out_val[a]
                for d in range(dim):
                    gi[d] = out_grad[d, a]
                b = a
                while b > base and out_idx[b - 1] > ci:
                    out_idx[b] = out_idx[b - 1]
                    out_val[b] = out_val[b - 1]
                    for d in range(dim):
                        out_grad[d, b] = out_grad[d, b - 1]
                    b -= 1
                out_idx[b] = ci
                out_val[b] = vi
                for d in range(dim):
                    out_grad[d, b] = gi[d]


_smoothed_rows_serial = serial_twin(_smoothed_rows)


def combine(Phi_v, cell_of, Phi_s, pts, coef):
    """Values at the integration points (CSR ``Phi_v``, one row each) and
    their cells' smoothed gradients, on one sparsity pattern.

    ``cell_of`` (rows,) names each row's cell; the smoothed gradient of
    cell c is ``sum_j coef[c, j] * Phi_s[pts[c, j]]``. Returns (indptr,
    indices, values, grads (dim, nnz)).
    """
    nrows, n = Phi_v.shape
    kernel = _smoothed_rows if nrows >= _PARALLEL_MIN else _smoothed_rows_serial
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), np.ascontiguousarray(pts),
            np.ascontiguousarray(coef),
            Phi_v.indptr.astype(np.int64), Phi_v.indices.astype(np.int64), Phi_v.data,
            Phi_s.indptr.astype(np.int64), Phi_s.indices.astype(np.int64), Phi_s.data, n)
    dim = coef.shape[2]
    count = np.zeros(nrows, np.int64)
    ptr = np.zeros(nrows + 1, np.int64)
    none_i, none_f = np.empty(0, np.int64), np.empty(0)
    kernel(*args, count, ptr, none_i, none_f, np.empty((dim, 0)), False)
    np.cumsum(count, out=ptr[1:])
    nnz = int(ptr[-1])
    idx = np.empty(nnz, np.int64)
    val = np.empty(nnz)
    grad = np.empty((dim, nnz))
    kernel(*args, count, ptr, idx, val, grad, True)
    return ptr, idx, val, grad
