"""NaturalNeighbourInterpolator and estimate_gradients: scipy's conventions, precision,
exact gradients, agreement with scipy, bad input."""
import math
import re

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
from scipy.spatial import Delaunay
from scipy.spatial.distance import pdist

from conftest import load_benchmark, load_example
from skfem_nem import NaturalNeighbourInterpolator, Triangulation, estimate_gradients
from skfem_nem.geometry.delaunay3d import Delaunay3D

METHODS_2D = ["sibson", "laplace", "sibson1", "farin", "linear", "nearest"]
METHODS_3D = ["sibson", "sibson1", "farin", "linear", "nearest"]
SMOOTH = ["sibson", "laplace", "sibson1", "farin", "linear"]       # linearly precise


def data(n=120, d=2, seed=0):
    """Random points in the unit square or cube with its corners (so that the hull is the
    square or the cube)."""
    rng = np.random.default_rng(seed)
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * d, indexing="ij")).reshape(d, -1).T
    return np.r_[corners, rng.random((n, d))]


def inside(m=200, d=2, seed=1, margin=0.05):
    return margin + (1 - 2 * margin) * np.random.default_rng(seed).random((m, d))


def linear(p, a=1.5, b=(2.0, -3.0, 0.5)):
    return a + p @ np.asarray(b[:p.shape[1]])


# --------------------------------------------------------------------------
# scipy's conventions
# --------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS_2D)
def test_shapes_and_trailing_dimensions(method):
    p = data()
    f = np.stack([linear(p), 2 * linear(p), -p[:, 0], p[:, 1]], axis=1).reshape(-1, 2, 2)
    itp = NaturalNeighbourInterpolator(p, f, method=method)
    q = inside(12).reshape(3, 4, 2)
    out = itp(q)
    assert out.shape == (3, 4, 2, 2)
    assert itp.gradient(q).shape == (3, 4, 2, 2, 2)
    # trailing dimensions are interpolated together, each as on its own
    for i in range(2):
        for j in range(2):
            one = NaturalNeighbourInterpolator(p, f[:, i, j], method=method)
            np.testing.assert_allclose(out[..., i, j], one(q), rtol=0, atol=1e-13)
    assert itp([0.5, 0.5]).shape == (2, 2)
    assert NaturalNeighbourInterpolator(p, f[:, 0, 0], method=method)([0.5, 0.5]).shape == ()


@pytest.mark.parametrize("method", ["sibson", "linear"])
def test_broadcasting_forms(method):
    p = data()
    itp = NaturalNeighbourInterpolator(p, np.sin(4 * p[:, 0]) * p[:, 1], method=method)
    x = np.linspace(0.1, 0.9, 5)
    y = np.linspace(0.2, 0.8, 3)
    X, Y = np.meshgrid(x, y)
    want = itp(np.stack([X, Y], axis=-1))
    assert want.shape == (3, 5)
    np.testing.assert_array_equal(itp(X, Y), want)
    np.testing.assert_array_equal(itp((X, Y)), want)
    np.testing.assert_array_equal(itp(x[None, :], y[:, None]), want)
    np.testing.assert_array_equal(itp.gradient(x[None, :], y[:, None]),
                                  itp.gradient(np.stack([X, Y], axis=-1)))
    assert itp(0.5, 0.5).shape == ()


@pytest.mark.parametrize("method", METHODS_2D)
def test_fill_value_outside_hull_points_on_hull_interpolate(method):
    p = data()
    f = linear(p)
    q = np.array([[-0.1, 0.5], [0.5, 1.0 + 1e-6], [2.0, 2.0], [0.3, 0.0], [1.0, 0.7],
                  [0.0, 0.0], [0.5, 0.5]])
    v = NaturalNeighbourInterpolator(p, f, method=method)(q)
    assert np.isnan(v[:3]).all()
    assert np.isfinite(v[3:]).all()
    if method != "nearest":
        np.testing.assert_allclose(v[3:], linear(q[3:]), atol=1e-12)
    w = NaturalNeighbourInterpolator(p, f, method=method, fill_value=-7)(q)
    np.testing.assert_array_equal(w[:3], -7.0)
    np.testing.assert_array_equal(w[3:], v[3:])
    g = NaturalNeighbourInterpolator(p, f, method=method).gradient(q)
    assert np.isnan(g[:3]).all() and np.isfinite(g[6]).all()


def test_points_outside_by_round_off_are_on_the_hull():
    p = data()
    itp = NaturalNeighbourInterpolator(p, linear(p))
    q = np.array([[0.4, -1e-14], [1 + 1e-13, 0.3], [0.4, -1e-6]])
    v = itp(q)
    np.testing.assert_allclose(v[:2], linear(np.clip(q[:2], 0, 1)), atol=1e-12)
    assert np.isnan(v[2])


