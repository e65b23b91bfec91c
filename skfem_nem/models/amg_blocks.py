"""The first level of the 3D viscous block's multigrid, made from the block's 3 x 3 node
blocks (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`) without the block as a
CSR matrix.

Why: pyamg sets up a hierarchy from a CSR matrix, and the 3D block as CSR takes twelve
bytes an entry (1.8 GB at 100,000 nodes), with pyamg's strength-of-connection matrix of
the same size beside it. On a plate step at 98,601 nodes that set-up was the step's peak:
7.86 GB before it, 10.1 GB during it. The finest level's three pieces need no such
matrix: the strong couplings come from the blocks (:meth:`BlockSymmetricRows.strong`,
pyamg's symmetric measure), pyamg aggregates them and fits the rigid-body modes into the
tentative prolongator ``T`` as it would, and the Galerkin product ``T^T A T`` is summed
from the blocks aggregate by aggregate (:func:`galerkin_of_blocks`: at 98,601 nodes 2.4 s
where scipy's products of slices of the block's rows took 8.6 s). pyamg then sets up the
levels below from ``T^T A T``. The first level's aggregates and prolongator are pyamg's
(up to a tie in the strength's last bit), ``T^T A T`` is pyamg's to rounding; the levels
below can aggregate otherwise, because pyamg's own product leaves the coarse matrix's
blocks unsorted, with some zero blocks stored, and its aggregation follows that order.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..basis.multigrid import polynomial_smoothers
from .block_rows import BlockSymmetricRows

__all__ = ["GALERKIN_SLICE", "galerkin_of_blocks", "hierarchy_of_blocks", "plain_aggregation"]

# entries of the block expanded to CSR at a time in a Galerkin product by scipy's (a
# prolongator not of aggregates): some 240 MB of CSR rows (a twelfth of the block at
# 100,000 nodes), the product's cost unchanged
GALERKIN_SLICE = 20_000_000


def plain_aggregation(options: dict) -> bool:
    """True if pyamg's ``options`` ask for plain aggregation: no prolongator smoothing and no
    relaxed candidates (both default to pyamg's Jacobi and Gauss-Seidel otherwise), the
    first level :func:`hierarchy_of_blocks` makes."""
    return ("smooth" in options and options["smooth"] is None
            and "improve_candidates" in options and options["improve_candidates"] is None)


def galerkin_of_blocks(A: BlockSymmetricRows, P, width: Optional[int] = None) -> sp.bsr_array:
    """``P^T A P`` for the block ``A`` and a prolongator ``P`` (fine x coarse), a BSR array
    with square blocks of ``width`` (default: ``P``'s block width; pyamg's form of a
    coarse level). An aggregation's prolongator (each row within one aggregate's
    ``width`` columns) takes :func:`_galerkin_rows`, any other one slices of the block's
    rows as CSR (:data:`GALERKIN_SLICE` entries each) and scipy's products."""
    if width is None:
        width = P.blocksize[1] if getattr(P, "format", None) == "bsr" else 1
    fitted = _aggregate_rows(sp.csr_matrix(P), width)
    if fitted is None:
        return _galerkin_by_slices(A, P, width)
    agg_of, tv, n_agg = fitted
    col_of, owner, tptr, tblock = A.walk_tables()
    members = np.argsort(agg_of, kind="stable")
    first = np.searchsorted(agg_of[members], np.arange(n_agg + 1))
    args = (A.indptr, A.indices, A.data, owner, tptr, tblock, col_of, A.position, first,
            members, agg_of, tv)
    count = np.zeros(n_agg, np.int64)
    _galerkin_rows(*args, count, count[:0], count[:0], np.zeros((0, width, width)))
    indptr = np.zeros(n_agg + 1, np.int64)
    np.cumsum(count, out=indptr[1:])
    indices, data = np.empty(indptr[-1], np.int64), np.empty((indptr[-1], width, width))
    _galerkin_rows(*args, count[:0], indptr, indices, data)
    idt = np.int32 if indptr[-1] < 2 ** 31 else np.int64
    return sp.bsr_array((data, indices.astype(idt), indptr.astype(idt)),
                        shape=(n_agg * width, n_agg * width))


def _galerkin_by_slices(A: BlockSymmetricRows, P, width: int) -> sp.bsr_array:
    """``P^T A P`` by scipy's products, ``A``'s rows as CSR a slice at a time."""
    P = sp.csr_matrix(P)
    n = A.shape[0]
    per_row = max(1.0, 2.0 * A.nnz / max(n, 1))
    step = max(1, int(GALERKIN_SLICE / per_row))
    out = None
    for r0, rows in zip(range(0, n, step), A.row_slices(step)):
        part = sp.csr_matrix(P[r0:r0 + step].T @ (rows @ P))
        out = part if out is None else out + part
    out = sp.bsr_array(out, blocksize=(width, width))
    out.sort_indices()
    return out


def _aggregate_rows(P: sp.csr_matrix, width: int):
    """``(agg_of, tv, n_agg)`` if each row of ``P`` has its entries among one aggregate's
    ``width`` columns: the row's aggregate (-1: an empty row) and its values there
    (n, width); else None."""
    if width < 1 or P.shape[1] % width:
        return None
    rows = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
    agg = P.indices // width
    if (agg != agg[P.indptr[rows]]).any():          # (each entry against its row's first)
        return None
    agg_of = np.full(P.shape[0], -1, np.int64)
    agg_of[rows] = agg
    tv = np.zeros((P.shape[0], width))
    np.add.at(tv, (rows, P.indices % width), P.data)
    return agg_of, tv, P.shape[1] // width


