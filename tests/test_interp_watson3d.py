"""Sibson's 3D values by Watson's decomposition (interp_watson3d): equal to the Box 1
coordinates' (the coordinates times the values) on random, clustered and lattice data, with
queries at data points, on faces, near and on the hull; the decomposition in rational
arithmetic; the flagged queries; the wiring into NaturalNeighbourInterpolator."""
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from skfem_nem import NaturalNeighbourInterpolator, sibson_coordinates
from skfem_nem.coordinates import interp_natural
from skfem_nem.coordinates.interp_watson3d import SibsonWatson3D, watson_applies
from skfem_nem.geometry.delaunay3d import Delaunay3D

TOL = 1e-12


def box1(tri, q):
    """The Box 1 coordinates (Lasserre's volumes) at q: with their gradients, which only
    Box 1 gives (3D values alone of large batches come from Watson's decomposition too)."""
    return sibson_coordinates(tri, q, gradient=True, undefined="nan")[0]


def cube(n, seed):
    """n random points in the unit cube and its corners."""
    rng = np.random.default_rng(seed)
    corners = np.array(np.meshgrid([0.0, 1.0], [0.0, 1.0], [0.0, 1.0],
                                   indexing="ij")).reshape(3, -1).T
    return np.vstack([corners, rng.random((n, 3))])


def watson(tri, q, f):
    """Watson's values, its flagged queries recomputed by the coordinates (as the
    interpolator does), and the flagged indices."""
    F = np.asarray(f).reshape(len(f), -1)
    v, bad = SibsonWatson3D(tri, F)(q)
    assert np.isnan(v[bad]).all() and np.isfinite(np.delete(v, bad, axis=0)).all()
    v[bad] = box1(tri, q[bad]) @ F
    return v.reshape((len(q),) + np.shape(f)[1:]), bad


def exact_watson(p, simplices, x, f):
    """Sibson's interpolant at x (3,) in rational arithmetic by the decomposition of the
    module: sum_T W_T sum_k lambda_k f_k / sum_T W_T, W_T = D^3 / (S prod lambda_k), over the
    tetrahedra whose circumsphere strictly holds x."""
    P = [tuple(Fraction(c) for c in pt) for pt in p]
    X = tuple(Fraction(c) for c in x)

    def det3(a, b, c):
        return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))

    num, den = Fraction(0), Fraction(0)
    for t in simplices:
        V = [P[i] for i in t]
        E = [tuple(V[k][d] - V[0][d] for d in range(3)) for k in (1, 2, 3)]
        S = det3(*E)
        # barycentrics by Cramer's rule; the circumcentre o by the normal equations
        a = tuple(X[d] - V[0][d] for d in range(3))
        lam = [det3(a, E[1], E[2]) / S, det3(E[0], a, E[2]) / S, det3(E[0], E[1], a) / S]
        lam = [1 - sum(lam)] + lam
        r = [sum(e * e for e in E[k]) / 2 for k in range(3)]
        o = [det3(*[tuple(r[k] if j == d else E[k][j] for j in range(3)) for k in range(3)])
             / S + V[0][d] for d in range(3)]
        D = sum((V[0][d] - o[d]) ** 2 for d in range(3)) - sum((X[d] - o[d]) ** 2
                                                                for d in range(3))
        if D <= 0:
            continue
        W = D ** 3 / (abs(S) * lam[0] * lam[1] * lam[2] * lam[3])
        den += W
        num += W * sum(lk * Fraction(float(f[i])) for lk, i in zip(lam, t))
    return float(num / den)


def test_applies_to_the_package_tetrahedralisation_only():
    from scipy.spatial import Delaunay
    p = cube(30, 0)
    assert watson_applies(Delaunay3D(p))
    assert not watson_applies(Delaunay(p))


def test_sibson_coordinates_take_watson_for_large_3d_batches(monkeypatch):
    """sibson_coordinates without gradients on a Delaunay3D: Watson's rows from WATSON_MIN
    queries (the Box 1 method's for the flagged ones), the Box 1 coordinates to round-off;
    a query outside the hull is named by its index in the whole batch."""
    from skfem_nem.coordinates import lasserre, watson3d
    p = cube(400, 12)
    tri = Delaunay3D(p)
    q = 0.05 + 0.9 * np.random.default_rng(13).random((3000, 3))
    calls = []
    real = watson3d.TetrahedraRecords.coordinates
    monkeypatch.setattr(watson3d.TetrahedraRecords, "coordinates",
                        lambda *a: calls.append(1) or real(*a))
    M = sibson_coordinates(tri, q)
    assert calls == [1]
    assert abs(M - box1(tri, q)).max() < 1e-11
    np.testing.assert_allclose(M @ p, q, rtol=0, atol=1e-12)
    q[2017] = [0.5, 0.5, 1.5]
    with pytest.raises(ValueError, match=r"x\[2017\]"):
        sibson_coordinates(tri, q)
    monkeypatch.setattr(lasserre, "WATSON_MIN", 10 ** 9)
    sibson_coordinates(tri, 0.25 + 0.5 * np.random.default_rng(14).random((3000, 3)))
    assert len(calls) == 2          # the batch with a query outside tried it, not this one


