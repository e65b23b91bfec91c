"""Tests of the robust predicates against an exact rational oracle."""
import math
import sys
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from skfem_nem.geometry import expansions as E
from skfem_nem.geometry import predicates as P
from skfem_nem.geometry.predicates import (
    INCIRCLE_REL_ERROR,
    ORIENT2D_REL_ERROR,
    incircle,
    incircle_sign,
    orient2d,
    orient2d_sign,
)

EPS = 2.0 ** -53
DBL_MAX = sys.float_info.max
SETTINGS = settings(max_examples=300, deadline=None)
FEWER = settings(max_examples=150, deadline=None)


# -- exact oracle --------------------------------------------------------------

def exact_orient(ax, ay, bx, by, cx, cy):
    ax, ay, bx, by, cx, cy = map(Fraction, (ax, ay, bx, by, cx, cy))
    return (ax - cx) * (by - cy) - (ay - cy) * (bx - cx)


def exact_incircle(ax, ay, bx, by, cx, cy, dx, dy):
    ax, ay, bx, by, cx, cy, dx, dy = map(Fraction, (ax, ay, bx, by, cx, cy, dx, dy))
    adx, ady, bdx, bdy, cdx, cdy = ax - dx, ay - dy, bx - dx, by - dy, cx - dx, cy - dy
    return ((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
            + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
            + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))


def sign(x):
    return (x > 0) - (x < 0)


def assert_close(value, exact, rel):
    """``value`` has the exact sign and is within ``rel`` of ``exact``
    (with saturation outside the float range)."""
    assert sign(value) == sign(exact), (value, float(exact))
    if abs(exact) > DBL_MAX:
        assert math.isinf(value)
    elif exact != 0:
        err = abs(Fraction(value) - exact)
        assert err <= Fraction(rel) * abs(exact) + Fraction(2.0 ** -1074), (
            value, float(exact), float(err / abs(exact)))


def assert_same(w, v, rel):
    """Two evaluations of the same determinant: equal signs, values within
    the error of both (saturated values must agree)."""
    assert sign(w) == sign(v), (w, v)
    if math.isinf(v) or math.isinf(w):
        assert w == v
    else:
        assert abs(w - v) <= 2 * rel * abs(v) + 2.0 ** -1073, (w, v)


def check_orient(p, rel=ORIENT2D_REL_ERROR):
    assert_close(orient2d(*p), exact_orient(*p), rel)


def check_incircle(p, rel=INCIRCLE_REL_ERROR):
    assert_close(incircle(*p), exact_incircle(*p), rel)


# -- strategies ----------------------------------------------------------------

FINITE = dict(allow_nan=False, allow_infinity=False, allow_subnormal=False)


def coords(bound=1e6):
    # Keep the dynamic range of one configuration moderate (the documented
    # domain of exactness); zero is allowed.
    return st.floats(-bound, bound, **FINITE).filter(lambda x: x == 0.0 or abs(x) >= 1e-30)


def nudge(x, k):
    """Move ``x`` by ``k`` ulps (zero stays: its neighbours are subnormal,
    outside the supported dynamic range of a configuration)."""
    if x == 0.0:
        return x
    direction = math.copysign(math.inf, k)
    for _ in range(abs(k)):
        x = float(np.nextafter(x, direction))
    return x


ulps = st.integers(-3, 3)


def random_points(n):
    return st.tuples(*[coords()] * (2 * n))


@st.composite
def near_collinear(draw):
    """Three points on a line, each coordinate moved by a few ulps."""
    if draw(st.booleans()):
        # y = m x + q
        m = draw(coords(10))
        q = draw(coords(10))
        xs = draw(st.lists(coords(10), min_size=3, max_size=3))
        pts = [(x, m * x + q) for x in xs]
    else:
        # c = a + t (b - a)
        ax, ay, bx, by = (draw(coords(10)) for _ in range(4))
        t = draw(coords(3))
        pts = [(ax, ay), (bx, by), (ax + t * (bx - ax), ay + t * (by - ay))]
    out = []
    for x, y in pts:
        out += [nudge(x, draw(ulps)), nudge(y, draw(ulps))]
    return tuple(out)


