"""Products with a symmetric sparse matrix kept as its upper triangle and computed on all of
numba's threads (:class:`SymmetricRows`): the finest level of the viscous block's multigrid
and of the quadratic natural-neighbour functions' two-level method (:mod:`.two_level`).

Why: a 3D natural-neighbour viscous block has some 460 entries a row (three components of
some 150 neighbours), and the Stokes solves of the 3D plate spend most of their time in
products with it (the preconditioner's conjugate-gradient steps and the Chebyshev
smoothing of its V-cycles). scipy multiplies on one thread and reads every entry, and the
product is bound by memory bandwidth. The upper triangle reads half the entries, and the
threads share the rows. On the viscous block of a 3D plate step at 9,956 nodes (29,253
unknowns, 13.5 million entries) a product takes 6.3 ms against scipy's 16.2 ms on two
cores (docs/stokes_3d.md).

Each thread takes a run of rows holding about the same number of entries and adds the
transposed terms ``a_ij x_i`` (j > i) into a vector of its own; the vectors are summed at
the end. Every entry is added by the same thread in the same order in every product, so the
results repeat bit for bit for a given number of threads.
"""
from __future__ import annotations

import weakref

import numba
import numpy as np
import scipy.sparse as sp
from numba import njit, prange

__all__ = ["SymmetricRows"]


class SymmetricRows:
    """The symmetric matrix ``A`` (CSR, square; only its upper triangle is read) for
    products ``A @ x`` on numba's threads. :meth:`refresh` takes new values of a matrix
    of the same pattern without finding the triangle again.

    ``values``: the precision the entries are kept in (``numpy.float32`` or
    ``numpy.float64``); the products are summed in double precision either way. Single
    precision reads two thirds of the bytes (4.5 against 7.8 ms on the block above), for
    a preconditioner whose own error is far larger than the rounding.
    """

    def __init__(self, A: sp.spmatrix, values=np.float64):
        A = sp.csr_matrix(A)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"SymmetricRows needs a square matrix, got shape {A.shape}")
        self.values = np.dtype(values)
        if self.values not in (np.float32, np.float64):
            raise ValueError(f"SymmetricRows keeps float32 or float64 values, got {values!r}")
        self.shape, self.dtype = A.shape, np.dtype(np.float64)
        # the row pointers of A, to know a matrix of its pattern again (its column indices
        # are not kept: same_pattern checks them against the triangle's)
        self.source_indptr = A.indptr.copy()
        self._checked = None        # a weak reference to the index array last found the same
        n = A.shape[0]
        counts = np.zeros(n + 1, dtype=np.int64)
        # the positions in A of the entries kept, in 32 bits where A's entries allow
        # (a 3D viscous block of 10,000 nodes: 27 MB less)
        position = np.int64 if A.indices.size >= np.iinfo(np.int32).max else np.int32
        self.diagonal_source = np.full(n, -1, dtype=position)     # -1: no diagonal entry
        _upper_counts(A.indptr, A.indices, counts, self.diagonal_source)
        self.indptr = np.cumsum(counts)
        self.source = np.empty(self.indptr[-1], dtype=position)
        self.indices = np.empty(self.indptr[-1], dtype=np.uint32)
        _upper_fill(A.indptr, A.indices, self.indptr, self.source, self.indices)
        chunks = max(1, min(numba.get_num_threads(), n))
        self.bounds = np.searchsorted(self.indptr, np.linspace(0, self.indptr[-1],
                                                               chunks + 1)).astype(np.int64)
        self.bounds[0], self.bounds[-1] = 0, n
        self.buffers = np.zeros((chunks, n))
        self.refresh(A)

    def twin(self, A: sp.spmatrix, values=np.float64) -> "SymmetricRows":
        """The matrix ``A``, of this one's pattern, with values in ``values``: the
        triangle's indices are shared, not found again (a matrix kept in two precisions)."""
        if not self.same_pattern(A):
            raise ValueError("SymmetricRows.twin needs a matrix of the same pattern")
        other = object.__new__(SymmetricRows)
        other.__dict__.update({k: v for k, v in self.__dict__.items()
                               if k not in ("data", "diagonal", "buffers")})
        other.values, other.buffers = np.dtype(values), np.zeros_like(self.buffers)
        other.refresh(A)
        return other

    @property
    def nnz(self) -> int:
        """Entries kept: the strict upper triangle and the diagonal."""
        return int(self.indptr[-1]) + self.shape[0]

    def same_pattern(self, A: sp.spmatrix) -> bool:
        """True if ``A`` is a CSR matrix whose values this one reads from the same places:
        the same row pointers, its diagonal and upper triangle at the same positions and
        columns. (Its lower triangle is never read.)"""
        if not (sp.issparse(A) and A.format == "csr" and A.shape == self.shape
                and np.array_equal(A.indptr, self.source_indptr)):
            return False
        if self._checked is not None and self._checked() is A.indices:
            return True     # the index array found the same a moment ago (a refresh's twin)
        same = _same_upper(A.indptr, A.indices, self.indptr, self.source, self.indices,
                           self.diagonal_source)
        # remembered by a weak reference: the array is not held
        self._checked = weakref.ref(A.indices) if same else None
        return same

    def refresh(self, A: sp.spmatrix) -> None:
        """Take the values of ``A``; a matrix of another pattern than the one this was made
        from is taken as if new."""
        if not self.same_pattern(A):
            self.__init__(A, self.values)
            return
        values = np.asarray(A.data, dtype=np.float64)
        self.data = np.empty(self.source.size, dtype=self.values)
        self.diagonal = np.empty(self.shape[0])
        _gather(values, self.source, self.data)
        _gather(values, self.diagonal_source, self.diagonal)

    def release_values(self) -> None:
        """Let go of the values until the next :meth:`refresh` (the triangle's pattern
        stays); products raise ``RuntimeError`` meanwhile."""
        self.data = self.diagonal = None

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        if self.data is None:
            raise RuntimeError("SymmetricRows: its values were let go (release_values); "
                               "refresh it first")
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.shape != (self.shape[1],):
            raise ValueError(f"SymmetricRows @ x needs x of shape ({self.shape[1]},), "
                             f"got {x.shape}")
        y = np.empty(self.shape[0])
        _symmetric_product(self.indptr, self.indices, self.data, self.diagonal, x, self.bounds,
                           self.buffers, y)
        return y

    matvec = __matmul__


