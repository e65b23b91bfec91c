"""Static condensation of the Stokes bubbles on tetrahedra, inside the assembly.

The 3D natural-neighbour velocity of method ``"nem"`` carries one quartic bubble per
tetrahedron and component (:class:`~skfem_nem.models.bubbles.ElementTetBubble`).
Each bubble lives in one tetrahedron, so eliminating it changes that tetrahedron's element
matrix only:

    A = A_nn - A_bn^T A_bb^-1 A_bn,      B = B_n - B_b A_bb^-1 A_bn,

with ``A_bn`` the coupling of the bubbles to the natural-neighbour functions and ``A_bb``
their 3 x 3 block. With one smoothing cell per tetrahedron the smoothed gradients of the
natural-neighbour functions are constant on it (``gradients_constant_per_element``), so
the viscous form ``2 eta eps(u) : eps(v)`` needs only the tetrahedron's summed weight
``W = sum_q eta_q dx_q`` and gradients ``G`` (S x 3):
``K[(j, cv), (i, cu)] = W (delta_cu,cv G_i . G_j + G_i[cv] G_j[cu])``, and the bubbles only
``g = sum_q eta_q dx_q grad b(x_q)`` and their block:
``A_bn[c, (i, d)] = delta_cd G_i . g + G_i[c] g[d]``. The kernels below compute these per
tetrahedron (:func:`_tet_blocks`) and fill the condensed block row by row over the
stencils' pattern (:func:`_condensed_rows_tet`), as the 2D kernels of
:mod:`skfem_nem.models.condensation` do for triangles; no element matrix is stored, and
the block comes out exactly symmetric (each entry sums the same products in the same
order as its transpose). The 2D kernels stay as they are: ``--dim 2`` is bitwise
unchanged. ``A_bb^-1 A_bn`` is not stored either: it is a formula in ``G``, ``g`` and the
block's inverse (:class:`~skfem_nem.models.coupling_tet.TetCoupling`), where as a sparse
matrix it took 1.5 GB at 100,000 nodes and its making as much again. The divergence
block's natural-neighbour part is coefficient-free and assembled once; its condensation
``B_b (A_bb^-1 A_bn)`` is added row by row (:class:`TetDivergence`: 0.04 s at 9,956 nodes
against 0.34 s as a sparse product and a difference).
"""
from __future__ import annotations


import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..basis.assembly import parallel_kernels
from ..basis.cell_rows import PARALLEL_MIN, count_then_fill
from ..basis.summation import (basis_row_order, blocks, incidence, node_pattern,
                               stencil_gradients)
from ..coordinates.batch import index_dtype
from ..jit import EXACT_FASTMATH, serial_twin
from .block_rows import BlockSymmetricRows
from .condensation import CondensedViscous
from .coupling_tet import TetCoupling, add_weighted_rows

__all__ = ["TetDivergence", "condensed_viscous_tet", "divergence_tet", "loads_tet"]

# pressure rows per task of the condensed divergence kernel (each task keeps marks the
# size of the velocity dofs)
_ROWS = 256


@njit(cache=True, parallel=True)
def _tet_blocks(ptr, nq, w, gb, Wsum, gsum, Ainv, det):
    """Per tetrahedron e: the summed weight ``Wsum[e]``, the bubble's weighted gradient
    ``gsum[e] = sum_q eta_q dx_q grad b(x_q)``, the inverse of the bubbles' 3 x 3 block
    into ``Ainv[e]`` and its determinant into ``det[e]`` (not positive: ``Ainv[e]`` is
    left as it was, zero, and the bubble drops out). The bubbles' coupling ``A_bn`` is
    not made: :class:`~skfem_nem.models.coupling_tet.TetCoupling` computes with it from
    these and the stencil gradients."""
    ne = ptr.shape[0] - 1
    for e in prange(ne):
        W = 0.0
        g = np.zeros(3)
        M = np.zeros((3, 3))
        for q in range(nq):
            wq = w[e, q]
            W += wq
            gg = gb[0, e, q] ** 2 + gb[1, e, q] ** 2 + gb[2, e, q] ** 2
            for a in range(3):
                g[a] += wq * gb[a, e, q]
                M[a, a] += wq * gg
                for b in range(3):
                    M[a, b] += wq * gb[a, e, q] * gb[b, e, q]
        Wsum[e] = W
        gsum[e] = g
        d = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
             - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
             + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
        det[e] = d
        if not d > 0.0:     # a flat tetrahedron (zero weights): its bubble drops out
            continue
        for a in range(3):
            for b in range(3):     # the cofactor inverse of the symmetric block
                a1, a2, b1, b2 = (a + 1) % 3, (a + 2) % 3, (b + 1) % 3, (b + 2) % 3
                Ainv[e, b, a] = (M[a1, b1] * M[a2, b2] - M[a1, b2] * M[a2, b1]) / d
        for a in range(3):
            for b in range(a + 1, 3):
                m = 0.5 * (Ainv[e, a, b] + Ainv[e, b, a])
                Ainv[e, a, b] = Ainv[e, b, a] = m