@pytest.mark.parametrize("method", METHODS_2D)
def test_prebuilt_triangulations_2d(method):
    p = data()
    f = np.cos(3 * p[:, 0]) + p[:, 1] ** 2
    q = inside(50)
    want = NaturalNeighbourInterpolator(p, f, method=method)(q)
    tri = Triangulation(p)
    itp = NaturalNeighbourInterpolator(tri, f, method=method)
    assert itp.triangulation is tri
    np.testing.assert_allclose(itp(q), want, atol=1e-14)
    np.testing.assert_allclose(NaturalNeighbourInterpolator(Delaunay(p), f, method=method)(q),
                               want, atol=1e-14)


@pytest.mark.parametrize("method", METHODS_3D)
def test_prebuilt_delaunay_3d(method):
    p = data(150, d=3)
    f = np.cos(3 * p[:, 0]) + p[:, 1] * p[:, 2]
    q = inside(40, d=3)
    ref = NaturalNeighbourInterpolator(p, f, method=method)(q)
    own = Delaunay3D(p)
    itp = NaturalNeighbourInterpolator(own, f, method=method)
    assert itp.triangulation is own
    np.testing.assert_array_equal(itp(q), ref)
    # Qhull's: its flat tetrahedra on the cube's faces (four co-circular corners) add face
    # diagonals to the neighbours the C1 methods' gradients are fitted on; with the same
    # gradients, the same values
    tri = Delaunay(p)
    itp = NaturalNeighbourInterpolator(tri, f, method=method)
    assert itp.triangulation is tri
    g = estimate_gradients(p, f)
    kw = {"gradients": g} if method in ("sibson1", "farin") else {}
    np.testing.assert_allclose(NaturalNeighbourInterpolator(tri, f, method=method, **kw)(q),
                               NaturalNeighbourInterpolator(p, f, method=method, **kw)(q),
                               atol=1e-14)


def test_triangulation_changed_afterwards_is_an_error():
    p = data()
    tri = Triangulation(p)
    itp = NaturalNeighbourInterpolator(tri, linear(p))
    tri.insert([[0.51, 0.49]])
    with pytest.raises(ValueError, match="nodes now"):
        itp(inside(3))


@pytest.mark.parametrize("method", SMOOTH + ["nearest"])
def test_rescale(method):
    """Axes of very different extent: rescaled like scipy, the same interpolant as on the
    rescaled data; gradients in the original units."""
    p = data(150) * np.array([1.0, 1e4]) + np.array([5.0, -3e3])
    f = 1.0 + 2.0 * p[:, 0] + 3e-4 * p[:, 1]
    q = inside(60) * np.array([1.0, 1e4]) + np.array([5.0, -3e3])
    itp = NaturalNeighbourInterpolator(p, f, method=method, rescale=True)
    np.testing.assert_array_equal(itp.points, p)
    ref = (p - p.mean(0)) / np.ptp(p - p.mean(0), axis=0)
    qr = (q - p.mean(0)) / np.ptp(p - p.mean(0), axis=0)
    np.testing.assert_allclose(itp(q), NaturalNeighbourInterpolator(ref, f, method=method)(qr),
                               rtol=1e-12, atol=1e-9)
    if method != "nearest":
        np.testing.assert_allclose(itp(q), 1.0 + 2.0 * q[:, 0] + 3e-4 * q[:, 1], rtol=1e-11)
        np.testing.assert_allclose(itp.gradient(q), np.broadcast_to([2.0, 3e-4], q.shape),
                                   rtol=1e-8)
    if method == "linear":
        sc = LinearNDInterpolator(p, f, rescale=True)(q)
        np.testing.assert_allclose(itp(q), sc, rtol=1e-12)


def test_complex_values():
    p = data()
    f = linear(p) + 1j * np.sin(p[:, 0])
    q = np.r_[inside(20), [[3.0, 3.0]]]
    for method in METHODS_2D:
        itp = NaturalNeighbourInterpolator(p, f, method=method)
        v = itp(q)
        assert v.dtype == np.complex128 and np.isnan(v[-1])
        re = NaturalNeighbourInterpolator(p, f.real, method=method)(q[:-1])
        im = NaturalNeighbourInterpolator(p, f.imag, method=method)(q[:-1])
        np.testing.assert_allclose(v[:-1], re + 1j * im, atol=1e-13)


def test_chunks_give_the_same_result():
    p = data()
    f = np.exp(p[:, 0]) * p[:, 1]
    q = np.r_[inside(100), [[2.0, 0.5]], inside(30, seed=5)]
    for method in METHODS_2D:
        a = NaturalNeighbourInterpolator(p, f, method=method)
        b = NaturalNeighbourInterpolator(p, f, method=method, chunk=7)
        np.testing.assert_array_equal(a(q), b(q))
        np.testing.assert_array_equal(a.gradient(q), b.gradient(q))


