"""Tests of the robust 3D predicates against an exact rational oracle."""
import math
import sys
from fractions import Fraction

import numpy as np
from hypothesis import given, settings, strategies as st

from skfem_nem.geometry import predicates3d as P
from skfem_nem.geometry.predicates3d import (
    INSPHERE_REL_ERROR,
    ORIENT3D_REL_ERROR,
    insphere,
    insphere_sign,
    orient3d,
    orient3d_sign,
)

EPS = 2.0 ** -53
DBL_MAX = sys.float_info.max
SETTINGS = settings(max_examples=300, deadline=None)
FEWER = settings(max_examples=120, deadline=None)
FINITE = dict(allow_nan=False, allow_infinity=False, allow_subnormal=False)


# -- exact oracle ----------------------------------------------------------------------

def det3(u, v, w):
    return (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))


def points_of(p):
    f = [Fraction(v) for v in p]
    return [f[i:i + 3] for i in range(0, len(f), 3)]


def exact_orient(*p):
    a, b, c, d = points_of(p)
    return det3([b[i] - a[i] for i in range(3)], [c[i] - a[i] for i in range(3)],
                [d[i] - a[i] for i in range(3)])


def exact_insphere(*p):
    """det[b - a, c - a, d - a] convention: positive inside for positive a, b, c, d."""
    a, b, c, d, e = points_of(p)
    rows = [[x[i] - e[i] for i in range(3)] for x in (a, b, c, d)]
    lifts = [r[0] ** 2 + r[1] ** 2 + r[2] ** 2 for r in rows]
    det = 0
    for k in range(4):
        others = [rows[j] for j in range(4) if j != k]
        det += (-1) ** (k + 3) * lifts[k] * det3(*others)
    return -det


def sign(x):
    return (x > 0) - (x < 0)


def assert_close(value, exact, rel):
    assert sign(value) == sign(exact), (value, exact)
    if abs(exact) > DBL_MAX:  # saturated
        assert math.isinf(value)
    elif exact != 0:
        err = abs(Fraction(value) - exact)
        assert err <= Fraction(rel) * abs(exact) + Fraction(2.0 ** -1074), (value, float(exact))


# -- strategies ------------------------------------------------------------------------

def coords(bound=1e6):
    return st.floats(-bound, bound, **FINITE).filter(lambda x: x == 0.0 or abs(x) >= 1e-30)


def nudge(x, k):
    if x == 0.0:
        return x
    for _ in range(abs(k)):
        x = float(np.nextafter(x, math.copysign(math.inf, k)))
    return x


ulps = st.integers(-3, 3)


def random_points(n):
    return st.tuples(*[coords()] * (3 * n))


@st.composite
def near_coplanar(draw):
    """Four points of a plane a + s u + t v, each coordinate moved by a few ulps."""
    a, u, v = ([draw(coords(10)) for _ in range(3)] for _ in range(3))
    out = []
    for _ in range(4):
        s, t = draw(coords(3)), draw(coords(3))
        out += [nudge(a[i] + s * u[i] + t * v[i], draw(ulps)) for i in range(3)]
    return tuple(out)


@st.composite
def near_cospherical(draw):
    """Five points of a sphere, moved by a few ulps; the first four positively oriented."""
    c = [draw(coords(10)) for _ in range(3)]
    r = draw(st.floats(1e-3, 1e3, **FINITE))
    pts = []
    for _ in range(5):
        th = draw(st.floats(0.0, math.pi, **FINITE))
        ph = draw(st.floats(0.0, 2 * math.pi, **FINITE))
        pts.append([c[0] + r * math.sin(th) * math.cos(ph), c[1] + r * math.sin(th) * math.sin(ph),
                    c[2] + r * math.cos(th)])
    if exact_orient(*sum(pts[:4], [])) < 0:
        pts[0], pts[1] = pts[1], pts[0]
    return tuple(nudge(v, draw(ulps)) for q in pts for v in q)


