"""Summing over natural-neighbour stencils into one global matrix, row by row.

Element e of a natural-neighbour basis couples all the functions of its stencil, so its
matrix is a dense (Dv S_e) x (Du S_e) block, and the global matrix has the pattern of the
stencils: node v couples with the union of the stencils of the elements around it. That
pattern (:func:`node_pattern`) is kept with the basis; :func:`sum_coo` adds the element
matrices of the whole-mesh assembly (:mod:`skfem_nem.basis.assembly`) into it row by row,
each entry once and, with the dofs numbered ``D node + c`` (scikit-fem's vector
numbering), in canonical CSR order. The condensed viscous block of the Stokes solver
(:mod:`skfem_nem.models.condensation`) fills the same pattern row by row with a kernel of
its own, which computes each element's row where it adds it, and so does
:func:`sum_coo_gradients` for bases whose gradients are the same at all of an element's
points (the smoothed basis on tetrahedra): the gradient terms of a row come from the
elements' gradients and the form's coefficients summed over the points, no element matrix
stored. In all of them an entry sums its elements in ascending order, so element matrices
exactly symmetric give a sum exactly symmetric (the gradient rows: symmetric to round-off).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..coordinates.batch import index_dtype
from ..jit import serial_twin

__all__ = ["basis_row_order", "blocks", "incidence", "node_pattern", "row_order",
           "stencil_gradients", "stencil_union", "sum_coo",
           "sum_coo_gradients"]


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
def _node_pattern(ptr, sten, inc_ptr, inc_e, order, n, nblocks):
    """Sparsity pattern between nodes: node v couples with the (sorted)
    nodes ``cols[cptr[v]:cptr[v + 1]]``, the union of the stencils of the
    elements whose stencil holds v. The rows are taken in ``order``
    (:func:`row_order`)."""
    cnt = np.zeros(n, np.int64)
    for blk in prange(nblocks):
        mark = np.full(n, -1, np.int64)
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
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
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
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
              ndu, ndv, order, nblocks, rows_out, cols_out, data_out):
    """Add the local matrices ``K`` of the elements ``e0 .. e1 - 1`` into the global
    matrix, row by row (``init``: first set the rows, columns and zeros):
    node v's rows (components cv) hold the entries with the nodes
    ``cols[cptr[v]:cptr[v + 1]]`` (components cu) at
    ``Dv Du cptr[v] + (cv n_v + k) Du + cu``; no two entries share a place,
    and with dofs numbered ``D node + c`` the entries come out row-major
    sorted (canonical CSR order). Blocks of elements added in ascending order sum each
    entry's elements in the same order as one block of all. Rows are taken in ``order``
    (:func:`row_order`)."""
    n = cptr.shape[0] - 1
    for blk in prange(nblocks):
        pos = np.full(n, -1, np.int64)
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
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


@njit(cache=True, parallel=True)
def _sum_gradient_rows(ptr, sten, Gs, Ce, pa, pb, L, e0, e1, inc_ptr, inc_e, inc_l, cptr,
                       cols, Du, Dv, order, nblocks, data_out):
    """Add the gradient-gradient terms of the elements ``e0 .. e1 - 1`` into the global
    matrix (laid out as by :func:`_sum_rows`, which must have set it up), computing each
    element's row where it adds it: the gradients are the same at all of an element's
    points (``Gs`` (nnz of the stencils, dim): the gradient of stencil function s), so
    its test function j's row is ``sum_p Ce[p, e - e0] Gs[j, gv] Gs[i, gu]`` over the
    pairs p = (component cu, d/dx_gu of u; cv, d/dx_gv of v), ``a = c L + 1 + g``. No
    element matrix is stored: the work is that of summing them. Rows are taken in
    ``order`` (:func:`row_order`)."""
    n = cptr.shape[0] - 1
    dim = Gs.shape[1]
    for blk in prange(nblocks):
        pos = np.full(n, -1, np.int64)
        w = np.empty((Dv, Du, dim))
        for i in range(blk * n // nblocks, (blk + 1) * n // nblocks):
            v = order[i]
            nv = cptr[v + 1] - cptr[v]
            base = Dv * Du * cptr[v]
            for k in range(nv):
                pos[cols[cptr[v] + k]] = k
            for t in range(inc_ptr[v], inc_ptr[v + 1]):
                e = inc_e[t]
                if e < e0 or e >= e1:
                    continue
                s0 = ptr[e]
                _test_row(Ce, pa, pb, L, e - e0, Gs, s0 + inc_l[t], w)
                if Du == 1 and Dv == 1 and dim == 3:    # scalar forms in 3D: unrolled
                    w0, w1, w2 = w[0, 0, 0], w[0, 0, 1], w[0, 0, 2]
                    for s in range(s0, ptr[e + 1]):
                        data_out[base + pos[sten[s]]] += (w0 * Gs[s, 0] + w1 * Gs[s, 1]
                                                          + w2 * Gs[s, 2])
                    continue
                for s in range(s0, ptr[e + 1]):
                    at = base + pos[sten[s]] * Du
                    for cv in range(Dv):
                        for cu in range(Du):
                            x = 0.0
                            for g in range(dim):
                                x += w[cv, cu, g] * Gs[s, g]
                            data_out[at + cv * nv * Du + cu] += x


@njit(cache=True, inline="always")
def _test_row(Ce, pa, pb, L, c, Gs, sj, w):
    """``w[cv, cu, gu] = sum_p Ce[p, c] Gs[sj, gv]`` over the pairs p = (cu, gu; cv, gv):
    test function sj's row of its element's matrix is ``w . Gs[s]`` for trial function
    s."""
    w[:] = 0.0
    for p in range(pa.shape[0]):
        cu, gu = pa[p] // L, pa[p] % L - 1
        cv, gv = pb[p] // L, pb[p] % L - 1
        w[cv, cu, gu] += Ce[p, c] * Gs[sj, gv]


@njit(cache=True, parallel=True)
def _stencil_gradients(ptr, sten, indptr, indices, grads, nq, Gs):
    """``Gs[s]``: the gradient of stencil function s of its element at the element's
    first point (CSR row ``e nq``), zero where the row has none."""
    dim = grads.shape[0]
    for e in prange(ptr.shape[0] - 1):
        s0, s1 = ptr[e], ptr[e + 1]
        for s in range(s0, s1):
            for g in range(dim):
                Gs[s, g] = 0.0
        r = e * nq
        for kk in range(indptr[r], indptr[r + 1]):
            lo, hi = s0, s1 - 1
            while lo < hi:          # the stencil is sorted
                mid = (lo + hi) // 2
                if sten[mid] < indices[kk]:
                    lo = mid + 1
                else:
                    hi = mid
            for g in range(dim):
                Gs[lo, g] = grads[g, kk]


# Serial twins of the parallel kernels (small meshes: see assembly.PARALLEL_MIN)
_node_pattern_serial = serial_twin(_node_pattern)
_sum_rows_serial = serial_twin(_sum_rows)
_sum_gradient_rows_serial = serial_twin(_sum_gradient_rows)
_stencil_gradients_serial = serial_twin(_stencil_gradients)


def node_pattern(basis, parallel: bool = False) -> tuple:
    """The node incidence and node-node pattern of a basis' stencils, cached with the
    basis: ``(inc_ptr, inc_e, inc_l, cptr, cols)`` (see :func:`_incidence` and
    :func:`_node_pattern`)."""
    pat = basis.__dict__.get("_node_pattern")
    if pat is None:
        n = basis.function_dofs.shape[1]
        ptr, sten = basis.stencil_ptr, basis.stencil_nodes
        inc = _incidence(ptr, sten, n)
        order = row_order(basis.mesh.p, ptr, sten, inc[0], inc[1])
        kernel = _node_pattern if parallel else _node_pattern_serial
        pat = inc + kernel(ptr, sten, inc[0], inc[1], order, n, blocks(n))
        basis.__dict__["_node_pattern"] = pat
        basis.__dict__["_row_order"] = order
    return pat


def basis_row_order(basis) -> np.ndarray:
    """The :func:`row_order` of a basis' functions (cached with its :func:`node_pattern`)."""
    if "_row_order" not in basis.__dict__:
        node_pattern(basis)
    return basis.__dict__["_row_order"]


