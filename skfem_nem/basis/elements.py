"""The natural-neighbour elements (a numbering: one dof per node) and the integration rules.

The functions themselves are not polynomials on the cells, so the elements only number the
degrees of freedom; :mod:`skfem_nem.basis.natural_neighbour` evaluates them. The choice between
the consistent default (gradient smoothing) and Gauss quadrature is made here once, for the
cell and facet bases alike.
"""
from __future__ import annotations

import numpy as np
from skfem import MeshTet
from skfem.element import Element, ElementVector
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTet, RefTri

__all__ = ["coordinate_method", "ElementNaturalNeighbour", "ElementNaturalNeighbour2",
           "ElementTetNaturalNeighbour",
           "gauss_rule", "element_for", "element_order", "integration_scheme",
           "QUADRATURE_POINTS", "INTEGRATIONS"]


#: number of quadrature points -> scikit-fem integration order on triangles
QUADRATURE_POINTS = {3: 2, 4: 3, 6: 4, 7: 5, 12: 6, 13: 7}
#: integration schemes: gradients smoothed over cells (consistent, the
#: default; :mod:`skfem_nem.basis.smoothing`) or Gauss quadrature of the gradients
INTEGRATIONS = ("smoothed", "gauss")


class ElementNaturalNeighbour(Element):
    """Degrees of freedom of natural-neighbour trial functions: one per node.

    Only a numbering: the functions themselves are evaluated by
    :class:`NaturalNeighbourBasis` (they are not polynomials on the
    triangles). Wrap it in ``ElementVector`` for vector fields.
    """

    nodal_dofs = 1
    maxdeg = 1  # default integration order 2: the 3-point rule (the paper's)
    dofnames = ["u"]
    doflocs = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    refdom = RefTri

    def gbasis(self, mapping, X, i, tind=None):
        raise NotImplementedError(
            "natural-neighbour functions are not defined triangle by triangle: "
            "use skfem_nem.NaturalNeighbourBasis(mesh, ...) instead of Basis/CellBasis")

    def lbasis(self, X, i):
        raise NotImplementedError(
            "natural-neighbour functions have no reference-element basis: "
            "use skfem_nem.NaturalNeighbourBasis")


class ElementTetNaturalNeighbour(ElementNaturalNeighbour):
    """The natural-neighbour numbering on tetrahedra (one dof per node).

    :class:`NaturalNeighbourBasis` on a ``MeshTet`` uses it in place of
    :class:`ElementNaturalNeighbour` (either may be passed);
    ``ElementVector(ElementTetNaturalNeighbour())`` has three components.
    """

    doflocs = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    refdom = RefTet


class ElementNaturalNeighbour2(ElementNaturalNeighbour):
    """Degrees of freedom of quadratic natural-neighbour functions: P2's, one per node
    and one per edge (the field's value at the edge's midpoint on the boundary and on
    segments; elsewhere the midpoint parameter of its polar form).

    The functions are the coordinates in quadratic Bernstein form
    (:mod:`skfem_nem.basis.quadratic`): they reproduce quadratic fields, and with the
    quadratically consistent smoothing (:mod:`skfem_nem.basis.smoothing_quadratic`) they
    converge at P2's rates. Triangles only; wrap it in ``ElementVector`` for vector
    fields (dofs numbered as scikit-fem numbers ``ElementVector(ElementTriP2())``'s).

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import ElementNaturalNeighbour2, NaturalNeighbourBasis, delaunay_mesh
    >>> mesh = delaunay_mesh(np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [.4, .6]]))
    >>> basis = NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2())
    >>> int(basis.N) == mesh.p.shape[1] + mesh.facets.shape[1]    # nodes and edges
    True
    >>> u = basis.doflocs[0] ** 2 - basis.doflocs[1]     # at the nodes and edge midpoints
    >>> x = np.array([[0.3, 0.7, 0.55], [0.2, 0.5, 0.9]])
    >>> bool(np.allclose(basis.probes(x) @ u, x[0] ** 2 - x[1]))   # reproduced
    True
    """

    facet_dofs = 1
    maxdeg = 2
    dofnames = ["u", "u"]
    doflocs = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.0], [0.5, 0.5],
                        [0.0, 0.5]])


def element_order(elem) -> int:
    """1 for the natural-neighbour coordinates, 2 for their quadratic Bernstein form."""
    base = elem.elem if isinstance(elem, ElementVector) else elem
    return 2 if isinstance(base, ElementNaturalNeighbour2) else 1


