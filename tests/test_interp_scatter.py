"""Sibson's values by the scatter over the Delaunay triangles (interp_scatter): equal to the
area method's (the coordinates times the values) on random, clustered and lattice data, with
queries on edges, at data points and on the hull; the flagged queries; the layouts of the
queries; the wiring into NaturalNeighbourInterpolator."""
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from skfem_nem import (NaturalNeighbourInterpolator, Triangulation, natural_neighbour_to_grid,
                       sibson_coordinates)
from skfem_nem.coordinates import interp_natural
from skfem_nem.coordinates.interp_hull import HullTest
from skfem_nem.coordinates.interp_scatter import SibsonScatter, scatter_applies
from skfem_nem.coordinates.interp_scatter_layout import query_layout

TOL = 1e-12


def square(n, seed, sides=True):
    """n random points in the unit square, its corners and (``sides``) points on its sides."""
    rng = np.random.default_rng(seed)
    s = rng.random((4, 6))
    p = [[[0, 0], [1, 0], [0, 1], [1, 1]], rng.random((n, 2))]
    if sides:
        p += [np.c_[s[0], 0 * s[0]], np.c_[s[1], 1 + 0 * s[1]], np.c_[0 * s[2], s[2]],
              np.c_[1 + 0 * s[3], s[3]]]
    return np.concatenate(p).astype(float)


def reference(tri, q, f):
    """The area method's values: the Sibson coordinates times the data."""
    return sibson_coordinates(tri, q) @ f


def scattered(tri, q, f):
    """The scatter's values, its flagged queries recomputed as the interpolator does."""
    F = np.asarray(f).reshape(len(f), -1)
    v, bad = SibsonScatter(tri, F)(q)
    assert np.isnan(v[bad]).all() and np.isfinite(np.delete(v, bad, axis=0)).all()
    v[bad] = reference(tri, q[bad], F)
    return v.reshape((len(q),) + np.shape(f)[1:]), bad


def exact_sibson(p, triangles, x, f):
    """Sibson's interpolant at x (2,) in rational arithmetic, by the decomposition the
    scatter uses (its terms for the triangles whose circumcircle strictly holds x)."""
    P = [(Fraction(a), Fraction(b)) for a, b in p]
    X = (Fraction(x[0]), Fraction(x[1]))
    num, den = [Fraction(0)] * f.shape[1], Fraction(0)
    for t in triangles:
        (ax, ay), (bx, by), (cx, cy) = ((u - X[0], w - X[1]) for u, w in (P[i] for i in t))
        S = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
        # the lifted in-circle determinant is S * (R^2 - |x - o|^2)
        D = (a2 * (bx * cy - by * cx) + b2 * (cx * ay - cy * ax) + c2 * (ax * by - ay * bx)) / S
        if D <= 0:
            continue
        eab, ebc, eca = ax * by - ay * bx, bx * cy - by * cx, cx * ay - cy * ax
        for i, w in zip(t, (S * D * D / (eab * eca), S * D * D / (ebc * eab),
                            S * D * D / (eca * ebc))):
            den += w
            num = [nk + w * Fraction(float(fk)) for nk, fk in zip(num, f[i])]
    return np.array([float(nk / den) for nk in num])


def close(a, b, scale=1.0):
    np.testing.assert_allclose(a, b, rtol=0, atol=TOL * scale)


@pytest.fixture
def scatter_always(monkeypatch):
    """Every Sibson value call of the interpolator by the scatter."""
    monkeypatch.setattr(interp_natural, "SCATTER_MIN", 1)
    monkeypatch.setattr(interp_natural, "SCATTER_PER_TRIANGLE", 0.0)


@pytest.fixture
def scatter_never(monkeypatch):
    monkeypatch.setattr(interp_natural, "SCATTER_MIN", 1 << 62)


