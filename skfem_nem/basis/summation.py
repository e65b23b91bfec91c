"""Summing over natural-neighbour stencils into one global matrix, row by row.

Element e of a natural-neighbour basis couples all the functions of its stencil, so its
matrix is a dense (Dv S_e) x (Du S_e) block, and the global matrix has the pattern of the
stencils: node v couples with the union of the stencils of the elements around it. That
pattern (:func:`node_pattern`) is kept with the basis; :func:`sum_coo` adds the element
matrices of the whole-mesh assembly (:mod:`skfem_nem.basis.assembly`) into it row by row,
each entry once and, with the dofs numbered ``D node + c`` (scikit-fem's vector
numbering), in canonical CSR order. The condensed viscous block of the Stokes solver
(:mod:`skfem_nem.models.condensation`) fills the same pattern row by row with a kernel of
its own, which computes each element's row where it adds it. In both, an entry sums its
elements in ascending order, so element matrices exactly symmetric give a sum exactly
symmetric.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..coordinates.batch import index_dtype
from ..jit import serial_twin

__all__ = ["blocks", "incidence", "node_pattern", "stencil_union", "sum_coo"]


@njit(cache=True)
def _incidence(ptr, sten, n):
    """Node -> (element, local index) lists of the stencils: node v is
    function ``inc_l[k]`` of element ``inc_e[k]`` for k in
    ``inc_ptr[v]:inc_ptr[v + 1]``."""
    ne = ptr.shape[0] - 1
    inc_ptr = np.zeros(n + 1, np.int64)
    for k in range(ptr[ne]):
        inc_ptr[sten[k] + 1] += 1
    for v in range(n):
        inc_ptr[v + 1] += inc_ptr[v]
    fill = inc_ptr[:-1].copy()
    inc_e = np.empty(ptr[ne], np.int64)
    inc_l = np.empty(ptr[ne], np.int64)
    for e in range(ne):
        for s in range(ptr[e], ptr[e + 1]):
            v = sten[s]
            inc_e[fill[v]] = e
            inc_l[fill[v]] = s - ptr[e]
            fill[v] += 1
    return inc_ptr, inc_e, inc_l


_GAPS = (701, 301, 132, 57, 23, 10, 4, 1)  # Ciura's gaps, for the Shell sort below


@njit(cache=True)
def _sort_run(a, lo, hi):
    """Sort a[lo:hi] in place (Shell sort: rows of tens to hundreds of nodes; numba's
    quicksort would add a second or two to the first run's compilation)."""
    for g in _GAPS:
        for i in range(lo + g, hi):
            x = a[i]
            j = i
            while j - g >= lo and a[j - g] > x:
                a[j] = a[j - g]
                j -= g
            a[j] = x


@njit(cache=True, parallel=True)
def _node_pattern(ptr, sten, inc_ptr, inc_e, n, nblocks):
    """Sparsity pattern between nodes: node v couples with the (sorted)
    nodes ``cols[cptr[v]:cptr[v + 1]]``, the union of the stencils of the
    elements whose stencil holds v."""
    cnt = np.zeros(n, np.int64)
    for blk in prange(nblocks):
        mark = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            c = 0
            for k in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[k]
                for s in range(ptr[e], ptr[e + 1]):
                    if mark[sten[s]] != v:
                        mark[sten[s]] = v
                        c += 1
            cnt[v] = c
    cptr = np.zeros(n + 1, np.int64)
    for v in range(n):
        cptr[v + 1] = cptr[v] + cnt[v]
    cols = np.empty(cptr[n], np.int64)
    for blk in prange(nblocks):
        mark = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            c = cptr[v]
            for k in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[k]
                for s in range(ptr[e], ptr[e + 1]):
                    if mark[sten[s]] != v:
                        mark[sten[s]] = v
                        cols[c] = sten[s]
                        c += 1
            _sort_run(cols, cptr[v], cptr[v + 1])
    return cptr, cols


@njit(cache=True, parallel=True)
def _sum_rows(ptr, sten, off, K, e0, e1, init, inc_ptr, inc_e, inc_l, cptr, cols, Du, Dv,
              ndu, ndv, nblocks, rows_out, cols_out, data_out):
    """Add the local matrices ``K`` of the elements ``e0 .. e1 - 1`` into the global
    matrix, row by row (``init``: first set the rows, columns and zeros):
    node v's rows (components cv) hold the entries with the nodes
    ``cols[cptr[v]:cptr[v + 1]]`` (components cu) at
    ``Dv Du cptr[v] + (cv n_v + k) Du + cu``; no two entries share a place,
    and with dofs numbered ``D node + c`` the entries come out row-major
    sorted (canonical CSR order). Blocks of elements added in ascending order sum each
    entry's elements in the same order as one block of all."""
    n = cptr.shape[0] - 1
    for blk in prange(nblocks):
        pos = np.full(n, -1, np.int64)
        for v in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            nv = cptr[v + 1] - cptr[v]
            base = Dv * Du * cptr[v]
            for k in range(nv):
                pos[cols[cptr[v] + k]] = k
            if init:
                for cv in range(Dv):
                    for k in range(nv):
                        for cu in range(Du):
                            o = base + (cv * nv + k) * Du + cu
                            rows_out[o] = ndv[cv, v]
                            cols_out[o] = ndu[cu, cols[cptr[v] + k]]
                            data_out[o] = 0.0
            for t in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[t]
                if e < e0 or e >= e1:
                    continue
                j = inc_l[t]
                s0 = ptr[e]
                S = ptr[e + 1] - s0
                nc = Du * S
                for cv in range(Dv):
                    src = off[e] + (Dv * j + cv) * nc
                    dst = base + cv * nv * Du
                    for i in range(S):
                        k = pos[sten[s0 + i]]
                        for cu in range(Du):
                            data_out[dst + k * Du + cu] += K[src + Du * i + cu]


# Serial twins of the parallel kernels (small meshes: see assembly.PARALLEL_MIN)
_node_pattern_serial = serial_twin(_node_pattern)
_sum_rows_serial = serial_twin(_sum_rows)


def node_pattern(basis, parallel: bool = False) -> tuple:
    """The node incidence and node-node pattern of a basis' stencils, cached with the
    basis: ``(inc_ptr, inc_e, inc_l, cptr, cols)`` (see :func:`_incidence` and
    :func:`_node_pattern`)."""
    pat = basis.__dict__.get("_node_pattern")
    if pat is None:
        n = basis.function_dofs.shape[1]
        ptr, sten = basis.stencil_ptr, basis.stencil_nodes
        inc = _incidence(ptr, sten, n)
        kernel = _node_pattern if parallel else _node_pattern_serial
        pat = inc + kernel(ptr, sten, inc[0], inc[1], n, blocks(n))
        basis.__dict__["_node_pattern"] = pat
    return pat


def incidence(ptr, sten, n: int) -> tuple:
    """``(inc_ptr, inc_e, inc_l)``: node v is entry ``inc_l[k]`` of element ``inc_e[k]``
    of the element lists ``sten[ptr[e]:ptr[e + 1]]`` for k in ``inc_ptr[v]:inc_ptr[v + 1]``
    (elements ascending)."""
    return _incidence(np.asarray(ptr, dtype=np.int64), np.asarray(sten, dtype=np.int64), n)


def stencil_union(ptr, sten, inc_ptr, inc_e, n: int, parallel: bool = False) -> tuple:
    """``(cptr, cols)``: node v's sorted union ``cols[cptr[v]:cptr[v + 1]]`` of the stencils
    ``sten[ptr[e]:ptr[e + 1]]`` of the elements ``inc_e[inc_ptr[v]:inc_ptr[v + 1]]``."""
    kernel = _node_pattern if parallel else _node_pattern_serial
    return kernel(ptr, sten, inc_ptr, inc_e, n, blocks(n))


def blocks(n: int) -> int:
    """How many row blocks the parallel row kernels split n nodes into."""
    import numba
    return max(1, min(n // 256, 4 * numba.get_num_threads()))


def _summed(u, v, Du, Dv, element_blocks, parallel, idt):
    """Rows, columns and values of the summed element matrices, each entry once."""
    inc_ptr, inc_e, inc_l, cptr, cols = node_pattern(u, parallel)
    n = cptr.shape[0] - 1
    nnz = Du * Dv * int(cptr[-1])
    ind = np.empty((2, nnz), dtype=idt)
    data = np.empty(nnz)
    ndu = np.ascontiguousarray(u.function_dofs[:Du], dtype=np.int64)
    ndv = np.ascontiguousarray(v.function_dofs[:Dv], dtype=np.int64)
    kernel = _sum_rows if parallel else _sum_rows_serial
    for k, (e0, e1, off, K) in enumerate(element_blocks):
        kernel(u.stencil_ptr, u.stencil_nodes, off, K, e0, e1, k == 0, inc_ptr, inc_e,
               inc_l, cptr, cols, Du, Dv, ndu, ndv, blocks(n), ind[0], ind[1], data)
    return ind, data, cptr


def sum_coo(u, v, Du, Dv, element_blocks, parallel: bool = False):
    """COO arrays ``(rows and columns (2, nnz), values)`` of the element matrices of the
    ``Du``-vector trial basis ``u`` and the ``Dv``-vector test basis ``v`` (sharing
    their stencils) summed: each entry once. ``element_blocks`` yields ``(e0, e1, off,
    K)`` for consecutive ascending ranges of elements covering them all: element e's
    matrix, (Dv S) x (Du S) row-major, at ``K[off[e]:off[e + 1]]`` (``off`` indexed by
    the element, its block's ``K`` only held while the block is summed)."""
    ind, data, _ = _summed(u, v, Du, Dv, element_blocks, parallel,
                           index_dtype(max(u.N, v.N), 0))
    return ind, data