def row_order(p, ptr, sten, inc_ptr, inc_e) -> np.ndarray:
    """The order in which the row kernels take the functions: along the Z-order curve
    through a node of each (a function that is not a node, the quadratic basis' edge
    functions: the first node of the first stencil that holds it). Rows are computed
    independently, so the order changes no result; it keeps the stencils of consecutive
    rows in cache. With nodes numbered at random (random points, as scikit-fem numbers
    them) the 3D Laplace pattern and sums took 6.8 s at 100,000 nodes in node order
    (docs/ndim.md)."""
    from ..geometry.nodesets import morton_order
    n = inc_ptr.shape[0] - 1
    nv = p.shape[1]
    rep = np.minimum(np.arange(n), nv - 1)
    far = np.flatnonzero((np.arange(n) >= nv) & (np.diff(inc_ptr) > 0))
    rep[far] = sten[ptr[inc_e[inc_ptr[far]]]]
    if n < 2:
        return np.arange(n, dtype=np.int64)
    return np.ascontiguousarray(morton_order(p.T[rep]), dtype=np.int64)


def incidence(ptr, sten, n: int) -> tuple:
    """``(inc_ptr, inc_e, inc_l)``: node v is entry ``inc_l[k]`` of element ``inc_e[k]``
    of the element lists ``sten[ptr[e]:ptr[e + 1]]`` for k in ``inc_ptr[v]:inc_ptr[v + 1]``
    (elements ascending)."""
    return _incidence(np.asarray(ptr, dtype=np.int64), np.asarray(sten, dtype=np.int64), n)