def test_callers_arrays_are_not_modified():
    p = data()
    f = np.c_[linear(p), p[:, 0]]
    g = np.stack([np.broadcast_to([2.0, -3.0], p.shape), np.broadcast_to([1.0, 0.0], p.shape)],
                 axis=1)
    q = inside(20) * np.array([1.0, 1.1])
    copies = [a.copy() for a in (p, f, g, q)]
    itp = NaturalNeighbourInterpolator(p, f, method="sibson1", gradients=g, rescale=True)
    before = itp(q)
    itp.gradient(q)
    for a, b in zip((p, f, g, q), copies):
        np.testing.assert_array_equal(a, b)
    f[:] = 0.0                               # the interpolator holds its own copy
    np.testing.assert_array_equal(itp(q), before)


# --------------------------------------------------------------------------
# precision
# --------------------------------------------------------------------------

def drawn_points(rng, n, d, kind, scale, shift):
    """The point sets of the property tests: uniform, clustered (a cluster 1e-4 wide among
    unit-scale points) or a lattice, shifted and scaled."""
    if kind == "uniform":
        p = rng.random((n + d + 1, d))
    elif kind == "clustered":
        p = np.r_[rng.random((n, d)), 0.4 + 1e-4 * rng.random((n // 2 + d + 1, d))]
    else:
        k = 3 + n % 4
        p = np.array(np.meshgrid(*[np.arange(k)] * d)).reshape(d, -1).T / (k - 1)
    return (np.unique(p, axis=0) + shift) * scale


def roundoff_bound(p, f):
    """The round-off bound of linear precision on the point set p with values f: values at
    points h apart fix a slope only to eps |f| / h, and that slope is carried over the
    coordinates' magnitude |x| (the larger of the points' extent and distance from the
    origin), so errors scale as eps |f| |x| / h_min. The factor 100 is 10 times the largest
    measured over 1,500 draws of these point sets (sibson1 and farin on uniform 2D sets, whose
    nodal gradients come from fits over the closest pairs); on a uniform set it is about
    1e-12, on a cluster 1e-6 wide about 3e-8."""
    h = pdist(p)
    extent = max(h.max(), np.abs(p).max())
    return 100 * np.finfo(float).eps * np.abs(f).max() * extent / h.min()


def simplex_condition(p, simplices) -> float:
    """(longest edge)^d / (d! volume) of the thinnest simplex: the round-off of barycentric
    coordinates in it relative to eps. ``"linear"`` interpolates with them, so its error
    scales with this where the simplices are thinner than the closest pair is close (a draw
    of 7 points had a triangle of area 1.7e-4 with edges near 0.9: 2,400 against
    extent / h_min = 6.7, and an error of 1.2e-13, 900 eps |f|)."""
    P = p[simplices]
    d = p.shape[1]
    E = P[:, 1:] - P[:, :1]
    vol = np.abs(np.linalg.det(E)) / math.factorial(d)
    longest = np.max([np.linalg.norm(P[:, a] - P[:, b], axis=1)
                      for a in range(d + 1) for b in range(a + 1, d + 1)], axis=0)
    return float(np.max(longest ** d / (math.factorial(d) * vol)))


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(4, 80), st.sampled_from([2, 3]),
       st.sampled_from(["uniform", "clustered", "lattice"]),
       st.floats(1e-3, 1e3), st.integers(-100, 100).map(lambda k: k / 10))
@example(7484876, 4, 2, "clustered", 1.0, 0.0)     # 5 of 9 points within 1e-4: error 1.2e-10
def test_linear_precision(seed, n, d, kind, scale, shift):
    rng = np.random.default_rng(seed)
    p = drawn_points(rng, n, d, kind, scale, shift)
    b = rng.standard_normal(d)
    f = 0.7 + (p / scale - shift) @ b
    tri = Triangulation(p) if d == 2 else Delaunay(p)
    S = tri.triangles if d == 2 else tri.simplices
    t = rng.integers(0, S.shape[0], 30)
    q = np.einsum("mk,mkd->md", rng.dirichlet(np.ones(d + 1), 30), p[S[t]])
    exact = 0.7 + (q / scale - shift) @ b
    for method in (SMOOTH if d == 2 else METHODS_3D[:-1]):
        itp = NaturalNeighbourInterpolator(tri, f, method=method)
        bound = roundoff_bound(p, f)
        if method == "linear":
            bound = max(bound, 100 * np.finfo(float).eps * np.abs(f).max()
                        * simplex_condition(p, S))
        np.testing.assert_allclose(itp(q), exact, rtol=0, atol=bound, err_msg=method)
        g = itp.gradient(q) * scale
        ok = np.isfinite(g).all(axis=1)
        assert ok.mean() > 0.5
        # gradients: a looser bound (near a cluster the estimated nodal gradients of the C1
        # methods carry the round-off of a badly conditioned fit, up to ~1e-6 here)
        np.testing.assert_allclose(g[ok], np.broadcast_to(b, g[ok].shape), atol=1e-5,
                                   err_msg=method)


@pytest.mark.parametrize("d", [2, 3])
def test_sibson1_spherical_quadratic_precision(d):
    """With exact gradients Sibson's C1 interpolant reproduces a + b.x + c|x - x0|^2 (not a
    general quadratic: that needs Farin's)."""
    p = data(300, d=d, seed=3)
    rng = np.random.default_rng(4)
    b, c, x0 = rng.standard_normal(d), 0.8, rng.random(d)

    def f(x):
        return 1.0 + x @ b + c * ((x - x0) ** 2).sum(-1)

    grads = b + 2 * c * (p - x0)
    q = inside(200, d=d)
    itp = NaturalNeighbourInterpolator(p, f(p), method="sibson1", gradients=grads)
    np.testing.assert_allclose(itp(q), f(q), atol=1e-12)
    np.testing.assert_allclose(itp.gradient(q), b + 2 * c * (q - x0), atol=1e-10)
    # it interpolates the values and the gradients at the data points
    np.testing.assert_allclose(itp(p[20:30]), f(p[20:30]), atol=1e-14)
    np.testing.assert_allclose(itp.gradient(p[20:30]), grads[20:30], atol=1e-14)
    # a general quadratic is not reproduced (the reason Farin's interpolant exists)
    H = np.diag(np.arange(1.0, d + 1))
    g2 = NaturalNeighbourInterpolator(p, 0.5 * np.einsum("ni,ij,nj->n", p, H, p),
                                      method="sibson1", gradients=p @ H)
    assert np.abs(g2(q) - 0.5 * np.einsum("ni,ij,nj->n", q, H, q)).max() > 1e-6


@pytest.mark.parametrize("d", [2, 3])
def test_farin_quadratic_precision(d):
    """With exact gradients Farin's C1 interpolant reproduces every quadratic, and from
    estimated ones too (they are exact for quadratics)."""
    p = data(300, d=d, seed=13)
    rng = np.random.default_rng(14)
    b = rng.standard_normal(d)
    H = rng.standard_normal((d, d))
    H = H + H.T

    def f(x):
        return 1.0 + x @ b + 0.5 * np.einsum("...i,ij,...j->...", x, H, x)

    q = inside(200, d=d)
    itp = NaturalNeighbourInterpolator(p, f(p), method="farin", gradients=b + p @ H)
    np.testing.assert_allclose(itp(q), f(q), atol=1e-12)
    np.testing.assert_allclose(itp.gradient(q), b + q @ H, atol=1e-10)
    np.testing.assert_allclose(itp(p[20:30]), f(p[20:30]), atol=1e-14)
    np.testing.assert_allclose(itp.gradient(p[20:30]), b + p[20:30] @ H, atol=1e-14)
    est = NaturalNeighbourInterpolator(p, f(p), method="farin")
    np.testing.assert_allclose(est(q), f(q), atol=1e-9)


@pytest.mark.parametrize("d, method", [(2, "direct"), (3, "direct"), (2, "global")])
def test_estimated_gradients_exact_for_quadratics(d, method):
    p = data(200, d=d, seed=5)
    rng = np.random.default_rng(6)
    b = rng.standard_normal((d, 2))
    H = rng.standard_normal((2, d, d))
    H = H + np.swapaxes(H, 1, 2)
    f = 1 + p @ b + 0.5 * np.einsum("ni,kij,nj->nk", p, H, p)          # (n, 2)
    g = estimate_gradients(p, f, method=method)
    assert g.shape == (p.shape[0], 2, d)
    exact = b.T[None] + np.einsum("kij,nj->nki", H, p)
    np.testing.assert_allclose(g, exact, atol=1e-9)
    # from a prebuilt triangulation, the same
    tri = Triangulation(p) if d == 2 else Delaunay(p)
    np.testing.assert_allclose(estimate_gradients(tri, f, method=method), g, atol=1e-12)
    # a sibson1 interpolant from the estimated gradients: the same as given them
    q = inside(30, d=d)
    a = NaturalNeighbourInterpolator(p, f, method="sibson1")
    np.testing.assert_allclose(a.gradients, g, atol=1e-9)
    c = NaturalNeighbourInterpolator(p, f, method="sibson1", gradients=exact)
    np.testing.assert_allclose(a(q), c(q), atol=1e-8)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(4, 80), st.sampled_from([2, 3]),
       st.sampled_from(["uniform", "clustered", "lattice"]),
       st.floats(1e-3, 1e3), st.integers(-100, 100).map(lambda k: k / 10))
def test_estimated_gradients_exact_for_linear_data(seed, n, d, kind, scale, shift):
    """Every gradient estimate returns the gradient of linear data, on random, clustered
    (a cluster 1e-4 wide among unit-scale points) and lattice point sets at any scale."""
    rng = np.random.default_rng(seed)
    p = drawn_points(rng, n, d, kind, scale, shift)
    b = rng.standard_normal((d, 2))
    f = 0.7 + (p / scale - shift) @ b                                   # (n, 2)
    before = f.copy()
    for method in ("direct", "global") if d == 2 else ("direct",):
        g = estimate_gradients(p, f, method=method) * scale
        np.testing.assert_allclose(g, np.broadcast_to(b.T, g.shape), atol=1e-6, err_msg=method)
    np.testing.assert_array_equal(f, before)


def test_default_gradient_estimate():
    """The C1 methods estimate their gradients by "global" in 2D and by "direct" in 3D, as
    estimate_gradients does by default; complex values as their two parts."""
    for d, method in ((2, "global"), (3, "direct")):
        p = data(80, d=d, seed=13)
        f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1])
        g = estimate_gradients(p, f, method=method)
        np.testing.assert_allclose(estimate_gradients(p, f), g, atol=1e-14)
        for m in ("sibson1", "farin"):
            np.testing.assert_allclose(NaturalNeighbourInterpolator(p, f, method=m).gradients,
                                       g, atol=1e-14)
    assert np.abs(g - estimate_gradients(p, f, method="direct")).max() == 0.0
    p = data(80, seed=13)
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1])
    assert np.abs(estimate_gradients(p, f, method="direct") - estimate_gradients(p, f)).max() \
        > 1e-3
    z = estimate_gradients(p, f + 1j * p[:, 1] ** 2, method="global")
    np.testing.assert_allclose(z.real, estimate_gradients(p, f, method="global"), atol=1e-12)
    np.testing.assert_allclose(z.imag, estimate_gradients(p, p[:, 1] ** 2), atol=1e-9)


