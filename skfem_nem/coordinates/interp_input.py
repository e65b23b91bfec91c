"""Input checks of the scattered-data interpolant, in scipy's conventions.

Data points (an array or a prebuilt triangulation, optionally rescaled to the unit cube as
scipy's ``rescale=True`` does), data values with trailing dimensions, nodal gradients, fill
values and query points (one array of shape (..., d), or d coordinate arrays that broadcast).
Every check names the offending argument; the caller's arrays are copied, never modified.
"""
from __future__ import annotations

import numpy as np

from ..geometry.delaunay_nd import DELAUNAY_TYPES, check_delaunay, delaunay_of
from ..geometry.triangulation import Triangulation, validate_nodes

__all__ = ["triangulated", "check_values", "check_gradients", "check_fill_value",
           "query_points"]


def _rescaled(p):
    """scipy's rescaling: the points centred on their mean and divided by their extent per
    axis (an axis without extent keeps scale 1)."""
    offset = p.mean(axis=0)
    scale = np.ptp(p - offset, axis=0)
    scale[~(scale > 0)] = 1.0
    return (p - offset) / scale, offset, scale


def triangulated(points, rescale: bool):
    """``(p, triangulation, offset, scale)`` of the data ``points``: the (n, d) points (after
    rescaling), their :class:`~skfem_nem.Triangulation` (2D) or ``scipy.spatial.Delaunay``
    (3D), and the rescaling (``None`` without)."""
    if isinstance(points, (Triangulation,) + DELAUNAY_TYPES):
        if rescale:
            raise ValueError("rescale=True is not supported with a prebuilt triangulation as "
                             "points (rescale the points before triangulating them)")
        if isinstance(points, Triangulation):
            return points.nodes, points, None, None
        p = np.asarray(points.points, dtype=np.float64)
        d = p.shape[1]
        if d == 2:
            tri = Triangulation.from_triangles(p, points.simplices)
            return tri.nodes, tri, None, None
        if d != 3:
            raise ValueError(f"points must be 2- or 3-dimensional, got a {d}D Delaunay")
        p = validate_nodes(p, dim=3, name="points")
        check_delaunay(points, p)
        return p, points, None, None
    shape = np.shape(points)
    if len(shape) != 2 or shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (n, 2) or (n, 3), got {shape}")
    p = validate_nodes(points, dim=shape[1], name="points")
    offset = scale = None
    if rescale:
        p, offset, scale = _rescaled(p)
    tri = Triangulation(p) if p.shape[1] == 2 else delaunay_of(p)
    return (tri.nodes if p.shape[1] == 2 else p), tri, offset, scale


def _numeric(a, name):
    if a.dtype.kind not in "biufc":
        raise ValueError(f"{name} must be numbers (real or complex), got dtype {a.dtype}")
    return a.astype(np.complex128 if a.dtype.kind == "c" else np.float64)


def check_values(values, n: int):
    """``(V, trailing)``: the values as an (n, K) float or complex copy, and their trailing
    shape."""
    a = np.asarray(values)
    if a.ndim == 0 or a.shape[0] != n:
        raise ValueError(f"values must have shape (n, ...) with one row per data point, "
                         f"n = {n}; got shape {a.shape}")
    a = _numeric(a, "values")
    return a.reshape(n, -1).copy(), a.shape[1:]


def check_gradients(gradients, n: int, trailing, d: int, dtype):
    """The nodal gradients ``(n, *trailing, d)`` as an (n, K, d) copy."""
    a = np.asarray(gradients)
    want = (n,) + tuple(trailing) + (d,)
    if a.shape != want:
        raise ValueError(f"gradients must have shape (n, ..., d) = {want} (the values' shape "
                         f"and the dimension), got {a.shape}")
    a = _numeric(a, "gradients").astype(np.result_type(a.dtype, dtype, np.float64))
    if not np.isfinite(a).all():
        i = int(np.flatnonzero(~np.isfinite(a.reshape(n, -1)).all(axis=1))[0])
        raise ValueError(f"gradients must be finite; gradients[{i}] is not")
    return a.reshape(n, -1, d).copy()


def check_fill_value(fill_value):
    a = np.asarray(fill_value)
    if a.ndim != 0 or a.dtype.kind not in "biufc":
        raise ValueError(f"fill_value must be a number (NaN by default), got {fill_value!r}")
    return a.item()


def query_points(args, d: int) -> np.ndarray:
    """The query points of ``itp(xi)`` / ``itp(x, y[, z])`` as an array of shape (..., d)
    (scipy's forms: one array, a tuple of d arrays, or d arrays that broadcast)."""
    if len(args) == 1 and isinstance(args[0], tuple):
        args = args[0]
    if len(args) == 1:
        xi = np.asarray(args[0])
        if xi.ndim == 0 or xi.shape[-1] != d:
            raise ValueError(f"xi must have shape (..., {d}) for {d}D data, got {xi.shape}")
    elif len(args) == d:
        xi = np.stack(np.broadcast_arrays(*[np.asarray(a) for a in args]), axis=-1)
    else:
        raise ValueError(f"pass the query points as one array of shape (..., {d}) or as {d} "
                         f"coordinate arrays; got {len(args)} arguments")
    if xi.dtype.kind not in "biuf":
        raise ValueError(f"query points must be real numbers, got dtype {xi.dtype}")
    xi = xi.astype(np.float64, copy=len(args) == 1)     # stacked: our own array already
    if np.isfinite(xi).all():
        return xi
    bad = ~np.isfinite(xi).all(axis=-1)
    if bad.any():
        first = tuple(int(k) for k in np.argwhere(bad)[0])
        raise ValueError(f"{int(bad.sum())} query point(s) have non-finite coordinates; first "
                         f"is xi[{first}] = {xi[first].tolist()}")
    return xi
