"""The velocity and pressure bases of the Stokes problem on one triangulation.

Kept apart from :mod:`skfem_nem.models.stokes` (forms, assembly, the solve) and from
:mod:`skfem_nem.models.stokes_walls` (conditions on the velocity dofs), which both build
on these spaces: which bases a method pairs (natural-neighbour velocity with bubbles and
P1 pressure, the quadratic natural-neighbour velocity and P1 pressure, or Taylor-Hood),
with one quadrature, and the same spaces restricted to a subset of the triangles for a
distributed assembly (:meth:`StokesSpaces.restricted`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from skfem import Basis, MeshTri
from skfem.element import ElementH1, ElementTriP0, ElementTriP1, ElementTriP2, ElementVector
from skfem.refdom import RefTri

from ..basis import (ElementNaturalNeighbour, ElementNaturalNeighbour2, NaturalNeighbourBasis,
                     gauss_rule)

__all__ = ["ElementTriBubble", "StokesSpaces", "stokes_spaces"]


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


@dataclass
class StokesSpaces:
    """Velocity and pressure bases on one triangulation (same quadrature)."""

    mesh: MeshTri
    method: str
    ubasis: object
    pbasis: Basis
    p0basis: Basis
    bbasis: Optional[Basis] = None
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
    def stabilised(self) -> bool:
        """True where the pressure projection stabilisation is used."""
        return self.method == "nem-projection"

    @property
    def quadrature_points(self) -> np.ndarray:
        """Global coordinates of the quadrature points, (2, ne, nq)."""
        return np.asarray(self.pbasis.global_coordinates())

    def restricted(self, elements: np.ndarray) -> "StokesSpaces":
        """The same spaces (same dofs, quadrature and integration) integrating over
        the triangles ``elements`` only: :func:`assemble_stokes` on them gives those
        triangles' share of every block, and the shares of a partition of the
        triangles add up to the whole system (distributed assembly). Coefficients
        given at the quadrature points of all triangles are taken at these."""
        elements = np.unique(np.asarray(elements, dtype=np.int64))
        if elements.size == 0 or elements[0] < 0 or elements[-1] >= self.mesh.nelements:
            raise ValueError(f"elements must be a non-empty subset of the "
                             f"{self.mesh.nelements} triangles, got {elements.size} index(es)"
                             f" in [{elements.min(initial=0)}, {elements.max(initial=0)}]")
        if self.elements is not None:
            raise ValueError("these spaces are already restricted: restrict the whole ones")
        quad = self.pbasis.quadrature

        def sub(basis):
            if basis is None:
                return None
            if isinstance(basis, NaturalNeighbourBasis):
                return basis.with_elements(elements)
            return Basis(self.mesh, basis.elem, quadrature=quad, elements=elements)

        return StokesSpaces(self.mesh, self.method, sub(self.ubasis), sub(self.pbasis),
                            sub(self.p0basis), sub(self.bbasis), elements)


def stokes_spaces(mesh: MeshTri, method: str = "nem", npoints: Optional[int] = None,
                  coordinates: str = "sibson", integration: Optional[str] = None) -> StokesSpaces:
    """Velocity/pressure bases for :func:`solve_stokes`.

    Parameters
    ----------
    mesh
        A Delaunay ``MeshTri`` (build it with :func:`skfem_nem.delaunay_mesh`).
    method
        ``"nem"`` (natural-neighbour velocity with bubbles, P1 pressure), ``"nem2"``
        (quadratic natural-neighbour velocity, ``ElementNaturalNeighbour2``: P2's
        unknowns and rates, P1 pressure, inf-sup stable without bubbles; fixed meshes:
        its functions are not updated locally) or ``"taylor-hood"`` (P2 velocity, P1
        pressure).
    npoints
        Gauss points per triangle (1, 3, 4, 6, 7, 12, 13). Natural-neighbour
        velocities: ``None`` (default) integrates them consistently by
        gradient smoothing (:mod:`skfem_nem.basis.smoothing`; 3 points per
        triangle, one per smoothing cell; quadratic: linear smoothed gradients per
        triangle, :mod:`skfem_nem.basis.smoothing_quadratic`); a number asks for Gauss
        quadrature of their gradients with that rule. Taylor-Hood: default 6, which
        integrates its forms exactly.
    coordinates
        ``"sibson"`` or ``"laplace"`` (NEM only).
    integration
        ``"smoothed"`` or ``"gauss"`` for the natural-neighbour velocity (see
        :class:`~skfem_nem.NaturalNeighbourBasis`); ``None`` follows
        ``npoints``. Not an option of Taylor-Hood.
    """
    bb = None
    if method in ("nem", "nem-projection"):
        ub = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()),
                                   npoints=npoints, coordinates=coordinates,
                                   integration=integration)
        quad = ub.quadrature
        if method == "nem":
            bb = Basis(mesh, ElementVector(ElementTriBubble()), quadrature=quad)
    elif method == "nem2":
        ub = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()),
                                   npoints=npoints, coordinates=coordinates,
                                   integration=integration)
        quad = ub.quadrature
    elif method in ("taylor-hood", "th"):
        method = "taylor-hood"
        if integration not in (None, "gauss"):
            raise ValueError(f"integration={integration!r} is an option of the "
                             f"natural-neighbour velocity; Taylor-Hood uses Gauss quadrature")
        quad = gauss_rule(6 if npoints is None else npoints)
        ub = Basis(mesh, ElementVector(ElementTriP2()), quadrature=quad)
    else:
        raise ValueError(f"method must be 'nem', 'nem-projection', 'nem2' or "
                         f"'taylor-hood', got {method!r}")
    pb = Basis(mesh, ElementTriP1(), quadrature=quad)
    p0 = Basis(mesh, ElementTriP0(), quadrature=quad)
    return StokesSpaces(mesh, method, ub, pb, p0, bb)