@njit(cache=True, parallel=True, fastmath=EXACT_FASTMATH)
def _condensed_rows_tet(ptr, sten, G, Wsum, g, Ainv, inc_ptr, inc_e, inc_l, cptr, cols, n3,
                        order, nblocks, klo, ubptr, indices_out, data_out):
    """The condensed viscous block row by row: node v's three rows hold its couplings
    with the nodes ``cols[cptr[v]:cptr[v + 1]]`` (dofs ``3 node + c``, CSR order); each
    tetrahedron around v adds the row of its condensed element matrix that belongs to
    v, computed where it is added (:func:`_add_row_tet`). Rows are taken in ``order``
    (:func:`~skfem_nem.basis.summation.row_order`). With ``klo`` not empty, only the
    couplings with nodes from ``cols[cptr[v] + klo[v]]`` on (those >= v) are made, as
    3 x 3 blocks from ``9 ubptr[v]`` (:func:`_upper_pattern`), and ``indices_out`` is not
    written."""
    n = cptr.shape[0] - 1
    upper = klo.size > 0
    for blk in prange(nblocks):
        pos = np.full(n3, -1, np.int64)
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
            nv = cptr[v + 1] - cptr[v]
            lo = klo[v] if upper else 0
            base = 9 * ubptr[v] if upper else 9 * cptr[v]
            kstride, cvstride = (9, 3) if upper else (3, 3 * nv)
            for k in range(nv):
                pos[cols[cptr[v] + k]] = k - lo if k >= lo else -1
            data_out[base:base + 9 * (nv - lo)] = 0.0
            if not upper:
                for k in range(nv):
                    for cv in range(3):
                        for cu in range(3):
                            indices_out[base + (cv * nv + k) * 3 + cu] = \
                                3 * cols[cptr[v] + k] + cu
            for t in range(inc_ptr[v], inc_ptr[v + 1]):
                _add_row_tet(inc_e[t], inc_l[t], ptr, sten, G, Wsum, g, Ainv, pos, base,
                             kstride, cvstride, data_out)


@njit(cache=True)
def _upper_pattern(cptr, cols):
    """Each node's first coupling with a node >= itself (``klo``), and the 3 x 3 blocks of
    those couplings: node v's from ``ubptr[v]``, their nodes ``bind``."""
    n = cptr.shape[0] - 1
    klo = np.zeros(n, np.int64)
    ubptr = np.zeros(n + 1, np.int64)
    for v in range(n):
        k = 0
        while k < cptr[v + 1] - cptr[v] and cols[cptr[v] + k] < v:
            k += 1
        klo[v] = k
        ubptr[v + 1] = ubptr[v] + cptr[v + 1] - cptr[v] - k
    bind = np.empty(ubptr[n], np.uint32)
    for v in range(n):
        for k in range(ubptr[v + 1] - ubptr[v]):
            bind[ubptr[v] + k] = cols[cptr[v] + klo[v] + k]
    return klo, ubptr, bind


