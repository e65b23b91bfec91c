"""Static condensation of the Stokes bubbles, triangle by triangle, before the sum.

The natural-neighbour velocity of method ``"nem"`` carries one cubic bubble per triangle
and component (:class:`~skfem_nem.models.stokes_bases.ElementTriBubble`). A bubble lives
in one triangle, so eliminating it changes only that triangle's element matrix: the
viscous block of triangle e becomes ``A_e - A_bn,e^T A_bb,e^-1 A_bn,e``, where ``A_bn,e``
(2 x 2 S_e) couples its two bubbles to its S_e stencil functions and ``A_bb,e`` is their
2 x 2 block. Doing that here, on the element matrices before they are summed
(:func:`skfem_nem.basis.assembly.element_matrices`,
:func:`skfem_nem.basis.summation.sum_csr`), replaces the global sparse products
``A - A_bn^T (A_bb^-1 A_bn)`` and the mixed natural-neighbour x bubble assembly, which
took about half of the plate's assembly at 88,000 nodes, and leaves no pattern to find:
the condensed block has the stencils' pattern, which the summation keeps with the basis.
Each corrected element matrix is made exactly symmetric, so the summed block is too.

The kernel evaluates the viscous form ``2 eta eps(u) : eps(v)`` itself, on the
stencils' gradients at the quadrature points and the bubble's (the tests compare it with
scikit-fem's assembly of the form); the divergence and the loads of the bubbles stay
scikit-fem assemblies on the bubble basis (three nonzeros per bubble).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..basis.assembly import element_matrices, parallel_kernels, stencil_position
from ..basis.summation import sum_csr
from ..jit import serial_twin

__all__ = ["CondensedViscous", "condensed_viscous"]


@njit(cache=True, inline="always")
def _bubble_blocks(e, ptr, sten, indptr, indices, grads, nq, w, gb, Abb, Abn):
    """A_bb,e (2, 2) and A_bn,e (2, 2 S) of the viscous form on triangle e: the
    bubble's gradient ``gb`` and the stencil functions' gradients at its points,
    weighted by ``w`` = eta dx (2 eta times the 1/2 of each symmetric gradient)."""
    s0 = ptr[e]
    S = ptr[e + 1] - s0
    Abb[:, :] = 0.0
    Abn[:, :] = 0.0
    for q in range(nq):
        wq = w[e, q]
        g0, g1 = gb[0, e, q], gb[1, e, q]
        gg = g0 * g0 + g1 * g1
        Abb[0, 0] += wq * (gg + g0 * g0)
        Abb[1, 1] += wq * (gg + g1 * g1)
        Abb[0, 1] += wq * g0 * g1
        r = e * nq + q
        for kk in range(indptr[r], indptr[r + 1]):
            i = stencil_position(sten, s0, S, indices[kk])
            p0, p1 = wq * grads[0, kk], wq * grads[1, kk]
            dot = p0 * g0 + p1 * g1
            # A_bn[d, 2 i + c] += w (delta_cd grad phi . grad psi + d_d phi d_c psi)
            Abn[0, 2 * i] += dot + p0 * g0
            Abn[0, 2 * i + 1] += p0 * g1
            Abn[1, 2 * i] += p1 * g0
            Abn[1, 2 * i + 1] += dot + p1 * g1
    Abb[1, 0] = Abb[0, 1]


@njit(cache=True, parallel=True)
def _condense(ptr, sten, indptr, indices, grads, nq, w, gb, off, K, off2, AiAbn, Ainv,
              det):
    """Condense the bubbles out of the element matrices ``K`` (2 S x 2 S each, at
    ``K[off[e]:off[e + 1]]``) in place and symmetrise them; writes A_bb,e^-1 A_bn,e
    (2 x 2 S at ``AiAbn[off2[e]:off2[e + 1]]``), A_bb,e^-1 (``Ainv[e]``) and the
    determinant of A_bb,e (``det[e]``; where it is not positive, e is left as is)."""
    ne = ptr.shape[0] - 1
    for e in prange(ne):
        S = ptr[e + 1] - ptr[e]
        n = 2 * S
        Abb = np.empty((2, 2))
        Abn = np.empty((2, n))
        _bubble_blocks(e, ptr, sten, indptr, indices, grads, nq, w, gb, Abb, Abn)
        d = Abb[0, 0] * Abb[1, 1] - Abb[0, 1] * Abb[1, 0]
        det[e] = d
        if not d > 0.0:
            continue
        Ainv[e, 0, 0], Ainv[e, 1, 1] = Abb[1, 1] / d, Abb[0, 0] / d
        Ainv[e, 0, 1] = Ainv[e, 1, 0] = -Abb[0, 1] / d
        o2 = off2[e]
        for c in range(n):
            AiAbn[o2 + c] = Ainv[e, 0, 0] * Abn[0, c] + Ainv[e, 0, 1] * Abn[1, c]
            AiAbn[o2 + n + c] = Ainv[e, 1, 0] * Abn[0, c] + Ainv[e, 1, 1] * Abn[1, c]
        o = off[e]
        for r in range(n):
            for c in range(r, n):
                corr_rc = Abn[0, r] * AiAbn[o2 + c] + Abn[1, r] * AiAbn[o2 + n + c]
                corr_cr = Abn[0, c] * AiAbn[o2 + r] + Abn[1, c] * AiAbn[o2 + n + r]
                v = 0.5 * ((K[o + r * n + c] - corr_rc) + (K[o + c * n + r] - corr_cr))
                K[o + r * n + c] = v
                K[o + c * n + r] = v


_condense_serial = serial_twin(_condense)


class CondensedViscous:
    """The viscous block with the bubbles condensed out, and what the rest of the
    condensation needs: ``A`` (nu, nu) CSR, exactly symmetric; ``Ainv`` (nb, nb) the
    block-diagonal inverse of the bubbles' block; ``AiAbn`` (nb, nu) ``A_bb^-1 A_bn``."""

    def __init__(self, A: sp.csr_matrix, Ainv: sp.csr_matrix, AiAbn: sp.csr_matrix):
        self.A, self.Ainv, self.AiAbn = A, Ainv, AiAbn


