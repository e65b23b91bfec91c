import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
from scipy.spatial import Delaunay

from helpers import edge_set
from skfem_nem import Triangulation


def check_valid(tri):
    T, N = tri.triangles, tri.neighbours
    assert np.all(tri.orientation() > 0)
    # adjacency is symmetric and neighbours share the right edge
    for t in range(T.shape[0]):
        for k in range(3):
            u = N[t, k]
            if u < 0:
                continue
            assert t in N[u]
            e = {T[t, (k + 1) % 3], T[t, (k + 2) % 3]}
            assert e <= set(T[u])
    # Euler: triangles = 2n - 2 - hull vertices
    nh = np.count_nonzero(N < 0)
    assert T.shape[0] == 2 * tri.npoints - 2 - nh


def test_random_matches_qhull():
    rng = np.random.default_rng(0)
    p = rng.random((500, 2))
    tri = Triangulation(p)
    check_valid(tri)
    assert tri.is_delaunay()
    assert edge_set(tri.triangles) == edge_set(Delaunay(p).simplices)


def test_structured_grid_is_delaunay():
    x, y = np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 2, 7))
    p = np.c_[x.ravel(), y.ravel()]
    tri = Triangulation(p)
    check_valid(tri)
    assert tri.is_delaunay()
    assert tri.ntriangles == 2 * 8 * 6


def test_collinear_hull_runs():
    # many nodes on each side of the square: collinear hull runs
    s = np.linspace(0, 1, 21)
    p = np.r_[np.c_[s, 0 * s], np.c_[s, 1 + 0 * s], np.c_[0 * s[1:-1], s[1:-1]],
              np.c_[1 + 0 * s[1:-1], s[1:-1]], [[0.5, 0.5], [0.3, 0.6]]]
    tri = Triangulation(p)
    check_valid(tri)
    assert tri.is_delaunay()
    assert len(tri.hull_edges) == 80


def test_lawson_repairs_any_triangulation():
    # start from a valid but non-Delaunay triangulation: a grid triangulation
    # whose nodes were jittered (connectivity kept), no inverted triangles
    rng = np.random.default_rng(1)
    n = 15
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    p = np.c_[x.ravel(), y.ravel()]
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    T = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    interior = (p[:, 0] > 0) & (p[:, 0] < 1) & (p[:, 1] > 0) & (p[:, 1] < 1)
    p[interior] += 0.3 / n * (rng.random((interior.sum(), 2)) - 0.5)
    tri = Triangulation.from_triangles(p, T, make_delaunay=False)
    check_valid(tri)
    assert not tri.is_delaunay()
    flips = tri.make_delaunay()
    assert flips > 0
    check_valid(tri)
    assert tri.is_delaunay()
    assert edge_set(tri.triangles) == edge_set(Delaunay(p).simplices)


def test_locate_and_cavity():
    rng = np.random.default_rng(2)
    p = rng.random((300, 2))
    tri = Triangulation(p)
    q = 0.05 + 0.9 * rng.random((200, 2))
    t = tri.locate(q)
    assert np.all(t >= 0)
    for qi, ti in zip(q, t):
        a, b, c = p[tri.triangles[ti]]
        # barycentric coordinates all >= 0
        M = np.c_[b - a, c - a]
        lam = np.linalg.solve(M, qi - a)
        assert lam.min() >= -1e-12 and lam.sum() <= 1 + 1e-12
    # outside
    assert np.all(tri.locate(np.array([[2.0, 2.0], [-1, 0.5]])) == -1)
    # cavity = brute-force set of triangles whose circumcircle contains the point
    x = q[0]
    cav = tri.cavity(x)
    brute = [s for s in range(tri.ntriangles) if tri.incircle(s, x) > 0]
    assert list(cav) == brute
    assert tri.cavity(p[5]).size == 0
    with pytest.raises(ValueError, match="outside"):
        tri.cavity([3.0, 3.0])


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(4, 60),
       st.sampled_from(["uniform", "clustered", "nearly_collinear", "grid"]))
def test_hypothesis_delaunay(seed, n, kind):
    rng = np.random.default_rng(seed)
    if kind == "uniform":
        p = rng.random((n, 2))
    elif kind == "clustered":
        p = np.r_[rng.random((n, 2)), 0.5 + 1e-7 * rng.random((n, 2))]
    elif kind == "nearly_collinear":
        t = rng.random(n)
        p = np.c_[t, 0.3 * t + 1e-9 * rng.standard_normal(n)]
        p = np.r_[p, [[0.5, 0.4]]]
    else:
        k = max(2, int(np.sqrt(n)))
        x, y = np.meshgrid(np.arange(k), np.arange(k + 1))
        p = np.c_[x.ravel(), y.ravel()].astype(float)
        p = p @ np.array([[1.0, 0.0], [0.5, 1.0]]) if seed % 2 else p
    tri = Triangulation(p)
    check_valid(tri)
    assert tri.is_delaunay()


