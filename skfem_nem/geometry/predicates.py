"""Robust two-dimensional geometric predicates, callable from numba code.

Two predicates are provided, compiled with ``numba.njit`` and taking float64
scalars, so that they can be called from other nopython kernels as well as
from Python:

``orient2d(ax, ay, bx, by, cx, cy)``
    The determinant ``(a - c) x (b - c)``, twice the signed area of the
    triangle: positive when ``a, b, c`` turn counter-clockwise, negative when
    clockwise, zero when collinear.

``incircle(ax, ay, bx, by, cx, cy, dx, dy)``
    Positive when ``d`` lies strictly inside the circle through the
    counter-clockwise triple ``a, b, c``, negative outside, zero on it
    (the sign convention of Shewchuk's ``incircle``).

Guarantees
----------
For finite inputs the *sign* of the result is the sign of the determinant
evaluated in exact arithmetic on the given doubles (zero included), and the
*value* approximates that exact determinant with a relative error of at most
:data:`ORIENT2D_REL_ERROR` and :data:`INCIRCLE_REL_ERROR` (both ``2**-42``,
about 2.3e-13).  Values outside the
float64 range saturate to ``+-inf`` or to the smallest subnormal of the right
sign, and subnormal values are within one subnormal ulp.  The exact stage
rescales the input by a power of two, so uniformly huge or tiny configurations
are fine; exactness is only lost if a single configuration mixes nonzero
coordinates whose magnitudes differ by more than roughly ``2**480``
(``orient2d``) or ``2**200`` (``incircle``), where the error-free
transformations underflow.

Design
------
Each predicate is a cascade of three stages, after J. R. Shewchuk, "Adaptive
Precision Floating-Point Arithmetic and Fast Robust Geometric Predicates",
Discrete & Computational Geometry 18:305-363 (1997).

1. Float filter.  The determinant is evaluated in ordinary floating point
   together with Shewchuk's stage-A error bound, ``ccwerrboundA * detsum`` for
   ``orient2d`` and ``iccerrboundA * permanent`` for ``incircle``
   (``ccwerrboundA = (3 + 16 eps) eps``, ``iccerrboundA = (10 + 96 eps) eps``,
   ``eps = 2**-53``).  Shewchuk's test ``|det| > errbound`` certifies only the
   sign; since callers also use the value (dividing by ``orient2d`` to build
   circumcentres of nearly collinear triples), the float result is accepted
   only when the bound is at most the target relative error times ``|det|``.
   The filter is trusted only while the permanent lies in a range in which
   overflow is impossible and underflow negligible.  It allocates nothing.

2. Double-double stage.  The coordinate differences are formed exactly as
   two-term expansions (``two_diff``) and the same determinant is evaluated in
   double-double arithmetic.  Its error is below ``2**-96`` times the
   permanent (a deliberately generous version of the ``O(eps**2)`` bound), so
   this stage settles, to within ``2**-50`` relative and again without
   allocation, every input whose determinant exceeds about ``3e-14`` times the
   permanent, i.e. everything but (nearly) degenerate configurations.

3. Exact stage.  The determinant is expanded into 2x2 brackets
   ``[pq] = px*qy - qx*py`` of the coordinates and evaluated exactly with
   floating-point expansions: ``two_product`` (Veltkamp splitting, splitter
   ``2**27 + 1``), ``two_sum``/``two_diff``, ``fast_expansion_sum_zeroelim``
   and ``scale_expansion_zeroelim``.  The differences ``ax - cx`` etc. are
   generally not exact, so this stage works on the original coordinates (the
   4x4 lifted determinant for ``incircle``).  When all differences happen to
   be exact (grids, nearby points) it works on them instead, with the last
   point at the origin, which prunes most of the terms; if moreover they are
   small multiples of a common power of two (dyadic grids), the plain float
   formula is already exact and is used directly.  Coordinates are rescaled by
   a power of two (exactly) so that products neither overflow nor underflow.
   The expansion is compressed (Shewchuk's ``compress``) and its largest
   component, which carries the exact sign and approximates the expansion to
   within an ulp, is scaled back and returned.  This stage is not adaptive
   and uses small scratch arrays; it is reached only for (nearly) degenerate
   inputs.  The error-free transformations and the expansion arithmetic are
   shared with the 3D predicates and live in :mod:`.expansions`.

All floating-point code relies on IEEE 754 double precision with
round-to-nearest-even and no fused multiply-add contraction, which is what
numba generates without ``fastmath``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .expansions import (
    approximate,
    bracket,
    expansion_sum,
    fast_two_sum,
    rescale_exponent,
    scale_exponent,
    scale_expansion,
    two_diff,
    two_product,
    two_sum,
    unscale,
)

__all__ = ["orient2d", "incircle", "orient2d_sign", "incircle_sign",
           "ORIENT2D_REL_ERROR", "INCIRCLE_REL_ERROR"]

# -- constants ---------------------------------------------------------------

_EPS = 2.0 ** -53  # unit roundoff: half an ulp of 1.0

# Shewchuk's stage-A error bounds (1997, section 4).
_CCW_ERRBOUND_A = (3.0 + 16.0 * _EPS) * _EPS
_ICC_ERRBOUND_A = (10.0 + 96.0 * _EPS) * _EPS

#: Bound on the relative error of the value returned by :func:`orient2d`.
ORIENT2D_REL_ERROR = 2.0 ** -42
#: Bound on the relative error of the value returned by :func:`incircle`.
INCIRCLE_REL_ERROR = 2.0 ** -42

# The float filter accepts when errbound <= REL_ERROR * |det|.
_ORIENT2D_FILTER = 2.0 ** 42
_INCIRCLE_FILTER = 2.0 ** 42
# Error bound of the double-double stages relative to the permanent (the
# analysis gives below 12 eps**2 for orient2d and 40 eps**2 for incircle) and
# the acceptance factor: error <= 2**-51 |det|, so that together with the
# final rounding the relative error stays below 2**-50.
_DD_ERRBOUND = 2.0 ** -96
_DD_ACCEPT = 2.0 ** 51

# The float stages are trusted only when the permanent lies in [_TINY, _HUGE]:
# then nothing overflows and the absolute error caused by underflow is
# negligible next to the relative error bounds.
_TINY = 2.0 ** -900
_HUGE = 2.0 ** 1000

# Upper bounds on the number of components of the exact expansions.
_BRACKET_LEN = 4  # [pq] = px*qy - qx*py
_MINOR_LEN = 3 * _BRACKET_LEN  # sum of three brackets: a 3x3 orientation
_LIFTED_LEN = 8 * _MINOR_LEN  # (x*x + y*y) * minor
_INCIRCLE_LEN = 4 * _LIFTED_LEN  # the full 4x4 determinant


# -- double-double arithmetic --------------------------------------------------
# A double-double is an unevaluated sum hi + lo with |lo| <= eps |hi|.

@njit(cache=True)
def _dd_mul(ah, al, bh, bl):
    """Product of two double-doubles; error below ``8 eps**2 |a b|``."""
    p, e = two_product(ah, bh)
    e += ah * bl + al * bh
    return fast_two_sum(p, e)


@njit(cache=True)
def _dd_add(ah, al, bh, bl):
    """Sum of two double-doubles; error below ``3 eps**2 (|a| + |b|)``.

    The final renormalisation is a full ``two_sum`` because after
    cancellation the low-order part may exceed the high-order one.
    """
    s, e = two_sum(ah, bh)
    e += al + bl
    return two_sum(s, e)


@njit(cache=True)
def _orient2d_dd(ax, ay, bx, by, cx, cy):
    """Double-double ``orient2d``: return ``(value, error bound)``."""
    acx, acxt = two_diff(ax, cx)
    acy, acyt = two_diff(ay, cy)
    bcx, bcxt = two_diff(bx, cx)
    bcy, bcyt = two_diff(by, cy)
    lh, ll = _dd_mul(acx, acxt, bcy, bcyt)
    rh, rl = _dd_mul(acy, acyt, bcx, bcxt)
    det, _ = _dd_add(lh, ll, -rh, -rl)
    return det, _DD_ERRBOUND * (abs(lh) + abs(rh))


@njit(cache=True)
def _incircle_dd(ax, ay, bx, by, cx, cy, dx, dy):
    """Double-double ``incircle``: return ``(value, error bound)``."""
    adx, adxt = two_diff(ax, dx)
    ady, adyt = two_diff(ay, dy)
    bdx, bdxt = two_diff(bx, dx)
    bdy, bdyt = two_diff(by, dy)
    cdx, cdxt = two_diff(cx, dx)
    cdy, cdyt = two_diff(cy, dy)

    p1h, p1l = _dd_mul(bdx, bdxt, cdy, cdyt)
    p2h, p2l = _dd_mul(cdx, cdxt, bdy, bdyt)
    p3h, p3l = _dd_mul(cdx, cdxt, ady, adyt)
    p4h, p4l = _dd_mul(adx, adxt, cdy, cdyt)
    p5h, p5l = _dd_mul(adx, adxt, bdy, bdyt)
    p6h, p6l = _dd_mul(bdx, bdxt, ady, adyt)
    mah, mal = _dd_add(p1h, p1l, -p2h, -p2l)
    mbh, mbl = _dd_add(p3h, p3l, -p4h, -p4l)
    mch, mcl = _dd_add(p5h, p5l, -p6h, -p6l)

    xh, xl = _dd_mul(adx, adxt, adx, adxt)
    yh, yl = _dd_mul(ady, adyt, ady, adyt)
    lah, lal = _dd_add(xh, xl, yh, yl)
    xh, xl = _dd_mul(bdx, bdxt, bdx, bdxt)
    yh, yl = _dd_mul(bdy, bdyt, bdy, bdyt)
    lbh, lbl = _dd_add(xh, xl, yh, yl)
    xh, xl = _dd_mul(cdx, cdxt, cdx, cdxt)
    yh, yl = _dd_mul(cdy, cdyt, cdy, cdyt)
    lch, lcl = _dd_add(xh, xl, yh, yl)

    tah, tal = _dd_mul(lah, lal, mah, mal)
    tbh, tbl = _dd_mul(lbh, lbl, mbh, mbl)
    tch, tcl = _dd_mul(lch, lcl, mch, mcl)
    sh, sl = _dd_add(tah, tal, tbh, tbl)
    det, _ = _dd_add(sh, sl, tch, tcl)
    permanent = ((abs(p1h) + abs(p2h)) * lah
                 + (abs(p3h) + abs(p4h)) * lbh
                 + (abs(p5h) + abs(p6h)) * lch)
    return det, _DD_ERRBOUND * permanent


# -- exact stages ------------------------------------------------------------

@njit(cache=True)
def _on_lattice(x1, y1, x2, y2, x3, y3, bits, min_exp, max_exp):
    """Whether all six values are integer multiples of ``q = 2**(e - bits)``,
    where ``2**e`` bounds their magnitudes, and ``e`` is in ``[min_exp,
    max_exp]``.

    The values are then integers of at most ``bits`` bits times ``q``; with
    ``bits`` = 26 (degree 2) or 12 (degree 4) and the exponent range keeping
    all products normal, the plain float determinant is computed exactly.
    """
    m = max(abs(x1), abs(y1), abs(x2), abs(y2), abs(x3), abs(y3))
    if m == 0.0:
        return True
    e = scale_exponent(m)
    if e < min_exp or e > max_exp:
        return False
    q = math.ldexp(1.0, e - bits)
    inv_q = math.ldexp(1.0, bits - e)
    for v in (x1, y1, x2, y2, x3, y3):
        t = v * inv_q
        if t != math.floor(t) or t * q != v:
            return False
    return True


# The exact stages allocate their work space. They are compiled when this module is
# imported (eager signatures), with reference counting: a kernel compiled without it
# (``_nrt=False``, e.g. the coordinates' query block) would otherwise compile them in
# its own mode the first time it calls them, where allocation is refused, and fail
# in a process that had not yet used them (a run restarted from a checkpoint).
_EXACT_ORIENT2D = "float64(" + ", ".join(["float64"] * 6) + ")"
_EXACT_INCIRCLE = "float64(" + ", ".join(["float64"] * 8) + ")"


@njit(_EXACT_ORIENT2D, cache=True)
def _orient2d_exact(ax, ay, bx, by, cx, cy):
    """Exact ``orient2d`` as ``[ab] + [bc] + [ca]``, rounded to a float."""
    acx, acxt = two_diff(ax, cx)
    acy, acyt = two_diff(ay, cy)
    bcx, bcxt = two_diff(bx, cx)
    bcy, bcyt = two_diff(by, cy)
    if acxt == 0.0 and acyt == 0.0 and bcxt == 0.0 and bcyt == 0.0:
        # Exact differences: if they lie on a coarse dyadic lattice the plain
        # float formula is exact, otherwise translate c to the origin.
        if _on_lattice(acx, acy, bcx, bcy, 0.0, 0.0, 26, -480, 500):
            return acx * bcy - acy * bcx
        ax, ay, bx, by, cx, cy = acx, acy, bcx, bcy, 0.0, 0.0

    m = max(abs(ax), abs(ay), abs(bx), abs(by), abs(cx), abs(cy))
    if m == 0.0:
        return 0.0
    k = rescale_exponent(m, 500)
    if k != 0:
        ax = math.ldexp(ax, -k)
        ay = math.ldexp(ay, -k)
        bx = math.ldexp(bx, -k)
        by = math.ldexp(by, -k)
        cx = math.ldexp(cx, -k)
        cy = math.ldexp(cy, -k)

    B = _BRACKET_LEN
    work = np.empty(5 * B + _MINOR_LEN)
    ab = work[0:B]
    bc = work[B:2 * B]
    ca = work[2 * B:3 * B]
    abbc = work[3 * B:5 * B]
    det = work[5 * B:]
    n_ab = bracket(ax, ay, bx, by, ab)
    n_bc = bracket(bx, by, cx, cy, bc)
    n_ca = bracket(cx, cy, ax, ay, ca)
    n_abbc = expansion_sum(ab, n_ab, bc, n_bc, abbc)
    n_det = expansion_sum(abbc, n_abbc, ca, n_ca, det)
    return unscale(approximate(det, n_det), 2 * k)


@njit(cache=True)
def _lifted_term(px, py, minor, nminor, sign, tmp, out):
    """``out = sign * (px*px + py*py) * minor``; return its length.

    ``tmp`` is scratch space of ``10 * _MINOR_LEN`` entries.
    """
    M = _MINOR_LEN
    x1 = tmp[0:2 * M]
    xx = tmp[2 * M:6 * M]
    yy = tmp[6 * M:10 * M]
    n1 = scale_expansion(minor, nminor, sign * px, x1)
    nxx = scale_expansion(x1, n1, px, xx)
    n1 = scale_expansion(minor, nminor, sign * py, x1)
    nyy = scale_expansion(x1, n1, py, yy)
    return expansion_sum(xx, nxx, yy, nyy, out)


@njit(_EXACT_INCIRCLE, cache=True)
def _incircle_exact(ax, ay, bx, by, cx, cy, dx, dy):
    """Exact ``incircle`` by Laplace expansion of the 4x4 lifted determinant.

    With rows ``(x, y, x*x + y*y, 1)`` for ``a, b, c, d`` and the 3x3
    orientation ``O(p, q, r) = [pq] + [qr] + [rp]``::

        det = lift(a) O(b,c,d) - lift(b) O(a,c,d)
            + lift(c) O(a,b,d) - lift(d) O(a,b,c)
    """
    # Long kernel: Shewchuk's exact expansion arithmetic, written out term by term as in his
    # predicates; a loop over the terms would allocate.
    adx, adxt = two_diff(ax, dx)
    ady, adyt = two_diff(ay, dy)
    bdx, bdxt = two_diff(bx, dx)
    bdy, bdyt = two_diff(by, dy)
    cdx, cdxt = two_diff(cx, dx)
    cdy, cdyt = two_diff(cy, dy)
    if (adxt == 0.0 and adyt == 0.0 and bdxt == 0.0 and bdyt == 0.0
            and cdxt == 0.0 and cdyt == 0.0):
        # Exact differences: if they lie on a coarse dyadic lattice the plain
        # float formula is exact, otherwise translate d to the origin, where
        # the brackets and the lift involving d vanish.
        if _on_lattice(adx, ady, bdx, bdy, cdx, cdy, 12, -240, 250):
            return ((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
                    + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
                    + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))
        ax, ay, bx, by, cx, cy = adx, ady, bdx, bdy, cdx, cdy
        dx = 0.0
        dy = 0.0

    m = max(abs(ax), abs(ay), abs(bx), abs(by),
            abs(cx), abs(cy), abs(dx), abs(dy))
    if m == 0.0:
        return 0.0
    k = rescale_exponent(m, 250)
    if k != 0:
        ax = math.ldexp(ax, -k)
        ay = math.ldexp(ay, -k)
        bx = math.ldexp(bx, -k)
        by = math.ldexp(by, -k)
        cx = math.ldexp(cx, -k)
        cy = math.ldexp(cy, -k)
        dx = math.ldexp(dx, -k)
        dy = math.ldexp(dy, -k)

    B = _BRACKET_LEN
    M = _MINOR_LEN
    L = _LIFTED_LEN
    work = np.empty(8 * B + 15 * M + 8 * L + _INCIRCLE_LEN)
    ab, bc, cd, da = work[0:B], work[B:2 * B], work[2 * B:3 * B], work[3 * B:4 * B]
    ac, bd, ca, db = work[4 * B:5 * B], work[5 * B:6 * B], work[6 * B:7 * B], work[7 * B:8 * B]
    o = 8 * B
    tmp = work[o:o + M]
    o_bcd = work[o + M:o + 2 * M]
    o_acd = work[o + 2 * M:o + 3 * M]
    o_abd = work[o + 3 * M:o + 4 * M]
    o_abc = work[o + 4 * M:o + 5 * M]
    o += 5 * M
    scratch = work[o:o + 10 * M]
    o += 10 * M
    t_a = work[o:o + L]
    t_b = work[o + L:o + 2 * L]
    t_c = work[o + 2 * L:o + 3 * L]
    t_d = work[o + 3 * L:o + 4 * L]
    o += 4 * L
    s_ab = work[o:o + 2 * L]
    s_cd = work[o + 2 * L:o + 4 * L]
    o += 4 * L
    det = work[o:]

    n_ab = bracket(ax, ay, bx, by, ab)
    n_bc = bracket(bx, by, cx, cy, bc)
    n_cd = bracket(cx, cy, dx, dy, cd)
    n_da = bracket(dx, dy, ax, ay, da)
    n_ac = bracket(ax, ay, cx, cy, ac)
    n_bd = bracket(bx, by, dx, dy, bd)
    for i in range(n_ac):
        ca[i] = -ac[i]
    for i in range(n_bd):
        db[i] = -bd[i]

    n = expansion_sum(bc, n_bc, cd, n_cd, tmp)
    n_bcd = expansion_sum(tmp, n, db, n_bd, o_bcd)
    n = expansion_sum(ac, n_ac, cd, n_cd, tmp)
    n_acd = expansion_sum(tmp, n, da, n_da, o_acd)
    n = expansion_sum(ab, n_ab, bd, n_bd, tmp)
    n_abd = expansion_sum(tmp, n, da, n_da, o_abd)
    n = expansion_sum(ab, n_ab, bc, n_bc, tmp)
    n_abc = expansion_sum(tmp, n, ca, n_ac, o_abc)

    n_a = _lifted_term(ax, ay, o_bcd, n_bcd, 1.0, scratch, t_a)
    n_b = _lifted_term(bx, by, o_acd, n_acd, -1.0, scratch, t_b)
    n_c = _lifted_term(cx, cy, o_abd, n_abd, 1.0, scratch, t_c)
    n_d = _lifted_term(dx, dy, o_abc, n_abc, -1.0, scratch, t_d)

    n_s_ab = expansion_sum(t_a, n_a, t_b, n_b, s_ab)
    n_s_cd = expansion_sum(t_c, n_c, t_d, n_d, s_cd)
    n_det = expansion_sum(s_ab, n_s_ab, s_cd, n_s_cd, det)
    return unscale(approximate(det, n_det), 4 * k)


# -- public predicates -------------------------------------------------------

@njit(cache=True)
def orient2d_fast(ax, ay, bx, by, cx, cy):
    """Plain floating-point ``orient2d``; no robustness guarantee."""
    return (ax - cx) * (by - cy) - (ay - cy) * (bx - cx)


@njit(cache=True)
def incircle_fast(ax, ay, bx, by, cx, cy, dx, dy):
    """Plain floating-point ``incircle``; no robustness guarantee."""
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy
    return ((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
            + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
            + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))


@njit(cache=True)
def orient2d(ax, ay, bx, by, cx, cy):
    """Robust orientation of the triangle ``a, b, c``.

    Returns ``(ax-cx)*(by-cy) - (ay-cy)*(bx-cx)``, twice the signed area:
    positive if ``a, b, c`` are counter-clockwise, negative if clockwise, and
    ``0.0`` if and only if they are collinear, all as in exact arithmetic on
    the given doubles.  The relative error of the value is at most
    :data:`ORIENT2D_REL_ERROR` (``2**-42``).
    """
    det_left = (ax - cx) * (by - cy)
    det_right = (ay - cy) * (bx - cx)
    det = det_left - det_right
    det_sum = abs(det_left) + abs(det_right)
    if det_sum >= _TINY and det_sum <= _HUGE:
        if abs(det) >= _ORIENT2D_FILTER * (_CCW_ERRBOUND_A * det_sum):
            return det
        det, err = _orient2d_dd(ax, ay, bx, by, cx, cy)
        if _DD_ACCEPT * err <= abs(det) and det != 0.0:
            return det
    return _orient2d_exact(ax, ay, bx, by, cx, cy)


@njit(cache=True)
def incircle(ax, ay, bx, by, cx, cy, dx, dy):
    """Robust in-circle test of ``d`` against the circle through ``a, b, c``.

    Returns the determinant::

        | ax-dx  ay-dy  (ax-dx)**2 + (ay-dy)**2 |
        | bx-dx  by-dy  (bx-dx)**2 + (by-dy)**2 |
        | cx-dx  cy-dy  (cx-dx)**2 + (cy-dy)**2 |

    which, for counter-clockwise ``a, b, c``, is positive if ``d`` lies
    strictly inside their circumcircle, negative if outside and ``0.0`` if and
    only if the four points are co-circular (or ``a, b, c`` collinear and
    ``d`` on their line), all as in exact arithmetic on the given doubles.
    The sign flips if ``a, b, c`` are clockwise.  The relative error of the
    value is at most :data:`INCIRCLE_REL_ERROR` (``2**-42``).
    """
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy

    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy

    det = (alift * (bdxcdy - cdxbdy)
           + blift * (cdxady - adxcdy)
           + clift * (adxbdy - bdxady))
    permanent = ((abs(bdxcdy) + abs(cdxbdy)) * alift
                 + (abs(cdxady) + abs(adxcdy)) * blift
                 + (abs(adxbdy) + abs(bdxady)) * clift)
    # An underflowing product is later multiplied by at most a lift, hence
    # the lower limit on the permanent grows with the lifts.
    if permanent >= _TINY * (1.0 + (alift + blift + clift)) and permanent <= _HUGE:
        if abs(det) >= _INCIRCLE_FILTER * (_ICC_ERRBOUND_A * permanent):
            return det
        det, err = _incircle_dd(ax, ay, bx, by, cx, cy, dx, dy)
        if _DD_ACCEPT * err <= abs(det) and det != 0.0:
            return det
    return _incircle_exact(ax, ay, bx, by, cx, cy, dx, dy)


@njit(cache=True)
def orient2d_sign(ax, ay, bx, by, cx, cy):
    """:func:`orient2d` for callers that need only the sign (walks, flips).

    Shewchuk's sign-only filter: when the float determinant exceeds its error
    bound it is returned as is (correct sign, value possibly inexact);
    otherwise the exact-sign :func:`orient2d` decides.
    """
    det_left = (ax - cx) * (by - cy)
    det_right = (ay - cy) * (bx - cx)
    det = det_left - det_right
    det_sum = abs(det_left) + abs(det_right)
    if det_sum >= _TINY and det_sum <= _HUGE and abs(det) > _CCW_ERRBOUND_A * det_sum:
        return det
    return orient2d(ax, ay, bx, by, cx, cy)


@njit(cache=True)
def incircle_sign(ax, ay, bx, by, cx, cy, dx, dy):
    """:func:`incircle` for callers that need only the sign (cavities, flips).

    Shewchuk's sign-only filter, then the exact-sign :func:`incircle`.
    """
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy
    det = (alift * (bdxcdy - cdxbdy)
           + blift * (cdxady - adxcdy)
           + clift * (adxbdy - bdxady))
    permanent = ((abs(bdxcdy) + abs(cdxbdy)) * alift
                 + (abs(cdxady) + abs(adxcdy)) * blift
                 + (abs(adxbdy) + abs(bdxady)) * clift)
    if (permanent >= _TINY * (1.0 + (alift + blift + clift)) and permanent <= _HUGE
            and abs(det) > _ICC_ERRBOUND_A * permanent):
        return det
    return incircle(ax, ay, bx, by, cx, cy, dx, dy)
