"""Geometry: exact predicates, the 2D Delaunay triangulation, Delaunay meshes and node sets.

The lowest layer: nothing here imports the coordinates, the basis or anything above.
"""
from .meshes import delaunay_mesh
from .nodesets3d import box_nodes_3d
from .triangulation import Triangulation, validate_nodes

__all__ = ["Triangulation", "box_nodes_3d", "delaunay_mesh", "validate_nodes"]
