"""Cost of one step of the 3D evolving mesh: local repair against a rebuild.

Nodes: ``box_nodes_3d(n)`` in the unit cube (nodes on the walls, seed 0). Velocity: two
stacked cellular vortices, ``u = (sin(pi x) cos(pi y), -cos(pi x) sin(pi y) + sin(pi y)
cos(pi z), -cos(pi y) sin(pi z))``, divergence free and tangent to every wall (the wall
nodes slide along their walls). Time step: ``dt = 0.1 h / 2`` with ``h = n**(-1/3)``, so the
largest displacement per step is about 0.1 h. Walls: ``"box"``.

For each size (after a numba warm-up on a small mesh), ``--steps`` steps of
:meth:`LagrangianMesh3D.advance`. Reported per step (best and median over the steps): the
repair (:meth:`Delaunay3D.moved`: flips, relocated nodes), the whole step without the
velocity callback, and on the same nodes, interleaved so that both see the same machine
load, a rebuild with the package's :class:`Delaunay3D` and with Qhull
(``scipy.spatial.Delaunay``). Every step's tetrahedra are compared with a fresh
``Delaunay3D`` of the same nodes (``same``: all steps equal). ``us / changed`` is the repair
time per changed tetrahedron: flat across sizes when the cost is linear in what changed.

**Diffusion** (``--diffusion NODES``): integration-point fields carried through a round trip
(``--steps`` steps of the vortex, then as many of the reversed vortex: the nodes come back to
round-off, and with them the unique Delaunay tetrahedra), for both remap rules. Patterns: a
Gaussian bump (width 0.1 at (0.5, 0.25, 0.5)), a step (1 for x < 0.5) and the linear
x + 2y + 3z, against their values at the same points (L2 weighted by the cells' volumes).

Run ``python benchmarks/evolve_3d.py [--sizes 1e4 1e5] [--steps 5]`` (about 2 minutes) and
``python benchmarks/evolve_3d.py --diffusion 4000 --steps 20`` (about 1 minute).
Results: docs/evolution.md.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial import Delaunay

from skfem_nem import LagrangianMesh3D
from skfem_nem.evolution.remap3d import cell_volumes
from skfem_nem.geometry.delaunay3d import Delaunay3D
from skfem_nem.geometry.nodesets3d import box_nodes_3d

MAX_SPEED = 2.0  # of the velocity below (both vortices add up at the cube's centre lines)


def velocity(x):
    a, b, c = np.pi * x.T
    return np.c_[np.sin(a) * np.cos(b),
                 -np.cos(a) * np.sin(b) + np.sin(b) * np.cos(c),
                 -np.cos(b) * np.sin(c)]


def tet_set(simplices):
    return set(map(tuple, np.sort(simplices, axis=1).tolist()))


def run(n, steps):
    """Per-step rows of one size."""
    mesh = LagrangianMesh3D(box_nodes_3d(n, seed=0))
    dt = 0.1 * n ** (-1 / 3) / MAX_SPEED
    rows = []
    for _ in range(steps):
        spent = [0.0]

        def timed(x):
            t = time.perf_counter()
            v = velocity(x)
            spent[0] += time.perf_counter() - t
            return v

        t = time.perf_counter()
        report = mesh.advance(timed, dt)
        step = time.perf_counter() - t - spent[0]
        x = np.array(mesh.nodes)
        t = time.perf_counter()
        fresh = Delaunay3D(x)
        ours = time.perf_counter() - t
        t = time.perf_counter()
        Delaunay(x)
        qhull = time.perf_counter() - t
        rows.append(dict(report, step_s=step, ours_s=ours, qhull_s=qhull,
                         same=tet_set(mesh.mesh.t.T) == tet_set(fresh.simplices)))
    return rows


def table(results):
    print("| nodes | tets | flips / step | relocated / step | rebuilt | changed tets / step "
          "| repair s (best, median) | step s | Delaunay3D rebuild s | Qhull rebuild s "
          "| Qhull / repair | Delaunay3D / repair | us / changed | same |")
    print("|" + "---|" * 14)
    for n, rows in results.items():
        rep = np.array([r["repair_seconds"] for r in rows])
        chg = np.mean([r["tetrahedra_changed"] for r in rows])
        q = np.median([r["qhull_s"] for r in rows])
        o = np.median([r["ours_s"] for r in rows])
        print(f"| {n:,} | {rows[-1]['tetrahedra']:,} | {np.mean([r['flips'] for r in rows]):.0f} "
              f"| {np.mean([r['relocated'] for r in rows]):.1f} "
              f"| {sum(r['rebuilt'] for r in rows)} | {chg:.0f} "
              f"| {rep.min():.3f}, {np.median(rep):.3f} "
              f"| {np.median([r['step_s'] for r in rows]):.3f} | {o:.3f} | {q:.3f} "
              f"| {q / np.median(rep):.1f} | {o / np.median(rep):.1f} "
              f"| {1e6 * np.median(rep) / chg:.1f} | {all(r['same'] for r in rows)} |")


def patterns(x):
    """The carried patterns at points x (..., 3): a Gaussian bump, a step, a linear field."""
    r2 = ((x - np.array([0.5, 0.25, 0.5])) ** 2).sum(axis=-1)
    return {"bump": np.exp(-r2 / (2 * 0.1 ** 2)), "step": (x[..., 0] < 0.5).astype(float),
            "linear": x[..., 0] + 2 * x[..., 1] + 3 * x[..., 2]}


def diffusion(n, steps, rule):
    """A round trip (the vortex for ``steps`` steps, then reversed): rows per pattern."""
    p = box_nodes_3d(n, seed=0)
    m = LagrangianMesh3D(p, ip_fields=patterns(LagrangianMesh3D(p).ip_points()), remap=rule)
    start = {k: m.ip_integral(k) for k in m.ip_fields}
    dt = 0.1 * n ** (-1 / 3) / MAX_SPEED
    for sign in (1.0, -1.0):
        for _ in range(steps):
            m.advance(lambda x: sign * velocity(x), dt)
    back = np.abs(np.array(m.nodes) - p).max()
    exact = patterns(m.ip_points())
    w = cell_volumes(np.array(m.nodes), m.mesh.t.T)[:, None]
    flips = sum(r["flips"] for r in m.history)
    rows = []
    for k, f in m.ip_fields.items():
        e = exact[k]
        rows.append((k, rule, flips, back, 1 - f.max() / e.max(),
                     np.sqrt((w * (f - e) ** 2).sum() / (w * e ** 2).sum()),
                     f.min(), f.max(), e.min(), e.max(), (m.ip_integral(k) - start[k]) / start[k]))
    return rows


def diffusion_table(n, steps):
    print("| pattern | rule | flips | nodes back to | peak loss | rel. L2 error | range "
          "| first range | integral change |")
    print("|" + "---|" * 9)
    for rule in ("conservative", "average"):
        for k, r, fl, back, peak, l2, lo, hi, elo, ehi, di in diffusion(n, steps, rule):
            print(f"| {k} | {r} | {fl} | {back:.1e} | {peak:.3f} | {l2:.3f} | [{lo:.3f}, {hi:.3f}] "
                  f"| [{elo:.3f}, {ehi:.3f}] | {di:.1e} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5])
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--diffusion", type=int, metavar="NODES",
                    help="the round-trip diffusion study on this many nodes instead")
    args = ap.parse_args(argv)
    t = time.perf_counter()
    run(300, 2)
    print(f"one-time kernel load and warm-up: {time.perf_counter() - t:.1f} s\n")
    if args.diffusion:
        diffusion_table(args.diffusion, args.steps)
        return
    table({int(n): run(int(n), args.steps) for n in args.sizes})


if __name__ == "__main__":
    main()
