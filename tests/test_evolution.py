"""The Lagrangian evolving mesh: moves, flips, remaps, injection, checkpoints."""
import warnings

import numpy as np
import pytest
from scipy.spatial import Delaunay

from helpers import edge_set, square_nodes, vortex
from skfem_nem import LagrangianMesh
from skfem_nem.evolution import MoveNotConverged, StepTooLong

A3 = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def jittered_square(n=600, seed=0, k=16):
    """Unit-square nodes, the sides' nodes jittered, the interior ones off the walls."""
    return square_nodes(n, k, seed, jitter=0.3, margin=0.01)


def ip_points(lm):
    X = lm.nodes[lm.triangles]  # (nt, 3, 2)
    return np.einsum("kj,tjd->tkd", A3, X)


def check_mesh(lm, n):
    tri = lm.triangulation
    assert tri.npoints == n
    assert np.all(tri.orientation() > 0)
    assert tri.is_delaunay()
    used = np.zeros(n, bool)
    used[tri.triangles.ravel()] = True
    assert used.all()  # no node lost
    # same edges as Qhull on the same nodes (random nodes: no co-circular quads)
    assert edge_set(tri.triangles) == edge_set(Delaunay(tri.nodes).simplices)


@pytest.mark.parametrize("jitter", [0.01, 0.05, 0.1, 0.3])
def test_random_jitter(jitter):
    p = jittered_square()
    lm = LagrangianMesh(p)
    h = 1 / np.sqrt(p.shape[0])
    rng = np.random.default_rng(1)
    d = jitter * h * (rng.random(p.shape) - 0.5)
    r = lm.advance(lambda x: d, 1.0)
    check_mesh(lm, p.shape[0])
    # locality: only triangles near flips change
    assert r["triangles_changed"] <= 2 * r["flips"] + 10 * r["relocated"]
    assert r["triangles_changed"] <= r["stencils_affected"] <= 4 * r["triangles_changed"]
    # walls kept exactly
    on = (p == 0) | (p == 1)
    np.testing.assert_array_equal(lm.nodes[on], p[on])
    if jitter >= 0.1:
        assert r["flips"] > 0


def test_shear_and_vortex_many_steps():
    p = jittered_square(400)
    lm = LagrangianMesh(p, node_fields={"x0": p})
    for _ in range(5):
        lm.advance(lambda x: np.c_[0.6 * np.sin(np.pi * x[:, 0]) * (x[:, 1] - 0.5),
                                   0 * x[:, 1]], 0.05)
    check_mesh(lm, p.shape[0])
    for _ in range(20):
        lm.advance(vortex, 0.02)
    check_mesh(lm, p.shape[0])
    assert sum(h["flips"] for h in lm.history) > 100
    # node fields follow their nodes
    np.testing.assert_array_equal(lm.node_fields["x0"], p)


def test_rigid_motion_causes_no_flip():
    p = jittered_square(300)
    lm = LagrangianMesh(p, walls=None)
    T0 = lm.triangles.copy()
    r = lm.advance(lambda x: np.ones_like(x) * [0.25, -0.5], 1.0)
    assert r["flips"] == 0
    c = np.array([0.5, 0.5])
    for _ in range(4):
        r = lm.advance(lambda x: np.c_[-(x[:, 1] - c[1]), x[:, 0] - c[0]], 0.1)
        assert r["flips"] == 0
    np.testing.assert_array_equal(lm.triangles, T0)


@pytest.mark.parametrize("remap", ["conservative", "average"])
def test_remap_on_flips(remap):
    p = jittered_square(500)
    lm = LagrangianMesh(p, remap=remap)
    rng = np.random.default_rng(2)
    # move the nodes without repairing, then repair at fixed positions
    d = 0.1 / np.sqrt(p.shape[0]) * (rng.random(p.shape) - 0.5)
    on = (p == 0) | (p == 1)
    for scale in (1.0, 0.5, 0.3, 0.2, 0.1):
        lm._set_positions(np.where(on, p, p + scale * d))
        if np.all(lm.triangulation.orientation() > 0):  # flips can repair this
            break
    assert not lm.triangulation.is_delaunay()
    xq = ip_points(lm)
    f1 = rng.random(xq.shape[:2])
    lm.ip_fields["s"] = np.stack([f1, 3 * f1 + 2, xq[..., 0] + 2 * xq[..., 1]], -1)
    before = lm.ip_integral("s")
    flips = lm.triangulation.make_delaunay(on_flips=lm._on_flips)
    assert flips > 10
    after = lm.ip_integral("s")
    s = lm.ip_fields["s"]
    # linear relations between components survive both rules
    np.testing.assert_allclose(s[..., 1], 3 * s[..., 0] + 2, atol=1e-12)
    if remap == "conservative":
        np.testing.assert_allclose(after, before, rtol=0, atol=1e-12)
        # a linear field is kept exactly
        xq = ip_points(lm)
        np.testing.assert_allclose(s[..., 2], xq[..., 0] + 2 * xq[..., 1], atol=1e-12)
    else:
        assert np.abs(after[:2] - before[:2]).max() > 1e-12  # not conservative


