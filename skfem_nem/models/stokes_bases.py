"""The velocity and pressure bases of the Stokes problem on one triangulation.

Kept apart from :mod:`skfem_nem.models.stokes` (forms, assembly, the solve) and from
:mod:`skfem_nem.models.stokes_walls` (conditions on the velocity dofs), which both build
on these spaces: which bases a method pairs (natural-neighbour velocity with bubbles and
P1 pressure, the quadratic natural-neighbour velocity and P1 pressure, Taylor-Hood, or
scikit-fem's MINI), with one quadrature, and the same spaces restricted to a subset of
the triangles for a distributed assembly (:meth:`StokesSpaces.restricted`).

The same methods on a Delaunay ``MeshTet`` (3D) take the tetrahedron's elements: its
quartic bubble (:mod:`skfem_nem.models.bubbles`), P1 and P0 pressures, P2 for Taylor-Hood and
``ElementTetMini``; the natural-neighbour velocity is then the smoothed Box 1 basis, one
smoothing cell per tetrahedron (:class:`~skfem_nem.NaturalNeighbourBasis`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Optional

import numpy as np
from skfem import Basis, MeshTet, MeshTri
from skfem.element import (ElementTetMini, ElementTetP0, ElementTetP1, ElementTetP2,
                           ElementTriMini, ElementTriP0, ElementTriP1, ElementTriP2,
                           ElementVector)
from skfem.refdom import RefTet

from ..basis import (ElementNaturalNeighbour, ElementNaturalNeighbour2, NaturalNeighbourBasis,
                     gauss_rule)
from .bubbles import Bubbles

__all__ = ["StokesSpaces", "stokes_spaces"]


# the elements of each method on triangles and on tetrahedra
_ELEMENTS = {
    "tri": {"p1": ElementTriP1, "p0": ElementTriP0, "p2": ElementTriP2,
            "mini": ElementTriMini},
    "tet": {"p1": ElementTetP1, "p0": ElementTetP0, "p2": ElementTetP2,
            "mini": ElementTetMini},
}

# Gauss orders on tetrahedra: Taylor-Hood's forms (P2 gradients times P2 gradients,
# loads) exactly, and MINI's quartic bubble's gradients exactly
TET_ORDER = {"taylor-hood": 4, "mini": 6}
#: order of the rule carrying the natural-neighbour velocity's values on tetrahedra
#: (scikit-fem's 4 points, as the bubble's condensation integrates on it)
BUBBLE_ORDER = 2


@dataclass
class StokesSpaces:
    """Velocity and pressure bases on one triangulation (same quadrature)."""

    mesh: MeshTri | MeshTet
    method: str
    ubasis: object
    pbasis: Basis
    # the condensed bubbles of method "nem" (models.bubbles), else None
    bubbles: Optional[Bubbles] = None
    # the triangles these bases integrate over (None: all), see restricted()
    elements: Optional[np.ndarray] = None

    @property
    def n_velocity(self) -> int:
        """Number of velocity unknowns."""
        return self.ubasis.N

    @property
    def n_pressure(self) -> int:
        """Number of pressure unknowns."""
        return self.pbasis.N

    @property
    def dim(self) -> int:
        """Space dimension (2 on triangles, 3 on tetrahedra)."""
        return self.mesh.dim()

    @property
    def stabilised(self) -> bool:
        """True where the pressure projection stabilisation is used."""
        return self.method == "nem-projection"

    @cached_property
    def p0basis(self) -> Basis:
        """The piecewise-constant basis on the pressure's quadrature (the projection
        stabilisation's): built on first use, as only ``"nem-projection"`` reads it."""
        on = {} if self.elements is None else {"elements": self.elements}
        tet = isinstance(self.mesh, MeshTet)
        p0 = Basis(self.mesh, _ELEMENTS["tet" if tet else "tri"]["p0"](),
                   quadrature=self.pbasis.quadrature, **on)
        if tet:
            _zero_flat_gradients(p0)
        return p0

    @property
    def quadrature_points(self) -> np.ndarray:
        """Global coordinates of the quadrature points, (dim, ne, nq)."""
        return np.asarray(self.pbasis.global_coordinates())

    def restricted(self, elements: np.ndarray) -> "StokesSpaces":
        """The same spaces (same dofs, quadrature and integration) integrating over
        the triangles ``elements`` only: :func:`assemble_stokes` on them gives those
        triangles' share of every block, and the shares of a partition of the
        triangles add up to the whole system (distributed assembly). Coefficients
        given at the quadrature points of all triangles are taken at these."""
        elements = _subset(self.mesh, elements)
        if self.elements is not None:
            raise ValueError("these spaces are already restricted: restrict the whole ones")
        quad = self.pbasis.quadrature
        tet = isinstance(self.mesh, MeshTet)

        def sub(basis):
            if basis is None or isinstance(basis, NaturalNeighbourBasis):
                return None if basis is None else basis.with_elements(elements)
            out = basis.restricted(elements) if isinstance(basis, Bubbles) else \
                Basis(self.mesh, basis.elem, quadrature=quad, elements=elements)
            if tet:
                _zero_flat_gradients(out.basis if isinstance(out, Bubbles) else out)
            return out

        return StokesSpaces(self.mesh, self.method, sub(self.ubasis), sub(self.pbasis),
                            sub(self.bubbles), elements)


