"""Error-free transformations and floating-point expansion arithmetic.

The exact stages of the robust predicates (:mod:`.predicates` in 2D, :mod:`.predicates3d` in
3D) evaluate determinants exactly as sums of nonoverlapping doubles, after J. R. Shewchuk,
"Adaptive Precision Floating-Point Arithmetic and Fast Robust Geometric Predicates", Discrete &
Computational Geometry 18:305-363 (1997). The primitives live here so that both predicate
modules share one audited copy. All of them assume IEEE 754 double precision with
round-to-nearest-even and no fused multiply-add contraction (numba without ``fastmath``).
"""
from __future__ import annotations

import math

from numba import njit

__all__ = ["two_sum", "fast_two_sum", "two_diff", "split", "two_product_presplit",
           "two_product", "two_two_diff", "bracket", "expansion_sum", "scale_expansion",
           "approximate", "scale_exponent", "rescale_exponent", "unscale",
           "SPLITTER", "SMALLEST_SUBNORMAL"]

SPLITTER = 2.0 ** 27 + 1.0  # Veltkamp splitter for 53-bit significands
SMALLEST_SUBNORMAL = 5e-324


# -- error-free transformations ----------------------------------------------

@njit(cache=True)
def two_sum(a, b):
    """Return ``(x, y)`` with ``x = fl(a + b)`` and ``x + y = a + b`` exactly."""
    x = a + b
    b_virtual = x - a
    a_virtual = x - b_virtual
    return x, (a - a_virtual) + (b - b_virtual)


@njit(cache=True)
def fast_two_sum(a, b):
    """As :func:`two_sum`, valid when ``|a| >= |b|`` (or ``a`` has the larger
    exponent)."""
    x = a + b
    return x, b - (x - a)


@njit(cache=True)
def two_diff(a, b):
    """Return ``(x, y)`` with ``x = fl(a - b)`` and ``x + y = a - b`` exactly."""
    x = a - b
    b_virtual = a - x
    a_virtual = x + b_virtual
    return x, (a - a_virtual) + (b_virtual - b)


@njit(cache=True)
def split(a):
    """Veltkamp split: ``a = hi + lo`` with both halves of at most 26 bits."""
    c = SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


@njit(cache=True)
def two_product_presplit(a, b, b_hi, b_lo):
    """Dekker's product ``x + y = a * b`` with ``b`` already split."""
    x = a * b
    a_hi, a_lo = split(a)
    err = ((x - a_hi * b_hi) - a_lo * b_hi) - a_hi * b_lo
    return x, a_lo * b_lo - err


@njit(cache=True)
def two_product(a, b):
    """Return ``(x, y)`` with ``x = fl(a * b)`` and ``x + y = a * b`` exactly."""
    b_hi, b_lo = split(b)
    return two_product_presplit(a, b, b_hi, b_lo)


@njit(cache=True)
def two_two_diff(a1, a0, b1, b0):
    """``(a1 + a0) - (b1 + b0)`` as a 4-component nonoverlapping expansion.

    Both operands must be two-component expansions (``|a0|`` at most half an
    ulp of ``a1``).  The components are returned in order of increasing
    magnitude; some of them may be zero.
    """
    # Subtract b0, then b1, each time carrying the partial expansion upward.
    i, x0 = two_diff(a0, b0)
    j, k = two_sum(a1, i)
    i, x1 = two_diff(k, b1)
    x3, x2 = two_sum(j, i)
    return x0, x1, x2, x3


# -- expansion arithmetic ----------------------------------------------------
# An expansion is stored as ``(array, length)``: components in order of
# increasing magnitude, pairwise nonoverlapping, zero components removed (the
# zero expansion is the single component 0.0).

@njit(cache=True)
def bracket(px, py, qx, qy, h):
    """Store ``px*qy - qx*py`` exactly in ``h``; return its length."""
    s1, s0 = two_product(px, qy)
    t1, t0 = two_product(qx, py)
    x0, x1, x2, x3 = two_two_diff(s1, s0, t1, t0)
    n = 0
    if x0 != 0.0:
        h[n] = x0
        n += 1
    if x1 != 0.0:
        h[n] = x1
        n += 1
    if x2 != 0.0:
        h[n] = x2
        n += 1
    if x3 != 0.0 or n == 0:
        h[n] = x3
        n += 1
    return n


