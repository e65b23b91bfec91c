"""Natural-neighbour trial functions inside scikit-fem's assembly.

:class:`NaturalNeighbourBasis` evaluates Sibson (or Laplace) natural-neighbour
coordinates and their gradients at the quadrature points of a Delaunay
``MeshTri`` (or ``MeshTet``) and presents them to scikit-fem's
``BilinearForm``, ``LinearForm`` and ``Functional`` exactly like a
``CellBasis`` does for P1.

In 2D the coordinates come from the area method (:mod:`skfem_nem.coordinates.area2d`,
the default) or from the paper's Box 1 (``method="lasserre"``,
:mod:`skfem_nem.coordinates.lasserre`); on tetrahedra always from Box 1, with scikit-fem's
tetrahedral quadrature and the exact Delaunay tetrahedra of
:class:`~skfem_nem.geometry.delaunay3d.Delaunay3D`.

Stencils
--------
In the natural element method the trial functions that are non-zero in a
triangle are not its three vertices but the natural neighbours of its
quadrature points: the triangle's *stencil*. Its size varies (mean about 8,
tails above 30 near the hull), while a scikit-fem basis has one number of
local functions for all its elements. The basis therefore splits the
triangles into groups of equal stencil size; each group is an ordinary
basis with a fixed ``Nbfun``, and assembly sums the groups' contributions
(see :mod:`skfem_nem.basis.assembly`). Cost scales with the sum over triangles of
the stencil size squared, not with the largest stencil.
"""
from __future__ import annotations

import time
import weakref
from typing import Optional, Tuple

import numpy as np
from numpy import ndarray
from skfem import MeshTet, MeshTri
from skfem.assembly.basis import AbstractBasis
from skfem.element import DiscreteField, Element, ElementVector

from . import assembly, nonlinear, plotting
from ..coordinates import natural_neighbour_coordinates
from ..coordinates.watson3d import TetrahedraRecords, records_of
from ..geometry.delaunay3d import Delaunay3D
from ..geometry.meshes import adopt, own_triangulation, tetrahedron_neighbours
from .domain import check_used_nodes, into_domain
from .elements import (coordinate_method, element_for, element_order, gauss_rule,
                       integration_scheme)
from .companions import companion_basis, is_natural_neighbour, refuse_keywords
from .plotting import DEFAULT_NREFS, refined_values, visuals_call
from .projection import (l2_project, normalize_elements, positions_in, projection_dofs,
                         stencil_dofs)
from .groups import GroupBasis
from .stencils import fill_group, stencil_union
from . import updates
from .cell_rows import CellRows
from .smoothing import smoothed_functions, value_rule, vertex_points
from . import quadratic
from .smoothing_quadratic import smoothed_quadratic

__all__ = ["NaturalNeighbourBasis", "NaturalNeighbourBasisBase"]


