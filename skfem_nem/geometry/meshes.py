"""Scikit-fem meshes for natural-neighbour bases: built, checked, adopted.

Natural-neighbour functions are defined by the Delaunay triangulation of the
nodes, not by a mesh's cells, so a basis first *adopts* its mesh: it checks
that the cells are Delaunay (the quadrature lives on them, the coordinates on
the triangulation) and caches on the mesh the triangulation the coordinates
are computed on. :func:`delaunay_mesh` builds a mesh that passes the check
by construction; given segments, it builds the constrained Delaunay
triangulation (interfaces, outlines, the boundary of a non-convex domain),
names the segments as the mesh's boundaries and drops the triangles of holes.

The triangulation is cached on the mesh and, by the digest of its nodes and
triangles, for every mesh with the same nodes and triangles: scikit-fem's
``with_boundaries`` and ``with_subdomains`` return new mesh objects, which
find their constrained triangulation there instead of losing the segments.
"""
from __future__ import annotations

import hashlib
import weakref

import numpy as np
from skfem import MeshTet, MeshTri

from .constrained import check_segments, flood_regions, pair_keys
from .delaunay3d import Delaunay3D
from .delaunay_nd import delaunay_of
from .entities import prime_facets
from .predicates import orient2d
from .triangulation import Triangulation, unused_nodes, validate_nodes
from .walls3d import face_keys

__all__ = ["adopt", "delaunay_mesh", "outside_domain", "tetrahedron_neighbours",
           "triangulation_mesh", "triangulation_of"]


# the constrained triangulations of delaunay_mesh(points, segments=...) by the digest of
# the mesh's (nodes, triangles), kept while a mesh holds them (weakly referenced: the cache
# on each mesh is the strong reference), and the named boundaries (segment facets) that a
# mesh must carry to be given one: a plain mesh with the same nodes and triangles is not
_BY_DIGEST: "weakref.WeakValueDictionary[str, object]" = weakref.WeakValueDictionary()
_NAMED: "weakref.WeakKeyDictionary[object, dict]" = weakref.WeakKeyDictionary()
# the triangles of a mesh's triangulation that lie outside the mesh (holes, the notch of a
# non-convex domain): walls for the coordinates, outside for point queries
_VOID: "weakref.WeakKeyDictionary[Triangulation, np.ndarray]" = weakref.WeakKeyDictionary()


def _digest(p, t) -> str:
    h = hashlib.blake2b(digest_size=16)
    for a in (p, t):
        a = np.ascontiguousarray(a)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _cache(mesh, tri, void=None, named=None):
    """Cache ``tri`` on the mesh; ``void``: its triangles outside the mesh; ``named``:
    the mesh's segment boundaries (name -> facets), which identify meshes derived from
    it by scikit-fem (``with_boundaries``, ``with_subdomains``)."""
    mesh._skfem_nem_triangulation = tri
    if isinstance(tri, Triangulation) and void is not None and void.any():
        _VOID[tri] = void
    if named:
        _BY_DIGEST[_digest(mesh.p, mesh.t)] = tri
        _NAMED[tri] = named
    return mesh


def _registered(mesh):
    """The constrained triangulation of the mesh ``mesh`` was derived from, if any."""
    tri = _BY_DIGEST.get(_digest(mesh.p, mesh.t))
    if tri is None:
        return None
    have = mesh._boundaries or {}
    for name, facets in _NAMED.get(tri, {}).items():
        if name not in have or not np.array_equal(np.asarray(have[name]), facets):
            return None
    return tri


def outside_domain(mesh, x) -> np.ndarray:
    """Indices of the points x (m, 2) that lie outside a 2D mesh's domain but inside
    the convex hull of its nodes: in a hole or in the notch of a non-convex domain
    (points on the domain's boundary are inside). Points outside the hull are left
    to the coordinates, which report them."""
    tri = triangulation_of(mesh)
    void = _VOID.get(tri) if isinstance(tri, Triangulation) else None
    if void is None:
        return np.empty(0, dtype=np.int64)
    x = np.asarray(x, dtype=np.float64).reshape(-1, 2)
    t = tri.locate(x)
    cand = np.flatnonzero(t >= 0)
    cand = cand[void[t[cand]]]
    return np.array([i for i in cand if not _on_domain(tri, void, int(t[i]), x[i])],
                    dtype=np.int64)


