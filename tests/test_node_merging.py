"""Node removal and merging: stars refilled with conservative remap, segments merged where
a node ending two of them goes, indices compacted; the merge policy in converging flow; a
failing removal leaves everything as it was."""
import numpy as np
import pytest

from test_evolution_segments import (LINE_Y, assert_same_state, check_chain,
                                     check_constrained, outlined_square, saved_state)
from helpers import edge_set, square_nodes
from scipy.spatial import cKDTree
from skfem_nem import LagrangianMesh
from skfem_nem.evolution.merging import CLUSTER_FRACTION, WALL_GAP_FRACTION, conservative_fill

A3 = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def linear(lm):
    """A linear field with two components at the ip points of the current mesh."""
    X = np.einsum("kj,tjd->tkd", A3, lm.nodes[lm.triangles])
    return np.stack([1 + 2 * X[..., 0] - 3 * X[..., 1], 0.5 * X[..., 0] * 0 + X[..., 1]], -1)


def mesh_with_fields(seed=0):
    nodes, segs, poly, line = outlined_square(300, seed)
    lm = LagrangianMesh(nodes, segments=segs, node_fields={"x": nodes})
    lm.ip_fields["lin"] = linear(lm)
    lm.ip_fields["rand"] = np.random.default_rng(seed).normal(size=(lm.triangles.shape[0], 3, 2))
    return lm, poly, line


def interior_free_nodes(lm, k, seed):
    free = ~lm.segment_nodes() & ~np.isin(np.arange(lm.nodes.shape[0]),
                                          lm.triangulation.hull_edges.ravel())
    return np.random.default_rng(seed).choice(np.flatnonzero(free), k, replace=False)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_remove_nodes_keeps_a_valid_mesh_conserves_and_compacts(seed):
    lm, poly, line = mesh_with_fields(seed)
    n0 = lm.nodes.shape[0]
    x_before = lm.nodes.copy()
    I_lin, I_rand = lm.ip_integral("lin"), lm.ip_integral("rand")
    gone = interior_free_nodes(lm, 25, seed)
    new = lm.remove_nodes(gone)
    check_constrained(lm)
    assert lm.nodes.shape[0] == n0 - 25 == lm.node_fields["x"].shape[0]
    assert (new[gone] == -1).all()
    kept = np.flatnonzero(new >= 0)
    np.testing.assert_array_equal(new[kept], np.arange(n0 - 25))
    np.testing.assert_array_equal(lm.nodes, x_before[kept])
    np.testing.assert_array_equal(lm.node_fields["x"], x_before[kept])
    # the integrals to round-off, any field; a linear field kept exactly
    np.testing.assert_allclose(lm.ip_integral("lin"), I_lin, rtol=0, atol=1e-13)
    np.testing.assert_allclose(lm.ip_integral("rand"), I_rand, rtol=0, atol=1e-13)
    np.testing.assert_allclose(lm.ip_fields["lin"], linear(lm), rtol=0, atol=1e-12)
    # the segments follow the renumbering
    check_chain(lm, new[poly], closed=True)
    check_chain(lm, new[line], closed=False)


def test_conservative_fill_of_one_triangle_split_differently():
    """Two old triangles of a square, refilled by the other diagonal: integrals kept."""
    sq = np.array([[0., 0.], [1., 0.], [1., 1.], [0., 1.]])
    Xo = sq[[[0, 1, 2], [0, 2, 3]]]
    Xn = sq[[[0, 1, 3], [1, 2, 3]]]
    Vo = np.random.default_rng(3).normal(size=(2, 3, 4))
    out = conservative_fill(Xo, Vo, Xn)
    area = np.array([0.5, 0.5])
    before = (area[:, None] * Vo.mean(axis=1)).sum(0)   # vertex mean = integral / area
    after = (area[:, None] * out.mean(axis=1)).sum(0)   # 3-point rule
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-14)


def test_removing_a_polygon_node_merges_its_segments():
    lm, poly, line = mesh_with_fields(5)
    nseg = lm.triangulation.segments.shape[0]
    v = int(poly[7])
    a, b, _ = lm.segment_merge(v)
    assert {a, b} == {int(poly[6]), int(poly[8])}
    I_rand = lm.ip_integral("rand")
    new = lm.remove_nodes([v])
    check_constrained(lm)
    assert lm.triangulation.segments.shape[0] == nseg - 1
    chain = check_chain(lm, new[poly[new[poly] >= 0]], closed=True)
    assert len(chain) == len(poly) - 1
    np.testing.assert_allclose(lm.ip_integral("rand"), I_rand, rtol=0, atol=1e-13)


