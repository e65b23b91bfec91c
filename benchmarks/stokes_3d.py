"""Stokes flow on tetrahedra: rates, inf-sup constants and solver iterations in 3D.

Three tables, each printed as markdown:

1. **Manufactured solution** (``Manufactured3D``: unit cube, viscosity ratio ``--ratio``
   across it, free slip on all six faces, exact for this flow): relative L2 errors of
   velocity and pressure and their rates in h (h ~ n^(-1/3)) for NEM (natural-neighbour
   velocity with condensed bubbles, P1 pressure) and scikit-fem's MINI and Taylor-Hood on
   the same Delaunay tetrahedra, with the unknowns, the set-up (spaces and assembly) and
   solve seconds and the iterations of the solver ``"auto"`` takes. Taylor-Hood and MINI
   stop at ``--baseline-max`` interior nodes.
2. **Inf-sup constants** of the three pairs on random node sets of growing size (dense
   eigen-solve, small sets only).
3. **Iterations** of the block-preconditioned FGMRES (AMG V-cycles on the viscous block,
   six rigid-body modes as near null space; viscosity-weighted pressure mass for the
   Schur complement) against the node count: viscosity ratio 1 and the "sinker"
   (``Sinker``: 8 spheres, contrast 1e4, no slip).
4. With ``--sphere``, the **settling sphere** of ``examples/ex22_settling_sphere.py`` at
   the spacings ``(hs, hw)`` given: its velocity against Haberman & Sayre's with the
   sphere's triangles as walls, the error's order between resolutions, the Richardson
   estimate of the limit from the last two, the volume of the triangles' polyhedron over
   the sphere's, and the velocity on the same nodes without walls.

Times are warm: a first small solve loads the numba kernels before any is timed (the
one-time load is printed apart). Best of ``--repeat`` for the times.

    python benchmarks/stokes_3d.py [--sizes 1000 3000 10000] [--baseline-max 3000]
        [--iteration-sizes 1000 10000] [--inf-sup 30 90 250 500] [--ratio 20]
        [--sphere 0.08 0.3 0.06 0.25 0.04 0.2]
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

from skfem_nem import delaunay_mesh
from skfem_nem.geometry import box_nodes_3d
from skfem_nem.models.analytic3d import Manufactured3D, Sinker, relative_errors
from skfem_nem.models.stokes import assemble_stokes, inf_sup_constant, solve_stokes, stokes_spaces

METHODS = ("nem", "mini", "taylor-hood")


def timed_solve(mesh, method, viscosity, force, repeat=1, **kw):
    """(spaces, solution, set-up seconds, solve seconds), the best of ``repeat``."""
    best = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        S = stokes_spaces(mesh, method)
        sys_ = assemble_stokes(S, viscosity, force)
        t1 = time.perf_counter()
        sol = solve_stokes(S, None, system=sys_, **kw)
        t2 = time.perf_counter()
        if best is None or t2 - t0 < best[2] + best[3]:
            best = (S, sol, t1 - t0, t2 - t1)
    return best


def rates_table(sizes, ratio, baseline_max, repeat) -> str:
    ms = Manufactured3D(ratio)
    rows = ["| interior nodes | nodes | method | unknowns | u L2 | rate | p L2 | rate | "
            "set-up s | solve s | solver (its) |", "|" + "---|" * 11]
    last = {}
    for n in sizes:
        mesh = delaunay_mesh(box_nodes_3d(n, seed=0))
        nodes = mesh.p.shape[1]
        for method in METHODS:
            if method != "nem" and n > baseline_max:
                continue
            S, sol, t_set, t_sol = timed_solve(mesh, method, ms.viscosity, ms.force, repeat)
            eu, ep = relative_errors(S, sol, ms)
            ru = rp = ""
            if method in last:
                n0, eu0, ep0 = last[method]
                k = -3.0 / np.log(nodes / n0)
                ru, rp = f"{k * np.log(eu / eu0):.2f}", f"{k * np.log(ep / ep0):.2f}"
            last[method] = (nodes, eu, ep)
            its = f"{sol.info.get('solver', sol.solver)} ({sol.iterations})"
            rows.append(f"| {n:,} | {nodes:,} | {method} | {S.n_velocity + S.n_pressure:,} | "
                        f"{eu:.3e} | {ru} | {ep:.3e} | {rp} | {t_set:.2f} | {t_sol:.2f} | "
                        f"{its} |")
            print(rows[-1], flush=True)
    return "\n".join(rows)


def inf_sup_table(sizes) -> str:
    rows = ["| interior nodes | nodes | NEM (bubbles) | NEM without bubbles | MINI | "
            "Taylor-Hood |", "|---|---|---|---|---|---|"]
    for n in sizes:
        mesh = delaunay_mesh(box_nodes_3d(n, seed=5))
        b = [inf_sup_constant(stokes_spaces(mesh, "nem")),
             inf_sup_constant(stokes_spaces(mesh, "nem-projection"), stabilised=False),
             inf_sup_constant(stokes_spaces(mesh, "mini")),
             inf_sup_constant(stokes_spaces(mesh, "taylor-hood"))]
        rows.append(f"| {n:,} | {mesh.p.shape[1]:,} | " + " | ".join(f"{v:.3f}" for v in b)
                    + " |")
        print(rows[-1], flush=True)
    return "\n".join(rows)


def iterations_table(sizes, repeat) -> str:
    sinker = Sinker(8, contrast=1e4, seed=0)
    cases = (("ratio 1, free slip", lambda x: 1.0 + 0 * x[0], Manufactured3D(1.0).force, {}),
             ("sinker 1e4, no slip", sinker.viscosity, sinker.force,
              dict(free_slip=None, no_slip="all")))
    rows = ["| case | interior nodes | nodes | velocity unknowns | FGMRES its | set-up s | "
            "solve s |", "|---|---|---|---|---|---|---|"]
    for name, eta, f, walls in cases:
        for n in sizes:
            mesh = delaunay_mesh(box_nodes_3d(n, seed=0))
            S, sol, t_set, t_sol = timed_solve(mesh, "nem", eta, f, repeat, solver="fgmres",
                                               tol=1e-8, maxiter=500, **walls)
            rows.append(f"| {name} | {n:,} | {mesh.p.shape[1]:,} | {S.n_velocity:,} | "
                        f"{sol.iterations} | {t_set:.2f} | {t_sol:.2f} |")
            print(rows[-1], flush=True)
    return "\n".join(rows)


def sphere_table(spacings) -> str:
    """The settling sphere at each ``(hs, hw)``, its surface's triangles walls: velocity /
    reference, the order of the error between successive resolutions (in hs), the
    Richardson limit, the volume of the polyhedron of the surface's triangles over the
    sphere's, and the velocity on the same nodes without walls."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    import ex22_settling_sphere as ex
    rows = ["| hs | hw | nodes | FGMRES its | seconds | v / reference | order | "
            "Richardson limit | polyhedron / sphere volume | without walls |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    last = []
    for hs, hw in spacings:
        t0 = time.perf_counter()
        sol, mesh, v = ex.settle(hs, hw)
        seconds = time.perf_counter() - t0
        r = v / ex.REFERENCE
        order = limit = ""
        if len(last) >= 1:
            hs0, r0 = last[-1]
            order_k = np.log((1 - r0) / (1 - r)) / np.log(hs0 / hs)
            order = f"{order_k:.2f}"
            f = (hs / hs0) ** order_k
            limit = f"{(r - f * r0) / (1 - f):.3f}" if order_k > 0 else ""
        last.append((hs, r))
        s, faces = ex.surface(hs)
        volume = np.abs(np.einsum("ij,ij->i", s[faces[:, 0]], np.cross(
            s[faces[:, 1]], s[faces[:, 2]]))).sum() / 6 / (4 / 3 * np.pi * ex.A ** 3)
        plain = ex.settle(hs, hw, walls=False)[2] / ex.REFERENCE
        rows.append(f"| {hs} | {hw} | {mesh.p.shape[1]:,} | {sol.iterations} | "
                    f"{seconds:.1f} | {r:.4f} | {order} | {limit} | {volume:.4f} | "
                    f"{plain:.4f} |")
        print(rows[-1], flush=True)
    return "\n".join(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 3000, 10000],
                    help="interior node counts of the rates table (none: skipped)")
    ap.add_argument("--baseline-max", type=int, default=3000)
    ap.add_argument("--iteration-sizes", type=int, nargs="*", default=[1000, 10000],
                    help="interior node counts of the iterations table (none: skipped)")
    ap.add_argument("--inf-sup", type=int, nargs="*", default=[30, 90, 250, 500],
                    help="interior node counts of the inf-sup table (none: skipped)")
    ap.add_argument("--ratio", type=float, default=20.0)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--sphere", type=float, nargs="*", default=[],
                    help="pairs hs hw of the settling-sphere study (none: skipped)")
    a = ap.parse_args(argv)
    if len(a.sphere) % 2:
        ap.error(f"--sphere takes pairs hs hw, got {len(a.sphere)} number(s)")
    t0 = time.perf_counter()
    ms = Manufactured3D(a.ratio)
    for method in METHODS:      # load the kernels once
        timed_solve(delaunay_mesh(box_nodes_3d(30, seed=0)), method, ms.viscosity, ms.force)
    print(f"one-time kernel load: {time.perf_counter() - t0:.1f} s\n")
    out = {"rates": rates_table(a.sizes, a.ratio, a.baseline_max, a.repeat) if a.sizes else ""}
    print()
    out["inf_sup"] = inf_sup_table(a.inf_sup) if a.inf_sup else ""
    print()
    out["iterations"] = iterations_table(a.iteration_sizes, a.repeat) if a.iteration_sizes \
        else ""
    print()
    pairs = list(zip(a.sphere[::2], a.sphere[1::2]))
    out["sphere"] = sphere_table(pairs) if pairs else ""
    print()
    for title, table in (("Manufactured solution, viscosity ratio "
                          f"{a.ratio:g}", out["rates"]),
                         ("Inf-sup constants (no slip)", out["inf_sup"]),
                         ("FGMRES iterations (tol 1e-8)", out["iterations"]),
                         ("Settling sphere (Haberman-Sayre)", out["sphere"])):
        if table:
            print(f"### {title}\n\n{table}\n")
    return out


if __name__ == "__main__":
    main()
