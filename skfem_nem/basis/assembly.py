"""Teach scikit-fem's forms to assemble over natural-neighbour bases.

A :class:`~skfem_nem.NaturalNeighbourBasis` is a set of groups of triangles with equal
stencil size; each group is an ordinary scikit-fem basis. The wrappers installed here make
``BilinearForm`` and ``LinearForm`` (and therefore ``asm``) loop over those groups and
concatenate their COO contributions, so user code is unchanged. Forms on ordinary bases take
scikit-fem's own code path untouched. The wrappers are installed when the first
natural-neighbour basis (a :class:`StencilBasis`) is built, not on import, and
:func:`restore_scikit_fem_assembly` takes them out again.

Keyword arguments are split with the groups: dof vectors are interpolated by each group,
arrays and ``DiscreteField`` objects defined over all elements (shape ``(..., nelems, nq)``)
are restricted to the group's elements.

Bilinear and linear forms on natural-neighbour bases whose trial and test functions share
their stencils (the usual case: one basis, or a scalar and a vector basis on the same mesh)
take a faster road that needs no groups at all: the form is linear in the components of
(value, gradient) of u and of v, so ``form(u, v) = sum_ab C_ab(x) u_a v_b``; the
coefficients ``C`` are read off by calling the form on unit fields (all of them stacked into
one call per chunk of elements) and a numba kernel contracts them, element by element, with
the values and gradients of the element's stencil functions. The form is called a fixed
number of times whatever the stencil sizes, and the work is the sum over elements of the
stencil size squared. On a basis whose gradients are the same at all of an element's points
(the smoothed basis on tetrahedra) the gradient-gradient terms skip the element matrices:
their coefficients are summed over the points and the global rows are computed from the
elements' gradients (:func:`~skfem_nem.basis.summation.sum_coo_gradients`). Functionals
need no wrapper: they read only the quadrature data, which a natural-neighbour basis has
over all its elements.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange
from skfem.assembly import CellBasis
from skfem.assembly.form import BilinearForm, LinearForm
from skfem.assembly.form.form import FormExtraParams
from skfem.element import DiscreteField, ElementVector

from ..coordinates.batch import index_dtype
from ..jit import serial_twin
from .coefficients import (NotProbeable, probe_coefficients, split_kwargs, tile,
                           tile_array)
from .summation import sum_coo, sum_coo_gradients

_INSTALLED = False
#: element-pairs evaluated per form call in the stacked assembly
STACK_SIZE = 1 << 16
#: assemble natural-neighbour pairs from the form's coefficients (probed on
#: unit fields) instead of calling the form on stacked pairs
PROBE = True
#: assemble forms on bases that share their functions over the whole mesh at
#: once (coefficients probed once per chunk of elements, numba contraction)
WHOLE = True


class StencilBasis:
    """Marks bases whose local functions differ from element to element
    (natural-neighbour stencils): forms on them are assembled here; forms on
    any other basis take scikit-fem's own code, untouched."""


class StencilGroup:
    """Marks the per-stencil-size group bases of a natural-neighbour basis: ``stencil_values
    = (V, G)`` and ``stacked(idx)`` for the stacked assembly; ``release_fields()`` drops
    the per-function fields (``basis``) that scikit-fem's own assembly made them build."""


def _is_nn(basis) -> bool:
    return isinstance(basis, StencilBasis)


def _partner(basis, nn, idx, key):
    """``basis`` restricted to the elements ``idx`` of the NEM basis ``nn``."""
    if _is_nn(basis):
        return basis.restricted(idx, key)
    if isinstance(basis, CellBasis):
        if not _same_elements(basis, nn):
            raise ValueError("a CellBasis mixed with a natural-neighbour basis must live "
                             "on the same elements of the same mesh: build it with "
                             "nn_basis.with_element(element)")
        if basis.X.shape[-1] != nn.X.shape[-1] or not np.allclose(basis.X, nn.X):
            raise ValueError("quadrature mismatch: build the CellBasis with "
                             "quadrature=nn_basis.quadrature (or nn_basis.with_element)")
        cache = nn.__dict__.setdefault("_partners", {})
        k = (id(basis), key)
        if k not in cache:
            cache[k] = (basis, basis.with_elements(idx if nn.tind is None else nn.tind[idx]))
        return cache[k][1]
    raise TypeError(f"cannot mix {type(basis).__name__} with a natural-neighbour basis")


