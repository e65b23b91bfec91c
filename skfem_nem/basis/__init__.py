"""Natural-neighbour trial functions inside scikit-fem's assembly.

The elements and bases, the gradient-smoothing cells of the consistent default integration, and
the assembly hook that lets scikit-fem's forms assemble natural-neighbour stencils.
"""
from .assembly import restore_scikit_fem_assembly
from .elements import (ElementNaturalNeighbour, ElementNaturalNeighbour2,
                       ElementTetNaturalNeighbour, gauss_rule)
from .facet_basis import NaturalNeighbourFacetBasis
from .natural_neighbour import NaturalNeighbourBasis
from .solvers import natural_neighbour_solver

__all__ = ["ElementNaturalNeighbour", "ElementNaturalNeighbour2", "ElementTetNaturalNeighbour",
           "NaturalNeighbourBasis", "NaturalNeighbourFacetBasis", "gauss_rule",
           "natural_neighbour_solver", "restore_scikit_fem_assembly"]