class NaturalNeighbourBasisBase(AbstractBasis, assembly.StencilBasis):
    """Shared machinery of the cell and facet bases: stencils and groups."""

    coordinates: str
    method: str
    triangulation: object  # Triangulation (2D area method) or scipy Delaunay

    def _coordinates(self, pts, gradient=False, hint=None, undefined="nan", faces=None):
        """Coordinates (and gradients) at the (m, dim) points pts. In 3D, ``faces`` (m,)
        says that point i lies in the mesh's tetrahedron ``hint[i]``, on its face opposite
        the vertex slot ``faces[i]`` (-1: inside): Sibson's values there come from Watson's
        decomposition (:mod:`~skfem_nem.coordinates.watson3d`), the same coordinates as
        the Box 1 method's at a fraction of the cost."""
        if faces is not None and not gradient and self.coordinates == "sibson":
            records = self._tetrahedra_records()
            if records is not None:
                return records.coordinates(
                    pts, hint, faces, lambda q: self._coordinates(q, undefined=undefined))
        kw = {}
        if self.method == "area" and hint is not None and self._hints_valid():
            kw["hint"] = hint
        if self.mesh.dim() == 2:
            # points on the boundary that round-off put a few ulps outside the domain
            pts, _ = into_domain(self.mesh, pts)
        return natural_neighbour_coordinates(
            self.triangulation, pts, gradient=gradient, kind=self.coordinates,
            undefined=undefined, method=self.method, **kw)

    def _tetrahedra_records(self):
        """The mesh's :class:`~skfem_nem.coordinates.watson3d.TetrahedraRecords` (the
        adoption checked its tetrahedra to be Delaunay), None where a flat tetrahedron rules
        Watson's decomposition out. Where the triangulation holds the mesh's own tetrahedra
        in their order (a mesh of the package's), they are the triangulation's records, which
        the coordinates of other points read too; else they are cached on the mesh."""
        p, t = self.mesh.p.T, self.mesh.t.T
        tri = self.triangulation
        if (isinstance(tri, Delaunay3D) and tri.simplices.shape == t.shape
                and np.array_equal(tri.simplices, t) and np.array_equal(tri.points, p)):
            rec = records_of(tri)
        else:
            rec = getattr(self.mesh, "_skfem_nem_watson", None)
            if rec is None or not rec.describes(p, t):
                rec = TetrahedraRecords(p, t, tetrahedron_neighbours(self.mesh))
                self.mesh._skfem_nem_watson = rec
        return rec if rec.usable else None

    def _hints_valid(self) -> bool:
        """Are the mesh's triangles those of the triangulation, one for one (so that a
        mesh triangle is a valid start of the point location)? Not for a mesh that is
        not Delaunay (refined, smoothed, imported), whose nodes were triangulated anew."""
        ok = self.__dict__.get("_hints_ok")
        if ok is None:
            ok = self._hints_ok = own_triangulation(self.mesh, self.triangulation)
        return ok

    def _build(self, x, hint, dx):
        """Coordinates and gradients at the (dim, ne, nq) points x (of weights dx)."""
        dim, ne, nq = x.shape
        pts = np.ascontiguousarray(x.transpose(1, 2, 0).reshape(-1, dim))
        Phi, D = self._coordinates(pts, gradient=True, hint=np.repeat(hint, nq))
        if Phi.nnz and not all(np.isfinite(Dk.data).all() for Dk in D):
            Phi, D = self._fix_undefined(pts, Phi, D, dx, hint)
        if self.order == 2:
            return quadratic.lift(self.mesh, Phi, D)
        # gradients as one (dim, nnz) array on Phi's pattern
        return Phi, np.stack([Dk.data for Dk in D]) if len(D) else np.empty((0, Phi.nnz))

    def _build_smoothed(self, x, elems, cell_of, nodal=None):
        """Values at the (dim, ne, nq) points x and smoothed gradients
        (:func:`~skfem_nem.basis.smoothing.smoothed_functions`); in 3D the values and the
        cells' gradient rows apart (a :class:`~skfem_nem.basis.cell_rows.CellRows`, None)."""
        out = smoothed_functions(self.mesh, self._coordinates, x, elems, cell_of, nodal)
        return out if isinstance(out, tuple) else (out, None)

    @property
    def order(self) -> int:
        """1: the natural-neighbour coordinates; 2: their quadratic Bernstein form."""
        return element_order(self.elem)

    @property
    def function_dofs(self) -> ndarray:
        """(components, functions) the dof of each component of each function (a column
        of ``values_matrix``): nodes, then (quadratic) the mesh's edges."""
        d = self.dofs
        return d.nodal_dofs if self.order == 1 else np.hstack([d.nodal_dofs, d.facet_dofs])

    def _set_functions(self, Phi, G, ne, nq):
        """Values (CSR, one row per quadrature point) and gradients (dim, nnz)
        on their pattern, or (``Phi`` a :class:`~skfem_nem.basis.cell_rows.CellRows`, ``G``
        None) values and one gradient row per cell, joined on first use; the stencils
        follow. Forms on the basis are assembled from these from now on
        (:mod:`skfem_nem.basis.assembly`)."""
        assembly.install()
        nonlinear.install()
        from .facet_basis import NaturalNeighbourFacetBasis  # (it builds on this module)
        plotting.install(NaturalNeighbourBasis, NaturalNeighbourFacetBasis)
        self.cell_rows = Phi if isinstance(Phi, CellRows) else None
        if self.cell_rows is None:
            self._join(Phi, G)
            ptr, sten = stencil_union(Phi.indptr, Phi.indices, nq, ne)
        else:
            self._values = self._gradients = self._gradient_matrices = None
            ptr, sten = self.cell_rows.stencils(nq)
        self.stencil_ptr, self.stencil_nodes = ptr, sten
        self.stencil_sizes = np.diff(ptr)
        self._groups = None

    def _join(self, Phi=None, G=None):
        """Set (or, from the cell rows, make) the values and gradients on one pattern."""
        if Phi is None:
            Phi, G = self.cell_rows.joined()
        self._values, self._gradients = Phi, G
        self._gradient_matrices = [self._on_pattern(Phi, G[k]) for k in range(G.shape[0])]

    def _joined(self):
        """``(values, gradients, gradient matrices)`` on one pattern, joined on first use."""
        if self._values is None:
            self._join()
        return self._values, self._gradients, self._gradient_matrices

    @property
    def values_matrix(self):
        """(ne * nq, N) CSR: the functions' values at the quadrature points."""
        return self._joined()[0]

    @property
    def gradient_entries(self):
        """(dim, nnz): the functions' gradients on the pattern of ``values_matrix``."""
        return self._joined()[1]

    @property
    def _D(self):
        """The gradients as dim CSR matrices sharing ``values_matrix``'s pattern."""
        return self._joined()[2]

    @staticmethod
    def _on_pattern(Phi, data):
        """The CSR matrix of ``data`` on ``Phi``'s pattern, sharing ``data`` and the index
        arrays (scipy's constructor copies ``data``: three gradient copies of the values'
        size, a third of a 3D Stokes basis' memory)."""
        D = type(Phi)((data, Phi.indices, Phi.indptr), shape=Phi.shape)
        D.data = data
        return D

    @property
    def groups(self):
        """The elements grouped by stencil size, each an ordinary basis with
        a fixed ``Nbfun`` (built on first use: forms on bases that share
        their functions assemble without them)."""
        if self._groups is None:
            sizes = self.stencil_sizes
            order = np.argsort(sizes, kind="stable")
            bounds = np.flatnonzero(np.diff(sizes[order])) + 1
            self._groups = [self._make_group(elems) for elems in np.split(order, bounds)
                            if elems.size]
        return self._groups

    def _make_group(self, elems):
        """The basis of the elements ``elems`` (all of one stencil size)."""
        ptr, sten = self.stencil_ptr, self.stencil_nodes
        S = int(ptr[elems[0] + 1] - ptr[elems[0]])
        nq = self.dx.shape[1]
        V = np.zeros((S, elems.size, nq))
        G = np.zeros((len(self._D), S, elems.size, nq))
        Phi = self.values_matrix
        fill_group(elems, ptr, sten, Phi.indptr, Phi.indices, Phi.data,
              tuple(Dk.data for Dk in self._D), nq, V, G)
        stencils = sten[ptr[elems][None, :] + np.arange(S)[:, None]]
        return self._group(elems, stencils, V, G)

    def restricted(self, idx, key=None):
        """A group basis on the elements ``idx`` (equal stencil sizes), cached."""
        cache = self.__dict__.setdefault("_restrict_cache", {})
        k = (idx.size, hash(np.ascontiguousarray(idx).tobytes()))
        if k not in cache:
            cache[k] = self._make_group(np.asarray(idx))
        return cache[k]

    def _fix_undefined(self, pts, Phi, D, dx, elems):
        """Undefined gradients at quadrature points: allowed only in cells of
        zero measure (the flat tetrahedra a ``MeshTet`` of Qhull's has between
        co-spherical nodes, e.g. lattices), whose points carry no weight; their gradients
        become 0."""
        finite = np.ones(Phi.shape[0], dtype=bool)
        for Dk in D:
            finite &= np.isfinite(np.asarray(Dk.sum(axis=1)).ravel())
        bad = np.flatnonzero(~finite)
        weight = dx.reshape(-1)[bad]
        if np.any(weight != 0.0):
            e = int(elems[bad[np.flatnonzero(weight != 0.0)[0]] // dx.shape[1]])
            raise ValueError(
                f"quadrature points at nodes or on the convex hull (first in element {e}): "
                f"gradients of natural-neighbour functions are undefined there; use a "
                f"quadrature rule with interior points")
        out = []
        for Dk in D:
            Dk = Dk.copy()
            Dk.data[~np.isfinite(Dk.data)] = 0.0
            out.append(Dk)
        return Phi, out

    def _group(self, elems, stencils, V, G):
        return GroupBasis(self, elems, stencils, V, G)

    # -- what assembly and users read ----------------------------------------
    @property
    def Nbfun(self):
        raise AttributeError(
            "a natural-neighbour basis has no single number of local functions; its "
            "groups do (basis.groups[k].Nbfun); for skfem.autodiff's NonlinearForm, import "
            "skfem.autodiff before building the basis")

    @Nbfun.setter
    def Nbfun(self, value):
        pass

    @property
    def element_dofs(self):
        raise AttributeError(
            "natural-neighbour stencils vary between triangles: see basis.stencil_nodes, "
            "basis.stencil_ptr, or basis.groups[k].element_dofs")

    @property
    def basis(self):
        """The local functions of the first group (a representative: assembly
        uses ``groups``; scikit-fem reads only their number of components)."""
        return self.groups[0].basis

    @basis.setter
    def basis(self, value):
        pass

    def __repr__(self):
        return (f"<skfem_nem {type(self).__name__}({type(self.mesh).__name__}, "
                f"{type(self.elem).__name__})>\n  Number of elements: {self.nelems}\n"
                f"  Number of DOFs: {self.N}\n  Integration: {self.integration}\n"
                f"  Stencil sizes: mean "
                f"{self.stencil_sizes.mean():.2f}, max {self.stencil_sizes.max()} "
                f"({len(self.groups)} groups)")

    def default_parameters(self):
        return {"x": self.global_coordinates(), "h": self.mesh_parameters()}

    def interpolate(self, w: ndarray) -> DiscreteField:
        """Values and gradients of the dof vector ``w`` (N,) at the quadrature
        points: a DiscreteField with value (ne, nq) and grad (dim, ne, nq), or
        (dim, ne, nq) and (dim, dim, ne, nq) for a vector basis."""
        w = np.asarray(w)
        if w.shape[0] != self.N:
            raise ValueError(f"dof vector has {w.shape[0]} entries, the basis {self.N}")
        sh = self.dx.shape

        def field(u):
            if self.cell_rows is not None:      # (the same numbers, nothing joined)
                rows = self.cell_rows
                return ((rows.values() @ u).reshape(sh),
                        rows.gradients_at_points(u).reshape((-1,) + sh))
            return ((self.values_matrix @ u).reshape(sh),
                    np.stack([(Dk @ u).reshape(sh) for Dk in self._D]))

        nd = self.function_dofs
        if isinstance(self.elem, ElementVector):
            vals, grads = zip(*[field(w[nd[c]]) for c in range(self.elem.dim)])
            return DiscreteField(np.stack(vals), np.stack(grads))
        return DiscreteField(*field(w[nd[0]]))

    def zeros(self, dtype=None):
        return np.zeros(self.N, dtype=dtype)

    @property
    def gradients_constant_per_element(self) -> bool:
        """True when every function's gradient is the same at all the quadrature points
        of an element: the smoothed linear basis on tetrahedra (one smoothing cell per
        tetrahedron). The assembly then contracts gradient terms once per element."""
        return (getattr(self, "integration", None) == "smoothed"
                and getattr(self, "order", 1) == 1 and self.mesh.dim() == 3
                and self.dx.ndim == 2)

    @property
    def nstencil_entries(self) -> int:
        """Sum over elements of the stencil size squared (assembly work)."""
        return int((self.stencil_sizes.astype(np.int64) ** 2).sum())


class NaturalNeighbourBasis(NaturalNeighbourBasisBase):
    """Natural-neighbour (Sibson or Laplace) trial functions on a ``MeshTri`` or
    a Delaunay ``MeshTet``.

    Parameters
    ----------
    mesh
        A ``MeshTri`` (any triangles: the functions come from the Delaunay
        triangulation of its nodes, constrained by its boundary if the domain is
        not convex and by the segments of :func:`delaunay_mesh`), or a
        ``MeshTet`` whose tetrahedra are Delaunay (build it with
        :func:`delaunay_mesh`; checked, a ``ValueError`` says how to fix it).
    elem
        ``ElementNaturalNeighbour()`` (default) or
        ``ElementVector(ElementNaturalNeighbour())``; dofs are numbered as
        scikit-fem numbers them for these elements (node i's dofs for the
        vector case are ``dim i, ..., dim i + dim - 1``, named ``u^1``,
        ``u^2``, ...). On a ``MeshTet`` the tetrahedron variant
        :class:`ElementTetNaturalNeighbour` is used (same numbering).
    integration
        ``"smoothed"`` (the default when no Gauss rule is given): gradients
        smoothed over cells, the boundary integral of each function times the
        normal over the cell's area (:mod:`skfem_nem.basis.smoothing`). Three cells
        per triangle (one at each vertex, one integration point each: the
        3-point rule's points, weights ``|T|/3``) or one per tetrahedron (its
        four vertices, 1/20 of its volume each, where the values are known,
        and its centroid, 4/5: one coordinate query). Consistent: the linear
        patch test passes to round-off and
        the rates are optimal. ``"gauss"``: values and exact gradients at the
        points of a Gauss rule (``intorder``, ``npoints``, ``quadrature``;
        default the 3-point rule on triangles, 4 points on tetrahedra); not
        exact for natural-neighbour functions, so not consistent.
    intorder, npoints, quadrature
        A Gauss rule per cell (implies ``integration="gauss"`` unless
        ``integration="smoothed"`` is given on tetrahedra: then the rule's
        points carry the values and share the tetrahedron's smoothed gradient): scikit-fem's
        integration order (on tetrahedra: 2 -> 4 points, 3 -> 6, 4 -> 11), or
        on triangles the number of points (1, 3, 4, 6, 7, 12, 13; 4 and 13
        have a negative weight), or an explicit ``(X, W)`` pair on the
        reference cell.
    coordinates
        ``"sibson"`` (default) or ``"laplace"`` (2D area method only).
    method
        ``"area"`` (2D default: the area method, the paper's method 1) or
        ``"lasserre"`` (Box 1, method 2; the only one on tetrahedra).

    With smoothed integration, ``interpolate(u)`` gives the values at the
    integration points and the smoothed gradients (the gradient the forms
    see); for the exact gradient of the field at points use a Gauss basis
    (e.g. ``npoints=7``, as for error norms).

    Everything a ``CellBasis`` offers for assembly works: forms, ``asm``,
    ``get_dofs``, ``interpolate``, ``project``, ``probes``, ``plot``. Trial
    and test bases may be mixed with scikit-fem ``CellBasis`` objects on the
    same mesh and quadrature.

    Examples
    --------
    >>> import numpy as np
    >>> from skfem import BilinearForm, Functional
    >>> from skfem.helpers import dot, grad
    >>> from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
    >>> nodes = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> basis = NaturalNeighbourBasis(delaunay_mesh(nodes))
    >>> basis.integration, int(basis.N)                # one function per node
    ('smoothed', 5)
    >>> @BilinearForm
    ... def laplace(u, v, w):
    ...     return dot(grad(u), grad(v))
    >>> A = laplace.assemble(basis)
    >>> A.shape, bool(np.allclose(A @ np.ones(5), 0))   # constants in the kernel
    ((5, 5), True)
    >>> @Functional
    ... def area(w):
    ...     return 1.0 + 0.0 * w.x[0]
    >>> round(float(area.assemble(basis)), 12)
    1.0
    """

    def __init__(self, mesh: MeshTri | MeshTet, elem: Optional[Element] = None,
                 intorder: Optional[int] = None,
                 quadrature: Optional[Tuple[ndarray, ndarray]] = None,
                 npoints: Optional[int] = None, coordinates: str = "sibson",
                 method: Optional[str] = None, integration: Optional[str] = None,
                 elements=None, mapping=None, dofs=None, disable_doflocs: bool = False):
        refuse_keywords("NaturalNeighbourBasis", mapping=mapping, dofs=dofs)
        self._setup(mesh, elem, intorder, quadrature, npoints, coordinates, method,
                    integration, elements, disable_doflocs)
        elems = np.arange(self.nelems) if self.tind is None else self.tind
        self._set_functions(*self._functions(elems), self.nelems, self.X.shape[1])

    def _setup(self, mesh, elem=None, intorder=None, quadrature=None, npoints=None,
               coordinates="sibson", method=None, integration=None, elements=None,
               disable_doflocs=False):
        """Everything but the functions: checks, triangulation, scikit-fem's mapping and
        dofs, the quadrature and its weights ``dx``."""
        elem = element_for(mesh, elem, "NaturalNeighbourBasis")
        check_used_nodes(mesh, "NaturalNeighbourBasis")
        self.method = coordinate_method(mesh, coordinates, method)
        self.integration = integration_scheme(integration, npoints, intorder, quadrature,
                                              mesh.dim())
        self.triangulation = adopt(mesh, self.method)
        self.coordinates = coordinates
        if self.integration == "smoothed" and intorder is None and quadrature is None:
            rule = value_rule(mesh.dim())
        else:
            rule = gauss_rule(npoints, intorder, quadrature, mesh.refdom)
        with np.errstate(divide="ignore", invalid="ignore"):
            # (flat cells have no inverse mapping; only F and detDF are used)
            super().__init__(mesh, elem, None, None, rule, mesh.refdom,
                             disable_doflocs=disable_doflocs)
            # a subdomain basis: sorted element indices (the smoothing cells are
            # numbered in this order)
            self.tind = None if elements is None else normalize_elements(mesh, elements)
            self.nelems = mesh.nelements if self.tind is None else self.tind.size
            if self.nelems == 0:
                raise ValueError(f"elements={elements!r} selects no element")
            self.dx = np.abs(self.mapping.detDF(self.X, tind=self.tind)) * np.broadcast_to(
                self.W, (self.nelems, self.W.shape[-1]))

    def _functions(self, elems, positions=None):
        """Values (CSR, nq rows per element) and gradients (dim, nnz) at the quadrature
        points of the mesh's elements ``elems`` (sorted), at ``positions`` on the basis'
        element axis (default all)."""
        pos = slice(None) if positions is None else positions
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.mapping.F(self.X, tind=elems)
        if self.integration == "gauss":
            return self._build(x, elems, self.dx[pos])
        if self.order == 2:
            return smoothed_quadratic(self.mesh, self._coordinates, x, self.dx[pos], elems)
        nq = self.X.shape[1]
        # 2D: point q of a triangle lies in the cell of its vertex q;
        # 3D: one cell per tetrahedron
        if self.mesh.dim() == 2:
            return self._build_smoothed(x, elems, np.arange(elems.size * nq))
        vert = vertex_points(self.X)
        nodal = np.where(vert >= 0, self.mesh.t[np.maximum(vert, 0)][:, elems].T, -1)
        return self._build_smoothed(x, elems, np.repeat(np.arange(elems.size), nq),
                                    nodal.ravel())

    def updated(self, mesh: MeshTri) -> "NaturalNeighbourBasis":
        """This basis on ``mesh``, a later state of its mesh (nodes moved, added or taken
        out, triangles flipped or split: an evolving mesh's next step), recomputing the
        functions only in the triangles whose stencils may have changed and copying the
        others' (:mod:`skfem_nem.basis.updates` says which, and why that is exact).

        Equal to ``NaturalNeighbourBasis(mesh, ...)`` with the same keywords to round-off.
        Both meshes must be their own (constrained) Delaunay triangulations, with or
        without segments, and this basis a 2D one on all the mesh's triangles (else
        ``ValueError`` naming what differs). ``update_report`` of the new basis:
        ``recomputed`` and ``kept`` triangles, the seconds of the recomputation
        (``recompute_seconds``, O(recomputed)) and of the whole update (``seconds``: with
        the O(triangles) copies and the new mesh's scikit-fem mapping and dofs)."""
        start = time.perf_counter()
        reason = self.update_obstacle(mesh)
        if reason is not None:
            raise ValueError(reason)
        new = self._unfilled(mesh, hints_ok=True)  # checked by update_obstacle
        old_c, new_c, marked = updates.changed_triangles(
            self.mesh.p.T, self.mesh.t.T, mesh.p.T, mesh.t.T)
        marked[updates.segment_change(self.triangulation, new.triangulation)] = True
        keep = updates.kept_elements(self.stencil_ptr, self.stencil_nodes, old_c, new_c,
                                     marked)
        redo = np.flatnonzero(~keep)
        nq = self.X.shape[1]
        t0 = time.perf_counter()
        part = new._functions(redo, redo) if redo.size else None
        t1 = time.perf_counter()
        Phi, grad = updates.splice_rows(keep, nq, (self.values_matrix, self.gradient_entries),
                                        part, mesh.nvertices)
        new._set_functions(Phi, grad, mesh.nelements, nq)
        new.kept_elements, new.update_source = keep, weakref.ref(self)
        new.update_report = {"recomputed": int(redo.size), "kept": int(keep.sum()),
                             "recompute_seconds": t1 - t0,
                             "seconds": time.perf_counter() - start}
        return new

    def update_obstacle(self, mesh) -> Optional[str]:
        """Why :meth:`updated` cannot move this basis to ``mesh`` (a sentence), or None."""
        return updates.obstacle(self, mesh)

    def global_coordinates(self) -> DiscreteField:
        # cached here: scikit-fem's own cache attributes differ between versions
        if self.__dict__.get("_x_field") is None:
            self._x_field = DiscreteField(self.mapping.F(self.X, tind=self.tind))
        return self._x_field

    def mesh_parameters(self) -> DiscreteField:
        if self.__dict__.get("_h_field") is None:
            self._h_field = DiscreteField(
                np.abs(self.mapping.detDF(self.X, tind=self.tind)) ** (1.0 / self.mesh.dim()))
        return self._h_field

    def with_element(self, elem: Element):
        """The same mesh, elements and quadrature with another element: a natural-neighbour
        element gives a natural-neighbour basis; a scikit-fem element (``ElementTriP0()``,
        ``ElementTriP1()``, their ``ElementVector``, ...) an ordinary ``CellBasis`` at the
        very same quadrature points, for piecewise coefficients and projections that combine
        with forms on this basis."""
        if not is_natural_neighbour(elem):
            return companion_basis(self, elem)
        return type(self)(self.mesh, elem, **self.construction_keywords())

    def with_elements(self, elements=None) -> "NaturalNeighbourBasis":
        """The same element and integration on a subset of the mesh's elements (or all)."""
        return type(self)(self.mesh, self.elem, **{**self.construction_keywords(),
                                                   "elements": elements})

    def _unfilled(self, mesh, hints_ok: bool, **keywords) -> "NaturalNeighbourBasis":
        """A basis like this one on ``mesh`` (with ``keywords`` replacing its construction
        keywords) whose functions the caller fills in."""
        out = type(self).__new__(type(self))
        out._setup(mesh, self.elem, **{**self.construction_keywords(), **keywords})
        out._hints_ok = hints_ok
        return out

    def subset(self, elements) -> "NaturalNeighbourBasis":
        """:meth:`with_elements` without computing anything: the subdomain basis on
        ``elements`` (of a basis on all the mesh's triangles) takes this basis' functions
        there, copied (for :func:`~skfem_nem.basis.updates.updated_matrix`)."""
        if self.tind is not None:
            raise ValueError("subset() of a subdomain basis: take the subset of the basis "
                             "on all the mesh's triangles")
        sub = self._unfilled(self.mesh, self._hints_valid(), elements=elements)
        nq = self.X.shape[1]
        Phi, G = updates.gather_rows(sub.tind, nq, self.values_matrix, self.gradient_entries)
        sub._set_functions(Phi, G, sub.nelems, nq)
        return sub

    def construction_keywords(self) -> dict:
        """The keywords that rebuild this basis (coordinates, method, integration, rule,
        elements) with another element."""
        X, W = value_rule(self.mesh.dim())
        default = self.integration == "smoothed" and self.X.shape == X.shape and \
            np.array_equal(self.X, X) and np.array_equal(self.W, W)
        # (a smoothed basis on tetrahedra may carry its values at a Gauss rule's points)
        rule = {} if default else {"quadrature": self.quadrature}
        return {"coordinates": self.coordinates, "method": self.method,
                "integration": self.integration, "elements": self.tind, **rule}

    def boundary(self, facets=None, intorder: Optional[int] = None, quadrature=None):
        """The :class:`NaturalNeighbourFacetBasis` of ``facets`` (default the boundary),
        with this basis' element, coordinates and integration scheme."""
        if self.tind is not None:
            raise NotImplementedError("the boundary of a subdomain basis: build "
                                      "NaturalNeighbourFacetBasis(mesh, facets=...) with the "
                                      "subdomain's boundary facets")
        from .facet_basis import NaturalNeighbourFacetBasis
        return NaturalNeighbourFacetBasis(
            self.mesh, self.elem, facets=facets, intorder=intorder, quadrature=quadrature,
            coordinates=self.coordinates, method=self.method, integration=self.integration)

    def split_bases(self):
        if isinstance(self.elem, ElementVector):
            return [self.with_element(self.elem.elem) for _ in range(self.elem.dim)]
        return [self]

    # -- evaluation at arbitrary points ----------------------------------------
    def probes(self, x: ndarray):
        """Sparse matrix mapping a dof vector to its values at points x (dim, m).

        Scalar: shape (m, N). Vector: (dim * m, N), component-major rows, as
        scikit-fem's ``CellBasis.probes``. Points outside the domain (outside the
        convex hull, or in a hole or the notch of a non-convex 2D domain) raise
        ``ValueError`` naming the first.
        """
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[0] != self.mesh.dim():
            raise ValueError(f"points must have shape ({self.mesh.dim()}, m), got {x.shape}")
        if self.mesh.dim() == 2:
            _, out = into_domain(self.mesh, x.T)
            if out.size:
                raise ValueError(f"point {out[0]} at {x[:, out[0]].tolist()} is outside the "
                                 f"domain of the mesh ({out.size} such point(s))")
        Phi = self._coordinates(x.T, undefined="raise")
        if self.order == 2:
            Phi, _ = quadratic.lift(self.mesh, Phi)
        import scipy.sparse as sp
        nd = self.function_dofs
        blocks = [Phi @ sp.csr_matrix((np.ones(nd.shape[1]), (np.arange(nd.shape[1]), nd[c])),
                                      shape=(nd.shape[1], self.N)) for c in range(nd.shape[0])]
        return sp.vstack(blocks, format="csr") if len(blocks) > 1 else blocks[0]

    def interpolator(self, y: ndarray):
        """A function x (dim, ...) -> values of the dof vector y at x."""
        def f(x):
            x = np.asarray(x, dtype=float)
            shape = x.shape[1:]
            out = self.probes(x.reshape(x.shape[0], -1)) @ y
            if isinstance(self.elem, ElementVector):
                return out.reshape((self.elem.dim,) + shape)
            return out.reshape(shape)
        return f

    def point_source(self, x: ndarray) -> ndarray:
        return self.probes(np.asarray(x, dtype=float)[:, None]).toarray()[0]

    def project(self, interp, elements=None, dtype=None) -> ndarray:
        """L2 projection of ``interp`` (callable of x, DiscreteField, array or tuple of
        components at the quadrature points, or a number) onto the basis; returns a dof
        vector.

        ``elements`` (indices, a boolean mask, a callable of the midpoints or a subdomain
        name, as in scikit-fem) projects on those triangles' functions only: the dofs of
        the nodes in their stencils; the other dofs are zero. A subdomain basis projects on
        the functions that are non-zero on its own triangles. ``dtype``: real projections
        only (``None`` or a float type)."""
        keep = None
        if elements is not None or self.tind is not None:
            pos = (np.arange(self.nelems) if elements is None
                   else self.element_positions(elements))
            keep = projection_dofs(self, pos)
        return l2_project(self, interp, keep, dtype)

    def stencil_dofs(self, elements) -> ndarray:
        """The dofs of the functions that are non-zero on ``elements`` (indices, a boolean
        mask over the mesh's triangles, a callable of their midpoints or a subdomain name;
        of a subdomain basis' own triangles): the nodes of their stencils, every component
        of a vector basis."""
        return stencil_dofs(self, self.element_positions(elements))

    def element_positions(self, elements) -> ndarray:
        """Positions on the basis' element axis of the mesh's ``elements`` (anything
        ``elements=`` accepts); for a subdomain basis they must be among its own."""
        e = normalize_elements(self.mesh, elements)
        return e if self.tind is None else positions_in(self.tind, e, "element")

    def refinterp(self, y: ndarray, nrefs: int = DEFAULT_NREFS, Nrefs: Optional[int] = None):
        """A refined MeshTri and the values of y at its nodes (for plotting; 2D): the
        natural-neighbour field itself, component-major for a vector basis
        (:func:`~skfem_nem.basis.plotting.refined_values`). ``Nrefs`` is scikit-fem's
        older name of ``nrefs``."""
        return refined_values(self, y, nrefs if Nrefs is None else Nrefs)

    def plot(self, x, visuals: str = "matplotlib", **kwargs):
        """scikit-fem's ``plot`` of the dof vector ``x``: the natural-neighbour field on
        refined triangles (``nrefs``, default 2; Gouraud shading unless ``shading`` is
        given), with the keywords of scikit-fem's ``MeshTri`` plot (``ax``, ``colorbar``,
        ``vmin``, ``levels``, ...); arrows for a 2D vector basis, as scikit-fem."""
        return visuals_call(self, "plot", visuals, x, **kwargs)

    def plot3(self, x, visuals: str = "matplotlib", **kwargs):
        """scikit-fem's ``plot3``: the surface of a scalar field on refined triangles."""
        return visuals_call(self, "plot3", visuals, x, **kwargs)

    def draw(self, visuals: str = "matplotlib", **kwargs):
        """scikit-fem's ``draw`` of a basis: the outline of its triangles."""
        return visuals_call(self, "draw", visuals, **kwargs)
