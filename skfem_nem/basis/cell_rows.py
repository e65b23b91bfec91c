"""Values and smoothed gradients kept apart: one gradient row per smoothing cell.

Why
---
On tetrahedra the smoothing cell is the tetrahedron itself, and its five points (the
vertices and the centroid, :func:`~skfem_nem.basis.smoothing.value_rule`) share one smoothed
gradient. Written on one sparsity pattern with the values, as the bases of triangles store
them, every gradient is copied to five rows: at 100,000 nodes those joined rows took 4.2 s
and 2.7 GB, more than the coordinates. :class:`CellRows` keeps the value rows (the vertex
rows hold a single 1) and one gradient row per cell; the stencils and the stencils'
gradients, all the assembly of gradient terms reads
(:func:`~skfem_nem.basis.summation.sum_coo_gradients`), come straight from them. The joined
rows are made only for a reader that asks for them (:meth:`CellRows.joined`), and then they
are bitwise those the joined construction gave.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..jit import serial_twin, sort_with

__all__ = ["CellRows", "count_then_fill", "gradient_rows", "join_rows", "two_pass"]

#: rows per block of the row kernels (blocks go to threads)
_BLOCK = 1024
#: rows below which the serial kernels run (waking threads costs more: about 0.3 us per
#: row serially, so from a few blocks on two threads gain)
PARALLEL_MIN = 4096


@njit(cache=True, parallel=True)
def _joined_rows(cell_of, v_ptr, v_idx, v_val, c_ptr, c_idx, c_grad, count, out_ptr, out_idx,
                 out_val, out_grad, fill):
    """Row r as the merge of the value row r and the gradient row of its cell
    cell_of[r] (both sorted by column); counts (``fill=False``) or writes
    (``fill=True``) as :func:`two_pass` runs it."""
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


def count_then_fill(kernel, serial, nrows, args, outputs):
    """Run a row kernel twice: counting each row's entries (``fill`` 0), then writing
    them at the prefix sums of the counts (``fill`` 1); ``outputs(nnz)`` makes the arrays
    the kernel writes (``outputs(0)``: the empty ones of the counting pass). Returns
    ``(indptr, outputs)``. The serial twin below :data:`PARALLEL_MIN` rows."""
    kernel = kernel if nrows >= PARALLEL_MIN else serial
    count = np.zeros(nrows, np.int64)
    ptr = np.zeros(nrows + 1, np.int64)
    kernel(*args, count, ptr, *outputs(0), 0)       # ``fill`` as an integer: kernels
    np.cumsum(count, out=ptr[1:])                    # with more modes share the signature
    out = outputs(int(ptr[-1]))
    kernel(*args, count, ptr, *out, 1)
    return ptr, out


def two_pass(kernel, serial, nrows, args, dim):
    """:func:`count_then_fill` of a kernel writing columns, values and gradients: one CSR
    pattern ``(indptr, indices, values, gradients (dim, nnz))``."""
    ptr, (idx, val, grad) = count_then_fill(
        kernel, serial, nrows, args,
        lambda nnz: (np.empty(nnz, np.int64), np.empty(nnz), np.empty((dim, nnz))))
    return ptr, idx, val, grad


def join_rows(V, cell_of, c_ptr, c_idx, c_grad):
    """Row r of the values ``V = (indptr, indices, data)`` (int64, rows sorted) joined with
    the gradient row ``cell_of[r]`` of ``(c_ptr, c_idx, c_grad)``: ``(indptr, indices,
    values, gradients)`` on the union of the two patterns."""
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), *V, c_ptr, c_idx, c_grad)
    return two_pass(_joined_rows, _joined_rows_serial, cell_of.shape[0], args,
                    c_grad.shape[0])


@njit(cache=True, parallel=True)
def _stencils(nq, cell_of, v_ptr, v_idx, c_ptr, c_idx, n, count, ptr, sten, fill):
    """Element e's stencil: the union of its points' value rows and its cell's gradient
    row, sorted (counts, then fills at ``ptr[e]``). A node is marked when first met, so
    each source is read once (a merge of the nq + 1 sorted rows compared all their heads at
    every step)."""
    ne = count.shape[0]
    nb = (ne + _BLOCK - 1) // _BLOCK
    for blk in prange(nb):
        mark = np.full(n, -1, np.int64)
        nodes = np.empty(0 if not fill else n, np.int64)
        slots = np.empty(0 if not fill else n, np.int64)
        for e in range(blk * _BLOCK, min(ne, blk * _BLOCK + _BLOCK)):
            cnt = 0
            c = cell_of[e * nq]
            for j in range(nq + 1):
                lo = c_ptr[c] if j == nq else v_ptr[e * nq + j]
                hi = c_ptr[c + 1] if j == nq else v_ptr[e * nq + j + 1]
                for k in range(lo, hi):
                    node = c_idx[k] if j == nq else v_idx[k]
                    if mark[node] != e:
                        mark[node] = e
                        if fill:
                            nodes[cnt] = node
                            slots[cnt] = cnt
                        cnt += 1
            if not fill:
                count[e] = cnt
                continue
            sort_with(nodes, slots, cnt)
            for i in range(cnt):
                sten[ptr[e] + i] = nodes[i]


_stencils_serial = serial_twin(_stencils)


@njit(cache=True, parallel=True)
def _gradient_rows(pts, coef, s_ptr, s_idx, s_val, n, count, out_ptr, out_idx, out_grad,
                   fill):
    """Cell c's gradient row ``sum_j coef[c, j] * S[pts[c, j]]``, sorted by column (counts,
    then fills at ``out_ptr[c]``). Each column's terms are added in the order of j, as a
    merge of the rows adds them; a column is placed when first met and the row sorted at
    the end (the merge of eight rows compared all their heads at every step)."""
    ncells, m = pts.shape
    dim = coef.shape[2]
    nb = (ncells + _BLOCK - 1) // _BLOCK
    for blk in prange(nb):
        mark = np.full(n, -1, np.int64)
        where = np.empty(n, np.int64)
        nodes = np.empty(0 if not fill else n, np.int64)
        slots = np.empty(0 if not fill else n, np.int64)
        acc = np.empty((0 if not fill else n, dim))
        for c in range(blk * _BLOCK, min(ncells, blk * _BLOCK + _BLOCK)):
            cnt = 0
            for j in range(m):
                q = pts[c, j]
                for k in range(s_ptr[q], s_ptr[q + 1]):
                    node = s_idx[k]
                    if mark[node] != c:
                        mark[node] = c
                        where[node] = cnt
                        if fill:
                            nodes[cnt] = node
                            slots[cnt] = cnt
                            for d in range(dim):
                                acc[cnt, d] = 0.0
                        cnt += 1
                    if fill:
                        for d in range(dim):
                            acc[where[node], d] += coef[c, j, d] * s_val[k]
            if not fill:
                count[c] = cnt
                continue
            sort_with(nodes, slots, cnt)
            for i in range(cnt):
                out_idx[out_ptr[c] + i] = nodes[i]
                for d in range(dim):
                    out_grad[d, out_ptr[c] + i] = acc[slots[i], d]


_gradient_rows_serial = serial_twin(_gradient_rows)


def gradient_rows(pts, coef, S, n: int):
    """The cells' gradient rows ``(c_ptr, c_idx, c_grad (dim, nnz))``: row c is
    ``sum_j coef[c, j] * S[pts[c, j]]``, ``S = (indptr, indices, data)`` (int64 indices,
    rows sorted; row r at ``indices[indptr[r]:indptr[r + 1]]``, which need not start at 0)
    of n columns."""
    dim = coef.shape[2]
    args = (np.ascontiguousarray(pts), np.ascontiguousarray(coef), *S, n)
    ptr, (idx, grad) = count_then_fill(
        _gradient_rows, _gradient_rows_serial, pts.shape[0], args,
        lambda nnz: (np.empty(nnz, np.int64), np.empty((dim, nnz))))
    return ptr, idx, grad


@njit(cache=True, parallel=True)
def _stencil_gradients(nq, cell_of, ptr, sten, c_ptr, c_idx, c_grad, Gs):
    """``Gs[s]``: the gradient of stencil function s of element e, its cell's gradient
    row entry, 0 where the row has none (both sorted)."""
    dim = c_grad.shape[0]
    for e in prange(ptr.shape[0] - 1):
        c = cell_of[e * nq]
        j, je = c_ptr[c], c_ptr[c + 1]
        for s in range(ptr[e], ptr[e + 1]):
            hit = j < je and c_idx[j] == sten[s]
            for d in range(dim):
                Gs[s, d] = c_grad[d, j] if hit else 0.0
            j += hit


_stencil_gradients_serial = serial_twin(_stencil_gradients)


@njit(cache=True, parallel=True)
def _cell_products(c_ptr, c_idx, c_grad, u, out):
    """``out[d, c] = sum_k c_grad[d, k] u[c_idx[k]]`` over cell c's row, in its order (as a
    CSR product adds)."""
    for c in prange(c_ptr.shape[0] - 1):
        for d in range(c_grad.shape[0]):
            x = 0.0
            for k in range(c_ptr[c], c_ptr[c + 1]):
                x += c_grad[d, k] * u[c_idx[k]]
            out[d, c] = x


@njit(cache=True)
def _transposed_products(c_ptr, c_idx, c_grad, Y, out):
    """``out[m, c_idx[k]] += sum_d c_grad[d, k] Y[m, d, c]`` over cell c's entries k: the
    transposed products of the cells' gradient rows with the fields ``Y`` (m, dim, cells),
    all m fields in one pass over the rows (serial: the scatter into ``out``)."""
    for c in range(c_ptr.shape[0] - 1):
        for k in range(c_ptr[c], c_ptr[c + 1]):
            j = c_idx[k]
            for m in range(Y.shape[0]):
                s = 0.0
                for d in range(c_grad.shape[0]):
                    s += c_grad[d, k] * Y[m, d, c]
                out[m, j] += s


class CellRows:
    """The functions of a smoothed basis whose points share their cell's gradient: the
    values ``V = (indptr, indices, data)`` (int64 indices, one sorted row per point, nq
    points an element, consecutive; ``shape`` (points, functions)), the cell of each
    point ``cell_of`` (the same for all of an element's points) and the cells' gradient
    rows ``(c_ptr, c_idx, c_grad (dim, nnz))``, sorted."""

    def __init__(self, V, shape, cell_of, c_ptr, c_idx, c_grad):
        self.V, self.shape = V, tuple(shape)
        self.cell_of = np.ascontiguousarray(cell_of, dtype=np.int64)
        self.c_ptr, self.c_idx, self.c_grad = c_ptr, c_idx, c_grad
        self._values = None                 # the values' CSR matrix, made on first use

    def stencils(self, nq: int):
        """``(ptr, sten)``: element e's sorted stencil ``sten[ptr[e]:ptr[e + 1]]``, the
        functions non-zero at its points or in its gradient."""
        args = (nq, self.cell_of, self.V[0], self.V[1], self.c_ptr, self.c_idx, self.shape[1])
        ptr, (sten,) = count_then_fill(_stencils, _stencils_serial, self.shape[0] // nq, args,
                                       lambda nnz: (np.empty(nnz, np.int64),))
        return ptr, sten

    def stencil_gradients(self, nq: int, ptr, sten):
        """(stencil entries, dim): each stencil function's gradient on its element."""
        Gs = np.empty((sten.shape[0], self.c_grad.shape[0]))
        parallel = ptr.shape[0] - 1 >= PARALLEL_MIN
        (_stencil_gradients if parallel else _stencil_gradients_serial)(
            nq, self.cell_of, ptr, sten, self.c_ptr, self.c_idx, self.c_grad, Gs)
        return Gs

    def values(self):
        """The values at the points, CSR (points, functions) on their own pattern (a
        joined row also holds its gradient's columns, with value 0 there)."""
        import scipy.sparse as sp
        if self._values is None:
            ptr, idx, val = self.V
            self._values = sp.csr_matrix((val[ptr[0]:ptr[-1]], idx[ptr[0]:ptr[-1]],
                                          ptr - ptr[0]), shape=self.shape)
        return self._values

    def gradients_at_points(self, u):
        """(dim, points): the gradient of the function of coefficients ``u`` (functions,)
        at each point, its cell's; the same numbers as the joined rows' products."""
        g = np.empty((self.c_grad.shape[0], self.c_ptr.shape[0] - 1))
        _cell_products(self.c_ptr, self.c_idx, self.c_grad, np.ascontiguousarray(u, float), g)
        return g[:, self.cell_of]

    def cell_sums(self, y: np.ndarray) -> np.ndarray:
        """(cells,) the sums of the points' values ``y`` (points,) over each cell's points."""
        return np.bincount(self.cell_of, weights=y, minlength=self.c_ptr.shape[0] - 1)

    def transposed_gradients(self, Y: np.ndarray) -> np.ndarray:
        """(m, functions): ``sum_r sum_d d_d phi_j(x_r) y[m, d, r]`` from the fields'
        sums over each cell's points ``Y`` (m, dim, cells; :meth:`cell_sums`): the points of
        a cell share its gradient row, so one pass over the cells' rows serves all m."""
        out = np.zeros((Y.shape[0], self.shape[1]))
        _transposed_products(self.c_ptr, self.c_idx, self.c_grad,
                             np.ascontiguousarray(Y, float), out)
        return out

    def joined(self):
        """The values (CSR) and the gradients (dim, nnz) on one pattern, row by row the
        union of a point's value row and its cell's gradient row."""
        import scipy.sparse as sp
        ptr, idx, val, grad = join_rows(self.V, self.cell_of, self.c_ptr, self.c_idx,
                                        self.c_grad)
        return sp.csr_matrix((val, idx, ptr), shape=self.shape), grad