SPHERE_9 = [(x, y, z) for x in range(-9, 10) for y in range(-9, 10) for z in range(-9, 10)
            if x * x + y * y + z * z == 81]


@st.composite
def exactly_cospherical(draw):
    """Five distinct lattice points of one sphere, translated and scaled by a power of two."""
    pts = draw(st.lists(st.sampled_from(SPHERE_9), min_size=5, max_size=5, unique=True))
    o = [draw(st.integers(-10 ** 9, 10 ** 9)) for _ in range(3)]
    k = draw(st.integers(-100, 100))
    return tuple(math.ldexp(v + o[i], k) for q in pts for i, v in enumerate(q))


@st.composite
def exactly_coplanar(draw):
    """Four integer points of the plane z = 2x - 3y + 5, translated and scaled by 2**k."""
    xy = draw(st.lists(st.tuples(st.integers(-50, 50), st.integers(-50, 50)),
                       min_size=4, max_size=4))
    k = draw(st.integers(-250, 250))
    return tuple(math.ldexp(v, k) for x, y in xy for v in (x, y, 2 * x - 3 * y + 5))


def integer_grid(n):
    return st.tuples(*[st.integers(-3, 3).map(float)] * (3 * n))


@st.composite
def grid_with_step(draw, n):
    h = draw(st.sampled_from([0.1, 0.3, 1.0 / 3.0, 0.5]))
    off = draw(st.sampled_from([0.0, 1.0, 1e8, -7.5e5]))
    return tuple(off + i * h for i in draw(st.tuples(*[st.integers(-3, 3)] * (3 * n))))


@st.composite
def translated(draw, base):
    p = draw(base)
    o = [draw(st.sampled_from([0.0, 1e8, -3e7, 0.1, 12345.678])) for _ in range(3)]
    return tuple(v + o[i % 3] for i, v in enumerate(p))


@st.composite
def scaled(draw, base):
    p = draw(base)
    s = 10.0 ** draw(st.integers(-60, 60))
    return tuple(v * s for v in p)


def in_domain(log2_range):
    def ok(p):
        a = [abs(v) for v in p if v != 0.0]
        return not a or max(a) <= min(a) * 2.0 ** log2_range
    return ok


orient_inputs = st.one_of(
    random_points(4), near_coplanar(), exactly_coplanar(), integer_grid(4), grid_with_step(4),
    translated(near_coplanar()), translated(integer_grid(4)), scaled(near_coplanar()),
    exactly_cospherical().map(lambda p: p[:12]),
).filter(in_domain(280))

insphere_inputs = st.one_of(
    random_points(5), near_cospherical(), exactly_cospherical(), integer_grid(5),
    grid_with_step(5), translated(near_cospherical()), translated(integer_grid(5)),
    scaled(near_cospherical()), scaled(exactly_cospherical()),
).filter(in_domain(140))


# -- tests -----------------------------------------------------------------------------

@SETTINGS
@given(orient_inputs)
def test_orient3d_matches_oracle(p):
    assert_close(orient3d(*p), exact_orient(*p), ORIENT3D_REL_ERROR)
    assert sign(orient3d_sign(*p)) == sign(exact_orient(*p))


@SETTINGS
@given(insphere_inputs)
def test_insphere_matches_oracle(p):
    assert_close(insphere(*p), exact_insphere(*p), INSPHERE_REL_ERROR)
    assert sign(insphere_sign(*p)) == sign(exact_insphere(*p))


@FEWER
@given(st.one_of(exactly_cospherical(), exactly_coplanar().map(lambda p: p + p[:3])))
def test_exact_zeros(p):
    """Cospherical points, and a point repeated: exactly zero."""
    assert insphere(*p) == 0.0 and insphere_sign(*p) == 0.0
    if exact_orient(*p[:12]) == 0:
        assert orient3d(*p[:12]) == 0.0 and orient3d_sign(*p[:12]) == 0.0


@FEWER
@given(exactly_coplanar())
def test_orient3d_exact_zero_on_plane(p):
    assert orient3d(*p) == 0.0 and orient3d_sign(*p) == 0.0


