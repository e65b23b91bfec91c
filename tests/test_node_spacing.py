"""The target node spacing of the evolving mesh: resolution kept over a whole run."""
import numpy as np
import pytest

from helpers import square_nodes, vortex
from skfem_nem import LagrangianMesh
from skfem_nem.evolution.spacing import (AREA_PER_SPACING2, EDGE_FACTOR, angle_fractions,
                                         smoothed_spacing)


def check_valid(lm):
    tri = lm.triangulation
    assert np.all(tri.orientation() > 0)
    assert tri.is_delaunay()
    assert not tri.missing_segments().size


def stretched(lm, flow, steps, dt, inject=2.0):
    """Run ``steps`` steps; the smallest node count over the first's and the longest edge
    over the first's, over all steps."""
    n0, L0 = lm.nodes.shape[0], lm.longest_edge()
    fewest, longest = 1.0, 1.0
    for _ in range(steps):
        rep = lm.advance(flow, dt, inject=inject, merge=True, maxiter=20)
        fewest = min(fewest, lm.nodes.shape[0] / n0)
        longest = max(longest, rep["longest_edge"] / L0)
        assert rep["longest_edge"] == pytest.approx(lm.longest_edge())
    return fewest, longest


def test_a_vortex_held_for_many_turns_keeps_the_resolution():
    """A cellular vortex turns its core about 4 times in t = 10 and stretches every ring
    of nodes around it: the node count stays above 0.9 of the first (and below 1.5 of it:
    no runaway injection), the longest edge within 2x the first, integrals kept; without
    the spacing target (no injection) the same flow thins the mesh past both bounds."""
    nodes = square_nodes(300, 12, 2, jitter=0.3, margin=0.01)
    lm = LagrangianMesh(nodes, ip_fields={"one": np.ones(3)}, node_fields={"x0": nodes})
    n0 = lm.nodes.shape[0]
    fewest, longest = stretched(lm, vortex, 200, 0.05)
    assert fewest >= 0.9 and longest <= 2.0
    assert lm.nodes.shape[0] < 1.5 * n0
    check_valid(lm)
    np.testing.assert_allclose(lm.ip_integral("one"), 1.0, rtol=1e-12)
    # the same run without injection: the bounds are not met by themselves
    bare = LagrangianMesh(nodes)
    fewest, longest = stretched(bare, vortex, 200, 0.05, inject=None)
    assert fewest < 0.9


def cell(x):
    """One convection cell (free slip on the unit square's walls): nodes run down the
    left wall and spread apart along the bottom wall from its left corner."""
    s, c = np.sin(np.pi * x), np.cos(np.pi * x)
    return np.c_[s[:, 0] * c[:, 1], -c[:, 0] * s[:, 1]]


def test_a_wall_hugging_flow_injects_on_the_wall():
    """A cell that spreads the nodes of the bottom wall apart: nodes are injected on the
    wall (exactly on it, known as wall nodes), no wall edge gets longer than the quality
    bound of its nodes' targets, and the count stays up over several turns."""
    nodes = square_nodes(300, 12, 2, jitter=0.3, margin=0.01)
    lm = LagrangianMesh(nodes, node_fields={"x0": nodes})
    walls = 0
    for _ in range(60):
        rep = lm.advance(cell, 0.05, inject=2.0, merge=True)
        walls += rep["walls_split"]
        P, h = lm.nodes, lm.target_spacing
        H = lm.triangulation.hull_edges
        length = np.hypot(*(P[H[:, 0]] - P[H[:, 1]]).T)
        assert np.all(length <= EDGE_FACTOR * np.maximum(h[H[:, 0]], h[H[:, 1]]))
    assert walls >= 10
    W = lm.on_walls
    np.testing.assert_array_equal(W[:, 1], (lm.nodes[:, 1] == 0.0) | (lm.nodes[:, 1] == 1.0))
    assert lm.nodes.shape[0] >= 0.9 * nodes.shape[0]
    check_valid(lm)


def test_the_default_target_is_the_drawn_sets_local_spacing():
    """Interior nodes of a lattice of edge h get the target h; a drawn random set is
    within its own target (no node's area above it), and the smoothing makes a small
    random cell's node take its neighbourhood's spacing."""
    h = 0.05
    x, y = np.meshgrid(np.arange(0, 1 + 1e-9, h), np.arange(0, 1 + 1e-9, h * np.sqrt(3) / 2))
    x = x + 0.5 * h * (np.arange(x.shape[0]) % 2)[:, None]
    P = np.c_[x.ravel(), y.ravel()]
    P = P[(P[:, 0] < 1 - 1e-9)]
    lm = LagrangianMesh(P, walls=None)
    fr = angle_fractions(lm.nodes, lm.triangles)
    inside = fr > 1 - 1e-9
    deep = inside & (np.abs(lm.nodes - 0.5).max(axis=1) < 0.3)
    np.testing.assert_allclose(lm.target_spacing[deep], h, rtol=1e-9)
    np.testing.assert_allclose(lm.reference_areas()[deep], AREA_PER_SPACING2 * h * h,
                               rtol=1e-9)
    rnd = LagrangianMesh(square_nodes(400, 12, 5, jitter=0.3))
    assert np.all(rnd.node_areas() <= rnd.reference_areas() * (1 + 1e-12))
    # smoothing: one node with a tiny spacing among equal ones
    E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]])
    s = smoothed_spacing(np.array([0.1, 1.0, 1.0, 1.0]), E, rounds=1)
    assert s[0] == pytest.approx(np.sqrt((0.01 + 3.0) / 4))


