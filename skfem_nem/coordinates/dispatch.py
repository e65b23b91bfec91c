"""The public coordinate functions: one entry point, a method per file behind it.

:func:`natural_neighbour_coordinates` checks the options and hands the query to the 2D area
method (:mod:`skfem_nem.coordinates.area2d`, the paper's method 1) or to Lasserre's volume
recursion (:mod:`skfem_nem.coordinates.lasserre`, the paper's Box 1, any of d = 2, 3, 4).
"""
from __future__ import annotations

from typing import Literal, Optional

import numpy as np

from ..geometry.delaunay_nd import DELAUNAY_TYPES
from ..geometry.hull import OUTSIDE_ROUNDOFF
from ..geometry.triangulation import Triangulation
from .area2d import area_coordinates
from .lasserre import sibson_coordinates_nd

__all__ = ["sibson_coordinates", "laplace_coordinates", "natural_neighbour_coordinates"]


def _dimension(nodes_or_triangulation) -> int:
    """Space dimension of nodes, a Triangulation or a scipy Delaunay (2 if unclear:
    the 2D checks then name the problem)."""
    if isinstance(nodes_or_triangulation, Triangulation):
        return 2
    if isinstance(nodes_or_triangulation, DELAUNAY_TYPES):
        return int(nodes_or_triangulation.points.shape[1])
    shape = np.shape(nodes_or_triangulation)
    return int(shape[1]) if len(shape) == 2 and shape[1] in (3, 4) else 2


def _as_triangulation(nodes_or_triangulation) -> Triangulation:
    if isinstance(nodes_or_triangulation, Triangulation):
        return nodes_or_triangulation
    if isinstance(nodes_or_triangulation, DELAUNAY_TYPES):
        return Triangulation(nodes_or_triangulation.points)
    return Triangulation(nodes_or_triangulation)


def _lasserre(src, x, gradient, kind, undefined, chunk, area_options):
    """The Lasserre branch of :func:`natural_neighbour_coordinates`."""
    if kind != "sibson":
        raise ValueError(f"the Lasserre method computes Sibson coordinates only, got "
                         f"kind={kind!r}")
    if area_options:
        raise ValueError("hint and return_triangles are options of the 2D area method "
                         "(method='area')")
    if isinstance(src, Triangulation):
        if src.segment_keys.size:
            raise ValueError("the triangulation has segments: constrained coordinates come "
                             "from the 2D area method only (method='area')")
        src = src.nodes
    if isinstance(src, DELAUNAY_TYPES):
        return sibson_coordinates_nd(src.points, x, gradient=gradient, delaunay=src,
                                     undefined=undefined, chunk=chunk)
    return sibson_coordinates_nd(src, x, gradient=gradient, undefined=undefined, chunk=chunk)