@FEWER
@given(orient_inputs)
def test_orient3d_antisymmetry(p):
    a, b, c, d = (p[i:i + 3] for i in range(0, 12, 3))
    o = orient3d(*p)
    assert orient3d(*b, *a, *c, *d) == -o
    assert sign(orient3d(*b, *c, *a, *d)) == sign(o)
    assert sign(orient3d(*a, *b, *d, *c)) == -sign(o)


@FEWER
@given(insphere_inputs)
def test_insphere_antisymmetry(p):
    a, b, c, d, e = (p[i:i + 3] for i in range(0, 15, 3))
    s = sign(insphere(*p))
    assert sign(insphere(*b, *a, *c, *d, *e)) == -s
    assert sign(insphere(*a, *b, *d, *c, *e)) == -s


def test_conventions():
    o = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    assert orient3d(*o) == 1.0  # det[b - a, c - a, d - a] of the unit tetrahedron
    assert insphere(*o, 0.2, 0.2, 0.2) > 0 > insphere(*o, 2.0, 2.0, 2.0)
    assert insphere(*o, 1.0, 1.0, 0.0) == 0.0  # a corner of the unit cube


def test_tiny_perturbations_of_cospherical_cube_corners():
    """Cube corners (cospherical) with the fifth moved by one ulp in each direction: the
    sign follows the exact determinant, the float formula does not always."""
    base = [0.1, 0.1, 0.1, 0.7, 0.1, 0.1, 0.1, 0.7, 0.1, 0.1, 0.1, 0.7]
    corner = (0.7, 0.7, 0.1)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            e = (nudge(corner[0], dx), nudge(corner[1], dy), corner[2])
            p = tuple(base) + e
            assert sign(insphere(*p)) == sign(exact_insphere(*p))
            assert sign(insphere_sign(*p)) == sign(exact_insphere(*p))


def test_classroom_example_3d():
    """After Kettner et al.'s grid: a point a few ulps off the line through two others;
    the naive float orientation errs on most of the grid, ours does not."""
    wrong = 0
    for i in range(32):
        for j in range(32):
            p = (0.5 + i * EPS, 0.5 + j * EPS, 0.5, 12.0, 12.0, 12.0, 24.0, 24.0, 24.0,
                 0.75 + i * EPS, 0.25, 0.5 + j * EPS)
            exact = exact_orient(*p)
            assert sign(orient3d(*p)) == sign(exact) == sign(orient3d_sign(*p))
            wrong += sign(P.orient3d_fast(*p)) != sign(exact)
    assert wrong > 100


def test_extreme_magnitudes():
    for k in (-150, -60, 60, 150):
        s = 2.0 ** k
        p = tuple(v * s for v in (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0))
        assert orient3d(*p) == 2.0 ** (3 * k)
        q = p + (0.2 * s, 0.2 * s, 0.2 * s)
        assert_close(insphere(*q), exact_insphere(*q), INSPHERE_REL_ERROR)


@FEWER
@given(st.one_of(orient_inputs))
def test_orient3d_exact_stage(p):
    assert_close(P._orient3d_exact(*p), exact_orient(*p), 2 * EPS)


@FEWER
@given(insphere_inputs)
def test_insphere_exact_stage(p):
    assert_close(P._insphere_exact(*p), exact_insphere(*p), 2 * EPS)


def test_exact_stage_paths():
    """Lattice differences, exact differences off a lattice and inexact differences."""
    rng = np.random.default_rng(3)
    for _ in range(100):
        lattice = rng.integers(-100, 100, 15) * 0.25
        close = 1.0 + rng.random(15)
        spread = rng.uniform(-1, 1, 15) * 10.0 ** rng.integers(-3, 4, 15)
        for p in (lattice, close, spread):
            p = tuple(float(v) for v in p)
            assert_close(P._orient3d_exact(*p[:12]), exact_orient(*p[:12]), 2 * EPS)
            assert_close(P._insphere_exact(*p), exact_insphere(*p), 2 * EPS)
