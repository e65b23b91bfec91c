"""Physical models on natural-neighbour spaces: Stokes flow, visco-elasto-plastic rheology and
analytic solutions to verify them against."""
from .stokes import StokesSolution, StokesSpaces, assemble_stokes, solve_stokes, stokes_spaces

__all__ = ["StokesSpaces", "StokesSolution", "stokes_spaces", "assemble_stokes", "solve_stokes"]
