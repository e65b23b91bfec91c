"""The bubbles of the natural-neighbour Stokes velocity, held as one scalar function.

Method ``"nem"`` enriches the velocity with one bubble per cell and component: the cubic
bubble of a triangle (:class:`ElementTriBubble`), the quartic one of a tetrahedron
(:class:`ElementTetBubble`). They are condensed out cell by cell
(:mod:`skfem_nem.models.condensation`, :mod:`skfem_nem.models.condensation_tet`), which
reads only the scalar bubble's gradient and integral; the divergence, the loads and the
velocity gradient read its components one at a time.

scikit-fem's vector basis ``ElementVector(ElementTetBubble())`` would hold the values and
gradients of all three vector functions of a tetrahedron at every point: 36 numbers a
point, where the scalar bubble has 4. On the 650,000 tetrahedra of a 100,000-node mesh
that is 750 MB against 83 MB. :class:`Bubbles` keeps the scalar basis alone and numbers
the bubbles as the vector basis does (``dim e + c``: cell e, component c). Where a form is
evaluated on them (:meth:`Bubbles.linear`, :meth:`Bubbles.bilinear`) it is given the
vector basis's fields of one component on a slice of cells at a time, so the numbers are
scikit-fem's bit for bit and the vector basis' arrays are never all made.
"""
from __future__ import annotations

from typing import Iterator, Optional

import numpy as np
import scipy.sparse as sp
from skfem import Basis, MeshTet
from skfem.assembly.form.form import FormExtraParams
from skfem.element import DiscreteField, ElementH1, ElementVector
from skfem.refdom import RefTet, RefTri

__all__ = ["ElementTriBubble", "ElementTetBubble", "Bubbles"]

#: cells a form is evaluated on at a time: the vector fields of one component then take
#: 12 numbers a point on at most this many cells (25 MB on tetrahedra with 4 points)
CELLS_AT_A_TIME = 65536


class ElementTriBubble(ElementH1):
    """The cubic bubble ``27 x y (1 - x - y)`` alone: one interior dof per
    triangle (the enrichment of the MINI element)."""

    interior_dofs = 1
    dim = 2
    maxdeg = 3
    dofnames = ["b"]
    doflocs = np.array([[1.0 / 3.0, 1.0 / 3.0]])
    refdom = RefTri

    def lbasis(self, X, i):
        x, y = X
        if i != 0:
            self._index_error()
        phi = 27.0 * x * y * (1.0 - x - y)
        dphi = 27.0 * np.array([y * (1.0 - x - y) - x * y, x * (1.0 - x - y) - x * y])
        return phi, dphi


class ElementTetBubble(ElementH1):
    """The quartic bubble ``256 x y z (1 - x - y - z)`` alone: one interior dof per
    tetrahedron (the enrichment of the 3D MINI element)."""

    interior_dofs = 1
    dim = 3
    maxdeg = 4
    dofnames = ["b"]
    doflocs = np.array([[0.25, 0.25, 0.25]])
    refdom = RefTet

    def lbasis(self, X, i):
        x, y, z = X
        if i != 0:
            self._index_error()
        s = 1.0 - x - y - z
        phi = 256.0 * x * y * z * s
        dphi = 256.0 * np.array([y * z * (s - x), x * z * (s - y), x * y * (s - z)])
        return phi, dphi