@pytest.mark.parametrize("bad, match", [
    (np.array([[0, 0], [1, 0], [np.nan, 1]]), r"nodes\[2\]"),
    (np.array([[0, 0], [1, 0], [0, np.inf], [1, 1]]), r"nodes\[2\]"),
    (np.array([[0, 0], [1, 0]]), "at least 3"),
    (np.array([[0, 0], [1, 1], [2, 2], [3, 3]]), "collinear"),
    (np.array([[0, 0], [1, 0], [0, 1], [1, 0]]), r"nodes\[3\] coincides with nodes\[1\]"),
    (np.zeros((3, 3)), "shape"),
])
def test_bad_nodes(bad, match):
    before = bad.copy()
    with pytest.raises(ValueError, match=match):
        Triangulation(bad)
    np.testing.assert_array_equal(bad, before)


def test_near_duplicate_named():
    p = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0.5], [0.5, 0.5 + 1e-17]])
    # 0.5 + 1e-17 == 0.5 in double: an exact duplicate
    with pytest.raises(ValueError, match=r"nodes\[5\] coincides with nodes\[4\]"):
        Triangulation(p)


def test_caller_arrays_untouched():
    rng = np.random.default_rng(3)
    p = rng.random((50, 2))
    before = p.copy()
    tri = Triangulation(p)
    np.testing.assert_array_equal(p, before)
    assert not tri.nodes.flags.writeable


@pytest.mark.parametrize("scale", [1e-7, 1e-9, 1e-12])
def test_clusters_of_nearly_coincident_nodes(scale):
    # Qhull drops or folds such clusters; every node must still be a vertex
    # of a valid Delaunay triangulation
    rng = np.random.default_rng(39)
    p = np.r_[rng.random((38, 2)), 0.5 + scale * rng.random((38, 2)),
              [[0.2, 0.3]] + scale * rng.random((5, 2))]
    tri = Triangulation(p)
    check_valid(tri)
    assert tri.is_delaunay()
    used = np.zeros(p.shape[0], bool)
    used[tri.triangles.ravel()] = True
    assert used.all()


# -- the mutation API (what the evolving mesh uses) ------------------------------

def _interior(tri):
    hull = np.unique(tri.hull_edges)
    return np.setdiff1d(np.arange(tri.npoints), hull)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(8, 60), st.booleans())
def test_remove_and_reinsert_vertex(seed, n, grid):
    """Removing an interior node refills its star with Delaunay triangles (the moves
    keep per-triangle data aligned); re-inserting it gives a Delaunay triangulation
    with the same edges as before (unique up to co-circular ties)."""
    rng = np.random.default_rng(seed)
    if grid:
        k = int(np.sqrt(n)) + 2
        x, y = np.meshgrid(np.linspace(0, 1, k), np.linspace(0, 1, k))
        p = np.c_[x.ravel(), y.ravel()]
    else:
        p = np.r_[rng.random((n, 2)), [[-1, -1], [2, -1], [2, 2], [-1, 2]]]
    tri = Triangulation(p)
    v = int(rng.choice(_interior(tri)))
    before, nt = edge_set(tri.triangles), tri.ntriangles
    label = np.arange(nt)  # data stored per triangle, follows the moves
    star = tri.star(v)
    slots, moves = tri.remove_vertex(v)
    for src, dst in moves:
        label[dst] = label[src]
    label = label[:tri.ntriangles]
    assert tri.ntriangles == label.size == nt - 2
    assert not (tri.triangles == v).any()
    assert slots.size == star.size - 2
    # triangles not in the star kept their data
    untouched = np.setdiff1d(np.arange(tri.ntriangles), slots)
    assert np.isin(label[untouched], star, invert=True).all()
    check_valid_without(tri, v)
    cav, new = tri.reinsert_vertex(v)
    assert new.size == 2
    check_valid(tri)
    if not grid:  # random nodes: the Delaunay triangulation is unique
        assert edge_set(tri.triangles) == before


def check_valid_without(tri, v):
    """A valid Delaunay triangulation of all nodes but v."""
    T, N = tri.triangles, tri.neighbours
    for t, k in zip(*np.nonzero(N >= 0)):
        u = N[t, k]
        assert t in N[u] and {T[t, (k + 1) % 3], T[t, (k + 2) % 3]} <= set(T[u])
    assert (tri.orientation() > 0).all()
    assert tri.non_delaunay_edges() == 0
    used = np.zeros(tri.npoints, bool)
    used[tri.triangles.ravel()] = True
    assert used.sum() == tri.npoints - 1 and not used[v]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(4, 40), st.integers(3, 9))
