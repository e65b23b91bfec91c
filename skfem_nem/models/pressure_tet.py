"""The pressure blocks of the Stokes problem on tetrahedra, from 4 x 4 blocks a tetrahedron.

Two blocks of the 3D system act on the linear pressure alone and change with the viscosity,
so every Picard iteration makes them again: the pressure mass weighted by ``1 / eta`` (the
Schur complement's preconditioner) and, for the bubble-enriched velocity, the bubbles'
``B_b A_bb^-1 B_b^T``. Each is a sum of one 4 x 4 block per tetrahedron, and both blocks are
a few batched products of small arrays: the P1 functions' values are the same at the
reference points of every tetrahedron, and the bubbles' part of the divergence is the
4 x 3 block of :class:`~skfem_nem.models.condensation_tet.TetDivergence`. At 223,445
tetrahedra the mass takes 0.18 s against scikit-fem's form assembly's 0.42 s, the bubbles'
block 0.20 s against the sparse triple product's 0.76 s; most of what is left is the sum
of the blocks into CSR.
"""
from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp

from ..geometry.entities import unique_ints

__all__ = ["tet_blocks_summed", "weighted_mass_tet", "bubble_stabilisation_tet"]


def tet_blocks_summed(pbasis, local: np.ndarray) -> sp.csr_matrix:
    """(np, np) CSR sum of the blocks ``local`` (ne, 4, 4) of the P1 pressure ``pbasis``'s
    tetrahedra (``local[e, i, j]`` at row ``element_dofs[i, e]``, column
    ``element_dofs[j, e]``). The pattern and each block entry's place in it are found once
    a basis (:func:`_pattern`); a call then sums the entries into their places."""
    ne = np.shape(pbasis.element_dofs)[1]
    if local.shape != (ne, 4, 4):
        raise ValueError(f"local must have shape ({ne}, 4, 4), got {local.shape}")
    indptr, indices, place = _pattern(pbasis)
    data = np.bincount(place, weights=local.ravel(), minlength=indices.size)
    return sp.csr_matrix((data, indices, indptr), shape=(pbasis.N, pbasis.N))


# the CSR pattern of each pressure basis and the place of each of its block entries, kept
# while the basis lives: the Picard iterations of a step make both blocks on one basis again
# and again, and scipy's sum of duplicates (a sort of every row) was most of their time
_PATTERNS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _pattern(pbasis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, place)``: the CSR pattern of ``pbasis``'s tetrahedra's blocks
    and, for each entry of ``local.ravel()``, the index of its CSR entry."""
    if pbasis in _PATTERNS:
        return _PATTERNS[pbasis]
    dofs = np.asarray(pbasis.element_dofs).T.astype(np.int64)      # (ne, 4)
    n = np.int64(pbasis.N)
    key = (np.repeat(dofs, 4, axis=1) * n + np.tile(dofs, (1, 4))).ravel()
    entries, place = unique_ints(key, return_inverse=True)
    indptr = np.zeros(pbasis.N + 1, np.int64)
    np.cumsum(np.bincount(entries // n, minlength=pbasis.N), out=indptr[1:])
    small = np.int32 if max(pbasis.N, entries.size) < 2 ** 31 else np.int64
    out = (indptr.astype(small), (entries % n).astype(small), place.astype(small))
    _PATTERNS[pbasis] = out
    return out


def weighted_mass_tet(pbasis, c: np.ndarray) -> sp.csr_matrix:
    """The P1 pressure mass ``(c p, q)`` weighted by ``c`` (ne, nq) at the quadrature
    points of ``pbasis`` (on tetrahedra)."""
    X = pbasis.quadrature[0]
    phi = np.stack([pbasis.elem.lbasis(X, i)[0] for i in range(4)])      # (4, nq)
    pairs = (phi[:, None, :] * phi[None, :, :]).reshape(16, -1)          # (16, nq)
    w = np.asarray(c, dtype=float) * pbasis.dx
    return tet_blocks_summed(pbasis, (w @ pairs.T).reshape(-1, 4, 4))


def bubble_stabilisation_tet(pbasis, local: np.ndarray, Q: np.ndarray) -> sp.csr_matrix:
    """``B_b A_bb^-1 B_b^T`` (np, np) from each tetrahedron's 4 x 3 block ``local`` of the
    bubbles' divergence and the inverse ``Q`` (ne, 3, 3) of its bubbles' block (zero for
    a flat tetrahedron)."""
    return tet_blocks_summed(pbasis, local @ Q @ np.swapaxes(local, 1, 2))