def _on_domain(tri, void, t, x):
    """True if x, in the closed void triangle t, is a node or on an edge that t shares
    with a triangle of the domain."""
    P, T, N = tri.nodes, tri.triangles, tri.neighbours
    if (P[T[t]] == x).all(axis=1).any():
        return True
    for k in range(3):
        a, b = T[t, (k + 1) % 3], T[t, (k + 2) % 3]
        u = N[t, k]
        if u >= 0 and not void[u] and orient2d(*P[a], *P[b], *x) == 0.0:
            return True
    return False


def delaunay_mesh(points, segments=None, holes=None, faces=None) -> MeshTri | MeshTet:
    """The Delaunay triangulation of points as a scikit-fem mesh.

    (n, 2) points give a ``MeshTri`` (robust 2D triangulation,
    :class:`~skfem_nem.Triangulation`), (n, 3) points a ``MeshTet`` (exact 3D
    tetrahedralisation, :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D`).
    Node i of the mesh is ``points[i]``: nothing is reordered or dropped, every
    node is a vertex of some triangle or tetrahedron. Raises ``ValueError`` for
    bad points (non-finite, too few, duplicate, all collinear or coplanar),
    naming the point.

    Co-spherical 3D points (lattices, nodes on a box's walls) are split into
    tetrahedra by a symbolic perturbation: no flat (zero-volume) tetrahedra, so
    scikit-fem's Lagrange elements work on such a mesh too. (A ``MeshTet`` of
    Qhull's tetrahedra, which keeps flat ones, is accepted by the natural-neighbour
    bases, which give their quadrature points zero weight.)

    Segments (2D)
        ``segments``: (k, 2) pairs of node indices, or a dict of such arrays by
        name, that must be edges: the mesh is then the constrained Delaunay
        triangulation, and natural-neighbour bases on it use constrained
        coordinates (the natural neighbours of a point are the nodes it sees
        without crossing a segment: functions kink across an interface and
        interpolate along it). Each name (``"segments"`` for an array) becomes a
        named boundary of the mesh, ``mesh.boundaries[name]``: the facets along
        those segments, interior ones included (a facet basis on them integrates
        over an interface). A node lying on a segment splits it; crossing
        segments raise ``ValueError`` naming both. ``holes``: (h, 2) points; the
        triangles of each region (bounded by segments) holding a hole point are
        left out of the mesh (the notch of an L-shaped domain, a slit), but stay in
        the triangulation the coordinates are computed on, as walls.

    Faces (3D)
        ``faces``: (k, 3) triples of node indices, or a dict of such arrays by name,
        that are walls for natural neighbours (:mod:`~skfem_nem.geometry.walls3d`): the
        conflict region of a point stops at them, so functions kink across a material
        interface and are linear on it. Each triangle must already be a face of the
        Delaunay tetrahedra (sample the surface more finely than the nodes beside it);
        the first that is not raises :class:`~skfem_nem.geometry.walls3d.MissingFace`
        (a ``ValueError``) naming it. Each name (``"faces"`` for an array) becomes a named
        boundary of the mesh, ``mesh.boundaries[name]``: the facets of its triangles.

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
    >>> type(tets).__name__, tets.t.shape     # (the 5 points are co-spherical)
    ('MeshTet1', (4, 2))

    An L-shaped domain: the boundary as segments, the notch as a hole.

    >>> L = np.array([[0, 0], [1, 0], [1, .5], [.5, .5], [.5, 1], [0, 1]], float)
    >>> outline = [[i, (i + 1) % 6] for i in range(6)]
    >>> m = delaunay_mesh(L, segments={"outline": outline}, holes=[[.75, .75]])
    >>> m.t.shape[1], sorted(m.boundaries)       # 4 triangles: the notch is left out
    (4, ['outline'])
    """
    shape = np.shape(points)
    if (segments is not None or holes is not None) and not (len(shape) == 2 and shape[1] == 2):
        raise ValueError("segments and holes are supported for 2D points only")
    if faces is not None and not (len(shape) == 2 and shape[1] == 3):
        raise ValueError("faces are supported for 3D points only (2D: segments)")
    if len(shape) == 2 and shape[1] == 2 and (segments is not None or holes is not None):
        return _constrained_mesh(points, segments, holes)
    if len(shape) == 2 and shape[1] == 3:
        p = validate_nodes(points, dim=3, name="points")
        tri = delaunay_of(p)
        if faces is not None:
            return _walled_mesh(p, tri, faces)
        return _cache(_tet_mesh(p, tri.simplices), tri)
    tri = Triangulation(points)
    return MeshTri(np.ascontiguousarray(tri.nodes.T), np.ascontiguousarray(tri.triangles.T))