@st.composite
def near_cocircular(draw):
    """Four points on a circle (counter-clockwise), moved by a few ulps."""
    cx, cy = draw(coords(10)), draw(coords(10))
    r = draw(st.floats(1e-3, 1e3, **FINITE))
    angles = sorted(draw(st.lists(st.floats(0.0, 2 * math.pi, **FINITE),
                                  min_size=4, max_size=4, unique=True)))
    out = []
    for t in angles:
        out += [nudge(cx + r * math.cos(t), draw(ulps)),
                nudge(cy + r * math.sin(t), draw(ulps))]
    return tuple(out)


# lattice points on the circle of radius 25
CIRCLE_25 = [(x, y) for x in range(-25, 26) for y in range(-25, 26) if x * x + y * y == 625]


@st.composite
def exactly_cocircular(draw):
    """Four distinct lattice points of one circle, translated and scaled by a
    power of two: exactly co-circular doubles."""
    pts = draw(st.lists(st.sampled_from(CIRCLE_25), min_size=4, max_size=4, unique=True))
    ox, oy = draw(st.integers(-10 ** 9, 10 ** 9)), draw(st.integers(-10 ** 9, 10 ** 9))
    k = draw(st.integers(-200, 200))
    return tuple(math.ldexp(v, k) for x, y in pts for v in (x + ox, y + oy))


def integer_grid(n):
    """Points of a small integer grid: many exact zeros."""
    return st.tuples(*[st.integers(-4, 4).map(float)] * (2 * n))


@st.composite
def translated(draw, base):
    """A configuration shifted by a large offset (the sum is rounded)."""
    p = draw(base)
    ox = draw(st.sampled_from([1.0, 1e8, -1e8, 12345.678, 2.0 ** 40]))
    oy = draw(st.sampled_from([0.0, 1e8, -3e7, 0.1]))
    return tuple(v + (ox if i % 2 == 0 else oy) for i, v in enumerate(p))


@st.composite
def scaled(draw, base):
    """A configuration scaled by 10**k, k in [-150, 150]."""
    p = draw(base)
    s = 10.0 ** draw(st.integers(-150, 150))
    return tuple(v * s for v in p)


@st.composite
def grid_with_step(draw, n):
    """Grid points offset + (i, j) * h, with an inexact step such as 0.1."""
    h = draw(st.sampled_from([0.1, 0.3, 1.0 / 3.0, 0.5]))
    off = draw(st.sampled_from([0.0, 1.0, 1e8, -7.5e5]))
    ij = draw(st.tuples(*[st.integers(-4, 4)] * (2 * n)))
    return tuple(off + i * h for i in ij)


def in_domain(log2_range):
    """Keep configurations inside the documented domain of exactness: the
    nonzero coordinates span at most ``2**log2_range`` (a tiny angle drawn
    for a point on a circle can otherwise put 1e-298 beside 1e2)."""
    def ok(p):
        a = [abs(v) for v in p if v != 0.0]
        return not a or max(a) <= min(a) * 2.0 ** log2_range
    return ok


orient_inputs = st.one_of(
    random_points(3), near_collinear(), integer_grid(3), grid_with_step(3),
    translated(near_collinear()), translated(integer_grid(3)),
    scaled(near_collinear()), scaled(integer_grid(3)),
    exactly_cocircular().map(lambda p: p[:6]),
).filter(in_domain(480))

incircle_inputs = st.one_of(
    random_points(4), near_cocircular(), exactly_cocircular(), integer_grid(4),
    grid_with_step(4), translated(near_cocircular()), translated(integer_grid(4)),
    scaled(near_cocircular()), scaled(exactly_cocircular()), scaled(integer_grid(4)),
).filter(in_domain(200))


# -- orient2d ------------------------------------------------------------------

@SETTINGS
@given(orient_inputs)
def test_orient2d_matches_oracle(p):
    check_orient(p)


