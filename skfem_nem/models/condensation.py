"""Static condensation of the Stokes bubbles, triangle by triangle, inside the assembly.

The natural-neighbour velocity of method ``"nem"`` carries one cubic bubble per triangle
and component (:class:`~skfem_nem.models.bubbles.ElementTriBubble`). A bubble lives
in one triangle, so eliminating it changes only that triangle's element matrix: the
viscous block of triangle e becomes ``A_e - A_bn,e^T A_bb,e^-1 A_bn,e``, where ``A_bn,e``
(2 x 2 S_e) couples its two bubbles to its S_e stencil functions and ``A_bb,e`` is their
2 x 2 block. Done here, inside the assembly, it replaces the global sparse products
``A - A_bn^T (A_bb^-1 A_bn)``, the mixed natural-neighbour x bubble assembly and the
symmetrisation ``(A + A^T) / 2``, which together took about half of the plate's
assembly at 88,000 nodes, and leaves no pattern to find: the condensed block has the
stencils' pattern (:func:`skfem_nem.basis.summation.node_pattern`).

Two kernels: :func:`_bubbles` computes, per triangle, the stencil gradients at its points
and the bubble blocks; :func:`_condensed_rows` fills the block row by row, each triangle
adding the row of its condensed element matrix that belongs to the row's node, computed
where it is added. No element matrix is stored (they would take 1 GB at 88,000 nodes),
and the block comes out exactly symmetric. The kernels evaluate the viscous form
``2 eta eps(u) : eps(v)`` themselves (the tests compare them with scikit-fem's assembly of
the form). The divergence block ``(u, grad q)`` is filled the same way, row by row over
the pressure nodes, with its correction ``- B_b A_bb^-1 A_bn`` (:func:`_divergence_rows`;
through scikit-fem's per-group road the mixed natural-neighbour x P1 assembly took 0.8 s
at 88,000 nodes). The bubbles' own divergence and loads stay scikit-fem assemblies on the
bubble basis (three nonzeros per bubble).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..basis.assembly import parallel_kernels, stencil_position
from ..basis.summation import basis_row_order, blocks, incidence, node_pattern, stencil_union
from ..coordinates.batch import index_dtype
from ..jit import serial_twin

__all__ = ["CondensedViscous", "condensed_viscous", "condensed_divergence"]


@njit(cache=True, inline="always")
def _gather_gradients(e, ptr, sten, indptr, indices, grads, nq, out, o):
    """Gradients of triangle e's stencil functions at its points into
    ``out[o:o + 2 nq S]``, as (nq, 2, S), zero where a function vanishes."""
    s0 = ptr[e]
    S = ptr[e + 1] - s0
    for t in range(2 * nq * S):
        out[o + t] = 0.0
    for q in range(nq):
        r = e * nq + q
        for kk in range(indptr[r], indptr[r + 1]):
            i = stencil_position(sten, s0, S, indices[kk])
            out[o + (2 * q) * S + i] = grads[0, kk]
            out[o + (2 * q + 1) * S + i] = grads[1, kk]


@njit(cache=True, parallel=True)
def _bubbles(ptr, sten, indptr, indices, grads, nq, w, gb, nodal, offg, Gl, off2, X, AiAbn,
             cols, Ainv, det):
    """Per triangle e: its stencil gradients (``Gl[offg[e]:]``, see
    :func:`_gather_gradients`), A_bn,e (2 x 2 S at ``X[off2[e]:off2[e + 1]]``) and
    A_bb,e^-1 A_bn,e (``AiAbn``, with the velocity dofs of its columns in ``cols``),
    A_bb,e^-1 (``Ainv[e]``) and the determinant of A_bb,e (``det[e]``, not positive:
    the rest of e is left unset). The viscous form on the bubble ``psi`` (gradient
    ``gb``) and the stencil functions, ``w`` = eta dx (2 eta times the 1/2 of each
    symmetric gradient): A_bn[d, 2 i + c] = sum_q w (delta_cd grad phi_i . grad psi
    + d_d phi_i d_c psi), A_bb[d, c] = sum_q w (delta_cd |grad psi|^2 + d_d psi d_c psi)."""
    ne = ptr.shape[0] - 1
    for e in prange(ne):
        s0 = ptr[e]
        S = ptr[e + 1] - s0
        n, o, og = 2 * S, off2[e], offg[e]
        _gather_gradients(e, ptr, sten, indptr, indices, grads, nq, Gl, og)
        b00 = b01 = b11 = 0.0
        for c in range(2 * n):
            X[o + c] = 0.0
        for q in range(nq):
            wq, g0, g1 = w[e, q], gb[0, e, q], gb[1, e, q]
            gg = g0 * g0 + g1 * g1
            b00 += wq * (gg + g0 * g0)
            b11 += wq * (gg + g1 * g1)
            b01 += wq * (g0 * g1)
            for i in range(S):
                p0 = wq * Gl[og + (2 * q) * S + i]
                p1 = wq * Gl[og + (2 * q + 1) * S + i]
                dot = p0 * g0 + p1 * g1
                X[o + 2 * i] += dot + p0 * g0
                X[o + 2 * i + 1] += p0 * g1
                X[o + n + 2 * i] += p1 * g0
                X[o + n + 2 * i + 1] += dot + p1 * g1
        d = b00 * b11 - b01 * b01
        det[e] = d
        if not d > 0.0:
            continue
        a00, a11, a01 = b11 / d, b00 / d, -b01 / d
        Ainv[e, 0, 0], Ainv[e, 1, 1], Ainv[e, 0, 1], Ainv[e, 1, 0] = a00, a11, a01, a01
        for c in range(n):
            AiAbn[o + c] = a00 * X[o + c] + a01 * X[o + n + c]
            AiAbn[o + n + c] = a01 * X[o + c] + a11 * X[o + n + c]
            cols[o + c] = cols[o + n + c] = nodal[c % 2, sten[s0 + c // 2]]


@njit(cache=True, parallel=True)
def _condensed_rows(ptr, sten, nq, w, offg, Gl, off2, X, Ainv, inc_ptr, inc_e, inc_l, cptr,
                    cols, nodal, order, nblocks, indices_out, data_out):
    """The condensed viscous block, row by row (node v's rows hold its couplings with
    the nodes ``cols[cptr[v]:cptr[v + 1]]``, CSR order for dofs ``2 node + c``): each
    triangle around v adds the row of its element matrix that belongs to v,
    ``sum_q w (delta_cu,cv grad phi_i . grad phi_j + d_cv phi_i d_cu phi_j)`` minus
    the bubbles' ``A_bn^T A_bb^-1 A_bn``, computed where it is added (no element
    matrix is stored). Both terms are written so that swapping (j, cv) and (i, cu)
    multiplies the same numbers, and the triangles add in ascending order in every
    row: the block comes out exactly symmetric. Rows are taken in ``order``
    (:func:`~skfem_nem.basis.summation.row_order`)."""
    n = cptr.shape[0] - 1
    for blk in prange(nblocks):
        pos = np.full(n, -1, np.int64)
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
            nv = cptr[v + 1] - cptr[v]
            base = 4 * cptr[v]
            for k in range(nv):
                pos[cols[cptr[v] + k]] = k
                for cv in range(2):
                    for cu in range(2):
                        o = base + (cv * nv + k) * 2 + cu
                        indices_out[o] = nodal[cu, cols[cptr[v] + k]]
                        data_out[o] = 0.0
            for t in range(inc_ptr[v], inc_ptr[v + 1]):
                _add_row(inc_e[t], inc_l[t], ptr, sten, nq, w, offg, Gl, off2, X, Ainv,
                         pos, base, nv, data_out)


@njit(cache=True, inline="always")
def _add_row(e, j, ptr, sten, nq, w, offg, Gl, off2, X, Ainv, pos, base, nv, data_out):
    """Add row j (both components) of triangle e's condensed element matrix."""
    s0 = ptr[e]
    S = ptr[e + 1] - s0
    n, o, og = 2 * S, off2[e], offg[e]
    a00, a11, a01 = Ainv[e, 0, 0], Ainv[e, 1, 1], Ainv[e, 0, 1]
    x0J0, x1J0, x0J1, x1J1 = X[o + 2 * j], X[o + n + 2 * j], X[o + 2 * j + 1], X[o + n + 2 * j + 1]
    for i in range(S):
        k00 = k01 = k10 = k11 = 0.0      # k_cv,cu: test component cv, trial cu
        for q in range(nq):
            gi0, gi1 = Gl[og + (2 * q) * S + i], Gl[og + (2 * q + 1) * S + i]
            gj0, gj1 = Gl[og + (2 * q) * S + j], Gl[og + (2 * q + 1) * S + j]
            dot = gi0 * gj0 + gi1 * gj1
            wq = w[e, q]
            k00 += wq * (dot + gi0 * gj0)
            k01 += wq * (gi0 * gj1)
            k10 += wq * (gi1 * gj0)
            k11 += wq * (dot + gi1 * gj1)
        x0I0, x1I0 = X[o + 2 * i], X[o + n + 2 * i]
        x0I1, x1I1 = X[o + 2 * i + 1], X[o + n + 2 * i + 1]
        d = base + pos[sten[s0 + i]] * 2
        data_out[d] += k00 - _corr(a00, a11, a01, x0J0, x1J0, x0I0, x1I0)
        data_out[d + 1] += k01 - _corr(a00, a11, a01, x0J0, x1J0, x0I1, x1I1)
        d += nv * 2
        data_out[d] += k10 - _corr(a00, a11, a01, x0J1, x1J1, x0I0, x1I0)
        data_out[d + 1] += k11 - _corr(a00, a11, a01, x0J1, x1J1, x0I1, x1I1)


