"""Scikit-fem meshes for natural-neighbour bases: built, checked, adopted.

Natural-neighbour functions are defined by the Delaunay triangulation of the
nodes, not by a mesh's cells, so a basis first *adopts* its mesh: it checks
that the cells are Delaunay (the quadrature lives on them, the coordinates on
the triangulation) and caches on the mesh the triangulation the coordinates
are computed on. :func:`delaunay_mesh` builds a mesh that passes the check
by construction.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.spatial import Delaunay
from skfem import MeshTet, MeshTri

from .delaunay_nd import delaunay_of
from .triangulation import Triangulation, unused_nodes, validate_nodes

__all__ = ["adopt", "delaunay_mesh", "triangulation_of"]


def delaunay_mesh(points) -> MeshTri | MeshTet:
    """The Delaunay triangulation of points as a scikit-fem mesh.

    (n, 2) points give a ``MeshTri`` (robust 2D triangulation,
    :class:`~skfem_nem.Triangulation`), (n, 3) points a ``MeshTet`` (Qhull,
    :class:`scipy.spatial.Delaunay`). Node i of the mesh is ``points[i]``:
    nothing is reordered or dropped, every node is a vertex of some
    triangle or tetrahedron. Raises ``ValueError`` for bad points (non-finite,
    too few, duplicate, all collinear or coplanar) and for points Qhull would
    drop (nearly coincident with others), naming the point.

    For co-spherical 3D points (lattices) Qhull glues its triangulations of
    the co-spherical cells with flat (zero-volume) tetrahedra; they are kept
    (the natural-neighbour basis gives their quadrature points zero weight),
    but scikit-fem's Lagrange elements cannot be used on such a mesh.

    Examples
    --------
    >>> import numpy as np
    >>> from skfem_nem import delaunay_mesh
    >>> points = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.], [0.5, 0.4]])
    >>> mesh = delaunay_mesh(points)
    >>> type(mesh).__name__, mesh.t.shape
    ('MeshTri1', (3, 4))
    >>> bool((mesh.p.T == points).all())   # node i is points[i]
    True
    >>> cube = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]
    >>> tets = delaunay_mesh(np.array(cube, dtype=float))
    >>> type(tets).__name__, tets.t.shape
    ('MeshTet1', (4, 3))
    """
    shape = np.shape(points)
    if len(shape) == 2 and shape[1] == 3:
        p = validate_nodes(points, dim=3, name="points")
        tri = delaunay_of(p)
        mesh = MeshTet(np.ascontiguousarray(p.T),
                       np.ascontiguousarray(tri.simplices.T, dtype=np.int64))
        mesh._skfem_nem_triangulation = tri
        return mesh
    tri = Triangulation(points)
    return MeshTri(np.ascontiguousarray(tri.nodes.T), np.ascontiguousarray(tri.triangles.T))


def _check_used(p, t, what):
    unused = unused_nodes(p.shape[0], t)
    if unused.size:
        i = int(unused[0])
        raise ValueError(
            f"mesh node {i} at {p[i].tolist()} belongs to no {what}, so no trial function "
            f"would be defined there ({unused.size} such node(s)); build the mesh "
            f"with skfem_nem.delaunay_mesh(points)")


def _tet_delaunay(mesh: MeshTet) -> Delaunay:
    """Qhull's Delaunay triangulation of a ``MeshTet``'s nodes, after checking
    that the mesh's own tetrahedra are Delaunay (the coordinates are computed
    on Qhull's tetrahedra: where several Delaunay triangulations exist, as for
    co-spherical nodes, all give the same natural-neighbour coordinates)."""
    p, t = mesh.p.T, mesh.t.T
    _check_used(p, t, "tetrahedron")
    tri = delaunay_of(np.ascontiguousarray(p))
    same = np.array_equal(np.unique(np.sort(tri.simplices, axis=1), axis=0),
                          np.unique(np.sort(t, axis=1), axis=0))
    if tri.simplices.shape[0] == t.shape[0] and same:
        return tri
    # another triangulation: local empty-sphere test across every interior face
    f2t = mesh.f2t
    inner = np.flatnonzero(f2t[1] >= 0)
    a, b = f2t[0, inner], f2t[1, inner]
    face = mesh.facets[:, inner]
    tb = t[b]
    opp = tb[~(tb[:, :, None] == face.T[:, None, :]).any(axis=2)]
    V = p[t[a]]                                   # (k, 4, 3)
    w = V - p[opp][:, None, :]
    lifted = np.concatenate([w, (w ** 2).sum(axis=2, keepdims=True)], axis=2)
    insph = np.linalg.det(lifted)
    orient = np.linalg.det(V[:, 1:] - V[:, :1])
    scale = np.abs(w).max(axis=(1, 2)) ** 5
    bad = np.flatnonzero(-insph * np.sign(orient) > 1e-10 * scale)
    if bad.size:
        raise ValueError(
            f"the mesh is not a Delaunay tetrahedralisation ({bad.size} interior face(s) fail "
            f"the in-sphere test; first: tetrahedra {int(a[bad[0]])} and {int(b[bad[0]])}); "
            f"natural-neighbour trial functions need one: build the mesh with "
            f"skfem_nem.delaunay_mesh(points)")
    return tri


def triangulation_of(mesh: MeshTri | MeshTet) -> Triangulation | Delaunay:
    """The triangulation the coordinates of a mesh are computed on, checked to
    be Delaunay and cached on the mesh: for a ``MeshTri`` its
    :class:`~skfem_nem.Triangulation` (same triangle order), for a
    ``MeshTet`` a :class:`scipy.spatial.Delaunay` of its nodes."""
    cached = getattr(mesh, "_skfem_nem_triangulation", None)
    if cached is not None:
        return cached
    if isinstance(mesh, MeshTet):
        tri = _tet_delaunay(mesh)
        mesh._skfem_nem_triangulation = tri
        return tri
    if not isinstance(mesh, MeshTri):
        raise TypeError(f"natural-neighbour bases need a MeshTri or a MeshTet, got "
                        f"{type(mesh).__name__}")
    p, t = mesh.p.T, mesh.t.T
    _check_used(p, t, "triangle")
    tri = Triangulation.from_triangles(p, t, make_delaunay=False)
    bad = tri.non_delaunay_edges()
    if bad:
        raise ValueError(
            f"the mesh is not a Delaunay triangulation ({bad} edge(s) fail the in-circle "
            f"test); natural-neighbour trial functions need one: build the mesh with "
            f"skfem_nem.delaunay_mesh(points)")
    he = tri.hull_edges
    # convex boundary? each boundary vertex must turn left (or go straight)
    nxt = {int(a): int(b) for a, b in he}
    P = tri.nodes
    a = he[:, 0]
    b = he[:, 1]
    c = np.array([nxt.get(int(v), -1) for v in b])
    if (c < 0).any():
        warnings.warn("the mesh boundary is not a single closed curve; natural-neighbour "
                      "coordinates assume the domain is the convex hull of the nodes",
                      stacklevel=3)
    else:
        turn = ((P[b, 0] - P[a, 0]) * (P[c, 1] - P[a, 1])
                - (P[b, 1] - P[a, 1]) * (P[c, 0] - P[a, 0]))
        if (turn < -1e-12 * np.ptp(P, axis=0).max() ** 2).any():
            v = int(b[np.argmin(turn)])
            warnings.warn(
                f"the mesh boundary is not convex (e.g. at node {v}); Sibson/Laplace "
                f"functions are then not interpolating along the concave part of the "
                f"boundary (a known NEM limitation)", stacklevel=3)
    mesh._skfem_nem_triangulation = tri
    return tri


def adopt(mesh, method):
    """The triangulation a basis on ``mesh`` queries with ``method`` (cached)."""
    tri = triangulation_of(mesh)
    if method == "lasserre" and isinstance(tri, Triangulation):
        cached = getattr(mesh, "_skfem_nem_delaunay", None)
        if cached is None:
            cached = delaunay_of(np.ascontiguousarray(tri.nodes))
            mesh._skfem_nem_delaunay = cached
        return cached
    return tri