@FEWER
@given(orient_inputs)
def test_orient2d_antisymmetry_and_cyclic_invariance(p):
    a, b, c = p[0:2], p[2:4], p[4:6]
    v = orient2d(*a, *b, *c)
    for q in ((*b, *a, *c), (*a, *c, *b), (*c, *b, *a)):
        assert_same(orient2d(*q), -v, ORIENT2D_REL_ERROR)
    for q in ((*b, *c, *a), (*c, *a, *b)):
        assert_same(orient2d(*q), v, ORIENT2D_REL_ERROR)


def test_orient2d_named_examples():
    # on the line y = x: exactly collinear as doubles
    assert orient2d(0.1, 0.1, 0.2, 0.2, 0.3, 0.3) == 0.0
    # not exactly collinear as doubles; the naive value is 25% off
    p = (0.1, 0.7, 0.2, 0.8, 0.3, 0.9)
    exact = exact_orient(*p)
    assert abs(Fraction(P.orient2d_fast(*p)) - exact) > abs(exact) / 8
    assert orient2d(*p) < 0.0
    check_orient(p)
    assert orient2d(0.0, 0.0, 1.0, 0.0, 0.0, 1.0) == 1.0
    assert orient2d(1.0, 1.0, 1.0, 1.0, 1.0, 1.0) == 0.0
    assert orient2d(1e8, 1e8, 1e8 + 1, 1e8 + 1, 1e8 + 2, 1e8 + 2) == 0.0
    # a subnormal coordinate, exact products
    assert orient2d(0.0, 0.0, 1.0, 0.0, 0.0, 5e-324) == 5e-324
    assert orient2d(0.0, 0.0, 2.0, 0.0, 1.0, -5e-324) == -1e-323


def test_orient2d_classroom_example():
    """Kettner et al., "Classroom examples of robustness problems in geometric
    computations": the orientation of p = (0.5 + i u, 0.5 + j u) against
    q = (12, 12), r = (24, 24), u = 2**-53, is garbled by naive floats."""
    u = 2.0 ** -53
    naive_wrong = 0
    for i in range(64):
        for j in range(64):
            px, py = 0.5 + i * u, 0.5 + j * u
            exact = exact_orient(px, py, 12.0, 12.0, 24.0, 24.0)
            for args in ((px, py, 12.0, 12.0, 24.0, 24.0),
                         (12.0, 12.0, 24.0, 24.0, px, py),
                         (24.0, 24.0, px, py, 12.0, 12.0)):
                assert_close(orient2d(*args), exact, ORIENT2D_REL_ERROR)
            # the pivot-p formula used in the paper
            naive_wrong += sign(P.orient2d_fast(12.0, 12.0, 24.0, 24.0, px, py)) != sign(exact)
    assert naive_wrong > 0  # the test is meaningful


def test_orient2d_extreme_magnitudes():
    for k in (-600, -500, -300, 0, 300, 480):
        s = 2.0 ** k
        p = tuple(v * s for v in (0.1, 0.7, 0.2, 0.8, 0.3, 0.9))
        check_orient(p)
        p = tuple(v * s for v in (0.5, 0.5, 12.0, 12.0, 24.0, 24.0 + 2.0 ** -48))
        check_orient(p)


# -- incircle ------------------------------------------------------------------

@SETTINGS
@given(incircle_inputs)
def test_incircle_matches_oracle(p):
    check_incircle(p)


@FEWER
@given(exactly_cocircular())
def test_incircle_exact_zero_on_circle(p):
    assert incircle(*p) == 0.0


@FEWER
@given(incircle_inputs)
def test_incircle_symmetries(p):
    a, b, c, d = p[0:2], p[2:4], p[4:6], p[6:8]
    v = incircle(*a, *b, *c, *d)
    for q in ((*b, *a, *c, *d), (*a, *c, *b, *d), (*a, *b, *d, *c), (*b, *c, *d, *a)):
        assert_same(incircle(*q), -v, INCIRCLE_REL_ERROR)  # odd permutations
    for q in ((*b, *c, *a, *d), (*c, *a, *b, *d), (*b, *a, *d, *c)):
        assert_same(incircle(*q), v, INCIRCLE_REL_ERROR)  # even permutations