@njit(cache=True, inline="always")
def _corr(a00, a11, a01, x0J, x1J, x0I, x1I):
    """(A_bn^T A_bb^-1 A_bn)[J, I], the same bits as its [I, J] (products of the same
    pairs, summed in the same order)."""
    return a00 * (x0J * x0I) + a11 * (x1J * x1I) + a01 * ((x0J * x1I) + (x1J * x0I))


@njit(cache=True, parallel=True)
def _divergence_rows(ptr, sten, indptr, indices, vals, nq, dx, gl, psi, off2, AiAbn, inc_ptr,
                     inc_e, inc_l, cptr, cols, nodal, nblocks, indices_out, data_out):
    """The condensed divergence block ``(u, grad q) - B_b A_bb^-1 A_bn`` row by row: row r
    (P1 function r, gradient ``gl[k, :, e]`` on triangle e where r is its vertex k) holds
    its couplings with the velocity nodes ``cols[cptr[r]:cptr[r + 1]]`` (CSR order, dofs
    ``2 node + c``); ``psi[e]`` is the integral of e's bubble, so that
    ``B_b[r, (e, d)] = psi[e] d_d lambda_r``."""
    n = cptr.shape[0] - 1
    for blk in prange(nblocks):
        pos = np.full(nodal.shape[1], -1, np.int64)
        for r in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            base = 2 * cptr[r]
            for k in range(cptr[r + 1] - cptr[r]):
                pos[cols[cptr[r] + k]] = k
                for c in range(2):
                    indices_out[base + 2 * k + c] = nodal[c, cols[cptr[r] + k]]
                    data_out[base + 2 * k + c] = 0.0
            for t in range(inc_ptr[r], inc_ptr[r + 1]):
                e = inc_e[t]
                g0, g1 = gl[inc_l[t], 0, e], gl[inc_l[t], 1, e]
                for q in range(nq):
                    rq = e * nq + q
                    for kk in range(indptr[rq], indptr[rq + 1]):
                        d = base + 2 * pos[indices[kk]]
                        wv = dx[e, q] * vals[kk]
                        data_out[d] += wv * g0
                        data_out[d + 1] += wv * g1
                s0, S, o = ptr[e], ptr[e + 1] - ptr[e], off2[e]
                b0, b1 = psi[e] * g0, psi[e] * g1
                for i in range(S):
                    d = base + 2 * pos[sten[s0 + i]]
                    for c in range(2):
                        data_out[d + c] -= (b0 * AiAbn[o + 2 * i + c]
                                            + b1 * AiAbn[o + 2 * S + 2 * i + c])