# --------------------------------------------------------------------------
# the values against the area method
# --------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(3))
def test_random_queries_match_the_area_method(seed):
    p = square(400, seed)
    tri = Triangulation(p)
    f = np.c_[np.sin(5 * p[:, 0]) * p[:, 1], 1 + p[:, 0] ** 2 - p[:, 1]]
    q = np.random.default_rng(seed + 10).random((5000, 2))
    v, bad = SibsonScatter(tri, f)(q)
    ok = np.setdiff1d(np.arange(len(q)), bad)
    close(v[ok], reference(tri, q[ok], f))
    assert bad.size < 0.01 * len(q)


def test_linear_precision_and_partition_of_unity():
    p = square(300, 4)
    tri = Triangulation(p)
    f = np.c_[np.ones(len(p)), p, 3 - 2 * p[:, 0] + 5 * p[:, 1]]
    q = np.random.default_rng(0).random((4000, 2))
    v, _ = scattered(tri, q, f)
    close(v, np.c_[np.ones(len(q)), q, 3 - 2 * q[:, 0] + 5 * q[:, 1]], 10)


def test_queries_on_edges_at_nodes_and_on_the_hull():
    """Queries on Delaunay edges (the terms' divisors vanish), near them, at the data points
    and on the hull are flagged or accurate, and end equal to the area method's."""
    p = square(200, 5)
    tri = Triangulation(p)
    f = np.cos(3 * p[:, 0]) + p[:, 1] ** 3
    E = tri.edges
    t = np.random.default_rng(1).random((len(E), 1))
    on = p[E[:, 0]] * t + p[E[:, 1]] * (1 - t)
    normal = (p[E[:, 1]] - p[E[:, 0]])[:, ::-1] * [1, -1]
    near = np.concatenate([on + d * normal for d in (1e-15, 1e-12, 1e-9, 1e-6, 1e-3)])
    q = np.concatenate([on, p, near[HullTest(p).distance(near) <= 0]])
    v, bad = scattered(tri, q, f)
    close(v, reference(tri, q, f))
    assert np.isin(np.arange(len(on)), bad).all()                   # on an edge: flagged
    assert np.isin(np.arange(len(on), len(on) + len(p)), bad).all()  # at a node


def test_lattice_data_and_grid_queries():
    """Co-circular data (a lattice: each square's diagonal either way) and a grid of queries
    many of which lie on its lines and at its points."""
    i, j = np.meshgrid(np.arange(12.0), np.arange(9.0))
    p = np.c_[i.ravel(), j.ravel()] * 0.5 + 3.0
    tri = Triangulation(p)
    f = np.sin(p[:, 0]) * p[:, 1]
    x, y = np.meshgrid(np.linspace(3, 8.5, 111), np.linspace(3, 7, 81))
    q = np.c_[x.ravel(), y.ravel()]
    v, bad = scattered(tri, q, f)
    close(v, reference(tri, q, f), 10)
    assert bad.size > 0


def test_cocircular_points():
    """Points on one circle (and its centre): every triangle has the same circumcircle."""
    a = np.linspace(0, 2 * np.pi, 17)[:-1]
    p = np.r_[np.c_[np.cos(a), np.sin(a)], [[0.0, 0.0]], np.c_[2 * np.cos(a), 2 * np.sin(a)]]
    tri = Triangulation(p)
    f = p[:, 0] ** 2 - p[:, 1]
    q = 1.8 * (np.random.default_rng(3).random((3000, 2)) - 0.5)
    v, _ = scattered(tri, q, f)
    close(v, reference(tri, q, f), 10)


def test_far_from_the_origin_and_tiny():
    """The terms are computed relative to the query: data far from the origin, or at a
    tiny scale, interpolate as well."""
    base = square(200, 6)
    q0 = np.random.default_rng(2).random((3000, 2))
    for shift, scale in ((1e6, 1.0), (0.0, 1e-9), (-3e3, 1e4)):
        p, q = shift + scale * base, shift + scale * q0
        tri = Triangulation(p)
        f = np.sin(4 * base[:, 0]) + base[:, 1]
        v, _ = scattered(tri, q, f)
        close(v, reference(tri, q, f), 1e2)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(3, 60),
       st.sampled_from(["uniform", "clustered", "lattice", "line"]))
