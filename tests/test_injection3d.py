"""Nodes added to 3D tetrahedralisations and to the 3D evolving mesh: an insertion gives the
tetrahedra a fresh build gives (random, lattice and outside points), and a flow that
stretches the mesh keeps every edge within the split bound while the integrals, linear
node fields and walls are kept; bad points leave everything as it was."""
import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from skfem_nem import LagrangianMesh3D
from skfem_nem.evolution.injection3d import SPLIT_FACTOR_3D, tet_edges
from skfem_nem.geometry.delaunay3d import Delaunay3D
from skfem_nem.geometry.nodesets3d import box_nodes_3d

from test_delaunay3d import check_tetrahedralisation, tet_set
from test_delaunay3d_repair import swirl

FEW = settings(max_examples=30, deadline=None)


def inserted_and_checked(p, q):
    d = Delaunay3D(p)
    before = (d.points.copy(), d.simplices.copy(), d.neighbors.copy())
    out = d.inserted(q)
    allp = np.concatenate([p, q])
    assert tet_set(out) == tet_set(Delaunay3D(allp))
    check_tetrahedralisation(allp, out, brute=True)
    assert all(np.array_equal(a, b) for a, b in zip(before, (d.points, d.simplices,
                                                              d.neighbors)))
    return out


@FEW
@given(st.integers(5, 60), st.integers(1, 30), st.integers(0, 2 ** 31))
@example(40, 1, 0)
def test_inserted_points_give_the_fresh_tetrahedralisation(n, k, seed):
    """New points inside and outside the hull (the ghost vertex renumbered)."""
    rng = np.random.default_rng(seed)
    inserted_and_checked(rng.random((n, 3)), 1.6 * rng.random((k, 3)) - 0.3)


@FEW
@given(st.integers(2, 4), st.integers(0, 2 ** 31))
def test_inserted_lattice_points_give_the_fresh_tetrahedralisation(m, seed):
    """Cospherical lattices, new lattice points at half steps (ties broken as a build
    breaks them)."""
    g = np.linspace(0, 1, m)
    p = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    h = np.linspace(0.5 / (m - 1), 1 - 0.5 / (m - 1), m - 1)
    q = np.stack(np.meshgrid(h, g, h), -1).reshape(-1, 3)
    q = q[np.random.default_rng(seed).permutation(len(q))[:max(1, len(q) // 2)]]
    inserted_and_checked(p, q)


@pytest.mark.parametrize("q, words", [
    ([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]], "new point 1 at [0.5, 0.5, 0.5] coincides with new "
                                        "point 0"),
    ([[0.25, 0.5, 0.5], [0.0, 0.0, 0.0]], "new point 1 at [0.0, 0.0, 0.0] coincides with node 0"),
    ([[np.nan, 0, 0]], "points[0] = [nan, 0.0, 0.0] is not finite"),
    ([1.0, 2.0], "points must have shape (k, 3)"),
])
def test_bad_new_points_are_named(q, words):
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.0]])
    d = Delaunay3D(p)
    with pytest.raises(ValueError) as err:
        d.inserted(np.array(q, dtype=float))
    assert words in str(err.value)


def ratio(lm):
    """The longest edge over the larger target spacing of its nodes."""
    e = tet_edges(lm.mesh.t.T)
    p, h = lm.nodes, lm.target_spacing
    return (np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
            / np.maximum(h[e[:, 0]], h[e[:, 1]])).max()