def blocked_polygon_node(lm, poly):
    """A polygon node whose segments cannot merge: a node is put just inside the triangle
    of it and its two neighbours (by rebuilding the mesh with that node)."""
    nodes = lm.nodes.copy()
    a, v, b = poly[0], poly[1], poly[2]
    inside = (nodes[a] + nodes[v] + nodes[b]) / 3
    return np.r_[nodes, inside[None]], int(v)


@pytest.mark.parametrize("which", ["wall", "blocked segment", "hull"])
def test_a_failing_removal_leaves_the_state_unchanged(which, tmp_path):
    nodes, segs, poly, _ = outlined_square(300, 6)
    if which == "blocked segment":
        nodes, bad = blocked_polygon_node(LagrangianMesh(nodes, segments=segs), poly)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)},
                        node_fields={"x": nodes}, walls=None if which == "hull" else "box")
    lm.advance(lambda x: 0.1 * np.c_[np.sin(np.pi * x[:, 0]) * (x[:, 1] - .5), 0 * x[:, 1]],
               0.02, inject=2.0)
    if which != "blocked segment":  # a corner of the box (walls) or of the hull
        bad = int(np.argmin(np.hypot(*lm.nodes.T)))
    else:
        assert lm.segment_merge(bad) is False
    good = interior_free_nodes(lm, 3, 6)
    before = saved_state(lm, tmp_path / "before.npz")
    with pytest.raises(ValueError, match="cannot be (removed|merged)"):
        lm.remove_nodes(np.r_[good, bad])   # the good ones are taken out first
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    lm.remove_nodes(good)
    check_constrained(lm)


def stagnation(x):
    """u = (-x, y) about the centre, damped to zero at the walls: nodes converge on x = 0.5
    (and near the top and bottom walls, where the flow slows down)."""
    r = x - 0.5
    damp = 16 * x[:, 0] * (1 - x[:, 0]) * x[:, 1] * (1 - x[:, 1])
    return np.c_[-r[:, 0], r[:, 1]] * damp[:, None]


def test_merging_in_a_converging_flow_happens_and_is_counted():
    nodes, segs, poly, line = outlined_square(400, 7, centre=(0.5, 0.35))
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"one": np.ones(3)})
    area = lm.ip_integral("one")
    count = lm.nodes.shape[0]
    removed = merged = 0
    for _ in range(30):
        rep = lm.advance(stagnation, 0.15, inject=2.0, merge=True)
        count += rep["injected"] - rep["removed"] - rep["merged"]
        removed += rep["removed"]
        merged += rep["merged"]
        poly, line = lm.node_map[poly], lm.node_map[line]
        poly, line = poly[poly >= 0], line[line >= 0]
        poly = check_chain(lm, poly, closed=True)
        line = check_chain(lm, line, closed=False)
        check_constrained(lm)
        assert lm.nodes.shape[0] == count
    assert removed > 0 and merged > 0
    np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-12)


def test_without_merge_nothing_is_removed():
    nodes, segs, _, _ = outlined_square(300, 8)
    lm = LagrangianMesh(nodes, segments=segs)
    for _ in range(10):
        rep = lm.advance(stagnation, 0.15, inject=2.0)
        assert rep["removed"] == rep["merged"] == 0
    with pytest.raises(ValueError, match="merge must be"):
        lm.advance(stagnation, 0.1, merge=1)


def test_a_failing_merge_inside_advance_restores_everything(tmp_path, monkeypatch):
    nodes, segs, _, _ = outlined_square(400, 9)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"s": np.arange(3.0)})
    for _ in range(40):
        rep = lm.advance(stagnation, 0.15, inject=2.0)
    before = saved_state(lm, tmp_path / "before.npz")
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        raise RuntimeError("compaction failed")

    monkeypatch.setattr(lm, "_compact", failing)
    with pytest.raises(RuntimeError, match="compaction failed"):
        lm.advance(stagnation, 0.15, inject=2.0, merge=True)
    assert calls
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), before)
    monkeypatch.undo()
    rep = lm.advance(stagnation, 0.15, inject=2.0, merge=True)
    assert rep["removed"] + rep["merged"] > 0
    check_constrained(lm)