def _same_elements(a, b) -> bool:
    """Do two bases integrate over the same elements of one mesh, in one order?"""
    if a.mesh is not b.mesh or a.nelems != b.nelems:
        return False
    if a.tind is None or b.tind is None:
        return a.tind is None and b.tind is None
    return bool(np.array_equal(a.tind, b.tind))


def _pairs(ubasis, vbasis):
    """Yield (element indices, u group, v group) covering all elements."""
    nn = ubasis if _is_nn(ubasis) else vbasis
    if _is_nn(ubasis) and _is_nn(vbasis) and ubasis is not vbasis:
        if ubasis.nelems != vbasis.nelems or (
                not hasattr(ubasis, "find") and not _same_elements(ubasis, vbasis)):
            raise ValueError("trial and test natural-neighbour bases live on different "
                             "element sets")
        key = ubasis.stencil_sizes.astype(np.int64) * 100000 + vbasis.stencil_sizes
        order = np.argsort(key, kind="stable")
        bounds = np.flatnonzero(np.diff(key[order])) + 1
        for idx in np.split(order, bounds):
            k = int(key[idx[0]])
            yield idx, ubasis.restricted(idx, ("pair", k)), vbasis.restricted(idx, ("pair", k))
        return
    for g in nn.groups:
        idx = g.tind
        u = g if ubasis is nn else _partner(ubasis, nn, idx, ("group", g.Nbfun))
        v = g if vbasis is nn else _partner(vbasis, nn, idx, ("group", g.Nbfun))
        yield idx, u, v


def _stackable(b):
    return isinstance(b, StencilGroup)


def _probes(g, ne, nq):
    """Unit fields, one per scalar component of (value, gradient) of the
    element of group basis g: (D, 1 + dim) of them for a D-vector element."""
    dim = g.stencil_values[1].shape[0]
    vec = isinstance(g.elem, ElementVector)
    D = g.elem.dim if vec else 1
    out = []
    for c in range(D):
        for k in range(1 + dim):
            val = np.zeros((D, ne, nq))
            grad = np.zeros((D, dim, ne, nq))
            if k == 0:
                val[c] = 1.0
            else:
                grad[c, k - 1] = 1.0
            out.append((DiscreteField(val, grad),) if vec
                       else (DiscreteField(val[0], grad[0]),))
    return out, D, dim


def _probe_pays(u, v) -> bool:
    """Probing costs (D (1 + dim))^2 form calls on one element's worth of
    data each; stacking all pairs costs about one call per 65k element-pairs.
    Probe when the saved pair evaluations outweigh the extra calls (small
    groups are cheaper stacked: their cost is call overhead)."""
    dim = u.stencil_values[1].shape[0]
    P = (u.elem.dim if isinstance(u.elem, ElementVector) else 1) * (1 + dim)
    Q = (v.elem.dim if isinstance(v.elem, ElementVector) else 1) * (1 + dim)
    pairs = u.Nbfun * v.Nbfun
    return pairs > P * Q and u.nelems * (pairs - P * Q) > P * Q * 100