@njit(cache=True, inline="always", fastmath=EXACT_FASTMATH)
def _add_row_tet(e, j, ptr, sten, G, Wsum, g, Ainv, pos, base, kstride, cvstride,
                 data_out):
    """Add row j (three components) of tetrahedron e's condensed element matrix:
    ``W (delta G_i . G_j + G_i[cv] G_j[cu]) - (A_bn^T A_bb^-1 A_bn)[(j, cv), (i, cu)]``.

    With ``A_bn``'s block of function i ``X_i = p_i I + G_i g^T`` (``p_i = G_i . g``)
    and ``Q = A_bb^-1`` the correction is ``X_j^T Q X_i = p_i p_j Q + p_j q_i g^T +
    p_i g q_j^T + (G_j^T Q G_i) g g^T`` with ``q_i = Q G_i``: four terms of one pair
    instead of a sum over the 3 x 3 bubble block per entry (2.4 times fewer operations).
    Each term is written so that the transposed entry multiplies the same numbers in
    the same order, and the block stays exactly symmetric."""
    s0 = ptr[e]
    S = ptr[e + 1] - s0
    W = Wsum[e]
    Q = Ainv[e]
    gb = g[e]
    gj = G[3 * (s0 + j):3 * (s0 + j) + 3]
    pj = gj[0] * gb[0] + gj[1] * gb[1] + gj[2] * gb[2]
    qj = (Q[0, 0] * gj[0] + Q[0, 1] * gj[1] + Q[0, 2] * gj[2],
          Q[1, 0] * gj[0] + Q[1, 1] * gj[1] + Q[1, 2] * gj[2],
          Q[2, 0] * gj[0] + Q[2, 1] * gj[1] + Q[2, 2] * gj[2])
    for i in range(S):
        if pos[sten[s0 + i]] < 0:
            continue        # (a block below the diagonal, not made)
        gi = G[3 * (s0 + i):3 * (s0 + i) + 3]
        pi = gi[0] * gb[0] + gi[1] * gb[1] + gi[2] * gb[2]
        qi = (Q[0, 0] * gi[0] + Q[0, 1] * gi[1] + Q[0, 2] * gi[2],
              Q[1, 0] * gi[0] + Q[1, 1] * gi[1] + Q[1, 2] * gi[2],
              Q[2, 0] * gi[0] + Q[2, 1] * gi[1] + Q[2, 2] * gi[2])
        dot = gi[0] * gj[0] + gi[1] * gj[1] + gi[2] * gj[2]
        sq = (Q[0, 0] * (gi[0] * gj[0]) + Q[1, 1] * (gi[1] * gj[1]) + Q[2, 2] * (gi[2] * gj[2])
              + Q[0, 1] * ((gi[0] * gj[1]) + (gi[1] * gj[0]))
              + Q[0, 2] * ((gi[0] * gj[2]) + (gi[2] * gj[0]))
              + Q[1, 2] * ((gi[1] * gj[2]) + (gi[2] * gj[1])))
        pp = pi * pj
        d = base + pos[sten[s0 + i]] * kstride
        for cv in range(3):
            for cu in range(3):
                k = W * ((dot if cu == cv else 0.0) + gi[cv] * gj[cu])
                corr = (pp * Q[cv, cu] + (((pj * qi[cv]) * gb[cu]) + ((pi * qj[cu]) * gb[cv]))
                        + sq * (gb[cv] * gb[cu]))
                data_out[d + cv * cvstride + cu] += k - corr


_tet_blocks_serial = serial_twin(_tet_blocks)
_condensed_rows_tet_serial = serial_twin(_condensed_rows_tet)


def _nodal(ubasis) -> None:
    """``ValueError`` unless the velocity dofs are ``3 node + c`` with constant
    gradients per tetrahedron (the smoothed vector natural-neighbour basis)."""
    nodal = np.asarray(ubasis.dofs.nodal_dofs[:3])
    n = nodal.shape[1]
    if (ubasis.N != 3 * n or not np.array_equal(nodal, 3 * np.arange(n) + np.c_[0:3])
            or not getattr(ubasis, "gradients_constant_per_element", False)):
        raise ValueError("the velocity basis must be the smoothed vector natural-neighbour "
                         "basis on tetrahedra (dofs 3 node + c, one smoothing cell each)")