def test_injection_keeps_delaunay():
    p = jittered_square(300)
    lm = LagrangianMesh(p, node_fields={"rho": 1 + p[:, 0]}, ip_fields={"s": np.ones(3)})
    I0 = lm.ip_integral("s")
    # strong divergent flow from the centre thins the middle
    def spread(x):
        X, Y = x[:, 0], x[:, 1]
        return -0.3 * np.c_[np.sin(2 * np.pi * X) * np.sin(np.pi * Y),
                            np.sin(2 * np.pi * Y) * np.sin(np.pi * X)]
    inj = 0
    for _ in range(10):
        r = lm.advance(spread, 0.1, inject=1.5)
        inj += r["injected"]
    assert inj > 0
    n = lm.triangulation.npoints
    assert n == p.shape[0] + inj
    check_mesh(lm, n)
    assert lm.node_fields["rho"].shape == (n,)
    # injected nodes get interpolated values (the field is linear in the initial x)
    assert np.all((lm.node_fields["rho"] >= 1) & (lm.node_fields["rho"] <= 2))
    # the constant ip field keeps its integral (= area) through splits and flips
    np.testing.assert_allclose(lm.ip_integral("s"), I0, atol=1e-12)


def test_restart_is_bit_identical(tmp_path):
    p = jittered_square(300)
    a = LagrangianMesh(p, node_fields={"x0": p}, ip_fields={"s": np.arange(3.0)})
    for _ in range(3):
        a.advance(vortex, 0.03)
    a.save(tmp_path / "ck.npz")
    b = LagrangianMesh.load(tmp_path / "ck.npz")
    for _ in range(4):
        a.advance(vortex, 0.03, inject=1.3)
        b.advance(vortex, 0.03, inject=1.3)
    np.testing.assert_array_equal(a.nodes, b.nodes)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    np.testing.assert_array_equal(a.ip_fields["s"], b.ip_fields["s"])
    np.testing.assert_array_equal(a.node_fields["x0"], b.node_fields["x0"])
    assert a.time == b.time and a.step == b.step and a.history == b.history
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("bad, match", [
    (lambda x: np.full_like(x, np.nan), "non-finite values at .* node"),
    (lambda x: np.zeros((3, 2)), "shape"),
    (lambda x: 100 * np.ones_like(x), "leave the box"),
])
def test_bad_velocity_leaves_mesh_unchanged(bad, match):
    p = jittered_square(200)
    lm = LagrangianMesh(p, ip_fields={"s": np.arange(3.0)})
    lm.advance(vortex, 0.02)
    state = (lm.nodes.copy(), lm.triangles.copy(), lm.ip_fields["s"].copy(), lm.time, lm.step)
    with pytest.raises(ValueError, match=match):
        lm.advance(bad, 0.1)
    np.testing.assert_array_equal(lm.nodes, state[0])
    np.testing.assert_array_equal(lm.triangles, state[1])
    np.testing.assert_array_equal(lm.ip_fields["s"], state[2])
    assert (lm.time, lm.step) == state[3:]
    with pytest.raises(ValueError, match="dt"):
        lm.advance(vortex, -1.0)


def test_max_dt_and_basis():
    p = jittered_square(200)
    lm = LagrangianMesh(p)
    v = vortex(p)
    dt = lm.max_dt(v, 0.1)
    assert dt > 0
    r = lm.advance(vortex, dt)
    assert r["substeps"] == 1
    b = lm.basis()
    assert b.nelems == lm.triangles.shape[0]
    # ip slot k of triangle t is the basis' quadrature point k of element t
    np.testing.assert_allclose(np.asarray(b.global_coordinates()).transpose(1, 2, 0),
                               ip_points(lm), atol=1e-14)