class Bubbles:
    """One bubble per cell and component on ``mesh`` (a ``MeshTri`` or ``MeshTet``), at
    the points of ``quadrature``, numbered ``dim e + c`` as scikit-fem's
    ``ElementVector`` of the bubble numbers them; ``elements``: the cells integrated over
    (None: all; the numbering stays the whole mesh's).

    >>> from skfem import MeshTri
    >>> from skfem.quadrature import get_quadrature
    >>> from skfem_nem.models.bubbles import Bubbles
    >>> b = Bubbles(MeshTri(), get_quadrature(MeshTri().elem.refdom, 3))
    >>> b.N, b.element_dofs.tolist()
    (4, [[0, 2], [1, 3]])
    """

    def __init__(self, mesh, quadrature, elements: Optional[np.ndarray] = None):
        self.mesh = mesh
        self.element = ElementTetBubble() if isinstance(mesh, MeshTet) else ElementTriBubble()
        self.elements = elements
        extra = {} if elements is None else {"elements": elements}
        #: the scalar bubble's scikit-fem basis (its values and gradients)
        self.basis = Basis(mesh, self.element, quadrature=quadrature, **extra)

    @property
    def dim(self) -> int:
        """Components a bubble has (2 on triangles, 3 on tetrahedra)."""
        return self.mesh.dim()

    @property
    def N(self) -> int:
        """Number of bubble dofs, ``dim`` times the mesh's cells."""
        return self.dim * self.mesh.nelements

    @property
    def dx(self) -> np.ndarray:
        """(ne, nq) quadrature weights times the Jacobian determinants."""
        return self.basis.dx

    @property
    def quadrature(self) -> tuple:
        """The reference points and weights."""
        return self.basis.quadrature

    @property
    def element_dofs(self) -> np.ndarray:
        """(dim, ne) the dofs of each integrated cell's bubbles, ``dim e + c``."""
        tind = self.basis.tind
        cells = np.arange(self.mesh.nelements) if tind is None else np.asarray(tind)
        return self.dim * cells[None] + np.arange(self.dim)[:, None]

    def gradient(self) -> np.ndarray:
        """(dim, ne, nq) the scalar bubble's gradient at the points (C order)."""
        return np.ascontiguousarray(np.asarray(self.basis.basis[0][0].grad))

    def integral(self) -> np.ndarray:
        """(ne,) the quadrature's integral of each cell's bubble (its values at the
        reference points, as scikit-fem's assembly takes them)."""
        phi = self.element.lbasis(self.quadrature[0], 0)[0]
        return (self.dx * phi[None]).sum(axis=1)

    def gradient_of(self, x: np.ndarray) -> np.ndarray:
        """(dim, dim, ne, nq) the gradient ``[i, j] = d u_i / d x_j`` of the bubble field
        with dofs ``x`` (N,) at the points."""
        x = np.asarray(x)
        if x.shape != (self.N,):
            raise ValueError(f"bubble dofs x must have shape ({self.N},), got {x.shape}")
        g = self.gradient()
        return np.stack([x[self.element_dofs[c]][None, :, None] * g for c in range(self.dim)])

    def block_diagonal(self, blocks: np.ndarray) -> sp.csr_matrix:
        """(N, N) CSR of one (dim, dim) block per integrated cell, ``blocks`` (ne, dim,
        dim), on that cell's bubbles (e.g. the inverse of the bubbles' block)."""
        d, bd = self.dim, self.element_dofs.T                  # (ne, dim)
        if blocks.shape != (bd.shape[0], d, d):
            raise ValueError(f"blocks must have shape ({bd.shape[0]}, {d}, {d}), got "
                             f"{blocks.shape}")
        return sp.csr_matrix((blocks.ravel(), (np.repeat(bd, d, axis=1).ravel(),
                                               np.tile(bd, (1, d)).ravel())),
                             shape=(self.N, self.N))

    def vector_basis(self) -> Basis:
        """scikit-fem's basis of the vector bubble on the same cells and points (its
        arrays for all components: for small meshes, e.g. an inf-sup eigenproblem)."""
        extra = {} if self.elements is None else {"elements": self.elements}
        return Basis(self.mesh, ElementVector(self.element, self.dim),
                     quadrature=self.quadrature, **extra)

    def restricted(self, elements: np.ndarray) -> "Bubbles":
        """The same bubbles integrating over the cells ``elements`` only."""
        return Bubbles(self.mesh, self.quadrature, elements)

    def linear(self, form, **w) -> np.ndarray:
        """(N,) scikit-fem's ``form.assemble(vector_basis(), **w)`` for a ``LinearForm``
        whose coefficients ``w`` are numbers or arrays with the cells on their last axis
        but one (at the quadrature points), without the vector basis."""
        out = np.zeros(self.N)
        dofs = self.element_dofs
        for cells in self._slices():
            params = self._params(w, cells)
            dx = self.dx[cells]
            for c in range(self.dim):
                out[dofs[c, cells]] = np.sum(form.form(self._component(c, cells), params) * dx,
                                             axis=1)
        return out

    def bilinear(self, form, vbasis, **w) -> sp.csr_matrix:
        """(vbasis.N, N) scikit-fem's ``form.assemble(vector_basis(), vbasis, **w)`` for a
        ``BilinearForm`` with the bubbles as trial functions and the scalar scikit-fem
        basis ``vbasis`` (same cells and points) as test functions."""
        rows, cols, vals = [], [], []
        dofs, vdofs = self.element_dofs, np.asarray(vbasis.element_dofs)
        for cells in self._slices():
            params = self._params(w, cells)
            dx = self.dx[cells]
            for c in range(self.dim):
                u = self._component(c, cells)
                for j in range(vbasis.Nbfun):
                    v = _cells_of(vbasis.basis[j][0], cells)
                    vals.append(np.sum(form.form(u, v, params) * dx, axis=1))
                    rows.append(vdofs[j, cells])
                    cols.append(dofs[c, cells])
        return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))),
                             shape=(vbasis.N, self.N)).tocsr()

    def _slices(self) -> Iterator[slice]:
        ne = self.dx.shape[0]
        for start in range(0, ne, CELLS_AT_A_TIME):
            yield slice(start, min(start + CELLS_AT_A_TIME, ne))

    def _params(self, w: dict, cells: slice) -> FormExtraParams:
        ne = self.dx.shape[0]
        out = {}
        for key, value in w.items():
            a = np.asarray(value)
            if a.ndim >= 2 and a.shape[-2] == ne:
                a = DiscreteField(a[..., cells, :])
            elif a.ndim != 0:
                raise ValueError(f"coefficient {key!r} must be a number or have the "
                                 f"{ne} cells on its last axis but one, got shape {a.shape}")
            out[key] = a if a.ndim else value
        return FormExtraParams(out)

    def _component(self, c: int, cells: slice) -> DiscreteField:
        """The vector bubble's component-c field on ``cells``, as ElementVector has it."""
        scalar = self.basis.basis[0][0]
        fields = []
        for f in scalar.astuple:
            if f is None:
                fields.append(None)
                continue
            f = np.asarray(f)[..., cells, :]
            tmp = np.zeros((self.dim,) + f.shape)
            tmp[c] = f
            fields.append(tmp)
        return DiscreteField(*fields)


def _cells_of(field: DiscreteField, cells: slice) -> DiscreteField:
    """``field`` (a scikit-fem basis function at the points) on ``cells`` only."""
    return DiscreteField(*(None if f is None else np.asarray(f)[..., cells, :]
                           for f in field.astuple))