def condensed_viscous_tet(ubasis, bubbles, eta: np.ndarray,
                          blocks: bool = False) -> CondensedViscous:
    """The viscous block ``2 eta eps(u) : eps(v)`` of the smoothed natural-neighbour
    velocity ``ubasis`` on tetrahedra with the ``bubbles``
    (:class:`~skfem_nem.models.bubbles.Bubbles` on the same quadrature)
    condensed out, for the viscosity ``eta`` (ne, nq) at the quadrature points; exactly
    symmetric. ``blocks``: the block as its nodes' upper 3 x 3 blocks
    (:class:`~skfem_nem.models.block_rows.BlockSymmetricRows`; half the entries made, the
    same values bit for bit), else CSR. Raises ``ValueError`` naming the first tetrahedron
    whose bubble block is singular."""
    _nodal(ubasis)
    ptr = ubasis.stencil_ptr
    ne, nq = ubasis.dx.shape
    Wsum, gsum, det = np.empty(ne), np.empty((ne, 3)), np.empty(ne)
    Ainv = np.zeros((ne, 3, 3))
    w = np.ascontiguousarray(eta * ubasis.dx)
    parallel = parallel_kernels(ubasis)
    # the stencil functions' gradients, 3 a function (cached with the basis: the Picard
    # iterations of a step share them)
    G = np.ascontiguousarray(stencil_gradients(ubasis, parallel)).reshape(-1)
    (_tet_blocks if parallel else _tet_blocks_serial)(
        ptr, nq, w, bubbles.gradient(), Wsum, gsum, Ainv, det)
    # flat tetrahedra (Qhull's, of co-spherical or co-planar nodes) carry no weight and
    # no bubble; any other singular block is an error
    bad = ~(det > 0) & (Wsum > 0)
    if bad.any():
        raise ValueError(f"degenerate tetrahedron {int(np.flatnonzero(bad)[0])}: its bubble "
                         f"block is singular ({int(bad.sum())} tetrahedra)")
    A = _summed_tet(ubasis, G, Wsum, gsum, Ainv, parallel, blocks)
    coupling = TetCoupling(ptr, ubasis.stencil_nodes, G, gsum, Ainv, ubasis.N, parallel,
                           _part_dofs(bubbles), bubbles.N)
    return CondensedViscous(A, bubbles.block_diagonal(Ainv), coupling, None)


def _part_dofs(bubbles):
    """(ne, 3) the bubble dofs of the tetrahedra integrated over where they are some of
    the mesh's (an MPI rank's part), else None."""
    return None if bubbles.elements is None else np.ascontiguousarray(bubbles.element_dofs.T)


def _summed_tet(ubasis, G, Wsum, gsum, Ainv, parallel, upper=False):
    """The condensed block from :func:`_condensed_rows_tet`, CSR over the stencils' pattern,
    or (``upper``) as its nodes' upper blocks."""
    inc_ptr, inc_e, inc_l, cptr, cols = node_pattern(ubasis, parallel)
    n = cptr.shape[0] - 1
    rows = (ubasis.stencil_ptr, ubasis.stencil_nodes, G, Wsum, gsum, Ainv, inc_ptr, inc_e,
            inc_l, cptr, cols, n, basis_row_order(ubasis), blocks(n))
    kernel = _condensed_rows_tet if parallel else _condensed_rows_tet_serial
    nnz = 9 * int(cptr[-1])
    idt = index_dtype(ubasis.N, nnz)
    if upper:
        klo, ubptr, bind = _upper_pattern(cptr, cols)
        data = np.empty(9 * int(ubptr[-1]))
        kernel(*rows, klo, ubptr, np.empty(0, dtype=idt), data)
        return BlockSymmetricRows.from_blocks(ubptr, bind, data, np.arange(3 * n))
    indices, data = np.empty(nnz, dtype=idt), np.empty(nnz)
    kernel(*rows, np.empty(0, dtype=np.int64), cptr, indices, data)
    nv = np.diff(cptr)
    indptr = np.empty(3 * n + 1, dtype=idt)
    indptr[:-1] = (9 * cptr[:-1, None] + 3 * nv[:, None] * np.arange(3)[None]).ravel()
    indptr[-1] = nnz
    return sp.csr_matrix((data, indices, indptr), shape=(ubasis.N, ubasis.N))


def divergence_tet(ubasis, pbasis) -> sp.csr_matrix:
    """The divergence block ``(u, grad q)`` (np, nu) of the natural-neighbour velocity
    ``ubasis`` and the P1 pressure ``pbasis`` on tetrahedra, by two sparse products: the
    P1 gradients are constant on a tetrahedron, so ``B[r, 3 j + d] = sum_e d_d lambda_r(e)
    int_e phi_j``, and ``int_e phi_j`` is the sum of the weighted values at e's points."""
    Phi = _point_values(ubasis)                         # (ne nq, n) values at the points
    ne, nq = ubasis.dx.shape
    sums = sp.csr_matrix((ubasis.dx.ravel(), np.arange(ne * nq),
                          np.arange(0, ne * nq + 1, nq)), shape=(ne, ne * nq))
    integrals = (sums @ Phi).tocsr()                    # (ne, n): int_e phi_j
    tets = np.asarray(pbasis.element_dofs)              # (4, ne) pressure dofs
    out = sp.csr_matrix((pbasis.N, ubasis.N))
    nodal = np.asarray(ubasis.dofs.nodal_dofs)
    for d in range(3):
        grad_d = np.stack([np.asarray(pbasis.basis[k][0].grad)[d, :, 0] for k in range(4)])
        Gd = sp.csr_matrix((grad_d.ravel(), (tets.ravel(), np.tile(np.arange(ne), 4))),
                           shape=(pbasis.N, ne))
        Bd = (Gd @ integrals).tocoo()
        out = out + sp.csr_matrix((Bd.data, (Bd.row, nodal[d, Bd.col])),
                                  shape=(pbasis.N, ubasis.N))
    return out.tocsr()