def triangulation_mesh(tri: Triangulation | Delaunay3D) -> MeshTri | MeshTet:
    """The ``MeshTri`` of a :class:`~skfem_nem.Triangulation` (same nodes, same
    triangles in the same order) with ``tri`` cached as its triangulation: bases on
    it use ``tri`` as it is, segments (constrained coordinates) included. ``tri``
    must not change afterwards: pass a copy of one that will. For a
    :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` the ``MeshTet`` of its
    tetrahedra (same order), which a moving 3D mesh repairs instead of rebuilding."""
    if isinstance(tri, Delaunay3D):
        return _cache(_tet_mesh(tri.points, tri.simplices), tri)
    mesh = MeshTri(np.ascontiguousarray(tri.nodes.T), np.ascontiguousarray(tri.triangles.T),
                   sort_t=False)
    return _cache(mesh, tri)


def _tet_mesh(p: np.ndarray, simplices: np.ndarray) -> MeshTet:
    """The ``MeshTet`` of nodes ``p`` (n, 3) and tetrahedra ``simplices`` (m, 4), its
    facets found at once by keys (:func:`~.entities.prime_facets`): every natural-neighbour
    basis on it needs them (the smoothing cells), and scikit-fem's own search was the
    slowest part of a 3D basis's set-up."""
    mesh = MeshTet(np.ascontiguousarray(p.T), np.ascontiguousarray(simplices.T, dtype=np.int64))
    prime_facets(mesh)
    return mesh


def _walled_mesh(p, tri, faces):
    """:func:`delaunay_mesh` with walls (3D): the mesh named by its walls' facets."""
    named = faces if isinstance(faces, dict) else {"faces": faces}
    for name in named:
        if not isinstance(name, str):
            raise ValueError(f"face names must be strings, got {name!r}")
    slots = tri.wall_off(named)
    mesh = _tet_mesh(p, tri.simplices)
    n = p.shape[0]
    fk = face_keys(mesh.facets.T, n)
    order = np.argsort(fk)
    facets = {name: np.sort(order[np.searchsorted(fk[order], face_keys(
        np.asarray(f).reshape(-1, 3), n))]) for name, f in named.items()}
    if slots.any():
        mesh = mesh.with_boundaries(facets)
        prime_facets(mesh)
    return _cache(mesh, tri, named=facets)


def _named(segments, n):
    """The segments as a dict name -> (k, 2) int64 array (checked)."""
    if not isinstance(segments, dict):
        segments = {"segments": segments}
    out = {}
    for name, s in segments.items():
        if not isinstance(name, str):
            raise ValueError(f"segment names must be strings, got {name!r}")
        out[name] = check_segments(s, n, name=f"segments[{name!r}]")
    return out


def _kept_triangles(tri, holes):
    """(nt,) True for the triangles outside every region holding a hole point."""
    keep = np.ones(tri.ntriangles, dtype=bool)
    if holes is None:
        return keep
    h = np.array(holes, dtype=np.float64, ndmin=2)
    if h.size == 0:
        return keep
    if h.ndim != 2 or h.shape[1] != 2 or not np.isfinite(h).all():
        raise ValueError(f"holes must be finite points of shape (h, 2), got {np.shape(holes)}")
    seeds = tri.locate(h)
    bad = np.flatnonzero(seeds < 0)
    if bad.size:
        raise ValueError(f"holes[{bad[0]}] = {h[bad[0]].tolist()} is outside the convex hull "
                         f"of the points")
    label = flood_regions(tri.triangles, tri.neighbours, tri.segment_keys, seeds)
    keep = label < 0
    if not keep.any():
        raise ValueError("the holes take every triangle: the segments do not separate the "
                         "holes from the domain (is the outline closed?)")
    return keep


