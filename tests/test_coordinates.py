import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial import cKDTree

from helpers import check_properties, dense
from skfem_nem import Triangulation, laplace_coordinates, sibson_coordinates

KINDS = [sibson_coordinates, laplace_coordinates]


def random_nodes(n, seed=0):
    """Random nodes in the unit square with its four corners (so the hull is the square)."""
    rng = np.random.default_rng(seed)
    return np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], rng.random((n - 4, 2))]


def interior_queries(m, seed=1, margin=0.02):
    rng = np.random.default_rng(seed)
    return margin + (1 - 2 * margin) * rng.random((m, 2))


def fd_check(tri, q, coords, h=1e-7, rtol=1e-5):
    """Central finite differences of the values against the gradients."""
    Phi, (Dx, Dy) = coords(tri, q, gradient=True)
    for k, D in enumerate((Dx, Dy)):
        e = np.zeros(2)
        e[k] = h
        fd = (dense(coords(tri, q + e)) - dense(coords(tri, q - e))) / (2 * h)
        G = dense(D)
        err = np.abs(fd - G).max()
        scale = max(1.0, np.abs(G).max())
        assert err < rtol * scale, f"FD mismatch {err:.2e} in direction {k}"


def away_from_hull(x, margin=0.05):
    return np.all((x > margin) & (x < 1 - margin), axis=1)


@pytest.mark.parametrize("coords", KINDS)
def test_kronecker_delta(coords):
    p = random_nodes(200)
    Phi = coords(p, p)
    np.testing.assert_array_equal(dense(Phi), np.eye(p.shape[0]))


@pytest.mark.parametrize("coords", KINDS)
def test_partition_of_unity_linear_precision(coords):
    p = random_nodes(400)
    q = np.r_[interior_queries(2000), np.random.default_rng(5).random((500, 2))]
    check_properties(p, q, coords)


@pytest.mark.parametrize("coords", KINDS)
def test_finite_differences_random(coords):
    p = random_nodes(300, seed=3)
    tri = Triangulation(p)
    fd_check(tri, interior_queries(300, seed=4), coords)


@pytest.mark.parametrize("coords", KINDS)
def test_on_delaunay_edges(coords):
    p = random_nodes(300, seed=6)
    tri = Triangulation(p)
    T, N = tri.triangles, tri.neighbours
    rng = np.random.default_rng(7)
    t, k = np.nonzero(N >= 0)
    sel = rng.choice(t.size, 200, replace=False)
    a = p[T[t[sel], (k[sel] + 1) % 3]]
    b = p[T[t[sel], (k[sel] + 2) % 3]]
    s = rng.uniform(0.1, 0.9, (sel.size, 1))
    q = a + s * (b - a)
    q = np.r_[q, 0.5 * (a + b)]
    check_properties(tri, q, coords)
    fd_check(tri, q[away_from_hull(q)], coords)
    # finite values everywhere (the Watson construction gives inf/NaN here)
    Phi, D = coords(tri, q, gradient=True)
    assert np.all(np.isfinite(Phi.data)) and all(np.all(np.isfinite(d.data)) for d in D)


@pytest.mark.parametrize("coords", KINDS)
def test_near_nodes(coords):
    p = random_nodes(200, seed=8)
    tri = Triangulation(p)
    rng = np.random.default_rng(9)
    i = rng.choice(np.flatnonzero(away_from_hull(p)), 50, replace=False)
    for r in (1e-3, 1e-6, 1e-9):
        ang = rng.uniform(0, 2 * np.pi, i.size)
        q = p[i] + r * np.c_[np.cos(ang), np.sin(ang)]
        # gradients lose digits like eps * spacing / r this close to a node
        F, _ = check_properties(tri, q, coords, tol=1e-12, grad_tol=max(1e-10, 1e-16 / r))
        # the node's own coordinate tends to one
        assert np.all(F[np.arange(i.size), i] > 1 - 1e4 * r)
    q = p[i] + 1e-4 * np.c_[np.cos(ang), np.sin(ang)]
    fd_check(tri, q, coords, h=1e-9, rtol=1e-5)