def test_a_stretching_flow_keeps_every_edge_within_the_bound():
    """A vortex held for 40 steps: without injection the longest edge grows to about nine
    target spacings; with it, no edge exceeds the bound after any step, nodes are added on
    the walls too, the tetrahedra are those of the nodes, and a split keeps the
    integration-point integral."""
    runs = {}
    for inject in (None, SPLIT_FACTOR_3D):
        p = box_nodes_3d(300, seed=0)
        lm = LagrangianMesh3D(p, {"x0": p.copy(), "f": 2 * p[:, 0] - p[:, 2]},
                              remap="conservative")
        assert ratio(lm) <= SPLIT_FACTOR_3D
        rng = np.random.default_rng(0)
        lm.ip_fields = {"s": rng.random((lm.mesh.nelements, 4))}
        worst = 0.0
        for _ in range(40):
            n = lm.nodes.shape[0]
            rep = lm.advance(swirl, 0.05, tol=1e-8, inject=inject)
            worst = max(worst, ratio(lm))
            assert rep["injected"] == lm.nodes.shape[0] - n
        runs[inject] = (lm, worst)
    lm0, worst0 = runs[None]
    lm, worst = runs[SPLIT_FACTOR_3D]
    assert worst0 > 2 * SPLIT_FACTOR_3D and lm0.history[-1]["injected"] == 0
    assert worst <= SPLIT_FACTOR_3D * (1 + 1e-12)
    added = lm.nodes.shape[0] - runs[None][0].nodes.shape[0]
    assert added > 50
    new = np.arange(lm0.nodes.shape[0], lm.nodes.shape[0])
    on_wall = ((lm.nodes[new] == 0) | (lm.nodes[new] == 1)).any(axis=1)
    assert on_wall.sum() > 10 and (~on_wall).any()
    # an added node's fields: the Sibson interpolant where it was added (linear: exact;
    # x0 of an added node is its position then, not its initial one)
    f = lm.node_fields["f"]
    assert f.shape == (lm.nodes.shape[0],)
    assert tet_set_of(lm) == tet_set(Delaunay3D(np.array(lm.nodes)))
    # splitting (nodes that do not move) keeps the integral to round-off
    before = lm.ip_integral("s")
    assert lm.split_long_edges(2.0) > 0
    np.testing.assert_allclose(lm.ip_integral("s"), before, rtol=1e-12)


def tet_set_of(lm):
    return {tuple(sorted(t)) for t in lm.mesh.t.T.tolist()}


def test_inserted_nodes_take_interpolated_fields_and_keep_integrals():
    p = box_nodes_3d(200, seed=3)
    lm = LagrangianMesh3D(p, {"lin": p @ [1.0, -2.0, 0.5], "vec": np.c_[p, 2 * p]})
    rng = np.random.default_rng(1)
    lm.ip_fields = {"t": rng.standard_normal((lm.mesh.nelements, 4, 3, 3))}
    before = lm.ip_integral("t")
    x = np.array([[0.3, 0.4, 0.5], [0.7, 0.2, 0.0], [0.5, 1.0, 0.5]])
    lm.insert_nodes(x)
    n = lm.nodes.shape[0]
    np.testing.assert_array_equal(lm.nodes[-3:], x)
    np.testing.assert_allclose(lm.node_fields["lin"][-3:], x @ [1.0, -2.0, 0.5], atol=1e-13)
    np.testing.assert_allclose(lm.node_fields["vec"][-3:], np.c_[x, 2 * x], atol=1e-13)
    np.testing.assert_allclose(lm.ip_integral("t"), before, atol=1e-13)
    assert lm.target_spacing.shape == (n,) and lm.ip_fields["t"].shape[0] == lm.mesh.nelements
    assert tet_set_of(lm) == tet_set(Delaunay3D(np.array(lm.nodes)))


@pytest.mark.parametrize("x, words", [
    ([[0.5, 0.5, 1.2]], "points[0] = [0.5, 0.5, 1.2] lies outside the box"),
    ([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]], "coincides with new point 0"),
])
def test_bad_inserted_nodes_leave_the_mesh_as_it_was(x, words):
    p = box_nodes_3d(100, seed=4)
    lm = LagrangianMesh3D(p, {"a": p[:, 0].copy()})
    lm.ip_fields = {"s": np.ones((lm.mesh.nelements, 4))}
    state = (lm.nodes.copy(), lm.mesh.t.copy(), lm.target_spacing.copy(),
             lm.node_fields["a"].copy(), lm.ip_fields["s"].copy())
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
        lm.insert_nodes(x)
    after = (lm.nodes, lm.mesh.t, lm.target_spacing, lm.node_fields["a"], lm.ip_fields["s"])
    assert all(np.array_equal(a, b) for a, b in zip(state, after))