def test_a_step_is_never_accepted_with_an_unconverged_predictor_corrector():
    p = jittered_square(200)
    lm = LagrangianMesh(p, node_fields={"x0": p[:, 0]})
    before = lm.nodes.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # and no warning either
        with pytest.raises(MoveNotConverged, match="did not converge in 1 iterations"):
            lm.advance(vortex, 0.02, maxiter=1, tol=1e-16)
    # nothing moved, the clock and history as before: the caller retries
    np.testing.assert_array_equal(lm.nodes, before)
    assert (lm.time, lm.step, lm.history) == (0.0, 0, [])
    assert issubclass(MoveNotConverged, StepTooLong)
    r = lm.advance(vortex, 0.02)
    assert r["converged"] and r["iterations"] < 10


def saved_state(lm, path):
    """The whole state as the checkpoint writes it (nodes, triangles,
    neighbours, every field, reference areas, walls, clock, history)."""
    lm.save(path)
    with np.load(path) as z:
        return {k: z[k].copy() for k in z.files}


def assert_same_state(a, b):
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def spread(x):
    X, Y = x[:, 0], x[:, 1]
    return -0.3 * np.c_[np.sin(2 * np.pi * X) * np.sin(np.pi * Y),
                        np.sin(2 * np.pi * Y) * np.sin(np.pi * X)]


def jitter(seed):
    """A velocity that varies within elements (random, about 0.3 spacings per
    unit time in the middle, vanishing at the walls): triangles invert."""
    def v(x):
        bump = 16 * x[:, 0] * (1 - x[:, 0]) * x[:, 1] * (1 - x[:, 1])
        return 0.015 * bump[:, None] * np.random.default_rng(seed).standard_normal(x.shape)
    return v


@pytest.mark.parametrize("stage", ["velocity", "_move", "_relocate", "inject_nodes",
                                   "min_angle"])
def test_failed_step_leaves_the_whole_state_unchanged(stage, tmp_path, monkeypatch):
    """Each stage of a step fails in turn, after doing its work: nodes,
    triangles, fields, reference areas, clock and history come back exactly."""
    p = jittered_square(300)
    lm = LagrangianMesh(p, node_fields={"rho": 1 + p[:, 0]}, ip_fields={"s": np.arange(3.0)})
    lm.advance(spread, 0.1, inject=1.5)
    before = saved_state(lm, tmp_path / "before.npz")
    history = [dict(h) for h in lm.history]
    calls = {"n": 0}

    def failing(original):
        def f(*args, **kwargs):
            original(*args, **kwargs)
            calls["n"] += 1
            raise RuntimeError(f"{stage} failed")
        return f

    velocity = jitter(1)
    if stage == "velocity":
        def velocity(x, v=jitter(1)):
            calls["n"] += 1
            if calls["n"] == 2:                  # the corrector, after the predictor
                raise RuntimeError("velocity failed")
            return v(x)
    else:
        monkeypatch.setattr(lm, stage, failing(getattr(lm, stage)))
    with pytest.raises(RuntimeError, match=f"{stage} failed"):
        lm.advance(velocity, 1.0, inject=1.2, max_substeps=4)
    assert calls["n"] >= 1                        # the stage did run
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    assert lm.history == history
    monkeypatch.undo()
    lm.advance(spread, 0.1, inject=1.5)          # and the mesh goes on
    check_mesh(lm, lm.triangulation.npoints)


@pytest.mark.parametrize("kw, match", [
    ({"maxiter": 0}, "maxiter"), ({"max_substeps": 0}, "max_substeps"),
    ({"inject": 1.0}, "inject"), ({"tol": -1.0}, "tol"), ({"dt": float("nan")}, "dt"),
    ({"velocity": 3.0}, "velocity")])
def test_step_arguments_checked_before_anything_moves(kw, match, tmp_path):
    p = jittered_square(150)
    lm = LagrangianMesh(p, ip_fields={"s": np.arange(3.0)})
    calls = []
    args = {"velocity": lambda x: calls.append(1) or vortex(x), "dt": 0.02, **kw}
    before = saved_state(lm, tmp_path / "before.npz")
    with pytest.raises((ValueError, TypeError), match=match):
        lm.advance(**args)
    assert not calls
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)