def circumcircle(a, b, c):
    d = 2 * ((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0])
    b_, c_ = b - a, c - a
    o = np.array([c_[1] * (b_ @ b_) - b_[1] * (c_ @ c_), b_[0] * (c_ @ c_) - c_[0] * (b_ @ b_)]) / d
    return a + o, np.hypot(*o)


@pytest.mark.parametrize("coords", KINDS)
def test_continuity_across_edges_and_circles(coords):
    p = random_nodes(200, seed=10)
    tri = Triangulation(p)
    T, N = tri.triangles, tri.neighbours
    rng = np.random.default_rng(11)
    pts, nrm = [], []
    # across interior edges
    t, k = np.nonzero(N >= 0)
    for j in rng.choice(t.size, 60, replace=False):
        a = p[T[t[j], (k[j] + 1) % 3]]
        b = p[T[t[j], (k[j] + 2) % 3]]
        e = b - a
        pts.append(a + rng.uniform(0.2, 0.8) * e)
        nrm.append(np.array([-e[1], e[0]]) / np.hypot(*e))
    # across circumcircles (points on a circle, inside the hull)
    for s in rng.choice(tri.ntriangles, 200, replace=False):
        o, r = circumcircle(*p[T[s]])
        ang = rng.uniform(0, 2 * np.pi)
        x = o + r * np.array([np.cos(ang), np.sin(ang)])
        if np.all((x > 0.02) & (x < 0.98)):
            pts.append(x)
            nrm.append(np.array([np.cos(ang), np.sin(ang)]))
    x, n = np.array(pts), np.array(nrm)
    jumps = {}
    for d in (1e-6, 1e-8):
        Fp, Dp = coords(tri, x + d * n, gradient=True)
        Fm, Dm = coords(tri, x - d * n, gradient=True)
        Gp = np.stack([dense(D) for D in Dp], -1)
        Gm = np.stack([dense(D) for D in Dm], -1)
        gmax = np.maximum(np.abs(Gp).max((1, 2)), np.abs(Gm).max((1, 2)))
        # values: Lipschitz with the local gradient bound (no jump)
        dF = np.abs(dense(Fp) - dense(Fm)).max(1)
        assert np.all(dF <= 2 * d * np.sqrt(2) * gmax * 1.01 + 1e-13)
        jumps[d] = (np.abs(Gp - Gm).max((1, 2)), gmax)
    if coords is sibson_coordinates:
        # gradients: the jump shrinks with the distance (C1 across circles)
        (g6, s6), (g8, _) = jumps[1e-6], jumps[1e-8]
        assert np.all(g8 <= 0.05 * g6 + 1e-9 * s6)