def along_the_walls(x):
    """Flow converging on x = 0.5 along the top and bottom walls (free slip): the wall
    nodes crowd there."""
    return np.c_[-(x[:, 0] - 0.5) * 4 * x[:, 0] * (1 - x[:, 0]), 0 * x[:, 1]]


def test_wall_nodes_crowded_by_the_flow_are_removed():
    """Nodes on a wall (not corners) that the flow crowds together are removed too: their
    open fans refilled, the walls and the box kept, integrals conserved; without
    merging they pile up."""
    spacing = {}
    for merge in (True, False):
        nodes, segs, poly, _ = outlined_square(300, 3, centre=(0.5, 0.5))
        lm = LagrangianMesh(nodes, segments=segs, ip_fields={"one": np.ones(3)})
        area = lm.ip_integral("one")
        corners = nodes[np.abs(nodes - 0.5).min(axis=1) == 0.5]
        removed = 0
        for _ in range(50):
            rep = lm.advance(along_the_walls, 0.1, inject=2.0, merge=merge)
            removed += rep["removed"]
            check_constrained(lm)
        top = np.flatnonzero(lm.nodes[:, 1] == 1.0)
        spacing[merge] = np.diff(np.sort(lm.nodes[top, 0])).min()
        assert removed > 0 if merge else removed == 0
        for c in corners:
            assert (lm.nodes == c).all(axis=1).any()
        np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-12)
        assert 0.5 * lm.triangulation.orientation().sum() == pytest.approx(1.0, rel=1e-13)
    # measured: 9.4e-3 with merging (17 top nodes -> 17, walls split near the corners),
    # 3.6e-4 without (17 -> 38)
    assert spacing[True] > 1e-3 > 2 * spacing[False]


def test_released_segments_are_no_longer_kept(tmp_path):
    """Released segments stop being edges that flips keep: the mesh is Delaunay across
    them (flipped with the remap: integrals kept), their nodes stay, the others stay
    segments; bad rows are refused and a failure leaves the mesh as it was."""
    nodes, segs, poly, line = outlined_square(300, 5)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"one": np.ones(3)})
    for _ in range(4):  # a wavy line: its segments are no longer Delaunay edges
        lm.advance(lambda x: np.c_[0 * x[:, 0], 0.6 * np.sin(10 * np.pi * x[:, 0])
                                   * np.exp(-((x[:, 1] - LINE_Y) / 0.05) ** 2)], 0.05, tol=1e-6)
    area = lm.ip_integral("one")
    tri = lm.triangulation
    kept = edge_set(tri.triangles)
    n, k = lm.nodes.shape[0], tri.segments.shape[0]
    rows = np.flatnonzero(tri.segment_source >= poly.size)      # the polyline's
    with pytest.raises(ValueError, match="segment rows must lie in"):
        lm.release_segments([k])
    saved = saved_state(lm, tmp_path / "before.npz")
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        raise RuntimeError("flips failed")

    original = tri.make_delaunay
    tri.make_delaunay = failing
    with pytest.raises(RuntimeError, match="flips failed"):
        lm.release_segments(rows)
    assert calls
    del tri.make_delaunay
    assert tri.make_delaunay == original
    assert_same_state(saved_state(lm, tmp_path / "after.npz"), saved)
    assert lm.release_segments(rows) == rows.size
    assert tri.segments.shape[0] == k - rows.size and lm.nodes.shape[0] == n
    assert (tri.segment_source < poly.size).all()
    check_constrained(lm)
    check_chain(lm, poly, closed=True)
    np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-13)
    # the mesh the polygon alone gives (random nodes: unique), not the one with the line
    alone = LagrangianMesh(lm.nodes, segments=segs[:poly.size]).triangulation
    assert edge_set(tri.triangles) == edge_set(alone.triangles) != kept


