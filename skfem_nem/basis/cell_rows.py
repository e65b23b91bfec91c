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

from ..jit import serial_twin

__all__ = ["CellRows", "join_rows", "two_pass"]

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


def two_pass(kernel, serial, nrows, args, dim):
    """The two passes of a row kernel (count, then fill) into one CSR pattern:
    ``(indptr, indices, values, gradients (dim, nnz))``."""
    kernel = kernel if nrows >= PARALLEL_MIN else serial
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


def join_rows(V, cell_of, c_ptr, c_idx, c_grad):
    """Row r of the values ``V = (indptr, indices, data)`` (int64, rows sorted) joined with
    the gradient row ``cell_of[r]`` of ``(c_ptr, c_idx, c_grad)``: ``(indptr, indices,
    values, gradients)`` on the union of the two patterns."""
    args = (np.ascontiguousarray(cell_of, dtype=np.int64), *V, c_ptr, c_idx, c_grad)
    return two_pass(_joined_rows, _joined_rows_serial, cell_of.shape[0], args,
                    c_grad.shape[0])


@njit(cache=True, inline="always")
def _union_row(e, nq, cell, v_ptr, v_idx, c_ptr, c_idx, head, out, at, fill):
    """The sorted union of the value rows ``e nq .. e nq + nq - 1`` and the gradient row
    ``cell`` (source nq), written at ``out[at:]`` when filling; returns its length."""
    for j in range(nq):
        head[j] = v_ptr[e * nq + j]
    head[nq] = c_ptr[cell]
    n = 0
    while True:
        col = -1
        for j in range(nq + 1):
            stop = c_ptr[cell + 1] if j == nq else v_ptr[e * nq + j + 1]
            if head[j] < stop:
                x = c_idx[head[j]] if j == nq else v_idx[head[j]]
                if col < 0 or x < col:
                    col = x
        if col < 0:
            return n
        for j in range(nq + 1):
            stop = c_ptr[cell + 1] if j == nq else v_ptr[e * nq + j + 1]
            if head[j] < stop and (c_idx[head[j]] if j == nq else v_idx[head[j]]) == col:
                head[j] += 1
        if fill:
            out[at + n] = col
        n += 1


@njit(cache=True, parallel=True)
def _stencils(nq, cell_of, v_ptr, v_idx, c_ptr, c_idx, count, ptr, sten, fill):
    """Element e's stencil: the union of its points' value rows and its cell's gradient
    row, sorted (counts, then fills at ``ptr[e]``)."""
    ne = count.shape[0]
    nb = (ne + _BLOCK - 1) // _BLOCK
    for blk in prange(nb):
        head = np.empty(nq + 1, np.int64)
        for e in range(blk * _BLOCK, min(ne, blk * _BLOCK + _BLOCK)):
            n = _union_row(e, nq, cell_of[e * nq], v_ptr, v_idx, c_ptr, c_idx, head, sten,
                           ptr[e] if fill else 0, fill)
            if not fill:
                count[e] = n


_stencils_serial = serial_twin(_stencils)


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

    def stencils(self, nq: int):
        """``(ptr, sten)``: element e's sorted stencil ``sten[ptr[e]:ptr[e + 1]]``, the
        functions non-zero at its points or in its gradient."""
        ne = self.shape[0] // nq
        kernel = _stencils if ne >= PARALLEL_MIN else _stencils_serial
        args = (nq, self.cell_of, self.V[0], self.V[1], self.c_ptr, self.c_idx)
        count = np.zeros(ne, np.int64)
        ptr = np.zeros(ne + 1, np.int64)
        kernel(*args, count, ptr, np.empty(0, np.int64), False)
        np.cumsum(count, out=ptr[1:])
        sten = np.empty(ptr[-1], np.int64)
        kernel(*args, count, ptr, sten, True)
        return ptr, sten

    def stencil_gradients(self, nq: int, ptr, sten):
        """(stencil entries, dim): each stencil function's gradient on its element."""
        Gs = np.empty((sten.shape[0], self.c_grad.shape[0]))
        parallel = ptr.shape[0] - 1 >= PARALLEL_MIN
        (_stencil_gradients if parallel else _stencil_gradients_serial)(
            nq, self.cell_of, ptr, sten, self.c_ptr, self.c_idx, self.c_grad, Gs)
        return Gs

    def joined(self):
        """The values (CSR) and the gradients (dim, nnz) on one pattern, row by row the
        union of a point's value row and its cell's gradient row."""
        import scipy.sparse as sp
        ptr, idx, val, grad = join_rows(self.V, self.cell_of, self.c_ptr, self.c_idx,
                                        self.c_grad)
        return sp.csr_matrix((val, idx, ptr), shape=self.shape), grad
