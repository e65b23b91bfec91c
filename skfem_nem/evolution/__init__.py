"""The Lagrangian evolving mesh: nodes move with the flow, flips repair the triangulation.

Integration-point fields are remapped on flips, and nodes are injected and removed to keep
a target spacing for the whole run.
"""
from .lagrangian import LagrangianMesh
from .lagrangian3d import LagrangianMesh3D
from .stepping import MoveNotConverged, StepTooLong

__all__ = ["LagrangianMesh", "LagrangianMesh3D", "StepTooLong", "MoveNotConverged"]