_bubbles_serial = serial_twin(_bubbles)
_condensed_rows_serial = serial_twin(_condensed_rows)
_divergence_rows_serial = serial_twin(_divergence_rows)


class CondensedViscous:
    """The viscous block with the bubbles condensed out, and what the rest of the
    condensation needs: ``A`` (nu, nu) CSR, exactly symmetric; ``Ainv`` (nb, nb) the
    block-diagonal inverse of the bubbles' block; ``AiAbn`` (nb, nu) ``A_bb^-1 A_bn``, a
    CSR matrix on triangles, on tetrahedra an operator that is not stored
    (:class:`~skfem_nem.models.coupling_tet.TetCoupling`: ``@``, ``.T @``)."""

    def __init__(self, A: sp.csr_matrix, Ainv: sp.csr_matrix, AiAbn,
                 local: tuple):
        self.A, self.Ainv, self.AiAbn = A, Ainv, AiAbn
        # (offsets, values) of A_bb^-1 A_bn triangle by triangle, for the divergence
        self.local = local


def _rows_csr(rows: np.ndarray, indptr: np.ndarray, cols: np.ndarray, data: np.ndarray,
              shape: tuple) -> sp.csr_matrix:
    """CSR matrix of the given rows, in the order ``rows`` (a permutation of a subset)."""
    if np.array_equal(rows, np.arange(shape[0])):
        return sp.csr_matrix((data, cols, indptr), shape=shape)
    return sp.csr_matrix((data, (np.repeat(rows, np.diff(indptr)), cols)), shape=shape)


