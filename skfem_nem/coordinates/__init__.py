"""Natural-neighbour coordinates: the 2D area method and Lasserre's n-D volume recursion;
on them, scattered-data interpolation in scipy's style (:class:`NaturalNeighbourInterpolator`).

Built on :mod:`skfem_nem.geometry`; the basis and everything above build on these.
"""
from .dispatch import laplace_coordinates, natural_neighbour_coordinates, sibson_coordinates
from .interp_gradients import estimate_gradients
from .interpolator import NaturalNeighbourInterpolator, natural_neighbour_to_grid
from .lasserre import sibson_coordinates_nd

__all__ = ["sibson_coordinates", "laplace_coordinates", "natural_neighbour_coordinates",
           "sibson_coordinates_nd", "NaturalNeighbourInterpolator", "estimate_gradients",
           "natural_neighbour_to_grid"]