@njit(cache=True, parallel=True)
def _upper_counts(indptr, indices, counts, diagonal):
    """``counts[i + 1]``: entries of row i above the diagonal; ``diagonal[i]``: the
    position of its diagonal entry (left at -1 if none)."""
    for i in prange(indptr.size - 1):
        c = 0
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] > i:
                c += 1
            elif indices[k] == i:
                diagonal[i] = k
        counts[i + 1] = c


@njit(cache=True, parallel=True)
def _upper_fill(indptr, indices, up_ptr, source, up_indices):
    """The strict upper triangle's column indices and the positions of its entries in
    ``A``."""
    for i in prange(indptr.size - 1):
        w = up_ptr[i]
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] > i:
                source[w] = k
                up_indices[w] = indices[k]
                w += 1


@njit(cache=True)
def _same_upper(indptr, indices, up_ptr, source, up_indices, diagonal):
    """True if the strict upper triangle of the CSR pattern ``indptr, indices`` is at the
    positions ``source`` with the columns ``up_indices`` (rows by ``up_ptr``) and its
    diagonal entries at ``diagonal`` (-1: none). One thread: it runs once a solve, 42 ms
    on 13.8 million entries (comparing two copies of the index arrays took 13 ms, but held
    a copy of 55 MB), and a parallel kernel costs a run seconds more to compile."""
    for i in range(indptr.size - 1):
        w, d = up_ptr[i], -1
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j > i:
                if w >= up_ptr[i + 1] or source[w] != k or up_indices[w] != j:
                    return False
                w += 1
            elif j == i:
                d = k
        if w != up_ptr[i + 1] or d != diagonal[i]:
            return False
    return True


@njit(cache=True, parallel=True)
def _gather(values, source, out):
    """``out[k] = values[source[k]]``, zero where ``source[k]`` is -1."""
    for k in prange(source.size):
        out[k] = values[source[k]] if source[k] >= 0 else 0.0


@njit(cache=True, parallel=True, fastmath=True)
def _symmetric_product(indptr, indices, data, diagonal, x, bounds, buffers, y):
    """``y = A x`` from the strict upper triangle and the diagonal of ``A``: chunk t of rows
    (``bounds``) adds its rows' sums and its transposed terms into ``buffers[t]``; then the
    buffers are summed. A chunk only writes at or after its first row, so only that part is
    cleared."""
    for t in prange(bounds.size - 1):
        buf = buffers[t]
        buf[bounds[t]:] = 0.0
        for i in range(bounds[t], bounds[t + 1]):
            xi = x[i]
            acc = diagonal[i] * xi
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                a = data[k]
                acc += a * x[j]
                buf[j] += a * xi
            buf[i] += acc
    for i in prange(y.size):
        acc = 0.0
        for t in range(bounds.size - 1):
            if i >= bounds[t]:
                acc += buffers[t, i]
        y[i] = acc