@njit(cache=True)
def expansion_sum(e, elen, f, flen, h):
    """``h = e + f`` (Shewchuk's fast_expansion_sum_zeroelim).

    The components of ``e`` and ``f`` are merged by increasing magnitude and
    accumulated with error-free additions; the nonzero roundoff terms form the
    result, which is strongly nonoverlapping if the inputs are.  ``h`` must
    not alias ``e`` or ``f`` and needs room for ``elen + flen`` entries.
    """
    i = 0
    j = 0
    if abs(f[0]) < abs(e[0]):
        q = f[0]
        j = 1
    else:
        q = e[0]
        i = 1
    n = 0
    while i < elen or j < flen:
        if j >= flen or (i < elen and abs(e[i]) <= abs(f[j])):
            g = e[i]
            i += 1
        else:
            g = f[j]
            j += 1
        q, err = two_sum(q, g)
        if err != 0.0:
            h[n] = err
            n += 1
    if q != 0.0 or n == 0:
        h[n] = q
        n += 1
    return n


@njit(cache=True)
def scale_expansion(e, elen, b, h):
    """``h = b * e`` (Shewchuk's scale_expansion_zeroelim).

    ``h`` must not alias ``e`` and needs room for ``2 * elen`` entries.
    """
    b_hi, b_lo = split(b)
    q, err = two_product_presplit(e[0], b, b_hi, b_lo)
    n = 0
    if err != 0.0:
        h[n] = err
        n += 1
    for i in range(1, elen):
        p1, p0 = two_product_presplit(e[i], b, b_hi, b_lo)
        s, err = two_sum(q, p0)
        if err != 0.0:
            h[n] = err
            n += 1
        q, err = fast_two_sum(p1, s)
        if err != 0.0:
            h[n] = err
            n += 1
    if q != 0.0 or n == 0:
        h[n] = q
        n += 1
    return n


@njit(cache=True)
def approximate(e, elen):
    """Float approximation of an expansion, computed by compressing it in place.

    Shewchuk's ``compress``: a downward pass renormalises the expansion from
    its largest component, an upward pass then accumulates it from the
    smallest.  The final accumulator is the largest component of the
    compressed expansion, which has the sign of the exact sum and
    approximates it within about one ulp.  ``e`` is overwritten.
    """
    bottom = elen - 1
    q = e[bottom]
    for i in range(elen - 2, -1, -1):
        q, small = two_sum(q, e[i])
        if small != 0.0:
            e[bottom] = q
            bottom -= 1
            q = small
    e[bottom] = q
    for i in range(bottom + 1, elen):
        q, _ = two_sum(e[i], q)
    return q


# -- power-of-two rescaling of the exact stages ------------------------------

@njit(cache=True)
def scale_exponent(m):
    """Exponent ``k`` with ``m * 2**-k`` in ``[0.5, 1)`` (``m > 0``)."""
    return math.frexp(m)[1]


@njit(cache=True)
def rescale_exponent(m, max_exp):
    """Power of two ``k`` by which to divide coordinates of magnitude at most
    ``m`` before the exact evaluation.

    Small configurations are always scaled up to ``m`` in ``[0.5, 1)``, which
    loses nothing and keeps products away from underflow.  Large ones are
    scaled down only when products could overflow (exponent above
    ``max_exp``), since scaling down can push the smallest coordinates into
    the subnormal range.
    """
    k = scale_exponent(m)
    if 0 < k <= max_exp:
        return 0
    return k


@njit(cache=True)
def unscale(v, k):
    """``v * 2**k``, saturating to the smallest subnormal instead of zero."""
    r = math.ldexp(v, k)
    if r == 0.0 and v != 0.0:
        r = math.copysign(SMALLEST_SUBNORMAL, v)
    return r
