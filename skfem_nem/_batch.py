"""Plumbing shared by the coordinate kernels of every dimension.

The 2D area method (:mod:`skfem_nem.coordinates`) and the n-D Lasserre
method (:mod:`skfem_nem.lasserre`) both check query points the same way,
write padded per-query rows from their numba kernels, compress them into one
CSR sparsity pattern shared by values and gradients, and report the same
status codes with the same messages.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

# status codes of the query kernels
OK = 0
OUTSIDE = 1
OVERFLOW = 2
AT_NODE = 3
ON_HULL = 4
UNBOUNDED = 5


def check_queries(x, d: int) -> np.ndarray:
    """A float64 copy of the (m, d) query points x (a single (d,) point becomes
    (1, d)); ``ValueError`` for a wrong shape or non-finite coordinates,
    naming the first offending query and the count."""
    q = np.array(x, dtype=np.float64, copy=True)
    if q.ndim == 1 and q.shape[0] == d:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != d:
        raise ValueError(f"query points must have shape (m, {d}), got {np.shape(x)}")
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


def csr_family(indptr, indices, values, shape):
    """One CSR matrix per array in ``values`` on the same (indptr, indices)
    pattern (each matrix gets its own copy of the index arrays)."""
    indptr = indptr.astype(indices.dtype, copy=False)
    mats = [sp.csr_matrix((values[0], indices, indptr), shape=shape)]
    for v in values[1:]:
        mats.append(sp.csr_matrix((v, indices.copy(), indptr.copy()), shape=shape))
    return mats


@njit(cache=True, parallel=True)
def _gather(count, offset, rows, out_i, out_v, out_g, ind0, ind1, ind2, val0, val1, val2,
            nblocks):
    """Padded rows -> flat arrays, in parallel blocks of rows.

    Row ``rows[r]`` of ``out_i``, ``out_v`` (mc, cap) and ``out_g`` (2, mc,
    cap) (all rows in order if ``rows`` is empty) has ``count[r]`` entries,
    which go from position ``offset[r]`` on to ``ind0`` (column indices),
    ``val0`` (values) and, if ``ind1`` is not empty, to ``ind1``, ``ind2``
    (copies of the indices) and ``val1``, ``val2`` (gradients).
    """
    m = count.shape[0]
    sel = rows.shape[0] > 0
    grad = ind1.shape[0] > 0
    for blk in prange(nblocks):
        for r in range(blk * m // nblocks, (blk + 1) * m // nblocks):
            src = rows[r] if sel else r
            p0 = offset[r]
            for j in range(count[r]):
                ind0[p0 + j] = out_i[src, j]
                val0[p0 + j] = out_v[src, j]
                if grad:
                    ind1[p0 + j] = out_i[src, j]
                    ind2[p0 + j] = out_i[src, j]
                    val1[p0 + j] = out_g[0, src, j]
                    val2[p0 + j] = out_g[1, src, j]


@njit(cache=True)
def _move_rows(indptr, new_indptr, rows, arrays, new_arrays):
    """Copy the entries of every row except ``rows`` (sorted) from each of
    ``arrays`` (CSR layout ``indptr``) to ``new_arrays`` (layout ``new_indptr``)."""
    j = 0
    for r in range(indptr.shape[0] - 1):
        if j < rows.shape[0] and rows[j] == r:
            j += 1
            continue
        a = indptr[r]
        b = new_indptr[r]
        for e in range(indptr[r + 1] - a):
            for k in range(len(arrays)):
                new_arrays[k][b + e] = arrays[k][a + e]


@njit(cache=True)
def _touch(a):
    """Write one element per 4 KiB page of the flat array ``a`` (fault its
    pages in from one thread: concurrent first touches of the same pages from
    several threads serialise in the kernel and cost far more)."""
    step = max(1, 4096 // a.itemsize)
    for i in range(0, a.shape[0], step):
        a[i] = 0


class RowStore:
    """CSR matrices with one sparsity pattern: values and, optionally, two
    gradient components, filled chunk by chunk from padded kernel rows with
    sorted indices.

    ``m`` rows, ``n`` columns, ``k`` = 1 or 3 matrices, each with its own
    copy of the column indices (scipy may sort or prune one matrix in place).
    The flat arrays grow by an estimate from the rows seen so far (in practice
    they are allocated once), and rows are gathered into them in parallel.
    """

    def __init__(self, m: int, n: int, k: int):
        if k not in (1, 3):
            raise ValueError(f"k must be 1 or 3, got {k}")
        self.m, self.n, self.k = m, n, k
        self.indptr = np.zeros(m + 1, dtype=np.int64)
        self.nnz = 0
        self.indices = [np.empty(0, dtype=index_dtype(n, 0)) for _ in range(k)]
        self.vals = [np.empty(0) for _ in range(k)]

    def _targets(self):
        """The 6 flat arrays :func:`_gather` writes (empty ones for k = 1)."""
        ind, val = self.indices, self.vals
        if self.k == 1:
            ind = ind + [ind[0][:0]] * 2
            val = val + [val[0][:0]] * 2
        return (*ind, *val)

    def _reserve(self, need: int, rows_done: int):
        """Room for ``need`` entries; more for the rows still to come."""
        if need <= self.indices[0].shape[0]:
            return
        rest = self.m - rows_done
        cap = need + int(1.02 * rest * need / max(rows_done, 1)) + 1024
        dtype = index_dtype(self.n, cap)
        for lst, dt in ((self.indices, dtype), (self.vals, np.float64)):
            for j in range(self.k):
                a = np.empty(cap, dtype=dt)
                _touch(a)
                a[:self.nnz] = lst[j][:self.nnz]
                lst[j] = a

    def append(self, r0: int, count, buffers, nthreads: int = 1):
        """Add rows r0, ..., r0 + mc - 1 (the next ones): ``count`` (mc,) entries
        of the padded ``buffers`` = (out_i, out_v (mc', cap), out_g (2, mc', cap))."""
        mc = count.shape[0]
        offset = self.indptr[r0:r0 + mc + 1]
        np.cumsum(count, out=offset[1:])
        offset[1:] += self.nnz
        need = int(offset[-1])
        self._reserve(need, r0 + mc)
        nblocks = max(1, min(mc // 1024, 8 * nthreads))
        _gather(count, offset[:-1], np.empty(0, np.int64), *buffers, *self._targets(),
                nblocks)
        self.nnz = need

    def replace(self, rows, sel, count, buffers):
        """Replace the (sorted) rows ``rows`` by rows ``sel`` of the padded
        ``buffers``, with ``count`` entries each (after all rows were added)."""
        if not rows.size:
            return
        sizes = np.diff(self.indptr)
        sizes[rows] = count
        indptr = np.zeros_like(self.indptr)
        np.cumsum(sizes, out=indptr[1:])
        nnz = int(indptr[-1])
        dtype = index_dtype(self.n, nnz)
        indices = [np.empty(nnz, dtype=dtype) for _ in range(self.k)]
        vals = [np.empty(nnz) for _ in range(self.k)]
        for new, old in ((indices, self.indices), (vals, self.vals)):
            _move_rows(self.indptr, indptr, rows, tuple(old), tuple(new))
        self.indptr, self.indices, self.vals, self.nnz = indptr, indices, vals, nnz
        _gather(count, indptr[rows], sel, *buffers, *self._targets(), 1)

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
        for j in range(self.k):
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
