"""Quadratic natural-neighbour functions: the coordinates in Bernstein form.

Why
---
Natural-neighbour coordinates reproduce linear fields and no more, so a NEM field
converges at rate 2 in L2 and 1 in H1, an order below P2 (Taylor-Hood's velocity) at
about the same number of unknowns. Using the coordinates ``lambda_i`` as the
barycentric variables of a quadratic Bernstein polynomial raises the order by one:

    u(x) = sum_i sum_j lambda_i(x) lambda_j(x) c_ij,

with ``c_ij`` the *polar form* (blossom) ``b(x_i, x_j)`` of the field at the two nodes
(the Bezier form over natural-neighbour coordinates goes back to Farin, CAGD 7, 1990,
who built a C1 cubic one). For a quadratic ``q`` the polar form is symmetric and affine
in each argument, and the coordinates sum to one with ``sum_i lambda_i x_i = x``, so
the sum is ``b(x, x) = q(x)``: quadratics are reproduced exactly, on any node set and
with constrained (visibility-restricted) coordinates alike.

Degrees of freedom
------------------
P2's: the value ``u_i`` at each node and the value ``m_e`` at the midpoint of each
edge of the mesh (the constrained Delaunay triangulation). They give the polar form
where the pair shares an edge, exactly for quadratics:

* ``c_ii = u_i``;
* ``c_ij = 2 m_e - (u_i + u_j) / 2`` for the edge e = (i, j).

Two nodes can be natural neighbours of one point without sharing an edge (the far
vertices of two triangles whose circumcircles overlap there). Their polar form comes
from multi-affinity through a triangle T = (i, a, b) at i: with ``x_j = alpha x_i +
beta x_a + gamma x_b``, ``c_ij = alpha u_i + beta c_ia + gamma c_ib``, averaged with the
same from j's side. T is the triangle whose angle at i contains the direction to j (its
weights are then bounded; any triangle at i would reproduce quadratics).

Along a hull edge or a segment the coordinates are the edge's linear 1D weights, so
there the function is the P2 interpolant of the edge's two nodal values and its midpoint
value: Dirichlet data are imposed on those dofs exactly as for P2.

The functions are numbered nodes first, then edges (``mesh.facets``), which is the
order of scikit-fem's nodal and facet dofs.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..jit import sort_with
from .summation import blocks

__all__ = ["lift", "pair_matrix", "edge_index", "n_functions", "distinct_pairs"]

#: a direction on the boundary of a triangle's angle at i (round-off) still counts as
#: inside it: barycentric weights above -SECTOR_TOL select the triangle
SECTOR_TOL = 1e-12


def n_functions(mesh) -> int:
    """Number of quadratic functions on ``mesh``: one per node and one per edge."""
    return mesh.p.shape[1] + mesh.facets.shape[1]


def lift(mesh, Phi, D=None):
    """The quadratic functions at the points where ``Phi`` holds the coordinates.

    ``Phi`` (m, nodes) CSR of natural-neighbour coordinates, ``D`` their gradients
    (list of dim CSR on Phi's pattern) or None. Returns ``(Q, G)``: the (m, nodes +
    edges) CSR of the quadratic functions and their gradients as a (dim, nnz) array on
    Q's pattern (``(dim, 0)``-shaped entries for ``D=None``: none).
    """
    Phi = sp.csr_matrix(Phi)
    nv = mesh.p.shape[1]
    term_ptr, first, second = _pair_entries(Phi.indptr.astype(np.int64))
    keys, pair = distinct_pairs(Phi.indices.astype(np.int64), first, second, nv)
    C = pair_matrix(mesh, keys)
    dim = 0 if D is None else len(D)
    grads = (np.zeros((0, Phi.nnz)) if D is None
             else np.stack([np.asarray(Dk.data, dtype=float) for Dk in D]))
    args = (term_ptr, first, second, pair, Phi.data.astype(float), grads,
            C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data, n_functions(mesh),
            blocks(Phi.shape[0]))
    count = np.zeros(Phi.shape[0], np.int64)
    _lift_rows(*args, count, np.empty(0, np.int64), np.empty(0), np.empty((dim, 0)), False)
    ptr = np.zeros(Phi.shape[0] + 1, np.int64)
    np.cumsum(count, out=ptr[1:])
    idx, val, grad = np.empty(ptr[-1], np.int64), np.empty(ptr[-1]), np.empty((dim, ptr[-1]))
    _lift_rows(*args, ptr, idx, val, grad, True)
    Q = sp.csr_matrix((val, idx, ptr), shape=(Phi.shape[0], n_functions(mesh)))
    return Q, grad


def _pair_entries(indptr):
    """Every pair of entries (first <= second) of each row, row after row: (term_ptr,
    first, second), row r's pairs at term_ptr[r]:term_ptr[r + 1]."""
    nnz = int(indptr[-1])
    k = np.diff(indptr)
    term_ptr = np.zeros(indptr.size, np.int64)
    np.cumsum(k * (k + 1) // 2, out=term_ptr[1:])
    row = np.repeat(np.arange(indptr.size - 1), k)
    count = indptr[row + 1] - np.arange(nnz)            # entries from this one to the row's end
    first = np.repeat(np.arange(nnz), count)
    start = np.repeat(np.cumsum(count) - count, count)
    second = first + (np.arange(first.size) - start)
    return term_ptr, first, second


def distinct_pairs(indices, first, second, nv):
    """The node pairs ``lo <= hi`` of the entries ``(first[k], second[k])`` (columns
    ``indices``), as ``np.unique(lo * nv + hi, return_inverse=True)`` would give them:
    the pairs grouped by ``lo`` (a counting sort) and each group's few ``hi`` sorted
    apart. At 64,000 nodes the 14.5 million pair terms of the values' rows have 783,000
    distinct pairs: 0.3 s here, 1.2 s by ``np.unique`` (NumPy 2 hashes the keys) and 0.9 s
    by one sort of them."""
    keys = np.empty(first.size, np.int64)
    inverse = np.empty(first.size, np.int64)
    m = _group_pairs(indices, first, second, nv, keys, inverse)
    return keys[:m], inverse


@njit(cache=True)
def _group_pairs(indices, first, second, nv, keys, inverse):
    """The distinct keys ``lo * nv + hi`` into ``keys`` in increasing order, each pair's
    index among them into ``inverse``; returns their number."""
    lo = np.empty(first.size, np.int32)
    hi = np.empty(first.size, np.int32)
    for k in range(first.size):
        a, b = indices[first[k]], indices[second[k]]
        lo[k], hi[k] = min(a, b), max(a, b)
    start = np.zeros(nv + 1, np.int64)
    for k in range(lo.size):
        start[lo[k] + 1] += 1
    for v in range(nv):
        start[v + 1] += start[v]
    at = start[:-1].copy()
    member = np.empty(lo.size, np.int64)
    for k in range(lo.size):
        member[at[lo[k]]] = k
        at[lo[k]] += 1
    slot = np.full(nv, -1, np.int64)
    seen = np.empty(nv, np.int64)
    m = 0
    for v in range(nv):
        n = 0
        for s in range(start[v], start[v + 1]):
            h = hi[member[s]]
            if slot[h] < 0:
                slot[h] = 0
                seen[n] = h
                n += 1
        sort_with(seen, seen, n)
        for a in range(n):
            slot[seen[a]] = m + a
            keys[m + a] = v * nv + seen[a]
        for s in range(start[v], start[v + 1]):
            inverse[member[s]] = slot[hi[member[s]]]
        for a in range(n):
            slot[seen[a]] = -1
        m += n
    return m


@njit(cache=True, parallel=True)
def _lift_rows(term_ptr, first, second, pair, lam, grads, c_ptr, c_idx, c_val, nfun, nb,
               ptr, idx, val, grad, fill):
    """Row by row (Gustavson's sparse product): each pair term lambda_a lambda_b
    (twice for a != b) spread over the functions of its pair's polar value. First
    pass (``fill`` False) counts each row's functions into ``ptr``; the second writes
    them at ``ptr[r]``. ``nb`` blocks of rows (:func:`~.summation.blocks`) run in parallel,
    each with a slot array of its own (8 bytes a function)."""
    m = term_ptr.shape[0] - 1
    for blk in prange(nb):
        slot = np.full(nfun, -1, np.int64)
        for r in range(blk * m // nb, (blk + 1) * m // nb):
            _lift_row(r, term_ptr, first, second, pair, lam, grads, c_ptr, c_idx, c_val,
                      ptr, idx, val, grad, fill, slot)


@njit(cache=True)
def _lift_row(r, term_ptr, first, second, pair, lam, grads, c_ptr, c_idx, c_val,
              ptr, idx, val, grad, fill, slot):
    """Row r of :func:`_lift_rows` (``slot``: -1 for every function on entry and exit)."""
    dim = grads.shape[0]
    n = 0
    base = ptr[r] if fill else 0
    for t in range(term_ptr[r], term_ptr[r + 1]):
        a, b, p = first[t], second[t], pair[t]
        w = 1.0 if a == b else 2.0
        for k in range(c_ptr[p], c_ptr[p + 1]):
            f = c_idx[k]
            if slot[f] < 0:
                slot[f] = base + n
                if fill:
                    idx[base + n] = f
                    val[base + n] = 0.0
                    for d in range(dim):
                        grad[d, base + n] = 0.0
                n += 1
            if fill:
                s = slot[f]
                c = w * c_val[k]
                val[s] += c * lam[a] * lam[b]
                for d in range(dim):
                    grad[d, s] += c * (lam[a] * grads[d, b] + lam[b] * grads[d, a])
    if not fill:
        ptr[r] = n
    # reset the slots of this row's functions
    for t in range(term_ptr[r], term_ptr[r + 1]):
        p = pair[t]
        for k in range(c_ptr[p], c_ptr[p + 1]):
            slot[c_idx[k]] = -1


def pair_matrix(mesh, keys) -> sp.csr_matrix:
    """(pairs, functions) CSR: row k is the polar value of the node pair ``keys[k] =
    lo * nodes + hi`` (lo <= hi) as a combination of nodal and midpoint values."""
    nv = mesh.p.shape[1]
    lo, hi = keys // nv, keys % nv
    k = np.arange(keys.size)
    diag = lo == hi
    table = _edge_table(mesh)
    edge = np.where(diag, -1, edge_index(mesh, lo, hi, table))
    on = ~diag & (edge >= 0)
    rows = [k[diag], k[on], k[on], k[on]]
    cols = [lo[diag], nv + edge[on], lo[on], hi[on]]
    vals = [np.ones(diag.sum()), np.full(on.sum(), 2.0), np.full(on.sum(), -0.5),
            np.full(on.sum(), -0.5)]
    far = np.flatnonzero(~diag & (edge < 0))
    if far.size:
        for s, d in ((lo[far], hi[far]), (hi[far], lo[far])):
            r, c, v = _through_triangle(mesh, s, d, table)
            rows.append(far[r])
            cols.append(c)
            vals.append(0.5 * v)
    C = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(keys.size, n_functions(mesh)))
    C.sum_duplicates()
    return C


def _edge_table(mesh):
    """The mesh edges' keys ``lo * nodes + hi``, sorted, and the edge of each."""
    f = np.sort(mesh.facets, axis=0).astype(np.int64)
    fk = f[0] * mesh.p.shape[1] + f[1]
    order = np.argsort(fk)
    return fk[order], order


def edge_index(mesh, lo, hi, table=None) -> np.ndarray:
    """The mesh edge (facet) joining nodes lo[k] < hi[k], or -1 (``table``: the
    mesh's :func:`_edge_table`, made here if not given)."""
    fk, order = _edge_table(mesh) if table is None else table
    key = np.asarray(lo, np.int64) * mesh.p.shape[1] + np.asarray(hi, np.int64)
    pos = np.minimum(np.searchsorted(fk, key), fk.size - 1)
    return np.where(fk[pos] == key, order[pos], -1)


def _node_triangles(mesh):
    """CSR (ptr, triangles) of the triangles at each node."""
    t = mesh.t
    node = t.T.ravel()
    order = np.argsort(node, kind="stable")
    ptr = np.zeros(mesh.p.shape[1] + 1, np.int64)
    np.cumsum(np.bincount(node, minlength=mesh.p.shape[1]), out=ptr[1:])
    return ptr, np.repeat(np.arange(t.shape[1]), 3)[order]


def _through_triangle(mesh, i, j, table):
    """Polar value of the pairs (i[k], j[k]) by multi-affinity through the triangle at
    i whose angle contains the direction to j (else the one with the smallest
    weights): (pair k, function, coefficient) triplets."""
    ptr, tris = _node_triangles(mesh)
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    a, b = np.empty(i.size, np.int64), np.empty(i.size, np.int64)
    be, ga = np.empty(i.size), np.empty(i.size)
    _best_triangles(np.ascontiguousarray(mesh.p, dtype=np.float64),
                    np.ascontiguousarray(mesh.t, dtype=np.int64), ptr, tris.astype(np.int64),
                    i, j, a, b, be, ga)
    nv = mesh.p.shape[1]
    e_a = edge_index(mesh, np.minimum(i, a), np.maximum(i, a), table)
    e_b = edge_index(mesh, np.minimum(i, b), np.maximum(i, b), table)
    k = np.arange(i.size)
    # alpha u_i + beta (2 m_ia - (u_i + u_a) / 2) + gamma (2 m_ib - (u_i + u_b) / 2)
    alpha = 1.0 - be - ga
    return (np.concatenate([k] * 5), np.concatenate([i, a, b, nv + e_a, nv + e_b]),
            np.concatenate([alpha - 0.5 * (be + ga), -0.5 * be, -0.5 * ga, 2 * be, 2 * ga]))


@njit(cache=True)
def _best_triangles(p, t, ptr, tris, i, j, a_out, b_out, beta_out, gamma_out):
    """For each pair k, the triangle (i[k], a, b) at i[k] in which x_j has barycentric
    weights (beta, gamma) of a and b: the first (in the order of ``tris``) whose angle
    at i holds the direction to j (both weights >= -SECTOR_TOL), else the one with the
    smallest larger weight; among those inside, the smallest too (ties: the first). A
    loop over each node's few triangles (it was a sort of all candidates, 0.55 s of a
    0.57 s pair matrix at 8,000 nodes)."""
    for k in range(i.shape[0]):
        n = i[k]
        best_in, best_size = False, np.inf
        for c in range(ptr[n], ptr[n + 1]):
            tri = tris[c]
            at = 0
            while t[at, tri] != n:
                at += 1
            a, b = t[(at + 1) % 3, tri], t[(at + 2) % 3, tri]
            beta, gamma = _weights(p, n, a, b, j[k])
            size = max(abs(beta), abs(gamma))
            if size != size:
                size = np.inf                   # a degenerate triangle sorts last
            inside = beta >= -SECTOR_TOL and gamma >= -SECTOR_TOL
            if c == ptr[n] or (inside and not best_in) or (inside == best_in
                                                          and size < best_size):
                best_in, best_size = inside, size
                a_out[k], b_out[k], beta_out[k], gamma_out[k] = a, b, beta, gamma


@njit(cache=True)
def _weights(p, i, a, b, j):
    """Barycentric weights (of a and b) of x_j in the triangle (x_i, x_a, x_b)."""
    ea0, ea1 = p[0, a] - p[0, i], p[1, a] - p[1, i]
    eb0, eb1 = p[0, b] - p[0, i], p[1, b] - p[1, i]
    r0, r1 = p[0, j] - p[0, i], p[1, j] - p[1, i]
    det = ea0 * eb1 - ea1 * eb0
    return (r0 * eb1 - r1 * eb0) / det, (ea0 * r1 - ea1 * r0) / det