def stokes_spaces(mesh: MeshTri | MeshTet, method: str = "nem", npoints: Optional[int] = None,
                  coordinates: str = "sibson", integration: Optional[str] = None,
                  elements=None) -> StokesSpaces:
    """Velocity/pressure bases for :func:`solve_stokes`.

    Parameters
    ----------
    mesh
        A Delaunay ``MeshTri`` or ``MeshTet`` (build it with
        :func:`skfem_nem.delaunay_mesh`).
    method
        ``"nem"`` (natural-neighbour velocity with bubbles, P1 pressure), ``"nem2"``
        (quadratic natural-neighbour velocity, ``ElementNaturalNeighbour2``: P2's
        unknowns and rates, P1 pressure, inf-sup stable without bubbles; fixed meshes:
        its functions are not updated locally; triangles only), ``"taylor-hood"`` (P2
        velocity, P1 pressure) or ``"mini"`` (scikit-fem's MINI: P1 velocity with a
        bubble, P1 pressure, nothing condensed; a baseline).
    npoints
        Gauss points per triangle (1, 3, 4, 6, 7, 12, 13). Natural-neighbour
        velocities: ``None`` (default) integrates them consistently by
        gradient smoothing (:mod:`skfem_nem.basis.smoothing`; 3 points per
        triangle, one per smoothing cell; quadratic: linear smoothed gradients per
        triangle, :mod:`skfem_nem.basis.smoothing_quadratic`); a number asks for Gauss
        quadrature of their gradients with that rule. Taylor-Hood: default 6, which
        integrates its forms exactly. On tetrahedra only ``None``: the smoothed
        natural-neighbour velocity takes 4 points per tetrahedron, Taylor-Hood and MINI
        Gauss rules that integrate their forms exactly.
    coordinates
        ``"sibson"`` or ``"laplace"`` (NEM only).
    integration
        ``"smoothed"`` or ``"gauss"`` for the natural-neighbour velocity (see
        :class:`~skfem_nem.NaturalNeighbourBasis`); ``None`` follows
        ``npoints``. Not an option of Taylor-Hood or MINI.
    elements
        ``None`` (default: all the cells), cell indices, or ``"owned"``: this MPI rank's
        part of the cells (:func:`skfem_nem.parallel.owned_elements`; all of them on one
        rank). The spaces are then built on those cells alone, nothing is computed or held
        for the others, and they are what :meth:`StokesSpaces.restricted` gives of the
        whole spaces, to round-off: this rank's share of a distributed solve
        (``solve_stokes(..., solver="petsc")``, the ranks' cells a partition of the mesh).
    """
    tet = isinstance(mesh, MeshTet)
    method = _checked_method(mesh, method, npoints)
    el = _ELEMENTS["tet" if tet else "tri"]
    elements = _cells(mesh, elements)
    on = {} if elements is None else {"elements": elements}
    bb = None
    if method.startswith("nem"):
        elem = ElementNaturalNeighbour2() if method == "nem2" else ElementNaturalNeighbour()
        # tetrahedra: values at scikit-fem's 4-point rule, where the bubble's gradient
        # is not zero (it is at the default points, the vertices and the centroid)
        smoothed = tet and integration in (None, "smoothed")
        ub = NaturalNeighbourBasis(mesh, ElementVector(elem, mesh.dim()), npoints=npoints,
                                   coordinates=coordinates,
                                   integration="smoothed" if smoothed else integration,
                                   intorder=BUBBLE_ORDER if smoothed else None, **on)
        quad = ub.quadrature
        if method == "nem":
            bb = Bubbles(mesh, quad, elements)
    else:
        if integration not in (None, "gauss"):
            raise ValueError(f"integration={integration!r} is an option of the "
                             f"natural-neighbour velocity; "
                             f"{'Taylor-Hood' if method == 'taylor-hood' else 'MINI'} "
                             f"uses Gauss quadrature")
        if tet:
            quad = gauss_rule(intorder=TET_ORDER[method], refdom=RefTet)
        else:
            quad = gauss_rule(6 if npoints is None else npoints)
        ub = Basis(mesh, ElementVector(el["p2" if method == "taylor-hood" else "mini"]()),
                   quadrature=quad, **on)
    pb = Basis(mesh, el["p1"](), quadrature=quad, **on)
    if tet:
        for b in (ub, pb, None if bb is None else bb.basis):
            _zero_flat_gradients(b)
    return StokesSpaces(mesh, method, ub, pb, bb, elements)


