"""Sibson coordinates in 2-4 dimensions by Lasserre's volume recursion
(skfem_nem.coordinates.lasserre)."""
import itertools

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, Delaunay, HalfspaceIntersection, Voronoi

from helpers import check_properties, compare_2d, dense
from skfem_nem import Triangulation, sibson_coordinates
from skfem_nem.coordinates.lasserre import sibson_coordinates_nd
from skfem_nem.geometry.delaunay3d import Delaunay3D


def hypercube_nodes(n, d, seed):
    """Random nodes in the unit cube with its 2^d corners (the hull is the cube)."""
    rng = np.random.default_rng(seed)
    corners = np.array(list(itertools.product([0.0, 1.0], repeat=d)))
    return np.r_[corners, rng.random((n - len(corners), d))]


def lattice(k, d):
    g = np.linspace(0.0, 1.0, k)
    return np.array(list(itertools.product(*[g] * d)))


def on_faces(p, tri, m, seed, dim):
    """m random points on Delaunay faces of dimension ``dim`` inside the unit
    cube (convex combinations of dim + 1 vertices of a simplex)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < m:
        s = rng.integers(tri.nsimplex)
        verts = rng.choice(tri.simplices[s], dim + 1, replace=False)
        w = rng.random(dim + 1) + 0.2
        x = w @ p[verts] / w.sum()
        if np.minimum(x, 1 - x).min() > 1e-3:
            out.append(x)
    return np.array(out)


def fd_error(p, q, tri, h=1e-6, raw=False):
    """Largest difference between the gradients and central finite
    differences of the values, relative to the largest gradient entry."""
    d = p.shape[1]
    kw = dict(delaunay=tri, _raw=raw)
    _, dPhi = sibson_coordinates_nd(p, q, gradient=True, **kw)
    err = 0.0
    scale = max(np.abs(dense(D)).max() for D in dPhi)
    for k in range(d):
        e = np.zeros(d)
        e[k] = h
        fd = (dense(sibson_coordinates_nd(p, q + e, **kw)) -
              dense(sibson_coordinates_nd(p, q - e, **kw))) / (2 * h)
        err = max(err, np.abs(fd - dense(dPhi[k])).max())
    return err / scale


# ---------------------------------------------------------------------------
# 2D: agreement with the area method
# ---------------------------------------------------------------------------

def test_2d_matches_area_method_at_random_points():
    p = hypercube_nodes(300, 2, seed=0)
    q = 0.01 + 0.98 * np.random.default_rng(1).random((2000, 2))
    compare_2d(p, q, lasserre=sibson_coordinates_nd)


def test_2d_matches_area_method_on_delaunay_edges():
    p = hypercube_nodes(200, 2, seed=2)
    tri = Triangulation(p)
    T, N = tri.triangles, tri.neighbours
    rng = np.random.default_rng(3)
    t, k = np.nonzero(N >= 0)  # interior edges: opposite vertex k of triangle t
    pick = rng.choice(t.size, 400)
    a = p[T[t[pick], (k[pick] + 1) % 3]]
    b = p[T[t[pick], (k[pick] + 2) % 3]]
    s = rng.random((400, 1))
    compare_2d(p, a + s * (b - a), lasserre=sibson_coordinates_nd)


def test_2d_lattice_matches_area_method():
    """Co-circular nodes: every square of the grid has four nodes on a circle."""
    p = lattice(9, 2)
    q = 0.01 + 0.98 * np.random.default_rng(4).random((500, 2))
    q[:100, 0] = 0.5                      # on grid lines
    q[100:150] = np.floor(q[100:150] * 8) / 8 + 1 / 16  # square centres
    compare_2d(p, q, lasserre=sibson_coordinates_nd)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 60))
def test_2d_matches_area_method_hypothesis(seed, n):
    rng = np.random.default_rng(seed)
    p = rng.random((n, 2))
    hull = ConvexHull(p)
    # random points inside the hull: convex combinations of hull vertices
    w = rng.random((30, hull.vertices.size)) ** 4
    q = (w / w.sum(1, keepdims=True)) @ p[hull.vertices]
    F, G = sibson_coordinates_nd(p, q, gradient=True, undefined="nan")
    F2 = sibson_coordinates(p, q)
    np.testing.assert_allclose(dense(F), dense(F2), rtol=0, atol=1e-10)


def test_2d_hull_edges_are_linear():
    p = hypercube_nodes(80, 2, seed=5)
    s = np.linspace(0.05, 0.95, 19)
    q = np.c_[s, np.zeros_like(s)]                    # on the side y = 0
    F = dense(sibson_coordinates_nd(p, q))
    F2 = dense(sibson_coordinates(p, q))
    np.testing.assert_allclose(F, F2, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------
# 3D: the paper's test, properties, lattices
# ---------------------------------------------------------------------------

def voronoi_volume_of_inserted_point(p, x):
    vor = Voronoi(np.r_[p, x[None]])
    region = vor.regions[vor.point_region[-1]]
    assert -1 not in region, "choose x well inside: its cell must be bounded"
    return ConvexHull(vor.vertices[region]).volume


def test_3d_second_order_volumes_sum_to_voronoi_cell():
    """Box 1: 220 random nodes in 3D; the second-order volumes of a point sum to
    the volume of its (first-order) Voronoi cell among the nodes."""
    rng = np.random.default_rng(6)
    p = rng.random((220, 3))
    q = 0.3 + 0.4 * rng.random((40, 3))
    V = dense(sibson_coordinates_nd(p, q, _raw=True)).sum(1)
    ref = np.array([voronoi_volume_of_inserted_point(p, x) for x in q])
    np.testing.assert_allclose(V, ref, rtol=1e-12)


@pytest.mark.parametrize("d, n, m", [(3, 220, 400), (4, 120, 40)])
def test_properties_random(d, n, m):
    p = hypercube_nodes(n, d, seed=7 + d)
    q = 0.02 + 0.96 * np.random.default_rng(d).random((m, d))
    F, _ = check_properties(p, q, sibson_coordinates_nd)
    assert np.all((F > 0).sum(1) >= d + 1)


@pytest.mark.parametrize("d, dim", [(3, 2), (3, 1), (4, 3), (4, 2), (4, 1)])
def test_properties_on_delaunay_faces(d, dim):
    """Points exactly on interior Delaunay faces and edges (the paper: the
    method does not break down there)."""
    p = hypercube_nodes(150 if d == 3 else 80, d, seed=11)
    tri = Delaunay(p)
    q = on_faces(p, tri, 100 if d == 3 else 20, seed=dim, dim=dim)
    check_properties(p, q, sibson_coordinates_nd, delaunay=tri)


@pytest.mark.parametrize("d, k", [(3, 5), (4, 4)])
def test_properties_lattice(d, k):
    """Lattices: many co-spherical nodes, flat simplices in Qhull's output,
    bisectors through common edges (coincident constraints)."""
    p = lattice(k, d)
    rng = np.random.default_rng(12)
    q = 0.05 + 0.9 * rng.random((60 if d == 3 else 8, d))
    q[: q.shape[0] // 3, 0] = 0.5          # on lattice planes
    check_properties(p, q, sibson_coordinates_nd)


@pytest.mark.parametrize("d", [3, 4])
def test_kronecker_delta(d):
    p = hypercube_nodes(60 if d == 3 else 40, d, seed=13)
    np.testing.assert_array_equal(dense(sibson_coordinates_nd(p, p)), np.eye(p.shape[0]))
    # and continuously so: close to an interior node
    i = int(np.argmin(np.abs(p - 0.5).sum(1)))
    x = p[i] + 1e-9 * np.random.default_rng(0).standard_normal((5, d))
    F = dense(sibson_coordinates_nd(p, x))
    assert np.all(F[:, i] > 1 - 1e-7)
    np.testing.assert_allclose(F @ p, x, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------
# gradients against finite differences
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("d, n, m", [(2, 100, 200), (3, 150, 60), (4, 80, 10)])
def test_gradients_finite_differences(d, n, m):
    p = hypercube_nodes(n, d, seed=14)
    tri = Delaunay(p)
    q = 0.05 + 0.9 * np.random.default_rng(15).random((m, d))
    assert fd_error(p, q, tri) < 1e-6
    # the gradient of the unnormalised second-order volumes,
    # grad V_i = (1/|p_i - x|) integral over the bisector facet of (y - x) dS
    assert fd_error(p, q, tri, raw=True) < 1e-6


@pytest.mark.parametrize("d, n, m", [(2, 100, 100), (3, 150, 40), (4, 80, 8)])
def test_gradients_finite_differences_on_faces(d, n, m):
    p = hypercube_nodes(n, d, seed=16)
    tri = Delaunay(p)
    q = np.r_[on_faces(p, tri, m, seed=17, dim=d - 1), on_faces(p, tri, m, seed=18, dim=1)]
    assert fd_error(p, q, tri) < 1e-6
    assert fd_error(p, q, tri, raw=True) < 1e-6


def test_lattice_symmetry():
    """At the centre of a lattice cube, point symmetry: opposite nodes have equal
    coordinates and opposite gradients."""
    p = lattice(4, 3)
    x = np.array([[0.5, 0.5, 0.5]])
    F, G = sibson_coordinates_nd(p, x, gradient=True)
    F, G = dense(F)[0], np.array([dense(g)[0] for g in G])
    centre = np.flatnonzero(F > 0)
    for i in centre:
        j = int(np.flatnonzero((np.abs(p - (1.0 - p[i])) < 1e-12).all(1))[0])
        np.testing.assert_allclose(F[i], F[j], atol=1e-14)
        np.testing.assert_allclose(G[:, i], -G[:, j], atol=1e-12)


# ---------------------------------------------------------------------------
# convex hull
# ---------------------------------------------------------------------------

def hull_limit_weights(P2, x2):
    """Reference for a point x2 on a hull facet, from the nodes P2 on the facet
    (in the facet's coordinates): weights integral over C_i of
    (|y - p_i|^2 - |y - x|^2) dy = A_i (|c_i - p_i|^2 - |c_i - x|^2), with
    C_i the 2D second-order Voronoi cell, A_i its area, c_i its centroid,
    here by Qhull's half-space intersection."""
    w = np.zeros(len(P2))
    for i in range(len(P2)):
        H = [np.r_[P2[i] - x2, -(P2[i] @ P2[i] - x2 @ x2) / 2]]
        H += [np.r_[P2[j] - P2[i], -(P2[j] @ P2[j] - P2[i] @ P2[i]) / 2]
              for j in range(len(P2)) if j != i]
        H = np.array(H)
        nrm = np.linalg.norm(H[:, :-1], axis=1)
        res = linprog([0, 0, -1], A_ub=np.c_[H[:, :-1], nrm], b_ub=-H[:, -1],
                      bounds=[(None, None)] * 2 + [(0, None)])
        if res.status != 0 or res.x[-1] < 1e-9:
            continue
        V = HalfspaceIntersection(H, res.x[:2]).intersections
        V = V[ConvexHull(V).vertices]
        x, y = V.T
        cr = x * np.roll(y, -1) - np.roll(x, -1) * y
        A = cr.sum() / 2
        c = np.array([((x + np.roll(x, -1)) * cr).sum(),
                      ((y + np.roll(y, -1)) * cr).sum()]) / (6 * A)
        w[i] = A * (((c - P2[i]) ** 2).sum() - ((c - x2) ** 2).sum())
    return w / w.sum()


def test_3d_hull_facet_limit():
    """On a facet of the hull the coordinates are the limits from inside:
    only the nodes on the facet count, with weights
    integral over C_i of (|y - p_i|^2 - |y - x|^2) dy (C_i: the 2D second-order
    cell in the facet). These are not the 2D Sibson coordinates (those would
    be the areas of C_i)."""
    rng = np.random.default_rng(19)
    face = np.c_[rng.random((30, 2)), np.zeros(30)]
    p = np.r_[hypercube_nodes(120, 3, seed=20), face]
    on = np.flatnonzero(p[:, 2] == 0.0)
    q2 = 0.02 + 0.96 * rng.random((60, 2))
    q = np.c_[q2, np.zeros(60)]
    F = dense(sibson_coordinates_nd(p, q))
    assert np.all(np.delete(F, on, axis=1) == 0.0)
    np.testing.assert_allclose(F.sum(1), 1.0, atol=1e-14)
    np.testing.assert_allclose(F @ p, q, atol=1e-14)
    ref = np.array([hull_limit_weights(p[on, :2], x) for x in q2[:10]])
    np.testing.assert_allclose(F[:10][:, on], ref, atol=1e-11)
    assert np.abs(F[:, on] - dense(sibson_coordinates(p[on, :2], q2))).max() > 1e-2
    # continuity from inside: phi(x + t e_z) = phi(x) + O(t)
    for t in (1e-5, 1e-8):
        Fin = dense(sibson_coordinates_nd(p, q + [0, 0, t]))
        assert np.abs(Fin - F).max() < 1e3 * t
    # on a hull edge: linear between the two nodes around x
    s = np.linspace(0.1, 0.9, 9)
    e = np.c_[s, 0 * s, 0 * s]
    F = dense(sibson_coordinates_nd(p, e))
    np.testing.assert_allclose(F @ p, e, atol=1e-14)
    assert np.all((F > 0).sum(1) == 2)
    assert np.abs(dense(sibson_coordinates_nd(p, e + [0, 1e-8, 1e-8])) - F).max() < 1e-5


def test_4d_hull():
    """Facets (exact limit weights), 2-faces (extrapolated) and edges of a 4D hull."""
    p = hypercube_nodes(60, 4, seed=21)
    rng = np.random.default_rng(22)
    for ones in (1, 2, 3):
        q = 0.1 + 0.8 * rng.random((6, 4))
        q[:, 4 - ones:] = 1.0
        F = dense(sibson_coordinates_nd(p, q))
        np.testing.assert_allclose(F.sum(1), 1.0, atol=1e-12)
        np.testing.assert_allclose(F @ p, q, atol=1e-11)
        assert np.all(F[:, (p[:, 4 - ones:] != 1.0).any(1)] == 0.0)
        inward = -1e-7 * (q - 0.5)
        assert np.abs(dense(sibson_coordinates_nd(p, q + inward)) - F).max() < 1e-4


# ---------------------------------------------------------------------------
# input checking
# ---------------------------------------------------------------------------

def test_gradients_undefined_at_nodes_and_on_the_hull():
    p = hypercube_nodes(50, 3, seed=23)
    with pytest.raises(ValueError, match=r"coincide with a node; first is x\[1\] .* \(node 17\)"):
        sibson_coordinates_nd(p, np.r_[[[0.5, 0.5, 0.5]], p[17:18]], gradient=True)
    with pytest.raises(ValueError, match=r"convex hull; first is x\[0\]"):
        sibson_coordinates_nd(p, np.array([[0.5, 0.5, 0.0], [0.5, 0.5, 0.5]]),
                              gradient=True)
    q = np.r_[[[0.5, 0.5, 0.5]], p[17:18], [[0.5, 0.5, 0.0]]]
    F, G = sibson_coordinates_nd(p, q, gradient=True, undefined="nan")
    G = [dense(g) for g in G]
    assert np.all(np.isfinite(G[0][0]))
    assert np.isnan(G[0][1, 17]) and np.isnan(G[2][2, 0])
    np.testing.assert_array_equal(dense(F)[1], np.eye(50)[17])


def test_bad_nodes():
    q = np.array([[0.2, 0.2, 0.2]])
    with pytest.raises(ValueError, match=r"non-finite.*nodes\[2\]"):
        sibson_coordinates_nd(np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0],
                                        [0, 0, 1.0]]), q)
    with pytest.raises(ValueError, match="at least 4"):
        sibson_coordinates_nd(np.eye(3), q)
    with pytest.raises(ValueError, match=r"nodes\[4\] coincides with nodes\[0\]"):
        sibson_coordinates_nd(np.r_[np.eye(3), [[0, 0, 0]], [[1.0, 0, 0]]], q)
    flat = np.c_[np.random.default_rng(0).random((20, 2)), np.zeros(20)]
    with pytest.raises(ValueError, match="degenerate.*flat"):
        sibson_coordinates_nd(flat, q)
    with pytest.raises(ValueError, match="d = 2, 3 or 4"):
        sibson_coordinates_nd(np.random.default_rng(0).random((40, 5)), np.zeros((1, 5)))
    p = hypercube_nodes(30, 3, seed=24)
    with pytest.raises(ValueError, match="other points"):
        sibson_coordinates_nd(p, q, delaunay=Delaunay(p[::-1]))


