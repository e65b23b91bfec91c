"""Tests of the own 3D Delaunay tetrahedralisation: validity, the empty-sphere property by
exact predicates, agreement with Qhull on generic input, lattices and degenerate input."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numba import njit
from scipy.spatial import ConvexHull, Delaunay

from skfem_nem.geometry.delaunay3d import Delaunay3D
from skfem_nem.geometry.nodesets3d import box_nodes_3d
from skfem_nem.geometry.predicates3d import insphere, orient3d

FEW = settings(max_examples=40, deadline=None)


@njit(cache=True)
def _orientations(P, S):
    out = np.empty(S.shape[0])
    for t in range(S.shape[0]):
        a, b, c, d = S[t]
        out[t] = orient3d(P[a, 0], P[a, 1], P[a, 2], P[b, 0], P[b, 1], P[b, 2],
                          P[c, 0], P[c, 1], P[c, 2], P[d, 0], P[d, 1], P[d, 2])
    return out


@njit(cache=True)
def _max_insphere(P, S):
    """For each tet, the largest exact insphere value over all points that are not its
    vertices (must be <= 0: no point strictly inside a circumsphere)."""
    out = np.full(S.shape[0], -np.inf)
    for t in range(S.shape[0]):
        a, b, c, d = S[t]
        for e in range(P.shape[0]):
            if e == a or e == b or e == c or e == d:
                continue
            s = insphere(P[a, 0], P[a, 1], P[a, 2], P[b, 0], P[b, 1], P[b, 2],
                         P[c, 0], P[c, 1], P[c, 2], P[d, 0], P[d, 1], P[d, 2],
                         P[e, 0], P[e, 1], P[e, 2])
            out[t] = max(out[t], s)
    return out


def check_neighbours(S, N):
    m = S.shape[0]
    faces = {}
    for t in range(m):
        for i in range(4):
            key = tuple(sorted(np.delete(S[t], i)))
            faces.setdefault(key, []).append((t, i))
    for key, sides in faces.items():
        assert len(sides) <= 2, key
        if len(sides) == 2:
            (t, i), (s, j) = sides
            assert N[t, i] == s and N[s, j] == t
        else:
            t, i = sides[0]
            assert N[t, i] == -1
    return faces


def check_tetrahedralisation(p, d, brute=True):
    S, N = d.simplices, d.neighbors
    assert S.shape[1] == 4 and N.shape == S.shape
    assert np.array_equal(np.unique(S), np.arange(p.shape[0])), "every point is a vertex"
    assert (_orientations(p, S) > 0).all(), "positively oriented, none flat"
    faces = check_neighbours(S, N)
    hull = ConvexHull(p - p.mean(axis=0))  # centred: Qhull's volume of far-off points errs
    vol = _orientations(p, S).sum() / 6
    assert abs(vol - hull.volume) <= 1e-7 * hull.volume
    # hull triangles: outward (counter-clockwise seen from outside) and on Qhull's hull
    H = d.convex_hull
    assert H.shape[0] == sum(len(s) == 1 for s in faces.values())
    inner = p.mean(axis=0)
    for f in H[:50]:
        a, b, c = p[f]
        assert orient3d(*a, *b, *c, *inner) < 0
    if brute:
        assert (_max_insphere(p, S) <= 0).all(), "empty circumspheres"


def tet_set(d):
    return set(map(tuple, np.sort(d.simplices, axis=1).tolist()))


def same_as_qhull(p, d):
    q = Delaunay(p)
    return set(map(tuple, np.sort(d.simplices, axis=1))) == \
        set(map(tuple, np.sort(q.simplices, axis=1)))


@pytest.mark.parametrize("n", [4, 5, 30, 300])
def test_random_points(n):
    p = np.random.default_rng(n).random((n, 3))
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)
    assert same_as_qhull(p, d)


def test_many_random_points_match_qhull():
    p = np.random.default_rng(1).standard_normal((5000, 3))
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d, brute=False)
    assert same_as_qhull(p, d)


@FEW
@given(st.integers(5, 120), st.integers(0, 2 ** 31))
def test_random_sets(n, seed):
    p = np.random.default_rng(seed).random((n, 3)) * 10.0 - 3.0
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)
    assert same_as_qhull(p, d)


def unique_rows(p):
    return np.unique(p, axis=0)


@FEW
@given(st.integers(6, 80), st.integers(0, 2 ** 31), st.sampled_from([2, 3, 4, 6]),
       st.sampled_from([1.0, 0.1, 1e-3, 2.0 ** -20]), st.sampled_from([0.0, 1e4, -0.3]))
def test_snapped_to_a_coarse_grid(n, seed, k, h, offset):
    """Grid points: many cospherical and coplanar subsets, also with inexact steps."""
    g = np.random.default_rng(seed).integers(0, k + 1, (n, 3))
    p = unique_rows(g) * h + offset
    if p.shape[0] < 4 or np.linalg.matrix_rank(p[1:] - p[0]) < 3:
        return
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)
    # ties are broken by a perturbation, not by the insertion order: unique result
    assert tet_set(Delaunay3D(p, seed=seed + 1)) == tet_set(d)


@pytest.mark.parametrize("k", [2, 3, 5])
def test_cubic_lattice(k):
    """All points cospherical by cells: k**3 cubes, each cut into tetrahedra, none flat."""
    g = np.arange(k + 1, dtype=float)
    p = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)
    assert abs(_orientations(p, d.simplices).sum() / 6 - k ** 3) < 1e-12


def test_lattice_result_does_not_depend_on_the_insertion_order():
    """The perturbation makes the tetrahedralisation unique: other random insertion orders
    give the same tetrahedra."""
    g = np.arange(4, dtype=float) * 0.1
    p = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    ref = set(map(tuple, np.sort(Delaunay3D(p).simplices, axis=1)))
    for seed in (1, 2, 3):
        assert set(map(tuple, np.sort(Delaunay3D(p, seed=seed).simplices, axis=1))) == ref


def test_box_with_lattice_faces():
    """Random interior points, lattice faces (four cocircular points per face square)."""
    g = np.linspace(0.0, 1.0, 6)
    X, Y = np.meshgrid(g, g, indexing="ij")
    faces = []
    for c in (0.0, 1.0):
        for axis in range(3):
            f = np.insert(np.stack([X.ravel(), Y.ravel()], 1), axis, c, axis=1)
            faces.append(f)
    inner = np.random.default_rng(5).uniform(0.05, 0.95, (200, 3))
    p = unique_rows(np.vstack(faces + [inner]))
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)


SPHERE_425 = [(x, y, z) for x in range(-20, 21) for y in range(-20, 21) for z in range(-20, 21)
              if x * x + y * y + z * z == 425]


@pytest.mark.parametrize("offset", [0.0, 1e8])
def test_all_points_cospherical(offset):
    """336 lattice points of one sphere: every tetrahedron has the same circumsphere."""
    p = np.array(SPHERE_425, dtype=float) + offset
    d = Delaunay3D(p)
    check_tetrahedralisation(p, d)
    assert (_max_insphere(p, d.simplices) == 0).all()


def test_coplanar_layers_and_a_cylinder():
    """Points on two parallel planes; points on circles stacked on a line (cocircular and
    coplanar subsets everywhere)."""
    rng = np.random.default_rng(0)
    layers = np.vstack([np.c_[rng.random((80, 2)), np.full(80, z)] for z in (0.0, 1.0)])
    check_tetrahedralisation(layers, Delaunay3D(layers))
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    cyl = np.c_[np.cos(a).repeat(5), np.sin(a).repeat(5), np.tile(np.arange(5.0), 24)]
    check_tetrahedralisation(cyl, Delaunay3D(cyl))


@pytest.mark.parametrize("scale", [1.0, 1.0 / 119])
def test_moment_curve(scale):
    """Points (t, t**2, t**3) have a quadratic number of Delaunay tetrahedra: the flat arrays,
    the cavity and the edge table all grow."""
    t = np.arange(120.0) * scale
    p = np.c_[t, t * t, t ** 3]
    d = Delaunay3D(p)
    assert d.nsimplex > 7 * p.shape[0] + 64  # beyond the initial capacity
    check_tetrahedralisation(p, d)
    assert same_as_qhull(p, d)


def test_box_nodes_3d():
    p = box_nodes_3d(300, seed=2)
    check_tetrahedralisation(p, Delaunay3D(p))


def test_find_simplex():
    p = np.random.default_rng(8).random((400, 3))
    d = Delaunay3D(p)
    q = np.random.default_rng(9).uniform(-0.2, 1.2, (2000, 3))
    s = d.find_simplex(q)
    ref = Delaunay(p).find_simplex(q)
    assert np.array_equal(s < 0, ref < 0)
    for j in np.flatnonzero(s >= 0):
        a, b, c, e = p[d.simplices[s[j]]]
        x = q[j]
        assert orient3d(*x, *b, *c, *e) >= 0 and orient3d(*a, *x, *c, *e) >= 0
        assert orient3d(*a, *b, *x, *e) >= 0 and orient3d(*a, *b, *c, *x) >= 0
    vt = d.vertex_to_simplex
    assert all(i in d.simplices[vt[i]] for i in range(p.shape[0]))
    indptr, indices = d.vertex_neighbor_vertices
    ref_ptr, ref_ind = Delaunay(p).vertex_neighbor_vertices
    for k in range(p.shape[0]):
        assert np.array_equal(indices[indptr[k]:indptr[k + 1]],
                              np.sort(ref_ind[ref_ptr[k]:ref_ptr[k + 1]]))
    assert np.array_equal(d.find_simplex(p[:1]), d.find_simplex(p[0][None]))


def test_duplicates_are_named():
    p = np.random.default_rng(0).random((50, 3))
    p[37] = p[12]
    with pytest.raises(ValueError, match=r"points\[37\] coincides with points\[12\]"):
        Delaunay3D(p)


@pytest.mark.parametrize("p, match", [
    (np.eye(3), "at least 4"),
    (np.c_[np.random.default_rng(0).random((20, 2)), np.zeros(20)], "coplanar"),
    (np.outer(np.arange(10.0), [1.0, 2.0, 3.0]), "coplanar"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), "not finite"),
    (np.zeros((5, 2)), "shape"),
])
def test_degenerate_input(p, match):
    with pytest.raises(ValueError, match=match):
        Delaunay3D(p)
