"""Sparse LU factors of the viscous block, the preconditioner of solver ``"schur"``
(:mod:`skfem_nem.models.stokes_solvers`): of the whole block, or of the diagonal
block of each velocity component, the two made and applied side by side in two
threads (SuperLU releases the interpreter lock).

Kept apart from the solvers because a factorisation is one concern with its own
choices (scaling, precision, ordering, the split by components); the solvers only
call ``solve``.
"""
from __future__ import annotations

import threading
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .stokes_amg import scaled_block, unit_scale

__all__ = ["ComponentFactors", "ViscousFactor", "in_two_threads", "ordering"]

#: blocks with more entries a row than this are ordered by COLAMD, the others by symmetric
#: minimum degree. Measured on the scaled viscous block, 2,139 nodes, no slip: Taylor-Hood
#: (22 entries a row) fills 1.8M with minimum degree against 3.4M with COLAMD, the linear
#: natural-neighbour block (61) 1.0M against 1.4M; the quadratic natural-neighbour block
#: (200) 40M in 4.8 s against 27M in 2.6 s, and at 4,220 nodes 106M in 17.4 s against 81M
#: in 10.2 s
DENSE_ROW_ENTRIES = 100


def ordering(M: sp.spmatrix) -> str:
    """SuperLU's column ordering for the block M (see :data:`DENSE_ROW_ENTRIES`)."""
    return "COLAMD" if M.nnz > DENSE_ROW_ENTRIES * M.shape[0] else "MMD_AT_PLUS_A"


class ViscousFactor:
    """Sparse LU of the viscous block ``A`` scaled by its diagonal, ``D^-1/2 A D^-1/2``,
    in the precision ``dtype`` (ordered by :func:`ordering`); :meth:`solve`
    applies the resulting approximation of ``A^-1`` to double-precision vectors. The
    scaling takes the viscosity contrast out of the factors' rounding: an unscaled
    single-precision factorisation needed as many iterations at a contrast of 1e6 but
    took twice as long to make (SolCx, 16,430 nodes)."""

    def __init__(self, A: sp.spmatrix, dtype=np.float64):
        # a CSR block is factorised as its transpose, whose CSC arrays are its own
        # (no conversion of the block; solves then use the transposed factors)
        self.trans = "T" if A.format == "csr" else "N"
        M = A.T if self.trans == "T" else sp.csc_matrix(A)
        if not M.has_sorted_indices:
            # (COLAMD factorises a block with unsorted columns wrongly; the copy leaves
            # the caller's arrays as they are)
            M = M.sorted_indices()
        self.scale = unit_scale(M)
        scaled = scaled_block(M, self.scale, dtype)
        self.dtype = np.dtype(dtype)
        try:
            self.lu = spla.splu(scaled, permc_spec=ordering(scaled),
                                options=dict(SymmetricMode=True))
        except RuntimeError as err:
            raise RuntimeError(f"the viscous block is singular ({err}): check the wall "
                               f"conditions (a rigid-body motion left free?)") from None

    def solve(self, r: np.ndarray) -> np.ndarray:
        """``A^-1 r`` (to the rounding of the factors' precision)."""
        s = self.scale
        return s * self.lu.solve((s * r).astype(self.dtype), trans=self.trans).astype(float)


class ComponentFactors:
    """Sparse LU of the two diagonal blocks of the viscous block ``A``, one per velocity
    component (``components``: 0 or 1 for each row), each as :class:`ViscousFactor`;
    :meth:`solve` applies the block-diagonal approximation of ``A^-1``. The coupling of
    the components through the symmetric gradient is left to the Krylov method (with
    walls that hold the rigid motions, Korn's inequality makes the block-diagonal part
    spectrally equivalent to ``A``). Each block has half the unknowns and half the
    entries a row of ``A``, so the two fill half as much as ``A``'s factors, and the
    two are made and applied in two threads: at 120,642 unknowns (SolCx, 60,814 nodes,
    contrast 10) 0.87 s to factorise against 3.58 s for the whole block, 42 FGMRES
    iterations against 24, 3.4 s to solve against 6.5 s (docs/stokes.md)."""

    def __init__(self, A: sp.spmatrix, components: np.ndarray, dtype=np.float64):
        A = sp.csr_matrix(A)
        self.rows = [np.flatnonzero(components == c) for c in (0, 1)]
        blocks = [A[r][:, r] for r in self.rows]
        self.parts = in_two_threads([lambda b=b: ViscousFactor(b, dtype) for b in blocks])
        self.dtype = self.parts[0].dtype

    def solve(self, r: np.ndarray) -> np.ndarray:
        """The block-diagonal approximation of ``A^-1 r``."""
        parts = in_two_threads([lambda k=k: self.parts[k].solve(r[self.rows[k]])
                                for k in (0, 1)])
        x = np.empty(r.shape)
        for rows, part in zip(self.rows, parts):
            x[rows] = part
        return x


def in_two_threads(tasks: Sequence[Callable]) -> list:
    """The results of the two calls ``tasks``, the first in a new thread, the second
    in this one (an exception in either is raised here)."""
    out, err = [None, None], []

    def first():
        try:
            out[0] = tasks[0]()
        except BaseException as e:  # raised again in the calling thread
            err.append(e)

    t = threading.Thread(target=first)
    t.start()
    try:
        out[1] = tasks[1]()
    finally:
        t.join()
    if err:
        raise err[0]
    return out