def test_property_any_point_set(seed, n, kind):
    rng = np.random.default_rng(seed)
    if kind == "uniform":
        p = rng.random((n, 2))
    elif kind == "clustered":
        p = np.r_[rng.random((3, 2)), 0.5 + 1e-4 * rng.random((n, 2))]
    elif kind == "lattice":
        p = np.unique(rng.integers(0, 6, (n + 3, 2)), axis=0).astype(float)
    else:   # nearly collinear points and a few off the line
        t = rng.random(n)
        p = np.r_[np.c_[t, 0.3 * t + 1e-6 * rng.random(n)], rng.random((3, 2))]
    try:
        tri = Triangulation(p)
    except ValueError:
        assume(False)
    lo, hi = p.min(axis=0), p.max(axis=0)
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], 23), np.linspace(lo[1], hi[1], 19))
    q = np.r_[np.c_[x.ravel(), y.ravel()], lo + (hi - lo) * rng.random((400, 2)), p]
    q = q[HullTest(p).distance(q) <= 0]
    assume(len(q))
    f = np.c_[np.cos(2 * p[:, 0]) * p[:, 1], p[:, 0] - 2 * p[:, 1]]
    v, _ = scattered(tri, q, f)
    ref = reference(tri, q, f)
    tol = 10 * TOL * max(1.0, np.abs(p).max())
    # where the two differ (the area method loses digits on slivers: clustered data), the
    # scatter's value is the exact one
    differ = np.flatnonzero(np.abs(v - ref).max(axis=1) > tol)
    assert differ.size <= 0.05 * len(q)
    for i in differ[:4]:
        close(v[i], exact_sibson(p, tri.triangles, q[i], f), tol / TOL)


# --------------------------------------------------------------------------
# the layouts and the scope
# --------------------------------------------------------------------------

def test_a_regular_grid_is_its_own_bucket_grid_and_any_order_gives_the_same():
    p = square(300, 7)
    tri = Triangulation(p)
    f = np.exp(p[:, 0]) * p[:, 1]
    x, y = np.meshgrid(np.linspace(0, 1, 67), np.linspace(0, 1, 45))
    q = np.c_[x.ravel(), y.ravel()]
    assert query_layout(q)[2].size == 0                 # not sorted: a grid
    perm = np.random.default_rng(0).permutation(len(q))
    assert query_layout(q[perm])[2].size == len(q)      # sorted into buckets
    S = SibsonScatter(tri, f[:, None])
    a, bad_a = S(q)
    b, bad_b = S(q[perm])
    np.testing.assert_array_equal(np.sort(perm[bad_b]), bad_a)
    close(a[perm], b)
    # a grid with one row or one column, and one point
    for qq in (q[:67], q[::67], q[:1]):
        v, bad = scattered(tri, qq, f[:, None])
        close(v, reference(tri, qq, f[:, None]))


def test_scope():
    """Unconstrained Delaunay triangulations only."""
    p = square(50, 8)
    assert scatter_applies(Triangulation(p))
    assert not scatter_applies(Triangulation(p, segments=[[0, 3]]))
    kite = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 0.2], [0.0, -0.2]])
    long_diagonal = Triangulation.from_triangles(kite, [[0, 1, 2], [1, 0, 3]],
                                                 make_delaunay=False)
    assert not long_diagonal.is_delaunay() and not scatter_applies(long_diagonal)
    assert scatter_applies(Triangulation.from_triangles(kite, [[0, 1, 2], [1, 0, 3]]))


def test_no_queries_and_no_values():
    p = square(30, 13)
    tri = Triangulation(p)
    v, bad = SibsonScatter(tri, np.ones((len(p), 2)))(np.empty((0, 2)))
    assert v.shape == (0, 2) and bad.size == 0
    v, bad = SibsonScatter(tri, np.ones((len(p), 0)))(np.full((5, 2), 0.5))
    assert v.shape == (5, 0) and bad.size == 0


