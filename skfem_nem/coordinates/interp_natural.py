"""Natural-neighbour interpolants of scattered data: Sibson's and Laplace's (C0 blends).

``f(x) = sum_i phi_i(x) f_i`` with the Sibson or Laplace coordinates ``phi_i`` of
:func:`~skfem_nem.coordinates.natural_neighbour_coordinates`, and its exact gradient
``sum_i grad phi_i(x) f_i`` from the coordinates' exact derivatives. Sibson's interpolant is
C1 except at the data points (where it has cone-like kinks), Laplace's is C0 across the
Delaunay circumcircles. The gradient is undefined at the data points and on the hull (NaN
there).
"""
from __future__ import annotations

import numpy as np

from .dispatch import natural_neighbour_coordinates

__all__ = ["BlendedInterpolant", "NaturalInterpolant", "coordinates_of", "row_sums"]


def row_sums(indptr, a):
    """Sums of the entries a (nnz, ...) over the CSR rows (no row is empty)."""
    return np.add.reduceat(a, indptr[:-1], axis=0)


class BlendedInterpolant:
    """The state of a C1 interpolant: the triangulation, the data points p (n, d), their
    ``values`` (n, K) and nodal ``gradients`` (n, K, d), blended by the coordinates."""

    def __init__(self, triangulation, p, values, gradients):
        self.triangulation = triangulation
        self.p = p
        self.values = values
        self.gradients = gradients


def coordinates_of(triangulation, q, gradient: bool, kind: str = "sibson"):
    """Coordinates (and with ``gradient`` their derivatives, NaN rows where undefined) of the
    points q inside the hull; ``triangulation`` is a :class:`~skfem_nem.Triangulation` (2D,
    area method) or a ``scipy.spatial.Delaunay`` (3D, Lasserre's method)."""
    return natural_neighbour_coordinates(triangulation, q, gradient=gradient, kind=kind,
                                         undefined="nan")


class NaturalInterpolant:
    """``sum_i phi_i(x) values_i`` with the ``kind`` ("sibson" or "laplace") coordinates."""

    def __init__(self, triangulation, values, kind: str):
        self.triangulation = triangulation
        self.values = values
        self.kind = kind

    def __call__(self, q, gradient: bool):
        if not gradient:
            return coordinates_of(self.triangulation, q, False, self.kind) @ self.values, None
        Phi, dPhi = coordinates_of(self.triangulation, q, True, self.kind)
        grad = np.stack([D @ self.values for D in dPhi], axis=-1)
        return Phi @ self.values, grad
