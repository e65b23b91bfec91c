"""Scattered-data interpolation: NaturalNeighbourInterpolator against scipy, in one run.

2D: ``--points`` random points in the unit square (its corners and random points on its
sides among them, so that the grid lies in the hull), values of Franke's function,
interpolated on a ``--grid`` x ``--grid`` grid of the square by each method of
``skfem_nem.NaturalNeighbourInterpolator`` and by scipy's ``LinearNDInterpolator``,
``CloughTocher2DInterpolator`` and ``NearestNDInterpolator``.
3D: ``--points-3d`` random points in the unit cube (plus its corners), ``--queries-3d``
random queries inside, against scipy's linear and nearest interpolants and natinterp3d's
Sibson interpolation when it is installed (``pip install natinterp3d``; optional).

Every triangulation is built once (the "triangulation" row; Qhull for scipy, the package's
checked Delaunay triangulation for ours, in 3D its ``Delaunay3D``) and handed to each
interpolator; "build" is the rest of the set-up (for ``sibson1``, ``farin`` and
Clough-Tocher, the gradient estimate). Calls are
timed warm, best of ``--repeats``: a first small call loads the numba kernels (their one-time
load from numba's cache, or compilation on a fresh install, is printed apart). "gradient" is
``itp.gradient`` (values and exact gradients); errors are against the exact function at the
queries.

Franke's six test functions (Franke 1979, as in Renka and Brown's TOMS Algorithm 792 tests):
100 data points in the unit square (Franke's own set, or ``--franke-points random``), max and
mean errors on the 33 x 33 grid at the grid points inside the data's hull, every 2D method
beside scipy's linear and Clough-Tocher interpolants, and the C1 methods from other
gradients (the "direct" estimate, Clough-Tocher's, exact). The gradient estimates on the
``--points`` set: seconds and errors of each, against scipy's global estimate.
MetPy (optional: ``pip install metpy`` or the ``bench`` extra):
its ``natural_neighbor_to_grid`` against ours on ``--metpy-points`` random points and a
``--metpy-grid`` square grid (MetPy takes about a minute for the defaults), and on a grid
through lattice data.

    python benchmarks/interpolation.py [--points 100000] [--grid 1000]
        [--points-3d 20000] [--queries-3d 100000] [--repeats 2] [--no-3d] [--scatter-only]
        [--franke-points franke|random] [--metpy-points 10000] [--metpy-grid 100] [--no-metpy]
"""
import argparse
import time

import numpy as np
from scipy.interpolate import (CloughTocher2DInterpolator, LinearNDInterpolator,
                               NearestNDInterpolator)
from scipy.spatial import Delaunay

from skfem_nem import NaturalNeighbourInterpolator, Triangulation, estimate_gradients
from skfem_nem.geometry.delaunay3d import Delaunay3D


def franke(x, y):
    return (0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
            + 0.75 * np.exp(-(9 * x + 1) ** 2 / 49 - (9 * y + 1) / 10)
            + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
            - 0.2 * np.exp(-(9 * x - 4) ** 2 - (9 * y - 7) ** 2))


def smooth_3d(p):
    return np.sin(3 * p[..., 0]) * np.cos(2 * p[..., 1]) + p[..., 2] ** 2


def cube_points(n, d, seed):
    """n points: the corners of the unit square or cube, in 2D also sqrt(n) random points on
    each side (on the hull every method is linear between the data on it), the rest random
    inside."""
    rng = np.random.default_rng(seed)
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * d, indexing="ij")).reshape(d, -1).T
    parts = [corners]
    if d == 2:
        s = rng.random((4, int(np.sqrt(n))))
        parts += [np.c_[s[0], 0 * s[0]], np.c_[s[1], 1 + 0 * s[1]], np.c_[0 * s[2], s[2]],
                  np.c_[1 + 0 * s[3], s[3]]]
    k = sum(a.shape[0] for a in parts)
    return np.r_[tuple(parts) + (rng.random((n - k, d)),)]


def best(fn, repeats):
    """(result, best seconds) of ``repeats`` calls."""
    out, t = None, np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        t = min(t, time.perf_counter() - t0)
    return out, t


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def kernel_load():
    """Seconds of the first calls of every method on a small set (numba's kernels loaded)."""
    t0 = time.perf_counter()
    for d, methods in ((2, ["sibson", "laplace", "sibson1", "farin", "linear", "nearest"]),
                       (3, ["sibson", "sibson1", "farin", "linear", "nearest"])):
        p = cube_points(60, d, seed=1)
        for m in methods:
            itp = NaturalNeighbourInterpolator(p, p[:, 0], method=m)
            itp.gradient(0.3 + 0.4 * p[:5])
    return time.perf_counter() - t0