def test_random_data_equal_to_the_coordinates_and_few_flagged():
    p = cube(3000, 1)
    tri = Delaunay3D(p)
    rng = np.random.default_rng(2)
    q = 0.02 + 0.96 * rng.random((20000, 3))
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + p[:, 2] ** 2
    v, bad = watson(tri, q, f)
    np.testing.assert_allclose(v, box1(tri, q) @ f, rtol=0, atol=TOL)
    assert bad.size < 0.03 * q.shape[0]      # slivers' cancelling terms: about 1%


def test_rational_decomposition_equals_the_coordinates():
    """The decomposition itself, in exact arithmetic, is Sibson's interpolant."""
    p = cube(40, 3)
    tri = Delaunay3D(p)
    f = p[:, 0] ** 2 - p[:, 1] * p[:, 2]
    q = np.array([[0.31, 0.52, 0.47], [0.7, 0.2, 0.65], [0.5, 0.5, 0.5]])
    for x, ref in zip(q, box1(tri, q) @ f):
        assert exact_watson(p, tri.simplices, x, f) == pytest.approx(ref, abs=1e-13)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(5, 200), seed=st.integers(0, 2 ** 31), scale=st.sampled_from([1e-3, 1.0,
                                                                                   1e4]),
       cluster=st.booleans())
def test_linear_precision_and_agreement_property(n, seed, scale, cluster):
    """Random and clustered node sets at any scale: linear data reproduced, values equal to
    the coordinates', at random queries and at the nodes themselves."""
    rng = np.random.default_rng(seed)
    p = cube(n, seed)
    if cluster:
        p[8:] = 0.5 + 0.05 * rng.standard_normal((n, 3)).clip(-9, 9)
    p = p * scale + 3.0 * scale
    tri = Delaunay3D(p)
    q = np.vstack([p.min(0) + (p.max(0) - p.min(0)) * (0.01 + 0.98 * rng.random((300, 3))),
                   p[8:20]])
    lin = np.c_[1.0 + p @ [1.0, -2.0, 0.5] / scale, p[:, 0] / scale]
    v, _ = watson(tri, q, lin)
    np.testing.assert_allclose(v[:, 0], 1.0 + q @ [1.0, -2.0, 0.5] / scale, rtol=0,
                               atol=1e-11)
    np.testing.assert_allclose(v, box1(tri, q) @ lin, rtol=0, atol=1e-11)


def test_lattice_queries_on_faces_edges_nodes_and_hull_are_flagged_or_exact():
    """A cubic lattice (every cube's 8 corners co-spherical): queries at the nodes, on the
    lattice's faces and edges and on the hull are flagged or equal to the coordinates."""
    g = np.linspace(0.0, 1.0, 5)
    p = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    tri = Delaunay3D(p)
    rng = np.random.default_rng(4)
    q = np.vstack([rng.random((500, 3)), p[::7], [[0.5, 0.3, 0.125], [0.25, 0.25, 0.6],
                                                 [1.0, 0.4, 0.3], [0.0, 0.0, 0.7]]])
    f = np.cos(2 * p[:, 0]) + p[:, 1] * p[:, 2]
    v, bad = watson(tri, q, f)
    np.testing.assert_allclose(v, box1(tri, q) @ f, rtol=0, atol=TOL)
    at_nodes = np.arange(500, 500 + p[::7].shape[0])
    on_hull = np.arange(q.shape[0] - 2, q.shape[0])
    assert np.isin(at_nodes, bad).all() and np.isin(on_hull, bad).all()


def test_trailing_and_complex_values():
    p = cube(200, 5)
    tri = Delaunay3D(p)
    q = 0.1 + 0.8 * np.random.default_rng(6).random((400, 3))
    f = np.stack([p[:, 0] + 1j * p[:, 1], p[:, 2] ** 2 - 2j], axis=1)
    v, bad = SibsonWatson3D(tri, f)(q)
    ok = np.setdiff1d(np.arange(q.shape[0]), bad)
    np.testing.assert_allclose(v[ok], (box1(tri, q) @ f)[ok], rtol=0, atol=TOL)
    v0, bad0 = SibsonWatson3D(tri, f[:, :0])(q)
    assert v0.shape == (400, 0) and bad0.size == 0


def test_interpolator_takes_watson_for_large_3d_batches(monkeypatch):
    """NaturalNeighbourInterpolator's 3D Sibson values go through Watson's decomposition from
    WATSON_MIN queries (built once), with the same values as the coordinates' path, NaN
    (fill_value) outside the hull, and gradients still from the coordinates."""
    p = cube(500, 7)
    f = np.exp(p[:, 0]) * p[:, 1]
    rng = np.random.default_rng(8)
    q = np.vstack([rng.random((3000, 3)), [[1.5, 0.5, 0.5]]])
    itp = NaturalNeighbourInterpolator(p, f)
    calls = []
    real = SibsonWatson3D.__call__
    monkeypatch.setattr(SibsonWatson3D, "__call__", lambda s, x: calls.append(len(x))
                        or real(s, x))
    v = itp(q)
    assert calls == [3000]
    assert np.isnan(v[-1])
    np.testing.assert_allclose(v[:-1], box1(p, q[:-1]) @ f, rtol=0, atol=TOL)
    monkeypatch.setattr(interp_natural, "WATSON_MIN", 10 ** 9)
    fresh = NaturalNeighbourInterpolator(p, f)
    np.testing.assert_allclose(fresh(q), v, rtol=0, atol=TOL)
    assert calls == [3000]
    g = itp.gradient(q[:5])
    assert g.shape == (5, 3) and calls == [3000]