def test_incircle_named_examples():
    assert incircle(0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0) == 0.0
    assert incircle(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.5, 0.5) == 0.5
    assert incircle(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 2.0, 2.0) < 0.0
    assert incircle(0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.5, 0.5) < 0.0  # clockwise
    # a unit grid square offset by 1e8, and with an inexact step
    o = 1e8
    assert incircle(o, o, o + 1, o, o + 1, o + 1, o, o + 1) == 0.0
    check_incircle((o, o, o + 0.1, o, o + 0.1, o + 0.1, o, o + 0.1))
    check_incircle((0.1, 0.1, 0.3, 0.1, 0.3, 0.3, 0.1, 0.3))


def test_incircle_near_circle_grid():
    """d = (1 + i u, 1 + j u) around the point (1, 1) of the circle through
    (0, 0), (1, 0), (0, 1)."""
    u = 2.0 ** -52
    for i in range(-16, 16):
        for j in range(-16, 16):
            check_incircle((0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0 + i * u, 1.0 + j * u))


def test_incircle_extreme_magnitudes():
    base = (0.1, 0.1, 0.3, 0.1, 0.3, 0.3, 0.1, 0.3 + 2.0 ** -50)
    for k in (-700, -300, -240, 0, 200, 300):
        s = 2.0 ** k
        p = tuple(v * s for v in base)
        value, exact = incircle(*p), exact_incircle(*p)
        assert sign(value) == sign(exact) != 0
        if 2.0 ** -1000 < abs(exact) < DBL_MAX:
            assert_close(value, exact, INCIRCLE_REL_ERROR)
    # saturation outside the float range keeps the sign
    huge = incircle(*(v * 2.0 ** 300 for v in (0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.5, 0.5)))
    assert huge == math.inf
    tiny = incircle(*(v * 2.0 ** -300 for v in (0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 2.0, 2.0)))
    assert tiny == -5e-324


# -- the stages individually ---------------------------------------------------

mid_floats = st.floats(-2.0 ** 400, 2.0 ** 400, **FINITE).filter(
    lambda x: x == 0.0 or abs(x) >= 2.0 ** -400)


@FEWER
@given(mid_floats, mid_floats)
def test_error_free_transformations(a, b):
    fa, fb = Fraction(a), Fraction(b)
    x, y = E.two_sum(a, b)
    assert x == a + b and Fraction(x) + Fraction(y) == fa + fb
    x, y = E.two_diff(a, b)
    assert x == a - b and Fraction(x) + Fraction(y) == fa - fb
    x, y = E.two_product(a, b)  # fails under FMA contraction
    assert x == a * b and Fraction(x) + Fraction(y) == fa * fb


def components(h, n):
    return [float(v) for v in h[:n]]


def assert_expansion(h, n, value):
    """``h[:n]`` is a zero-free, magnitude-sorted expansion summing to value."""
    comps = components(h, n)
    assert sum(map(Fraction, comps)) == value
    if n > 1:
        assert all(c != 0.0 for c in comps)
        assert all(abs(comps[i]) < abs(comps[i + 1]) for i in range(n - 1))


@FEWER
@given(st.tuples(*[coords(1e3)] * 9))
def test_expansion_arithmetic(v):
    ax, ay, bx, by, cx, cy, dx, dy, s = v
    e, f, h = np.empty(4), np.empty(4), np.empty(8)
    ne = E.bracket(ax, ay, bx, by, e)
    fe = Fraction(ax) * Fraction(by) - Fraction(bx) * Fraction(ay)
    assert_expansion(e, ne, fe)
    nf = E.bracket(cx, cy, dx, dy, f)
    ff = Fraction(cx) * Fraction(dy) - Fraction(dx) * Fraction(cy)
    assert_expansion(f, nf, ff)
    nh = E.expansion_sum(e, ne, f, nf, h)
    assert_expansion(h, nh, fe + ff)
    g = np.empty(16)
    ng = E.scale_expansion(h, nh, s, g)
    exact = (fe + ff) * Fraction(s)
    assert_expansion(g, ng, exact)
    approx = E.approximate(g, ng)
    assert sign(approx) == sign(exact)
    assert abs(Fraction(approx) - exact) <= Fraction(2 * EPS) * abs(exact)