def test_a_failed_step_takes_its_injected_nodes_back(monkeypatch):
    """A step whose injection fails (here the remap of its second split, after the repair
    and a first split) leaves the nodes, fields, targets and tetrahedra of its start."""
    from skfem_nem.evolution import injection3d
    p = box_nodes_3d(300, seed=0)
    lm = LagrangianMesh3D(p, {"a": p[:, 0].copy()})
    lm.ip_fields = {"s": np.ones((lm.mesh.nelements, 4))}
    for _ in range(12):
        lm.advance(swirl, 0.05, tol=1e-8)
    assert lm.long_edges().size
    state = (lm.nodes.copy(), lm.mesh.t.copy(), lm.target_spacing.copy(),
             lm.node_fields["a"].copy(), lm.ip_fields["s"].copy(), lm.time, len(lm.history))
    calls = []
    remap = injection3d.remap_fields

    def failing(*args):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("remap failed")
        return remap(*args)
    monkeypatch.setattr(injection3d, "remap_fields", failing)
    with pytest.raises(RuntimeError, match="remap failed"):
        lm.advance(swirl, 0.05, tol=1e-8, inject=1.5)
    assert len(calls) == 2
    after = (lm.nodes, lm.mesh.t, lm.target_spacing, lm.node_fields["a"], lm.ip_fields["s"],
             lm.time, len(lm.history))
    assert all(np.array_equal(a, b) for a, b in zip(state, after))


def test_save_and_load_carry_the_targets(tmp_path):
    p = box_nodes_3d(200, seed=5)
    lm = LagrangianMesh3D(p)
    for _ in range(10):
        lm.advance(swirl, 0.05, tol=1e-8, inject=SPLIT_FACTOR_3D)
    lm.save(tmp_path / "m.npz")
    back = LagrangianMesh3D.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(back.target_spacing, lm.target_spacing)
    np.testing.assert_array_equal(back.nodes, lm.nodes)


# --------------------------------------------------------------------------
# removal
# --------------------------------------------------------------------------

def removed_and_checked(p, idx):
    d = Delaunay3D(p)
    before = (d.points.copy(), d.simplices.copy(), d.neighbors.copy())
    out = d.removed(idx)
    keep = np.ones(p.shape[0], bool)
    keep[idx] = False
    np.testing.assert_array_equal(out.points, p[keep])
    assert tet_set(out) == tet_set(Delaunay3D(p[keep]))
    check_tetrahedralisation(p[keep], out, brute=True)
    assert all(np.array_equal(a, b) for a, b in zip(before, (d.points, d.simplices,
                                                              d.neighbors)))
    return out


@FEW
@given(st.integers(8, 60), st.integers(0, 2 ** 31), st.floats(0.05, 0.6))
@example(40, 0, 0.5)
def test_removed_points_give_the_fresh_tetrahedralisation(n, seed, share):
    """Interior and hull nodes removed (the hull shrinks with them)."""
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    k = max(1, min(n - 5, int(share * n)))
    out = removed_and_checked(p, rng.choice(n, k, replace=False))
    # the result is a working tetrahedralisation: it can be moved and added to
    q = out.points + 0.01 * rng.standard_normal(out.points.shape)
    assert tet_set(out.moved(q)[0]) == tet_set(Delaunay3D(q))
    assert tet_set(out.inserted([[0.5, 0.5, 0.5]])) == tet_set(
        Delaunay3D(np.r_[out.points, [[0.5, 0.5, 0.5]]]))


@FEW
@given(st.integers(3, 4), st.integers(0, 2 ** 31))
def test_removed_lattice_points_give_the_fresh_tetrahedralisation(m, seed):
    g = np.linspace(0, 1, m)
    p = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    removed_and_checked(p, rng.choice(p.shape[0], int(rng.integers(1, p.shape[0] // 2)),
                                      replace=False))


@pytest.mark.parametrize("idx, words", [
    ([9], "index 9 is out of range for 6 nodes"),
    ([1, 1], "indices must not repeat"),
    ([0, 1], "removing 2 of 6 nodes would leave fewer than 5"),
])
def test_bad_removals_are_named(idx, words):
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.0], [0.3, 0.3, 0.3]])
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        Delaunay3D(p).removed(idx)