def element_for(mesh, elem, who):
    """``elem`` (natural-neighbour, scalar or vector) on the reference cell of
    ``mesh``: the triangle and tetrahedron variants are the same numbering."""
    elem = ElementNaturalNeighbour() if elem is None else elem
    vec = isinstance(elem, ElementVector)
    base = elem.elem if vec else elem
    if not isinstance(base, ElementNaturalNeighbour):
        name = type(base).__name__ + ("" if base is elem else " in ElementVector")
        raise TypeError(f"{who} needs ElementNaturalNeighbour(), ElementNaturalNeighbour2() "
                        f"or their ElementVector, got {name}: for "
                        f"{type(base).__name__} functions use scikit-fem's Basis(mesh, "
                        f"element), or nn_basis.with_element(element) for a companion on "
                        f"the same quadrature points")
    if isinstance(base, ElementNaturalNeighbour2):
        if isinstance(mesh, MeshTet):
            raise ValueError(f"{who}: ElementNaturalNeighbour2 (quadratic) works on "
                             f"triangles only; on tetrahedra use ElementNaturalNeighbour()")
        return elem
    want = ElementTetNaturalNeighbour if isinstance(mesh, MeshTet) else ElementNaturalNeighbour
    if type(base) is not want:
        base = want()
        elem = ElementVector(base) if vec else base
    return elem


def integration_scheme(integration, npoints=None, intorder=None, quadrature=None, dim=2):
    """The integration scheme: ``integration`` if given (checked against the
    rule options), else Gauss when a rule is asked for, smoothed otherwise. On
    tetrahedra (``dim`` 3) a smoothed basis takes ``intorder`` or ``quadrature``
    as the points that carry values (all in the tetrahedron, its one smoothing
    cell)."""
    rule = [k for k, v in (("npoints", npoints), ("intorder", intorder),
                           ("quadrature", quadrature)) if v is not None]
    if integration is None:
        return "gauss" if rule else "smoothed"
    if integration not in INTEGRATIONS:
        raise ValueError(f"integration must be one of {', '.join(map(repr, INTEGRATIONS))}, "
                         f"got {integration!r}")
    if integration == "smoothed" and rule and not (dim == 3 and rule[0] != "npoints"):
        raise ValueError(f"{rule[0]} chooses a Gauss rule, but integration='smoothed' has "
                         f"its own points (one per smoothing cell); pass "
                         f"integration='gauss' with it")
    return integration


def gauss_rule(npoints=None, intorder=None, quadrature=None, refdom=RefTri):
    """The Gauss rule (X, W) on ``refdom`` asked for by ``npoints`` (triangles:
    1, 3, 4, 6, 7, 12, 13), ``intorder`` (scikit-fem's orders) or an explicit
    ``quadrature``; default order 2 (the 3-point rule on triangles)."""
    if quadrature is not None:
        X, W = quadrature
        X, W = np.asarray(X, dtype=float), np.asarray(W, dtype=float)
        if X.ndim != 2 or W.ndim != 1:
            raise ValueError(
                f"quadrature=(X, W) must be one rule on the reference cell, X (dim, nq) and W "
                f"(nq,); got X {X.shape}, W {W.shape}: a rule per element (as "
                f"skfem.supermeshing.elementwise_quadrature gives) is not supported. To "
                f"carry a natural-neighbour field y to another mesh, project its values: "
                f"other_basis.project(nem_basis.interpolator(y))")
        return X, W
    if npoints is not None:
        if refdom is not RefTri:
            raise ValueError("npoints chooses a triangle rule; on tetrahedra pass intorder "
                             "or quadrature")
        if npoints == 1:
            return np.array([[1.0 / 3.0], [1.0 / 3.0]]), np.array([0.5])
        if npoints not in QUADRATURE_POINTS:
            raise ValueError(f"npoints must be one of 1, {', '.join(map(str, QUADRATURE_POINTS))}; "
                             f"got {npoints}")
        return get_quadrature(RefTri, QUADRATURE_POINTS[npoints])
    return get_quadrature(refdom, 2 if intorder is None else intorder)


def coordinate_method(mesh, coordinates: str, method):
    """The coordinates' method for ``mesh`` (``"area"`` on triangles by default,
    ``"lasserre"`` on tetrahedra); ``ValueError`` naming a bad ``coordinates`` or
    ``method`` or a pair that does not go together."""
    if coordinates not in ("sibson", "laplace"):
        raise ValueError(f"coordinates must be 'sibson' or 'laplace', got {coordinates!r}")
    tet = isinstance(mesh, MeshTet)
    if method is None:
        method = "lasserre" if tet else "area"
    if method not in ("area", "lasserre"):
        raise ValueError(f"method must be 'area' or 'lasserre', got {method!r}")
    if tet and method != "lasserre":
        raise ValueError("on tetrahedra the coordinates come from the Lasserre method only "
                         "(method='lasserre')")
    if method == "lasserre" and coordinates != "sibson":
        raise ValueError("the Lasserre method computes Sibson coordinates only "
                         "(coordinates='sibson')")
    return method
