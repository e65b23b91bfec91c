"""Coefficients of a scikit-fem form read off by calling it on unit fields, and the
element-wise keyword data split and tiled for the calls.

Why a module of its own: the natural-neighbour assembly (:mod:`.assembly`) contracts a
form's coefficients with the stencil functions, and the coefficients come from a concept
of their own. A form linear in the components of (value, gradient) of u and of v is
``sum_ab C_ab(x) u_a v_b``; calling it on unit fields (all of them stacked along the element
axis, one call per chunk of elements) gives each ``C_ab``. A form that never touches its
parameters ``w`` has the same coefficients on every element, proved by calling it once with
a stand-in that raises on any use (:func:`constant_coefficients`).
"""
from __future__ import annotations

import numpy as np
from skfem.assembly.form.form import FormExtraParams
from skfem.element import DiscreteField

__all__ = ["NotProbeable", "constant_coefficients", "probe_coefficients", "split_kwargs",
           "split_value", "tile", "tile_array", "unit_fields"]


def split_value(v, idx, nelems):
    if isinstance(v, tuple):
        return tuple(split_value(x, idx, nelems) for x in v)
    if isinstance(v, DiscreteField):
        if v.ndim >= 2 and v.shape[-2] == nelems:
            return DiscreteField(*[None if a is None else np.asarray(a)[..., idx, :]
                                   for a in v.astuple])
        return v
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[-2] == nelems:
        return v[..., idx, :]
    return v


def split_kwargs(kwargs, idx, nelems):
    return {k: split_value(v, idx, nelems) for k, v in kwargs.items()}


def tile(v, reps, nelems):
    """Repeat element-wise data ``reps`` times along the element axis."""
    if isinstance(v, tuple):
        return tuple(tile(x, reps, nelems) for x in v)
    if isinstance(v, DiscreteField):
        if v.ndim >= 2 and v.shape[-2] == nelems:
            return DiscreteField(*[None if x is None else tile_array(np.asarray(x), reps)
                                   for x in v.astuple])
        return v
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[-2] == nelems:
        return tile_array(v, reps)
    return v


def tile_array(x, reps):
    sh = x.shape
    return np.broadcast_to(x[..., None, :, :], sh[:-2] + (reps,) + sh[-2:]).reshape(
        sh[:-2] + (reps * sh[-2],) + sh[-1:])


def unit_fields(D, dim, reps, ne, nq, which):
    """Unit fields stacked along the element axis: block r (of ``ne``
    elements) of the result is the unit field ``which[r]``, the component
    a = c (1 + dim) + k of (value, gradient) of a D-vector (k = 0) or its
    derivative d/dx_{k-1}. Returns the form argument tuple."""
    val = np.zeros((D, reps, ne, nq))
    grad = np.zeros((D, dim, reps, ne, nq))
    L = 1 + dim
    for r, a in enumerate(which):
        c, k = divmod(int(a), L)
        if k == 0:
            val[c, r] = 1.0
        else:
            grad[c, k - 1, r] = 1.0
    val = val.reshape(D, reps * ne, nq)
    grad = grad.reshape(D, dim, reps * ne, nq)
    if D == 1:
        return (DiscreteField(val[0], grad[0]),)
    return (DiscreteField(val, grad),)