def row(name, build, call, grad, value, exact):
    err = value - exact
    ok = np.isfinite(err)
    rms = np.sqrt(np.mean(err[ok] ** 2))
    g = "" if grad is None else f"{grad:.3f}"
    return (f"| {name} | {build:.3f} | {call:.3f} | {g} | {rms:.2e} | {np.abs(err[ok]).max():.2e}"
            f" | {int((~ok).sum())} |")


HEADER = ("| method | build s | call s | gradient s | rms error | max error | NaN |\n"
          "|---|---|---|---|---|---|---|")


def study_2d(n, grid, repeats):
    p = cube_points(n, 2, seed=0)
    f = franke(p[:, 0], p[:, 1])
    x, y = np.meshgrid(np.linspace(0, 1, grid), np.linspace(0, 1, grid))
    exact = franke(x, y)
    tri, t_tri = timed(lambda: Triangulation(p))
    dl, t_qhull = timed(lambda: Delaunay(p))
    lines = [f"2D: {n:,} points, {grid} x {grid} = {grid * grid:,} grid queries", "", HEADER,
             f"| triangulation (ours / Qhull) | {t_tri:.3f} / {t_qhull:.3f} | | | | | |"]
    for m in ("sibson", "laplace", "sibson1", "farin", "linear", "nearest"):
        itp, tb = timed(lambda: NaturalNeighbourInterpolator(tri, f, method=m))
        v, tc = best(lambda: itp(x, y), repeats)
        _, tg = best(lambda: itp.gradient(x, y), repeats)
        lines.append(row(m, tb, tc, tg, v, exact))
    for name, cls in (("scipy LinearNDInterpolator", LinearNDInterpolator),
                      ("scipy CloughTocher2DInterpolator", CloughTocher2DInterpolator),
                      ("scipy NearestNDInterpolator", NearestNDInterpolator)):
        src = p if cls is NearestNDInterpolator else dl
        itp, tb = timed(lambda: cls(src, f))
        itp(x[:2, :2], y[:2, :2])
        v, tc = best(lambda: itp(x, y), repeats)
        lines.append(row(name, tb, tc, None, v, exact))
    return lines


def study_3d(n, m, repeats):
    p = cube_points(n, 3, seed=0)
    f = smooth_3d(p)
    q = 0.02 + 0.96 * np.random.default_rng(1).random((m, 3))
    exact = smooth_3d(q)
    own, t_tri = timed(lambda: Delaunay3D(p))
    dl, t_qhull = timed(lambda: Delaunay(p))
    lines = [f"3D: {n:,} points, {m:,} random queries", "", HEADER,
             f"| triangulation (ours / Qhull) | {t_tri:.3f} / {t_qhull:.3f} | | | | | |"]
    for meth in ("sibson", "sibson1", "farin", "linear", "nearest"):
        itp, tb = timed(lambda: NaturalNeighbourInterpolator(own, f, method=meth))
        v, tc = best(lambda: itp(q), repeats)
        _, tg = best(lambda: itp.gradient(q), repeats)
        lines.append(row(meth, tb, tc, tg, v, exact))
    for name, cls in (("scipy LinearNDInterpolator", LinearNDInterpolator),
                      ("scipy NearestNDInterpolator", NearestNDInterpolator)):
        itp, tb = timed(lambda: cls(dl if cls is LinearNDInterpolator else p, f))
        itp(q[:5])
        v, tc = best(lambda: itp(q), repeats)
        lines.append(row(name, tb, tc, None, v, exact))
    try:
        import natinterp3d
    except ImportError:
        lines.append("| natinterp3d | not installed | | | | | |")
    else:
        natinterp3d.Interpolator(p[:50]).interpolate(q[:5], f[:50])
        v, tc = best(lambda: natinterp3d.Interpolator(p).interpolate(q, f), repeats)
        lines.append(row("natinterp3d (Sibson)", 0.0, tc, None, np.asarray(v), exact))
    return lines


