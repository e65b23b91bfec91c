"""skfem-nem: the Natural Element Method (Braun & Sambridge, Nature 1995) for scikit-fem.

Layers as sub-packages, bottom to top; a lower layer never imports a higher one:

- :mod:`skfem_nem.geometry`: exact predicates, the Delaunay triangulation, meshes, node sets;
- :mod:`skfem_nem.coordinates`: Sibson and Laplace coordinates (2D area method, n-D recursion),
  scattered-data interpolation on them;
- :mod:`skfem_nem.basis`: NEM trial functions inside scikit-fem's assembly, consistent
  integration by gradient smoothing;
- :mod:`skfem_nem.parallel`: solvers on PETSc over MPI (optional petsc4py);
- :mod:`skfem_nem.evolution`: the Lagrangian evolving mesh;
- :mod:`skfem_nem.models`: Stokes flow, visco-elasto-plastic rheology, analytic solutions;
- :mod:`skfem_nem.apps`: the sinking plate, the command line, output writers.

This module only re-exports the public names.
"""
from .basis import (ElementNaturalNeighbour, ElementNaturalNeighbour2, ElementTetNaturalNeighbour,
                    NaturalNeighbourBasis, NaturalNeighbourFacetBasis,
                    natural_neighbour_solver, restore_scikit_fem_assembly)
from .coordinates import (NaturalNeighbourInterpolator, estimate_gradients, laplace_coordinates,
                          natural_neighbour_coordinates, natural_neighbour_to_grid,
                          sibson_coordinates)
from .evolution import LagrangianMesh, LagrangianMesh3D
from .geometry import Triangulation, delaunay_mesh

__version__ = "0.1.0"

__all__ = [
    "Triangulation",
    "ElementNaturalNeighbour",
    "ElementNaturalNeighbour2",
    "ElementTetNaturalNeighbour",
    "NaturalNeighbourBasis",
    "NaturalNeighbourFacetBasis",
    "natural_neighbour_solver",
    "delaunay_mesh",
    "LagrangianMesh",
    "LagrangianMesh3D",
    "sibson_coordinates",
    "laplace_coordinates",
    "natural_neighbour_coordinates",
    "NaturalNeighbourInterpolator",
    "estimate_gradients",
    "natural_neighbour_to_grid",
    "restore_scikit_fem_assembly",
    "__version__",
]
