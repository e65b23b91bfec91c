"""Scattered-data interpolation in scipy's style on the natural-neighbour coordinates.

:class:`NaturalNeighbourInterpolator` takes the arguments and conventions of
``scipy.interpolate.LinearNDInterpolator``: data points (or a prebuilt triangulation), values
with trailing dimensions, a fill value outside the convex hull, ``rescale``; it is called on
query points of shape (..., d) or on d coordinate arrays, and also gives the exact gradient of
the interpolant. The methods, one module each: Sibson's and Laplace's C0 blends
(:mod:`~skfem_nem.coordinates.interp_natural`), Sibson's and Farin's C1 interpolants
(:mod:`~skfem_nem.coordinates.interp_sibson1`, :mod:`~skfem_nem.coordinates.interp_farin`),
piecewise-linear and nearest-neighbour
interpolation (:mod:`~skfem_nem.coordinates.interp_simplex`); the hull test in
:mod:`~skfem_nem.coordinates.interp_hull`, the input checks in
:mod:`~skfem_nem.coordinates.interp_input`, the gradient estimate of the C1 method in
:mod:`~skfem_nem.coordinates.interp_gradients`.
"""
from __future__ import annotations

import numpy as np

from ..geometry.delaunay_nd import DELAUNAY_TYPES
from ..geometry.triangulation import Triangulation
from .interp_farin import FarinInterpolant
from .interp_gradients import nodal_gradients
from .interp_hull import HullTest
from .interp_input import (check_fill_value, check_gradients, check_values, query_points,
                           triangulated)
from .interp_natural import NaturalInterpolant
from .interp_sibson1 import Sibson1Interpolant
from .interp_simplex import LinearInterpolant, NearestInterpolant

__all__ = ["NaturalNeighbourInterpolator", "METHODS", "natural_neighbour_to_grid"]

# method -> the dimensions it works in
METHODS = {"sibson": (2, 3), "laplace": (2,), "sibson1": (2, 3), "farin": (2, 3),
           "linear": (2, 3), "nearest": (2, 3)}
# methods that blend nodal gradients
C1_METHODS = ("sibson1", "farin")
# the methods that keep the walls of a 3D tetrahedralisation (geometry.walls3d): Sibson's
# values on the regions cut at them (gradients refused), and the linear interpolant of the
# tetrahedra, which no wall crosses; the C1 methods need gradients and "nearest" sees through
WALLED_METHODS = ("sibson", "linear")
# In 3D the gradients of the Sibson coordinates (Lasserre's method) lose accuracy within a
# small distance of the hull (measured on random nodes: errors of sum_i x_i grad phi_i = I
# 7e-10 at 1e-6 of the hull, 1e-2 at 1e-8, 1e2 at 1e-10): gradients there are NaN. Relative
# to the diagonal of the data's bounding box.
NEAR_HULL_3D = 1e-6


