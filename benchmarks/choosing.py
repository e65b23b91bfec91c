"""NEM, P1 or P2: the time each method needs to reach the same error, problem by problem.

For each problem every method is solved on a short sequence of node sets. Each solve is
timed as basis + assembly + solve, warm (a first solve on the smallest set loads numba's
kernels and is not timed), the best of ``--repeat``. The target error of a problem is the
largest of the methods' smallest errors, so that every method reaches it within its
sequence. The time to reach it is interpolated log-log between the two sets whose errors
bracket it ("<=" when the coarsest set is already below it). The table gives the times and
their ratios to NEM's.

Problems (the error is the one each docs page reports):

* Poisson 2D, smooth (u = sin(pi x) sin(pi y)), uniform and graded node sets of
  ``examples/ex04_nem_vs_fem.py``: H1-seminorm error;
* Poisson 2D on the L-shape of ``benchmarks/nonconvex.py`` with the corner singularity
  u = r^(2/3) sin(2 phi / 3) at the re-entrant corner: H1-seminorm error, on node sets that
  are one pattern near the corner, scaled with the spacing (``lshape_nodes``);
* plane elasticity, Timoshenko's cantilever of ``examples/ex03_cantilever.py`` (random
  nodes): relative energy error;
* Stokes 2D, Donea and Huerta's flow (no slip), NEM pair against Taylor-Hood: velocity L2;
* Poisson 3D, ``examples/ex06_poisson_3d.py``: H1-seminorm error;
* linear elasticity 3D on the unit cube, a smooth displacement vanishing on its faces
  (``elasticity_3d``): H1-seminorm error;
* Stokes 3D, ``Manufactured3D`` (viscosity ratio 20), NEM pair against Taylor-Hood:
  relative velocity L2.

The tables of ``docs/choosing.md``.

    python benchmarks/choosing.py [--repeat 2] [--only poisson lshape elasticity stokes
        poisson3d elasticity3d stokes3d]

About 4 minutes on two cores (P1 has no stable Stokes pair here: "-").
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from skfem import (Basis, BilinearForm, ElementTriP1, ElementTriP2, ElementVector, Functional,
                   condense, solve)
from skfem.helpers import dot, grad

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis,  # noqa: E402
                       delaunay_mesh)


def best_time(fn, repeat):
    """(seconds, result) of the fastest of ``repeat`` calls."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


# ---------------------------------------------------------------------------
# the problems: each returns {method: [(nodes, error, seconds), ...]}
# ---------------------------------------------------------------------------

def poisson_2d(kind, repeat, sizes=(250, 1000, 4000), p2_sizes=(100, 250, 1000)):
    from ex04_nem_vs_fem import error_basis, errors, laplace, load, make_basis, node_set

    out = {}
    for m in ("NEM", "P1", "P2"):
        out[m] = []
        for n in (p2_sizes if m == "P2" else sizes):
            mesh = delaunay_mesh(node_set(kind, n))

            def run():
                b = make_basis(mesh, m)
                return solve(*condense(laplace.assemble(b), load.assemble(b), D=b.get_dofs()))
            sec, u = best_time(run, repeat)
            out[m].append((mesh.nvertices, errors(error_basis(mesh, m), u)[1], sec))
    return out


# the L-shape [0,1]^2 without (1/2,1)^2: phi is the angle at the corner (1/2, 1/2) from the
# edge y = 1/2, x > 1/2, through the domain to the edge x = 1/2, y > 1/2 (phi in [0, 3 pi/2])

def _polar(x, y):
    dx, dy = x - 0.5, y - 0.5
    r = np.hypot(dx, dy)
    phi = np.mod(np.arctan2(dy, dx), 2 * np.pi)   # 0 along y = 1/2 to the right
    phi = np.where(phi < np.pi / 2 - 1e-12, phi + 2 * np.pi, phi) - np.pi / 2
    return r, phi, np.arctan2(dy, dx)


def singular(x, y):
    r, phi, _ = _polar(x, y)
    # phi runs from 0 on the edge x = 1/2 (y > 1/2) to 3 pi/2 on the edge y = 1/2 (x > 1/2)
    return r ** (2 / 3) * np.sin(2 * phi / 3)


def singular_grad(x, y):
    r, phi, theta = _polar(x, y)
    r = np.maximum(r, 1e-300)
    ur = 2 / 3 * r ** (-1 / 3) * np.sin(2 * phi / 3)
    ut = 2 / 3 * r ** (-1 / 3) * np.cos(2 * phi / 3)    # (1/r) du/dphi
    return np.array([ur * np.cos(theta) - ut * np.sin(theta),
                     ur * np.sin(theta) + ut * np.cos(theta)])


