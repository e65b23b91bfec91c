"""Natural-neighbour interpolants of scattered data: Sibson's and Laplace's (C0 blends).

``f(x) = sum_i phi_i(x) f_i`` with the Sibson or Laplace coordinates ``phi_i`` of
:func:`~skfem_nem.coordinates.natural_neighbour_coordinates`, and its exact gradient
``sum_i grad phi_i(x) f_i`` from the coordinates' exact derivatives. Sibson's interpolant is
C1 except at the data points (where it has cone-like kinks), Laplace's is C0 across the
Delaunay circumcircles. The gradient is undefined at the data points and on the hull (NaN
there). Sibson's values (no gradient) of a large 2D batch are evaluated triangle by triangle
instead (:mod:`~skfem_nem.coordinates.interp_scatter`), the queries it flags by the
coordinates.
"""
from __future__ import annotations

import numpy as np

from ..geometry.triangulation import Triangulation
from .dispatch import natural_neighbour_coordinates
from .interp_scatter import SibsonScatter, scatter_applies
from .interp_watson3d import SibsonWatson3D, watson_applies

__all__ = ["BlendedInterpolant", "NaturalInterpolant", "coordinates_of", "row_sums",
           "SCATTER_MIN", "SCATTER_PER_TRIANGLE", "WATSON_MIN"]

# Sibson's values of at least SCATTER_MIN queries, and of at least SCATTER_PER_TRIANGLE per
# triangle near them, go to the scatter (below that its pass over the triangles costs more
# than the per-query gather saves)
SCATTER_MIN = 10_000
SCATTER_PER_TRIANGLE = 0.25
# the scatter's chunks of queries: up to this many bytes of work space (a parallel pass per
# chunk, and one for the flagged queries, cost more than the queries on a busy machine)
SCATTER_BYTES = 1 << 27
# Sibson's values of at least WATSON_MIN 3D queries go to Watson's decomposition (its
# records of the tetrahedra cost about what a few hundred queries by the coordinates do)
WATSON_MIN = 1000


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
    """``sum_i phi_i(x) values_i`` with the ``kind`` ("sibson" or "laplace") coordinates,
    computed ``chunk`` queries at a time (Sibson's values of large 2D batches: scattered)."""

    def __init__(self, triangulation, values, kind: str, chunk: int = 1 << 16):
        self.triangulation = triangulation
        self.values = values
        self.kind = kind
        self.chunk = chunk
        self.scatter = None     # the SibsonScatter, built on the first large batch (2D)
        self.watson = None      # the SibsonWatson3D, likewise (3D)

    def scatters(self, q) -> bool:
        """True if the values at the points q (m, d) are the scatter's (2D) or Watson's
        decomposition's (3D) to evaluate."""
        if self._watson_for(q.shape[0]):
            return True
        return self._scatter_for(q.shape[0]) and \
            q.shape[0] >= SCATTER_PER_TRIANGLE * self.scatter.triangles_near(q)

    def chunk_size(self, m: int) -> int:
        """How many of m queries to pass at a time for their values: more for the scatter."""
        if self._watson_for(m):
            return max(self.chunk, SCATTER_BYTES // self.watson.bytes_per_query)
        if not self._scatter_for(m):
            return self.chunk
        return max(self.chunk, SCATTER_BYTES // self.scatter.bytes_per_query)

    def _scatter_for(self, m: int) -> bool:
        """True if m queries are enough for the scatter and it applies (built here)."""
        tri = self.triangulation
        if self.kind != "sibson" or m < SCATTER_MIN or not isinstance(tri, Triangulation):
            return False
        if self.scatter is None:
            self.scatter = SibsonScatter(tri, self.values) if scatter_applies(tri) else False
        return bool(self.scatter)

    def _watson_for(self, m: int) -> bool:
        """True if m queries are enough for Watson's 3D decomposition and it applies (built
        here, or before for fewer queries)."""
        if self.watson is None:
            if self.kind != "sibson" or m < WATSON_MIN or \
                    not watson_applies(self.triangulation):
                return False
            self.watson = SibsonWatson3D(self.triangulation, self.values)
        return bool(self.watson)

    def __call__(self, q, gradient: bool):
        if not gradient and self.scatters(q):
            v, redo = (self.watson if self.watson else self.scatter)(q)
            if redo.size:
                v[redo] = self.gathered(q[redo])
            return v, None
        if not gradient:
            return self.gathered(q), None
        Phi, dPhi = coordinates_of(self.triangulation, q, True, self.kind)
        grad = np.stack([D @ self.values for D in dPhi], axis=-1)
        return Phi @ self.values, grad

    def gathered(self, q):
        """The values at the points q from their coordinates, ``chunk`` queries at a time."""
        if q.shape[0] <= self.chunk:
            return coordinates_of(self.triangulation, q, False, self.kind) @ self.values
        return np.concatenate([self.gathered(q[i:i + self.chunk])
                               for i in range(0, q.shape[0], self.chunk)])