@pytest.mark.parametrize("method", ["direct", "global"])
def test_estimated_gradients_second_order_accurate(method):
    """O(h^2) inside (measured: a factor 3.7 per 4x points); near the hull of these sets
    (only the corners on the sides) Delaunay neighbours reach far along the sides."""
    errors = []
    for n in (400, 1600):
        p = data(n, seed=7)
        g = estimate_gradients(p, np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]), method=method)
        exact = np.c_[3 * np.cos(3 * p[:, 0]) * np.cos(2 * p[:, 1]),
                      -2 * np.sin(3 * p[:, 0]) * np.sin(2 * p[:, 1])]
        inner = np.all((p > 0.1) & (p < 0.9), axis=1)
        errors.append(np.sqrt(np.mean((g - exact)[inner] ** 2)))
    assert errors[1] < errors[0] / 3.0               # O(h^2): a factor 4 per 4x points


@pytest.mark.parametrize("d, method", [(2, m) for m in SMOOTH] + [(3, m) for m in METHODS_3D[:4]])
def test_gradient_against_finite_differences(d, method):
    p = data(150, d=d, seed=8)
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + p[:, -1] ** 2
    itp = NaturalNeighbourInterpolator(p, f, method=method)
    q = inside(60, d=d, seed=9)
    h = 1e-6
    fd = np.stack([(itp(q + h * e) - itp(q - h * e)) / (2 * h) for e in np.eye(d)], axis=-1)
    g = itp.gradient(q)
    # linear: a difference straddling a simplex face is not a derivative
    err = np.abs(g - fd).max(axis=1)
    assert np.median(err) < 1e-8 and np.mean(err < 1e-6) > (0.9 if method == "linear" else 0.97)