def natural_neighbour_coordinates(
    nodes_or_triangulation,
    x,
    gradient: bool = False,
    kind: Literal["sibson", "laplace"] = "sibson",
    undefined: Literal["raise", "nan"] = "raise",
    chunk: int = 1 << 15,
    return_triangles: bool = False,
    hint=None,
    hull_tol: float = OUTSIDE_ROUNDOFF,
    method: Optional[Literal["area", "lasserre"]] = None,
):
    """Natural-neighbour coordinates (and gradients) of points in 2, 3 or 4 dimensions.

    Parameters
    ----------
    nodes_or_triangulation
        (n, d) nodes with d = 2, 3 or 4; or, to reuse a triangulation over
        many calls, a :class:`~skfem_nem.Triangulation` (2D) or a
        :class:`scipy.spatial.Delaunay` of the nodes (any d, Lasserre method).
    x
        (m, d) query points, inside the convex hull (its boundary included).
    gradient
        Also return the gradients.
    kind
        ``"sibson"`` (area) or ``"laplace"`` (non-Sibsonian) coordinates.
    undefined
        What to do when gradients are requested at a node or on a convex-hull
        edge, where this module does not define them: ``"raise"`` a
        ``ValueError`` naming the query, or set that row's gradients to NaN.
    chunk
        Queries are processed in chunks of this many points (bounds memory).
    return_triangles
        Also return the (m,) index of a triangle containing each point.
    hint
        Optional (m,) triangle indices to start each point's search from
        (e.g. the triangle known to contain it); a bucket grid otherwise.
    hull_tol
        Points outside the convex hull by less than ``hull_tol`` times the
        diagonal of the nodes' bounding box are round-off: they are moved onto
        the nearest hull edge. Farther points are an error. (Area method; the
        Lasserre method has its own relative tolerance, see
        :mod:`skfem_nem.coordinates.lasserre`.)
    method
        ``"area"``: the 2D area method of this module (the paper's method 1;
        the default in 2D). ``"lasserre"``: volumes of second-order Voronoi
        cells by Lasserre's recursion, :func:`skfem_nem.coordinates.lasserre.sibson_coordinates_nd`
        (the paper's Box 1, method 2; the default and only method in 3D and
        4D; Sibson coordinates only, no ``hint`` or ``return_triangles``).

    Returns
    -------
    Phi : scipy.sparse.csr_matrix, shape (m, n)
        ``Phi[q, i] = phi_i(x_q)``, so ``Phi @ f`` interpolates nodal values f.
    dPhi : list of d csr_matrix, shape (m, n)
        Only with ``gradient=True``: ``dPhi[k][q, i] = d phi_i / d x_k (x_q)``
        (units: 1 / length), with the same sparsity pattern as ``Phi``.

    Raises
    ------
    ValueError
        For bad nodes (see :class:`~skfem_nem.Triangulation`), non-finite
        queries, queries outside the convex hull (naming the first and the
        count), and gradients at nodes or hull edges with
        ``undefined="raise"``; for an unknown ``method``, or options the
        chosen method does not have.
    """
    d = _dimension(nodes_or_triangulation)
    if method is None:
        method = "area" if d == 2 else "lasserre"
    if method not in ("area", "lasserre"):
        raise ValueError(f"method must be 'area' or 'lasserre', got {method!r}")
    if method == "lasserre":
        return _lasserre(nodes_or_triangulation, x, gradient, kind, undefined, chunk,
                         hint is not None or return_triangles)
    if d != 2:
        raise ValueError(f"the area method works in 2D only; {d}D nodes need "
                         f"method='lasserre'")
    return area_coordinates(_as_triangulation(nodes_or_triangulation), x, gradient, kind,
                            undefined, chunk, return_triangles, hint, hull_tol)


def sibson_coordinates(nodes_or_triangulation, x, gradient: bool = False, **kwargs):
    """Sibson natural-neighbour coordinates of points x (m, d), d = 2, 3, 4.

    Returns a CSR matrix ``Phi`` (m, n) with ``Phi[q, i] = phi_i(x_q)``; with
    ``gradient=True`` returns ``(Phi, [dPhi/dx_1, ..., dPhi/dx_d])``. In 2D
    the area method is the default (``method="lasserre"`` selects the paper's
    Box 1); 3D and 4D nodes use the Lasserre method. See
    :func:`natural_neighbour_coordinates` for all options and errors.

    Examples
    --------
    The coordinates sum to one and reproduce linear functions, here the
    points' own coordinates and a linear field with its gradient:

    >>> import numpy as np
    >>> from skfem_nem import sibson_coordinates
    >>> nodes = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> x = np.array([[0.5, 0.5], [0.25, 0.75]])
    >>> Phi = sibson_coordinates(nodes, x)
    >>> Phi.shape, Phi.toarray().sum(axis=1).round(12).tolist()
    ((2, 5), [1.0, 1.0])
    >>> (Phi @ nodes).round(12).tolist()
    [[0.5, 0.5], [0.25, 0.75]]
    >>> f = 3 + 2 * nodes[:, 0] - nodes[:, 1]
    >>> Phi, (Dx, Dy) = sibson_coordinates(nodes, x, gradient=True)
    >>> (Dx @ f).round(12).tolist(), (Dy @ f).round(12).tolist()
    ([2.0, 2.0], [-1.0, -1.0])
    """
    return natural_neighbour_coordinates(nodes_or_triangulation, x, gradient=gradient,
                                         kind="sibson", **kwargs)


def laplace_coordinates(nodes_or_triangulation, x, gradient: bool = False, **kwargs):
    """Laplace (non-Sibsonian) natural-neighbour coordinates of points x (m, 2).

    Same signature and outputs as :func:`sibson_coordinates`.
    """
    return natural_neighbour_coordinates(nodes_or_triangulation, x, gradient=gradient,
                                         kind="laplace", **kwargs)
