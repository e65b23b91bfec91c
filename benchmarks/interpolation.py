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
checked Delaunay triangulation for ours) and handed to each interpolator; "build" is the
rest of the set-up (for ``sibson1``, ``farin`` and Clough-Tocher, the gradient estimate). Calls are
timed warm, best of ``--repeats``: a first small call loads the numba kernels (their one-time
load from numba's cache, or compilation on a fresh install, is printed apart). "gradient" is
``itp.gradient`` (values and exact gradients); errors are against the exact function at the
queries.

    python benchmarks/interpolation.py [--points 100000] [--grid 1000]
        [--points-3d 20000] [--queries-3d 100000] [--repeats 2] [--no-3d]
"""
import argparse
import time

import numpy as np
from scipy.interpolate import (CloughTocher2DInterpolator, LinearNDInterpolator,
                               NearestNDInterpolator)
from scipy.spatial import Delaunay

from skfem_nem import NaturalNeighbourInterpolator, Triangulation


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
    dl, t_qhull = timed(lambda: Delaunay(p))
    lines = [f"3D: {n:,} points, {m:,} random queries", "", HEADER,
             f"| triangulation (Qhull) | {t_qhull:.3f} | | | | | |"]
    for meth in ("sibson", "sibson1", "farin", "linear", "nearest"):
        itp, tb = timed(lambda: NaturalNeighbourInterpolator(dl, f, method=meth))
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--grid", type=int, default=1000)
    ap.add_argument("--points-3d", type=int, default=20_000)
    ap.add_argument("--queries-3d", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-3d", action="store_true", help="skip the 3D study")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    load = kernel_load()
    lines = [f"One-time numba kernel load (first calls on a small set): {load:.2f} s", ""]
    lines += study_2d(a.points, a.grid, a.repeats)
    if not a.no_3d:
        lines += [""] + study_3d(a.points_3d, a.queries_3d, a.repeats)
    lines += ["", f"(whole run: {time.perf_counter() - t0:.0f} s)"]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