def test_gradient_undefined_at_data_points():
    p = data()
    f = np.sin(3 * p[:, 0])
    for method, defined in [("sibson", False), ("laplace", False), ("sibson1", True),
                            ("farin", True), ("linear", True), ("nearest", True)]:
        g = NaturalNeighbourInterpolator(p, f, method=method).gradient(p[10:13])
        assert np.isfinite(g).all() == defined, method


def test_linear_agrees_with_scipy():
    for d, n in ((2, 400), (3, 300)):
        p = np.random.default_rng(10 + d).random((n, d))
        f = np.stack([np.sin(5 * p[:, 0]), p[:, 1] * p[:, -1]], axis=1)
        q = np.random.default_rng(20 + d).random((500, d)) * 1.2 - 0.1
        ours = NaturalNeighbourInterpolator(p, f, method="linear")(q)
        theirs = LinearNDInterpolator(p, f)(q)
        np.testing.assert_array_equal(np.isnan(ours), np.isnan(theirs))
        assert np.isfinite(ours).sum() > 100
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12, equal_nan=True)


def test_nearest_agrees_with_scipy_inside():
    p = np.random.default_rng(11).random((300, 2))
    f = np.arange(300.0)
    q = inside(400, seed=12, margin=0.1)
    np.testing.assert_array_equal(NaturalNeighbourInterpolator(p, f, method="nearest")(q),
                                  NearestNDInterpolator(p, f)(q))


