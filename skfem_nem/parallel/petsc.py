"""PETSc through petsc4py: finding it, moving scipy matrices and numpy vectors in and out.

Why a module of its own: petsc4py is optional (the default installation is pip-only and
PyPI has no PETSc binaries), so every use of it goes through :func:`import_petsc`, which
finds a Debian PETSc that is installed but not on the path and otherwise raises one clear
error naming the installation route. Everything else in :mod:`skfem_nem.parallel` is
built on the few conversions here.

A matrix reaches PETSc in one of two ways. Replicated: every rank holds the whole
matrix and inserts only its own block of rows (PETSc's default split of the rows, or the
split the caller gives); :func:`check_replicated` verifies that the ranks really hold the
same matrix (a random node set drawn without a seed would differ). Distributed: every
rank holds only its share (the part its own cells assembled, :func:`owned_elements`)
and :func:`summed_rows` sends each rank the rows it owns from every other share (or
:func:`sent_rows`, for a caller that lets its share go before the rows are added up); the
owned rows then come in as one CSR block, which preallocates the MPIAIJ matrix exactly.
The mesh itself is the same on every rank (:func:`ranks_differing` checks it).

PETSc objects are destroyed explicitly (:func:`destroying`): left to
the garbage collector, a parallel object's destruction is a collective call made at
different times on different ranks, which can hang or mix messages at exit.
"""
from __future__ import annotations

import glob
import hashlib
import os
import sys
from contextlib import contextmanager
from typing import Iterator, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
from numba import njit

from ..basis.locality import inverse_order, renumbered
from .partition import Bisection

__all__ = ["PETSC_INSTALL_HINT", "PetscUnavailableError", "import_petsc", "debian_petsc_dir",
           "csr_to_petsc", "vector", "gather", "destroying", "check_replicated",
           "default_options", "default_split", "split_bounds", "row_range", "ranks_differing",
           "world", "rows_to_petsc", "summed_rows", "sent_rows", "ReceivedRows", "summed",
           "maximum", "joined", "first_block_first", "nest_from_rows", "nest_blocks", "nest_of",
           "owned_elements"]

PETSC_INSTALL_HINT = (
    "petsc4py and mpi4py are needed for the parallel solvers. PyPI has PETSc only as a "
    "source build; on Debian or Ubuntu install the binaries with "
    "`apt-get install python3-petsc4py python3-mpi4py`, make a virtual environment that sees "
    "them (`/usr/bin/python3 -m venv --system-site-packages .venv-mpi`), install this package "
    "there with numpy below 2 (`pip install -e \".[test]\" \"numpy<2\"`), and set PETSC_DIR to "
    "Debian's PETSc (/usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real) if it is not found; "
    "see docs/parallel.md")
"""How to install PETSc for this package: the text of :class:`PetscUnavailableError`."""

# Debian's PETSc for real scalars: petsc4py lives in its lib/python3/dist-packages, and
# Debian's .pth file finds it only through PETSC_DIR or the /usr/lib/petsc link (which
# only the development package installs)
DEBIAN_PETSC_GLOB = "/usr/lib/petscdir/petsc*/*-real"


class PetscUnavailableError(ImportError):
    """petsc4py (or mpi4py) cannot be imported; the message says how to install them."""


def debian_petsc_dir() -> Optional[str]:
    """PETSC_DIR if set, else the newest Debian PETSc for real scalars, else None."""
    env = os.environ.get("PETSC_DIR")
    if env:
        return env
    found = sorted(glob.glob(DEBIAN_PETSC_GLOB))
    return found[-1] if found else None


def import_petsc():
    """The ``petsc4py.PETSc`` module, initialised with the command line.

    Looks for petsc4py on the path, then in the PETSc directory of
    :func:`debian_petsc_dir`. The command-line arguments go to PETSc's options database
    (``-stokes_ksp_monitor`` and the like), as in any PETSc program. Raises
    :class:`PetscUnavailableError` naming the installation route when petsc4py, mpi4py
    or PETSc's library cannot be loaded.
    """
    if "petsc4py.PETSc" in sys.modules:
        return sys.modules["petsc4py.PETSc"]
    try:
        petsc4py = _find_petsc4py()
        import mpi4py  # noqa: F401  (PETSc's communicators as mpi4py ones)
        petsc4py.init(sys.argv)
        from petsc4py import PETSc
    except ImportError as err:
        raise PetscUnavailableError(f"{PETSC_INSTALL_HINT} (import failed: {err})") from None
    return PETSc


