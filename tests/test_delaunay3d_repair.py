"""Tests of the local repair of a moving 3D Delaunay tetrahedralisation (flips and relocated
nodes): after every move the tetrahedra are exactly those a fresh build gives, on random,
lattice, cospherical and walled node sets, and bad moves leave the original untouched."""
import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from skfem_nem.geometry.delaunay3d import Delaunay3D
from skfem_nem.geometry.nodesets3d import box_nodes_3d

from test_delaunay3d import check_tetrahedralisation, same_as_qhull, tet_set

FEW = settings(max_examples=30, deadline=None)


def swirl(p):
    """A smooth flow tangent to the unit cube's walls (free slip)."""
    x, y, z = np.pi * p.T
    return np.c_[np.sin(x) * np.cos(y), -np.cos(x) * np.sin(y) + 0.3 * np.sin(y) * np.cos(z),
                 -0.3 * np.cos(y) * np.sin(z)]


def moved_and_checked(d, q, brute=True, rebuilt=0):
    """Repair d for positions q: the same tetrahedra as a fresh build, a valid structure,
    d unchanged, ``rebuilt`` as given (None: either); returns the repaired
    tetrahedralisation and the report."""
    before = (d.points.copy(), d.simplices.copy(), d.neighbors.copy())
    out, report = d.moved(q)
    assert tet_set(out) == tet_set(Delaunay3D(q))
    check_tetrahedralisation(q, out, brute=brute)
    assert all(np.array_equal(a, b) for a, b in zip(before, (d.points, d.simplices,
                                                              d.neighbors)))
    assert rebuilt is None or report["rebuilt"] == rebuilt
    return out, report


@FEW
@given(st.integers(8, 60), st.integers(0, 2 ** 31), st.sampled_from([0.01, 0.1, 0.5, 3.0]))
@example(40, 0, 3.0)
def test_random_moves_give_the_fresh_tetrahedralisation(n, seed, amplitude):
    """Independent random moves, small to larger than the spacing (nodes change places)."""
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    q = p + amplitude * n ** (-1 / 3) * rng.standard_normal(p.shape)
    out, _ = moved_and_checked(Delaunay3D(p), q)
    assert same_as_qhull(q, out)


@pytest.mark.parametrize("seed", range(20))
def test_tiny_sets_turned_inside_out(seed):
    """Five or six nodes thrown about: hull nodes whose other neighbours are coplanar (a
    flat link) are removed by turning the faces opposite them into hull faces."""
    rng = np.random.default_rng(seed)
    n = 5 + seed % 2
    p = rng.random((n, 3))
    q = p + 2.0 * rng.standard_normal(p.shape)
    moved_and_checked(Delaunay3D(p), q)


@FEW
@given(st.integers(2, 4), st.integers(0, 2 ** 31), st.sampled_from([1e-3, 0.1, 0.4]))
def test_lattice_moved_by_a_lattice_step(k, seed, step):
    """A cubic lattice (every cell cospherical) whose nodes move to other lattice-like,
    still cospherical positions: ties broken by the same perturbation as a fresh build."""
    g = np.stack(np.meshgrid(*[np.arange(k + 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    q = g.copy()
    pick = rng.random(g.shape[0]) < 0.5
    q[pick] += step * rng.integers(-1, 2, (int(pick.sum()), 3))
    if np.unique(q, axis=0).shape[0] < q.shape[0]:
        return
    moved_and_checked(Delaunay3D(g), q)


def test_a_smooth_flow_is_mended_by_flips():
    """Walls with coplanar nodes sliding along them, a flow over many steps: every step's
    tetrahedra are the fresh ones, and flips do most of the work."""
    p = box_nodes_3d(600, seed=1)
    d = Delaunay3D(p)
    flips = relocated = 0
    for _ in range(6):
        q = p + 0.15 * 600 ** (-1 / 3) * swirl(p)
        q = np.clip(q, 0.0, 1.0)
        q[p == 0.0], q[p == 1.0] = 0.0, 1.0  # wall nodes stay on their walls
        d, report = moved_and_checked(d, q, brute=False)
        flips += report["flips"]
        relocated += report["relocated"]
        p = q
    assert flips > 0
    assert relocated < flips


def test_points_on_a_sphere_rotated():
    """All nodes cospherical before and after (a rotation keeps them so)."""
    rng = np.random.default_rng(3)
    p = rng.standard_normal((80, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    c, s = np.cos(0.05), np.sin(0.05)
    q = p @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    moved_and_checked(Delaunay3D(p), q)


def test_unmoved_nodes_change_nothing():
    p = np.random.default_rng(0).random((200, 3))
    d = Delaunay3D(p)
    out, report = d.moved(p.copy())
    assert report == dict(report, flips=0, relocated=0, rebuilt=0)
    assert np.array_equal(out.simplices, d.simplices)


def test_coincident_nodes_are_named_and_nothing_changes():
    p = np.random.default_rng(0).random((50, 3))
    d = Delaunay3D(p)
    q = p.copy()
    q[7] = q[31]
    before = d.simplices.copy()
    with pytest.raises(ValueError, match=r"points\[31\] coincides with points\[7\]"):
        d.moved(q)
    assert np.array_equal(d.simplices, before)
    assert tet_set(d.moved(p)[0]) == tet_set(d)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((49, 3)), r"shape of the nodes"),
    (np.full((50, 3), np.nan), r"points\[0\]"),
])
def test_bad_positions_are_refused(bad, match):
    d = Delaunay3D(np.random.default_rng(0).random((50, 3)))
    with pytest.raises(ValueError, match=match):
        d.moved(bad)
