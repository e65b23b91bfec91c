"""Products with a symmetric matrix of a 3D vector field kept as the 3x3 blocks of its nodes'
upper triangle (:class:`BlockSymmetricRows`): the finest level of the 3D viscous block's
multigrid.

Why: :class:`~skfem_nem.basis.symmetric_rows.SymmetricRows` keeps one column index (and one
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


def _check_increasing(position: np.ndarray) -> None:
    """``ValueError`` unless the positions are >= 0 and increase."""
    if position.size and (position[0] < 0 or (np.diff(position) <= 0).any()):
        raise ValueError("BlockSymmetricRows: the positions must be >= 0 and increase "
                         "with the rows")


class BlockSymmetricRows:
    """The symmetric matrix ``A`` (CSR, square, on the unknowns placed by ``position``;
    only its upper triangle is read) as the 3x3 blocks of its nodes' upper triangle, for
    products ``A @ x`` on numba's threads. The interface of
    :class:`~skfem_nem.basis.symmetric_rows.SymmetricRows`: :meth:`refresh` takes new
    values of a matrix whose entries fit the same blocks, :meth:`twin` keeps it in a
    second precision, :meth:`release_values` lets the values go.

    ``values``: ``numpy.float32`` or ``numpy.float64``; the products sum in double
    precision either way.

    Made from the blocks themselves (:meth:`from_blocks`, as the 3D condensed viscous
    block is assembled), it is the block for the whole solve: restricted to the free
    unknowns (:meth:`restricted`), its diagonal, its rows as CSR (:meth:`tocsr`, for the
    multigrid's set-up and the reactions) and scaled in place (:meth:`scale`).
    """

    def __init__(self, A: sp.spmatrix, position: np.ndarray, values=np.float64):
        A = sp.csr_matrix(A)
        position = np.asarray(position, dtype=np.int64)
        if A.shape[0] != A.shape[1] or position.shape != (A.shape[0],):
            raise ValueError(f"BlockSymmetricRows needs a square matrix and a position per "
                             f"row, got shape {A.shape} and {position.shape} positions")
        _check_increasing(position)
        self.values = np.dtype(values)
        if self.values not in (np.float32, np.float64):
            raise ValueError(f"BlockSymmetricRows keeps float32 or float64 values, "
                             f"got {values!r}")
        self.n_nodes = int(position[-1]) // WIDTH + 1 if position.size else 0
        node_rows = np.searchsorted(position // WIDTH,
                                    np.arange(self.n_nodes + 1)).astype(np.int64)
        self.source_indptr = A.indptr.copy()
        self._checked = None        # a weak reference to the index array last found fitting
        counts = np.zeros(self.n_nodes + 1, dtype=np.int64)
        _node_neighbours(A.indptr, A.indices, position, node_rows, counts,
                         counts[:0].astype(np.uint32), counts)
        self.indptr = np.cumsum(counts)
        self.indices = np.empty(self.indptr[-1], dtype=np.uint32)
        _node_neighbours(A.indptr, A.indices, position, node_rows, self.indptr,
                         self.indices, counts[:0])
        self._place(position)
        self.buffers = np.zeros((self.bounds.size - 1, WIDTH * self.n_nodes))
        self.data = None
        self.refresh(A)

    @classmethod
    def from_blocks(cls, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                    position: np.ndarray) -> "BlockSymmetricRows":
        """The matrix of the blocks ``data`` (nine values a block, row-major: component of
        the row, then of the column) of nodes ``indices[indptr[i]:indptr[i + 1]]`` (sorted,
        each >= i) of each node i, on the unknowns at ``position`` (increasing); the
        arrays are taken, not copied."""
        position = np.asarray(position, dtype=np.int64)
        _check_increasing(position)
        if data.size != WIDTH * WIDTH * indices.size or indptr[-1] != indices.size:
            raise ValueError(f"BlockSymmetricRows.from_blocks: {indices.size} blocks need "
                             f"{WIDTH * WIDTH * indices.size} values, got {data.size}")
        self = object.__new__(cls)
        self.indptr, self.indices, self.data = indptr, indices, data
        self.values = np.dtype(data.dtype)
        self.n_nodes = indptr.size - 1
        self._place(position)
        self.source_indptr, self._checked = None, None
        self.buffers = np.zeros((self.bounds.size - 1, WIDTH * self.n_nodes))
        return self

    def _place(self, position: np.ndarray) -> None:
        """The unknowns at ``position`` (increasing, within the nodes' components)."""
        if position.size and position[-1] >= WIDTH * self.n_nodes:
            raise ValueError(f"BlockSymmetricRows: position {int(position[-1])} is past the "
                             f"{WIDTH * self.n_nodes} components of {self.n_nodes} nodes")
        self.position = position
        self.shape, self.dtype = (position.size, position.size), np.dtype(np.float64)
        self.node_rows = np.searchsorted(position // WIDTH,
                                         np.arange(self.n_nodes + 1)).astype(np.int64)
        chunks = max(1, min(numba.get_num_threads(), self.n_nodes))
        self.bounds = np.searchsorted(self.indptr, np.linspace(0, self.indptr[-1],
                                                               chunks + 1)).astype(np.int64)
        self.bounds[0], self.bounds[-1] = 0, self.n_nodes

    def restricted(self, position: np.ndarray) -> "BlockSymmetricRows":
        """The same blocks (shared, not copied) on the unknowns at ``position`` (a subset
        of this one's, increasing): ``A[free][:, free]`` for the free unknowns."""
        position = np.asarray(position, dtype=np.int64)
        if not np.isin(position, self.position).all():
            raise ValueError("BlockSymmetricRows.restricted: the positions must be among "
                             "the matrix's own")
        other = object.__new__(BlockSymmetricRows)
        other.__dict__.update(self.__dict__)
        other._place(position)
        other.source_indptr, other._checked = None, None
        other.buffers = np.zeros_like(self.buffers)
        return other

    def copy(self) -> "BlockSymmetricRows":
        """The same blocks (shared) with a copy of the values."""
        other = object.__new__(BlockSymmetricRows)
        other.__dict__.update(self.__dict__)
        other.data, other.buffers = self._values().copy(), np.zeros_like(self.buffers)
        return other

    def diagonal(self) -> np.ndarray:
        """The diagonal entries of the unknowns."""
        out = np.zeros(self.shape[0])
        _block_diagonal(self.indptr, self.indices, self._values(), self.position, out)
        return out

    def tocsr(self, rows: np.ndarray = None) -> sp.csr_matrix:
        """The whole symmetric matrix on the unknowns as CSR in double precision; with
        ``rows`` (positions among the unknowns', increasing) those rows only, over all
        columns. Columns are sorted; every value of a block is an entry (zeros too)."""
        row_pos = self.position if rows is None else np.asarray(rows, dtype=np.int64)
        return self._walk(self.walk_tables(), row_pos)

    def row_slices(self, step: int):
        """The rows of the unknowns as CSR (:meth:`tocsr`), ``step`` rows at a time, the
        blocks' transposed pattern found once for all of them."""
        ex = self.walk_tables()
        for r0 in range(0, self.shape[0], step):
            yield self._walk(ex, self.position[r0:r0 + step])

    def strong(self, theta: float) -> sp.csr_matrix:
        """The strong couplings of the unknowns, as pyamg's symmetric strength of
        connection keeps them from the CSR matrix: each diagonal entry, and ``a_ij`` where
        ``a_ij^2 >= theta^2 |a_ii| |a_jj|``. The pattern is what aggregation reads; the
        values are ones (single precision)."""
        diag = np.zeros(WIDTH * self.n_nodes)
        diag[self.position] = np.abs(self.diagonal())
        C = self._walk(self.walk_tables(), self.position, float(theta) ** 2, diag)
        C.data = np.ones(C.nnz, dtype=np.float32)
        return C

    def walk_tables(self) -> tuple:
        """What walking the rows of the whole symmetric matrix needs: ``(col_of, owner,
        tptr, tblock)``, each position's column (-1: not an unknown), each block's row
        node and, for each node j, the blocks (i, j) with i < j
        (``tblock[tptr[j]:tptr[j + 1]]``); row r's entries are then entry (b, a) of those
        blocks and entry (a, b) of the node's own (``a = position[r] % 3``)."""
        col_of = np.full(WIDTH * self.n_nodes, -1, dtype=np.int64)
        col_of[self.position] = np.arange(self.shape[0])
        owner = np.repeat(np.arange(self.n_nodes, dtype=np.int32), np.diff(self.indptr))
        return (col_of, owner) + _transposed_blocks(self.indptr, self.indices, owner,
                                                    self.n_nodes)

    def _walk(self, ex: tuple, row_pos: np.ndarray, theta2: float = 0.0,
              diag: np.ndarray = None) -> sp.csr_matrix:
        """CSR rows ``row_pos`` of the symmetric matrix, all its entries (``theta2`` 0) or
        the strong ones (``diag``: the absolute diagonal by position); values where all are
        kept, else none (zeros)."""
        col_of, owner, tptr, tblock = ex
        if not (col_of[row_pos] >= 0).all():
            raise ValueError("BlockSymmetricRows.tocsr: the rows must be among the unknowns")
        args = (self.indptr, self.indices, self._values(), owner, tptr, tblock, col_of,
                row_pos, np.zeros(0) if diag is None else diag, theta2)
        counts = np.zeros(row_pos.size, dtype=np.int64)
        _walk_rows(*args, counts, counts[:0], counts[:0], np.zeros(0))
        nnz = int(counts.sum())
        idt = np.int32 if max(nnz, self.shape[0]) < np.iinfo(np.int32).max else np.int64
        indptr = np.zeros(row_pos.size + 1, dtype=idt)
        np.cumsum(counts, out=indptr[1:])
        indices = np.empty(nnz, dtype=idt)
        data = np.empty(nnz) if theta2 == 0.0 else np.zeros(nnz)
        _walk_rows(*args, counts[:0], indptr, indices, data if theta2 == 0.0 else data[:0])
        return sp.csr_matrix((data, indices, indptr), shape=(row_pos.size, self.shape[0]))

    def scale(self, s: np.ndarray) -> None:
        """``diag(s) A diag(s)`` in place, ``s`` one factor an unknown (the unknowns not
        placed keep theirs): each value ``(a_ij s_j) s_i``, as
        :func:`~skfem_nem.models.stokes_amg.scaled_block` computes a CSR row's, and each
        diagonal block mirrored from its upper part."""
        full = np.ones(WIDTH * self.n_nodes)
        full[self.position] = s
        _scale_blocks(self.indptr, self.indices, self._values(), full)

    def _values(self) -> np.ndarray:
        if self.data is None:
            raise RuntimeError("BlockSymmetricRows: its values were let go "
                               "(release_values); refresh it first")
        return self.data

    def twin(self, A, values=np.float64) -> "BlockSymmetricRows":
        """The matrix ``A`` (CSR whose entries fit this one's blocks, or a
        :class:`BlockSymmetricRows` of them) with values in ``values``: the blocks' indices
        are shared, not found again."""
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

    def same_pattern(self, A) -> bool:
        """True if ``A`` is a CSR matrix with the same row pointers whose upper entries all
        fall into this one's blocks, or a :class:`BlockSymmetricRows` of the same blocks
        and unknowns, so that :meth:`refresh` takes its values."""
        if isinstance(A, BlockSymmetricRows):
            return self.same_blocks(A) and np.array_equal(A.position, self.position)
        if not (sp.issparse(A) and A.format == "csr" and A.shape == self.shape
                and self.source_indptr is not None
                and np.array_equal(A.indptr, self.source_indptr)):
            return False
        if self._checked is not None and self._checked() is A.indices:
            return True     # the index array found fitting a moment ago (a refresh's twin)
        fits = _fits(A.indptr, A.indices, self.position, self.node_rows, self.indptr,
                     self.indices)
        self._checked = weakref.ref(A.indices) if fits else None
        return fits

    def same_blocks(self, other: "BlockSymmetricRows") -> bool:
        """True if ``other`` keeps the blocks of the same node pairs."""
        return (other.indptr is self.indptr and other.indices is self.indices) or (
            np.array_equal(other.indptr, self.indptr)
            and np.array_equal(other.indices, self.indices))

    def refresh(self, A) -> None:
        """Take the values of ``A`` (CSR, or a :class:`BlockSymmetricRows` on the same
        unknowns, whose values are shared where they have this one's precision); a matrix
        of other blocks is taken as if new."""
        if isinstance(A, BlockSymmetricRows):
            if not np.array_equal(A.position, self.position):
                raise ValueError("BlockSymmetricRows.refresh: the matrix is on other "
                                 "unknowns")
            if not self.same_blocks(A):
                self.indptr, self.indices, self.bounds = A.indptr, A.indices, A.bounds
                self.node_rows, self.source_indptr, self._checked = A.node_rows, None, None
            self.data = None
            self.data = A._values().astype(self.values, copy=False)
            return
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
        data = self._values()
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.shape[1],):
            raise ValueError(f"BlockSymmetricRows @ x needs x of shape ({self.shape[1]},), "
                             f"got {x.shape}")
        full = np.zeros(WIDTH * self.n_nodes)
        full[self.position] = x
        out = np.empty_like(full)
        _block_product(self.indptr, self.indices, data, full, self.bounds,
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


@njit(cache=True, parallel=True)
def _block_diagonal(bptr, bind, data, position, out):
    """The diagonal entry of each unknown at ``position`` (zero without a diagonal
    block)."""
    for r in prange(position.size):
        i, a = position[r] // WIDTH, position[r] % WIDTH
        if bptr[i + 1] > bptr[i] and bind[bptr[i]] == i:
            out[r] = data[9 * bptr[i] + (WIDTH + 1) * a]


@njit(cache=True, parallel=True)
def _scale_blocks(bptr, bind, data, s):
    """``data`` of block (i, j), entry (a, b), times ``s[3 j + b]`` then ``s[3 i + a]``;
    each diagonal block's lower part then mirrored from its upper one."""
    for i in prange(bptr.size - 1):
        for k in range(bptr[i], bptr[i + 1]):
            j = bind[k]
            for a in range(WIDTH):
                si = s[WIDTH * i + a]
                for b in range(WIDTH):
                    q = 9 * k + WIDTH * a + b
                    data[q] = data[q] * s[WIDTH * j + b] * si
        if bptr[i + 1] > bptr[i] and bind[bptr[i]] == i:
            q = 9 * bptr[i]
            data[q + 3], data[q + 6], data[q + 7] = data[q + 1], data[q + 2], data[q + 5]


@njit(cache=True)
def _transposed_blocks(bptr, bind, owner, n):
    """For each node j, the blocks (i, j) with i < j, in increasing i: ``tblock[tptr[j]:
    tptr[j + 1]]`` (a counting sort of the blocks by column node)."""
    tptr = np.zeros(n + 1, np.int64)
    for k in range(bind.size):
        if bind[k] != owner[k]:
            tptr[bind[k] + 1] += 1
    for j in range(n):
        tptr[j + 1] += tptr[j]
    fill = tptr[:-1].copy()
    tblock = np.empty(tptr[n], np.int64)
    for k in range(bind.size):
        j = bind[k]
        if j != owner[k]:
            tblock[fill[j]] = k
            fill[j] += 1
    return tptr, tblock


@njit(cache=True, inline="always")
def _kept(c, v, p, row, eps, diag, theta2):
    """Entry ``v`` at position ``p`` (column ``c``) of the row at position ``row`` is
    kept: an unknown's, and all are kept (``theta2`` 0), or the diagonal, or strong."""
    return c >= 0 and (theta2 == 0.0 or p == row or v * v >= eps * diag[p])


@njit(cache=True, parallel=True)
def _walk_rows(bptr, bind, data, owner, tptr, tblock, col_of, row_pos, diag, theta2,
               counts, indptr, indices, out):
    """CSR rows ``row_pos`` of the symmetric matrix: the transposed blocks of the nodes
    below (entry (b, a) of block (i, j)), then the node's own blocks, columns ascending;
    the entries :func:`_kept`. Their number into ``counts`` where it is not empty, else
    their columns into ``indices`` from ``indptr`` (and values into ``out``, not empty).
    The two loops differ only in which block entry they read."""
    for r in prange(row_pos.size):
        i, a, row = row_pos[r] // WIDTH, row_pos[r] % WIDTH, row_pos[r]
        eps = theta2 * diag[row] if theta2 != 0.0 else 0.0
        o = indptr[r] if counts.size == 0 else 0
        for t in range(tptr[i], tptr[i + 1]):
            k = tblock[t]
            for b in range(WIDTH):
                p, v = WIDTH * owner[k] + b, data[9 * k + WIDTH * b + a]
                if _kept(col_of[p], v, p, row, eps, diag, theta2):
                    if counts.size == 0:
                        indices[o] = col_of[p]
                        if out.size:
                            out[o] = v
                    o += 1
        for k in range(bptr[i], bptr[i + 1]):
            for b in range(WIDTH):
                p, v = WIDTH * bind[k] + b, data[9 * k + WIDTH * a + b]
                if _kept(col_of[p], v, p, row, eps, diag, theta2):
                    if counts.size == 0:
                        indices[o] = col_of[p]
                        if out.size:
                            out[o] = v
                    o += 1
        if counts.size:
            counts[r] = o