def test_shift_nodes_moves_flips_or_refuses(tmp_path):
    """Small shifts move the nodes and flips restore the constrained Delaunay property
    (integrals kept); a shift that inverts a triangle, of a wall node, or non-finite,
    is refused with the mesh as it was."""
    nodes, segs, poly, _ = outlined_square(300, 6)
    lm = LagrangianMesh(nodes, segments=segs, ip_fields={"one": np.ones(3)})
    area = lm.ip_integral("one")
    centre = lm.nodes[poly].mean(axis=0)
    out = 0.004 * (lm.nodes[poly] - centre)          # the polygon grows by 0.4%
    saved = saved_state(lm, tmp_path / "before.npz")
    wall = int(np.flatnonzero(lm.nodes[:, 1] == 0.0)[1])
    for idx, dx, word in (([wall], [[0.01, 0]], f"node {wall} is on a wall"),
                          (poly, 50 * out, "would invert triangle"),
                          (poly[:1], [[np.nan, 0]], "finite")):
        with pytest.raises(ValueError, match=word):
            lm.shift_nodes(idx, dx)
        assert_same_state(saved_state(lm, tmp_path / "after.npz"), saved)
    x = lm.nodes.copy()
    lm.shift_nodes(poly, out)
    np.testing.assert_array_equal(lm.nodes[poly], x[poly] + out)
    check_constrained(lm)
    np.testing.assert_allclose(lm.ip_integral("one"), area, rtol=1e-13)


def towards_the_bottom(x):
    """Every node drawn towards the bottom wall and spread along it (free slip): the gap
    under a sinking plate, where the nodes are squeezed flat and stretched."""
    return np.c_[(x[:, 0] - 0.5) * 4 * x[:, 0] * (1 - x[:, 0]), -2 * x[:, 1] * (1 - x[:, 1])]


def two_lines_over_the_bottom(seed=1, k=17):
    """Random nodes in the unit square and two open polylines of k nodes, at y = 0.2 and
    0.4, for the flow ``towards_the_bottom`` to squeeze."""
    xs = np.linspace(0.3, 0.7, k)
    lines = np.r_[np.c_[xs, np.full(k, 0.2)], np.c_[xs, np.full(k, 0.4)]]
    p = square_nodes(400, 16, seed, jitter=0.3, margin=0.01)
    d, _ = cKDTree(lines).query(p)
    p = p[(d > 0.03) | (np.arange(p.shape[0]) < 64)]
    a, b = p.shape[0] + np.arange(k), p.shape[0] + k + np.arange(k)
    return np.r_[p, lines], np.r_[np.c_[a[:-1], a[1:]], np.c_[b[:-1], b[1:]]]


def test_a_merge_never_leaves_a_segment_that_the_next_split_splits_again():
    """Line nodes squeezed flat (crowded by area) while their line is stretched keep
    their place: merging one would leave a segment longer than the split length, split
    again in the next step (measured before this rule: 13 merges, then 11 splits)."""
    nodes, segs = two_lines_over_the_bottom()
    lm = LagrangianMesh(nodes, segments=segs)
    for _ in range(20):
        lm.advance(towards_the_bottom, 0.1, inject=2.0)
    on_line = lm.segment_nodes()
    crowded = lm.spacing_ratios() < CLUSTER_FRACTION
    assert np.count_nonzero(crowded & on_line) >= 10   # the squeezed line nodes
    rep = lm.merge_nodes()
    assert rep["removed"] > 100 and rep["merged"] <= 3
    check_constrained(lm)
    assert lm.split_segments(2.0) == 0


def test_injection_skips_places_where_the_new_node_would_be_removed_at_once():
    """In the squeezed gap the grown nodes' areas lie in slivers: a node injected there
    would be crowded at once and merged out in the same step (measured without the
    rule: 63 of 328 injected nodes)."""
    lm = LagrangianMesh(square_nodes(300, 16, 0, jitter=0.3, margin=0.01))
    injected = lost = 0
    for _ in range(25):
        n0 = lm.nodes.shape[0]
        rep = lm.advance(towards_the_bottom, 0.1, inject=2.0, merge=True)
        injected += rep["injected"]
        lost += int((lm.node_map[n0:] < 0).sum())   # injected this step, removed again
        check_constrained(lm)
    assert injected > 50
    assert lost <= 0.05 * injected


def cell(x):
    """One convection cell (free slip on the unit square's walls): nodes run down the
    left wall and spread apart along the bottom wall from its left corner."""
    s, c = np.sin(np.pi * x), np.cos(np.pi * x)
    return np.c_[s[:, 0] * c[:, 1], -c[:, 0] * s[:, 1]]