class TetDivergence:
    """The parts of the condensed divergence block ``B_n - B_b A_bb^-1 A_bn`` that do not
    change with the viscosity, prepared once per spaces: the natural-neighbour functions'
    block ``Bn`` (np, nu), tetrahedron e's 4 x 3 block of the bubbles' ``Bb`` (np, nb; e's
    bubble dofs ``bubbles[e]``, the mesh's ``3 cell + c``) and the tetrahedra around each
    pressure dof. :meth:`condensed` adds the bubbles' part row by row."""

    def __init__(self, Bn: sp.csr_matrix, Bb: sp.csr_matrix, pbasis, bubbles: np.ndarray):
        Bn = sp.csr_matrix(Bn)
        Bn.sum_duplicates()
        # columns in 32 bits where the velocity dofs allow (at 100,000 nodes this block and
        # the condensed one's kept pattern hold some 5e7 entries each: 0.4 GB less)
        self.col_dtype = index_dtype(Bn.shape[1], 0)
        self.Bn = (np.asarray(Bn.indptr, dtype=np.int64),
                   np.asarray(Bn.indices, dtype=self.col_dtype), np.asarray(Bn.data, dtype=float))
        self.shape = Bn.shape
        pd = np.asarray(pbasis.element_dofs)                   # (4, ne) pressure dofs
        ne = pd.shape[1]
        rows = np.repeat(pd.T, 3, axis=1).ravel()              # (e, k, c) order
        cols = np.tile(bubbles, (1, 4)).ravel()
        self.local = np.asarray(sp.csr_matrix(Bb)[rows, cols]).reshape(ne, 4, 3)
        self.incidence = incidence(np.arange(0, 4 * ne + 1, 4), pd.T.ravel(), Bn.shape[0])
        self.pattern = None     # the condensed block's rows and the coupling's, once found

    def condensed(self, cv: CondensedViscous) -> sp.csr_matrix:
        """The block with the bubbles of ``cv`` (its ``A_bb^-1 A_bn``, three rows of the
        same columns per tetrahedron) condensed out, CSR with sorted rows; each row sums
        its ``Bn`` entries and its tetrahedra's terms (:func:`_divergence_rows`). The
        pattern is found on the first call and kept: it depends on the stencils alone."""
        weights = cv.AiAbn.row_weights()
        ptr_s, sten = weights[:2]
        args = (*self.Bn, *self.incidence, self.local, *weights, self.shape[1])
        kernel = (_divergence_rows if self.shape[0] >= PARALLEL_MIN
                  else _divergence_rows_serial)
        if self.pattern is None:
            ptr, (idx, val) = count_then_fill(
                _divergence_rows, _divergence_rows_serial, self.shape[0], args,
                lambda nnz: (np.empty(nnz, self.col_dtype), np.empty(nnz)))
            self.pattern = (ptr, idx, ptr_s, sten)      # (the basis' stencils: not copied)
        else:
            ptr, idx, ptr0, sten0 = self.pattern
            if not (np.array_equal(ptr0, ptr_s) and np.array_equal(sten0, sten)):
                raise ValueError("TetDivergence.condensed: the bubbles' coupling has another "
                                 "pattern than the stencils it was first given")
            val = np.empty(idx.size)
            kernel(*args, np.empty(self.shape[0], np.int64), ptr, idx, val, 2)
        idt = index_dtype(self.shape[1], int(ptr[-1]))
        return sp.csr_matrix((val, idx.astype(idt, copy=False), ptr.astype(idt)),
                             shape=self.shape)