class NaturalNeighbourInterpolator:
    """Natural-neighbour interpolation of scattered data in 2D and 3D, in scipy's style.

    Parameters
    ----------
    points
        (n, d) data points, d = 2 or 3; or, to reuse a triangulation, a
        :class:`~skfem_nem.Triangulation` (2D) or a ``scipy.spatial.Delaunay`` (2D or 3D) of
        them. The triangulation is built (or adopted) once, here; do not change a
        ``Triangulation`` while interpolators use it (one that gains nodes is an error).
        The package's :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` with walls
        (``wall_off``: faults, interfaces) keeps them for ``"sibson"`` (values only) and
        ``"linear"``; the other methods refuse it.
    values
        (n, ...) data values, real or complex; trailing dimensions are interpolated together.
    method
        ``"sibson"`` (default: Sibson's natural-neighbour interpolant, C1 except at the data
        points), ``"laplace"`` (2D; C0), ``"sibson1"`` (Sibson's C1 interpolant, blending the
        linear Taylor functions at the neighbours: needs ``gradients`` or estimates them with
        :func:`~skfem_nem.estimate_gradients`), ``"farin"`` (Farin's C1 interpolant, a cubic in
        the Sibson coordinates that reproduces quadratics; gradients as ``"sibson1"``),
        ``"linear"`` (barycentric on the Delaunay simplices, as
        ``scipy.interpolate.LinearNDInterpolator``) or ``"nearest"``.
    fill_value
        The value at query points outside the convex hull of the data (NaN by default).
        Points on the hull interpolate.
    rescale
        Rescale the points to the unit cube (each axis centred and divided by its extent)
        before triangulating; the queries are rescaled alike. As scipy's option: for data
        whose axes have very different units. Not with a prebuilt triangulation.
    gradients
        (n, ..., d) gradients of the data at the data points for ``"sibson1"`` and ``"farin"``
        (with respect to the original, unscaled coordinates). Only for those methods.
    chunk
        Queries are evaluated in chunks of this many points, so that memory stays bounded
        for any number of queries. (Sibson's values of a large 2D batch, which need less
        memory per query than the coordinates, go in chunks of up to ~128 MB of work space
        if that is more points.)

    Attributes
    ----------
    points : (n, d) the data points as given (a copy)
    values : (n, ...) the data values (a copy)
    method, fill_value, rescale
    triangulation : the :class:`~skfem_nem.Triangulation` (2D) or ``scipy.spatial.Delaunay``
        (3D) of the (rescaled) points
    gradients : (n, ..., d) the nodal gradients ``"sibson1"`` and ``"farin"`` blend (given or
        estimated; None for the other methods)

    Raises
    ------
    ValueError
        For bad points (wrong shape, non-finite, duplicates, fewer than d + 1, flat), values
        of the wrong length, an unknown method (naming the valid ones) or one not available
        in the dimension, ``gradients`` of the wrong shape or with a method that does not use
        them, ``rescale`` with a prebuilt triangulation, a non-numeric fill value.

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import NaturalNeighbourInterpolator
    >>> rng = np.random.default_rng(0)
    >>> p = rng.random((200, 2))
    >>> itp = NaturalNeighbourInterpolator(p, 1 + 2 * p[:, 0] - 3 * p[:, 1])
    >>> itp([[0.5, 0.5], [2.0, 2.0]]).round(12)            # outside the hull: NaN
    array([0.5, nan])
    >>> x, y = np.meshgrid(np.linspace(0.2, 0.8, 4), np.linspace(0.2, 0.8, 3))
    >>> itp(x, y).shape, itp.gradient(x, y).shape
    ((3, 4), (3, 4, 2))
    >>> itp.gradient([0.3, 0.6]).round(12)
    array([ 2., -3.])
    """

    def __init__(self, points, values, method: str = "sibson", fill_value=np.nan,
                 rescale: bool = False, gradients=None, *, chunk: int = 1 << 16):
        if not isinstance(method, str) or method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}; got "
                             f"{method!r}")
        if not (isinstance(chunk, (int, np.integer)) and chunk > 0):
            raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
        p, tri, self._offset, self._scale = triangulated(points, bool(rescale))
        given = (points.nodes if isinstance(points, Triangulation) else
                 points.points if isinstance(points, DELAUNAY_TYPES) else points)
        self.points = np.array(given, dtype=np.float64, copy=True)
        n, d = p.shape
        if d not in METHODS[method]:
            raise ValueError(f"method {method!r} works in {' and '.join(map(str, METHODS[method]))}"
                             f"D only, the points are {d}D (3D: 'sibson', 'sibson1', 'farin', "
                             f"'linear', 'nearest')")
        if gradients is not None and method not in C1_METHODS:
            raise ValueError(f"gradients are used by the C1 method(s) {C1_METHODS} only, not "
                             f"by method={method!r}")
        if getattr(tri, "walled_neighbors", None) is not None and method not in WALLED_METHODS:
            raise ValueError(f"the tetrahedralisation has walls (Delaunay3D.wall_off): method "
                             f"{method!r} does not keep them, {WALLED_METHODS} do")
        V, self._trailing = check_values(values, n)
        self.values = V.reshape((n,) + self._trailing).copy()
        self.method, self.rescale = method, bool(rescale)
        self.fill_value = check_fill_value(fill_value)
        self.triangulation = tri
        self._n, self._d, self._chunk = n, d, int(chunk)
        self._dtype = np.result_type(V.dtype, np.asarray(self.fill_value).dtype, np.float64)
        self._hull = HullTest(p)
        self.gradients = None
        self._evaluate = self._method(p, tri, V, gradients)

    def _method(self, p, tri, V, gradients):
        """The evaluator of the method on points inside the hull (rescaled coordinates)."""
        if self.method in ("sibson", "laplace"):
            return NaturalInterpolant(tri, V, self.method, self._chunk)
        if self.method == "linear":
            return LinearInterpolant(p, tri, V)
        if self.method == "nearest":
            return NearestInterpolant(p, V)
        if gradients is None:
            G = nodal_gradients(p, tri, V)
        else:
            G = check_gradients(gradients, self._n, self._trailing, self._d, V.dtype)
            if self._scale is not None:
                G = G * self._scale
        scale = 1.0 if self._scale is None else self._scale
        self.gradients = (G / scale).reshape((self._n,) + self._trailing + (self._d,))
        if self.method == "farin":
            return FarinInterpolant(tri, p, V, G)
        return Sibson1Interpolant(tri, p, V, G)

    def __call__(self, *args):
        """The interpolant at the query points: one array ``xi`` of shape (..., d), or d
        coordinate arrays ``x, y[, z]`` that broadcast; returns ``(..., *values.shape[1:])``,
        ``fill_value`` outside the convex hull."""
        xi = query_points(args, self._d)
        out, _ = self._run(xi.reshape(-1, self._d), False)
        return out.reshape(xi.shape[:-1] + self._trailing)

    def gradient(self, *args):
        """The exact gradient of the interpolant at the query points (the forms of
        ``__call__``): shape ``(..., *values.shape[1:], d)``, NaN outside the convex hull. NaN
        also where the gradient is undefined: for ``"sibson"`` and ``"laplace"`` at the data
        points and on the hull, for ``"sibson1"`` and ``"farin"`` on the hull; in 3D also
        within 1e-6 of the diagonal of the data's bounding box from the hull (there the
        coordinates' gradients lose their accuracy)."""
        xi = query_points(args, self._d)
        _, grad = self._run(xi.reshape(-1, self._d), True)
        return grad.reshape(xi.shape[:-1] + self._trailing + (self._d,))

    def _run(self, q, gradient: bool):
        """Values (m, K) and, with ``gradient``, gradients (m, K, d) of the points q (m, d),
        chunk by chunk."""
        tri = self.triangulation
        if isinstance(tri, Triangulation) and tri.npoints != self._n:
            raise ValueError(f"the triangulation has {tri.npoints} nodes now, it had "
                             f"{self._n} when the interpolator was built")
        m, K = q.shape[0], int(np.prod(self._trailing, dtype=np.int64))
        out = np.full((m, K), self.fill_value, dtype=self._dtype)
        grad = np.full((m, K, self._d), np.nan, dtype=self._dtype) if gradient else None
        step = self._chunk
        if not gradient and isinstance(self._evaluate, NaturalInterpolant):
            step = self._evaluate.chunk_size(m)
        for c0 in range(0, m, step):
            qc = q[c0:c0 + step]
            if self._scale is not None:
                qc = (qc - self._offset) / self._scale
            rows, pts, dist = self._hull.inside(qc)
            if not rows.size:
                continue
            v, g = self._evaluate(pts, gradient)
            # all inside: a slice, not a fancy index (a copy less of a large batch)
            at = slice(c0, c0 + rows.size) if rows.size == qc.shape[0] else c0 + rows
            out[at] = v
            if gradient:
                if self._d == 3 and self.method not in ("linear", "nearest"):
                    g[dist > -NEAR_HULL_3D * self._hull.diagonal] = np.nan
                grad[at] = g if self._scale is None else g / self._scale
        return out, grad

    def __repr__(self) -> str:
        return (f"NaturalNeighbourInterpolator({self._n} points in {self._d}D, "
                f"values {self.values.shape[1:]}, method={self.method!r})")