def _checked_method(mesh, method: str, npoints) -> str:
    """The method's name (``"th"`` is Taylor-Hood), after checking the mesh, the method and
    ``npoints`` (``ValueError`` naming what is wrong)."""
    tet = isinstance(mesh, MeshTet)
    if not (tet or isinstance(mesh, MeshTri)):
        raise ValueError(f"mesh must be a Delaunay MeshTri or MeshTet, got "
                         f"{type(mesh).__name__}")
    method = "taylor-hood" if method == "th" else method
    if method not in ("nem", "nem-projection", "nem2", "taylor-hood", "mini"):
        raise ValueError(f"method must be 'nem', 'nem-projection', 'nem2', 'taylor-hood' "
                         f"or 'mini', got {method!r}")
    if tet and npoints is not None:
        raise ValueError(f"npoints={npoints!r} chooses a triangle rule; on tetrahedra "
                         f"leave it None (each method takes its own rule)")
    if tet and method == "nem2":
        raise ValueError("method 'nem2' (quadratic natural neighbours) is built on "
                         "triangles only; on tetrahedra use 'nem' or 'taylor-hood'")
    return method


def _cells(mesh, elements) -> Optional[np.ndarray]:
    """The cells of ``stokes_spaces(..., elements=...)``: None (all), or sorted indices
    (``"owned"``: this MPI rank's part, None on one rank)."""
    if isinstance(elements, str):
        if elements != "owned":
            raise ValueError(f"elements must be None, cell indices or 'owned', got "
                             f"{elements!r}")
        from ..parallel.petsc import owned_elements
        elements = owned_elements(mesh)
    if elements is None:
        return None
    return _subset(mesh, elements)


def _subset(mesh, elements) -> np.ndarray:
    """``elements`` as sorted unique cell indices; ``ValueError`` unless a non-empty
    subset of the mesh's cells."""
    elements = np.unique(np.asarray(elements, dtype=np.int64))
    if elements.size == 0 or elements[0] < 0 or elements[-1] >= mesh.nelements:
        cells = "tetrahedra" if mesh.dim() == 3 else "triangles"
        raise ValueError(f"elements must be a non-empty subset of the "
                         f"{mesh.nelements} {cells}, got {elements.size} index(es)"
                         f" in [{elements.min(initial=0)}, {elements.max(initial=0)}]")
    return elements


def _zero_flat_gradients(basis) -> None:
    """Gradients 0 on the flat tetrahedra of ``basis`` (zero volume: a mesh of Qhull's
    tetrahedra has them between co-spherical or co-planar nodes), where scikit-fem's inverse
    mapping gives NaN: they carry no weight, and 0 times NaN would spoil the assembled sums."""
    if basis is None or isinstance(basis, NaturalNeighbourBasis) or \
            not hasattr(basis, "basis") or not hasattr(basis, "dx"):
        # (the natural-neighbour gradients are zero there already, and reading its
        # ``basis`` would build the dense per-element arrays assembly never needs)
        return
    flat = np.flatnonzero(~(np.asarray(basis.dx).sum(axis=-1) > 0))
    if flat.size == 0:
        return
    for fields in basis.basis:
        for field in fields:
            grad = getattr(field, "grad", None)
            # (constant fields, such as P0's zero gradient, are broadcast: nothing to do)
            if isinstance(grad, np.ndarray) and grad.ndim >= 2 and \
                    grad.shape[-2] == basis.dx.shape[0] and grad.flags.writeable:
                grad[..., flat, :] = 0.0