def _constrained_mesh(points, segments, holes):
    """:func:`delaunay_mesh` with segments and holes (2D)."""
    p = validate_nodes(points, name="points")
    named = _named(segments if segments is not None else {}, p.shape[0])
    allseg = np.concatenate([np.empty((0, 2), np.int64), *named.values()])
    tri = Triangulation(p, segments=allseg)
    keep = _kept_triangles(tri, holes)
    tri.reorder_triangles(np.argsort(~keep, kind="stable"))
    nkeep = int(keep.sum())
    t = tri.triangles[:nkeep]
    unused = unused_nodes(p.shape[0], t)
    if unused.size:
        i = int(unused[0])
        raise ValueError(f"points[{i}] = {p[i].tolist()} lies in a hole ({unused.size} such "
                         f"point(s)); remove it or move the hole")
    mesh = MeshTri(np.ascontiguousarray(p.T), np.ascontiguousarray(t.T))
    facets = _segment_facets(mesh, tri, named) if named else {}
    if facets:
        mesh = mesh.with_boundaries(facets)
    return _cache(mesh, tri, np.arange(tri.ntriangles) >= nkeep, facets)


def _segment_facets(mesh, tri, named):
    """Facet indices of the mesh along each name's segments (and their pieces)."""
    fkey = pair_keys(mesh.facets.T)
    order = np.argsort(fkey)
    first = np.cumsum([0] + [len(s) for s in named.values()])
    out = {}
    for r, name in enumerate(named):
        mine = (tri.segment_source >= first[r]) & (tri.segment_source < first[r + 1])
        keys = tri.segment_keys[mine]
        pos = np.searchsorted(fkey[order], keys).clip(0, fkey.size - 1)
        found = fkey[order][pos] == keys
        out[name] = np.sort(order[pos[found]])
    return out


def _check_used(p, t, what):
    unused = unused_nodes(p.shape[0], t)
    if unused.size:
        i = int(unused[0])
        raise ValueError(
            f"mesh node {i} at {p[i].tolist()} belongs to no {what}, so no trial function "
            f"would be defined there ({unused.size} such node(s)); build the mesh "
            f"with skfem_nem.delaunay_mesh(points)")


def _tet_delaunay(mesh: MeshTet) -> Delaunay3D:
    """The Delaunay tetrahedralisation (:class:`Delaunay3D`) of a ``MeshTet``'s nodes, after
    checking that the mesh's own tetrahedra are Delaunay (the coordinates are computed on
    ours: where several Delaunay triangulations exist, as for co-spherical nodes, all give
    the same natural-neighbour coordinates)."""
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


def triangulation_of(mesh: MeshTri | MeshTet) -> Triangulation | Delaunay3D:
    """The triangulation the coordinates of a mesh are computed on, cached on the
    mesh: for a ``MeshTet`` a :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` of its
    nodes (its tetrahedra checked to be Delaunay); for a ``MeshTri`` whose boundary is
    convex its own triangles as a :class:`~skfem_nem.Triangulation` (same order)
    if they are Delaunay, else the Delaunay triangulation of its nodes (a refined,
    smoothed or imported mesh keeps its triangles for integration; the functions
    depend on the nodes only); for a non-convex ``MeshTri`` (an L-shape, an
    annulus, a mesh read from gmsh) the constrained Delaunay triangulation of its
    nodes with its boundary facets as segments, so that no natural neighbour is
    seen through the outside."""
    cached = getattr(mesh, "_skfem_nem_triangulation", None)
    if cached is None and isinstance(mesh, (MeshTri, MeshTet)):
        cached = _registered(mesh)
        if cached is not None:
            mesh._skfem_nem_triangulation = cached
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
    if not _convex_boundary(tri):
        tri, void = _constrained_of(mesh)
        _cache(mesh, tri, void)
        return tri
    if tri.non_delaunay_edges():
        tri = Triangulation(np.ascontiguousarray(p))
    _cache(mesh, tri)
    return tri