def natural_neighbour_to_grid(xp, yp, variable, grid_x, grid_y, method: str = "sibson"):
    """Scattered 2D data on a grid, as MetPy's ``natural_neighbor_to_grid``.

    ``xp``, ``yp``, ``variable``: (n,) the data points' coordinates and values;
    ``grid_x``, ``grid_y``: the grid's coordinates (same shape, as ``np.meshgrid`` gives).
    Returns the values on the grid (that shape), NaN outside the points' convex hull.
    ``method`` as :class:`NaturalNeighbourInterpolator`'s (Sibson's by default, which is
    MetPy's method).

    >>> import numpy as np
    >>> from skfem_nem import natural_neighbour_to_grid
    >>> x, y = np.meshgrid(np.linspace(0, 1, 3), np.linspace(0, 1, 3))
    >>> gx, gy = np.meshgrid([0.25, 0.75], [0.5])
    >>> natural_neighbour_to_grid(x.ravel(), y.ravel(), (x + 2 * y).ravel(), gx, gy).round(12)
    array([[1.25, 1.75]])
    """
    xp, yp, z = (np.asarray(a) for a in (xp, yp, variable))
    if not (xp.ndim == yp.ndim == z.ndim == 1 and xp.size == yp.size == z.size):
        raise ValueError(f"xp, yp and variable must be 1D arrays of one length, got shapes "
                         f"{xp.shape}, {yp.shape} and {z.shape}")
    gx, gy = np.asarray(grid_x, dtype=float), np.asarray(grid_y, dtype=float)
    if gx.shape != gy.shape:
        raise ValueError(f"grid_x and grid_y must have one shape, got {gx.shape} and "
                         f"{gy.shape}")
    return NaturalNeighbourInterpolator(np.c_[xp, yp], z, method=method)(gx, gy)
