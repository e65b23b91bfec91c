"""The public coordinate functions in every dimension: method dispatch, 2D Lasserre
against the area method, 3D and 4D through ``sibson_coordinates``."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay

from helpers import check_properties, compare_2d, dense
from skfem_nem import Triangulation, natural_neighbour_coordinates, sibson_coordinates
from skfem_nem.coordinates.lasserre import sibson_coordinates_nd
from skfem_nem.geometry.delaunay3d import Delaunay3D


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lasserre_equals_area_in_2d(seed):
    rng = np.random.default_rng(seed)
    p = rng.random((400, 2))
    tri = Triangulation(p)
    # queries inside the triangles, on interior Delaunay edges and near nodes
    t = rng.integers(0, tri.ntriangles, 300)
    lam = rng.dirichlet(np.ones(3), 300)
    q = np.einsum("mk,mkd->md", lam, p[tri.triangles[t]])
    a, b = p[tri.triangles[t[:50], 0]], p[tri.triangles[t[:50], 1]]
    s = rng.random((50, 1))
    on_edge = a + s * (b - a)
    q = np.r_[q, on_edge]
    q = q[tri.locate(q) >= 0]
    compare_2d(p, q, gtol=1e-12)
    # within 1e-7 of a node both methods lose gradient digits like 1e-17 / r
    near = p[tri.triangles[t[50:80], 2]] + 1e-7 * rng.standard_normal((30, 2))
    compare_2d(p, near[tri.locate(near) >= 0], gtol=1e-7)
    # the Triangulation object is accepted by both methods
    np.testing.assert_allclose(
        dense(sibson_coordinates(tri, q[:20], method="lasserre")),
        dense(sibson_coordinates(tri, q[:20])), atol=1e-12)


@pytest.mark.parametrize("d", [3, 4])
def test_public_function_in_3d_and_4d(d):
    rng = np.random.default_rng(d)
    p = rng.random((300 if d == 3 else 150, d))
    q = 0.2 + 0.6 * rng.random((40, d))
    p_before, q_before = p.copy(), q.copy()
    Phi, dPhi = sibson_coordinates(p, q, gradient=True)
    assert np.array_equal(p, p_before) and np.array_equal(q, q_before)
    check_properties(p, q, (Phi, dPhi))
    ref, dref = sibson_coordinates_nd(p, q, gradient=True)
    assert abs(Phi - ref).max() == 0.0
    assert all(abs(a - b).max() == 0.0 for a, b in zip(dPhi, dref))
    # a scipy Delaunay is reused (in 3D the nodes alone are triangulated by Delaunay3D, whose
    # tetrahedra come in another order: the same coordinates up to round-off), and so is ours
    tri = Delaunay(p)
    Phi2 = natural_neighbour_coordinates(tri, q)
    assert abs(Phi2 - Phi).max() <= (0.0 if d == 4 else 1e-14)
    if d == 3:
        Phi3 = natural_neighbour_coordinates(Delaunay3D(p), q)
        assert abs(Phi3 - Phi).max() == 0.0
    # nodal interpolation: Kronecker delta
    D = sibson_coordinates(p, p[:7]).toarray()
    np.testing.assert_array_equal(D, np.eye(p.shape[0])[:7])


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(8, 80))
def test_3d_properties_on_random_node_sets(seed, n):
    # small random node sets (many hull-adjacent, thin simplices); queries inside
    # random Delaunay tetrahedra. Measured over 1,800 such queries: partition of
    # unity 4e-16, linear precision 1.5e-13, gradient identities 7e-10 relative
    # (near thin hull tetrahedra, whose cells are huge)
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    tri = Delaunay(p)
    s = rng.integers(0, tri.simplices.shape[0], 6)
    q = np.einsum("mk,mkd->md", rng.dirichlet(np.ones(4), 6), p[tri.simplices[s]])
    Phi, dPhi = sibson_coordinates(tri, q, gradient=True)
    check_properties(p, q, (Phi, dPhi), tol=1e-11, grad_tol=1e-8, neg_tol=1e-13)


@pytest.mark.xfail(strict=True, reason="known defect: a 3D gradient identity holds to "
                   "2.6e-5 only (query 3 of this draw; gradients below 4, insphere margins "
                   "above 1e-4); 1 draw of the property test above in over 1,500 fails so")
def test_3d_gradient_identity_on_a_drawn_set_it_misses():
    """The draw of the property test that failed once (seed 670924, 8 nodes), kept
    so the defect stays in view; strict: it fails here once the gradients are fixed."""
    rng = np.random.default_rng(670924)
    p = rng.random((8, 3))
    tri = Delaunay(p)
    s = rng.integers(0, tri.simplices.shape[0], 6)
    q = np.einsum("mk,mkd->md", rng.dirichlet(np.ones(4), 6), p[tri.simplices[s]])
    Phi, dPhi = sibson_coordinates(tri, q, gradient=True)
    check_properties(p, q, (Phi, dPhi), tol=1e-11, grad_tol=1e-8, neg_tol=1e-13)


def test_3d_chunks_give_the_same_matrices():
    rng = np.random.default_rng(5)
    p = rng.random((200, 3))
    q = 0.3 + 0.4 * rng.random((130, 3))
    Phi, dPhi = sibson_coordinates(p, q, gradient=True)
    Phi2, dPhi2 = sibson_coordinates(p, q, gradient=True, chunk=17)
    assert abs(Phi - Phi2).max() == 0.0 and np.array_equal(Phi.indices, Phi2.indices)
    assert all(abs(a - b).max() == 0.0 for a, b in zip(dPhi, dPhi2))


def test_3d_large_batches_in_z_order_keep_the_callers_rows():
    # from _SORT_MIN queries on, a batch runs in Z-order; every row must come back to
    # its query, bit for bit the row a small (unsorted) batch of that query gives
    from skfem_nem.coordinates import lasserre
    rng = np.random.default_rng(11)
    p = rng.random((800, 3))
    q = 0.2 + 0.6 * rng.random((lasserre._SORT_MIN + 500, 3))
    Phi, dPhi = sibson_coordinates(p, q, gradient=True, chunk=1000)
    parts = [sibson_coordinates(p, q[i:i + 900], gradient=True) for i in range(0, len(q), 900)]
    import scipy.sparse as sp
    Phi2 = sp.vstack([a for a, _ in parts], format="csr")
    assert np.array_equal(Phi.indptr, Phi2.indptr) and np.array_equal(Phi.indices, Phi2.indices)
    assert np.array_equal(Phi.data, Phi2.data)
    for k in range(3):
        assert np.array_equal(dPhi[k].data, sp.vstack([b[k] for _, b in parts], format="csr").data)
    # and a point outside is still named by its own index
    q[1234] = [2.0, 0.5, 0.5]
    with pytest.raises(ValueError, match=r"x\[1234\]"):
        sibson_coordinates(p, q)


def test_dispatch_errors():
    rng = np.random.default_rng(0)
    p3 = rng.random((50, 3))
    with pytest.raises(ValueError, match="area method works in 2D only"):
        sibson_coordinates(p3, p3[:2] * 0.5 + 0.25, method="area")
    with pytest.raises(ValueError, match="Sibson coordinates only"):
        natural_neighbour_coordinates(p3, p3[:2] * 0.5 + 0.25, kind="laplace")
    with pytest.raises(ValueError, match="method must be"):
        sibson_coordinates(p3, p3[:2], method="watson")
    with pytest.raises(ValueError, match="hint and return_triangles"):
        sibson_coordinates(rng.random((20, 2)), [[0.5, 0.5]], method="lasserre", hint=[0])
    with pytest.raises(ValueError, match=r"shape \(m, 3\)"):
        sibson_coordinates(p3, [[0.5, 0.5]])
    with pytest.raises(ValueError, match=r"x\[1\] = \[2.0, 0.5, 0.5\]"):
        sibson_coordinates(p3, [[0.5, 0.5, 0.5], [2.0, 0.5, 0.5]])
    with pytest.raises(ValueError, match=r"non-finite.*x\[0\]"):
        sibson_coordinates(p3, [[np.nan, 0.5, 0.5]])
    dup = np.r_[p3, p3[4:5]]
    with pytest.raises(ValueError, match=r"nodes\[50\] coincides with nodes\[4\]"):
        sibson_coordinates(dup, [[0.5, 0.5, 0.5]])
    with pytest.raises(ValueError, match=r"\(node 3\)"):
        sibson_coordinates(p3, p3[3:4], gradient=True)


def test_scipy_delaunay_in_2d_works_with_both_methods():
    rng = np.random.default_rng(7)
    p = rng.random((100, 2))
    tri = Delaunay(p)
    q = 0.3 + 0.4 * rng.random((20, 2))
    A = sibson_coordinates(tri, q)
    B = sibson_coordinates(tri, q, method="lasserre")
    assert abs(A - B).max() < 1e-12 and abs(A - sibson_coordinates(p, q)).max() == 0.0


def _lattice_wall_box():
    """Random nodes in the unit cube whose bottom face is a 6 x 6 lattice (its squares'
    corners co-circular: Qhull spans flat tetrahedra of four of them, on the wall)."""
    from skfem_nem import delaunay_mesh
    from skfem_nem.geometry import box_nodes_3d
    p = box_nodes_3d(150, (1, 1, 1), seed=0, boundary_spacing=0.25)
    g = np.linspace(0, 1, 6)
    X, Y = np.meshgrid(g, g)
    return delaunay_mesh(np.vstack([p[p[:, 2] > 0], np.c_[X.ravel(), Y.ravel(), 0 * X.ravel()]]))


def test_flat_tetrahedra_in_a_hull_plane_are_sealed_off(monkeypatch):
    """The flat tetrahedra of wall nodes are found (exactly those with their four nodes on
    the wall), none of a cube lattice's interior flat ones is, and cutting them off the
    adjacency leaves every coordinate and gradient as it was (the region no longer grows
    across the wall, which is all that changes)."""
    import skfem_nem.coordinates.lasserre as lasserre
    from skfem_nem.geometry.delaunay_nd import hull_plane_flats
    m = _lattice_wall_box()
    tri = Delaunay(np.ascontiguousarray(m.p.T))              # Qhull's, as a user may pass it
    p, S = tri.points, tri.simplices
    found = hull_plane_flats(p, S, np.unique(tri.convex_hull))
    vol = np.abs(np.linalg.det(p[S[:, 1:]] - p[S[:, :1]]))
    on_wall = np.flatnonzero((vol == 0) & (p[S][:, :, 2] == 0).all(axis=1))
    assert on_wall.size > 0 and np.array_equal(np.sort(found), on_wall)
    g = np.linspace(0, 1, 4)
    lattice = np.array(np.meshgrid(g, g, g)).reshape(3, -1).T
    d = Delaunay(lattice)
    L = lattice[d.simplices]
    flat = np.flatnonzero(np.abs(np.linalg.det(L[:, 1:] - L[:, :1])) < 1e-12)
    flagged = hull_plane_flats(lattice, d.simplices, np.unique(d.convex_hull))
    V = lattice[d.simplices[flagged]]                    # (k, 4, 3)
    on_a_face = ((V == 0).all(axis=1) | (V == 1).all(axis=1)).any(axis=1)
    assert on_a_face.all() and 0 < flagged.size < flat.size   # the others cross the cube
    q = np.random.default_rng(1).random((600, 3))
    q[:200, 2] *= 0.05                                   # many next to the lattice wall
    A, dA = natural_neighbour_coordinates(tri, q, gradient=True, method="lasserre")
    monkeypatch.setattr(lasserre, "sealed_neighbours",
                        lambda p, tri: np.array(tri.neighbors, dtype=np.int64))
    B, dB = natural_neighbour_coordinates(tri, q, gradient=True, method="lasserre")
    assert abs(A - B).max() < 1e-13
    assert max(abs(a - b).max() for a, b in zip(dA, dB)) < 1e-10


def test_a_wall_of_flat_tetrahedra_does_not_stall_the_3d_basis():
    """The nodes of a 3D sinking plate pressed onto the bottom wall (1,900 nodes, 163 of
    them on the wall): Qhull makes 308 flat tetrahedra there. The conflict regions of the
    smoothed basis' points grew across them into co-spherical clusters whose cells took the
    general recursion, and the basis took hours. The package's own tetrahedralisation
    (Delaunay3D) makes none; the basis is built, and its values are a partition of unity with
    linear precision away from the wall."""
    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
    from pathlib import Path
    nodes = np.load(Path(__file__).parent / "data" / "plate3d_wall_nodes.npz")["nodes"]
    P = nodes[Delaunay(nodes).simplices]
    assert np.count_nonzero(np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) == 0) >= 300
    m = delaunay_mesh(nodes)
    P = m.p.T[m.t.T]
    assert np.count_nonzero(np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) == 0) == 0
    b = NaturalNeighbourBasis(m, ElementNaturalNeighbour())
    Phi = b.values_matrix
    x = b.global_coordinates().value.reshape(3, -1).T
    assert abs(Phi.sum(axis=1).A1 - 1).max() < 1e-12
    away = x[:, 2] > 1e-6
    assert abs(Phi @ m.p.T - x)[away].max() < 1e-10


def test_points_on_a_wall_stay_inside_next_to_nearly_flat_tetrahedra():
    """The same plate two steps on: nodes 1e-11 above the bottom wall make tetrahedra nearly,
    not exactly, in its plane. Sealed off, their neighbours' faces would be hull facets tilted
    off the wall, and points on the wall (a figure's slice) came out outside the hull; only
    exactly planar ones are sealed, and the wall's points interpolate."""
    from pathlib import Path
    nodes = np.load(Path(__file__).parent / "data" / "plate3d_wall_nodes.npz")["pressed"]
    A, B = np.meshgrid(np.linspace(0, 4, 120), np.linspace(0, 1, 8))
    x = np.c_[A.ravel(), np.ones(A.size), B.ravel()]      # the slice y = 1, bottom row z = 0
    Phi = sibson_coordinates(nodes, x)
    assert abs(Phi.sum(axis=1).A1 - 1).max() < 1e-12 and abs(Phi @ nodes - x).max() < 1e-10