# (inside the documented domain of exactness, as the inputs above: a random coordinate
# of 1e-288 next to 1.0 makes the exact stage's products underflow)
stage_orient_inputs = st.one_of(random_points(3), near_collinear(), grid_with_step(3),
                                translated(near_collinear())).filter(in_domain(480))
stage_incircle_inputs = st.one_of(random_points(4), near_cocircular(), grid_with_step(4),
                                  translated(near_cocircular())).filter(in_domain(200))


@FEWER
@given(stage_orient_inputs)
def test_orient2d_stages(p):
    exact = exact_orient(*p)
    # exact stage: exact sign, within an ulp
    assert_close(P._orient2d_exact(*p), exact, 2 * EPS)
    # double-double stage: the returned bound holds
    value, err = P._orient2d_dd(*p)
    assert abs(Fraction(value) - exact) <= Fraction(err) + Fraction(EPS) * abs(Fraction(value))


@FEWER
@given(stage_incircle_inputs)
def test_incircle_stages(p):
    exact = exact_incircle(*p)
    assert_close(P._incircle_exact(*p), exact, 2 * EPS)
    value, err = P._incircle_dd(*p)
    assert abs(Fraction(value) - exact) <= Fraction(err) + Fraction(EPS) * abs(Fraction(value))


def test_exact_stage_paths():
    """Exact differences on a coarse lattice, exact differences off it, and
    inexact differences all reach the exact stage correctly."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        lattice = rng.integers(-1000, 1000, 8) * 0.25
        close = 1.0 + rng.random(8)  # differences exact (Sterbenz), full mantissas
        spread = rng.uniform(-1, 1, 8) * 10.0 ** rng.integers(-3, 4, 8)
        for p in (lattice, close, spread):
            p = tuple(float(v) for v in p)
            assert_close(P._orient2d_exact(*p[:6]), exact_orient(*p[:6]), 2 * EPS)
            assert_close(P._incircle_exact(*p), exact_incircle(*p), 2 * EPS)


@pytest.mark.parametrize("n", [3, 4])
def test_all_points_equal(n):
    f = orient2d if n == 3 else incircle
    assert f(*([0.0] * 2 * n)) == 0.0
    assert f(*([1e300] * 2 * n)) == 0.0
    assert f(*([-3.7e-200] * 2 * n)) == 0.0


@SETTINGS
@given(orient_inputs)
def test_orient2d_sign_matches_oracle(p):
    assert sign(orient2d_sign(*p)) == sign(exact_orient(*p))


@SETTINGS
@given(incircle_inputs)
def test_incircle_sign_matches_oracle(p):
    assert sign(incircle_sign(*p)) == sign(exact_incircle(*p))


def test_sign_variants_classroom_example():
    # Kettner et al.: the naive float orientation is wrong on this grid
    eps = 2.0 ** -53
    for i in range(64):
        for j in range(64):
            p = (0.5 + i * eps, 0.5 + j * eps, 12.0, 12.0, 24.0, 24.0)
            assert sign(orient2d_sign(*p)) == sign(exact_orient(*p))


def test_coordinates_compile_first_in_a_fresh_process(tmp_path):
    """A process whose first kernel is the coordinates' query block (compiled without
    reference counting), e.g. a run restarted from a checkpoint, with an empty numba
    cache: the exact predicates it calls were compiled with reference counting at
    import, so it compiles and the coordinates are a partition of unity."""
    import os
    import subprocess
    import sys

    from skfem_nem import LagrangianMesh
    nodes = np.random.default_rng(4).random((60, 2))
    LagrangianMesh(nodes).save(tmp_path / "mesh.npz")
    code = ("import numpy as np\n"
            "from skfem_nem import LagrangianMesh, natural_neighbour_coordinates\n"
            f"lm = LagrangianMesh.load({str(tmp_path / 'mesh.npz')!r})\n"
            "phi = natural_neighbour_coordinates(lm.triangulation, np.array([[0.4, 0.6]]))\n"
            "print(phi.sum())\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert abs(float(out.stdout.split()[-1]) - 1.0) < 1e-12