def test_bad_queries():
    p = hypercube_nodes(40, 3, seed=25)
    q = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.2, 0.2, 0.2], [0.5, -1e-6, 0.5]])
    before = q.copy()
    with pytest.raises(ValueError, match=r"2 query point\(s\) lie outside .* x\[1\]"):
        sibson_coordinates_nd(p, q)
    np.testing.assert_array_equal(q, before)
    with pytest.raises(ValueError, match=r"non-finite.*x\[1\]"):
        sibson_coordinates_nd(p, np.array([[0.5, 0.5, 0.5], [np.inf, 0.1, 0.1]]))
    with pytest.raises(ValueError, match="shape"):
        sibson_coordinates_nd(p, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="undefined"):
        sibson_coordinates_nd(p, q[:1], undefined="zero")
    # round-off outside a hull face is on the hull; a single point as a 1D array
    F = sibson_coordinates_nd(p, np.array([0.5, 0.5, -1e-17]))
    np.testing.assert_allclose(dense(F) @ p, [[0.5, 0.5, 0.0]], atol=1e-12)
    assert sibson_coordinates_nd(p, np.zeros((0, 3))).shape == (0, 40)


def test_delaunay_reuse():
    p = hypercube_nodes(80, 3, seed=26)
    q = 0.1 + 0.8 * np.random.default_rng(27).random((50, 3))
    A = sibson_coordinates_nd(p, q, gradient=True)
    B = sibson_coordinates_nd(p, q, gradient=True, delaunay=Delaunay3D(p))
    np.testing.assert_array_equal(dense(A[0]), dense(B[0]))
    for a, b in zip(A[1], B[1]):
        np.testing.assert_array_equal(dense(a), dense(b))
    # Qhull's tetrahedra, in another order: the same up to round-off
    C = sibson_coordinates_nd(p, q, gradient=True, delaunay=Delaunay(p))
    np.testing.assert_allclose(dense(A[0]), dense(C[0]), rtol=0, atol=1e-14)
    for a, c in zip(A[1], C[1]):
        np.testing.assert_allclose(dense(a), dense(c), rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------
# 3D: faces from the combinatorics against the general recursion
# ---------------------------------------------------------------------------

def test_3d_faces_from_combinatorics_match_the_recursion(monkeypatch):
    """Queries in general position take the cells' faces from the conflict
    region's combinatorics; with that path switched off (every simplex
    counts as ill-shaped) the general recursion must give the same values,
    gradients and sparsity pattern to round-off -- inside, on Delaunay faces
    and edges, near nodes and near the hull."""
    from skfem_nem.coordinates import lasserre as L

    p = hypercube_nodes(400, 3, seed=28)
    tri = Delaunay(p)
    rng = np.random.default_rng(29)
    s = rng.integers(0, tri.nsimplex, 300)
    inside = np.einsum("mk,mkd->md", rng.dirichlet(np.ones(4), 300), p[tri.simplices[s]])
    i = np.flatnonzero((np.abs(p - 0.5) < 0.4).all(1))[:60]
    v = rng.standard_normal((60, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    near = p[i] + np.repeat([1e-3, 1e-6, 1e-9], 20)[:, None] * v
    hull = 0.05 + 0.9 * rng.random((40, 3))
    hull[:, 2] = np.repeat([1e-2, 1e-4, 1e-7, 1e-10], 10)
    q = np.r_[inside, on_faces(p, tri, 60, seed=30, dim=2), on_faces(p, tri, 60, seed=31, dim=1),
              near, hull]
    F, G = sibson_coordinates_nd(p, q, gradient=True, delaunay=tri)
    monkeypatch.setattr(L, "_SHAPE", np.inf)
    F0, G0 = sibson_coordinates_nd(p, q, gradient=True, delaunay=tri)
    assert np.array_equal(F.indptr, F0.indptr) and np.array_equal(F.indices, F0.indices)
    np.testing.assert_allclose(F.data, F0.data, rtol=0, atol=1e-13)
    scale = max(np.abs(g.data).max() for g in G0)
    for a, b in zip(G, G0):
        np.testing.assert_allclose(a.data, b.data, rtol=0, atol=1e-11 * scale)
    # most of these queries did take the faces from the combinatorics
    fast = np.asarray(abs(F - F0).max(axis=1).todense()).ravel() > 0
    assert fast.mean() > 0.5


def test_3d_within_round_off_of_a_node():
    """Within 1e-13 of a node the walk's tolerance can end in a simplex that
    does not hold x and whose circumsphere x is outside of; the region must
    still be found (this raised "came out unbounded" before)."""
    p = hypercube_nodes(1000, 3, seed=32)
    rng = np.random.default_rng(33)
    i = np.flatnonzero((np.abs(p - 0.5) < 0.45).all(1))[:150]
    v = rng.standard_normal((150, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    for r in (1e-13, 1e-14, 1e-15):
        x = p[i] + r * v
        F = dense(sibson_coordinates_nd(p, x))
        np.testing.assert_allclose(F.sum(1), 1.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(F @ p, x, rtol=0, atol=1e-12)
        assert np.all(F[np.arange(150), i] > 1 - 1e-9)


# ---------------------------------------------------------------------------
# the query kernel as plain Python (numpy checks every index)
# ---------------------------------------------------------------------------

def test_query_kernel_stays_in_its_buffers_in_2d(monkeypatch):
    """Compiled kernels do not check indices, so a read past a buffer goes
    unnoticed. Run the query kernel as plain Python on 2D queries -- direct
    ones, and those that give the weights of 3D queries on a hull facet --
    and compare with the compiled kernel. (The 3D near-a-node test read a
    third column of the (ncap, d) neighbour offsets in 2D as well.)"""
    from skfem_nem.coordinates import lasserre as L
    from skfem_nem.coordinates import lasserre_query as LQ

    rng = np.random.default_rng(34)
    p2 = hypercube_nodes(30, 2, seed=35)
    q2 = 0.05 + 0.9 * rng.random((8, 2))
    p3 = np.r_[hypercube_nodes(40, 3, seed=36), np.c_[rng.random((10, 2)), np.zeros(10)]]
    q3 = np.c_[0.05 + 0.9 * rng.random((8, 2)), np.zeros(8)]
    compiled = [dense(sibson_coordinates_nd(p2, q2)), dense(sibson_coordinates_nd(p3, q3))]
    for name in ("query", "query_block"):
        f = getattr(LQ, name)
        monkeypatch.setattr(LQ, name, getattr(f, "py_func", f))
    monkeypatch.setattr(L, "query_batch_serial", getattr(LQ.query_batch, "py_func",
                                                         LQ.query_batch))
    python = [dense(sibson_coordinates_nd(p2, q2)), dense(sibson_coordinates_nd(p3, q3))]
    for a, b in zip(python, compiled):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
