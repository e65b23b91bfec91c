"""Products with a symmetric matrix of a 3D vector field kept as the 3x3 blocks of its nodes'
upper triangle (:class:`BlockSymmetricRows`): the finest level of the 3D viscous block's
multigrid.

Why: :class:`~skfem_nem.models.symmetric_rows.SymmetricRows` keeps one column index (and one
position in the source matrix) beside every value. A 3D viscous block couples every
component of a node with every component of its neighbours, so its entries come in dense
3x3 blocks, and one index a block serves nine values. The products of a 3D plate step's
solves are most of its time (at 100,000 nodes some 800 products of 85 ms), and a product
reads every value and index once. On a block of 100,000 nodes with 150 neighbours each (144
million entries) a product takes 28.6 ms in single and 31.8 ms in double precision, against
47 and 48 ms entry by entry; the index array is 32 MB against 290 MB, and no positions are
kept (a refresh walks the source matrix's rows beside the blocks).

The rows of the matrix are the free unknowns of the field. ``position[r]`` places unknown
r in the full field, ``3 * node + component``; the positions must increase with r (scikit-fem
numbers a vector basis's nodal unknowns node by node). Fixed components stay zero in the
blocks, and the products scatter into and gather from the full field.
"""
from __future__ import annotations

import weakref

import numba
import numpy as np
import scipy.sparse as sp
from numba import njit, prange

__all__ = ["BlockSymmetricRows", "node_positions"]

#: components of a node: the blocks are WIDTH x WIDTH
WIDTH = 3


def node_positions(ubasis, free: np.ndarray):
    """``3 * node + component`` of each dof in ``free`` of a 3D vector basis whose dofs are
    all nodal, or None where the basis has other dofs, is not 3D, or numbers them so that
    the positions do not increase with the dofs (then :class:`BlockSymmetricRows` cannot
    take its block)."""
    dofs = ubasis.dofs
    nodal = np.asarray(dofs.nodal_dofs)
    if ubasis.mesh.dim() != WIDTH or nodal.shape[0] != WIDTH or nodal.size != ubasis.N:
        return None
    position = np.empty(ubasis.N, dtype=np.int64)
    position[nodal] = WIDTH * np.arange(nodal.shape[1]) + np.arange(WIDTH)[:, None]
    position = position[np.asarray(free)]
    return position if (np.diff(position) > 0).all() else None