def test_remove_wall_vertex(seed, n, per_side):
    """A node on a straight stretch of the hull (a wall node between two wall nodes)
    can be removed: its open fan is refilled, the hull keeps its shape (the same area),
    the result is the Delaunay triangulation of the other nodes; corners cannot."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, per_side)
    walls = np.r_[np.c_[s, 0 * s], np.c_[s, 1 + 0 * s], np.c_[0 * s[1:-1], s[1:-1]],
                  np.c_[1 + 0 * s[1:-1], s[1:-1]]]
    walls[:, 0] *= 2  # a 2 x 1 box
    p = np.r_[walls, rng.uniform([0.05, 0.05], [1.95, 0.95], (n, 2))]
    tri = Triangulation(p)
    area = 0.5 * tri.orientation().sum()
    on_wall = np.flatnonzero(((p[:, 0] == 0) | (p[:, 0] == 2)) ^ ((p[:, 1] == 0) | (p[:, 1] == 1)))
    corners = np.flatnonzero(((p[:, 0] == 0) | (p[:, 0] == 2)) & ((p[:, 1] == 0) | (p[:, 1] == 1)))
    for c in corners:
        assert not tri.removable(int(c))
        with pytest.raises(ValueError, match=f"node {c} is a corner"):
            tri.remove_vertex(int(c))
    v = int(rng.choice(on_wall))
    assert tri.removable(v)
    fan, nt = tri.fan(v), tri.ntriangles
    label = np.arange(nt)
    slots, moves = tri.remove_vertex(v)
    for src, dst in moves:
        label[dst] = label[src]
    assert tri.ntriangles == nt - 1 and slots.size == fan.size - 1
    untouched = np.setdiff1d(np.arange(tri.ntriangles), slots)
    assert np.isin(label[:tri.ntriangles][untouched], fan, invert=True).all()
    check_valid_without(tri, v)
    assert 0.5 * tri.orientation().sum() == pytest.approx(area, rel=1e-14)
    assert len(tri.hull_edges) == 4 * (per_side - 1) - 1


def test_star_of_hull_node_raises():
    tri = Triangulation(np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.4, 0.5]]))
    with pytest.raises(ValueError, match="node 0 is on the hull"):
        tri.star(0)
    assert tri.star(4).size == 4


def test_move_snapshot_restore_split():
    rng = np.random.default_rng(3)
    tri = Triangulation(rng.random((40, 2)))
    snap = tri.snapshot()
    with pytest.raises(ValueError, match=r"moved nodes must have shape \(40, 2\)"):
        tri.move_nodes(np.zeros((39, 2)))
    x = tri.nodes @ np.array([[1.0, 0.0], [0.8, 1.0]])  # a shear: no triangle inverts
    tri.move_nodes(x)
    assert np.array_equal(tri.nodes, x) and not tri.nodes.flags.writeable
    assert (tri.orientation() > 0).all() and not tri.is_delaunay()
    assert tri.make_delaunay() > 0
    t = int(np.argmax(tri.orientation()))
    i = tri.split_triangle(t, tri.nodes[tri.triangles[t]].mean(axis=0))
    assert i == 40 and tri.ntriangles == snap["triangles"].shape[0] + 2
    assert (tri.orientation() > 0).all()
    tri.make_delaunay()
    check_valid(tri)
    tri.restore(snap)
    assert tri.nodes is snap["nodes"]
    assert np.array_equal(tri.triangles, snap["triangles"])
    assert np.array_equal(tri.neighbours, snap["neighbours"])
    assert tri.triangles is not snap["triangles"]  # the snapshot stays reusable
    check_valid(tri)


def test_from_arrays_checks_shapes():
    tri = Triangulation(np.random.default_rng(0).random((20, 2)))
    copy = Triangulation.from_arrays(tri.nodes, tri.triangles, tri.neighbours)
    assert np.array_equal(copy.triangles, tri.triangles) and copy.is_delaunay()
    with pytest.raises(ValueError, match="inconsistent shapes"):
        Triangulation.from_arrays(tri.nodes, tri.triangles, tri.neighbours[:-1])
    bad = tri.triangles.copy()
    bad[0, 0] = 99
    with pytest.raises(ValueError, match="out of range"):
        Triangulation.from_arrays(tri.nodes, bad, tri.neighbours)


def test_arrays_are_c_ordered_whatever_the_input_layout():
    """The kernels are compiled once per array layout: a mesh's transposed arrays
    (Fortran order) must not give the triangulation another layout than nodes given
    row by row, or every kernel compiles twice on a first run."""
    from skfem import MeshTri
    m = MeshTri().refined(2)
    P, T = m.p.T, m.t.T
    assert P.flags.f_contiguous and not P.flags.c_contiguous
    for tri in (Triangulation(P), Triangulation(P, T),
                Triangulation.from_arrays(P, T, Triangulation(P, T).neighbours)):
        for a in (tri.nodes, tri.triangles, tri.neighbours):
            assert a.flags.c_contiguous
        tri.move_nodes(np.asfortranarray(tri.nodes + 0.0))
        assert tri.nodes.flags.c_contiguous


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(4, 30))
@example(2998, 4)   # Qhull folds these even after thinning: a fan over the exact hull
def test_batch_queries_on_a_side_straight_to_round_off(seed, k):
    """Nodes of a side x = 0 computed as r cos(pi / 2) (as a mapped mesh has them: on a
    line to round-off only, so the hull has reflex vertices by an ulp): points between
    the side's nodes, in one sorted batch, get the coordinates they get when queried
    alone (a walk from the previous point stopped at a hull edge they are beyond by an
    ulp, and the retry walked from there again)."""
    from skfem_nem import sibson_coordinates
    rng = np.random.default_rng(seed)
    y = np.sort(rng.uniform(1, 2, k))
    side = np.c_[y * np.cos(np.pi / 2), y]
    p = np.r_[side, [[1, 1], [1, 2.1], [0.5, 0.9]], rng.uniform([0.1, 1.1], [0.9, 1.9], (20, 2))]
    tri = Triangulation(p)
    q = 0.5 * (side[1:] + side[:-1])
    batch = sibson_coordinates(tri, q).toarray()
    alone = np.vstack([sibson_coordinates(tri, x[None]).toarray() for x in q])
    np.testing.assert_allclose(batch, alone, atol=1e-12)
    # (not asserted: linear precision there; a side node inside the hull by an ulp makes
    # triangles 1e-16 thin, and the areas of a point between them are ill-conditioned)
    assert np.allclose(batch.sum(axis=1), 1.0) and (batch >= -1e-12).all()


@pytest.mark.xfail(strict=True, reason="known defect: on the draw (seed 506, k = 4) of the "
                   "test above, found by a randomised run, the point between the side's "
                   "first two nodes gets a coordinate of -0.09 (nodes 0, 1, 2: 0.891, 0.199, "
                   "-0.090), where the others get 1/2 and 1/2. Qhull's start has flat "
                   "triangles there and the thinned start is taken")
def test_batch_queries_on_a_side_straight_to_round_off_known_draw():
    test_batch_queries_on_a_side_straight_to_round_off.hypothesis.inner_test(506, 4)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2 ** 16), n=st.integers(30, 120), k=st.integers(1, 12))
def test_stars_and_edges_stay_exact_through_vertex_removals(seed, n, k):
    """After vertices are taken out one by one (the triangle kept per vertex as a hint
    goes stale), every interior vertex's star is the walk from its lowest-numbered
    triangle, as a fresh search gives it, and the edges are the unique sorted vertex
    pairs of the triangles."""
    from skfem_nem.geometry.stars import star_of
    rng = np.random.default_rng(seed)
    tri = Triangulation(rng.random((n, 2)))
    removed = set()
    for v in rng.permutation(n).tolist():
        if len(removed) == k:
            break
        try:
            tri.remove_vertex(v)
        except ValueError:      # on the hull and not removable
            continue
        removed.add(v)
    T = tri.triangles
    for v in set(range(n)) - removed:
        first = int(np.flatnonzero((T == v).any(axis=1))[0])
        ref, closed = star_of(T, tri.neighbours, v, first)
        if closed:
            np.testing.assert_array_equal(tri.star(v), ref)
    e = np.sort(np.concatenate([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]]), axis=1)
    np.testing.assert_array_equal(tri.edges, np.unique(e, axis=0))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2 ** 16), n=st.integers(10, 80), k=st.integers(1, 20))
def test_split_triangles_is_the_splits_one_by_one(seed, n, k):
    """A batch of splits grows the arrays once and gives the triangulation (nodes,
    triangles, neighbours) of the same splits made one after the other."""
    rng = np.random.default_rng(seed)
    one = Triangulation(rng.random((n, 2)))
    batch = Triangulation(one.nodes.copy())
    ts = rng.permutation(one.ntriangles)[:k]
    w = rng.dirichlet([1.0, 1.0, 1.0], size=ts.size)
    xs = np.einsum("kj,kjd->kd", w, one.nodes[one.triangles[ts]])
    for t, x in zip(ts, xs):
        one.split_triangle(int(t), x)
    new = batch.split_triangles(ts, xs)
    np.testing.assert_array_equal(new, np.arange(n, n + ts.size))
    for a, b in ((one.nodes, batch.nodes), (one.triangles, batch.triangles),
                 (one.neighbours, batch.neighbours)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="distinct triangles"):
        batch.split_triangles([0, 0], np.zeros((2, 2)))
    np.testing.assert_array_equal(batch.nodes, one.nodes)      # nothing changed
    np.testing.assert_array_equal(batch.triangles, one.triangles)