def stencil_union(ptr, sten, inc_ptr, inc_e, n: int, parallel: bool = False) -> tuple:
    """``(cptr, cols)``: node v's sorted union ``cols[cptr[v]:cptr[v + 1]]`` of the stencils
    ``sten[ptr[e]:ptr[e + 1]]`` of the elements ``inc_e[inc_ptr[v]:inc_ptr[v + 1]]``."""
    kernel = _node_pattern if parallel else _node_pattern_serial
    return kernel(ptr, sten, inc_ptr, inc_e, np.arange(n), n, blocks(n))


def blocks(n: int) -> int:
    """How many row blocks the parallel row kernels split n nodes into."""
    import numba
    return max(1, min(n // 64, 4 * numba.get_num_threads()))


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
    order = basis_row_order(u)
    for k, (e0, e1, off, K) in enumerate(element_blocks):
        kernel(u.stencil_ptr, u.stencil_nodes, off, K, e0, e1, k == 0, inc_ptr, inc_e,
               inc_l, cptr, cols, Du, Dv, ndu, ndv, order, blocks(n), ind[0], ind[1], data)
    return ind, data, cptr


def stencil_gradients(basis, parallel: bool = False):
    """(nnz of the stencils, dim): the gradient of each stencil function of a basis whose
    gradients are the same at all of an element's points, cached with the basis (a
    function's gradient in one place: the row sums read them stencil by stencil)."""
    Gs = basis.__dict__.get("_stencil_gradients")
    if Gs is None and getattr(basis, "cell_rows", None) is not None:
        Gs = basis.cell_rows.stencil_gradients(basis.dx.shape[1], basis.stencil_ptr,
                                               basis.stencil_nodes)
        basis.__dict__["_stencil_gradients"] = Gs
    if Gs is None:
        G = basis.gradient_entries
        Phi = basis.values_matrix
        Gs = np.empty((basis.stencil_nodes.shape[0], G.shape[0]))
        kernel = _stencil_gradients if parallel else _stencil_gradients_serial
        kernel(basis.stencil_ptr, basis.stencil_nodes, Phi.indptr, Phi.indices, G,
               basis.dx.shape[1], Gs)
        basis.__dict__["_stencil_gradients"] = Gs
    return Gs


def sum_coo_gradients(u, v, Du, Dv, chunks, parallel: bool = False):
    """As :func:`sum_coo`, for bases whose gradients are the same at all of an element's
    points: ``chunks`` yields ``(e0, e1, kind, data)``, consecutive ascending element
    ranges, either ``("gradients", (Ce, pa, pb))`` (the coefficients Ce (npair, e1 - e0)
    summed over the points of the gradient pairs ``(pa, pb)``, added by
    :func:`_sum_gradient_rows`) or ``("matrices", (off, K))`` (element matrices of the
    other pairs, as for :func:`sum_coo`); both kinds may come for one range."""
    inc_ptr, inc_e, inc_l, cptr, cols = node_pattern(u, parallel)
    n = cptr.shape[0] - 1
    ind = np.empty((2, Du * Dv * int(cptr[-1])), dtype=index_dtype(max(u.N, v.N), 0))
    data = np.empty(ind.shape[1])
    ndu = np.ascontiguousarray(u.function_dofs[:Du], dtype=np.int64)
    ndv = np.ascontiguousarray(v.function_dofs[:Dv], dtype=np.int64)
    ptr, sten = u.stencil_ptr, u.stencil_nodes
    dim = u.mesh.dim()
    Gs = stencil_gradients(u, parallel)
    rows = _sum_rows if parallel else _sum_rows_serial
    grads = _sum_gradient_rows if parallel else _sum_gradient_rows_serial
    empty = np.zeros(1)
    order = basis_row_order(u)
    rows(ptr, sten, np.zeros(ptr.shape[0], np.int64), empty, 0, 0, True, inc_ptr, inc_e,
         inc_l, cptr, cols, Du, Dv, ndu, ndv, order, blocks(n), ind[0], ind[1], data)
    for e0, e1, kind, what in _merged_gradient_chunks(chunks):
        if kind == "gradients":
            Ce, pa, pb = what
            grads(ptr, sten, Gs, Ce, pa, pb, 1 + dim, e0, e1, inc_ptr, inc_e, inc_l, cptr,
                  cols, Du, Dv, order, blocks(n), data)
        else:
            off, K = what
            rows(ptr, sten, off, K, e0, e1, False, inc_ptr, inc_e, inc_l, cptr, cols, Du,
                 Dv, ndu, ndv, order, blocks(n), ind[0], ind[1], data)
    return ind, data


#: most coefficients (numbers) of consecutive gradient chunks joined into one pass of the
#: row kernel (128 MB); each pass walks every row's elements, so the 11 chunks of a 3D
#: Laplacian at 100,000 nodes cost 3.5 s in 11 passes and 0.4 s in one
GRADIENT_COEFFICIENT_BUDGET = 1 << 24


def _merged_gradient_chunks(chunks):
    """The chunks of :func:`sum_coo_gradients` with consecutive gradient chunks of the same
    pairs joined (up to :data:`GRADIENT_COEFFICIENT_BUDGET`): the same sums in the same
    order (each row adds its elements in ascending order either way), fewer passes."""
    held = []

    def joined():
        Ce = held[0][3][0] if len(held) == 1 else np.concatenate([h[3][0] for h in held], 1)
        out = (held[0][0], held[-1][1], "gradients", (Ce, *held[0][3][1:]))
        held.clear()
        return out

    size = 0                                # coefficients held
    for chunk in chunks:
        e0, e1, kind, what = chunk
        if held and (kind != "gradients" or not _same_pairs(held[0][3], what)
                     or size + what[0].size > GRADIENT_COEFFICIENT_BUDGET):
            yield joined()
            size = 0
        if kind == "gradients":
            held.append(chunk)
            size += what[0].size
        else:
            yield chunk
    if held:
        yield joined()


def _same_pairs(a, b) -> bool:
    """Do two gradient chunks' data ``(Ce, pa, pb)`` have the same pairs?"""
    return np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])


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
