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
    # a scipy Delaunay is reused
    tri = Delaunay(p)
    Phi2 = natural_neighbour_coordinates(tri, q)
    assert abs(Phi2 - Phi).max() == 0.0
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
