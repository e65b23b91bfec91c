"""Stokes flow across a sharp viscosity interface with constrained natural neighbours.

Two-layer Couette flow in the unit square: viscosity 1 below y = 0.5 and
``ratio`` above, bottom wall at rest, top wall moving at speed 1, the exact
profile prescribed on the side walls. The exact flow is ``u = (U(y), 0)``,
``U`` piecewise linear with a kink at the interface (the shear stress
``eta U'`` is continuous), and a constant pressure.

Random nodes are not kept away from the interface's diametral discs, so the
interface segments are in general not Delaunay edges: the mesh is the
constrained Delaunay triangulation (``delaunay_mesh(points, segments=...)``).
The constrained natural-neighbour velocity then holds the two linear profiles
exactly (the strain rate is constant in each layer, the smoothed gradients are
exact and the traction balances across the interface), so the discrete
solution is the exact one to round-off. Measured on 300 random nodes (367
nodes in all), largest nodal velocity error: 4e-16 to 1.3e-15 (seeds 0, 1, ratios
1e3, 1e-3), pressure range up to 2.9e-10;
on the same nodes without the segments 0.079 (seed 0) and 0.098 (seed 1),
with a spurious vertical velocity of 0.042 / 0.025 and a pressure range of 136 /
67 where the exact pressure is constant.
"""
import numpy as np
import pytest

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import polyline_nodes
from skfem_nem.models.stokes import solve_stokes, stokes_spaces


def layered_nodes(n, seed):
    """Walls, the interface y = 0.5 (as segments) and n random nodes (those
    closer than h/4 to a wall or the interface dropped); returns the nodes and
    the (k, 2) interface segments."""
    h = 1 / np.sqrt(n)
    walls = polyline_nodes([[0, 0], [1, 0], [1, .5], [1, 1], [0, 1], [0, .5]], h, closed=True)
    line = polyline_nodes([[0, .5], [1, .5]], h)[1:-1]
    x = np.random.default_rng(seed).random((n, 2))
    gap = np.minimum.reduce([x[:, 0], 1 - x[:, 0], x[:, 1], 1 - x[:, 1], np.abs(x[:, 1] - .5)])
    pts = np.r_[walls, line, x[gap > 0.25 * h]]
    on = np.flatnonzero(pts[:, 1] == 0.5)
    on = on[np.argsort(pts[on, 0])]
    return pts, np.c_[on[:-1], on[1:]]


def couette_profile(y, ratio):
    """Exact velocity U(y): slope a below the interface, a / ratio above, U(1) = 1."""
    a = 1 / (0.5 + 0.5 / ratio)
    return np.where(y <= 0.5, a * y, 0.5 * a + a / ratio * (y - 0.5))


def solve_couette(mesh, ratio, method="nem"):
    spaces = stokes_spaces(mesh, method)
    dofs = spaces.ubasis.get_dofs()
    ux, uy = dofs.all("u^1"), dofs.all("u^2")
    y = spaces.ubasis.doflocs[1]
    walls = (np.r_[ux, uy], np.r_[couette_profile(y[ux], ratio), 0 * uy])
    return solve_stokes(spaces, lambda x: np.where(x[1] > 0.5, ratio, 1.0), 0.0,
                        free_slip=None, prescribed=walls, tol=1e-13)


def nodal_errors(mesh, s, ratio):
    v = s.velocity_at_nodes()
    return (np.abs(v[:, 0] - couette_profile(mesh.p[1], ratio)).max(), np.abs(v[:, 1]).max(),
            np.ptp(s.pressure_at_nodes()))


@pytest.mark.parametrize("ratio", [1e3, 1e-3])
@pytest.mark.parametrize("seed", [0, 1])
def test_two_layer_couette_exact_with_constrained_basis(seed, ratio):
    pts, seg = layered_nodes(300, seed)
    mesh = delaunay_mesh(pts, segments={"interface": seg})
    assert mesh.boundaries["interface"].size >= len(seg)
    s = solve_couette(mesh, ratio)
    eu, ev, p_range = nodal_errors(mesh, s, ratio)
    assert eu < 1e-10 and ev < 1e-10              # measured 1.3e-15 / 1.3e-15
    assert p_range < 1e-8                         # constant pressure (measured 2.9e-10)
    assert np.abs(s.info["bubble"]).max() < 1e-10  # the bubbles carry nothing


def test_two_layer_couette_unconstrained_basis_cannot():
    """The same nodes without segments: the C1 functions smear the kink."""
    pts, _ = layered_nodes(300, 0)
    mesh = delaunay_mesh(pts)
    eu, ev, p_range = nodal_errors(mesh, solve_couette(mesh, 1e3), 1e3)
    assert eu > 1e-2 and ev > 1e-2                # measured 0.079 / 0.042
    assert p_range > 1.0                          # measured 136


def test_two_layer_couette_taylor_hood_on_constrained_mesh():
    """Taylor-Hood on the constrained triangles (no triangle crosses the
    interface) is exact too: a check of the set-up."""
    pts, seg = layered_nodes(300, 0)
    mesh = delaunay_mesh(pts, segments={"interface": seg})
    eu, ev, _ = nodal_errors(mesh, solve_couette(mesh, 1e3, "taylor-hood"), 1e3)
    assert eu < 1e-10 and ev < 1e-10