# --------------------------------------------------------------------------
# whole rows of coordinates (watson3d.rows_3d), inside tetrahedra and on their faces
# --------------------------------------------------------------------------

def _centroid_and_face_queries(p, T):
    """The centroids of the tetrahedra T (slot -1) and of all their faces (slot: the
    opposite vertex), with the tetrahedron each lies in."""
    nt = T.shape[0]
    faces = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    k = np.tile(np.arange(4), nt)
    tt = np.repeat(np.arange(nt), 4)
    qf = p[T[tt][np.arange(4 * nt)[:, None], faces[k]]].mean(axis=1)
    return (np.vstack([p[T].mean(axis=1), qf]), np.r_[np.arange(nt), tt],
            np.r_[np.full(nt, -1), k])


@settings(max_examples=15, deadline=None)
@given(n=st.integers(10, 300), seed=st.integers(0, 2 ** 31),
       scale=st.sampled_from([1e-3, 1.0, 1e4]))
def test_rows_on_faces_and_inside_equal_the_box1_coordinates(n, seed, scale):
    """Rows at every tetrahedron's centroid and every face's centroid (where the two
    tetrahedra at the face take the closed-form limit): the Box 1 coordinates to round-off,
    linear precision, rows summing to one; hull faces and cancelling queries flagged."""
    from skfem_nem.coordinates.watson3d import TetrahedraRecords, rows_3d
    p = cube(n, seed) * scale
    tri = Delaunay3D(p)
    rec = TetrahedraRecords(p, tri.simplices, tri.neighbors)
    assert rec.usable
    q, start, slot = _centroid_and_face_queries(p, rec.T)
    ptr, idx, val, flagged = rows_3d(rec.R, rec.T, rec.NB, p.shape[0], q, start, slot)
    import scipy.sparse as sp
    M = sp.csr_matrix((val, idx, ptr), shape=(q.shape[0], p.shape[0]))
    hull_face = (slot >= 0) & (rec.NB[start, np.maximum(slot, 0)] < 0)
    assert np.isin(np.flatnonzero(hull_face), flagged).all()
    ok = np.setdiff1d(np.arange(q.shape[0]), flagged)
    ref = box1(tri, q[ok])
    assert abs(M[ok] - ref).max() < 1e-11
    np.testing.assert_allclose(M[ok] @ p / scale, q[ok] / scale, rtol=0, atol=1e-11)
    np.testing.assert_allclose(np.asarray(M[ok].sum(axis=1)).ravel(), 1.0, atol=1e-13)
    assert flagged.size <= hull_face.sum() + 0.05 * q.shape[0]


def test_tetrahedra_records_merge_the_fallback_rows_and_refuse_flat_meshes():
    """coordinates() puts the flagged queries' rows from the fallback in their places; a
    mesh with a flat tetrahedron (Qhull's on a lattice) is not usable."""
    from helpers import qhull_mesh
    from skfem_nem.coordinates.watson3d import TetrahedraRecords
    p = cube(200, 9)
    tri = Delaunay3D(p)
    rec = TetrahedraRecords(p, tri.simplices, tri.neighbors)
    q, start, slot = _centroid_and_face_queries(p, rec.T)
    calls = []

    def fallback(x):
        calls.append(x.shape[0])
        return box1(tri, x)

    M = rec.coordinates(q, start, slot, fallback)
    assert calls and calls[0] >= np.sum(rec.NB < 0)        # the hull faces, at least
    assert abs(M - box1(tri, q)).max() < 1e-11
    g = np.linspace(0.0, 1.0, 4)
    lattice = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    flat = qhull_mesh(lattice)
    from skfem_nem.geometry.meshes import tetrahedron_neighbours
    assert not TetrahedraRecords(flat.p.T, flat.t.T, tetrahedron_neighbours(flat)).usable
    lat = Delaunay3D(lattice)
    assert TetrahedraRecords(lattice, lat.simplices, lat.neighbors).usable
    # the neighbours a basis passes in, from scikit-fem's facets, are the same
    from skfem_nem import delaunay_mesh
    mesh = delaunay_mesh(p)
    T, NB = mesh.t.T, tetrahedron_neighbours(mesh)
    for t in range(0, T.shape[0], 7):
        for k in range(4):
            face = set(T[t]) - {T[t, k]}
            if NB[t, k] >= 0:
                assert face <= set(T[NB[t, k]]) and NB[t, k] != t
    assert (NB < 0).sum() == mesh.boundary_facets().size