# Franke's 100 data points in the unit square (Franke 1979; data set 1 of Renka and Brown's
# TOMS Algorithm 792 accuracy tests), x then y
FRANKE_NODES = """
0.0227035 0.0539888 0.0217008 0.0175129 0.0019029 -0.0509685 0.0395408 -0.0487061 0.0315828
-0.0418785 0.1324189 0.1090271 0.1254439 0.0934540 0.0767578 0.1451874 0.0626494 0.1452734
0.0958668 0.0695559 0.2645602 0.2391645 0.2088990 0.2767329 0.1714726 0.2266781 0.1909212
0.1867647 0.2304634 0.2426219 0.3663168 0.3857662 0.3832392 0.3179087 0.3466321 0.3776591
0.3873159 0.3812917 0.3795364 0.2803515 0.4149771 0.4277679 0.4200010 0.4663631 0.4855658
0.4092026 0.4792578 0.4812279 0.3977761 0.4027321 0.5848691 0.5730076 0.6063893 0.5013894
0.5741311 0.6106955 0.5990105 0.5380621 0.6096967 0.5026188 0.6616928 0.6427836 0.6396475
0.6703963 0.7001181 0.6333590 0.6908947 0.6895638 0.6718889 0.6837675 0.7736939 0.7635332
0.7410424 0.8258981 0.7306034 0.8086609 0.8214531 0.7290640 0.8076643 0.8170951 0.8424572
0.8684053 0.8366923 0.9418461 0.8478122 0.8599583 0.9175700 0.8596328 0.9279871 0.8512805
1.0449820 0.9670631 0.9857884 0.9676313 1.0129299 0.9657040 1.0019855 1.0359297 1.0414677
0.9471506
-0.0310206 0.1586742 0.2576924 0.3414014 0.4943596 0.5782854 0.6993418 0.7470194 0.9107649
0.9962890 0.0501330 0.0918555 0.2592973 0.3381592 0.4171125 0.5615563 0.6552235 0.7524066
0.9146523 0.9632421 0.0292939 0.0602303 0.2668783 0.3696044 0.4801738 0.5940595 0.6878797
0.8185576 0.9046507 0.9805412 0.0396955 0.0684484 0.2389548 0.3124129 0.4902989 0.5199303
0.6445227 0.8203789 0.8938079 0.9711719 -0.0284618 0.1560965 0.2262471 0.3175094 0.3891417
0.5084949 0.6324247 0.7511007 0.8489712 0.9978728 -0.0271948 0.1272430 0.2709269 0.3477728
0.4259422 0.6084711 0.6733781 0.7235242 0.9242411 1.0308762 0.0255959 0.0707835 0.2008336
0.3259843 0.4890704 0.5096324 0.6697880 0.7759569 0.9366096 1.0064516 0.0285374 0.1021403
0.1936581 0.3235775 0.4714228 0.6091595 0.6685053 0.8022808 0.8476790 1.0512371 0.0380499
0.0902048 0.2083092 0.3318491 0.4335632 0.5910139 0.6307383 0.8144841 0.9042310 0.9696030
-0.0120900 0.1334114 0.2695844 0.3795281 0.4396054 0.5044425 0.6941519 0.7459923 0.8682081
0.9801409
"""
# Franke's six test functions F1..F6 (exponential, cliff, saddle, gentle, steep, sphere), as
# in Renka and Brown's tests; F1 is ``franke`` above
FRANKE_FUNCTIONS = (
    franke,
    lambda x, y: (np.tanh(9 * (y - x)) + 1) / 9,
    lambda x, y: (1.25 + np.cos(5.4 * y)) / (6 + 6 * (3 * x - 1) ** 2),
    lambda x, y: np.exp(-81 / 16 * ((x - 0.5) ** 2 + (y - 0.5) ** 2)) / 3,
    lambda x, y: np.exp(-81 / 4 * ((x - 0.5) ** 2 + (y - 0.5) ** 2)) / 3,
    lambda x, y: np.sqrt(np.maximum(64 - 81 * ((x - 0.5) ** 2 + (y - 0.5) ** 2), 0)) / 9 - 0.5,
)
# the grid of Renka and Brown's error measure
FRANKE_GRID = 33
FRANKE_METHODS = ("sibson", "laplace", "sibson1", "farin", "linear", "nearest")


def franke_points(which="franke"):
    """The (100, 2) data points of the Franke study: Franke's node set (its hull sticks out
    of the unit square a little and misses parts of it), or ``"random"``: 100 uniform random
    points in the square, seed 0."""
    if which == "random":
        return np.random.default_rng(0).random((100, 2))
    return np.array(FRANKE_NODES.split(), dtype=float).reshape(2, 100).T


