"""The bubbles' coupling ``A_bb^-1 A_bn`` on tetrahedra, as an operator that is never stored.

The static condensation of the tetrahedra's bubbles (:mod:`skfem_nem.models.condensation_tet`)
needs ``M = A_bb^-1 A_bn`` three times a solve: the condensed divergence, the condensed load
``-M^T f_b`` and the bubbles' values after the solve ``A_bb^-1 f_b - M u``. As a sparse matrix
``M`` has nine entries per stencil function of each tetrahedron, 1.5 GB at 100,000 nodes, and
building it took a second array of that size. But each of its blocks is a formula in numbers
the condensation already holds: with tetrahedron e's stencil gradients ``G_s`` (constant on it),
its bubbles' weighted gradient ``g`` and the inverse ``Q`` of their 3 x 3 block,
``A_bn``'s block of function s is ``X_s = (G_s . g) I + G_s g^T``, so

    (M u)_e = Q (L + L^T) g,        L = sum_s u_s G_s^T  (the velocity gradient),
    (M^T y)_s = sum_e (G_s . g) Q y_e + g (G_s . Q y_e),

some 20 multiply-adds per stencil function, read from the gradients the basis keeps.
:class:`TetCoupling` is ``M`` as such an operator (``@``, ``.T @``, :meth:`~TetCoupling.tocsr`
for a check), and :meth:`~TetCoupling.row_weights` gives the divergence kernel what it needs
to add ``w^T M_e`` for a weight vector ``w`` row by row.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..jit import serial_twin

__all__ = ["TetCoupling"]


class TetCoupling:
    """``A_bb^-1 A_bn`` (3 ne, nu) of the tetrahedra's bubbles (dofs ``3 e + c``) and the
    natural-neighbour velocity (dofs ``3 node + d``): tetrahedron e's stencil
    ``sten[ptr[e]:ptr[e + 1]]`` with gradients ``G`` (3 a stencil function, flat), its
    bubbles' weighted gradient ``g[e]`` and the inverse ``Q[e]`` of their block (exactly
    symmetric; zero for a flat tetrahedron, which has no bubble). ``bubbles``: the
    (ne, 3) bubble dofs of these tetrahedra where they are some of a mesh's (an MPI rank's
    part), and ``n_bubbles`` all of them; then the rows are those dofs (``3 cell + c``).
    None: the tetrahedra are all the mesh's, in order."""

    def __init__(self, ptr, sten, G, g, Q, n_velocity: int, parallel: bool = True,
                 bubbles: Optional[np.ndarray] = None, n_bubbles: Optional[int] = None):
        self.ptr, self.sten, self.G, self.g, self.Q = ptr, sten, G, g, Q
        ne = ptr.shape[0] - 1
        if bubbles is not None and bubbles.shape != (ne, 3):
            raise ValueError(f"TetCoupling: bubbles must have shape ({ne}, 3), got "
                             f"{bubbles.shape}")
        self.rows = None if bubbles is None else np.ascontiguousarray(bubbles).ravel()
        self.shape = (3 * ne if bubbles is None else int(n_bubbles), int(n_velocity))
        self.dtype = np.dtype(np.float64)
        self.parallel = parallel

    def __matmul__(self, u: np.ndarray) -> np.ndarray:
        u = np.ascontiguousarray(u, dtype=np.float64)
        if u.shape != (self.shape[1],):
            raise ValueError(f"TetCoupling @ u needs u of shape ({self.shape[1]},), got "
                             f"{u.shape}")
        out = np.empty(self.rows.size if self.rows is not None else self.shape[0])
        (_apply if self.parallel else _apply_serial)(self.ptr, self.sten, self.G, self.g,
                                                     self.Q, u, out)
        if self.rows is None:
            return out
        whole = np.zeros(self.shape[0])      # (the other tetrahedra's bubbles: not here)
        whole[self.rows] = out
        return whole

    @property
    def T(self) -> "_Transposed":
        """The transpose, for ``M.T @ y``."""
        return _Transposed(self)

    def tocsr(self) -> sp.csr_matrix:
        """The operator as a CSR matrix (three rows of 3 S entries per tetrahedron):
        for checks and small problems, it is what this class is not to store."""
        ne, nst = self.ptr.shape[0] - 1, int(self.ptr[-1])
        indices, data = np.empty(9 * nst, np.int64), np.empty(9 * nst)
        _entries(self.ptr, self.sten, self.G, self.g, self.Q, indices, data)
        indptr = np.zeros(3 * ne + 1, np.int64)
        indptr[1:] = np.cumsum(np.repeat(3 * np.diff(self.ptr), 3))
        local = sp.csr_matrix((data, indices, indptr), shape=(3 * ne, self.shape[1]))
        if self.rows is None:
            return local
        return sp.csr_matrix((np.ones(3 * ne), (self.rows, np.arange(3 * ne))),
                             shape=(self.shape[0], 3 * ne)) @ local

    def row_weights(self) -> tuple:
        """``(ptr, sten, G, g, Q)``: what a kernel needs to add ``w^T M_e`` (the row
        ``sum_c w_c M[3 e + c, :]``): ``v = Q w``, then ``(G_s . g) v_d + (v . G_s) g_d``
        at column ``3 sten_s + d`` (:func:`add_weighted_rows`)."""
        return self.ptr, self.sten, self.G, self.g, self.Q