@njit(cache=True, parallel=True)
def _divergence_rows(bn_ptr, bn_idx, bn_val, inc_ptr, inc_e, inc_k, local, s_ptr, sten, G,
                     g, Q, nu, count, ptr, out_idx, out_val, fill):
    """Row r of ``B_n - B_b A_bb^-1 A_bn``: r's ``Bn`` entries, less ``sum_c
    Bb[r, 3 e + c] (A_bb^-1 A_bn)[3 e + c, :]`` for each tetrahedron e around r (r its
    vertex k; :func:`~skfem_nem.models.coupling_tet.add_weighted_rows` from the stencils
    ``s_ptr``, ``sten``, their gradients ``G``, the bubbles' ``g`` and ``Q``), summed in
    a dense row and cleared for the next. ``fill``: 0 counts the
    row's columns into ``count[r]`` (listed when first met), 1 writes them sorted with
    their values at ``ptr[r]``, 2 writes the values of the columns already there."""
    npr = count.shape[0]
    nb = (npr + _ROWS - 1) // _ROWS
    for blk in prange(nb):
        met = np.zeros(nu if fill < 2 else 0, np.bool_)
        dense = np.zeros(nu)
        cols = np.empty(nu if fill < 2 else 0, np.int64)
        for r in range(blk * _ROWS, min(npr, blk * _ROWS + _ROWS)):
            m = 0
            for t in range(bn_ptr[r], bn_ptr[r + 1]):
                j = bn_idx[t]
                if fill < 2 and not met[j]:
                    met[j], cols[m] = True, j
                    m += 1
                dense[j] += bn_val[t]
            for t in range(inc_ptr[r], inc_ptr[r + 1]):
                e, k = inc_e[t], inc_k[t]
                for s in range(s_ptr[e], s_ptr[e + 1] if fill < 2 else s_ptr[e]):
                    for d in range(3):
                        j = 3 * sten[s] + d
                        if not met[j]:
                            met[j], cols[m] = True, j
                            m += 1
                add_weighted_rows(e, local[e, k, 0], local[e, k, 1], local[e, k, 2], s_ptr,
                                  sten, G, g, Q, dense, -1.0)
            if fill == 0:
                count[r] = m
            elif fill == 1:
                out_idx[ptr[r]:ptr[r] + m] = np.sort(cols[:m])
            for a in range(ptr[r], ptr[r + 1] if fill > 0 else ptr[r]):
                out_val[a] = dense[out_idx[a]]
                dense[out_idx[a]] = 0.0
            for a in range(m if fill == 0 else 0):
                met[cols[a]], dense[cols[a]] = False, 0.0
            for a in range(m if fill == 1 else 0):
                met[cols[a]] = False


_divergence_rows_serial = serial_twin(_divergence_rows)


def loads_tet(ubasis, f: np.ndarray, tau=None) -> np.ndarray:
    """The load ``(f, v) - (tau, eps(v))`` on the natural-neighbour velocity ``ubasis``
    (dofs ``3 node + c``) from the body force ``f`` (3, ne, nq) and the optional stress
    ``tau`` (3, 3, ne, nq; its symmetric part acts) at its quadrature points, by sparse
    products with the basis's values and gradients at the points: 0.09 s at 10,000 nodes
    against 0.7 s through the form assembly, which probes the form point by point."""
    _nodal(ubasis)
    Phi = _point_values(ubasis)                              # (ne nq, n)
    dx = ubasis.dx.ravel()
    f = np.broadcast_to(f, (3,) + ubasis.dx.shape)
    b = np.empty((Phi.shape[1], 3))
    for c in range(3):
        b[:, c] = Phi.T @ (f[c].ravel() * dx)
    if tau is None:
        return b.ravel()
    rows = ubasis.cell_rows
    if rows is not None:  # the gradients are their cells': the stress summed over each cell
        Y = np.empty((3, 3, rows.c_ptr.shape[0] - 1))
        for c in range(3):
            for d in range(c, 3):
                Y[c, d] = Y[d, c] = rows.cell_sums(0.5 * (tau[c, d] + tau[d, c]).ravel() * dx)
        b -= rows.transposed_gradients(Y).T
        return b.ravel()
    for c in range(3):
        y = np.stack([0.5 * (tau[c, d] + tau[d, c]).ravel() * dx for d in range(3)])
        grads = ubasis.gradient_entries                      # (3, nnz of Phi)
        for d in range(3):
            Gd = sp.csr_matrix((grads[d], Phi.indices, Phi.indptr), shape=Phi.shape)
            b[:, c] -= Gd.T @ y[d]
    return b.ravel()


def _point_values(ubasis):
    """The basis' values at its points, CSR, without joining a basis' cell rows."""
    rows = getattr(ubasis, "cell_rows", None)
    return ubasis.values_matrix if rows is None else rows.values()