def franke_errors(p, k):
    """{interpolant: (max, mean) absolute error} of Franke's function F``k`` (1..6) from the
    data points p on the 33 x 33 grid of the unit square, over the grid points inside the
    data's convex hull (scipy gives NaN outside); and the number of those points."""
    fk = FRANKE_FUNCTIONS[k - 1]
    x, y = np.meshgrid(*[np.linspace(0, 1, FRANKE_GRID)] * 2)
    tri, dl, f = Triangulation(p), Delaunay(p), fk(p[:, 0], p[:, 1])
    inside = dl.find_simplex(np.c_[x.ravel(), y.ravel()]).reshape(x.shape) >= 0
    truth = fk(x, y)[inside]
    values = {m: NaturalNeighbourInterpolator(tri, f, method=m)(x, y) for m in FRANKE_METHODS}
    values["scipy LinearND"] = LinearNDInterpolator(dl, f)(x, y)
    ct = CloughTocher2DInterpolator(dl, f)
    values["scipy CloughTocher2D"] = ct(x, y)
    # the C1 interpolants (by default from the "global" gradient estimate) from other
    # gradients: the "direct" estimate, Clough-Tocher's (scipy's global estimate, its
    # interpolant's attribute ``grad``) and the exact ones (central differences, exact to
    # about 1e-10)
    h = 1e-6
    exact = np.c_[fk(p[:, 0] + h, p[:, 1]) - fk(p[:, 0] - h, p[:, 1]),
                  fk(p[:, 0], p[:, 1] + h) - fk(p[:, 0], p[:, 1] - h)] / (2 * h)
    for label, g in (("direct", estimate_gradients(tri, f, method="direct")),
                     ("Clough-Tocher's", getattr(ct, "grad", None)), ("exact", exact)):
        for m in ("sibson1", "farin") if g is not None else ():
            values[f"{m}, {label} gradients"] = NaturalNeighbourInterpolator(
                tri, f, method=m, gradients=np.reshape(g, (-1, 2)))(x, y)
    err = {name: np.abs(v[inside] - truth) for name, v in values.items()}
    return {name: (e.max(), e.mean()) for name, e in err.items()}, int(inside.sum())


def study_franke(which="franke"):
    """Franke's six functions, 100 points, errors on the 33 x 33 grid (markdown table)."""
    p = franke_points(which)
    errors = [franke_errors(p, k) for k in range(1, 7)]
    names = list(errors[0][0])
    what = ("Franke's 100 data points (Renka and Brown's data set 1)" if which == "franke"
            else "100 uniform random points (seed 0)")
    lines = [f"Franke's functions F1..F6: {what}, errors on the {FRANKE_GRID} x {FRANKE_GRID} "
             f"grid of the unit square at the {errors[0][1]} grid points inside the data's "
             f"convex hull; max error / mean error", "",
             "| interpolant | " + " | ".join(f"F{k}" for k in range(1, 7)) + " |",
             "|---" * 7 + "|"]
    for name in names:
        cells = [f"{e[name][0]:.2e} / {e[name][1]:.2e}" for e, _ in errors]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def gradient_costs(n, repeats):
    """Seconds and errors of the gradient estimates at n random points (seed 0) of the unit
    square, Franke's function: ``estimate_gradients``' methods and scipy's global estimate
    (the set-up of ``CloughTocher2DInterpolator``, its default tolerance), all on one
    prebuilt triangulation each (markdown lines)."""
    p = cube_points(n, 2, seed=0)
    f = franke(p[:, 0], p[:, 1])
    h = 1e-6
    exact = np.c_[franke(p[:, 0] + h, p[:, 1]) - franke(p[:, 0] - h, p[:, 1]),
                  franke(p[:, 0], p[:, 1] + h) - franke(p[:, 0], p[:, 1] - h)] / (2 * h)
    tri, dl = Triangulation(p), Delaunay(p)
    estimate_gradients(Triangulation(p[:50]), f[:50], method="global")     # kernels loaded
    lines = [f"Gradient estimates: {n:,} points, Franke's function", "",
             "| estimate | seconds | rms error | max error |", "|---|---|---|---|"]
    runs = [(f"estimate_gradients {m!r}", lambda m=m: estimate_gradients(tri, f, method=m))
            for m in ("direct", "global")]
    runs.append(("scipy CloughTocher2DInterpolator (global)",
                 lambda: np.reshape(CloughTocher2DInterpolator(dl, f).grad, (-1, 2))))
    for name, fn in runs:
        g, t = best(fn, repeats)
        e = np.abs(g - exact)
        lines.append(f"| {name} | {t:.3f} | {np.sqrt(np.mean(e ** 2)):.2e} | {e.max():.2e} |")
    return lines


