"""Prandtl's punch (examples/ex11_prandtl_punch.py): the von Mises limit load."""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import ex11_prandtl_punch as ex11  # noqa: E402


def test_limit_load_within_five_percent(tmp_path):
    rows = ex11.load_curve(n=1000, steps=6, du=0.02, verbose=False)
    q = np.array([r["load"] for r in rows])
    assert np.all(np.diff(q) > -1e-6 * q.max())          # the load never drops
    assert abs(q[-1] / ex11.PRANDTL - 1) < 0.05           # (2 + pi) k within 5%
    assert abs(q[-1] / q[-2] - 1) < 0.01                  # levelled off: a limit load
    assert q[1] < 0.9 * q[-1]                             # an elastic rise before it
    assert rows[-1]["yielded"] > rows[1]["yielded"]       # the plastic zone grew
    png = ex11.visualize(rows, path=tmp_path / "punch.png")
    assert Path(png).stat().st_size > 5000