def _chunks(ne, calls, lo=0, hi=None):
    """Ranges of the elements ``lo .. hi - 1`` (default all ``ne``) such that ``calls``
    stacked copies of one make about 65,536 elements per form call."""
    hi = ne if hi is None else hi
    step = max(1, (1 << 16) // max(1, calls))
    return [(e0, min(hi, e0 + step)) for e0 in range(lo, hi, step)]


class _Touched(Exception):
    """The form used ``w``: its coefficients may vary between elements."""


def _touched(self, *args, **kwargs):
    raise _Touched


class _NoParams:
    """Stands in for ``w`` on the first call of a form: any use of it (an
    attribute, a method such as ``w.copy()``, an item, ``in``, ``len``,
    iteration, truth, comparison, arithmetic, conversion) raises
    :class:`_Touched`. A form that returns without touching it computes its
    coefficients from the unit fields alone, which are the same on every
    element: that proves them constant. Anything else is probed element by
    element with the real parameters."""

    __slots__ = ()
    __getattribute__ = __getattr__ = _touched
    __getitem__ = __contains__ = __iter__ = __len__ = __bool__ = _touched
    __eq__ = __ne__ = __lt__ = __le__ = __gt__ = __ge__ = __hash__ = _touched
    __add__ = __radd__ = __sub__ = __rsub__ = __mul__ = __rmul__ = _touched
    __truediv__ = __rtruediv__ = __pow__ = __rpow__ = __neg__ = __matmul__ = _touched
    __array__ = __float__ = __int__ = __index__ = __call__ = _touched
    __repr__ = __str__ = __format__ = _touched


def constant_coefficients(form_fn, Du, Dv, dim, which_u, which_v, nq):
    """The coefficients of a form that does not use ``w``, as (pairs,)
    scalars, from one call on one element; None if the form uses ``w`` (or
    fails, or gives different values at the points)."""
    reps = len(which_u)
    U = unit_fields(Du, dim, reps, 1, nq, which_u)
    try:
        if which_v is None:
            out = form_fn(*U, _NoParams())
        else:
            out = form_fn(*U, *unit_fields(Dv, dim, reps, 1, nq, which_v), _NoParams())
        out = np.broadcast_to(np.asarray(out, dtype=np.float64), (reps, nq))
    except Exception:  # noqa: BLE001 -- _Touched, or any failure: not provably constant
        return None
    if not (out == out[:, :1]).all():
        return None
    return out[:, 0].copy()


def _probe(form_fn, args_u, args_v, w, ne, reps, nq, dx):
    """Call ``form_fn`` once on stacked unit fields (``args_v`` None for a
    linear form); returns the values times dx, (reps, ne, nq)."""
    W = FormExtraParams({k: tile(x, reps, ne) for k, x in w.items()})
    out = np.asarray(form_fn(*args_u, *args_v, W) if args_v is not None
                     else form_fn(*args_u, W), dtype=np.float64)
    return np.broadcast_to(out, (reps * ne, nq)).reshape(reps, ne, nq) * dx[None]


class NotProbeable(Exception):
    """The form cannot be called on unit fields (e.g. it reads u.hess)."""


def probe_coefficients(form, basis, kwargs, Du, Dv, which_u, which_v, lo=0, hi=None):
    """The form's coefficients, chunk by chunk of elements: yields
    ``(e0, e1, C, active)`` with C (len(active), e1 - e0, nq) the coefficients
    (times dx) of the nonzero unit-field pairs ``active`` (indices into
    ``which_u`` / ``which_v``; ``which_v`` and ``Dv`` None for a linear form,
    whose test function is then the ``which_u`` field). Raises
    :class:`NotProbeable` if the form fails on the first chunk."""
    dim = basis.mesh.dim()
    ne, nq = basis.dx.shape
    given = form._normalize_asm_kwargs(kwargs, basis)
    reps = len(which_u)
    const = constant_coefficients(form.form, Du, Dv, dim, which_u, which_v, nq)
    # the points' coordinates only for a form that reads w (1.4 ms of a 3D Laplacian's
    # 90 at 1,000 nodes)
    w = given if const is not None else {**basis.default_parameters(), **given}
    fields = {}
    for e0, e1 in _chunks(ne, 1 if const is not None else reps, lo, hi):
        if const is not None:
            active = np.flatnonzero(const)
            yield e0, e1, const[active, None, None] * basis.dx[None, e0:e1], active
            continue
        n = e1 - e0
        if n not in fields:
            fields[n] = (unit_fields(Du, dim, reps, n, nq, which_u),
                         None if which_v is None else
                         unit_fields(Dv, dim, reps, n, nq, which_v))
        try:
            C = _probe(form.form, *fields[n], split_kwargs(w, slice(e0, e1), ne), n, reps,
                       nq, basis.dx[e0:e1])
        except (AttributeError, TypeError, IndexError) as err:
            if e0 == 0:
                raise NotProbeable from err
            raise
        active = np.flatnonzero(np.any(C != 0.0, axis=(1, 2)))
        yield e0, e1, np.ascontiguousarray(C[active]), active