def test_more_than_eight_substeps():
    lm = LagrangianMesh(jittered_square(300))
    r = lm.advance(jitter(2), 1.0, max_substeps=12)
    assert r["substeps"] == 12
    check_mesh(lm, lm.triangulation.npoints)


def test_predictor_overshooting_a_wall_sees_the_velocity_on_the_wall():
    """Flow towards the bottom wall, v = (0, -k y): with k dt = 1.5 the Euler predictor
    puts the nodes near the wall below it, the trapezoidal corrector brings them back
    inside (y (1 - k dt / 2) / (1 + k dt / 2)). A velocity defined only inside the box
    (as a natural-neighbour interpolant is) is evaluated on the wall for the overshoot."""
    p = np.r_[square_nodes(200, 10, 1)]
    lm = LagrangianMesh(p)
    k, dt = 1.5, 1.0

    def inside_only(x):
        if (x < 0).any() or (x > 1).any():
            raise ValueError("outside the box")
        return np.c_[0 * x[:, 0], -k * x[:, 1]]

    y0 = lm.nodes[:, 1].copy()
    lm.advance(inside_only, dt, tol=1e-13, maxiter=120)
    interior = (y0 > 0) & (y0 < 1) & (lm.nodes[:, 0] > 0) & (lm.nodes[:, 0] < 1)
    np.testing.assert_allclose(lm.nodes[interior, 1], y0[interior] * 0.25 / 1.75, rtol=1e-9)


def test_a_node_carried_to_a_wall_stops_short_of_it():
    """A node whose velocity would carry it through the bottom wall (by less than its
    distance to it) stops at WALL_REACH of its distance; nodes moving away or along the
    wall move freely, and the stop is counted. Overshooting by more raises."""
    from skfem_nem.evolution.stepping import WALL_REACH
    p = jittered_square(200)
    lm = LagrangianMesh(p)
    k = int(np.argmin(np.where(lm.on_walls.any(axis=1), np.inf, lm.nodes[:, 1])))
    d = lm.nodes[k, 1]

    def down(x, speed=1.5 * d):
        v = np.zeros_like(x)
        v[np.abs(x[:, 0] - p[k, 0]) < 1e-9, 1] = -speed  # node k alone
        return v

    x0 = lm.nodes.copy()
    rep = lm.advance(down, 1.0)
    assert rep["stopped_at_walls"] == 1
    assert lm.nodes[k, 1] == pytest.approx((1 - WALL_REACH) * d, rel=1e-12)
    others = np.arange(len(x0)) != k
    np.testing.assert_array_equal(lm.nodes[others], x0[others])
    assert np.all(lm.triangulation.orientation() > 0)
    with pytest.raises(ValueError, match=f"first node {k} .*reduce dt"):
        lm.advance(lambda x: down(x, speed=10 * d), 1.0)   # 9 d past it: an error
    # a node 2e-4 from the wall carried 3e-4 past it (below 1e-3 of the box) stops too
    lm = LagrangianMesh(np.r_[p, [[0.5031, 2e-4]]])
    v = np.zeros_like(lm.nodes)
    v[-1, 1] = -5e-4
    rep = lm.advance(lambda x: v, 1.0)
    assert rep["stopped_at_walls"] == 1
    assert lm.nodes[-1, 1] == pytest.approx((1 - WALL_REACH) * 2e-4, rel=1e-12)


def test_replace_ip_fields_restores_a_saved_set_exactly():
    """A saved set of ip fields replaces the current one whole: values back, a field
    added since dropped; a field with the wrong row count is refused, nothing changed."""
    lm = LagrangianMesh(square_nodes(60, 8, 0), ip_fields={"s": np.arange(3.0)})
    saved = {k: v.copy() for k, v in lm.ip_fields.items()}
    lm.ip_fields["s"][:] = -1.0
    lm.ip_fields["added"] = np.ones((lm.triangles.shape[0], 3))
    with pytest.raises(ValueError, match="'bad' has"):
        lm.replace_ip_fields({"s": saved["s"], "bad": np.ones((2, 3))})
    assert set(lm.ip_fields) == {"s", "added"}
    lm.replace_ip_fields(saved)
    assert set(lm.ip_fields) == {"s"}
    np.testing.assert_array_equal(lm.ip_fields["s"], saved["s"])
