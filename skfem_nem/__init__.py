"""skfem-nem: the Natural Element Method (Braun & Sambridge, Nature 1995) for scikit-fem.

Layers (bottom to top): geometry (:mod:`~skfem_nem.predicates`,
:mod:`~skfem_nem.triangulation`), coordinates (:mod:`~skfem_nem.coordinates`),
basis (:mod:`~skfem_nem.meshes`: Delaunay meshes checked and adopted;
:mod:`~skfem_nem.smoothing`: consistent integration; :mod:`~skfem_nem.basis`: NEM trial
functions inside scikit-fem's assembly).
"""
from ._assembly import restore_scikit_fem_assembly
from .basis import (ElementNaturalNeighbour, ElementTetNaturalNeighbour, NaturalNeighbourBasis,
                    NaturalNeighbourFacetBasis)
from .coordinates import laplace_coordinates, natural_neighbour_coordinates, sibson_coordinates
from .evolution import LagrangianMesh
from .evolution3d import LagrangianMesh3D
from .meshes import delaunay_mesh
from .triangulation import Triangulation

__version__ = "0.1.0"

__all__ = [
    "Triangulation",
    "ElementNaturalNeighbour",
    "ElementTetNaturalNeighbour",
    "NaturalNeighbourBasis",
    "NaturalNeighbourFacetBasis",
    "delaunay_mesh",
    "LagrangianMesh",
    "LagrangianMesh3D",
    "sibson_coordinates",
    "laplace_coordinates",
    "natural_neighbour_coordinates",
    "restore_scikit_fem_assembly",
    "__version__",
]