def _interleaved(ubasis) -> np.ndarray:
    """(2, n) velocity dofs of the nodes, checked to be ``2 node + c``."""
    nodal = np.ascontiguousarray(ubasis.dofs.nodal_dofs[:2], dtype=np.int64)
    n = nodal.shape[1]
    if ubasis.N != 2 * n or not np.array_equal(nodal, 2 * np.arange(n) + np.c_[0:2]):
        raise ValueError("the velocity basis must number its dofs 2 node + c "
                         "(a vector natural-neighbour basis)")
    return nodal


def condensed_viscous(ubasis, bubbles, eta: np.ndarray) -> CondensedViscous:
    """The viscous block ``2 eta eps(u) : eps(v)`` of the natural-neighbour velocity
    ``ubasis`` with the ``bubbles`` (:class:`~skfem_nem.models.bubbles.Bubbles` on the
    same triangles and quadrature) condensed out, for the viscosity ``eta``
    (ne, nq) at the quadrature points. Raises ``ValueError`` naming the first triangle
    whose bubble block is singular."""
    nodal = _interleaved(ubasis)
    ptr, sten = ubasis.stencil_ptr, ubasis.stencil_nodes
    S = np.diff(ptr)
    ne, nq = ubasis.dx.shape
    offg, off2 = (np.zeros(ne + 1, dtype=np.int64) for _ in range(2))
    np.cumsum(2 * nq * S, out=offg[1:])
    np.cumsum(4 * S, out=off2[1:])
    Gl, X, AiAbn = np.empty(offg[-1]), np.empty(off2[-1]), np.empty(off2[-1])
    cols, Ainv, det = np.empty(off2[-1], dtype=np.int64), np.zeros((ne, 2, 2)), np.empty(ne)
    w = np.ascontiguousarray(eta * ubasis.dx)
    Phi = ubasis.values_matrix
    parallel = parallel_kernels(ubasis)
    (_bubbles if parallel else _bubbles_serial)(
        ptr, sten, Phi.indptr, Phi.indices, ubasis.gradient_entries, nq, w,
        bubbles.gradient(), nodal, offg, Gl, off2, X, AiAbn, cols, Ainv, det)
    bad = ~(det > 0)
    if bad.any():
        raise ValueError(f"degenerate triangle {int(np.flatnonzero(bad)[0])}: its bubble "
                         f"block is singular ({int(bad.sum())} triangle(s))")
    A = _summed(ubasis, nodal, nq, w, offg, Gl, off2, X, Ainv, parallel)
    bd = bubbles.element_dofs                      # (2, ne): the bubbles of triangle e
    indptr = np.zeros(2 * ne + 1, dtype=np.int64)
    np.cumsum(np.repeat(2 * S, 2), out=indptr[1:])
    AiAbn_m = _rows_csr(bd.T.ravel(), indptr, cols, AiAbn, (bubbles.N, ubasis.N))
    return CondensedViscous(A, bubbles.block_diagonal(Ainv), AiAbn_m, (off2, AiAbn))


