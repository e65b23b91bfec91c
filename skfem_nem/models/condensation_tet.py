"""Static condensation of the Stokes bubbles on tetrahedra, by sparse products.

The 3D natural-neighbour velocity of method ``"nem"`` carries one quartic bubble per
tetrahedron and component (:class:`~skfem_nem.models.stokes_bases.ElementTetBubble`).
Each bubble lives in one tetrahedron, so the bubbles' viscous block ``A_bb`` is block
diagonal, 3 x 3 a tetrahedron, and eliminating them gives

    A = A_nn - A_bn^T A_bb^-1 A_bn,      B = B_n - B_b A_bb^-1 A_bn,

with ``A_bn`` the coupling of the bubbles to the natural-neighbour functions. The 2D
condensation (:mod:`skfem_nem.models.condensation`) does this triangle by triangle inside
numba kernels written for two components; here the blocks are scikit-fem assemblies on
the smoothed Box 1 basis and the products are sparse. With one smoothing cell per
tetrahedron the natural-neighbour gradients are constant on it and the bubble's gradient
integrates to zero there, so ``A_bn`` vanishes for a viscosity constant on each
tetrahedron and is small otherwise: the condensation is cheap beside the assembly of
``A_nn``. The 2D kernels stay as they are: ``--dim 2`` is bitwise unchanged.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from skfem import BilinearForm
from skfem.helpers import ddot, sym_grad

from .condensation import CondensedViscous

__all__ = ["condensed_viscous_tet", "condensed_divergence_tet"]


@BilinearForm
def _viscous(u, v, w):
    # the viscous form 2 eta eps(u) : eps(v) (as in models.stokes, which imports this)
    return 2.0 * w["eta"] * ddot(sym_grad(u), sym_grad(v))


def _block_inverse(Abb: sp.csr_matrix, bd: np.ndarray) -> sp.csr_matrix:
    """The inverse of the block-diagonal ``Abb`` whose blocks are the dofs ``bd`` (d, ne)
    of each tetrahedron's bubbles; ``ValueError`` naming the first singular block."""
    d, ne = bd.shape
    blocks = np.empty((ne, d, d))
    for i in range(d):
        for j in range(d):
            blocks[:, i, j] = np.asarray(Abb[bd[i], bd[j]]).ravel()
    det = np.linalg.det(blocks)
    bad = ~(det > 0)
    if bad.any():
        raise ValueError(f"degenerate tetrahedron {int(np.flatnonzero(bad)[0])}: its bubble "
                         f"block is singular ({int(bad.sum())} tetrahedra)")
    inv = np.linalg.inv(blocks)
    inv = 0.5 * (inv + inv.transpose(0, 2, 1))
    rows = np.repeat(bd.T, d, axis=1).ravel()
    cols = np.tile(bd.T, (1, d)).ravel()
    return sp.csr_matrix((inv.ravel(), (rows, cols)), shape=Abb.shape)


def condensed_viscous_tet(ubasis, bbasis, eta: np.ndarray) -> CondensedViscous:
    """The viscous block ``2 eta eps(u) : eps(v)`` of the natural-neighbour velocity
    ``ubasis`` on tetrahedra with the bubbles of ``bbasis`` (a vector
    :class:`~skfem_nem.models.stokes_bases.ElementTetBubble` basis on the same quadrature)
    condensed out, for the viscosity ``eta`` (ne, nq) at the quadrature points. The block
    comes out exactly symmetric."""
    Ann = _viscous.assemble(ubasis, eta=eta).tocsr()
    Abn = _viscous.assemble(ubasis, bbasis, eta=eta).tocsr()          # (nb, nu)
    Abb = _viscous.assemble(bbasis, eta=eta).tocsr()
    Ainv = _block_inverse(Abb, np.asarray(bbasis.element_dofs))
    AiAbn = (Ainv @ Abn).tocsr()
    A = (Ann - Abn.T @ AiAbn).tocsr()
    A = (0.5 * (A + A.T)).tocsr()
    return CondensedViscous(A, Ainv, AiAbn, None)


def condensed_divergence_tet(Bn: sp.csr_matrix, Bb: sp.csr_matrix,
                             cv: CondensedViscous) -> sp.csr_matrix:
    """The divergence block with the bubbles condensed out, ``B_n - B_b A_bb^-1 A_bn``,
    from the natural-neighbour functions' block ``Bn`` (np, nu), the bubbles' ``Bb``
    (np, nb) and the condensed viscous block ``cv``."""
    return (Bn - Bb @ cv.AiAbn).tocsr()
