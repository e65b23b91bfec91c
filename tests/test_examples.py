"""The examples run and produce what they claim."""
from pathlib import Path

import numpy as np

from conftest import load_example as load


def test_ex01_interpolation(tmp_path):
    ex = load("ex01_interpolation")
    # second-order accurate, comparable with linear interpolation on the same triangles
    assert ex.errors["sibson"] < 0.03 and ex.errors["laplace"] < 0.03
    assert ex.rms["sibson"] < 1.3 * ex.rms["linear"]
    # nodal values are reproduced and the gradient is a real approximation
    assert np.allclose(ex.sibson_coordinates(ex.tri, ex.nodes) @ ex.values, ex.values, atol=1e-14)
    assert ex.grad_error < 1.0
    png = ex.visualize(tmp_path / "ex01.png")
    assert Path(png).stat().st_size > 10_000


def test_ex02_poisson(tmp_path):
    ex = load("ex02_poisson")
    nem, p1 = ex.results["NEM"], ex.results["P1"]
    # on the same graded triangles NEM is more accurate than P1 (measured:
    # L2 1.2e-3 vs 2.4e-3, energy 0.125 vs 0.139)
    assert nem["L2"] < 2e-3 and nem["L2"] < 0.8 * p1["L2"]
    assert nem["energy"] < p1["energy"]
    assert Path(ex.visualize(tmp_path / "ex02.png")).stat().st_size > 10_000