def _bubble_gradient(bbasis) -> np.ndarray:
    """(2, ne, nq) gradient of the scalar bubble at the quadrature points."""
    return np.ascontiguousarray(np.asarray(bbasis.basis[0][0].grad)[0])


def _rows_csr(rows: np.ndarray, indptr: np.ndarray, cols: np.ndarray, data: np.ndarray,
              shape: tuple) -> sp.csr_matrix:
    """CSR matrix of the given rows, in the order ``rows`` (a permutation of a subset)."""
    if np.array_equal(rows, np.arange(shape[0])):
        return sp.csr_matrix((data, cols, indptr), shape=shape)
    lens = np.diff(indptr)
    return sp.csr_matrix((data, (np.repeat(rows, lens), cols)), shape=shape)


def condensed_viscous(ubasis, bbasis, eta: np.ndarray, form) -> CondensedViscous:
    """The viscous block of the natural-neighbour velocity ``ubasis`` with the bubbles
    of ``bbasis`` (a vector :class:`ElementTriBubble` basis on the same triangles and
    quadrature) condensed out, for the viscosity ``eta`` (ne, nq) at the quadrature
    points; ``form`` is the viscous bilinear form (``2 eta eps(u) : eps(v)``), whose
    element matrices on ``ubasis`` are corrected. Raises ``ValueError`` naming the first
    triangle whose bubble block is singular."""
    off, K = element_matrices(form, ubasis, eta=eta)
    ptr = ubasis.stencil_ptr
    S = np.diff(ptr)
    ne = S.shape[0]
    off2 = np.zeros(ne + 1, dtype=np.int64)
    np.cumsum(4 * S, out=off2[1:])
    AiAbn, Ainv, det = np.empty(off2[-1]), np.zeros((ne, 2, 2)), np.empty(ne)
    w = np.ascontiguousarray(eta * ubasis.dx)
    Phi, G = ubasis.values_matrix, ubasis.gradient_entries
    parallel = parallel_kernels(ubasis)
    kernel = _condense if parallel else _condense_serial
    kernel(ptr, ubasis.stencil_nodes, Phi.indptr, Phi.indices, G, w.shape[1], w,
           _bubble_gradient(bbasis), off, K, off2, AiAbn, Ainv, det)
    bad = ~(det > 0)
    if bad.any():
        raise ValueError(f"degenerate triangle {int(np.flatnonzero(bad)[0])}: its bubble "
                         f"block is singular ({int(bad.sum())} triangle(s))")
    A = sum_csr(ubasis, 2, off, K, parallel)
    bd = bbasis.element_dofs                       # (2, ne): the bubbles of triangle e
    rows = bd.T.ravel()
    shape = (bbasis.N, ubasis.N)
    nodal = ubasis.dofs.nodal_dofs
    cols = np.empty(off2[-1], dtype=np.int64)
    sten = ubasis.stencil_nodes
    comp = np.stack([nodal[0, sten], nodal[1, sten]], axis=1).ravel()   # (2 S) per e
    starts = np.repeat(2 * ptr[:-1], 4 * S)
    local = np.arange(off2[-1]) - np.repeat(off2[:-1], 4 * S)
    cols[:] = comp[starts + local % np.repeat(2 * S, 4 * S)]
    indptr = np.zeros(2 * ne + 1, dtype=np.int64)
    np.cumsum(np.repeat(2 * S, 2), out=indptr[1:])
    AiAbn_m = _rows_csr(rows, indptr, cols, AiAbn, shape)
    r2 = np.repeat(bd.T, 2, axis=1).ravel()
    c2 = np.tile(bd.T, (1, 2)).ravel()
    Ainv_m = sp.csr_matrix((Ainv.ravel(), (r2, c2)), shape=(bbasis.N, bbasis.N))
    return CondensedViscous(A, Ainv_m, AiAbn_m)