# --------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------

def test_input_errors():
    p = data()
    f = linear(p)
    NNI = NaturalNeighbourInterpolator
    with pytest.raises(ValueError, match=r"'sibson', 'laplace', 'sibson1', 'farin', 'linear', "
                                         r"'nearest'.*'cubic'"):
        NNI(p, f, method="cubic")
    with pytest.raises(ValueError, match=r"points must have shape \(n, 2\) or \(n, 3\)"):
        NNI(p[:, :1], f)
    bad = p.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"points\[7\]"):
        NNI(bad, f)
    with pytest.raises(ValueError, match=r"duplicate"):
        NNI(np.r_[p, p[:1]], np.r_[f, f[:1]])
    with pytest.raises(ValueError, match=r"values must have shape \(n, \.\.\.\).*n = 124"):
        NNI(p, f[:-1])
    with pytest.raises(ValueError, match="values must be numbers"):
        NNI(p, np.array(["a"] * p.shape[0]))
    with pytest.raises(ValueError, match="'laplace' works in 2D only"):
        NNI(data(d=3), linear(data(d=3)), method="laplace")
    with pytest.raises(ValueError, match="gradients are used by"):
        NNI(p, f, method="sibson", gradients=np.zeros((p.shape[0], 2)))
    with pytest.raises(ValueError, match=r"gradients must have shape .*\(124, 2\)"):
        NNI(p, f, method="sibson1", gradients=np.zeros((p.shape[0], 3)))
    with pytest.raises(ValueError, match="rescale=True is not supported"):
        NNI(Triangulation(p), f, rescale=True)
    with pytest.raises(ValueError, match="fill_value must be a number"):
        NNI(p, f, fill_value="none")
    with pytest.raises(TypeError, match="tol"):
        NNI(p, f, tol=1e-6)                    # CloughTocher2DInterpolator's option
    with pytest.raises(ValueError, match="chunk"):
        NNI(p, f, chunk=0)
    with pytest.raises(ValueError, match=r"method must be one of 'direct', 'global'.*"
                                         r"'iterative'"):
        estimate_gradients(p, f, method="iterative")
    with pytest.raises(ValueError, match=r"'global' works in 2D only, the points are 3D"):
        estimate_gradients(data(d=3), linear(data(d=3)), method="global")


def test_query_errors():
    p = data()
    itp = NaturalNeighbourInterpolator(p, linear(p))
    with pytest.raises(ValueError, match=r"xi must have shape \(\.\.\., 2\)"):
        itp(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="got 3 arguments"):
        itp(0.1, 0.2, 0.3)
    q = inside(5)
    q[3, 0] = np.inf
    with pytest.raises(ValueError, match=r"1 query point\(s\) have non-finite.*xi\[\(3,\)\]"):
        itp(q)
    with pytest.raises(ValueError, match="real numbers"):
        itp(q.astype(complex))


# --------------------------------------------------------------------------
# the benchmark runs
# --------------------------------------------------------------------------

def test_benchmark_smoke(capsys):
    bench = load_benchmark("interpolation")
    bench.main(["--points", "2000", "--grid", "60", "--points-3d", "600", "--queries-3d", "500",
                "--repeats", "1", "--no-metpy", "--franke-points", "random"])
    out = capsys.readouterr().out
    assert "| sibson |" in out and "| farin |" in out and "LinearNDInterpolator" in out
    assert "3D" in out
    assert "100 uniform random points (seed 0)" in out and "| scipy CloughTocher2D |" in out