# the bar of the MetPy comparison: the same Sibson values up to round-off of the two
# different area computations (measured: 3e-13 on 10,000 random points)
METPY_AGREEMENT = 1e-10


def compare_metpy(n, grid):
    """MetPy's ``natural_neighbor_to_grid`` against ours: n random points in the unit square
    (seed 0), Franke's function, a grid x grid grid of the square; end to end (each builds
    its triangulation), both warm (a first small call each). Markdown lines; one line if
    MetPy is not installed."""
    try:
        from metpy.interpolate import natural_neighbor_to_grid
    except ImportError:
        return ["MetPy: not installed (optional: pip install metpy)"]
    from skfem_nem import natural_neighbour_to_grid
    p = np.random.default_rng(0).random((n, 2))
    xp, yp, z = p[:, 0], p[:, 1], franke(p[:, 0], p[:, 1])
    gx, gy = np.meshgrid(*[np.linspace(0, 1, grid)] * 2)
    for warm_up in (natural_neighbour_to_grid, natural_neighbor_to_grid):
        warm_up(xp[:50], yp[:50], z[:50], gx[1:3, 1:3], gy[1:3, 1:3])
    ours, t_ours = best(lambda: natural_neighbour_to_grid(xp, yp, z, gx, gy), 2)
    theirs, t_metpy = timed(lambda: np.asarray(natural_neighbor_to_grid(xp, yp, z, gx, gy)))
    both = np.isfinite(ours) & np.isfinite(theirs)
    diff = np.abs(ours - theirs)[both]
    agree = "yes" if diff.size and diff.max() <= METPY_AGREEMENT else "NO"
    return [f"MetPy natural_neighbor_to_grid: {n:,} random points, {grid} x {grid} grid", "",
            "| | seconds | NaN (outside the hull) |", "|---|---|---|",
            f"| MetPy | {t_metpy:.2f} | {int(np.isnan(theirs).sum())} |",
            f"| skfem_nem.natural_neighbour_to_grid | {t_ours:.3f} | "
            f"{int(np.isnan(ours).sum())} |", "",
            f"max difference {diff.max():.1e} at the {both.sum():,} grid points both define; "
            f"NaN at different grid points: {int((np.isnan(ours) != np.isnan(theirs)).sum())}; "
            f"same values to {METPY_AGREEMENT:g}: {agree}; MetPy / ours time: "
            f"{t_metpy / t_ours:.0f}"]


def metpy_through_data(k=11, grid=21):
    """Grid points on data points and on Delaunay edges: the data on a k x k lattice of the
    unit square, a grid x grid grid through it, MetPy's ``natural_neighbor_to_points`` called
    point by point (to count its failures one by one) against ours. Markdown lines."""
    import logging
    try:
        from metpy.interpolate import natural_neighbor_to_points
    except ImportError:
        return []
    s = np.linspace(0, 1, k)
    p = np.array(np.meshgrid(s, s)).reshape(2, -1).T
    z = np.sin(3 * p[:, 0]) + p[:, 1]
    q = np.array(np.meshgrid(*[np.linspace(0, 1, grid)] * 2)).reshape(2, -1).T
    ours = NaturalNeighbourInterpolator(p, z)(q)
    raised, nan, diff = 0, 0, [0.0]
    log = logging.getLogger("metpy")
    level, log.level = log.level, logging.CRITICAL   # its Qhull messages, one per failure
    try:
        for x, v in zip(q, ours):
            try:
                w = natural_neighbor_to_points(p, z, x[None])[0]
            except ZeroDivisionError:
                raised += 1
                continue
            nan += bool(np.isnan(w))
            diff.append(abs(w - v) if np.isfinite(w) else 0.0)
    finally:
        log.level = level
    ours_nan = int(np.isnan(ours).sum())
    return [f"Through the data: {k} x {k} lattice, {grid} x {grid} grid through it "
            f"({len(q)} points, all inside the hull): MetPy raises ZeroDivisionError at "
            f"{raised}, gives NaN at {nan}, agrees to {max(diff):.1e} at the others; ours "
            f"gives NaN at {ours_nan}"]