class BlockSymmetricRows:
    """The symmetric matrix ``A`` (CSR, square, on the unknowns placed by ``position``;
    only its upper triangle is read) as the 3x3 blocks of its nodes' upper triangle, for
    products ``A @ x`` on numba's threads. The interface of
    :class:`~skfem_nem.models.symmetric_rows.SymmetricRows`: :meth:`refresh` takes new
    values of a matrix whose entries fit the same blocks, :meth:`twin` keeps it in a
    second precision, :meth:`release_values` lets the values go.

    ``values``: ``numpy.float32`` or ``numpy.float64``; the products sum in double
    precision either way.
    """

    def __init__(self, A: sp.spmatrix, position: np.ndarray, values=np.float64):
        A = sp.csr_matrix(A)
        position = np.asarray(position, dtype=np.int64)
        if A.shape[0] != A.shape[1] or position.shape != (A.shape[0],):
            raise ValueError(f"BlockSymmetricRows needs a square matrix and a position per "
                             f"row, got shape {A.shape} and {position.shape} positions")
        if position.size and (position[0] < 0 or (np.diff(position) <= 0).any()):
            raise ValueError("BlockSymmetricRows: the positions must be >= 0 and increase "
                             "with the rows")
        self.values = np.dtype(values)
        if self.values not in (np.float32, np.float64):
            raise ValueError(f"BlockSymmetricRows keeps float32 or float64 values, "
                             f"got {values!r}")
        self.shape, self.dtype, self.position = A.shape, np.dtype(np.float64), position
        self.n_nodes = int(position[-1]) // WIDTH + 1 if position.size else 0
        self.node_rows = np.searchsorted(position // WIDTH,
                                         np.arange(self.n_nodes + 1)).astype(np.int64)
        self.source_indptr = A.indptr.copy()
        self._checked = None        # a weak reference to the index array last found fitting
        counts = np.zeros(self.n_nodes + 1, dtype=np.int64)
        _node_neighbours(A.indptr, A.indices, position, self.node_rows, counts,
                         counts[:0].astype(np.uint32), counts)
        self.indptr = np.cumsum(counts)
        self.indices = np.empty(self.indptr[-1], dtype=np.uint32)
        _node_neighbours(A.indptr, A.indices, position, self.node_rows, self.indptr,
                         self.indices, counts[:0])
        chunks = max(1, min(numba.get_num_threads(), self.n_nodes))
        self.bounds = np.searchsorted(self.indptr, np.linspace(0, self.indptr[-1],
                                                               chunks + 1)).astype(np.int64)
        self.bounds[0], self.bounds[-1] = 0, self.n_nodes
        self.buffers = np.zeros((chunks, WIDTH * self.n_nodes))
        self.data = None
        self.refresh(A)

    def twin(self, A: sp.spmatrix, values=np.float64) -> "BlockSymmetricRows":
        """The matrix ``A``, whose entries fit this one's blocks, with values in
        ``values``: the blocks' indices are shared, not found again."""
        if not self.same_pattern(A):
            raise ValueError("BlockSymmetricRows.twin needs a matrix that fits the same "
                             "blocks")
        other = object.__new__(BlockSymmetricRows)
        other.__dict__.update({k: v for k, v in self.__dict__.items()
                               if k not in ("data", "buffers")})
        other.values, other.buffers = np.dtype(values), np.zeros_like(self.buffers)
        other.refresh(A)
        return other

    @property
    def nnz(self) -> int:
        """Values kept: nine a block (fixed components and absent entries as zeros)."""
        return int(self.indptr[-1]) * WIDTH * WIDTH

    def same_pattern(self, A: sp.spmatrix) -> bool:
        """True if ``A`` is a CSR matrix with the same row pointers whose upper entries all
        fall into this one's blocks, so that :meth:`refresh` takes them."""
        if not (sp.issparse(A) and A.format == "csr" and A.shape == self.shape
                and np.array_equal(A.indptr, self.source_indptr)):
            return False
        if self._checked is not None and self._checked() is A.indices:
            return True     # the index array found fitting a moment ago (a refresh's twin)
        fits = _fits(A.indptr, A.indices, self.position, self.node_rows, self.indptr,
                     self.indices)
        self._checked = weakref.ref(A.indices) if fits else None
        return fits

    def refresh(self, A: sp.spmatrix) -> None:
        """Take the values of ``A``; a matrix whose entries do not fit the blocks is taken
        as if new."""
        if not self.same_pattern(A):
            self.__init__(A, self.position, self.values)
            return
        self.data = None                # (the old values go before the new are made)
        data = np.empty(self.nnz, dtype=self.values)
        _fill(A.indptr, A.indices, np.asarray(A.data, dtype=np.float64), self.position,
              self.node_rows, self.indptr, self.indices, data)
        self.data = data

    def release_values(self) -> None:
        """Let go of the values until the next :meth:`refresh` (the blocks' pattern
        stays); products raise ``RuntimeError`` meanwhile."""
        self.data = None

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        if self.data is None:
            raise RuntimeError("BlockSymmetricRows: its values were let go "
                               "(release_values); refresh it first")
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.shape[1],):
            raise ValueError(f"BlockSymmetricRows @ x needs x of shape ({self.shape[1]},), "
                             f"got {x.shape}")
        full = np.zeros(WIDTH * self.n_nodes)
        full[self.position] = x
        out = np.empty_like(full)
        _block_product(self.indptr, self.indices, self.data, full, self.bounds,
                       self.buffers, out)
        return out[self.position]

    matvec = __matmul__


@njit(cache=True)
def _upper_nodes(indptr, indices, position, first, last, node, out):
    """The nodes >= ``node`` among the columns of rows ``first:last``, sorted and unique,
    into ``out``; returns how many."""
    m = 0
    for r in range(first, last):
        for k in range(indptr[r], indptr[r + 1]):
            j = position[indices[k]] // WIDTH
            if j >= node:
                out[m] = j
                m += 1
    if m == 0:
        return 0
    s = np.sort(out[:m])
    u = 1
    for q in range(1, m):
        if s[q] != s[u - 1]:
            s[u] = s[q]
            u += 1
    out[:u] = s[:u]
    return u


