"""n-dimensional Delaunay triangulations (d = 2, 3, 4), checked.

Lasserre's volume recursion (:mod:`skfem_nem.coordinates.lasserre`) and the Delaunay meshes
(:mod:`skfem_nem.geometry.meshes`) need a triangulation in which every node is a vertex. In 3D
it is the package's own exact :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D`: three times
faster than Qhull, every distinct node a vertex, and no flat tetrahedra (co-spherical ties are
broken by symbolic perturbation). In 2D and 4D it is Qhull's, which silently drops nodes that
nearly coincide and would leave a node without a basis function: this module says which node is
lost, rather than letting that surface later.

A scipy ``Delaunay`` a user passes in 3D is accepted too. Qhull's triangulated output (``Qt``)
keeps flat simplices of co-spherical nodes; those that lie in a plane of the hull (nodes on a
box's wall, four of them co-circular) are no part of the domain: :func:`sealed_neighbours` cuts
them off the adjacency, so that a query inside sees their faces as hull facets rather than
growing its conflict region across the wall.
"""
from __future__ import annotations

import weakref

import numpy as np
from scipy.spatial import Delaunay, QhullError

from .delaunay3d import Delaunay3D
from .hull import FACET_PLANE
from .simplices_nd import FLAT
from .triangulation import unused_nodes, validate_nodes

# flat simplices tested against the hull nodes in blocks of this many (bounds the memory)
_PLANE_BLOCK = 256
# triangulation -> its sealed adjacency (dropped with the triangulation)
_SEALED: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

__all__ = ["delaunay_of", "check_nodes", "triangulate", "check_delaunay", "sealed_neighbours",
           "hull_plane_flats", "DELAUNAY_TYPES"]

#: the triangulation objects the n-D coordinates take: scipy's (any d), the package's own (3D)
DELAUNAY_TYPES = (Delaunay, Delaunay3D)


def check_nodes(nodes):
    """The (n, d) nodes as a float array, d = 2, 3 or 4 (``ValueError`` naming the problem)."""
    shape = np.shape(nodes)
    if len(shape) != 2 or shape[1] not in (2, 3, 4):
        raise ValueError(f"nodes must have shape (n, d) with d = 2, 3 or 4, got {shape}")
    return validate_nodes(nodes, dim=shape[1])


def triangulate(p):
    """The Delaunay triangulation of p (3D: :class:`Delaunay3D`; else Qhull's), with
    degenerate (flat) node sets named."""
    d = p.shape[1]
    if d == 3:
        return Delaunay3D(p)
    try:
        tri = Delaunay(p)
    except QhullError as err:
        rank = np.linalg.matrix_rank(p[1:] - p[0])
        if rank < d:
            raise ValueError(
                f"the {p.shape[0]} nodes are degenerate: they span only {rank} of "
                f"{d} dimensions (flat node set), so no {d}D triangulation exists") from None
        raise ValueError(f"Qhull failed to triangulate the nodes: {err}") from None
    return tri


def check_delaunay(tri, p):
    """Raise unless ``tri`` is a scipy Delaunay of exactly p with every node a vertex."""
    if not isinstance(tri, DELAUNAY_TYPES):
        raise ValueError(f"delaunay must be a scipy.spatial.Delaunay (or, in 3D, a Delaunay3D), "
                         f"got {type(tri).__name__}")
    if tri.points.shape != p.shape or not np.array_equal(tri.points, p):
        raise ValueError("delaunay was built on other points than nodes")
    unused = unused_nodes(p.shape[0], tri.simplices)
    if unused.size:
        i = int(unused[0])
        raise ValueError(
            f"node {i} at {p[i].tolist()} is not a vertex of any Delaunay simplex "
            f"({unused.size} such node(s); Qhull drops nodes that nearly "
            f"coincide with others)")


def delaunay_of(p) -> Delaunay | Delaunay3D:
    """The Delaunay triangulation of the checked (n, d) nodes p (:func:`triangulate`), with
    every node a vertex (``ValueError`` naming the node otherwise)."""
    tri = triangulate(p)
    check_delaunay(tri, p)
    return tri


def hull_plane_flats(p: np.ndarray, simplices: np.ndarray, hull_nodes: np.ndarray) -> np.ndarray:
    """The flat tetrahedra whose four nodes lie exactly (in floating point) in one plane that
    supports the hull: every hull node on one side of it, within :data:`FACET_PLANE` times the
    diameter. ``hull_nodes``: the hull's vertices (Qhull's, which leave out nodes inside a hull
    facet; a plane supports the hull if the extreme nodes are on one side of it).

    Exactly: the wall nodes a free-slip wall keeps (on ``z = 0``, say) are in its plane to
    the last bit, and then so are the cross products and residuals below. A tetrahedron only
    nearly in a wall's plane (a node 1e-11 above it) is left in: sealing it would make its
    neighbour's face a hull facet tilted off the wall, behind which points on the wall would
    be outside. Only in 3D (an empty array otherwise)."""
    S = np.asarray(simplices)
    if p.shape[1] != 3:
        return np.zeros(0, dtype=np.int64)
    E = p[S[:, 1:]] - p[S[:, :1]]                            # (ns, 3, 3) edges from vertex 0
    scale = np.prod(np.linalg.norm(E, axis=2), axis=1)
    flat = np.flatnonzero(np.abs(np.linalg.det(E)) <= FLAT * scale)
    if flat.size == 0:
        return flat
    E = E[flat]
    crosses = np.stack([np.cross(E[:, i], E[:, j]) for i, j in ((0, 1), (0, 2), (1, 2))], 1)
    pick = np.argmax(np.linalg.norm(crosses, axis=2), axis=1)
    normal = crosses[np.arange(flat.size), pick]             # (k, 3) exact for a wall's nodes
    planar = (np.einsum("kid,kd->ki", E, normal) == 0.0).all(axis=1)
    flat, normal = flat[planar], normal[planar]
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    tol = FACET_PLANE * np.ptp(p, axis=0).max()
    keep = np.zeros(flat.size, dtype=bool)
    H = p[hull_nodes]
    for b in range(0, flat.size, _PLANE_BLOCK):
        blk = slice(b, b + _PLANE_BLOCK)
        h = H @ normal[blk].T - np.einsum("kd,kd->k", p[S[flat[blk], 0]], normal[blk])
        keep[blk] = (h.min(axis=0) >= -tol) | (h.max(axis=0) <= tol)
    return flat[keep]


def sealed_neighbours(p: np.ndarray, tri) -> np.ndarray:
    """``tri.neighbors`` with the flat simplices in hull planes (:func:`hull_plane_flats`)
    replaced by -1: their neighbours' faces there are hull facets. Kept per triangulation (a
    3D time step queries one many times: 24 ms at 10,000 nodes); callers must not write it.
    A :class:`~skfem_nem.geometry.delaunay3d.Delaunay3D` with walls gives its
    ``walled_neighbors`` (:mod:`~skfem_nem.geometry.walls3d`)."""
    walls = getattr(tri, "walled_neighbors", None)
    if walls is not None:
        return walls
    NB = _SEALED.get(tri)
    if NB is None:
        NB = np.array(tri.neighbors, dtype=np.int64)
        if not isinstance(tri, Delaunay3D):                 # (which has no flat tetrahedra)
            flats = hull_plane_flats(p, tri.simplices, np.unique(np.asarray(tri.convex_hull)))
            if flats.size:
                NB[np.isin(NB, flats)] = -1
        _SEALED[tri] = NB
    return NB