def study_scatter(n, grid, repeats):
    """Sibson's values on the grid, by the scatter over the triangles (the default for large
    2D batches) and by the per-query coordinates it replaced, against scipy's
    LinearNDInterpolator: wall and CPU seconds of warm calls (best of ``repeats``), the first
    call apart (it builds the scatter's triangle records), the kernels' one-time load or
    compilation apart."""
    import numba
    from skfem_nem.coordinates import interp_natural
    load = timed(lambda: NaturalNeighbourInterpolator(cube_points(60, 2, 1), np.ones(60))(
        *np.meshgrid(np.linspace(0.1, 0.9, 110), np.linspace(0.1, 0.9, 100))))[1]
    p = cube_points(n, 2, seed=0)
    f = franke(p[:, 0], p[:, 1])
    x, y = np.meshgrid(np.linspace(0, 1, grid), np.linspace(0, 1, grid))
    tri, t_tri = timed(lambda: Triangulation(p))
    dl, t_qhull = timed(lambda: Delaunay(p))

    def cpu_best(fn):
        c = np.inf
        for _ in range(repeats):
            c0 = time.process_time()
            fn()
            c = min(c, time.process_time() - c0)
        return c

    def measure(make, warm=False):
        itp, tb = timed(make)
        if warm:        # scipy's first call sets up its point location (excluded, as above)
            itp(x[:2, :2], y[:2, :2])
        v, first = timed(lambda: itp(x, y))
        _, tc = best(lambda: itp(x, y), repeats)
        return f"{tb:.3f} | {first:.3f} | {tc:.3f} | {cpu_best(lambda: itp(x, y)):.3f}", v

    ours, v = measure(lambda: NaturalNeighbourInterpolator(tri, f))
    scipy_row, _ = measure(lambda: LinearNDInterpolator(dl, f), warm=True)
    saved = interp_natural.SCATTER_MIN
    interp_natural.SCATTER_MIN = 1 << 62          # every query by its coordinates
    try:
        gather, vg = measure(lambda: NaturalNeighbourInterpolator(tri, f))
    finally:
        interp_natural.SCATTER_MIN = saved
    return [f"Sibson's values, {n:,} points to a {grid} x {grid} grid ({numba.get_num_threads()}"
            f" numba threads; kernels' first load or compilation {load:.2f} s; triangulation "
            f"ours {t_tri:.3f} s, Qhull {t_qhull:.3f} s)", "",
            "| | build s | first call s | call s | call CPU s |", "|---|---|---|---|---|",
            f"| sibson (scatter) | {ours} |", f"| sibson (coordinates per query) | {gather} |",
            f"| scipy LinearNDInterpolator | {scipy_row} |", "",
            f"(scatter against coordinates: max difference {np.nanmax(np.abs(v - vg)):.1e})"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--grid", type=int, default=1000)
    ap.add_argument("--points-3d", type=int, default=20_000)
    ap.add_argument("--queries-3d", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-3d", action="store_true", help="skip the 3D study")
    ap.add_argument("--franke-points", choices=("franke", "random"), default="franke",
                    help="Franke's 100 points or 100 seeded random ones")
    ap.add_argument("--metpy-points", type=int, default=10_000)
    ap.add_argument("--metpy-grid", type=int, default=100)
    ap.add_argument("--no-metpy", action="store_true", help="skip the MetPy comparison")
    ap.add_argument("--scatter-only", action="store_true",
                    help="only the table of Sibson's values by the scatter against scipy")
    a = ap.parse_args(argv)
    if a.scatter_only:
        print("\n".join(study_scatter(a.points, a.grid, a.repeats)))
        return
    t0 = time.perf_counter()
    load = kernel_load()
    lines = [f"One-time numba kernel load (first calls on a small set): {load:.2f} s", ""]
    lines += study_2d(a.points, a.grid, a.repeats)
    lines += [""] + study_scatter(a.points, a.grid, a.repeats)
    if not a.no_3d:
        lines += [""] + study_3d(a.points_3d, a.queries_3d, a.repeats)
    lines += [""] + study_franke(a.franke_points)
    lines += [""] + gradient_costs(a.points, a.repeats)
    if not a.no_metpy:
        lines += [""] + compare_metpy(a.metpy_points, a.metpy_grid)
        lines += [""] + metpy_through_data()
    lines += ["", f"(whole run: {time.perf_counter() - t0:.0f} s)"]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
