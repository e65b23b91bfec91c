"""The viscoelastic build-up example."""
import numpy as np
import pytest

from conftest import load_example


@pytest.fixture(scope="module")
def ex09():
    return load_example("ex09_viscoelastic_buildup")


def test_ex09_buildup(ex09, tmp_path):
    # about 200 MPa after 250 kyr; the error is first order in dt
    assert ex09.final[np.inf] == pytest.approx(199.9e6, rel=2e-3)
    (d1, e1, _, _), (d2, e2, _, _), (d3, e3, _, _) = ex09.errors
    assert 1.6 < e1 / e2 < 2.1 and 1.75 < e2 / e3 < 2.1
    assert e3 < 0.035 * 200e6
    # the 100 MPa cap flattens the curve
    assert abs(ex09.final[ex09.YIELD] - 1e8) < 1e5 and ex09.capped_plateau < 1e5
    t, m, _, ps = ex09.curves[ex09.YIELD]
    assert m[t < 15 * ex09.KYR].max() < 1e8 and ps.min() > 0
    png = ex09.visualize(str(tmp_path / "ex09.png"))
    assert (tmp_path / "ex09.png").stat().st_size > 10_000 and png.endswith(".png")