def test_injection_refines_the_walls_too():
    """Where the flow spreads the nodes of a wall apart, long wall edges are split: new
    nodes on the wall exactly, known as wall nodes (a removal keeps them on it), node
    fields interpolated along the wall, integrals of the ip fields kept. Without it the
    bottom wall ends with its two corners alone (measured: 13 nodes -> 2 after 30 steps)."""
    nodes = square_nodes(300, 12, 2, jitter=0.3, margin=0.01)
    lm = LagrangianMesh(nodes, ip_fields={"one": np.ones(3)}, node_fields={"x0": nodes})
    split = 0
    for _ in range(30):
        rep = lm.advance(cell, 0.05, inject=2.0, merge=True)
        split += rep["walls_split"]
        check_constrained(lm)
    assert split >= 10
    P, W = lm.nodes, lm.on_walls
    bottom = np.sort(P[P[:, 1] == 0.0, 0])
    assert bottom.size >= 8 and np.diff(bottom).max() < 0.25
    np.testing.assert_array_equal(W[:, 1], (P[:, 1] == 0.0) | (P[:, 1] == 1.0))
    np.testing.assert_array_equal(W[:, 0], (P[:, 0] == 0.0) | (P[:, 0] == 1.0))
    np.testing.assert_allclose(lm.ip_integral("one"), 1.0, rtol=1e-12)
    np.testing.assert_allclose(lm.node_fields["x0"][P[:, 1] == 0.0, 1], 0.0, atol=1e-12)


def test_a_node_pressed_against_a_wall_is_removed():
    """An interior node 1e-4 from the bottom wall (a node stopped short of the wall step
    after step) is crowded by its distance to the wall, though its share of the areas is
    not small; a node at a normal distance is not."""
    p = square_nodes(200, 12, 4, jitter=0.3, margin=0.01)
    lm = LagrangianMesh(np.r_[p, [[0.47, 1e-4]]])
    ratio = lm.spacing_ratios()
    k = lm.nodes.shape[0] - 1
    share = np.zeros(k + 1)
    area = 0.5 * lm.triangulation.orientation()
    np.add.at(share, lm.triangles.ravel(), np.repeat(area / 3, 3))
    assert share[k] > 0.04 * np.median(share)           # not crowded by its area
    assert ratio[k] < 0.01 * CLUSTER_FRACTION / WALL_GAP_FRACTION < CLUSTER_FRACTION
    assert ratio[k] == ratio.min()
    rep = lm.merge_nodes()
    assert rep["node_map"][k] == -1
    check_constrained(lm)


def test_a_pair_on_top_of_each_other_is_joined():
    """Two interior nodes that come 1e-9 apart share one Voronoi cell, so each keeps about
    half a normal area and the area rule would keep both; the distance to the nearest node
    catches them: one of the two goes, and nothing else (a converging flow that brings two
    nodes together made an old-grid run crawl at a tiny dt before)."""
    from skfem_nem.evolution.merging import PAIR_GAP_FRACTION
    nodes = square_nodes(200, seed=3)
    inner = np.flatnonzero((nodes > 0.2).all(axis=1) & (nodes < 0.8).all(axis=1))
    a = int(inner[0])
    twin = nodes[a] + [1e-9, 0.0]
    lm = LagrangianMesh(np.vstack([nodes, twin]))
    ratio = lm.spacing_ratios()
    b = nodes.shape[0]
    assert ratio[a] < 1e-6 and ratio[b] < 1e-6            # caught by the distance
    # well apart, the distance rule leaves a node alone
    spacing = np.sqrt(lm.reference_areas())
    far = np.flatnonzero(ratio[:b] >= CLUSTER_FRACTION)
    assert far.size > 0.9 * b
    alone = LagrangianMesh(nodes).merge_nodes()["removed"]   # the draw's own crowding
    rep = lm.merge_nodes()
    assert rep["removed"] == alone + 1
    d, _ = cKDTree(lm.nodes).query(np.vstack([nodes[a], twin]), k=2)
    assert d[:, 0].max() < 2e-9 and d[:, 1].min() > 1e-3      # one of the two is left
    assert PAIR_GAP_FRACTION < CLUSTER_FRACTION and np.all(spacing > 0)
