"""solve_stokes(..., solver="petsc") on tetrahedra, with the spaces divided among the
ranks: each rank builds the natural-neighbour velocity and its condensed bubbles on its own
part of the tetrahedra, and the solution is the serial one. (Taylor-Hood and MINI divide by
scikit-fem's own restriction: tests/test_stokes.py compares their divided systems bit for
bit, serially.)"""
import numpy as np
import pytest

from skfem_nem import delaunay_mesh
from skfem_nem.models.analytic3d import Manufactured3D
from skfem_nem.models.stokes import solve_stokes, stokes_spaces
from agreement import rel

# agreement asked of the divided solve with the serial direct one (velocity and
# pressure, relative in the 2-norm): the PETSc solve's tolerance is far below it
AGREEMENT = 1e-8
PETSC_TOL = 1e-12


@pytest.fixture(scope="module")
def cube():
    """Random nodes in the unit cube (seeded: the same mesh on every rank)."""
    rng = np.random.default_rng(5)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    return delaunay_mesh(np.r_[corners, rng.random((200, 3))])


@pytest.mark.parametrize("method", ["nem"])
def test_divided_tetrahedra_give_the_serial_solution(cube, agree, method):
    """The manufactured flow of viscosity ratio 20 (free slip on the cube's faces): the
    ranks' parts partition the tetrahedra, none holds another's, and the velocity and
    pressure are the serial direct solve's."""
    ex = Manufactured3D()
    serial = solve_stokes(stokes_spaces(cube, method), ex.viscosity, ex.force,
                          solver="direct")
    divided = stokes_spaces(cube, method, elements="owned")
    s = solve_stokes(divided, ex.viscosity, ex.force, solver="petsc", tol=PETSC_TOL)
    mine = (np.arange(cube.nelements) if divided.elements is None
            else divided.elements)
    got = agree((mine.tolist(), divided.ubasis.nelems, divided.quadrature_points.shape[1],
                 rel(s.u, serial.u), rel(s.p, serial.p)))
    assert sorted(sum((g[0] for g in got), [])) == list(range(cube.nelements))
    for cells, held, points, du, dp in got:
        assert held == points == len(cells)
        assert du < AGREEMENT and dp < AGREEMENT, (du, dp)
