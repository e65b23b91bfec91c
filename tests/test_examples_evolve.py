"""The evolving-mesh example and a small version of the remap diffusion study."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def load(path, name):
    spec = importlib.util.spec_from_file_location(name, ROOT / path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def ex05():
    return load("examples/ex05_shear_flow.py", "ex05_shear_flow")


@pytest.fixture(scope="module")
def bench():
    return load("benchmarks/evolve.py", "bench_evolve")


def test_ex05_mesh_stays_delaunay(ex05):
    lm, start = ex05.lm, ex05.result["start"]
    tri = lm.triangulation
    assert len(lm.history) == ex05.N_STEPS
    assert sum(r["flips"] for r in lm.history) > 10 * ex05.N_STEPS
    assert tri.is_delaunay() and np.all(tri.orientation() > 0)
    # no node lost: every node is still a vertex and still carries its own field
    assert tri.npoints == start.shape[0]
    assert np.bincount(tri.triangles.ravel(), minlength=tri.npoints).min() > 0
    np.testing.assert_array_equal(lm.node_fields["x0"], start)
    # free-slip walls: wall nodes keep their wall coordinate
    on = (start == 0) | (start == 1)
    np.testing.assert_array_equal(lm.nodes[on], start[on])


def test_ex05_pairs(ex05):
    h, pairs = ex05.result["h"], ex05.pairs
    x0, x1 = ex05.result["start"], ex05.lm.nodes
    first = {tuple(e) for e in ex05.edges(ex05.result["snapshots"][0][1])}
    last = {tuple(e) for e in ex05.edges(ex05.lm.triangles)}
    (a, a2), (b, b2) = pairs["A"], pairs["B"]
    # B/B': neighbours at the start, far apart at the end
    assert (min(b, b2), max(b, b2)) in first
    assert np.linalg.norm(x1[b] - x1[b2]) > 10 * h
    # A/A': far apart at the start, neighbours at the end
    assert (min(a, a2), max(a, a2)) in last
    assert np.linalg.norm(x0[a] - x0[a2]) > 10 * h
    # both pairs are interior nodes
    for i in (a, a2, b, b2):
        assert np.all((x0[i] > 0) & (x0[i] < 1))


def test_ex05_figure(ex05, tmp_path):
    png = ex05.visualize(tmp_path / "ex05.png")
    assert Path(png).stat().st_size > 20_000


def test_rigid_rotation_of_a_disc_causes_no_flip(bench):
    r = bench.rigid_disc_check(n=500, steps=60)
    assert r["flips"] == 0
    assert r["same_triangles"] and r["field_unchanged"]


@pytest.mark.parametrize("remap", ["conservative", "average"])
def test_round_trip_diffusion(bench, remap):
    r = bench.diffusion_round_trip(n=600, duration=0.25, remap=remap)
    # time-reversible: nodes and triangulation come back, so only the remap acted
    assert r["return_error"] < 1e-9 and r["same_delaunay"]
    assert r["flips"] > 100
    m = r["patterns"]
    for name in bench.PATTERNS:
        assert 0 < m[name]["l2_error"] < 0.2
    if remap == "conservative":
        # every flip conserves the integral exactly
        assert all(abs(m[k]["remap_integral_change"]) < 1e-10 for k in bench.PATTERNS)
    else:
        # averaging and splitting creates no new extrema
        for name in bench.PATTERNS:
            lo, hi = m[name]["range"]
            elo, ehi = m[name]["initial_range"]
            assert elo <= lo and hi <= ehi


def test_round_trip_conservative_beats_average_on_smooth_fields(bench):
    # (the bump must be resolved: at 600 nodes its width is 1.5 h and both rules are alike)
    c = bench.diffusion_round_trip(n=1000, duration=0.25, remap="conservative")["patterns"]
    a = bench.diffusion_round_trip(n=1000, duration=0.25, remap="average")["patterns"]
    assert c["bump"]["l2_error"] < 0.6 * a["bump"]["l2_error"]
    assert c["linear"]["l2_error"] < 0.3 * a["linear"]["l2_error"]


def test_benchmark_step_smoke(bench):
    p = bench.box_nodes(300)
    out, lm = bench.run_config(p, 3, "conservative", budget=60, qhull=True)
    assert out["steps_done"] == 3 and out["delaunay"]
    assert out["excl_s"] <= out["step_s"] and out["qhull_s"] > 0
    assert lm.ip_fields["stress"].shape == (lm.triangles.shape[0], 3, 3)
