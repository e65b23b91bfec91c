"""Teach scikit-fem's forms to assemble over natural-neighbour bases.

A :class:`~skfem_nem.NaturalNeighbourBasis` is a set of groups of triangles
with equal stencil size; each group is an ordinary scikit-fem basis. The
wrappers installed here make ``BilinearForm``, ``LinearForm`` and
``Functional`` (and therefore ``asm``) loop over those groups and concatenate
their COO contributions, so user code is unchanged. Forms on ordinary bases
take scikit-fem's own code path untouched.

Keyword arguments are split with the groups: dof vectors are interpolated by
each group, arrays and ``DiscreteField`` objects defined over all elements
(shape ``(..., nelems, nq)``) are restricted to the group's elements.
"""
from __future__ import annotations

import numpy as np
from skfem.assembly import CellBasis
from skfem.assembly.form import BilinearForm, Functional, LinearForm
from skfem.assembly.form.form import FormExtraParams
from skfem.element import DiscreteField, ElementVector

_INSTALLED = False
#: element-pairs evaluated per form call in the stacked assembly
STACK_SIZE = 1 << 16
#: assemble natural-neighbour pairs from the form's coefficients (probed on
#: unit fields) instead of calling the form on stacked pairs
PROBE = True


def _is_nn(basis) -> bool:
    return getattr(basis, "groups", None) is not None and hasattr(basis, "stencil_sizes")


def _split_value(v, idx, nelems):
    if isinstance(v, tuple):
        return tuple(_split_value(x, idx, nelems) for x in v)
    if isinstance(v, DiscreteField):
        if v.ndim >= 2 and v.shape[-2] == nelems:
            return DiscreteField(*[None if a is None else np.asarray(a)[..., idx, :]
                                   for a in v.astuple])
        return v
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[-2] == nelems:
        return v[..., idx, :]
    return v


def _split_kwargs(kwargs, idx, nelems):
    return {k: _split_value(v, idx, nelems) for k, v in kwargs.items()}


def _partner(basis, nn, idx, key):
    """``basis`` restricted to the elements ``idx`` of the NEM basis ``nn``."""
    if _is_nn(basis):
        return basis._restricted(idx, key)
    if isinstance(basis, CellBasis):
        if basis.tind is not None or basis.nelems != nn.nelems:
            raise ValueError("a CellBasis mixed with a natural-neighbour basis must live "
                             "on all elements of the same mesh")
        if basis.X.shape[-1] != nn.X.shape[-1] or not np.allclose(basis.X, nn.X):
            raise ValueError("quadrature mismatch: build the CellBasis with "
                             "quadrature=nn_basis.quadrature")
        cache = nn.__dict__.setdefault("_partners", {})
        k = (id(basis), key)
        if k not in cache:
            cache[k] = (basis, basis.with_elements(idx))
        return cache[k][1]
    raise TypeError(f"cannot mix {type(basis).__name__} with a natural-neighbour basis")


def _pairs(ubasis, vbasis):
    """Yield (element indices, u group, v group) covering all elements."""
    nn = ubasis if _is_nn(ubasis) else vbasis
    if _is_nn(ubasis) and _is_nn(vbasis) and ubasis is not vbasis:
        if ubasis.nelems != vbasis.nelems:
            raise ValueError("trial and test natural-neighbour bases live on different "
                             "element sets")
        key = ubasis.stencil_sizes.astype(np.int64) * 100000 + vbasis.stencil_sizes
        order = np.argsort(key, kind="stable")
        bounds = np.flatnonzero(np.diff(key[order])) + 1
        for idx in np.split(order, bounds):
            k = int(key[idx[0]])
            yield idx, ubasis._restricted(idx, ("pair", k)), vbasis._restricted(idx, ("pair", k))
        return
    for g in nn.groups:
        idx = g.tind
        u = g if ubasis is nn else _partner(ubasis, nn, idx, ("group", len(g.basis)))
        v = g if vbasis is nn else _partner(vbasis, nn, idx, ("group", len(g.basis)))
        yield idx, u, v


