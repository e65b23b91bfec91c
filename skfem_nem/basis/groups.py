"""The triangles of one stencil size of a natural-neighbour basis, as one basis.

scikit-fem assembles over bases whose elements all have the same number of local
functions. A natural-neighbour basis has stencils of many sizes, so it splits its
triangles by stencil size into groups (:class:`GroupBasis`); each is an ordinary
basis with a fixed ``Nbfun``, and the assembly sums the groups' contributions
(:mod:`skfem_nem.basis.assembly`).
"""
from __future__ import annotations

import weakref

import numpy as np
from skfem.assembly.basis import AbstractBasis
from skfem.element import DiscreteField, ElementVector

from . import assembly

__all__ = ["GroupBasis", "restrict_field"]


class GroupBasis(AbstractBasis, assembly.StencilGroup):
    """The triangles of one stencil size: an ordinary basis with fixed Nbfun.

    Built by :class:`~skfem_nem.basis.NaturalNeighbourBasis`; users never see it, scikit-fem's
    form kernels do. It refers to its basis weakly: a reference back would make a
    cycle, whose arrays (every stencil's values and gradients, hundreds of megabytes
    at 10^5 nodes) Python frees only at its next cyclic collection, steps later.
    """

    def __init__(self, parent, elems, stencils, V, G):
        self._parent = weakref.ref(parent)
        self.mesh = parent.mesh
        self.elem = parent.elem
        self.mapping = parent.mapping
        self.dofs = parent.dofs
        self.X, self.W = parent.X, parent.W
        self.tind = elems
        self.nelems = elems.shape[0]
        self.dx = parent.dx[elems]
        S = stencils.shape[0]
        if isinstance(self.elem, ElementVector):
            dim = self.elem.dim
            nd = parent.function_dofs
            self._element_dofs = np.empty((dim * S, self.nelems), dtype=np.int64)
            for j in range(S):
                for c in range(dim):
                    self._element_dofs[dim * j + c] = nd[c, stencils[j]]
        else:
            self._element_dofs = parent.function_dofs[0][stencils]
        self.Nbfun = self._element_dofs.shape[0]
        self.stencil_values = (V, G)  # (V, G) arrays for the stacked assembly
        self._basis = None

    @property
    def basis(self):
        """scikit-fem's local functions, one-tuples of DiscreteField, built on first use:
        the stacked assembly works from :attr:`stencil_values` alone, and for a vector
        element these fields, mostly zeros, take four times their memory."""
        if self._basis is None:
            V, G = self.stencil_values
            if isinstance(self.elem, ElementVector):
                self._basis = [(self._component_field(j, c),)
                               for j in range(V.shape[0]) for c in range(self.elem.dim)]
            else:
                self._basis = [(DiscreteField(V[j], G[:, j]),) for j in range(V.shape[0])]
        return self._basis

    def release_fields(self) -> None:
        """Drop the fields of :attr:`basis` (rebuilt on next use)."""
        self._basis = None

    def _component_field(self, j, c):
        """Component c of the vector function of stencil node j."""
        V, G = self.stencil_values
        dim = self.elem.dim
        val = np.zeros((dim,) + V.shape[1:])
        val[c] = V[j]
        grad = np.zeros((dim, dim) + V.shape[1:])
        grad[c] = G[:, j]
        return DiscreteField(val, grad)

    def stacked(self, idx):
        """Local functions ``idx`` (P,) stacked along the element axis: a
        one-tuple of DiscreteField over P * nelems elements (pair-major)."""
        V, G = self.stencil_values
        nq = V.shape[2]
        if isinstance(self.elem, ElementVector):
            dim = self.elem.dim
            j, c = idx // dim, idx % dim
            val = np.zeros((dim, idx.size) + V.shape[1:])
            grad = np.zeros((dim, dim, idx.size) + V.shape[1:])
            for comp in range(dim):
                sel = c == comp
                val[comp, sel] = V[j[sel]]
                js = j[sel]
                for g in range(dim):
                    grad[comp, g, sel] = G[g, js]
            return (DiscreteField(val.reshape(dim, -1, nq), grad.reshape(dim, dim, -1, nq)),)
        return (DiscreteField(V[idx].reshape(-1, nq), G[:, idx].reshape(G.shape[0], -1, nq)),)

    @property
    def parent(self):
        """The basis whose triangles of one stencil size these are."""
        parent = self._parent()
        if parent is None:
            raise ReferenceError("a group of a NaturalNeighbourBasis outlived its basis")
        return parent

    @property
    def element_dofs(self):
        return self._element_dofs

    def default_parameters(self):
        x = self.parent.global_coordinates()
        h = self.parent.mesh_parameters()
        return {"x": restrict_field(x, self.tind), "h": restrict_field(h, self.tind)}

    def global_coordinates(self):
        return restrict_field(self.parent.global_coordinates(), self.tind)


def restrict_field(f, idx):
    """Restrict a DiscreteField (or tuple of them) over elements to ``idx``."""
    if isinstance(f, tuple):
        return tuple(restrict_field(g, idx) for g in f)
    if isinstance(f, DiscreteField):
        return DiscreteField(*[None if a is None else np.asarray(a)[..., idx, :]
                               for a in f.astuple])
    return f
