"""Natural-neighbour coordinates: the 2D area method and Lasserre's n-D volume recursion.

Built on :mod:`skfem_nem.geometry`; the basis and everything above build on these.
"""
from .dispatch import laplace_coordinates, natural_neighbour_coordinates, sibson_coordinates
from .lasserre import sibson_coordinates_nd

__all__ = ["sibson_coordinates", "laplace_coordinates", "natural_neighbour_coordinates",
           "sibson_coordinates_nd"]