def _probed_bilinear(form, u, v, kwargs):
    """All local matrices of two group bases from the form's coefficients.

    A bilinear form is linear in the components of (value, gradient) of u
    and of v, so ``form(u, v) = sum_ab C_ab(x) u_a v_b``; ``C`` is read off by
    calling the form on unit fields ((D (1 + dim))^2 calls, whatever the
    stencil size) and contracted with the stored values and gradients."""
    ne, nq = u.dx.shape
    w = FormExtraParams({**u.default_parameters(), **form._normalize_asm_kwargs(kwargs, u)})
    pu, Du, dim = _probes(u, ne, nq)
    pv, Dv, _ = _probes(v, ne, nq)
    C = np.empty((len(pu), len(pv), ne, nq), dtype=form.dtype)
    for a, Ua in enumerate(pu):
        for b, Vb in enumerate(pv):
            C[a, b] = form.form(*Ua, *Vb, w)
    C *= u.dx
    Pu = np.concatenate([u.stencil_values[0][None], u.stencil_values[1]])   # (1 + dim, S_u, ne, nq)
    Pv = np.concatenate([v.stencil_values[0][None], v.stencil_values[1]])
    C = C.reshape(Du, 1 + dim, Dv, 1 + dim, ne, nq)
    K = np.einsum("dlckeq,lteq,kseq->sctde", C, Pu, Pv, optimize=True)
    Su, Sv = Pu.shape[1], Pv.shape[1]
    K = K.reshape(Sv * Dv, Su * Du, ne)
    rows = np.broadcast_to(v.element_dofs[:, None, :], K.shape).ravel()
    cols = np.broadcast_to(u.element_dofs[None, :, :], K.shape).ravel()
    return np.array([rows, cols]), K.ravel()