def test_franke_c1_against_clough_tocher():
    """The benchmark's Franke table (Franke's 100 points, 33 x 33 grid, inside the hull): with
    their default ("global") gradients both C1 interpolants beat Clough-Tocher's max error on
    all six functions and its mean error on all but F2 (the cliff); from Clough-Tocher's own
    gradients Sibson's C1 interpolant beats its max error on all six, and from exact gradients
    Farin's beats its mean error on all six, by 1.7 to 4.6 times."""
    bench = load_benchmark("interpolation")
    p = bench.franke_points()
    assert p.shape == (100, 2) and p.min() < 0 and p.max() > 1   # the hull sticks out a little
    for k in range(1, 7):
        err, inside = bench.franke_errors(p, k)
        assert inside == 1076
        ct_max, ct_mean = err["scipy CloughTocher2D"]
        np.testing.assert_allclose(err["linear"], err["scipy LinearND"], rtol=1e-9)
        assert err["sibson1, Clough-Tocher's gradients"][0] < ct_max, k
        assert err["farin, exact gradients"][1] < 0.6 * ct_mean, k
        for m in ("sibson1", "farin"):
            assert err[m][1] < 0.6 * err["sibson"][1], (k, m)   # far ahead of the C0 ones
            assert err[m][0] < ct_max, (k, m)
            if k != 2:
                assert err[m][1] < ct_mean, (k, m)
                # the global estimate ahead of the direct one
                assert err[m][1] < err[f"{m}, direct gradients"][1], (k, m)
    assert err["farin"][1] < 0.5 * ct_mean                             # F6


def test_metpy_comparison():
    """Where MetPy is installed: its natural_neighbor_to_grid and ours give the same values to
    1e-10 and NaN at the same grid points; on a grid through lattice data ours has no NaN."""
    pytest.importorskip("metpy")
    bench = load_benchmark("interpolation")
    out = "\n".join(bench.compare_metpy(150, 7))
    assert "same values to 1e-10: yes" in out and "NaN at different grid points: 0;" in out
    line, = bench.metpy_through_data(4, 7)
    assert line.endswith("ours gives NaN at 0")
    agree = float(re.search(r"agrees to (\S+) at the others", line).group(1))
    assert agree <= bench.METPY_AGREEMENT


# --------------------------------------------------------------------------
# the gallery example
# --------------------------------------------------------------------------

def test_ex24_scattered_interpolation(tmp_path):
    ex = load_example("ex24_scattered_interpolation")
    # the C1 interpolants are the accurate ones (measured rms 5.4e-4 and 5.6e-4), the C0 ones
    # and the linear one comparable with each other (3.9e-3 to 4.2e-3)
    assert ex.rms["sibson1"] < 7e-4 and ex.rms["sibson1"] < 1.1 * ex.rms["Clough-Tocher (scipy)"]
    assert ex.rms["farin"] < 7e-4
    for name in ("sibson", "laplace", "linear"):
        assert 2e-3 < ex.rms[name] < 6e-3
    assert ex.grad_rms["sibson1"] < 0.3 * ex.grad_rms["linear"]       # 0.041 vs 0.23
    fig = ex.visualize(tmp_path / "ex24.png")
    assert (tmp_path / "ex24.png").exists()
    panels = fig.axes[1:7]
    for a, name in zip(panels, ex.fields):
        (img,) = a.get_images()
        np.testing.assert_allclose(img.get_array(), ex.fields[name] - ex.exact)
        assert name in a.get_title() and f"{ex.rms[name]:.1e}" in a.get_title()


def test_3d_gradients_next_to_the_hull_are_nan():
    """Within 1e-6 (of the diagonal) of the hull the 3D coordinates' gradients lose their
    accuracy (errors of order one at 1e-10): NaN there, exact farther in."""
    p = data(200, d=3, seed=15)
    b = np.array([1.0, -2.0, 0.5])
    q = np.array([[0.3, 0.6, 1e-9], [0.3, 0.6, 1e-4], [0.4, 1 - 1e-8, 0.5]])
    for method in ("sibson", "sibson1", "farin"):
        g = NaturalNeighbourInterpolator(p, p @ b, method=method).gradient(q)
        assert np.isnan(g[[0, 2]]).all() and np.isfinite(g[1]).all(), method
        np.testing.assert_allclose(g[1], b, atol=1e-8)
    g = NaturalNeighbourInterpolator(p, p @ b, method="linear").gradient(q)
    np.testing.assert_allclose(g, np.broadcast_to(b, g.shape), atol=1e-12)


@pytest.mark.parametrize("method", ["sibson", "farin", "linear"])
def test_rescale_3d(method):
    p = data(120, d=3, seed=16) * np.array([1.0, 1e3, 1e-3])
    b = np.array([2.0, -1e-3, 4e2])
    q = inside(40, d=3) * np.array([1.0, 1e3, 1e-3])
    itp = NaturalNeighbourInterpolator(p, 1.0 + p @ b, method=method, rescale=True)
    np.testing.assert_allclose(itp(q), 1.0 + q @ b, rtol=1e-11)
    np.testing.assert_allclose(itp.gradient(q), np.broadcast_to(b, q.shape), rtol=1e-7)