class _Transposed:
    """``M.T`` of a :class:`TetCoupling` ``M``, for products."""

    def __init__(self, M: TetCoupling):
        self.M = M
        self.shape = M.shape[::-1]

    def __matmul__(self, y: np.ndarray) -> np.ndarray:
        M = self.M
        y = np.ascontiguousarray(y, dtype=np.float64)
        if y.shape != (M.shape[0],):
            raise ValueError(f"TetCoupling.T @ y needs y of shape ({M.shape[0]},), got "
                             f"{y.shape}")
        out = np.zeros(M.shape[1])
        _apply_transposed(M.ptr, M.sten, M.G, M.g, M.Q, y if M.rows is None else y[M.rows],
                          out)
        return out


@njit(cache=True, parallel=True)
def _apply(ptr, sten, G, g, Q, u, out):
    """``out[3 e:3 e + 3] = Q_e (L + L^T) g_e`` with ``L = sum_s u_s G_s^T`` over the
    stencil of tetrahedron e."""
    for e in prange(ptr.shape[0] - 1):
        L = np.zeros((3, 3))
        for s in range(ptr[e], ptr[e + 1]):
            v = 3 * sten[s]
            for a in range(3):
                for b in range(3):
                    L[a, b] += u[v + a] * G[3 * s + b]
        h = np.zeros(3)
        for a in range(3):
            for b in range(3):
                h[a] += (L[a, b] + L[b, a]) * g[e, b]
        for c in range(3):
            out[3 * e + c] = Q[e, c, 0] * h[0] + Q[e, c, 1] * h[1] + Q[e, c, 2] * h[2]


@njit(cache=True)
def _apply_transposed(ptr, sten, G, g, Q, y, out):
    """``out += M^T y``: per tetrahedron ``z = Q_e y_e``, then ``(G_s . g) z + g (G_s . z)``
    added to stencil node s's three dofs (one thread: the nodes are shared; once a
    Picard iteration, 1.4e7 stencil functions in some 50 ms)."""
    for e in range(ptr.shape[0] - 1):
        z = np.zeros(3)
        for c in range(3):
            z[c] = Q[e, c, 0] * y[3 * e] + Q[e, c, 1] * y[3 * e + 1] + Q[e, c, 2] * y[3 * e + 2]
        for s in range(ptr[e], ptr[e + 1]):
            gs = G[3 * s:3 * s + 3]
            p = gs[0] * g[e, 0] + gs[1] * g[e, 1] + gs[2] * g[e, 2]
            gz = gs[0] * z[0] + gs[1] * z[1] + gs[2] * z[2]
            v = 3 * sten[s]
            for d in range(3):
                out[v + d] += p * z[d] + gz * g[e, d]


@njit(cache=True, parallel=True)
def _entries(ptr, sten, G, g, Q, indices, data):
    """Rows (e, c) of ``M`` in CSR order: tetrahedron e's three rows of 3 S entries,
    ``M[3 e + c, 3 sten_s + d] = Q[c, d] (G_s . g) + (Q G_s)[c] g[d]``."""
    for e in prange(ptr.shape[0] - 1):
        s0 = ptr[e]
        S3 = 3 * (ptr[e + 1] - s0)
        o = 9 * s0
        for i in range(ptr[e + 1] - s0):
            gs = G[3 * (s0 + i):3 * (s0 + i) + 3]
            p = gs[0] * g[e, 0] + gs[1] * g[e, 1] + gs[2] * g[e, 2]
            for c in range(3):
                qg = Q[e, c, 0] * gs[0] + Q[e, c, 1] * gs[1] + Q[e, c, 2] * gs[2]
                for d in range(3):
                    k = o + c * S3 + 3 * i + d
                    indices[k] = 3 * sten[s0 + i] + d
                    data[k] = Q[e, c, d] * p + qg * g[e, d]


@njit(cache=True, inline="always")
def add_weighted_rows(e, w0, w1, w2, ptr, sten, G, g, Q, dense, scale):
    """``dense += scale * sum_c w_c M[3 e + c, :]`` for tetrahedron e (the divergence
    kernel's condensation term): ``v = Q w``, then ``(G_s . g) v_d + (v . G_s) g_d`` at
    column ``3 sten_s + d``."""
    v0 = Q[e, 0, 0] * w0 + Q[e, 0, 1] * w1 + Q[e, 0, 2] * w2
    v1 = Q[e, 1, 0] * w0 + Q[e, 1, 1] * w1 + Q[e, 1, 2] * w2
    v2 = Q[e, 2, 0] * w0 + Q[e, 2, 1] * w1 + Q[e, 2, 2] * w2
    for s in range(ptr[e], ptr[e + 1]):
        gs0, gs1, gs2 = G[3 * s], G[3 * s + 1], G[3 * s + 2]
        p = gs0 * g[e, 0] + gs1 * g[e, 1] + gs2 * g[e, 2]
        vg = v0 * gs0 + v1 * gs1 + v2 * gs2
        j = 3 * sten[s]
        dense[j] += scale * (p * v0 + vg * g[e, 0])
        dense[j + 1] += scale * (p * v1 + vg * g[e, 1])
        dense[j + 2] += scale * (p * v2 + vg * g[e, 2])


_apply_serial = serial_twin(_apply)