def _stacked_bilinear(form, u, v, kwargs):
    """All local pairs (j, i) of two group bases in few form calls: the pairs
    are stacked along the element axis (scikit-fem calls the form once per
    pair, which for NEM's many small groups is dominated by call overhead)."""
    ne = u.nelems
    w = FormExtraParams({**u.default_parameters(), **form._normalize_asm_kwargs(kwargs, u)})
    nu, nv = u.Nbfun, v.Nbfun
    jj, ii = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    jj, ii = jj.ravel(), ii.ravel()
    per = max(1, STACK_SIZE // max(1, ne))
    data = np.empty((jj.size, ne), dtype=form.dtype)
    for p0 in range(0, jj.size, per):
        p1 = min(jj.size, p0 + per)
        reps = p1 - p0
        U = u.stacked(jj[p0:p1])
        V = v.stacked(ii[p0:p1])
        W = FormExtraParams({k: tile(x, reps, ne) for k, x in w.items()})
        dx = tile_array(u.dx, reps)
        data[p0:p1] = form._kernel(U, V, W, dx).reshape(reps, ne)
    rows = v.element_dofs[ii].ravel()
    cols = u.element_dofs[jj].ravel()
    return np.array([rows, cols]), data.ravel()


def _stacked_linear(form, v, kwargs):
    ne = v.nelems
    w = FormExtraParams({**v.default_parameters(), **form._normalize_asm_kwargs(kwargs, v)})
    n = v.Nbfun
    idx = np.arange(n)
    per = max(1, STACK_SIZE // max(1, ne))
    data = np.empty((n, ne), dtype=form.dtype)
    for p0 in range(0, n, per):
        p1 = min(n, p0 + per)
        reps = p1 - p0
        V = v.stacked(idx[p0:p1])
        W = FormExtraParams({k: tile(x, reps, ne) for k, x in w.items()})
        data[p0:p1] = form._kernel(V, W, tile_array(v.dx, reps)).reshape(reps, ne)
    return np.array([v.element_dofs.ravel()]), data.ravel()


# ---------------------------------------------------------------------------
# the whole-mesh road: coefficients probed once, contracted by numba kernels
# ---------------------------------------------------------------------------

@njit(cache=True, inline="always")
def stencil_position(sten, s0, S, c):
    """Position of node c in the sorted stencil ``sten[s0:s0 + S]`` (which
    holds it), by binary search."""
    lo = 0
    hi = S - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if sten[s0 + mid] < c:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _gather(e, ptr, sten, indptr, indices, vals, grads, nq, B):
    """Values and gradients of element e's stencil functions at its
    quadrature points: B (nq, 1 + dim, S), zero where a function vanishes."""
    dim = grads.shape[0]
    s0 = ptr[e]
    S = ptr[e + 1] - s0
    for q in range(nq):
        r = e * nq + q
        for kk in range(indptr[r], indptr[r + 1]):
            lo = stencil_position(sten, s0, S, indices[kk])
            B[q, 0, lo] = vals[kk]
            for g in range(dim):
                B[q, 1 + g, lo] = grads[g, kk]


@njit(cache=True, parallel=True)
def _contract_bilinear(e0, e1, ptr, sten, indptr, indices, vals, grads, nq, C, pa, pb,
                       Du, Dv, off, K, const_grad):
    """Local matrices of elements e0..e1-1.

    ``C`` (npairs, e1 - e0, nq): coefficient (times dx) of the pair
    ``(pa[p], pb[p])`` of (component, value/gradient) indices of u and v,
    ``a = c (1 + dim) + k`` with k = 0 for the value and 1 + g for d/dx_g.
    Element e's matrix, (Dv S) rows (test function j, component cv at
    ``Dv j + cv``) by (Du S) columns (``Du i + cu``), row-major, goes to
    ``K[off[e]:off[e + 1]]``. With ``const_grad`` (the gradients are the same at
    all of an element's points) the gradient-gradient pairs sum their coefficients
    over the points first and are contracted once.
    """
    dim = grads.shape[0]
    L = 1 + dim
    npair = pa.shape[0]
    for e in prange(e0, e1):
        S = ptr[e + 1] - ptr[e]
        B = np.zeros((nq, L, S))
        _gather(e, ptr, sten, indptr, indices, vals, grads, nq, B)
        nc = Du * S
        o = off[e]
        for r in range(Dv * S * nc):
            K[o + r] = 0.0
        for q in range(nq):
            for p in range(npair):
                if const_grad and pa[p] % L > 0 and pb[p] % L > 0:
                    continue
                _add_pair(C[p, e - e0, q], pa[p], pb[p], L, B[q], B[q], S, Du, Dv, o, nc, K)
        if const_grad:
            for p in range(npair):
                if pa[p] % L > 0 and pb[p] % L > 0:
                    coef = 0.0
                    for q in range(nq):
                        coef += C[p, e - e0, q]
                    _add_pair(coef, pa[p], pb[p], L, B[0], B[0], S, Du, Dv, o, nc, K)


@njit(cache=True, inline="always")
def _add_pair(coef, a, b, L, Bu, Bv, S, Du, Dv, o, nc, K):
    """Add ``coef`` times the outer product of the rows ``a % L`` of ``Bu`` (trial
    component ``a // L``) and ``b % L`` of ``Bv`` (test component ``b // L``) to the
    element matrix at ``K[o:]``."""
    if coef == 0.0:
        return
    cu, k = a // L, a % L
    cv, l_ = b // L, b % L
    for i in range(S):
        t = coef * Bu[k, i]
        if t == 0.0:
            continue
        col = o + Du * i + cu
        for j in range(S):
            K[col + (Dv * j + cv) * nc] += t * Bv[l_, j]


@njit(cache=True, parallel=True)
def _contract_linear(e0, e1, ptr, sten, indptr, indices, vals, grads, nq, C, pb, Dv, ndv,
                     off, rows, data):
    """Local load vectors of elements e0..e1-1 (see :func:`_contract_bilinear`)."""
    dim = grads.shape[0]
    L = 1 + dim
    npair = pb.shape[0]
    for e in prange(e0, e1):
        s0 = ptr[e]
        S = ptr[e + 1] - s0
        B = np.zeros((nq, L, S))
        _gather(e, ptr, sten, indptr, indices, vals, grads, nq, B)
        b = np.zeros((Dv, S))
        for q in range(nq):
            for p in range(npair):
                coef = C[p, e - e0, q]
                if coef == 0.0:
                    continue
                cv = pb[p] // L
                l_ = pb[p] % L
                for j in range(S):
                    b[cv, j] += coef * B[q, l_, j]
        o = off[e]
        for j in range(S):
            for cv in range(Dv):
                rows[o] = ndv[cv, sten[s0 + j]]
                data[o] = b[cv, j]
                o += 1


# Serial twins of the parallel kernels: on small meshes waking the thread
# pool costs more than the work (and OpenMP threads that spin between calls
# compete with everything else on the machine).
_contract_bilinear_serial = serial_twin(_contract_bilinear)
_contract_linear_serial = serial_twin(_contract_linear)
#: below this many stencil entries squared (times quadrature points) the
#: kernels run on one thread
PARALLEL_MIN = 1 << 21
#: the element matrices of the whole-mesh assembly are made and summed in blocks of
#: elements taking at most this many numbers (256 MB): all at once, 3D elasticity took
#: 4.3 GB at 10,000 nodes (9 S^2 numbers a tetrahedron). Blocks sum each entry's elements
#: in the same ascending order as one, so the matrices are the same to the bit
ELEMENT_MATRIX_BUDGET = 1 << 25


def _parallel(basis) -> bool:
    return basis.nstencil_entries * basis.dx.shape[1] >= PARALLEL_MIN


def _components(basis):
    """(number of components D, space dimension) of a natural-neighbour basis."""
    dim = basis.mesh.dim()
    return (basis.elem.dim if isinstance(basis.elem, ElementVector) else 1), dim


def _shares_functions(u, v) -> bool:
    """Do two natural-neighbour bases evaluate the same scalar functions at
    the same points (one basis, or e.g. a scalar and a vector basis on one
    mesh with one quadrature and one kind of coordinates)?"""
    if u is v:
        return True
    return (type(u) is type(v) and u.mesh is v.mesh and u.nelems == v.nelems
            and (hasattr(u, "find") or _same_elements(u, v))
            and u.coordinates == v.coordinates and u.method == v.method
            and u.X.shape == v.X.shape and np.array_equal(u.X, v.X)
            and np.array_equal(u.dx, v.dx)
            and np.array_equal(u.stencil_ptr, v.stencil_ptr)
            and np.array_equal(u.stencil_nodes, v.stencil_nodes))


def _element_matrices(form, u, v, kwargs):
    """``(Du, Dv, blocks)``: the element matrices of a bilinear form on two
    natural-neighbour bases that share their functions, made block by block of
    elements (``blocks`` yields ``(e0, e1, off, K)``, element e's matrix, (Dv S) x (Du S)
    row-major, at ``K[off[e]:off[e + 1]]``, at most :data:`ELEMENT_MATRIX_BUDGET` numbers
    a block); None if the form cannot be probed (the generator raises
    :class:`NotProbeable` on its first block then)."""
    if form.dtype != np.float64:
        return None
    Du, dim = _components(u)
    Dv, _ = _components(v)
    S = np.diff(u.stencil_ptr)
    off = np.zeros(S.shape[0] + 1, dtype=np.int64)
    np.cumsum(Du * Dv * S * S, out=off[1:])
    return Du, Dv, _blocks_of_matrices(form, u, kwargs, Du, Dv, dim, off)


def _blocks_of_matrices(form, u, kwargs, Du, Dv, dim, off):
    """The generator of :func:`_element_matrices`."""
    P, Q = Du * (1 + dim), Dv * (1 + dim)
    pa, pb = (x.ravel() for x in np.meshgrid(np.arange(P), np.arange(Q), indexing="ij"))
    Phi, G = u.values_matrix, u.gradient_entries
    kernel = _contract_bilinear if _parallel(u) else _contract_bilinear_serial
    const_grad = bool(getattr(u, "gradients_constant_per_element", False))
    for b0, b1 in _budget_blocks(off):
        offb = off - off[b0]
        K = np.empty(offb[b1])
        for e0, e1, C, active in probe_coefficients(form, u, kwargs, Du, Dv, pa, pb, b0, b1):
            kernel(e0, e1, u.stencil_ptr, u.stencil_nodes, Phi.indptr, Phi.indices, Phi.data,
                   G, u.dx.shape[1], C, pa[active], pb[active], Du, Dv, offb, K, const_grad)
        yield b0, b1, offb, K


def _budget_blocks(off):
    """Consecutive element ranges whose matrices take at most ``ELEMENT_MATRIX_BUDGET``
    numbers (an element larger than that alone)."""
    ne = off.size - 1
    b0 = 0
    while b0 < ne:
        b1 = int(np.searchsorted(off, off[b0] + ELEMENT_MATRIX_BUDGET, side="right")) - 1
        b1 = min(ne, max(b1, b0 + 1))
        yield b0, b1
        b0 = b1


def parallel_kernels(basis) -> bool:
    """Whether the kernels of a basis this size run on all threads (``PARALLEL_MIN``)."""
    return _parallel(basis)


def _whole_bilinear(form, u, v, kwargs):
    """COO data of a bilinear form on two natural-neighbour bases that share
    their functions, without groups; None if the form cannot be probed."""
    if form.dtype == np.float64 and getattr(u, "gradients_constant_per_element", False):
        Du, dim = _components(u)
        Dv, _ = _components(v)
        chunks = _gradient_chunks(form, u, kwargs, Du, Dv, dim)
        try:
            return sum_coo_gradients(u, v, Du, Dv, chunks, parallel=_parallel(u))
        except NotProbeable:
            return None
    out = _element_matrices(form, u, v, kwargs)
    if out is None:
        return None
    try:
        return sum_coo(u, v, *out, parallel=_parallel(u))
    except NotProbeable:
        return None  # take the group road


def _gradient_chunks(form, u, kwargs, Du, Dv, dim):
    """The chunks of :func:`~skfem_nem.basis.summation.sum_coo_gradients` for a form on a
    basis whose gradients are the same at all of an element's points: the gradient pairs'
    coefficients summed over the points (no element matrix), and element matrices of the
    pairs with a value, if the form has any."""
    L = 1 + dim
    pa, pb = (x.ravel() for x in np.meshgrid(np.arange(Du * L), np.arange(Dv * L),
                                             indexing="ij"))
    both = (pa % L > 0) & (pb % L > 0)
    kernel = _contract_bilinear if _parallel(u) else _contract_bilinear_serial
    S = np.diff(u.stencil_ptr)
    for e0, e1, C, active in probe_coefficients(form, u, kwargs, Du, Dv, pa, pb):
        grad = both[active]
        if grad.any():
            yield e0, e1, "gradients", (np.ascontiguousarray(C[grad].sum(axis=2)),
                                        pa[active[grad]], pb[active[grad]])
        if not grad.all():  # (the values on the gradients' pattern: made on first use)
            Phi, G = u.values_matrix, u.gradient_entries
            off = np.zeros(S.shape[0] + 1, dtype=np.int64)
            np.cumsum(Du * Dv * S[e0:e1] ** 2, out=off[e0 + 1:e1 + 1])
            K = np.empty(off[e1])
            kernel(e0, e1, u.stencil_ptr, u.stencil_nodes, Phi.indptr, Phi.indices, Phi.data,
                   G, u.dx.shape[1], np.ascontiguousarray(C[~grad]), pa[active[~grad]],
                   pb[active[~grad]], Du, Dv, off, K, False)
            yield e0, e1, "matrices", (off, K)


def _whole_linear(form, v, kwargs):
    """COO data of a linear form on a natural-neighbour basis, without
    groups; None if the form cannot be probed."""
    if form.dtype != np.float64:
        return None
    Dv, dim = _components(v)
    pb = np.arange(Dv * (1 + dim))
    Phi, G = v.values_matrix, v.gradient_entries
    ptr, sten = v.stencil_ptr, v.stencil_nodes
    nq = v.dx.shape[1]
    off = np.zeros(ptr.shape[0], dtype=np.int64)
    np.cumsum(Dv * np.diff(ptr), out=off[1:])
    rows = np.empty(off[-1], dtype=index_dtype(v.N, 0))
    data = np.empty(off[-1])
    ndv = np.ascontiguousarray(v.function_dofs[:Dv], dtype=np.int64)
    kernel = _contract_linear if _parallel(v) else _contract_linear_serial
    try:
        for e0, e1, C, active in probe_coefficients(form, v, kwargs, Dv, None, pb, None):
            kernel(e0, e1, ptr, sten, Phi.indptr, Phi.indices, Phi.data, G, nq,
                   C, pb[active], Dv, ndv, off, rows, data)
    except NotProbeable:
        return None
    return np.array([rows]), data


def restore_scikit_fem_assembly() -> bool:
    """Put scikit-fem's own ``BilinearForm._assemble`` and
    ``LinearForm._assemble`` back (the next natural-neighbour basis built
    installs the wrappers again), and ``NonlinearForm``'s if wrapped
    (:mod:`skfem_nem.basis.nonlinear`). Returns whether they were installed."""
    global _INSTALLED
    from . import nonlinear
    nonlinear.restore()
    if not _INSTALLED:
        return False
    BilinearForm._assemble, LinearForm._assemble = _SCIKIT_FEM
    _INSTALLED = False
    return True


#: scikit-fem's own assembly methods, as found before the first install
_SCIKIT_FEM = (BilinearForm._assemble, LinearForm._assemble)


def install():
    """Install the assembly wrappers (idempotent). Natural-neighbour bases
    call it when they are built, so importing the package changes nothing
    in scikit-fem; :func:`restore_scikit_fem_assembly` undoes it."""
    global _INSTALLED
    if _INSTALLED:
        return
    _INSTALLED = True

    bil, lin = _SCIKIT_FEM

    def bilinear_assemble(self, ubasis, vbasis=None, **kwargs):
        if vbasis is None:
            vbasis = ubasis
        if not (_is_nn(ubasis) or _is_nn(vbasis)):
            return bil(self, ubasis, vbasis, **kwargs)
        nelems = (ubasis if _is_nn(ubasis) else vbasis).nelems
        shape = (vbasis.N, ubasis.N)
        if WHOLE and _is_nn(ubasis) and _is_nn(vbasis) and _shares_functions(ubasis, vbasis):
            out = _whole_bilinear(self, ubasis, vbasis, dict(kwargs))
            if out is not None:
                return out[0], out[1], shape, None
        rows, data = [], []
        for idx, u, v in _pairs(ubasis, vbasis):
            kw = split_kwargs(kwargs, idx, nelems)
            if PROBE and _stackable(u) and _stackable(v) and _probe_pays(u, v):
                ind, d = _probed_bilinear(self, u, v, kw)
            elif STACK_SIZE > 0 and _stackable(u) and _stackable(v):
                ind, d = _stacked_bilinear(self, u, v, kw)
            else:
                ind, d, _, _ = bil(self, u, v, **kw)
                for b in filter(_stackable, (u, v)):   # one group's fields at a time
                    b.release_fields()
            rows.append(ind)
            data.append(d)
        return np.concatenate(rows, axis=1), np.concatenate(data), shape, None

    def linear_assemble(self, ubasis, vbasis=None, **kwargs):
        if not _is_nn(ubasis):
            return lin(self, ubasis, vbasis, **kwargs)
        shape = (ubasis.N,)
        if WHOLE:
            out = _whole_linear(self, ubasis, dict(kwargs))
            if out is not None:
                return out[0], out[1], shape, None
        rows, data = [], []
        for g in ubasis.groups:
            kw = split_kwargs(kwargs, g.tind, ubasis.nelems)
            if STACK_SIZE > 0:
                ind, d = _stacked_linear(self, g, kw)
            else:
                ind, d, _, _ = lin(self, g, **kw)
            rows.append(ind)
            data.append(d)
        return np.concatenate(rows, axis=1), np.concatenate(data), shape, None

    BilinearForm._assemble = bilinear_assemble
    LinearForm._assemble = linear_assemble