@pytest.mark.parametrize("method", METHODS_3D)
def test_fill_value_and_hull_3d(method):
    p = data(150, d=3, seed=17)
    f = linear(p)
    q = np.array([[0.3, 0.6, 0.0], [1.0, 0.2, 0.7], [0.5, 1.0, 1.0], [1.0, 1.0, 1.0],
                  [0.4, 0.5, 0.5], [0.3, 0.6, -1e-7], [1.2, 0.5, 0.5]])
    v = NaturalNeighbourInterpolator(p, f, method=method, fill_value=-1.0)(q)
    np.testing.assert_array_equal(v[5:], -1.0)
    if method != "nearest":
        np.testing.assert_allclose(v[:5], linear(q[:5]), atol=1e-12)
    g = NaturalNeighbourInterpolator(p, f, method=method).gradient(q)
    assert np.isnan(g[5:]).all() and np.isfinite(g[4]).all()


def test_c1_at_the_data_points():
    """Around a data point the gradients of the C1 interpolants tend to the data's gradient
    from every direction (like r); Sibson's C0-at-the-nodes interpolant keeps its kink."""
    p = data(300, seed=18)
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1])
    i = int(np.argmin(((p - 0.5) ** 2).sum(axis=1)))
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = np.c_[np.cos(ang), np.sin(ang)]
    for method in ("sibson1", "farin"):
        itp = NaturalNeighbourInterpolator(p, f, method=method)
        spread = [np.abs(itp.gradient(p[i] + r * ring) - itp.gradients[i]).max()
                  for r in (1e-3, 1e-5)]
        assert spread[1] < 1e-3 and spread[1] < spread[0] / 30, (method, spread)
    g = NaturalNeighbourInterpolator(p, f).gradient(p[i] + 1e-5 * ring)
    assert np.ptp(g, axis=0).max() > 0.05


def test_natural_neighbour_to_grid_as_metpy_calls_it():
    """MetPy's signature: 1D data arrays and a meshgrid; the interpolator's values on the
    grid, NaN outside the hull, and shapes checked by name."""
    from skfem_nem import natural_neighbour_to_grid
    rng = np.random.default_rng(3)
    xp, yp = rng.random(200), rng.random(200)
    z = np.sin(3 * xp) * yp
    gx, gy = np.meshgrid(np.linspace(-0.1, 1.1, 25), np.linspace(-0.1, 1.1, 19))
    g = natural_neighbour_to_grid(xp, yp, z, gx, gy)
    assert g.shape == gx.shape
    ref = NaturalNeighbourInterpolator(np.c_[xp, yp], z)(np.stack([gx, gy], axis=-1))
    np.testing.assert_array_equal(np.isnan(g), np.isnan(ref))
    np.testing.assert_allclose(g[~np.isnan(g)], ref[~np.isnan(ref)], rtol=0, atol=1e-14)
    assert np.isnan(g[0, 0]) and not np.isnan(g[9, 12])
    lin = natural_neighbour_to_grid(xp, yp, 2 * xp - yp, gx, gy, method="linear")
    inside = ~np.isnan(lin)
    np.testing.assert_allclose(lin[inside], (2 * gx - gy)[inside], atol=1e-12)
    with pytest.raises(ValueError, match="xp, yp and variable"):
        natural_neighbour_to_grid(xp, yp[:-1], z, gx, gy)
    with pytest.raises(ValueError, match="grid_x and grid_y"):
        natural_neighbour_to_grid(xp, yp, z, gx, gy[:-1])


@pytest.mark.parametrize("method", ["sibson", "sibson1", "farin"])
def test_c1_across_delaunay_edges(method):
    """Across interior Delaunay edges (where the triangles whose circumcircles hold a point
    change) the gradient of every C1 interpolant is continuous: its jump between the points
    at distance r on either side of an edge's midpoint vanishes like r."""
    p = data(200, seed=21)
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + p[:, 0] * p[:, 1] ** 2
    tri = Delaunay(p)
    edges = {tuple(sorted((int(s[i]), int(s[(i + 1) % 3])))) for s in tri.simplices
             for i in range(3)}
    mid = np.array([(p[a] + p[b]) / 2 for a, b in sorted(edges)])
    keep = (np.abs(mid - 0.5) < 0.35).all(axis=1)
    mid = mid[keep][:40]
    ab = np.array([p[b] - p[a] for a, b in sorted(edges)])[keep][:40]
    n = np.c_[-ab[:, 1], ab[:, 0]] / np.linalg.norm(ab, axis=1)[:, None]
    itp = NaturalNeighbourInterpolator(p, f, method=method)
    jumps = [np.abs(itp.gradient(mid + r * n) - itp.gradient(mid - r * n)).max()
             for r in (1e-4, 1e-6)]
    assert jumps[1] < 1e-3 and jumps[1] < jumps[0] / 30, jumps