@BilinearForm
def _laplace(u, v, w):
    return dot(grad(u), grad(v))


@Functional
def _h1_singular(w):
    g = w["uh"].grad - singular_grad(*w.x)
    return g[0] ** 2 + g[1] ** 2


# The H1 error of the corner singularity sits in the few triangles at the corner, and NEM's
# is set by how far the nearest interior nodes are: over 24 random node sets of one size the
# error^2 / h^(4/3) of the NEM interpolant ranged from 0.03 (an interior node at 0.45 h from
# the corner) to 0.12 (at 1.47 h), P1's from 0.21 to 0.33. With a new random patch at each
# level the measured rate is that scatter, not the method's. So the nodes within
# CORNER_PATCH spacings of the corner are one fixed jitter pattern, scaled by the spacing.
CORNER_PATCH = 6
# a hair above the spacing, so that edges of whole multiples of it are not cut once more
# by round-off in the division (0.5 / (0.5 / 49) > 49)
SPACING_ROUNDOFF = 1e-9
JITTER = 0.3        # of the spacing, as in benchmarks/nonconvex.py
CLEARANCE = 0.4     # of the spacing: no interior node closer to the outline


def _corner_jitter(m, seed):
    """(2m, 2m, 2) offsets of the grid's cells, in spacings, counted from the corner: random
    at each m, but the same CORNER_PATCH cells either side of the corner at every m."""
    jitter = np.random.default_rng([seed, m]).uniform(-JITTER, JITTER, (2 * m, 2 * m, 2))
    c = slice(m - CORNER_PATCH, m + CORNER_PATCH)
    jitter[c, c] = np.random.default_rng(seed).uniform(
        -JITTER, JITTER, (2 * CORNER_PATCH, 2 * CORNER_PATCH, 2))
    return jitter


def lshape_nodes(n, seed=0):
    """About n nodes of the L-shape: the outline at spacing h = 1 / (2 m) and a jittered
    grid of cell centres with the corner (1/2, 1/2) on its lines, so that the nodes near the
    corner, in units of h, are the same at every size (see CORNER_PATCH). Returns the
    nodes, the outline's segments and a point in the notch."""
    from nonconvex import distance, inside, outline

    corners = np.array([[0, 0], [1, 0], [1, .5], [.5, .5], [.5, 1], [0, 1]], float)
    m = max(CORNER_PATCH + 1, round(0.5 / np.sqrt(0.75 / n)))
    h = 0.5 / m
    bnd, seg = outline(corners, h * (1 + SPACING_ROUNDOFF))
    i, j = np.meshgrid(np.arange(-m, m), np.arange(-m, m), indexing="ij")  # from the corner
    q = 0.5 + h * (np.stack([i, j], -1) + 0.5 + _corner_jitter(m, seed)).reshape(-1, 2)
    q = q[inside(corners, q) & (distance(corners, q) > CLEARANCE * h)]
    return np.concatenate([bnd, q]), seg, np.array([[.75, .75]])


def lshape(repeat, sizes=(500, 2000, 8000), p2_sizes=(250, 1000, 4000)):
    out = {}
    for m in ("NEM", "P1", "P2"):
        out[m] = []
        for n in (p2_sizes if m == "P2" else sizes):
            p, seg, holes = lshape_nodes(n)
            mesh = delaunay_mesh(p, segments={"outline": seg}, holes=holes)

            def run():
                if m == "NEM":
                    b = NaturalNeighbourBasis(mesh)
                else:
                    b = Basis(mesh, ElementTriP1() if m == "P1" else ElementTriP2())
                D = b.get_dofs().all()
                x = singular(*(mesh.p if m == "NEM" else b.doflocs))
                A = _laplace.assemble(b)
                return solve(*condense(A, 0 * x, x=x, D=D))
            sec, u = best_time(run, repeat)
            if m == "NEM":
                eb = NaturalNeighbourBasis(mesh, npoints=7)
            else:
                eb = Basis(mesh, ElementTriP1() if m == "P1" else ElementTriP2(), intorder=6)
            err = np.sqrt(_h1_singular.assemble(eb, uh=eb.interpolate(u)))
            out[m].append((mesh.nvertices, err, sec))
    return out


def elasticity(repeat, sizes=(200, 800, 3200), p2_sizes=(100, 200, 800)):
    from ex03_cantilever import beam_errors, beam_nodes, error_basis, solve_beam

    out = {}
    for m in ("NEM", "P1", "P2"):
        out[m] = []
        for n in (p2_sizes if m == "P2" else sizes):
            mesh = delaunay_mesh(beam_nodes(n, "random"))
            runs = [solve_beam(mesh, m) for _ in range(repeat)]
            u, _, _ = runs[0]
            sec = min(r[2] for r in runs)
            _, energy = beam_errors(mesh, m, u, error_basis(mesh, m) if m == "NEM" else None)
            out[m].append((mesh.nvertices, energy, sec))
    return out