def _convex_boundary(tri) -> bool:
    """True if the hull edges of the mesh's triangles form one closed convex curve
    (else the domain is not the convex hull of its nodes)."""
    he = tri.hull_edges
    nxt = {int(a): int(b) for a, b in he}
    P = tri.nodes
    a, b = he[:, 0], he[:, 1]
    c = np.array([nxt.get(int(v), -1) for v in b])
    if (c < 0).any() or len(nxt) != len(he):
        return False
    # one loop: follow it from the first edge
    v, seen = int(a[0]), 0
    while True:
        v, seen = nxt[v], seen + 1
        if v == int(a[0]) or seen > len(he):
            break
    if seen != len(he):
        return False
    turn = np.array([orient2d(*P[i], *P[j], *P[k]) for i, j, k in zip(a, b, c)])
    return bool((turn >= 0).all())


def _constrained_of(mesh):
    """The constrained Delaunay triangulation of a non-convex mesh's nodes with its
    boundary facets as segments, and the mask of its triangles outside the mesh: the
    natural neighbours of a point are then the nodes it sees inside the domain."""
    p = np.ascontiguousarray(mesh.p.T)
    tri = Triangulation(p, segments=mesh.facets[:, mesh.boundary_facets()].T)
    label = flood_regions(tri.triangles, tri.neighbours, tri.segment_keys,
                          np.arange(tri.ntriangles))
    regions, first = np.unique(label, return_index=True)
    centroids = tri.nodes[tri.triangles[first]].mean(axis=1)
    inside = _in_mesh(mesh, centroids)
    return tri, ~inside[np.searchsorted(regions, label)]


def _in_mesh(mesh, x):
    """(m,) True for the points x (m, 2) inside some triangle of the mesh."""
    V = mesh.p[:, mesh.t]                      # (2, 3, ne)
    out = np.zeros(x.shape[0], dtype=bool)
    for i, q in enumerate(x):
        d = [((V[0, (k + 1) % 3] - q[0]) * (V[1, (k + 2) % 3] - q[1])
              - (V[1, (k + 1) % 3] - q[1]) * (V[0, (k + 2) % 3] - q[0])) for k in range(3)]
        d = np.array(d)
        out[i] = bool((((d >= 0).all(axis=0)) | ((d <= 0).all(axis=0))).any())
    return out


def tetrahedron_neighbours(mesh: MeshTet) -> np.ndarray:
    """(nt, 4) int64: the tetrahedron across the face of each tetrahedron of ``mesh`` opposite
    its vertex slot k (``mesh.t[k]``), -1 on the boundary; from scikit-fem's facet numbering
    (``t2f``, ``f2t``), which a basis on the mesh builds anyway."""
    t, t2f, f2t = mesh.t, mesh.t2f, mesh.f2t
    ne = t.shape[1]
    other = f2t[0, t2f] + f2t[1, t2f] - np.arange(ne)[None, :]     # (4, ne), -1 outside
    opposite = t.sum(axis=0)[None, :] - mesh.facets[:, t2f].sum(axis=0)  # node not on it
    slot = (t[None, :, :] == opposite[:, None, :]).argmax(axis=1)        # (4, ne)
    NB = np.empty((ne, 4), np.int64)
    NB[np.arange(ne)[None, :], slot] = other
    return NB


def own_triangulation(mesh, tri) -> bool:
    """Are the mesh's triangles those of the triangulation ``tri``, one for one (same
    slots, vertices in any order)?"""
    T = getattr(tri, "triangles", None)
    return T is not None and T.shape == mesh.t.T.shape and bool(
        np.array_equal(np.sort(T, axis=1), np.sort(mesh.t.T, axis=1)))


def adopt(mesh, method):
    """The triangulation a basis on ``mesh`` queries with ``method`` (cached)."""
    tri = triangulation_of(mesh)
    if method == "lasserre" and isinstance(tri, Triangulation):
        if tri.segment_keys.size:
            raise ValueError("the mesh has segments (interfaces or a non-convex boundary): "
                             "constrained coordinates come from the 2D area method only "
                             "(method='area', the 2D default)")
        cached = getattr(mesh, "_skfem_nem_delaunay", None)
        if cached is None:
            cached = delaunay_of(np.ascontiguousarray(tri.nodes))
            mesh._skfem_nem_delaunay = cached
        return cached
    return tri