def hierarchy_of_blocks(A: BlockSymmetricRows, B: np.ndarray, strength: tuple,
                        coarse_solver: str, **options):
    """pyamg's smoothed-aggregation hierarchy of the block ``A`` (scaled, on the free
    unknowns) with the near null space ``B``, its finest level made from the blocks: the
    symmetric strength ``strength`` (``("symmetric", {"theta": t})``), standard aggregation,
    the tentative prolongator (unsmoothed: the 3D block's prolongators are not smoothed),
    and ``T^T A T``; the levels below by ``pyamg.smoothed_aggregation_solver`` with
    ``options``. The finest level keeps no matrix (``A`` None) and no smoother: the caller
    applies its own. ``ValueError`` for another strength or a smoothed prolongator."""
    import pyamg
    from pyamg.aggregation import fit_candidates, standard_aggregation
    from pyamg.multilevel import MultilevelSolver
    from pyamg.relaxation.smoothing import setup_none
    name, kwargs = strength
    if name != "symmetric" or not plain_aggregation(options):
        raise ValueError(f"hierarchy_of_blocks makes the symmetric strength and plain "
                         f"aggregation (smooth=None, improve_candidates=None), got strength "
                         f"{name!r} and {options}")
    aggregates, _ = standard_aggregation(A.strong(kwargs["theta"]))
    T, coarse_modes = fit_candidates(aggregates, B)
    coarse = pyamg.smoothed_aggregation_solver(
        galerkin_of_blocks(A, T), B=coarse_modes, symmetry="symmetric", strength=strength,
        coarse_solver=coarse_solver, **options)
    polynomial_smoothers(coarse, options.get("presmoother"), options.get("postsmoother"))
    finest = MultilevelSolver.Level()
    finest.A, finest.B, finest.P, finest.R = None, B, T, T.T
    finest.presmoother = finest.postsmoother = setup_none(finest)
    return MultilevelSolver([finest] + coarse.levels, coarse_solver=coarse_solver)


@njit(cache=True, parallel=True)
def _galerkin_rows(bptr, bind, data, owner, tptr, tblock, col_of, position, first, members,
                   agg_of, tv, count, indptr, indices, out):
    """Block row a of ``T^T A T`` for a prolongator ``T`` of aggregates (row r: the values
    ``tv[r]`` in aggregate ``agg_of[r]``'s columns): for each row r of aggregate a
    (``members[first[a]:first[a + 1]]``), ``w_b = sum_c A[r, c] tv[c]`` over the columns of
    each aggregate b met, then ``tv[r] w_b^T`` into block (a, b). Rows of the symmetric
    ``A`` are walked as ``BlockSymmetricRows.walk_tables`` says: the transposed blocks of
    the nodes below (side 0), then the node's own (side 1). With ``count`` not empty only
    the number of blocks of each row is counted; else the blocks are written from
    ``indptr[a]``, aggregates ascending. Both passes and both sides in one loop nest, with
    working arrays a chunk of aggregates: hence its length."""
    n_agg, K = first.size - 1, tv.shape[1]
    values = count.size == 0
    nblocks = min(n_agg, 64)
    for blk in prange(nblocks):
        amark = np.full(n_agg, -1, np.int64)
        rmark = np.full(n_agg if values else 0, -1, np.int64)
        alist = np.empty(n_agg, np.int64)
        rlist = np.empty(n_agg if values else 0, np.int64)
        w = np.empty((n_agg if values else 0, K))
        acc = np.empty((n_agg if values else 0, K, K))
        for a in range(blk * n_agg // nblocks, (blk + 1) * n_agg // nblocks):
            na = 0
            for m in range(first[a], first[a + 1]):
                r = members[m]
                i, comp = position[r] // 3, position[r] % 3
                nr = 0
                for side in range(2):
                    lo, hi = (tptr[i], tptr[i + 1]) if side == 0 else (bptr[i], bptr[i + 1])
                    for t in range(lo, hi):
                        k = tblock[t] if side == 0 else t
                        node = owner[k] if side == 0 else bind[k]
                        for b3 in range(3):
                            c = col_of[3 * node + b3]
                            if c < 0 or agg_of[c] < 0:
                                continue
                            b = agg_of[c]
                            if amark[b] != a:
                                amark[b], alist[na] = a, b
                                na += 1
                                if values:
                                    acc[b] = 0.0
                            if not values:
                                continue
                            if rmark[b] != r:
                                rmark[b], rlist[nr] = r, b
                                nr += 1
                                w[b] = 0.0
                            v = data[9 * k + 3 * b3 + comp] if side == 0 else \
                                data[9 * k + 3 * comp + b3]
                            for q in range(K):
                                w[b, q] += v * tv[c, q]
                for s in range(nr):
                    b = rlist[s]
                    for p in range(K):
                        for q in range(K):
                            acc[b, p, q] += tv[r, p] * w[b, q]
            if not values:
                count[a] = na
                continue
            order = np.sort(alist[:na])
            for s in range(na):
                indices[indptr[a] + s] = order[s]
                out[indptr[a] + s] = acc[order[s]]