def _summed(ubasis, nodal, nq, w, offg, Gl, off2, X, Ainv, parallel) -> sp.csr_matrix:
    """The condensed block from :func:`_condensed_rows`, CSR over the stencils' pattern."""
    inc_ptr, inc_e, inc_l, cptr, cols = node_pattern(ubasis, parallel)
    n = cptr.shape[0] - 1
    nnz = 4 * int(cptr[-1])
    idt = index_dtype(ubasis.N, nnz)
    indices, data = np.empty(nnz, dtype=idt), np.empty(nnz)
    (_condensed_rows if parallel else _condensed_rows_serial)(
        ubasis.stencil_ptr, ubasis.stencil_nodes, nq, w, offg, Gl, off2, X, Ainv, inc_ptr,
        inc_e, inc_l, cptr, cols, nodal, basis_row_order(ubasis), blocks(n), indices, data)
    nv = np.diff(cptr)
    indptr = np.empty(2 * n + 1, dtype=idt)
    indptr[:-1] = (4 * cptr[:-1, None] + 2 * nv[:, None] * np.arange(2)[None]).ravel()
    indptr[-1] = nnz
    return sp.csr_matrix((data, indices, indptr), shape=(ubasis.N, ubasis.N))


def _divergence_data(ubasis, pbasis, bubbles, parallel: bool) -> tuple:
    """What the divergence block needs that no coefficient changes, once per spaces (kept
    with ``pbasis``): the pressure nodes' triangles and the union of their stencils
    (``(inc_ptr, inc_e, inc_l, cptr, cols)``), the P1 gradients (3, 2, ne) and the
    bubbles' integrals (ne,)."""
    data = pbasis.__dict__.get("_divergence_data")
    if data is None:
        ne = ubasis.dx.shape[0]
        tris = np.ascontiguousarray(pbasis.element_dofs, dtype=np.int64)     # (3, ne)
        inc = incidence(3 * np.arange(ne + 1), tris.T.ravel(), pbasis.N)
        pat = inc + stencil_union(ubasis.stencil_ptr, ubasis.stencil_nodes, inc[0], inc[1],
                                  pbasis.N, parallel)
        gl = np.ascontiguousarray(np.stack([np.asarray(pbasis.basis[k][0].grad)[:, :, 0]
                                            for k in range(3)]))
        data = pbasis.__dict__["_divergence_data"] = (pat, gl, bubbles.integral())
    return data


def condensed_divergence(ubasis, pbasis, bubbles, cv: CondensedViscous) -> sp.csr_matrix:
    """The divergence block ``(u, grad q)`` of the natural-neighbour velocity ``ubasis``
    and the P1 pressure ``pbasis``, with the ``bubbles`` condensed out as in
    ``cv`` (:func:`condensed_viscous`): ``B - B_b A_bb^-1 A_bn``, (np, nu) CSR over the
    union of the stencils of each pressure node's triangles."""
    nodal = _interleaved(ubasis)
    nq, npres = ubasis.dx.shape[1], pbasis.N
    parallel = parallel_kernels(ubasis)
    (inc_ptr, inc_e, inc_l, cptr, cols), gl, psi = _divergence_data(ubasis, pbasis, bubbles,
                                                                    parallel)
    nnz = 2 * int(cptr[-1])
    idt = index_dtype(ubasis.N, nnz)
    indices, data = np.empty(nnz, dtype=idt), np.empty(nnz)
    Phi = ubasis.values_matrix
    off2, AiAbn = cv.local
    (_divergence_rows if parallel else _divergence_rows_serial)(
        ubasis.stencil_ptr, ubasis.stencil_nodes, Phi.indptr, Phi.indices, Phi.data, nq,
        np.ascontiguousarray(ubasis.dx), gl, psi, off2, AiAbn, inc_ptr, inc_e, inc_l, cptr,
        cols, nodal, blocks(npres), indices, data)
    indptr = (2 * cptr).astype(idt)
    return sp.csr_matrix((data, indices, indptr), shape=(npres, ubasis.N))