# --------------------------------------------------------------------------
# the interpolator
# --------------------------------------------------------------------------

def test_interpolator_uses_the_scatter_on_large_batches():
    p = square(3000, 9)
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1])
    itp = NaturalNeighbourInterpolator(p, f)
    x, y = np.meshgrid(np.linspace(-0.1, 1.1, 250), np.linspace(-0.1, 1.1, 240))
    v = itp(x, y)
    assert itp._evaluate.scatter                     # built and used: 60 000 queries
    ref = NaturalNeighbourInterpolator(p, f)
    small = [ref(x[i:i + 20], y[i:i + 20]) for i in range(0, 240, 20)]    # gathered
    assert ref._evaluate.scatter is None
    np.testing.assert_allclose(v, np.concatenate(small), rtol=0, atol=TOL, equal_nan=True)
    assert np.isnan(v[0, 0]) and np.isfinite(v[125, 125])
    g = natural_neighbour_to_grid(p[:, 0], p[:, 1], f, x, y)
    np.testing.assert_allclose(g, v, rtol=0, atol=TOL, equal_nan=True)


@pytest.mark.usefixtures("scatter_always")
@pytest.mark.parametrize("rescale", [False, True])
def test_interpolator_trailing_dimensions_complex_fill_and_rescale(rescale, monkeypatch):
    p = square(200, 10) * [1.0, 1e-3]
    f = np.stack([np.sin(4 * p[:, 0]) + 1j * p[:, 1] * 1e3, p[:, 0] - 2j * p[:, 0] ** 2],
                 axis=1).reshape(-1, 1, 2) * np.array([1.0, -3.0]).reshape(1, 2, 1)
    q = np.random.default_rng(4).random((3000, 2)) * [1.2, 1.2e-3] - [0.1, 0.1e-3]
    out = NaturalNeighbourInterpolator(p, f, rescale=rescale, fill_value=-7.0)(q)
    assert out.shape == (3000, 2, 2) and out.dtype == complex
    monkeypatch.setattr(interp_natural, "SCATTER_MIN", 1 << 62)
    ref = NaturalNeighbourInterpolator(p, f, rescale=rescale, fill_value=-7.0)(q)
    np.testing.assert_allclose(out, ref, rtol=0, atol=TOL * 10)
    assert (out == -7.0).any()


@pytest.mark.usefixtures("scatter_always")
def test_gradients_laplace_and_constrained_stay_on_the_gather_path():
    p = square(100, 11)
    f = p[:, 0] * p[:, 1]
    q = np.random.default_rng(5).random((500, 2)) * 0.9 + 0.05
    itp = NaturalNeighbourInterpolator(p, f)
    g = itp.gradient(q)
    assert itp._evaluate.scatter is None and g.shape == (500, 2)
    lap = NaturalNeighbourInterpolator(p, f, method="laplace")
    lap(q)
    assert lap._evaluate.scatter is None
    tri = Triangulation(p, segments=[[0, 3]])
    con = NaturalNeighbourInterpolator(tri, f)
    v = con(q)
    assert con._evaluate.scatter is False
    np.testing.assert_allclose(v, sibson_coordinates(tri, q) @ f, rtol=0, atol=TOL)


@pytest.mark.usefixtures("scatter_always")
def test_chunks():
    """Chunks of the scatter hold up to ~128 MB of work space, more than ``chunk``; the
    gather path keeps to ``chunk``."""
    p = square(300, 12)
    f = np.cos(p[:, 0] + p[:, 1])
    q = np.random.default_rng(6).random((2000, 2))
    a = NaturalNeighbourInterpolator(p, f, chunk=7)(q)
    itp = NaturalNeighbourInterpolator(p, f, chunk=7)
    assert itp._evaluate.chunk_size(2000) > 2000
    np.testing.assert_allclose(a, sibson_coordinates(Triangulation(p), q) @ f, rtol=0,
                               atol=TOL)
