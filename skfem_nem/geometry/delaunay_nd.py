"""n-dimensional Delaunay triangulations (d = 2, 3, 4) from Qhull, checked.

Lasserre's volume recursion (:mod:`skfem_nem.coordinates.lasserre`) and the Delaunay meshes
(:mod:`skfem_nem.geometry.meshes`) need a triangulation in which every node is a vertex: Qhull
silently drops nodes that nearly coincide, which would leave a node without a basis function.
This module builds it and says which node is lost, rather than letting that surface later.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError

from .triangulation import unused_nodes, validate_nodes

__all__ = ["delaunay_of", "check_nodes", "triangulate", "check_delaunay"]


def check_nodes(nodes):
    """The (n, d) nodes as a float array, d = 2, 3 or 4 (``ValueError`` naming the problem)."""
    shape = np.shape(nodes)
    if len(shape) != 2 or shape[1] not in (2, 3, 4):
        raise ValueError(f"nodes must have shape (n, d) with d = 2, 3 or 4, got {shape}")
    return validate_nodes(nodes, dim=shape[1])


def triangulate(p):
    """Qhull's Delaunay triangulation of p, with degenerate (flat) node sets named."""
    d = p.shape[1]
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
    if not isinstance(tri, Delaunay):
        raise ValueError(f"delaunay must be a scipy.spatial.Delaunay, got {type(tri).__name__}")
    if tri.points.shape != p.shape or not np.array_equal(tri.points, p):
        raise ValueError("delaunay was built on other points than nodes")
    unused = unused_nodes(p.shape[0], tri.simplices)
    if unused.size:
        i = int(unused[0])
        raise ValueError(
            f"node {i} at {p[i].tolist()} is not a vertex of any Delaunay simplex "
            f"({unused.size} such node(s); Qhull drops nodes that nearly "
            f"coincide with others)")


def delaunay_of(p) -> Delaunay:
    """Qhull's Delaunay triangulation of the checked (n, d) nodes p, with every
    node a vertex (``ValueError`` naming the node otherwise)."""
    tri = triangulate(p)
    check_delaunay(tri, p)
    return tri