@njit(cache=True, parallel=True)
def _node_neighbours(indptr, indices, position, node_rows, starts, out, counts):
    """Each node's neighbours >= itself (the blocks of its row): their number into
    ``counts[node + 1]`` where ``counts`` is not empty, else the sorted nodes into ``out``
    from ``starts[node]``."""
    for i in prange(node_rows.size - 1):
        first, last = node_rows[i], node_rows[i + 1]
        buf = np.empty(indptr[last] - indptr[first], dtype=np.int64)
        u = _upper_nodes(indptr, indices, position, first, last, i, buf)
        if counts.size:
            counts[i + 1] = u
        else:
            for q in range(u):
                out[starts[i] + q] = buf[q]


@njit(cache=True, parallel=True)
def _fits(indptr, indices, position, node_rows, bptr, bind):
    """True if every entry of the upper triangle falls into a block of ``bptr, bind``."""
    misses = np.zeros(node_rows.size - 1, dtype=np.int64)
    for i in prange(node_rows.size - 1):
        for r in range(node_rows[i], node_rows[i + 1]):
            w = bptr[i]
            for k in range(indptr[r], indptr[r + 1]):
                if position[indices[k]] < position[r]:
                    continue
                j = position[indices[k]] // WIDTH
                while w < bptr[i + 1] and bind[w] < j:
                    w += 1
                if w == bptr[i + 1] or bind[w] != j:
                    misses[i] += 1
    return misses.sum() == 0


@njit(cache=True, parallel=True)
def _fill(indptr, indices, values, position, node_rows, bptr, bind, data):
    """The blocks' values from the upper triangle of ``A`` (every entry must fit: checked
    by :func:`_fits`); absent entries are zero, and each diagonal block is mirrored from
    its upper part."""
    for i in prange(node_rows.size - 1):
        data[bptr[i] * 9:bptr[i + 1] * 9] = 0.0
        for r in range(node_rows[i], node_rows[i + 1]):
            a = position[r] % WIDTH
            w = bptr[i]
            for k in range(indptr[r], indptr[r + 1]):
                pc = position[indices[k]]
                if pc < position[r]:
                    continue
                while bind[w] < pc // WIDTH:
                    w += 1
                data[9 * w + WIDTH * a + pc % WIDTH] = values[k]
        if bptr[i + 1] > bptr[i] and bind[bptr[i]] == i:       # the diagonal block
            q = 9 * bptr[i]
            data[q + 3], data[q + 6], data[q + 7] = data[q + 1], data[q + 2], data[q + 5]


@njit(cache=True, parallel=True, fastmath=True)
def _block_product(bptr, bind, data, x, bounds, buffers, y):
    """``y = A x`` from the nodes' upper 3x3 blocks: chunk t of nodes (``bounds``) adds its
    rows' sums and the transposed blocks' terms into ``buffers[t]``, then the buffers are
    summed. Written out for 3x3 blocks (numba does not unroll loops over the components),
    hence its length. A chunk only writes at or after its first node, so only that part is
    cleared."""
    for t in prange(bounds.size - 1):
        buf = buffers[t]
        buf[3 * bounds[t]:] = 0.0
        for i in range(bounds[t], bounds[t + 1]):
            x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
            a0 = a1 = a2 = 0.0
            for k in range(bptr[i], bptr[i + 1]):
                j, q = bind[k], 9 * k
                b00, b01, b02 = np.float64(data[q]), np.float64(data[q + 1]), \
                    np.float64(data[q + 2])
                b10, b11, b12 = np.float64(data[q + 3]), np.float64(data[q + 4]), \
                    np.float64(data[q + 5])
                b20, b21, b22 = np.float64(data[q + 6]), np.float64(data[q + 7]), \
                    np.float64(data[q + 8])
                y0, y1, y2 = x[3 * j], x[3 * j + 1], x[3 * j + 2]
                a0 += b00 * y0 + b01 * y1 + b02 * y2
                a1 += b10 * y0 + b11 * y1 + b12 * y2
                a2 += b20 * y0 + b21 * y1 + b22 * y2
                if j != i:
                    buf[3 * j] += b00 * x0 + b10 * x1 + b20 * x2
                    buf[3 * j + 1] += b01 * x0 + b11 * x1 + b21 * x2
                    buf[3 * j + 2] += b02 * x0 + b12 * x1 + b22 * x2
            buf[3 * i] += a0
            buf[3 * i + 1] += a1
            buf[3 * i + 2] += a2
    for i in prange(y.size):
        acc = 0.0
        for t in range(bounds.size - 1):
            if i >= 3 * bounds[t]:
                acc += buffers[t, i]
        y[i] = acc