def stokes_2d(repeat, sizes=(500, 2000, 8000), th_sizes=(100, 250, 500)):
    from skfem_nem.geometry.nodesets import box_nodes
    from skfem_nem.models.analytic import DoneaHuerta
    from skfem_nem.models.stokes import solve_stokes, stokes_spaces

    @Functional
    def l2u(w):
        d = w["u"] - DoneaHuerta.velocity(w.x)
        return d[0] ** 2 + d[1] ** 2

    out = {}
    for m in ("nem", "taylor-hood"):
        out[m] = []
        for n in (th_sizes if m == "taylor-hood" else sizes):
            mesh = delaunay_mesh(box_nodes(n, seed=1))

            def run():
                return solve_stokes(stokes_spaces(mesh, method=m), 1.0, DoneaHuerta.force,
                                    free_slip=None, no_slip="all", tol=1e-12)
            sec, s = best_time(run, repeat)
            if m == "nem":
                ub = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()),
                                           npoints=7)
            else:
                ub = Basis(mesh, s.spaces.ubasis.elem, intorder=6)
            out[m].append((mesh.nvertices, np.sqrt(l2u.assemble(ub, u=ub.interpolate(s.u))),
                           sec))
    return out


def poisson_3d(repeat, sizes=(250, 700, 2000), p2_sizes=(100, 250, 700)):
    from ex06_poisson_3d import cube_nodes, solve_on

    out = {}
    for m in ("NEM", "P1", "P2"):
        out[m] = []
        for n in (p2_sizes if m == "P2" else sizes):
            mesh = delaunay_mesh(cube_nodes(n))
            runs = [solve_on(mesh, m)[2] for _ in range(repeat)]
            out[m].append((mesh.nvertices, runs[0]["h1"], min(r["seconds"] for r in runs)))
    return out


def stokes_3d(repeat, sizes=(300, 1000, 3000), th_sizes=(100, 300)):
    from stokes_3d import timed_solve

    from skfem_nem.geometry import box_nodes_3d
    from skfem_nem.models.analytic3d import Manufactured3D, relative_errors

    ms = Manufactured3D(20.0)
    out = {}
    for m in ("nem", "taylor-hood"):
        out[m] = []
        for n in (th_sizes if m == "taylor-hood" else sizes):
            mesh = delaunay_mesh(box_nodes_3d(n, seed=0))
            S, sol, t_set, t_sol = timed_solve(mesh, m, ms.viscosity, ms.force, repeat)
            out[m].append((mesh.nvertices, relative_errors(S, sol, ms)[0], t_set + t_sol))
    return out


def _cube_field(x):
    """s = sin(pi x) sin(pi y) sin(pi z), zero on the unit cube's faces, and its gradient."""
    S = np.sin(np.pi * x)
    C = np.cos(np.pi * x)
    s = S[0] * S[1] * S[2]
    g = np.pi * np.array([C[0] * S[1] * S[2], S[0] * C[1] * S[2], S[0] * S[1] * C[2]])
    return s, g


def _cube_force(x, lam, mu):
    """-div sigma(u) for u = (s, s, s) (:func:`_cube_field`): (lam + mu) grad(div u) gives
    -(lam + mu) sum_k d_j d_k s, and mu Laplace(u) gives 3 mu pi^2 s."""
    S = np.sin(np.pi * x)
    C = np.cos(np.pi * x)
    s = S[0] * S[1] * S[2]
    cross = np.pi ** 2 * np.array([
        C[0] * C[1] * S[2] + C[0] * S[1] * C[2],
        C[0] * C[1] * S[2] + S[0] * C[1] * C[2],
        C[0] * S[1] * C[2] + S[0] * C[1] * C[2]])
    return -(lam + mu) * (cross - np.pi ** 2 * s) + 3 * mu * np.pi ** 2 * s


