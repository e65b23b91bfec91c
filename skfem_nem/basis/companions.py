"""Ordinary scikit-fem bases that live beside a natural-neighbour basis, and the
scikit-fem keywords that have no meaning for natural-neighbour functions.

scikit-fem scripts build piecewise coefficients and projections with
``basis.with_element(ElementTriP0())``: a basis on the same mesh, elements and quadrature,
whose fields (``p0.interpolate(k)``) enter forms on the first basis. For a
natural-neighbour basis such a companion is an ordinary ``CellBasis`` at the very same
quadrature points (for the default smoothed integration, the points and weights of the
smoothing cells), so the fields line up point by point with the natural-neighbour ones and
mixed forms assemble (:mod:`skfem_nem.basis.assembly`).

A natural-neighbour function is fixed by the nodes alone, so a reference-cell ``mapping`` and
a custom ``dofs`` numbering have nothing to act on: they raise, naming what to do instead.
"""
from __future__ import annotations

from skfem.assembly import CellBasis, FacetBasis
from skfem.element import Element, ElementVector

from .elements import ElementNaturalNeighbour

__all__ = ["companion_basis", "is_natural_neighbour", "refuse_keywords", "REFUSED"]

#: scikit-fem constructor keywords without meaning here, and what to do instead
REFUSED = {
    "mapping": "natural-neighbour functions are fixed by the nodes, not by a reference-cell "
               "mapping; the basis integrates with the mesh's own (affine) mapping: leave "
               "mapping=None",
    "dofs": "natural-neighbour dofs are one per node (dim per node for a vector), numbered "
            "as the mesh's nodes: leave dofs=None and renumber the solution vector instead",
}


def refuse_keywords(who, **given):
    """Raise for the first keyword of ``given`` (of :data:`REFUSED`) that is not None."""
    for name, value in given.items():
        if value is not None:
            raise TypeError(f"{who}({name}=...): {REFUSED[name]}")


def is_natural_neighbour(elem) -> bool:
    """Is ``elem`` a natural-neighbour element (scalar or vector)?"""
    base = elem.elem if isinstance(elem, ElementVector) else elem
    return isinstance(base, ElementNaturalNeighbour)


def companion_basis(nn, elem: Element):
    """A scikit-fem basis with element ``elem`` on the mesh, elements (or facets) and
    quadrature of the natural-neighbour basis ``nn``: a ``CellBasis`` for a cell basis, a
    ``FacetBasis`` for a facet basis."""
    if not isinstance(elem, Element):
        raise TypeError(f"with_element needs a scikit-fem Element, got {type(elem).__name__}")
    refdom = getattr(elem, "refdom", None)
    if refdom is not nn.mesh.refdom:
        raise ValueError(f"with_element({type(elem).__name__}()): the element lives on "
                         f"{getattr(refdom, '__name__', refdom)}, the mesh on "
                         f"{nn.mesh.refdom.__name__}")
    if hasattr(nn, "find"):  # a facet basis
        return FacetBasis(nn.mesh, elem, quadrature=nn.quadrature, facets=nn.find,
                          side=nn.side)
    return CellBasis(nn.mesh, elem, quadrature=nn.quadrature, elements=nn.tind)
