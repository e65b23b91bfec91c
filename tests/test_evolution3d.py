"""LagrangianMesh3D: nodes advected in 3D, fields follow their nodes, the tetrahedra repaired
every step into the ones a fresh build gives."""

import numpy as np
import pytest
from skfem import MeshTet

from helpers import cube_nodes, vortex
from skfem_nem import LagrangianMesh3D
from skfem_nem.geometry.delaunay3d import Delaunay3D


def inner_cube(n=300, seed=0):
    """Unit-cube nodes, 25 a face, all off the edges and walls."""
    return cube_nodes(n, seed, per_face=25, margin=(0.05, 0.02))


def test_fields_follow_their_nodes_and_nothing_is_lost():
    p = inner_cube()
    n = p.shape[0]
    rng = np.random.default_rng(1)
    density = rng.random(n)
    m = LagrangianMesh3D(p, {"density": density, "x0": p, "id": np.arange(n)})
    density[:] = -1.0                      # the mesh holds copies
    assert m.node_fields["density"].min() >= 0
    vol0 = m.mesh
    dt = 0.05
    assert 0 < m.max_dt(vortex(m.nodes)) < 0.05   # a step moves nodes past their neighbours
    changed = flips = 0
    x = np.array(m.nodes)
    for _ in range(6):
        r = m.advance(vortex, dt)
        # the nodes move like an accurate integration of the flow (trapezoidal
        # predictor-corrector: second order; reference by RK4 substeps)
        for _ in range(8):
            h = dt / 8
            k1 = vortex(x)
            k2 = vortex(x + h / 2 * k1)
            k3 = vortex(x + h / 2 * k2)
            k4 = vortex(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        err = np.abs(m.nodes - x).max()
        assert err < 3e-3
        assert r["converged"]
        changed += r["tetrahedra_changed"]
        flips += r["flips"]
        assert r["rebuilt"] == 0 and r["repair_seconds"] > 0
        # the repaired tetrahedra are the Delaunay ones of the moved nodes
        fresh = Delaunay3D(np.array(m.nodes)).simplices
        assert set(map(tuple, np.sort(m.mesh.t.T, axis=1).tolist())) == \
            set(map(tuple, np.sort(fresh, axis=1).tolist()))
        # nothing is lost: every node is a vertex, the tetrahedra fill the box
        assert isinstance(m.mesh, MeshTet) and np.unique(m.mesh.t).size == n
        assert abs(_volume(m.mesh) - 1.0) < 1e-12
    assert m.step == 6 and abs(m.time - 6 * dt) < 1e-15
    assert changed > 0 and flips > 0       # the connectivity did change, by flips
    assert np.abs(m.nodes - p).max() > 0.05
    # the fields are untouched and still belong to the same nodes
    np.testing.assert_array_equal(m.node_fields["x0"], p)
    np.testing.assert_array_equal(m.node_fields["id"], np.arange(n))
    assert np.array_equal(m.node_fields["density"], np.random.default_rng(1).random(n))
    # walls: the nodes on a face stay on it
    on = (p == 0) | (p == 1)
    np.testing.assert_array_equal(m.nodes[on], p[on])
    # Sibson interpolation of a node field reproduces it at the nodes
    np.testing.assert_allclose(m.interpolate("x0", m.nodes[:10]), p[:10], atol=1e-12)
    assert vol0 is not m.mesh
    # second order in time: half the step, a quarter of the error
    m2 = LagrangianMesh3D(p)
    for _ in range(12):
        m2.advance(vortex, dt / 2)
    assert np.abs(m2.nodes - x).max() < 0.3 * err
    b = m.basis()
    assert b is m.basis() and b.mesh is m.mesh


def test_bad_input_leaves_the_mesh_unchanged():
    p = inner_cube(100)
    m = LagrangianMesh3D(p, {"c": np.ones(p.shape[0])})
    t0 = m.mesh.t.copy()
    with pytest.raises(ValueError, match="shape"):
        m.advance(lambda x: x[:, :2], 0.01)
    with pytest.raises(ValueError, match="node 3"):
        m.advance(lambda x: np.where(np.arange(x.shape[0])[:, None] == 3, np.nan, 0 * x), 0.01)
    with pytest.raises(ValueError, match="leave the box"):
        m.advance(lambda x: np.tile([0.0, 0.0, 5.0], (x.shape[0], 1)), 1.0)
    with pytest.raises(ValueError, match="dt must be positive"):
        m.advance(vortex, -1.0)
    with pytest.raises(ValueError, match="maxiter must be a positive integer"):
        m.advance(vortex, 0.01, maxiter=0)
    with pytest.raises(TypeError, match="velocity must be a callable"):
        m.advance(np.zeros((p.shape[0], 3)), 0.01)
    assert m.step == 0 and np.array_equal(m.mesh.t, t0)
    with pytest.raises(ValueError, match="node field 'c'"):
        LagrangianMesh3D(p, {"c": np.ones(3)})
    # a flow that collapses two nodes onto each other is refused, naming them
    p = np.r_[p, [[0.5, 0.5, 0.5], [0.25, 0.5, 0.5]]]
    m = LagrangianMesh3D(p)
    t0 = m.mesh.t.copy()
    k = p.shape[0] - 1

    def collapse(x):
        v = np.zeros_like(x)
        v[k] = [0.25, 0.0, 0.0]
        return v

    coincide = rf"step 1.*points\[{k}\] coincides with points\[{k - 1}\]"
    with pytest.raises(ValueError, match=coincide):
        m.advance(collapse, 1.0)
    assert m.step == 0 and np.array_equal(m.mesh.t, t0) and np.array_equal(m.nodes, p)


def _volume(mesh):
    p = mesh.p.T[mesh.t.T]
    return np.abs(np.linalg.det(p[:, 1:] - p[:, :1])).sum() / 6


def test_nodes_pressed_onto_a_wall_are_put_on_it():
    """A flow towards the bottom wall, w = -1: each step a node covers at most 0.9 of its
    distance to the wall, so without a floor it would come 1e-11 close and more; a node
    closer than WALL_SNAP of the box is put on the wall, never left in between, and keeps
    its wall coordinate from then on (its normal velocity is dropped)."""
    from skfem_nem.evolution.lagrangian3d import WALL_SNAP
    from skfem_nem.geometry import box_nodes_3d
    p = box_nodes_3d(60, (1, 1, 1), seed=2, boundary_spacing=0.5)
    p[p[:, 2] > 0, 2] += 0.03 - p[p[:, 2] > 0, 2].min()       # the lowest at z = 0.03
    m = LagrangianMesh3D(p)
    walls0 = np.count_nonzero(p[:, 2] == 0)

    def down(x):
        return np.c_[0 * x[:, :2], -1 + 0 * x[:, 2]]

    snapped = 0
    for _ in range(100):
        snapped += m.advance(down, 1e-3)["snapped"]
        z = m.nodes[:, 2]
        assert not ((z > 0) & (z < WALL_SNAP)).any()
    assert snapped > 0 and np.count_nonzero(m.nodes[:, 2] == 0) == walls0 + snapped
    m.advance(lambda x: np.c_[0 * x[:, :2], 1 + 0 * x[:, 2]], 0.1)    # lifted: they stay
    assert np.count_nonzero(m.nodes[:, 2] == 0) == walls0 + snapped


def test_a_snapshot_takes_several_moves_back_whole():
    """restore(snapshot()) after two moves: the nodes, tetrahedra, fields, clock and
    reports of the snapshot, and the mesh moves on from there as before."""
    p = cube_nodes(150, seed=4)
    m = LagrangianMesh3D(p, {"x0": p})
    first = m.advance(vortex, 0.05)
    snap = m.snapshot()
    nodes, t, fields = m.nodes.copy(), m.mesh.t.copy(), m.node_fields["x0"].copy()
    m.advance(vortex, 0.05)
    m.advance(vortex, 0.05)
    assert m.step == 3 and len(m.history) == 3
    m.restore(snap)
    np.testing.assert_array_equal(m.nodes, nodes)
    np.testing.assert_array_equal(m.mesh.t, t)
    np.testing.assert_array_equal(m.node_fields["x0"], fields)
    assert (m.step, m.time, m.history) == (1, 0.05, [first])
    assert m.advance(vortex, 0.05)["step"] == 2
