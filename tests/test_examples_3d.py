"""ex06: 3D Poisson with NEM on Delaunay tetrahedra against P1 and P2; the 3D
natural-neighbour function figure.

Importing the example runs its default study (three node sets, about 25 s on
two cores); the numbers in the comments are the measured values that
docs/ndim.md reports.
"""
from pathlib import Path

import meshio
import numpy as np
import pytest

from conftest import load_example as load


@pytest.fixture(scope="module")
def ex06():
    return load("ex06_poisson_3d")


def test_reference_methods_converge(ex06):
    r = ex06.results
    # the set-up (manufactured solution, boundary nodes, error integrals) is right
    assert r["P1"]["fit_l2"] > 1.8 and r["P1"]["fit_h1"] > 0.9       # 2.25 / 1.13
    assert r["P2"]["fit_l2"] > 2.7 and r["P2"]["fit_h1"] > 1.8       # 3.59 / 2.38
    assert np.all(r["P2"]["dofs"] > 6 * r["P1"]["dofs"])


def test_nem_rates(ex06):
    nem = ex06.results["NEM"]
    assert nem["nodes"].size >= 3
    # fitted orders: L2 2.65, energy 1.30 (pre-asymptotic: the boundary share shrinks)
    assert 1.8 < nem["fit_l2"] < 3.2
    assert 0.9 < nem["fit_h1"] < 1.7
    assert np.all(nem["rate_l2"] > 1.7) and np.all(nem["rate_h1"] > 0.8)
    # NEM is more accurate than P1 on the same tetrahedra (measured 0.32-0.40 x in
    # L2, 0.50-0.55 x in energy), less than P2
    p1, p2 = ex06.results["P1"], ex06.results["P2"]
    assert np.all(nem["l2"] < 0.6 * p1["l2"]) and np.all(nem["h1"] < 0.8 * p1["h1"])
    assert np.all(nem["l2"] > p2["l2"])


def test_node_function_and_figure(ex06, tmp_path):
    node, X, phi, g = ex06.node_function(k=9)
    P = ex06.fig_mesh.p.T
    # a natural-neighbour function: in [0, 1], 1 at its node only, 0 at the others,
    # compact support around the node
    assert phi.min() >= -1e-14 and phi.max() <= 1 + 1e-14
    assert ex06.sibson_coordinates(P, P[node][None])[0, node] == 1.0
    lo, hi = X.reshape(-1, 3).min(0), X.reshape(-1, 3).max(0)
    assert np.all(lo <= P[node]) and np.all(P[node] <= hi) and np.all(hi - lo < 0.8)
    assert phi[0].max() < 0.05 and phi[-1].max() < 0.05
    path = ex06.visualize(str(tmp_path / "ex06.png"), k=9)
    assert Path(path).stat().st_size > 10_000
    m = meshio.read(tmp_path / "ex06_natural_neighbour_function.vtu")
    assert m.points.shape == (9 ** 3, 3) and m.cells[0].type == "hexahedron"
    np.testing.assert_allclose(m.point_data["phi"], phi.ravel())
    assert m.point_data["grad_phi"].shape == (9 ** 3, 3)
    s = meshio.read(tmp_path / "ex06_poisson_3d.vtu")
    assert s.cells[0].type == "tetra" and s.point_data["u"].shape == (ex06.mesh.nvertices,)
