"""scikit-fem's ``NonlinearForm`` (``skfem.autodiff``, with JAX) on natural-neighbour bases.

A ``NonlinearForm`` linearises an energy or a residual with JAX and assembles the Jacobian
and the right-hand side over one basis with a fixed number of local functions. A
natural-neighbour basis has one per group of triangles of equal stencil size
(``basis.groups``), each an ordinary basis: the wrapper installed here assembles the form
over every group (the point of linearisation, a dof vector, interpolated by the group;
element-wise keyword arguments restricted to its triangles) and sums the groups' COO data.
Forms on other bases take scikit-fem's own code, untouched.

The wrapper is installed with the assembly wrappers when a natural-neighbour basis is built,
if ``skfem.autodiff`` has been imported by then (importing it needs JAX, an optional
dependency of scikit-fem): import ``skfem.autodiff`` before building the basis.
"""
from __future__ import annotations

import sys

import numpy as np

from .assembly import StencilBasis

__all__ = ["install", "restore"]

#: scikit-fem's own NonlinearForm._assemble, once wrapped
_ORIGINAL = {}


def _split(v, idx, nelems):
    """Element-wise arrays (..., nelems, nq) restricted to the elements ``idx``."""
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[-2] == nelems:
        return v[..., idx, :]
    return v


def install() -> bool:
    """Wrap ``NonlinearForm._assemble`` (idempotent); returns whether it is wrapped (only
    once ``skfem.autodiff`` is imported)."""
    module = sys.modules.get("skfem.autodiff.form") or sys.modules.get("skfem.autodiff")
    form = getattr(module, "NonlinearForm", None)
    if form is None:
        return False
    if "assemble" in _ORIGINAL:
        return True
    original = _ORIGINAL["assemble"] = form._assemble
    _ORIGINAL["class"] = form

    def nonlinear_assemble(self, basis, x=None, **kwargs):
        if not isinstance(basis, StencilBasis):
            return original(self, basis, x=x, **kwargs)
        if x is not None and not isinstance(x, np.ndarray):
            raise TypeError("NonlinearForm on a natural-neighbour basis: pass x as a dof "
                            f"vector (got {type(x).__name__})")
        parts = []
        for g in basis.groups:
            kw = {k: _split(v, g.tind, basis.nelems) for k, v in kwargs.items()}
            parts.append(original(self, g, x=x, **kw))
        mat = tuple(p[0] for p in parts)
        vec = tuple(p[1] for p in parts)
        return ((np.concatenate([m[0] for m in mat], axis=1),
                 np.concatenate([m[1] for m in mat]), (basis.N, basis.N), None),
                (np.concatenate([v[0] for v in vec], axis=1),
                 np.concatenate([v[1] for v in vec]), (basis.N,), None))

    form._assemble = nonlinear_assemble
    return True


def restore() -> bool:
    """Put scikit-fem's own ``NonlinearForm._assemble`` back; returns whether it was
    wrapped."""
    if "assemble" not in _ORIGINAL:
        return False
    _ORIGINAL["class"]._assemble = _ORIGINAL.pop("assemble")
    del _ORIGINAL["class"]
    return True
