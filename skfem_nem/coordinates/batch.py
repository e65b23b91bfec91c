"""Plumbing shared by the coordinate kernels of every dimension.

The 2D area method (:mod:`skfem_nem.coordinates.area2d`) and the n-D Lasserre
method (:mod:`skfem_nem.coordinates.lasserre`) both check query points the same way,
turn the rows their numba kernels write into one CSR sparsity pattern shared
by values and gradients (the Lasserre kernel's padded rows through
:func:`compress`, the area kernel's flat rows through :class:`RowStore`), and
report the same status codes with the same messages.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..geometry.status import AT_NODE, ON_HULL, OUTSIDE


def check_queries(x, d: int) -> np.ndarray:
    """A float64 copy of the (m, d) query points x (a single (d,) point becomes
    (1, d)); ``ValueError`` for a wrong shape or non-finite coordinates,
    naming the first offending query and the count."""
    q = np.array(x, dtype=np.float64, copy=True)
    if q.ndim == 1 and q.shape[0] == d:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != d:
        raise ValueError(f"query points must have shape (m, {d}), got {np.shape(x)}")
    if np.isfinite(q).all():
        return q
    bad = np.flatnonzero(~np.isfinite(q).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{bad.size} query point(s) have non-finite coordinates; first is "
            f"x[{bad[0]}] = {q[bad[0]].tolist()}")
    return q


@njit(cache=True)
def _compress(count, indptr, out_i, out_v, out_g, want_grad, indices, data, grads):
    """Padded rows -> flat CSR arrays: ``out_i``, ``out_v`` (m, cap), ``out_g``
    (k, m, cap) into ``indices``, ``data`` (nnz,) and ``grads`` (k, nnz)."""
    k = out_g.shape[0]
    for r in range(count.shape[0]):
        p0 = indptr[r]
        for j in range(count[r]):
            indices[p0 + j] = out_i[r, j]
            data[p0 + j] = out_v[r, j]
            if want_grad:
                for c in range(k):
                    grads[c, p0 + j] = out_g[c, r, j]


def index_dtype(n: int, nnz: int):
    """int32 for CSR indices when they fit (what scipy would pick), else int64."""
    return np.int32 if max(n, nnz) < 2**31 - 1 else np.int64


def compress(count, out_i, out_v, out_g, gradient: bool, n: int):
    """Flat CSR arrays of padded kernel rows.

    ``count`` (m,) entries per row, ``out_i``/``out_v`` (m, cap) column
    indices and values, ``out_g`` (k, m, cap) gradient components (ignored
    unless ``gradient``). Returns ``(indptr, indices, data, grads)`` with
    ``grads`` of shape (k, nnz) (or (k, 0)), ``indptr`` int64 and
    ``indices`` of :func:`index_dtype`.
    """
    m = count.shape[0]
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(count, out=indptr[1:])
    nnz = int(indptr[-1])
    indices = np.empty(nnz, dtype=index_dtype(n, nnz))
    data = np.empty(nnz)
    grads = np.empty((out_g.shape[0], nnz if gradient else 0))
    _compress(count, indptr, out_i, out_v, out_g, gradient, indices, data, grads)
    return indptr, indices, data, grads


@njit(cache=True)
def _splice(indptr, arrays, rows, indptr2, arrays2, sel, new_indptr, new_arrays):
    """CSR rows (``indptr``, ``arrays``) with the (sorted) rows ``rows``
    replaced by the rows ``sel`` of (``indptr2``, ``arrays2``), written to
    ``new_indptr`` (m + 1,) and ``new_arrays`` (tuples of flat arrays)."""
    m = indptr.shape[0] - 1
    new_indptr[0] = 0
    j = 0
    for r in range(m):
        if j < rows.shape[0] and rows[j] == r:
            src, a, b = 1, indptr2[sel[j]], indptr2[sel[j] + 1]
            j += 1
        else:
            src, a, b = 0, indptr[r], indptr[r + 1]
        p0 = new_indptr[r]
        new_indptr[r + 1] = p0 + b - a
        for k in range(len(new_arrays)):
            if src:
                new_arrays[k][p0:p0 + b - a] = arrays2[k][a:b]
            else:
                new_arrays[k][p0:p0 + b - a] = arrays[k][a:b]


class RowStore:
    """CSR rows on one sparsity pattern: column indices ``indices`` and values
    ``vals`` (lists of k flat arrays, ``nnz`` entries each, possibly with
    slack after them) with row pointers ``indptr`` (m + 1,), ``n`` columns.

    One copy of the indices per matrix (scipy may sort or prune a matrix in
    place); rows sorted by column.
    """

    def __init__(self, n: int, indptr, indices, vals, nnz: int):
        self.n = n
        self.indptr = indptr
        self.indices = list(indices)
        self.vals = list(vals)
        self.nnz = nnz

    @property
    def m(self) -> int:
        return self.indptr.shape[0] - 1

    def replace(self, rows, other: "RowStore", sel):
        """Replace the (sorted) rows ``rows`` by the rows ``sel`` of ``other``."""
        if not rows.size:
            return
        counts = np.diff(self.indptr)
        counts[rows] = np.diff(other.indptr)[sel]
        nnz = int(counts.sum())
        dtype = index_dtype(self.n, nnz)
        indptr = np.empty_like(self.indptr)
        indices = [np.empty(nnz, dtype=dtype) for _ in self.indices]
        vals = [np.empty(nnz) for _ in self.vals]
        for new, old, old2 in ((indices, self.indices, other.indices),
                               (vals, self.vals, other.vals)):
            old = tuple(a.astype(dtype, copy=False) for a in old) if new is indices else tuple(old)
            old2 = (tuple(a.astype(dtype, copy=False) for a in old2) if new is indices
                    else tuple(old2))
            _splice(self.indptr, old, rows, other.indptr, old2, sel, indptr, tuple(new))
        self.indptr, self.indices, self.vals, self.nnz = indptr, indices, vals, nnz

    def matrices(self):
        """The k CSR matrices (m, n), flagged as having sorted indices."""
        nnz = self.nnz
        ind, val = self.indices, self.vals
        if ind[0].shape[0] > nnz + nnz // 16 + 4096:
            # estimate too generous: do not keep the slack alive
            ind = [a[:nnz].copy() for a in ind]
            val = [a[:nnz].copy() for a in val]
        indptr = self.indptr.astype(ind[0].dtype)
        mats = []
        for j in range(len(ind)):
            M = sp.csr_matrix((val[j][:nnz], ind[j][:nnz],
                               indptr if j == 0 else indptr.copy()), shape=(self.m, self.n))
            M.has_sorted_indices = True
            mats.append(M)
        return mats


def raise_outside(status, q, offset=0):
    """``ValueError`` if any query has status OUTSIDE, naming the first and the count."""
    out = np.flatnonzero(status == OUTSIDE)
    if out.size:
        i, xi = _where(out, q, offset)
        raise ValueError(
            f"{out.size} query point(s) lie outside the convex hull of the nodes; "
            f"first is x[{i}] = {xi.tolist()}")


def raise_undefined(status, q, nodes, hull_word: str, offset=0):
    """``ValueError`` for gradients requested at nodes (AT_NODE) or on the hull
    (ON_HULL), naming the first query, the count and, at a node, the node."""
    for code, what in ((AT_NODE, "coincide with a node"), (ON_HULL, f"lie on {hull_word}")):
        bad = np.flatnonzero(status == code)
        if bad.size:
            i, xi = _where(bad, q, offset)
            extra = ""
            if code == AT_NODE:
                j = int(np.flatnonzero((nodes == xi).all(axis=1))[0])
                extra = f" (node {j})"
            raise ValueError(
                f"gradients are undefined at {bad.size} query point(s) that {what}; "
                f"first is x[{i}] = {xi.tolist()}{extra}. Pass undefined='nan' to "
                f"get NaN rows there instead")


def _where(bad, q, offset):
    """(index of the first bad query in q, its point); ``bad`` counts from ``offset``."""
    i = offset + int(bad[0])
    return i, q[i]
