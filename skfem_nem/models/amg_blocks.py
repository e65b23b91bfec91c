"""The first level of the 3D viscous block's multigrid, made from the block's 3 x 3 node
blocks (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`) without the block as a
CSR matrix.

Why: pyamg sets up a hierarchy from a CSR matrix, and the 3D block as CSR takes twelve
bytes an entry (1.8 GB at 100,000 nodes), with pyamg's strength-of-connection matrix of
the same size beside it. On a plate step at 98,601 nodes that set-up was the step's peak:
7.86 GB before it, 10.1 GB during it. The finest level's three pieces need no such
matrix: the strong couplings come from the blocks (:meth:`BlockSymmetricRows.strong`,
pyamg's symmetric measure), pyamg aggregates them and fits the rigid-body modes into the
tentative prolongator ``T`` as it would, and the Galerkin product ``T^T A T`` takes the
block's rows as CSR a slice at a time (:func:`galerkin_of_blocks`). pyamg then sets up the
levels below from ``T^T A T``. The first level's aggregates and prolongator are pyamg's
(up to a tie in the strength's last bit), ``T^T A T`` is pyamg's to rounding; the levels
below can aggregate otherwise, because pyamg's own product leaves the coarse matrix's
blocks unsorted, with some zero blocks stored, and its aggregation follows that order.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .block_rows import BlockSymmetricRows

__all__ = ["GALERKIN_SLICE", "galerkin_of_blocks", "hierarchy_of_blocks", "plain_aggregation"]

# entries of the block expanded to CSR at a time in the Galerkin product: some 240 MB of
# CSR rows (a twelfth of the block at 100,000 nodes), the product's cost unchanged
GALERKIN_SLICE = 20_000_000


def plain_aggregation(options: dict) -> bool:
    """True if pyamg's ``options`` ask for plain aggregation: no prolongator smoothing and no
    relaxed candidates (both default to pyamg's Jacobi and Gauss-Seidel otherwise), the
    first level :func:`hierarchy_of_blocks` makes."""
    return ("smooth" in options and options["smooth"] is None
            and "improve_candidates" in options and options["improve_candidates"] is None)


def galerkin_of_blocks(A: BlockSymmetricRows, P) -> sp.bsr_array:
    """``P^T A P`` for the block ``A`` and a prolongator ``P`` (fine x coarse), from slices
    of the block's rows as CSR (:data:`GALERKIN_SLICE` entries each); a BSR array with
    square blocks of ``P``'s block width (pyamg's form of a coarse level)."""
    width = P.blocksize[1] if getattr(P, "format", None) == "bsr" else 1
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
    finest = MultilevelSolver.Level()
    finest.A, finest.B, finest.P, finest.R = None, B, T, T.T
    finest.presmoother = finest.postsmoother = setup_none(finest)
    return MultilevelSolver([finest] + coarse.levels, coarse_solver=coarse_solver)