def squeeze(p):
    """A flow towards the plane x = 1/2, tangent to the unit cube's walls: it crowds."""
    x = p[:, 0]
    return np.c_[4 * (0.5 - x) * x * (1 - x), np.zeros(p.shape[0]), np.zeros(p.shape[0])]


def shortest(lm):
    """The shortest edge over the smaller target spacing of its nodes."""
    e = tet_edges(lm.mesh.t.T)
    p, h = lm.nodes, lm.target_spacing
    return (np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
            / np.minimum(h[e[:, 0]], h[e[:, 1]])).min()


def test_a_crowding_flow_keeps_the_nodes_apart():
    """Nodes squeezed towards a plane for 30 steps: without removal the shortest edge falls
    far below a fifth of the target spacing; with it, not below a fifth after any step, the
    node fields follow their nodes through the node maps, and the tetrahedra are those of
    the nodes."""
    worst = {}
    for remove in (None, 0.2):
        p = box_nodes_3d(300, seed=2)
        lm = LagrangianMesh3D(p, {"id": np.arange(p.shape[0]).astype(float)})
        ids = np.arange(p.shape[0])
        w = np.inf
        for _ in range(30):
            rep = lm.advance(squeeze, 0.2, tol=1e-8, maxiter=20, remove=remove)
            assert rep["removed"] == np.count_nonzero(lm.node_map < 0)
            ids = ids[lm.node_map >= 0]
            w = min(w, shortest(lm))
        np.testing.assert_array_equal(lm.node_fields["id"], ids)
        assert tet_set_of(lm) == tet_set(Delaunay3D(np.array(lm.nodes)))
        worst[remove] = (w, lm.nodes.shape[0], p.shape[0])
    assert worst[None][0] < 0.05 and worst[None][1] == worst[None][2]
    assert worst[0.2][0] >= 0.2 * (1 - 1e-12) and worst[0.2][1] < worst[0.2][2]
    corners = (lm._on_wall.sum(axis=1) == 3).sum()
    assert corners == 8


def test_removal_keeps_integrals_and_refuses_corners():
    p = box_nodes_3d(300, seed=6)
    lm = LagrangianMesh3D(p, {"a": p[:, 0].copy()}, remap="conservative")
    rng = np.random.default_rng(2)
    lm.ip_fields = {"t": rng.standard_normal((lm.mesh.nelements, 4, 3))}
    before = lm.ip_integral("t")
    inner = np.flatnonzero(~lm._on_wall.any(axis=1))[:20]
    face = np.flatnonzero(lm._on_wall.sum(axis=1) == 1)[:5]
    node_map = lm.remove_nodes(np.r_[inner, face])
    np.testing.assert_allclose(lm.ip_integral("t"), before, atol=1e-12)
    assert (node_map < 0).sum() == 25 and lm.nodes.shape[0] == p.shape[0] - 25
    np.testing.assert_array_equal(lm.node_fields["a"], lm.nodes[:, 0])
    corner = int(np.flatnonzero(lm._on_wall.sum(axis=1) == 3)[0])
    state = (lm.nodes.copy(), lm.mesh.t.copy(), lm.ip_fields["t"].copy())
    with pytest.raises(ValueError, match=f"node {corner} is a corner of the box"):
        lm.remove_nodes([corner])
    with pytest.raises(ValueError, match="out of range"):
        lm.remove_nodes([10 ** 6])
    assert all(np.array_equal(a, b) for a, b in zip(state, (lm.nodes, lm.mesh.t,
                                                              lm.ip_fields["t"])))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 6), st.integers(1, 40), st.integers(0, 10**6))
def test_tet_edges_are_each_edge_once_in_order(m, n, seed):
    """The edges by integer keys are ``np.unique``'s rows: each once, lower node first,
    in lexicographic order, in the tetrahedra's index type."""
    rng = np.random.default_rng(seed)
    t = rng.integers(0, n, size=(m, 4)).astype([np.int32, np.int64][seed % 2])
    e = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
    ref = np.unique(np.sort(e, axis=1), axis=0)
    got = tet_edges(t)
    assert got.dtype == t.dtype and got.shape == ref.shape and np.array_equal(got, ref)