def _find_petsc4py():
    """Import petsc4py from the path or from Debian's PETSc directory."""
    try:
        import petsc4py
        return petsc4py
    except ImportError:
        where = debian_petsc_dir()
        if where is None:
            raise
    site = os.path.join(where, "lib", "python3", "dist-packages")
    if not os.path.isdir(site):
        raise ImportError(f"no petsc4py under PETSC_DIR={where}")
    sys.path.append(site)
    import petsc4py
    return petsc4py


def default_split(n: int, size: int) -> list:
    """PETSc's default numbers of rows per rank: ``n`` split as equally as possible,
    the lower ranks taking one more where it does not divide."""
    return [n // size + (1 if r < n % size else 0) for r in range(size)]


def row_range(n: int, comm, owned: Optional[Sequence[int]] = None) -> Tuple[int, int]:
    """This rank's rows ``[r0, r1)`` of ``n``: from ``owned`` (rows per rank) if given,
    else PETSc's default split (as equal as possible, lower ranks taking the rest)."""
    return split_bounds(n, comm.getSize(), owned)[comm.getRank()]


def split_bounds(n: int, size: int, owned: Optional[Sequence[int]] = None) -> list:
    """Every rank's ``(start, end)`` of ``n`` rows: from ``owned`` (rows per rank) if
    given, else PETSc's default split (:func:`default_split`)."""
    owned = default_split(n, size) if owned is None else [int(k) for k in owned]
    if len(owned) != size or sum(owned) != n or min(owned) < 0:
        raise ValueError(f"owned must give {size} non-negative row counts adding up to {n}, "
                         f"got {owned}")
    ends = np.cumsum([0] + owned).tolist()
    return list(zip(ends[:-1], ends[1:]))


def csr_to_petsc(A: sp.spmatrix, comm=None, owned: Optional[Sequence[int]] = None):
    """A square scipy sparse matrix (the same on every rank) as a PETSc AIJ matrix
    (MPIAIJ on several ranks), each rank inserting its own block of rows
    (:func:`row_range`); the columns are split like the rows."""
    PETSc = import_petsc()
    comm = PETSc.COMM_WORLD if comm is None else comm
    A = sp.csr_matrix(A)
    n, m = A.shape
    if n != m:
        raise ValueError(f"csr_to_petsc needs a square matrix, got shape {A.shape}")
    r0, r1 = row_range(n, comm, owned)
    return rows_to_petsc(A[r0:r1], n, comm)


def rows_to_petsc(block: sp.spmatrix, n: int, comm):
    """This rank's block of rows (``block``, in CSR, all ``n`` columns) of an ``n`` by
    ``n`` matrix as a PETSc AIJ matrix, preallocated exactly from the block's pattern;
    the columns are split like the rows."""
    k = block.shape[0]
    return _aij(block, ((k, n), (k, n)), comm)


def first_block_first(order: np.ndarray, first: np.ndarray, bounds: list) -> np.ndarray:
    """``order`` (new ``i`` is old ``order[i]``) with each rank's rows (``bounds``) put
    first-block first, each block keeping its order: ``first`` marks the old unknowns of
    the first block. A matrix so numbered is a PETSc nest (:func:`nest_from_rows`)."""
    order = np.asarray(order)
    out = np.empty_like(order)
    for a, b in bounds:
        mine = order[a:b]
        lead = first[mine]
        k = a + int(np.count_nonzero(lead))
        out[a:k], out[k:b] = mine[lead], mine[~lead]
    return out


def nest_from_rows(rows: sp.csr_matrix, first: np.ndarray, start: int, comm):
    """This rank's rows ``rows`` (CSR, all columns, from row ``start`` on) of a matrix
    whose unknowns ``first`` marks as the first block's, as a PETSc nest of four MPIAIJ
    blocks, and its two row index sets. Each rank's rows must hold the first block's
    unknowns first (:func:`first_block_first`), so the nest numbers the unknowns as the
    rows do and vectors split like the rows serve it. :func:`nest_blocks` and
    :func:`nest_of` in one call; a caller that can let its rows go once they are split
    calls them apart.

    Why a nest: PCFIELDSPLIT takes a nest's blocks as they are, where it copies them out
    of one AIJ matrix (the viscous block, most of the entries, twice in memory)."""
    return nest_of(nest_blocks(rows, first, start), comm)


def nest_blocks(rows: sp.csr_matrix, first: np.ndarray, start: int) -> list:
    """The four blocks of :func:`nest_from_rows`' rows, rows by rows, each as
    ``((indptr, indices, data), ((local, global) rows, (local, global) columns))`` in
    PETSc's index type: one pass over the rows, one copy of them in all (slicing rows and
    columns with scipy made two, and PETSc's index type a third of the indices)."""
    PETSc = import_petsc()
    k, n = rows.shape
    mine = first[start:start + k]
    nv = int(np.count_nonzero(mine))
    if not mine[:nv].all():
        raise ValueError(f"rows {start}..{start + k - 1}: the first block's unknowns must "
                         f"come first on every rank (first_block_first)")
    first = np.asarray(first, dtype=bool)
    nfirst = int(np.count_nonzero(first))
    new = np.empty(n, dtype=np.int64)                  # a column's place in its block
    new[first] = np.arange(nfirst)
    new[~first] = np.arange(n - nfirst)
    rows = sp.csr_matrix(rows)
    if not rows.has_sorted_indices:
        rows = rows.sorted_indices()
    counts = np.zeros((k, 2), dtype=np.int64)
    _block_counts(rows.indptr, rows.indices, first, counts)
    out, sizes = [], ((nv, nfirst), (k - nv, n - nfirst))   # (local, global) of each block
    for i, (r0, r1) in enumerate(((0, nv), (nv, k))):
        for j in range(2):
            ptr = np.zeros(r1 - r0 + 1, dtype=PETSc.IntType)
            np.cumsum(counts[r0:r1, j], out=ptr[1:])
            idx = np.empty(int(ptr[-1]), dtype=PETSc.IntType)
            val = np.empty(int(ptr[-1]), dtype=PETSc.ScalarType)
            _block_fill(rows.indptr, rows.indices, rows.data, first, new, r0, r1, j == 0,
                        ptr, idx, val)
            out.append(((ptr, idx, val), (sizes[i], sizes[j])))
    return out


def nest_of(blocks: list, comm):
    """The PETSc nest of :func:`nest_blocks`' four blocks (emptied as each becomes a
    PETSc matrix, so its arrays go as PETSc's copy is made) and its two row index
    sets."""
    PETSc = import_petsc()
    mats = []
    while blocks:
        csr, size = blocks.pop(0)
        M = PETSc.Mat().createAIJ(size=size, csr=csr, comm=comm)
        del csr
        M.assemble()
        mats.append(M)
    K = PETSc.Mat().createNest([mats[:2], mats[2:]], comm=comm)
    for M in mats:
        M.destroy()   # (the nest holds them)
    return K, K.getNestISs()[0]


@njit(cache=True)
def _block_counts(indptr, indices, first, counts):
    """Each row's entries in the first block's columns and in the others'."""
    for r in range(indptr.size - 1):
        for k in range(indptr[r], indptr[r + 1]):
            counts[r, 0 if first[indices[k]] else 1] += 1


@njit(cache=True)
def _block_fill(indptr, indices, data, first, new, r0, r1, lead, ptr, out_indices, out_data):
    """Rows ``r0 .. r1 - 1``' entries in the first block's columns (``lead``) or the
    others', renumbered within the block (``new``), in order."""
    for r in range(r0, r1):
        f = ptr[r - r0]
        for k in range(indptr[r], indptr[r + 1]):
            c = indices[k]
            if first[c] == lead:
                out_indices[f] = new[c]
                out_data[f] = data[k]
                f += 1


def _aij(block: sp.csr_matrix, size: tuple, comm):
    """A CSR block of rows as a PETSc AIJ matrix of local and global ``size``
    ((rows), (columns)), preallocated exactly."""
    PETSc = import_petsc()
    block = sp.csr_matrix(block)
    block.sort_indices()
    csr = (block.indptr.astype(PETSc.IntType), block.indices.astype(PETSc.IntType),
           np.asarray(block.data, dtype=PETSc.ScalarType))
    M = PETSc.Mat().createAIJ(size=size, csr=csr, comm=comm)
    M.assemble()
    return M


def summed_rows(part: sp.spmatrix, comm, owned: Optional[Sequence[int]] = None,
                order: Optional[np.ndarray] = None):
    """This rank's rows (:func:`row_range`) of the sum over the ranks of ``part``, each
    rank's share of a matrix assembled in parts (its own triangles): every rank sends
    each other rank the rows it owns and adds what it receives, so no rank ever holds
    more than its share and its own rows. ``order``: the unknowns renumbered first (new
    ``i`` is old ``order[i]``, rows and columns; one copy of the share).
    :func:`sent_rows` and :meth:`ReceivedRows.summed` in one call; a caller that can let
    its share go once it is sent calls them apart."""
    return sent_rows(part, comm, owned, order).summed()


def sent_rows(part: sp.spmatrix, comm, owned: Optional[Sequence[int]] = None,
              order: Optional[np.ndarray] = None) -> "ReceivedRows":
    """Every rank's rows of this rank's ``part`` sent to it, and this rank's rows of every
    rank's share received (``order`` as in :func:`summed_rows`); the share is not needed
    after, so a caller lets it go before :meth:`ReceivedRows.summed` adds them up.

    The rows go as raw arrays (MPI's ``Alltoallv`` of the row lengths, the column indices
    and the values straight from the share's arrays, which hold each rank's rows in one
    piece): no pickled copies. At 101,054 nodes on two ranks the exchange's peak was 375
    MB above the share with Python's ``alltoall`` of the blocks."""
    part = sp.csr_matrix(part)
    if order is not None:
        part = renumbered(part, order, inverse_order(order))
    bounds = split_bounds(part.shape[0], comm.getSize(), owned)
    return _exchanged(part, bounds, comm.tompi4py())


class ReceivedRows:
    """This rank's rows as every rank's share holds them (:func:`sent_rows`): the row
    lengths ``counts`` (sender by sender, ``mine`` rows each), and the column indices and
    values one sender's piece after the other, from ``at[s]``."""

    def __init__(self, counts, at, indices, data, mine: int, ncols: int):
        self.counts, self.at, self.indices, self.data = counts, at, indices, data
        self.mine, self.ncols = mine, ncols

    def summed(self) -> sp.csr_matrix:
        """The rows summed over the senders, as one CSR block with sorted columns. Once:
        the received arrays are let go as the rows are laid out (a row's pieces side by
        side, then added in place; scipy's sum of the senders' blocks one after the
        other held three copies of the rows)."""
        lengths = self.counts.reshape(self.at.size - 1, self.mine).sum(axis=0)
        total = int(lengths.sum())
        wide = self.indices.dtype != np.int32 or total > np.iinfo(np.int32).max
        ptr = np.zeros(self.mine + 1, dtype=np.int64 if wide else np.int32)
        np.cumsum(lengths, out=ptr[1:])
        indices = np.empty(total, dtype=ptr.dtype)
        data = np.empty(total, dtype=self.data.dtype)
        _side_by_side(self.counts, self.at, self.indices, self.data, ptr, indices, data)
        self.indices = self.data = None
        rows = sp.csr_matrix((data, indices, ptr), shape=(self.mine, self.ncols))
        rows.sum_duplicates()
        rows.eliminate_zeros()      # (as a sum of scipy's blocks: the same pattern)
        return rows


@njit(cache=True)
def _side_by_side(counts, at, indices, data, ptr, out_indices, out_data):
    """Each row's pieces from the senders (``counts`` sender by sender, pieces from
    ``at``) one after the other in the row ``ptr`` gives it."""
    mine = ptr.size - 1
    fill = ptr[:-1].astype(np.int64)
    for s in range(at.size - 1):
        o = at[s]
        for i in range(mine):
            n = counts[s * mine + i]
            f = fill[i]
            for k in range(n):
                out_indices[f + k] = indices[o + k]
                out_data[f + k] = data[o + k]
            fill[i] = f + n
            o += n


def _exchanged(K: sp.csr_matrix, bounds: list, mpi) -> ReceivedRows:
    """The rows ``bounds[rank]`` of every rank's ``K`` (rows in the same numbering on
    every rank), received on this rank."""
    rank, size = mpi.Get_rank(), mpi.Get_size()
    lo = np.array([a for a, _ in bounds], dtype=np.int64)
    hi = np.array([b for _, b in bounds], dtype=np.int64)
    lengths = np.diff(K.indptr).astype(np.int64)
    nnz_out = K.indptr[hi] - K.indptr[lo]
    nnz_in = np.empty(size, dtype=np.int64)
    mpi.Alltoall(np.ascontiguousarray(nnz_out, dtype=np.int64), nnz_in)
    mine = int(hi[rank] - lo[rank])
    rows_in = np.empty(size * mine, dtype=np.int64)
    mpi.Alltoallv([lengths, (hi - lo, lo)], [rows_in, (np.full(size, mine), mine * np.arange(
        size))])
    at = np.zeros(size + 1, dtype=np.int64)
    np.cumsum(nnz_in, out=at[1:])
    recv = []
    for buf in (K.indices, K.data):
        out = np.empty(int(at[-1]), dtype=buf.dtype)
        mpi.Alltoallv([buf, (nnz_out, K.indptr[lo])], [out, (nnz_in, at[:-1])])
        recv.append(out)
    return ReceivedRows(rows_in, at, recv[0], recv[1], mine, K.shape[1])


def summed(values: np.ndarray, comm=None) -> np.ndarray:
    """The sum over the ranks of ``values`` (the same shape on every rank), on every rank."""
    return _allreduced(values, "SUM", comm)


def maximum(values: np.ndarray, comm=None) -> np.ndarray:
    """The entrywise maximum over the ranks of ``values`` (the same shape on every rank),
    on every rank."""
    return _allreduced(values, "MAX", comm)


def _allreduced(values: np.ndarray, op: str, comm=None) -> np.ndarray:
    """``values`` reduced over the ranks by MPI's operation ``op`` (its name), on every
    rank (a copy on one rank)."""
    PETSc = import_petsc()
    comm = PETSc.COMM_WORLD if comm is None else comm
    values = np.ascontiguousarray(values, dtype=float)
    if comm.getSize() == 1:
        return values.copy()
    out = np.empty_like(values)
    from mpi4py import MPI
    comm.tompi4py().Allreduce(values, out, op=getattr(MPI, op))
    return out


def joined(part: np.ndarray, rows: np.ndarray, n: int, comm=None) -> np.ndarray:
    """The whole array of ``n`` rows of which each rank holds the rows ``rows`` (``part``,
    its cells' values of an integration-point field; the ranks' ``rows`` a partition of
    ``range(n)``), on every rank. Each row comes from one rank and is added to zeros,
    so it is that rank's bit for bit."""
    part = np.asarray(part, dtype=float)
    whole = np.zeros((n,) + part.shape[1:])
    whole[rows] = part
    return summed(whole, comm)


def vector(values: np.ndarray, comm=None, owned: Optional[Sequence[int]] = None):
    """A PETSc vector holding this rank's block of ``values`` (the same on every rank)."""
    PETSc = import_petsc()
    comm = PETSc.COMM_WORLD if comm is None else comm
    values = np.asarray(values, dtype=PETSc.ScalarType)
    r0, r1 = row_range(values.size, comm, owned)
    v = PETSc.Vec().createMPI((r1 - r0, values.size), comm=comm)
    v.setArray(values[r0:r1])
    return v


def gather(v) -> np.ndarray:
    """The whole of the distributed vector ``v`` on every rank."""
    PETSc = import_petsc()
    scatter, whole = PETSc.Scatter.toAll(v)
    try:
        scatter.scatter(v, whole, addv=PETSc.InsertMode.INSERT,
                        mode=PETSc.ScatterMode.FORWARD)
        return whole.getArray().copy()
    finally:
        scatter.destroy()
        whole.destroy()


@contextmanager
def destroying(*objects) -> Iterator[list]:
    """A list of PETSc objects (more may be appended) destroyed on leaving, in reverse
    order, on every rank at the same point of the program; then PETSc's deferred
    garbage (wrappers of sub-objects the Python collector dropped) is cleaned up there
    too, a collective call."""
    kept = [o for o in objects if o is not None]
    try:
        yield kept
    finally:
        for obj in reversed(kept):
            obj.destroy()
        PETSc = import_petsc()
        if hasattr(PETSc, "garbage_cleanup"):  # petsc4py 3.18 and later
            PETSc.garbage_cleanup()


@contextmanager
def default_options(prefix: str, defaults: dict) -> Iterator[None]:
    """Put ``defaults`` (option name without ``-`` and ``prefix`` -> value) into PETSc's
    options database where the user has not set them, and take them out again on
    leaving: the user's options (command line, ``PETSC_OPTIONS``,
    ``PETSc.Options().setValue``) win, the PETSc way."""
    PETSc = import_petsc()
    opts = PETSc.Options()
    added = []
    for key, value in defaults.items():
        name = prefix + key
        if not opts.hasName(name):
            opts.setValue(name, value)
            added.append(name)
    try:
        yield
    finally:
        for name in added:
            opts.delValue(name)


def check_replicated(A: sp.spmatrix, comm=None, what: str = "matrix") -> None:
    """``ValueError`` if the ranks do not hold the same sparse matrix ``A`` (naming
    the ranks that differ from rank 0): the serial assembly must be replicated."""
    A = sp.csr_matrix(A)
    differ = ranks_differing((np.asarray(A.shape), A.indptr, A.indices, A.data), comm)
    if differ:
        raise ValueError(f"the {what} differs between rank 0 and rank(s) {differ}: the "
                         f"serial assembly must give the same system on every rank (seed "
                         f"random node sets)")


def ranks_differing(arrays: Sequence[np.ndarray], comm=None) -> list:
    """The ranks whose ``arrays`` (shapes, types and bytes) differ from rank 0's, by
    a hash gathered to every rank (the same list on every rank; empty on one rank)."""
    PETSc = import_petsc()
    comm = PETSc.COMM_WORLD if comm is None else comm
    if comm.getSize() == 1:
        return []
    h = hashlib.sha1()
    for part in arrays:
        part = np.ascontiguousarray(part)
        h.update(f"{part.dtype.str}{part.shape}".encode())
        h.update(part.tobytes())
    digests = comm.tompi4py().allgather(h.hexdigest())
    return [r for r, d in enumerate(digests) if d != digests[0]]


def world() -> Tuple[int, int]:
    """This process's rank and the number of ranks in PETSc's ``COMM_WORLD``."""
    comm = import_petsc().COMM_WORLD
    return comm.getRank(), comm.getSize()


def owned_elements(mesh) -> Optional[np.ndarray]:
    """This rank's share of the cells of ``mesh`` for distributed assembly: those whose
    centroids lie in this rank's part of the recursive bisection of the mesh's nodes
    (:class:`~skfem_nem.parallel.partition.Bisection`; the rows are split by the same
    parts, :func:`skfem_nem.models.stokes_solvers.part_order`), sorted. None on a single
    rank (every cell)."""
    rank, size = world()
    if size == 1:
        return None
    p, t = np.asarray(mesh.p), np.asarray(mesh.t)
    return np.flatnonzero(Bisection(p, size).part(p[:, t].mean(axis=1)) == rank)