def test_a_callable_target_refines_and_is_checked(tmp_path):
    """``spacing=h(x)`` finer than the drawn set: a few steps of a slow flow bring every
    edge within the quality bound and every area near its target; the target is a
    function of position (not carried). A target that is not positive is refused naming
    the node, and a failing step leaves the mesh unchanged."""
    nodes = square_nodes(150, 8, 3, jitter=0.3, margin=0.02)

    def fine(x):
        return np.where(x[:, 0] < 0.5, 0.04, 0.08)

    lm = LagrangianMesh(nodes, spacing=fine)
    n0 = lm.nodes.shape[0]
    for _ in range(6):
        lm.advance(vortex, 0.01, inject=2.0, merge=True)
    assert lm.nodes.shape[0] > 2 * n0
    np.testing.assert_array_equal(lm.target_spacing, fine(lm.nodes))
    P, T, h = lm.nodes, lm.triangles, lm.target_spacing
    a, b = T, np.roll(T, -1, axis=1)
    ratio = np.hypot(*(P[a] - P[b]).transpose(2, 0, 1)) / np.maximum(h[a], h[b])
    assert ratio.max() <= EDGE_FACTOR
    check_valid(lm)
    # refused: a non-positive target, naming the node; the state as it was
    with pytest.raises(ValueError, match="spacing.*positive and finite.*at node 3"):
        LagrangianMesh(nodes, spacing=lambda x: np.where(np.arange(len(x)) == 3, 0.0, 0.1))
    lm.save(tmp_path / "before.npz")
    bad = {"calls": 0}

    def later(x):
        bad["calls"] += 1
        return np.full(len(x), np.nan)

    lm._spacing_fn = later
    with pytest.raises(ValueError, match="spacing"):
        lm.advance(vortex, 0.01, inject=2.0)
    assert bad["calls"] == 1
    lm._spacing_fn = fine
    lm.save(tmp_path / "after.npz")
    with np.load(tmp_path / "before.npz") as z0, np.load(tmp_path / "after.npz") as z1:
        for k in z0.files:
            np.testing.assert_array_equal(z0[k], z1[k], err_msg=k)
    with pytest.raises(TypeError, match="spacing must be None or a callable"):
        LagrangianMesh(nodes, spacing=0.1)


def test_targets_travel_with_checkpoints(tmp_path):
    """The carried target is saved and loaded bit for bit; a callable one must be given
    again on loading (a function is not stored)."""
    nodes = square_nodes(200, 10, 4, jitter=0.3, margin=0.01)
    lm = LagrangianMesh(nodes)
    for _ in range(5):
        lm.advance(vortex, 0.05, inject=1.5, merge=True)
    lm.save(tmp_path / "c.npz")
    back = LagrangianMesh.load(tmp_path / "c.npz")
    np.testing.assert_array_equal(back.target_spacing, lm.target_spacing)
    r1, r2 = (m.advance(vortex, 0.05, inject=1.5, merge=True) for m in (lm, back))
    np.testing.assert_array_equal(lm.nodes, back.nodes)
    fn = LagrangianMesh(nodes, spacing=lambda x: np.full(len(x), 0.1))
    fn.save(tmp_path / "f.npz")
    with pytest.raises(ValueError, match="callable target spacing: pass it again"):
        LagrangianMesh.load(tmp_path / "f.npz")
    again = LagrangianMesh.load(tmp_path / "f.npz", spacing=lambda x: np.full(len(x), 0.1))
    np.testing.assert_array_equal(again.target_spacing, 0.1)


def test_injected_nodes_take_their_values_from_their_own_side_of_a_segment():
    """Two layers split by a line of segments, a node field 1 on and above the line and 0
    below: nodes injected above the line see only their own layer (constrained natural
    neighbours) and get exactly 1; the same splits on an unconstrained mesh reach across
    the line and mix the layers."""
    rng = np.random.default_rng(7)
    line = np.c_[np.linspace(0, 1, 9), np.full(9, 0.5)]
    inner = rng.random((160, 2))
    inner = inner[np.abs(inner[:, 1] - 0.5) > 0.03]
    P = np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], line, inner]
    upper = np.where(P[:, 1] >= 0.5, 1.0, 0.0)
    seg = np.c_[np.arange(4, 12), np.arange(5, 13)]
    mixed = {}
    for segments in (seg, None):
        lm = LagrangianMesh(P, node_fields={"upper": upper}, segments=segments)
        n0 = lm.nodes.shape[0]
        assert lm.split_long_edges(factor=1.05) > 10
        new = np.arange(n0, lm.nodes.shape[0])
        above = new[lm.nodes[new, 1] > 0.5]
        assert above.size > 5
        mixed[segments is None] = np.abs(lm.node_fields["upper"][above] - 1.0).max()
        if segments is not None:
            check_valid(lm)
    assert mixed[False] < 1e-12 < 1e-3 < mixed[True]