def grid_triangulations(n=7):
    """A structured grid triangulated with all diagonals one way and the other."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    p = np.c_[x.ravel(), y.ravel()]
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    t1 = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    t2 = np.r_[np.c_[a, b, d], np.c_[b, c, d]]
    return p, Triangulation.from_triangles(p, t1), Triangulation.from_triangles(p, t2)


@pytest.mark.parametrize("coords", KINDS)
def test_cocircular_grid_independent_of_diagonal(coords):
    p, tri1, tri2 = grid_triangulations()
    assert tri1.is_delaunay() and tri2.is_delaunay()
    assert (tri1.triangles != tri2.triangles).any()
    rng = np.random.default_rng(12)
    q = 0.01 + 0.98 * rng.random((500, 2))
    # include points on the grid lines and exactly on the diagonals
    h = 1 / 6
    q = np.r_[q, [[0.5 * h, 0.5 * h], [2.5 * h, 1.5 * h], [2 * h, 2.3 * h], [2.2 * h, 3 * h]]]
    F1, D1 = coords(tri1, q, gradient=True)
    F2, D2 = coords(tri2, q, gradient=True)
    np.testing.assert_allclose(dense(F1), dense(F2), atol=1e-13)
    for a, b in zip(D1, D2):
        np.testing.assert_allclose(dense(a), dense(b), atol=1e-11)
    check_properties(tri1, q, coords)
    # against a slightly rotated copy (Qhull picks its own diagonals there)
    th = 1e-3
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    F3, (GX3, GY3) = coords(p @ R.T, q @ R.T, gradient=True)
    assert np.abs(dense(F3) - dense(F1)).max() < 1e-8
    G1 = np.stack([dense(D1[0]), dense(D1[1])], -1)
    G3 = np.stack([dense(GX3), dense(GY3)], -1) @ R  # rotate gradients back
    assert np.abs(G3 - G1).max() < 1e-6


@pytest.mark.parametrize("coords", KINDS)
@pytest.mark.parametrize("scale, shift", [(1.0, (1e3, -2e3)), (1e-6, (0, 0)), (1e6, (0, 0)),
                                          (1e-6, (3e-3, 1e-3))])
def test_invariance(coords, scale, shift):
    p = random_nodes(150, seed=13)
    q = interior_queries(400, seed=14)
    F, (GX, GY) = coords(p, q, gradient=True)
    shift = np.asarray(shift, dtype=float)
    F2, (GX2, GY2) = coords(scale * p + shift, scale * q + shift, gradient=True)
    np.testing.assert_allclose(dense(F2), dense(F), atol=1e-10)
    np.testing.assert_allclose(scale * dense(GX2), dense(GX), atol=1e-8)
    np.testing.assert_allclose(scale * dense(GY2), dense(GY), atol=1e-8)


def test_sibson_against_discrete_voronoi_areas():
    """Independent check: stolen areas measured by nearest-node counting on a fine grid."""
    p = random_nodes(40, seed=15)
    tri = Triangulation(p)
    tree = cKDTree(p)
    rng = np.random.default_rng(16)
    for x in 0.2 + 0.6 * rng.random((3, 2)):
        cav = tri.cavity(x)
        boxes = []
        for s in cav:
            o, r = circumcircle(*p[tri.triangles[s]])
            boxes.append(np.r_[o - r, o + r])
        boxes = np.array(boxes)
        lo, hi = boxes[:, :2].min(0), boxes[:, 2:].max(0)
        g = 1500
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], g), np.linspace(lo[1], hi[1], g))
        y = np.c_[gx.ravel(), gy.ravel()]
        d_old, i_old = tree.query(y)
        mine = np.hypot(*(y - x).T) < d_old
        counts = np.bincount(i_old[mine], minlength=p.shape[0])
        ref = counts / counts.sum()
        F = dense(sibson_coordinates(tri, x[None]))[0]
        assert np.abs(F - ref).max() < 5e-3
        assert set(np.flatnonzero(ref > 1e-3)) <= set(np.flatnonzero(F > 0))


def test_hull_edges_are_linear():
    p = random_nodes(100, seed=17)
    s = np.linspace(0, 1, 11)
    for coords in KINDS:
        # the bottom side of the square: node 0 (0,0) and 1 (1,0) plus any nodes on it
        q = np.c_[s, 0 * s]
        F = dense(coords(p, q))
        np.testing.assert_allclose(F[:, 0], 1 - s, atol=1e-15)
        np.testing.assert_allclose(F[:, 1], s, atol=1e-15)
        assert np.count_nonzero(F[:, 2:]) == 0
    # a query 1e-300 inside the hull edge is treated as on it
    F = dense(sibson_coordinates(p, np.array([[0.3, 1e-300]])))
    np.testing.assert_allclose(F[0, :2], [0.7, 0.3])


def test_near_hull_values_converge_to_linear():
    p = random_nodes(100, seed=18)
    for eps in (1e-4, 1e-8, 1e-12):
        q = np.array([[0.37, eps]])
        check_properties(p, q, sibson_coordinates, tol=1e-11, grad=False)
        F = dense(sibson_coordinates(p, q))[0]
        assert abs(F[0] - 0.63) < 100 * eps and abs(F[1] - 0.37) < 100 * eps


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(5, 80),
       st.sampled_from(["uniform", "clustered", "nearly_collinear", "graded", "lattice"]))
def test_hypothesis_properties(seed, n, kind):
    rng = np.random.default_rng(seed)
    if kind == "uniform":
        p = rng.random((n, 2))
    elif kind == "clustered":
        p = np.r_[rng.random((n, 2)), 0.4 + 1e-5 * rng.random((n, 2))]
    elif kind == "nearly_collinear":
        t = rng.random(n)
        p = np.r_[np.c_[t, 0.3 * t + 1e-7 * rng.standard_normal(n)], [[0.2, 0.5], [0.8, 0.1]]]
    elif kind == "graded":
        d = rng.random(n) ** 3
        p = np.c_[rng.random(n), 0.5 + np.where(rng.random(n) < 0.5, -d, d) * 0.5]
    else:
        k = max(2, int(np.sqrt(n)))
        x, y = np.meshgrid(np.arange(k + 1), np.arange(k))
        p = np.c_[x.ravel(), y.ravel()].astype(float)
    p = np.unique(p, axis=0)
    tri = Triangulation(p)
    # random queries inside the hull: convex combinations of triangle vertices
    t = rng.integers(0, tri.ntriangles, 50)
    lam = rng.dirichlet(np.ones(3), 50)
    q = np.einsum("mk,mkd->md", lam, p[tri.triangles[t]])
    for coords in KINDS:
        Phi = coords(tri, q, gradient=True, undefined="nan")[0]
        F = dense(Phi)
        np.testing.assert_allclose(F.sum(1), 1.0, atol=1e-10)
        np.testing.assert_allclose(F @ p, q, atol=1e-10 * max(1, np.abs(p).max()))
        assert F.min() > -1e-12
    np.testing.assert_array_equal(dense(sibson_coordinates(tri, p)), np.eye(p.shape[0]))


def test_gradient_at_node_and_hull():
    p = random_nodes(50, seed=19)
    with pytest.raises(ValueError, match=r"x\[1\] .* \(node 7\)"):
        sibson_coordinates(p, np.r_[[[0.5, 0.5]], p[7:8]], gradient=True)
    with pytest.raises(ValueError, match=r"convex-hull edge; first is x\[0\]"):
        sibson_coordinates(p, np.array([[0.5, 0.0], [0.5, 0.5]]), gradient=True)
    F, (GX, GY) = sibson_coordinates(p, np.r_[[[0.5, 0.5]], p[7:8], [[0.5, 0.0]]],
                                     gradient=True, undefined="nan")
    assert np.all(np.isfinite(dense(GX)[0]))
    assert np.isnan(GX[1, 7]) and np.isnan(GY[2, 0]) and np.isnan(GX[2, 1])
    np.testing.assert_array_equal(dense(F)[1], np.eye(50)[7])


def test_bad_queries():
    p = random_nodes(50, seed=20)
    tri = Triangulation(p)
    q = np.array([[0.5, 0.5], [1.5, 0.5], [0.2, 0.2], [-0.1, 2.0]])
    before = q.copy()
    with pytest.raises(ValueError, match=r"2 query point\(s\) lie outside .* x\[1\]"):
        sibson_coordinates(tri, q)
    np.testing.assert_array_equal(q, before)
    with pytest.raises(ValueError, match=r"non-finite.*x\[1\]"):
        sibson_coordinates(tri, np.array([[0.5, 0.5], [np.nan, 0.1]]))
    with pytest.raises(ValueError, match="shape"):
        sibson_coordinates(tri, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="kind"):
        from skfem_nem import natural_neighbour_coordinates
        natural_neighbour_coordinates(tri, q[:1], kind="watson")
    with pytest.raises(ValueError, match=r"nodes\[3\] coincides"):
        sibson_coordinates(np.array([[0, 0], [1, 0], [0, 1], [0, 0]]), q[:1])


def test_many_natural_neighbours():
    """Co-circular nodes: a point inside a regular 200-gon has all 200 as natural neighbours."""
    k = 200
    ang = 2 * np.pi * np.arange(k) / k
    p = np.c_[np.cos(ang), np.sin(ang)]
    tri = Triangulation(p)
    q = np.array([[1e-3, 2e-3], [0.5, 0.1]])
    Phi, (GX, GY) = sibson_coordinates(tri, q, gradient=True)
    assert Phi[0].nnz == k and Phi[1].nnz == k
    check_properties(tri, q, sibson_coordinates, tol=1e-11, grad_tol=1e-9)


def test_roundoff_outside_hull_is_snapped():
    # a rotated square: points computed on its sides fall outside by round-off
    th = 0.3
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    p = random_nodes(60, seed=21) @ R.T + np.array([3.7, -1.1])
    a, b = p[0], p[1]  # the side from corner (0,0) to (1,0)
    s = np.linspace(0.05, 0.95, 37)
    q = a + s[:, None] * (b - a)
    F = dense(sibson_coordinates(p, q))
    np.testing.assert_allclose(F[:, 0], 1 - s, atol=1e-12)
    np.testing.assert_allclose(F[:, 1], s, atol=1e-12)
    # clearly outside is still an error
    n = np.array([(b - a)[1], -(b - a)[0]])
    with pytest.raises(ValueError, match=r"outside .* x\[0\]"):
        sibson_coordinates(p, (q[3] + 1e-6 * n)[None])


def test_shared_pattern_with_exact_zero_gradients():
    # mirror-symmetric co-circular nodes: more than the first-pass buffer of
    # natural neighbours, and some gradient entries exactly zero; values and
    # gradients must still share one sparsity pattern
    t = 2 * np.pi * np.arange(1, 15) / 30
    h = np.c_[np.cos(t), np.sin(t)]
    nodes = np.r_[[[1.0, 0.0]], h, [[-1.0, 0.0]], h[::-1] * [1, -1]]
    Phi, (Dx, Dy) = sibson_coordinates(Triangulation(nodes), np.array([[0.5, 0.0], [0.1, 0.2]]),
                                       gradient=True)
    for D in (Dx, Dy):
        np.testing.assert_array_equal(D.indptr, Phi.indptr)
        np.testing.assert_array_equal(D.indices, Phi.indices)
    assert Phi[0].nnz == 30
    check_properties(Triangulation(nodes), np.array([[0.5, 0.0], [0.1, 0.2]]), sibson_coordinates,
                     tol=1e-11, grad_tol=1e-9)


def _rows_sorted(M):
    """True if the column indices increase strictly within every row."""
    d = np.diff(M.indices.astype(np.int64))
    row_start = np.zeros(M.indices.size, dtype=bool)
    row_start[M.indptr[1:-1][M.indptr[1:-1] < M.indices.size]] = True
    return bool(np.all((d > 0) | row_start[1:]))


def test_rows_sorted_and_chunking_independent():
    # random, hull, node and many-neighbour rows, split across chunks of
    # every size: same pattern, same values to round-off, rows sorted
    p = random_nodes(300, seed=30)
    p = p[np.hypot(*(p - 0.5).T) > 0.15]
    k = 40  # co-circular nodes around an empty disc: 40+ natural neighbours
    ang = 2 * np.pi * np.arange(k) / k
    p = np.r_[p, 0.5 + 0.1 * np.c_[np.cos(ang), np.sin(ang)]]
    tri = Triangulation(p)
    rng = np.random.default_rng(31)
    q = np.r_[rng.random((3000, 2)), p[::7], [[0.5, 0.5], [0.5, 0.0], [0.3, 1.0]],
              [[0.5 + 1e-4, 0.5]]]
    rng.shuffle(q)
    ref = sibson_coordinates(tri, q, gradient=True, undefined="nan")
    for chunk in (1, 7, 1000, 1 << 15):
        Phi, D = sibson_coordinates(tri, q, gradient=True, undefined="nan", chunk=chunk)
        for A, B in zip([Phi, *D], [ref[0], *ref[1]]):
            assert A.has_sorted_indices and _rows_sorted(A)
            np.testing.assert_array_equal(A.indptr, B.indptr)
            np.testing.assert_array_equal(A.indices, B.indices)
            np.testing.assert_allclose(A.data, B.data, rtol=1e-12, atol=1e-12)
    assert max(np.diff(ref[0].indptr)) >= k


def test_output_arrays_grow_past_the_first_estimate():
    # the first chunk holds queries at nodes (one entry each), the rest
    # ordinary points: the flat arrays must grow, and match one big chunk
    p = random_nodes(400, seed=32)
    tri = Triangulation(p)
    q = np.r_[p[4:], interior_queries(3000, seed=33)]
    Phi = laplace_coordinates(tri, q, chunk=256)
    ref = laplace_coordinates(tri, q)
    np.testing.assert_array_equal(Phi.indptr, ref.indptr)
    np.testing.assert_array_equal(Phi.indices, ref.indices)
    np.testing.assert_allclose(Phi.data, ref.data, rtol=1e-12, atol=1e-15)
    assert Phi.nnz == Phi.data.size == Phi.indices.size


def test_filtered_incircle_agrees_with_exact():
    """The cached-circumcircle filter decides exactly as the exact predicate."""
    from numba import njit
    from skfem_nem.geometry.delaunay2d import in_cavity, in_circumcircle

    @njit
    def both(P, T, CC, tris, Q, out):
        for i in range(tris.shape[0]):
            out[i, 0] = in_circumcircle(P, T, CC, tris[i], Q[i, 0], Q[i, 1])
            out[i, 1] = in_cavity(P, T, tris[i], Q[i, 0], Q[i, 1])

    rng = np.random.default_rng(34)
    g = np.stack(np.meshgrid(np.arange(7.0), np.arange(7.0)), -1).reshape(-1, 2)
    pr = random_nodes(100, seed=36)
    cases = [random_nodes(300, seed=35), g, g * 0.1 + 1e3, g * 1e-100, g * 1e100, pr * 1e-200,
             pr * 1e200, np.r_[pr, 0.5 + 1e-9 * rng.random((30, 2))]]
    for p in cases:
        # (Qhull does not take extreme scales: triangulate the unscaled nodes)
        s = np.abs(p).max()
        tri = Triangulation.from_triangles(p, Triangulation(p / s).triangles)
        P, T = tri.nodes, tri.triangles
        t = rng.integers(0, tri.ntriangles, 4000)
        # random points near the triangles, the nodes themselves (on or off
        # the circles: co-circular lattices) and points on the circles
        c = P[T[t, 0]] + tri.circumcentre_offsets[t]
        r = np.hypot(*tri.circumcentre_offsets[t].T)
        ang = rng.random(t.size) * 2 * np.pi
        on = c + r[:, None] * np.c_[np.cos(ang), np.sin(ang)]
        near = P[T[t]].mean(axis=1) + (rng.random((t.size, 2)) - 0.5) * 3 * r[:, None]
        nodes = P[rng.integers(0, P.shape[0], t.size)]
        for Q in (on, near, nodes):
            out = np.empty((t.size, 2), dtype=bool)
            both(P, T, tri.circumcircles, t, np.ascontiguousarray(Q), out)
            np.testing.assert_array_equal(out[:, 0], out[:, 1])


def test_fallback_cavity_search_agrees():
    # the general cavity search (used for overflow and for triangulations
    # that are not Delaunay) gives the traversal's results
    from skfem_nem.coordinates import area2d as C
    p, tri, _ = grid_triangulations()
    tri2 = Triangulation(random_nodes(200, seed=37))
    for t in (tri, tri2):
        q = interior_queries(500, seed=38)
        res = []
        for general in (False, True):
            st = np.empty(q.shape[0], np.int64)
            tl = np.empty(q.shape[0], np.int64)
            rows = C._run(t, q, np.empty(0, np.int64), C.SIBSON, True, general, C._CAP,
                          C._ROOM, 1 << 15, st, tl)
            assert (st == 0).all()
            res.append(rows.matrices())
        for A, B, tol in zip(res[0], res[1], (1e-13, 1e-10, 1e-10)):
            np.testing.assert_array_equal(A.indptr, B.indptr)
            np.testing.assert_array_equal(A.indices, B.indices)
            np.testing.assert_allclose(A.data, B.data, rtol=0, atol=tol * max(1, abs(A.data).max()))


def test_non_delaunay_triangulation_terminates():
    # flip convex interior edges at random: the cavities of the result need
    # not be trees; the coordinates must still come back (values are only
    # meaningful on Delaunay triangulations)
    from skfem_nem.geometry.delaunay2d import edge_violates, flip_edge
    p = random_nodes(200, seed=39)
    tri = Triangulation(p)
    T, N = tri.triangles.copy(), tri.neighbours.copy()
    rng = np.random.default_rng(40)
    flips = 0
    for t in rng.integers(0, T.shape[0], 400):
        for k in range(3):
            u = N[t, k]
            if u < 0:
                continue
            a, b, c = T[t, k], T[t, (k + 1) % 3], T[t, (k + 2) % 3]
            d = [T[u, j] for j in range(3) if N[u, j] == t][0]
            o1 = ((p[b, 0] - p[a, 0]) * (p[d, 1] - p[a, 1])
                  - (p[b, 1] - p[a, 1]) * (p[d, 0] - p[a, 0]))
            o2 = ((p[d, 0] - p[a, 0]) * (p[c, 1] - p[a, 1])
                  - (p[d, 1] - p[a, 1]) * (p[c, 0] - p[a, 0]))
            if o1 > 1e-9 and o2 > 1e-9 and not edge_violates(p, T, N, np.empty(0, np.int64), t, k):
                flip_edge(T, N, t, k)
                flips += 1
                break
    bad = Triangulation.from_triangles(p, T, make_delaunay=False)
    assert flips > 50 and not bad.is_delaunay()
    q = interior_queries(2000, seed=41)
    Phi = sibson_coordinates(bad, q)
    assert Phi.shape == (2000, p.shape[0]) and np.isfinite(Phi.data).all()


def test_rows_longer_than_the_staging_room():
    # every query has 20 natural neighbours (inside an empty co-circular
    # 20-gon), more than the first pass's room per query on average: the
    # rows that do not fit are finished in a second pass
    k = 20
    ang = 2 * np.pi * np.arange(k) / k
    ring = np.c_[np.cos(ang), np.sin(ang)]
    p = np.r_[ring, 3 * ring]
    tri = Triangulation(p)
    rng = np.random.default_rng(42)
    q = 0.5 * (rng.random((6000, 2)) - 0.5)
    Phi, (Dx, Dy) = sibson_coordinates(tri, q, gradient=True)
    assert (np.diff(Phi.indptr) >= k).all() and _rows_sorted(Phi)
    ref = sibson_coordinates(tri, q, gradient=True, chunk=1)
    for A, B in zip([Phi, Dx, Dy], [ref[0], *ref[1]]):
        np.testing.assert_array_equal(A.indptr, B.indptr)
        np.testing.assert_array_equal(A.indices, B.indices)
        np.testing.assert_allclose(A.data, B.data, rtol=1e-12, atol=1e-12)
    check_properties(tri, q[:200], sibson_coordinates, tol=1e-11, grad_tol=1e-9)