def elasticity_3d(repeat, sizes=(250, 700, 2000), p2_sizes=(100, 250, 700)):
    """Linear elasticity on the unit cube (E = 1, nu = 0.3), u = (s, s, s) with s of
    :func:`_cube_field`, clamped faces: H1-seminorm error of the displacement."""
    from ex06_poisson_3d import cube_nodes
    from skfem import ElementTetP1, ElementTetP2, LinearForm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    lam, mu = lame_parameters(1.0, 0.3)
    stiffness = linear_elasticity(lam, mu)
    load = LinearForm(lambda v, w: dot(_cube_force(w.x, lam, mu), v))

    @Functional
    def h1(w):
        g = _cube_field(w.x)[1]
        return sum(((w["u"].grad[i] - g) ** 2).sum(axis=0) for i in range(3))

    out = {}
    for m in ("NEM", "P1", "P2"):
        out[m] = []
        for n in (p2_sizes if m == "P2" else sizes):
            mesh = delaunay_mesh(cube_nodes(n))
            base = {"NEM": ElementNaturalNeighbour, "P1": ElementTetP1, "P2": ElementTetP2}[m]
            elem = ElementVector(base())

            def run():
                b = (NaturalNeighbourBasis(mesh, elem) if m == "NEM"
                     else Basis(mesh, elem, intorder=4))
                return b, solve(*condense(stiffness.assemble(b), load.assemble(b),
                                          D=b.get_dofs()))
            sec, (b, u) = best_time(run, repeat)
            eb = NaturalNeighbourBasis(mesh, elem, intorder=4) if m == "NEM" else b
            out[m].append((mesh.nvertices, np.sqrt(h1.assemble(eb, u=eb.interpolate(u))), sec))
    return out


PROBLEMS = {
    "poisson": ("Poisson 2D, smooth, uniform nodes", "H1",
                lambda r: poisson_2d("uniform", r)),
    "graded": ("Poisson 2D, smooth, graded nodes", "H1",
               lambda r: poisson_2d("graded", r)),
    "lshape": ("Poisson 2D, L-shape, corner r^(2/3)", "H1", lshape),
    "elasticity": ("Elasticity 2D, cantilever", "energy",
                   elasticity),
    "stokes": ("Stokes 2D, Donea-Huerta", "u L2", stokes_2d),
    "poisson3d": ("Poisson 3D, smooth", "H1", poisson_3d),
    "elasticity3d": ("Elasticity 3D, smooth, clamped cube", "H1", elasticity_3d),
    "stokes3d": ("Stokes 3D, manufactured flow", "u L2",
                 stokes_3d),
}


def time_to(rows, target):
    """(seconds, bound) to reach ``target`` by log-log interpolation; bound is "<=" when the
    coarsest set is below it already, "" when interpolated, None when not reached."""
    n, e, s = (np.array(c, float) for c in zip(*rows))
    if e[0] <= target:
        return s[0], "<="
    for i in range(len(e) - 1):
        if e[i] > target >= e[i + 1]:
            w = np.log(target / e[i]) / np.log(e[i + 1] / e[i])
            return float(np.exp((1 - w) * np.log(s[i]) + w * np.log(s[i + 1]))), ""
    return np.nan, None


def table(results):
    out = ["| problem | error | target | NEM s | P1 s | P2 / Taylor-Hood s | P1 / NEM | "
           "P2 / NEM | `--only` |", "|---|---|---|---|---|---|---|---|---|"]
    for key, (title, norm, _) in PROBLEMS.items():
        if key not in results:
            continue
        res = results[key]
        target = max(min(e for _, e, _ in rows) for rows in res.values())
        cells = {}
        for m, rows in res.items():
            sec, bound = time_to(rows, target)
            cells[m.lower()] = (sec, bound)
        nem = cells["nem"][0]

        def fmt(m):
            if m not in cells:
                return "-", "-"
            sec, bound = cells[m]
            if bound is None:
                return "not reached", "-"
            return f"{bound} {sec:.3g}".strip(), f"{bound} {sec / nem:.2g}".strip()
        p1, r1 = fmt("p1")
        p2, r2 = fmt("p2" if "p2" in cells else "taylor-hood")
        out.append(f"| {title} | {norm} | {target:.2e} | {nem:.3g} | {p1} | {p2} | {r1} | {r2} "
                   f"| `{key}` |")
    return "\n".join(out)


def raw_table(results):
    out = ["| problem | method | nodes | error | seconds |", "|---|---|---|---|---|"]
    for key, res in results.items():
        for m, rows in res.items():
            for n, e, s in rows:
                out.append(f"| {key} | {m} | {n} | {e:.3e} | {s:.4g} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", nargs="+", choices=list(PROBLEMS), default=list(PROBLEMS))
    args = ap.parse_args(argv)
    poisson_2d("uniform", 1, sizes=(100,), p2_sizes=(100,))     # load the kernels, untimed
    results = {}
    for key in args.only:
        t0 = time.perf_counter()
        results[key] = PROBLEMS[key][2](args.repeat)
        print(f"# {key}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    print(raw_table(results))
    print()
    print(table(results))


if __name__ == "__main__":
    main()