def _tile(v, reps, nelems):
    """Repeat element-wise data ``reps`` times along the element axis."""
    if isinstance(v, tuple):
        return tuple(_tile(x, reps, nelems) for x in v)
    if isinstance(v, DiscreteField):
        if v.ndim >= 2 and v.shape[-2] == nelems:
            return DiscreteField(*[None if x is None else _tile_array(np.asarray(x), reps)
                                   for x in v.astuple])
        return v
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[-2] == nelems:
        return _tile_array(v, reps)
    return v


def _tile_array(x, reps):
    sh = x.shape
    return np.broadcast_to(x[..., None, :, :], sh[:-2] + (reps,) + sh[-2:]).reshape(
        sh[:-2] + (reps * sh[-2],) + sh[-1:])


def _stackable(b):
    return hasattr(b, "stacked") and hasattr(b, "_raw")


def _probes(g, ne, nq):
    """Unit fields, one per scalar component of (value, gradient) of the
    element of group basis g: (D, 1 + dim) of them for a D-vector element."""
    dim = g._raw[1].shape[0]
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
    dim = u._raw[1].shape[0]
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
    Pu = np.concatenate([u._raw[0][None], u._raw[1]])   # (1 + dim, S_u, ne, nq)
    Pv = np.concatenate([v._raw[0][None], v._raw[1]])
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
        W = FormExtraParams({k: _tile(x, reps, ne) for k, x in w.items()})
        dx = _tile_array(u.dx, reps)
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
        W = FormExtraParams({k: _tile(x, reps, ne) for k, x in w.items()})
        data[p0:p1] = form._kernel(V, W, _tile_array(v.dx, reps)).reshape(reps, ne)
    return np.array([v.element_dofs.ravel()]), data.ravel()


def install():
    """Install the group-wise assembly wrappers (idempotent)."""
    global _INSTALLED
    if _INSTALLED:
        return
    _INSTALLED = True

    bil = BilinearForm._assemble
    lin = LinearForm._assemble
    fel = Functional.elemental

    def bilinear_assemble(self, ubasis, vbasis=None, **kwargs):
        if vbasis is None:
            vbasis = ubasis
        if not (_is_nn(ubasis) or _is_nn(vbasis)):
            return bil(self, ubasis, vbasis, **kwargs)
        nelems = (ubasis if _is_nn(ubasis) else vbasis).nelems
        rows, data = [], []
        shape = None
        shape = (vbasis.N, ubasis.N)
        for idx, u, v in _pairs(ubasis, vbasis):
            kw = _split_kwargs(kwargs, idx, nelems)
            if PROBE and _stackable(u) and _stackable(v) and _probe_pays(u, v):
                ind, d = _probed_bilinear(self, u, v, kw)
            elif STACK_SIZE > 0 and _stackable(u) and _stackable(v):
                ind, d = _stacked_bilinear(self, u, v, kw)
            else:
                ind, d, _, _ = bil(self, u, v, **kw)
            rows.append(ind)
            data.append(d)
        return np.concatenate(rows, axis=1), np.concatenate(data), shape, None

    def linear_assemble(self, ubasis, vbasis=None, **kwargs):
        if not _is_nn(ubasis):
            return lin(self, ubasis, vbasis, **kwargs)
        rows, data = [], []
        shape = None
        shape = (ubasis.N,)
        for g in ubasis.groups:
            kw = _split_kwargs(kwargs, g.tind, ubasis.nelems)
            if STACK_SIZE > 0:
                ind, d = _stacked_linear(self, g, kw)
            else:
                ind, d, _, _ = lin(self, g, **kw)
            rows.append(ind)
            data.append(d)
        return np.concatenate(rows, axis=1), np.concatenate(data), shape, None

    def functional_elemental(self, v, **kwargs):
        if not _is_nn(v):
            return fel(self, v, **kwargs)
        out = None
        for g in v.groups:
            r = fel(self, g, **_split_kwargs(kwargs, g.tind, v.nelems))
            if out is None:
                out = np.zeros((v.nelems,) + np.shape(r)[1:], dtype=np.asarray(r).dtype)
            out[g.tind] = r
        return out

    BilinearForm._assemble = bilinear_assemble
    LinearForm._assemble = linear_assemble
    Functional.elemental = functional_elemental
