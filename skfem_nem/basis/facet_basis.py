"""Natural-neighbour trial functions at quadrature points on facets.

Kept apart from :mod:`skfem_nem.basis.natural_neighbour` (the cell basis and the machinery
both share, :class:`~skfem_nem.basis.natural_neighbour.NaturalNeighbourBasisBase`) because a
facet basis adds its own concerns: the facets' geometry from scikit-fem's ``FacetBasis``, the
one-sided gradients on the hull, the traces of projections, ``w.n`` in forms.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from numpy import ndarray
from skfem import MeshTet, MeshTri
from skfem.assembly.basis import AbstractBasis, FacetBasis
from skfem.element import DiscreteField, Element, ElementTetP1, ElementTriP1, ElementVector

from ..geometry.meshes import adopt
from .companions import companion_basis, is_natural_neighbour, refuse_keywords
from .domain import check_used_nodes
from .elements import coordinate_method, element_for, element_order, integration_scheme
from .groups import GroupBasis, restrict_field
from .hull_gradients import one_sided_gradients
from .natural_neighbour import NaturalNeighbourBasisBase
from .projection import field_values, normalize_facets, positions_in

__all__ = ["NaturalNeighbourFacetBasis"]


class NaturalNeighbourFacetBasis(NaturalNeighbourBasisBase):
    """Natural-neighbour trial functions at quadrature points on facets.

    For Neumann loads, tractions, fluxes and Nitsche terms; ``w.n`` (outward
    normal), ``w.h`` and ``w.x`` are available in forms as with scikit-fem's
    ``FacetBasis``. On convex-hull facets the values reduce to the linear 1D
    weights of the facet's nodes; gradients there are the one-sided limits
    from inside, evaluated a relative distance ``1e-7`` (of the facet length)
    inside the domain.

    ``integration="smoothed"`` (default) gives each facet point the smoothed
    gradient of the cell it lies on (in 2D the vertex cell of the facet's
    half, in 3D the tetrahedron), so facet terms such as Nitsche's see the
    gradients of a smoothed cell basis and the patch test still passes;
    ``"gauss"`` the one-sided gradients above. Values are always exact.
    """

    def __init__(self, mesh: MeshTri | MeshTet, elem: Optional[Element] = None, facets=None,
                 intorder: Optional[int] = None, quadrature=None, coordinates: str = "sibson",
                 side: int = 0, method: Optional[str] = None,
                 integration: str = "smoothed", mapping=None, dofs=None,
                 disable_doflocs: bool = False):
        refuse_keywords("NaturalNeighbourFacetBasis", mapping=mapping, dofs=dofs)
        elem = element_for(mesh, elem, "NaturalNeighbourFacetBasis")
        if element_order(elem) != 1:
            raise NotImplementedError("no NaturalNeighbourFacetBasis for the quadratic element")
        check_used_nodes(mesh, "NaturalNeighbourFacetBasis")
        self.method = coordinate_method(mesh, coordinates, method)
        # (the facet rule serves both schemes: values and smoothed gradients)
        self.integration = integration = integration_scheme(integration)
        self.triangulation = adopt(mesh, self.method)
        self.coordinates = coordinates
        p1 = ElementTetP1() if isinstance(mesh, MeshTet) else ElementTriP1()
        geom = FacetBasis(mesh, p1, facets=facets, intorder=intorder,
                          quadrature=quadrature, side=side)
        self._geom = geom
        AbstractBasis.__init__(self, mesh, elem, geom.mapping, None, geom.quadrature,
                               mesh.refdom.brefdom, disable_doflocs=disable_doflocs)
        self.side = side
        self.find = geom.find
        self.tind = None
        self.nelems = geom.nelems
        self.dx = geom.dx
        self.normals = geom.normals
        x = np.asarray(geom.global_coordinates())
        if integration == "gauss":
            Phi, G = self._build(x, geom.tind, self.dx)
        else:
            Phi, G = self._build_smoothed(x, geom.tind, self._cells_of(x, geom.tind))
            if G is None:  # 3D: the facets' values joined with their cells' gradients
                Phi, G = Phi.joined()
        self._set_functions(Phi, G, *self.dx.shape)

    def project(self, interp, facets=None, dtype=None) -> ndarray:
        """L2 projection of ``interp`` (callable of x, DiscreteField, array or tuple of
        components at the facet quadrature points, or a number) on the basis' facets, as
        scikit-fem's ``FacetBasis.project``: the dofs of the facets' own nodes (of
        ``facets``, a subset of the basis' facets, if given) are the L2 projection of
        ``interp`` onto the linear hats of those nodes along the facets; the other dofs
        are zero.

        On boundary facets the natural-neighbour functions are those hats (their values
        on a boundary facet are the facet's linear 1D weights), so this is the projection
        onto the basis' own traces, and equals P1's. On interior facets (an interface,
        the surface of a conductor) functions of nodes off the facets are non-zero too and
        the traces of all of them are linearly dependent; the facets' nodal values are
        then the ones P1 would give, which is what Dirichlet conditions need."""
        pos = np.arange(self.nelems)
        if facets is not None:
            pos = positions_in(self.find, normalize_facets(self.mesh, facets), "facet")
        if dtype is not None and not np.issubdtype(np.dtype(dtype), np.floating):
            raise ValueError(f"project(dtype={np.dtype(dtype)}): natural-neighbour "
                             f"projections are real")
        f = field_values(self, interp)
        p1 = ElementTetP1() if isinstance(self.mesh, MeshTet) else ElementTriP1()
        if isinstance(self.elem, ElementVector):
            p1 = ElementVector(p1, self.elem.dim)
        trace = companion_basis(self, p1)
        y = trace.project(DiscreteField(f), facets=self.find[pos])
        out = np.zeros(self.N)
        out[self.dofs.nodal_dofs] = y[trace.nodal_dofs]
        return out if dtype is None else out.astype(dtype)

    def with_element(self, elem: Element):
        """The same facets and quadrature with another element: natural-neighbour, or a
        scikit-fem element (an ordinary ``FacetBasis`` at the same points)."""
        if not is_natural_neighbour(elem):
            return companion_basis(self, elem)
        rule = {} if self.quadrature is None else {"quadrature": self.quadrature}
        return type(self)(self.mesh, elem, facets=self.find, coordinates=self.coordinates,
                          side=self.side, method=self.method, integration=self.integration,
                          **rule)

    def trace(self, *args, **kwargs):
        raise NotImplementedError(
            "trace() builds a P1/P0 basis on the facets from per-element dofs, which "
            "natural-neighbour functions do not have: evaluate the field on the facets with "
            "NaturalNeighbourBasis(mesh).probes(x) at the points x = basis.global_coordinates()")

    def _cells_of(self, x, tind):
        """The smoothing cell of each facet point (dim, nf, nq), numbered as
        :func:`~skfem_nem.basis.smoothing.cells_2d` numbers the cells of
        ``np.unique(tind)``: in 2D the cell of the triangle's vertex nearest to
        the point (the facet's half it lies on), in 3D the tetrahedron."""
        elems, j = np.unique(tind, return_inverse=True)
        nq = x.shape[2]
        if self.mesh.dim() == 3:
            return np.repeat(j, nq)
        V = self.mesh.p[:, self.mesh.t[:, tind]]           # (2, 3, nf)
        d = ((x[:, None, :, :] - V[:, :, :, None]) ** 2).sum(axis=0)   # (3, nf, nq)
        return (3 * j[:, None] + d.argmin(axis=0)).ravel()

    def _fix_undefined(self, pts, Phi, D, dx, elems):
        # gradients on the hull: one-sided limits (basis.hull_gradients)
        nq = self.dx.shape[1]
        return one_sided_gradients(self._coordinates, pts, Phi, D, np.asarray(self.normals),
                                   np.asarray(self.mesh_parameters()),
                                   np.repeat(self._geom.tind, nq))

    def default_parameters(self):
        return {"x": self.global_coordinates(), "h": self.mesh_parameters(), "n": self.normals}

    def global_coordinates(self) -> DiscreteField:
        return self._geom.global_coordinates()

    def mesh_parameters(self) -> DiscreteField:
        return self._geom.mesh_parameters()

    def _group(self, elems, stencils, V, G):
        g = GroupBasis(self, elems, stencils, V, G)
        g.default_parameters = lambda: {
            "x": restrict_field(self.global_coordinates(), elems),
            "h": restrict_field(self.mesh_parameters(), elems),
            "n": restrict_field(self.normals, elems)}
        return g

