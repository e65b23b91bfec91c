"""Robust three-dimensional geometric predicates, callable from numba code.

The 3D Delaunay tetrahedralisation (:mod:`.delaunay3d`) and the flips that keep a moving mesh
Delaunay decide everything by two signs; a wrong sign from round-off corrupts the adjacency
(cavities that are not star-shaped, flips that invert tetrahedra). Both predicates take float64
scalars and return a float whose *sign* is that of the determinant evaluated exactly on the
given doubles, zero included, to the same standard as the 2D predicates of
:mod:`.predicates`.

``orient3d(a, b, c, d)``
    ``det[b - a, c - a, d - a]``, six times the signed volume of the tetrahedron: positive
    when ``d`` lies on the side of the plane ``a, b, c`` from which ``a, b, c`` turn
    counter-clockwise (a right-handed, "positively oriented" tetrahedron), zero when the
    four points are coplanar. This is the negative of Shewchuk's ``orient3d``.

``insphere(a, b, c, d, e)``
    For a positively oriented ``a, b, c, d``: positive when ``e`` lies strictly inside their
    circumsphere, negative outside, zero on it (the sign flips with the orientation). This is
    the negative of Shewchuk's ``insphere``, so that, as in 2D, "positive" means "inside"
    for positively oriented simplices.

Design
------
1. Float filter: Shewchuk's stage-A bounds (``o3derrboundA = (7 + 56 eps) eps`` and
   ``isperrboundA = (16 + 224 eps) eps`` times the permanent, ``eps = 2**-53``; J. R.
   Shewchuk, Discrete Comput. Geom. 18:305-363, 1997). The ``*_sign`` variants accept when
   ``|det|`` exceeds the bound (sign certified); :func:`orient3d` and :func:`insphere` also
   promise the value to within ``2**-42`` relative and accept only when the bound is below
   that fraction of ``|det|``. The filter is trusted only while the permanent lies in a
   range where nothing overflows and underflow is negligible (``_TINY``, ``_HUGE``).
2. Exact stage: the determinant with rows ``(x, y, z, 1)`` (orient3d) or ``(x, y, z,
   x*x + y*y + z*z, 1)`` (insphere) is expanded by cofactors into 2x2 brackets and evaluated
   with the expansion arithmetic of :mod:`.expansions`. When all coordinate differences to the
   last point are exact (grids, nearby points), they are used instead, with that point at the
   origin; if they moreover lie on a coarse dyadic lattice the plain float formula is exact
   and is returned directly (cubic lattices, the most degenerate input of all, never reach
   the expansions). Coordinates are rescaled by a power of two so that products neither
   overflow nor underflow; the largest component of the compressed expansion carries the
   exact sign and the value to within an ulp. The exact kernels are compiled at import with
   reference counting (eager signatures), like the 2D ones, so that kernels compiled without
   it can call them.

Exactness is lost only if one configuration mixes nonzero coordinates whose magnitudes differ
by more than about ``2**300`` (orient3d) or ``2**150`` (insphere).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .expansions import (
    approximate,
    bracket,
    expansion_sum,
    rescale_exponent,
    scale_exponent,
    scale_expansion,
    two_diff,
    two_product,
    unscale,
)

__all__ = ["orient3d", "insphere", "orient3d_sign", "insphere_sign",
           "orient3d_fast", "insphere_fast", "ORIENT3D_REL_ERROR", "INSPHERE_REL_ERROR"]

_EPS = 2.0 ** -53  # unit roundoff
# Shewchuk's stage-A error bounds (1997, section 4), rounded up by a factor 1 + 2**-40 that
# absorbs the (at most 2**-170 relative) effect of underflow allowed by the range checks.
_O3D_ERRBOUND_A = (7.0 + 56.0 * _EPS) * _EPS * (1.0 + 2.0 ** -40)
_ISP_ERRBOUND_A = (16.0 + 224.0 * _EPS) * _EPS * (1.0 + 2.0 ** -40)

#: Bound on the relative error of the value returned by :func:`orient3d`.
ORIENT3D_REL_ERROR = 2.0 ** -42
#: Bound on the relative error of the value returned by :func:`insphere`.
INSPHERE_REL_ERROR = 2.0 ** -42
_VALUE_FILTER = 2.0 ** 42  # accept the float value when errbound <= 2**-42 |det|

# Range in which the float filters are trusted (permanents scaled as in the 2D predicates:
# an underflowed product is later multiplied by at most a z-coordinate, and a lift).
_TINY = 2.0 ** -900
_HUGE = 2.0 ** 1000

# Dyadic lattices on which the plain float formula is exact: coordinate differences that are
# integers of at most _BITS bits times a common power of two (degree 3: 3 * 16 + 3 <= 53,
# degree 5: 5 * 9 + 7 <= 53), in an exponent range where every product stays normal.
_O3D_BITS, _O3D_MIN_EXP, _O3D_MAX_EXP = 16, -300, 330
_ISP_BITS, _ISP_MIN_EXP, _ISP_MAX_EXP = 9, -180, 190
# Largest exponent of the coordinates before the exact stages scale them down (products of
# degree 3 and 5 must not overflow).
_O3D_SCALE_EXP = 330
_ISP_SCALE_EXP = 190

# Upper bounds on the number of components of the exact expansions.
_B = 4  # bracket [pq] = px*qy - qx*py
_M3 = 3 * _B  # 3x3 determinant with rows (x, y, 1): three brackets
_M4 = 4 * 2 * _M3  # 4x4 with rows (x, y, z, 1): four z * M3
_LIFT = 6  # x*x + y*y + z*z
_T5 = 2 * _LIFT * _M4  # lift * M4
_D5 = 5 * _T5  # the 5x5 insphere determinant
_M3_WORK = 3 * _B + 2 * _B  # three brackets and a partial sum
_M4_WORK = _M3_WORK + _M3 + 2 * _M3 + 2 * _M4
_D5_WORK = _M4_WORK + _M4 + 2 * _M4 + 2 * _T5 + 2 * _D5


# -- lattice shortcut ---------------------------------------------------------------

@njit(cache=True)
def _on_lattice(values, bits, min_exp, max_exp):
    """Whether all values are integer multiples of ``q = 2**(e - bits)``, where ``2**e``
    bounds their magnitudes and ``e`` lies in ``[min_exp, max_exp]`` (see ``_O3D_BITS``)."""
    m = 0.0
    for v in values:
        m = max(m, abs(v))
    if m == 0.0:
        return True
    e = scale_exponent(m)
    if e < min_exp or e > max_exp:
        return False
    q = np.ldexp(1.0, e - bits)
    inv_q = np.ldexp(1.0, bits - e)
    for v in values:
        t = v * inv_q
        if t != np.floor(t) or t * q != v:
            return False
    return True


# -- exact cofactor expansions ----------------------------------------------------------

@njit(cache=True)
def _minor3(P, i, j, k, w, out):
    """``out`` = det of the rows ``(x, y, 1)`` of points i, j, k of P = [ij] + [jk] + [ki]."""
    a = w[0:_B]
    b = w[_B:2 * _B]
    c = w[2 * _B:3 * _B]
    s = w[3 * _B:5 * _B]
    na = bracket(P[i, 0], P[i, 1], P[j, 0], P[j, 1], a)
    nb = bracket(P[j, 0], P[j, 1], P[k, 0], P[k, 1], b)
    nc = bracket(P[k, 0], P[k, 1], P[i, 0], P[i, 1], c)
    ns = expansion_sum(a, na, b, nb, s)
    return expansion_sum(s, ns, c, nc, out)


@njit(cache=True)
def _copy(e, n, out):
    for i in range(n):
        out[i] = e[i]
    return n


@njit(cache=True)
def _minor4(P, rows, w, out):
    """``out`` = det of the rows ``(x, y, z, 1)`` of the four points ``rows`` of P, by
    cofactors of the z column: sum over r of ``(-1)**r z_r M3(other rows)``."""
    o = _M3_WORK
    m3 = w[o:o + _M3]
    zm = w[o + _M3:o + 3 * _M3]
    acc = w[o + 3 * _M3:o + 3 * _M3 + _M4]
    nxt = w[o + 3 * _M3 + _M4:o + 3 * _M3 + 2 * _M4]
    acc[0] = 0.0
    nacc = np.int64(1)  # not a literal 1: one specialization of expansion_sum and _copy
    for r in range(4):
        if r == 0:
            i, j, k = rows[1], rows[2], rows[3]
        elif r == 1:
            i, j, k = rows[0], rows[2], rows[3]
        elif r == 2:
            i, j, k = rows[0], rows[1], rows[3]
        else:
            i, j, k = rows[0], rows[1], rows[2]
        n3 = _minor3(P, i, j, k, w, m3)
        z = P[rows[r], 2] if r % 2 == 0 else -P[rows[r], 2]
        nz = scale_expansion(m3, n3, z, zm)
        nacc = expansion_sum(acc, nacc, zm, nz, nxt)
        acc, nxt = nxt, acc
    return _copy(acc, nacc, out)


@njit(cache=True)
def _det5(P, w):
    """Exact det of the rows ``(x, y, z, x*x + y*y + z*z, 1)`` of the five points of P, by
    cofactors of the lift column: sum over r of ``(-1)**(r + 3) lift_r M4(other rows)``."""
    o = _M4_WORK
    m4 = w[o:o + _M4]
    term = w[o + _M4:o + _M4 + 2 * _M4]
    o += 3 * _M4
    tacc = w[o:o + _T5]
    tnxt = w[o + _T5:o + 2 * _T5]
    o += 2 * _T5
    acc = w[o:o + _D5]
    nxt = w[o + _D5:o + 2 * _D5]
    acc[0] = 0.0
    nacc = np.int64(1)  # not a literal 1: one specialization of expansion_sum, approximate
    lift = np.empty(_LIFT)
    for r in range(5):
        rows = (0, 0, 0, 0)
        if r == 0:
            rows = (1, 2, 3, 4)
        elif r == 1:
            rows = (0, 2, 3, 4)
        elif r == 2:
            rows = (0, 1, 3, 4)
        elif r == 3:
            rows = (0, 1, 2, 4)
        else:
            rows = (0, 1, 2, 3)
        n4 = _minor4(P, rows, w, m4)
        nl = _lift(P[r, 0], P[r, 1], P[r, 2], lift)
        sgn = -1.0 if r % 2 == 0 else 1.0
        tacc[0] = 0.0
        nt = np.int64(1)
        for c in range(nl):
            ns = scale_expansion(m4, n4, sgn * lift[c], term)
            nt = expansion_sum(tacc, nt, term, ns, tnxt)
            tacc, tnxt = tnxt, tacc
        nacc = expansion_sum(acc, nacc, tacc, nt, nxt)
        acc, nxt = nxt, acc
    return approximate(acc, nacc)


@njit(cache=True)
def _lift(x, y, z, out):
    """``out`` = x*x + y*y + z*z exactly (at most six components)."""
    xx = np.empty(2)
    yy = np.empty(2)
    zz = np.empty(2)
    s = np.empty(4)
    xx[1], xx[0] = two_product(x, x)
    yy[1], yy[0] = two_product(y, y)
    zz[1], zz[0] = two_product(z, z)
    ns = expansion_sum(xx, _nonzero(xx), yy, _nonzero(yy), s)
    return expansion_sum(s, ns, zz, _nonzero(zz), out)


@njit(cache=True)
def _nonzero(e2):
    """Drop a zero low component of a two-component expansion (returns its length)."""
    if e2[0] == 0.0:
        e2[0] = e2[1]
        return 1
    return 2


@njit(cache=True)
def _load(P, k, coords):
    """Scale ``coords`` (x, y, z per point) by ``2**-k`` into the rows of P."""
    for i in range(len(coords)):
        P[i // 3, i % 3] = np.ldexp(coords[i], -k)


# -- float formulas ----------------------------------------------------------------------
# Shewchuk's formulas with a and b exchanged (his sign convention is the opposite one); each
# returns (det, permanent) so that the filters share them.

@njit(cache=True)
def _orient3d_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    adx, ady, adz = bx - dx, by - dy, bz - dz
    bdx, bdy, bdz = ax - dx, ay - dy, az - dz
    cdx, cdy, cdz = cx - dx, cy - dy, cz - dz
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    det = (adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy)
           + cdz * (adxbdy - bdxady))
    permanent = ((abs(bdxcdy) + abs(cdxbdy)) * abs(adz)
                 + (abs(cdxady) + abs(adxcdy)) * abs(bdz)
                 + (abs(adxbdy) + abs(bdxady)) * abs(cdz))
    scale = 1.0 + abs(adz) + abs(bdz) + abs(cdz)
    return det, permanent, scale


@njit(cache=True)
def _insphere_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez):
    # Long kernel: Shewchuk's insphere formula and permanent written out term by term; the
    # filter must not allocate and a loop over cofactors would.
    aex, aey, aez = bx - ex, by - ey, bz - ez
    bex, bey, bez = ax - ex, ay - ey, az - ez
    cex, cey, cez = cx - ex, cy - ey, cz - ez
    dex, dey, dez = dx - ex, dy - ey, dz - ez
    aexbey = aex * bey
    bexaey = bex * aey
    ab = aexbey - bexaey
    bexcey = bex * cey
    cexbey = cex * bey
    bc = bexcey - cexbey
    cexdey = cex * dey
    dexcey = dex * cey
    cd = cexdey - dexcey
    dexaey = dex * aey
    aexdey = aex * dey
    da = dexaey - aexdey
    aexcey = aex * cey
    cexaey = cex * aey
    ac = aexcey - cexaey
    bexdey = bex * dey
    dexbey = dex * bey
    bd = bexdey - dexbey
    abc = aez * bc - bez * ac + cez * ab
    bcd = bez * cd - cez * bd + dez * bc
    cda = cez * da + dez * ac + aez * cd
    dab = dez * ab + aez * bd + bez * da
    alift = aex * aex + aey * aey + aez * aez
    blift = bex * bex + bey * bey + bez * bez
    clift = cex * cex + cey * cey + cez * cez
    dlift = dex * dex + dey * dey + dez * dez
    det = (dlift * abc - clift * dab) + (blift * cda - alift * bcd)
    aezp, bezp, cezp, dezp = abs(aez), abs(bez), abs(cez), abs(dez)
    aexbeyp, bexaeyp = abs(aexbey), abs(bexaey)
    bexceyp, cexbeyp = abs(bexcey), abs(cexbey)
    cexdeyp, dexceyp = abs(cexdey), abs(dexcey)
    dexaeyp, aexdeyp = abs(dexaey), abs(aexdey)
    aexceyp, cexaeyp = abs(aexcey), abs(cexaey)
    bexdeyp, dexbeyp = abs(bexdey), abs(dexbey)
    permanent = (((cexdeyp + dexceyp) * bezp + (dexbeyp + bexdeyp) * cezp
                  + (bexceyp + cexbeyp) * dezp) * alift
                 + ((dexaeyp + aexdeyp) * cezp + (aexceyp + cexaeyp) * dezp
                    + (cexdeyp + dexceyp) * aezp) * blift
                 + ((aexbeyp + bexaeyp) * dezp + (bexdeyp + dexbeyp) * aezp
                    + (dexaeyp + aexdeyp) * bezp) * clift
                 + ((bexceyp + cexbeyp) * aezp + (cexaeyp + aexceyp) * bezp
                    + (aexbeyp + bexaeyp) * cezp) * dlift)
    lifts = 1.0 + alift + blift + clift + dlift
    return det, permanent, lifts * lifts


@njit(cache=True)
def orient3d_fast(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """Plain floating-point :func:`orient3d`; no robustness guarantee."""
    return _orient3d_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)[0]


@njit(cache=True)
def insphere_fast(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez):
    """Plain floating-point :func:`insphere`; no robustness guarantee."""
    return _insphere_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez)[0]


_EXACT_ORIENT3D = "float64(" + ", ".join(["float64"] * 12) + ")"
_EXACT_INSPHERE = "float64(" + ", ".join(["float64"] * 15) + ")"


@njit(_EXACT_ORIENT3D, cache=True)
def _orient3d_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """Exact :func:`orient3d`, rounded to a float (= det4 with rows b, a, c, d)."""
    u = two_diff(ax, dx) + two_diff(ay, dy) + two_diff(az, dz)
    v = two_diff(bx, dx) + two_diff(by, dy) + two_diff(bz, dz)
    w = two_diff(cx, dx) + two_diff(cy, dy) + two_diff(cz, dz)
    if (u[1] == 0.0 and u[3] == 0.0 and u[5] == 0.0 and v[1] == 0.0 and v[3] == 0.0
            and v[5] == 0.0 and w[1] == 0.0 and w[3] == 0.0 and w[5] == 0.0):
        d9 = (u[0], u[2], u[4], v[0], v[2], v[4], w[0], w[2], w[4])
        if _on_lattice(d9, _O3D_BITS, _O3D_MIN_EXP, _O3D_MAX_EXP):
            return orient3d_fast(u[0], u[2], u[4], v[0], v[2], v[4], w[0], w[2], w[4],
                                 0.0, 0.0, 0.0)
        ax, ay, az, bx, by, bz = u[0], u[2], u[4], v[0], v[2], v[4]
        cx, cy, cz, dx, dy, dz = w[0], w[2], w[4], 0.0, 0.0, 0.0
    m = max(abs(ax), abs(ay), abs(az), abs(bx), abs(by), abs(bz),
            abs(cx), abs(cy), abs(cz), abs(dx), abs(dy), abs(dz))
    if m == 0.0:
        return 0.0
    k = rescale_exponent(m, _O3D_SCALE_EXP)
    P = np.empty((4, 3))
    _load(P, k, (bx, by, bz, ax, ay, az, cx, cy, cz, dx, dy, dz))
    work = np.empty(_M4_WORK + _M4)
    det = work[_M4_WORK:]
    # the rows as int64s, not a tuple of literals: one specialization of _minor4
    n = _minor4(P, (np.int64(0), np.int64(1), np.int64(2), np.int64(3)), work, det)
    return unscale(approximate(det, n), 3 * k)


@njit(_EXACT_INSPHERE, cache=True)
def _insphere_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez):
    """Exact :func:`insphere`, rounded to a float (= det5 with rows b, a, c, d, e)."""
    u = two_diff(ax, ex) + two_diff(ay, ey) + two_diff(az, ez)
    v = two_diff(bx, ex) + two_diff(by, ey) + two_diff(bz, ez)
    w = two_diff(cx, ex) + two_diff(cy, ey) + two_diff(cz, ez)
    t = two_diff(dx, ex) + two_diff(dy, ey) + two_diff(dz, ez)
    if (u[1] == 0.0 and u[3] == 0.0 and u[5] == 0.0 and v[1] == 0.0 and v[3] == 0.0
            and v[5] == 0.0 and w[1] == 0.0 and w[3] == 0.0 and w[5] == 0.0
            and t[1] == 0.0 and t[3] == 0.0 and t[5] == 0.0):
        d12 = (u[0], u[2], u[4], v[0], v[2], v[4], w[0], w[2], w[4], t[0], t[2], t[4])
        if _on_lattice(d12, _ISP_BITS, _ISP_MIN_EXP, _ISP_MAX_EXP):
            return insphere_fast(u[0], u[2], u[4], v[0], v[2], v[4], w[0], w[2], w[4],
                                 t[0], t[2], t[4], 0.0, 0.0, 0.0)
        ax, ay, az, bx, by, bz = u[0], u[2], u[4], v[0], v[2], v[4]
        cx, cy, cz, dx, dy, dz = w[0], w[2], w[4], t[0], t[2], t[4]
        ex, ey, ez = 0.0, 0.0, 0.0
    m = max(abs(ax), abs(ay), abs(az), abs(bx), abs(by), abs(bz), abs(cx), abs(cy),
            abs(cz), abs(dx), abs(dy), abs(dz), abs(ex), abs(ey), abs(ez))
    if m == 0.0:
        return 0.0
    k = rescale_exponent(m, _ISP_SCALE_EXP)
    P = np.empty((5, 3))
    _load(P, k, (bx, by, bz, ax, ay, az, cx, cy, cz, dx, dy, dz, ex, ey, ez))
    return unscale(_det5(P, np.empty(_D5_WORK)), 5 * k)


# -- public predicates ------------------------------------------------------------------

@njit(cache=True)
def orient3d(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """Robust ``det[b - a, c - a, d - a]``: positive for a positively oriented
    tetrahedron, ``0.0`` if and only if the four points are coplanar, as in exact
    arithmetic on the given doubles; the value within :data:`ORIENT3D_REL_ERROR`."""
    det, perm, scale = _orient3d_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)
    if (_TINY * scale <= perm <= _HUGE
            and abs(det) >= _VALUE_FILTER * (_O3D_ERRBOUND_A * perm)):
        return det
    return _orient3d_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)


@njit(cache=True)
def insphere(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez):
    """Robust in-sphere test of ``e`` against the sphere through ``a, b, c, d``: for a
    positively oriented ``a, b, c, d`` positive strictly inside, negative outside, ``0.0``
    on it (or for coplanar ``a, b, c, d`` with ``e`` on their circle), as in exact arithmetic
    on the given doubles; the value within :data:`INSPHERE_REL_ERROR`."""
    det, perm, scale = _insphere_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz,
                                       ex, ey, ez)
    if (_TINY * scale <= perm <= _HUGE
            and abs(det) >= _VALUE_FILTER * (_ISP_ERRBOUND_A * perm)):
        return det
    return _insphere_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez)


@njit(cache=True)
def orient3d_sign(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """:func:`orient3d` for callers that need only the sign (walks, cavities, flips):
    the float value when it exceeds Shewchuk's bound, else the exact one."""
    det, perm, scale = _orient3d_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)
    if _TINY * scale <= perm <= _HUGE and abs(det) > _O3D_ERRBOUND_A * perm:
        return det
    return _orient3d_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)


@njit(cache=True)
def insphere_sign(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez):
    """:func:`insphere` for callers that need only the sign."""
    det, perm, scale = _insphere_float(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz,
                                       ex, ey, ez)
    if _TINY * scale <= perm <= _HUGE and abs(det) > _ISP_ERRBOUND_A * perm:
        return det
    return _insphere_exact(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz, ex, ey, ez)
