"""Mesh quality of nodes carried by a cellular shear flow, step by step.

The run of ``examples/ex05_shear_flow.py`` (two counter-rotating cells, free
slip walls, predictor-corrector steps and Lawson flips with
:class:`skfem_nem.LagrangianMesh`) for one or more node counts: every 25th
step the flips, substeps, relocated nodes, the minimum angle of the mesh and
the 1st percentile of the triangles' minimum angles (Lagrangian compression
near the stagnation points: nodes are never merged), then the totals and the
pairs of the paper's Fig. 6 (B/B' neighbours at the start, A/A' at the end)
in units of the mean node spacing h. The numbers of ``docs/evolution.md``.

    python benchmarks/shear_flow.py [--nodes 2000] [--steps 200] [--quick]

``--quick``: 300 nodes, 40 steps (a smoke run).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex05_shear_flow import N_NODES, N_STEPS, T_END, run  # noqa: E402


def triangle_min_angles(nodes, triangles):
    """(nt,) smallest angle of each triangle, degrees."""
    X = nodes[triangles]
    ang = []
    for k in range(3):
        u = X[:, (k + 1) % 3] - X[:, k]
        v = X[:, (k + 2) % 3] - X[:, k]
        ang.append(np.arctan2(np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]),
                              (u * v).sum(axis=1)))
    return np.degrees(np.min(ang, axis=0))


def quality_run(n_nodes, n_steps):
    """ex05's run (its time step; n_steps = N_STEPS is one turn) with the 1st
    percentile of the minimum angles after every step; returns (the result
    of ``run``, the percentiles)."""
    p1 = []
    res = run(n_nodes, n_steps, T_END * n_steps / N_STEPS,
              on_step=lambda lm: p1.append(
                  np.percentile(triangle_min_angles(lm.nodes, lm.triangles), 1)))
    return res, np.array(p1)


def step_table(res, p1, every=25):
    hist = res["mesh"].history
    rows = sorted(set(range(every - 1, len(hist), every)) | {len(hist) - 1})
    lines = ["| step | time | flips | substeps | relocated | min angle | "
             "1st percentile of min angles |", "|---|---|---|---|---|---|---|"]
    for i in rows:
        r = hist[i]
        lines.append(f"| {r['step']} | {r['time']:.2f} | {r['flips']} | {r['substeps']} | "
                     f"{r['relocated']} | {r['min_angle']:.4f} | {p1[i]:.3f} |")
    return "\n".join(lines)


def summary(res):
    lm, h, pairs = res["mesh"], res["h"], res["pairs"]
    hist = lm.history
    x0, x1 = res["start"], lm.nodes
    (a, a2), (b, b2) = pairs["A"], pairs["B"]
    start = triangle_min_angles(*res["snapshots"][0])
    return (f"{lm.triangulation.npoints} nodes, {len(hist)} steps of {res['dt'] / h:.2f} h: "
            f"{sum(r['flips'] for r in hist)} flips, "
            f"{sum(r['substeps'] - 1 for r in hist)} substeps beyond the first, "
            f"{sum(r['relocated'] for r in hist)} relocated, "
            f"Delaunay at the end: {lm.triangulation.is_delaunay()}; minimum angle "
            f"{start.min():.2f} -> {hist[-1]['min_angle']:.4f} degrees, 1st percentile "
            f"{np.percentile(start, 1):.2f} at the start.\n"
            f"B/B' = {b}, {b2}: {np.linalg.norm(x0[b] - x0[b2]) / h:.1f} h -> "
            f"{pairs['B_end_distance'] / h:.1f} h; A/A' = {a}, {a2}: "
            f"{pairs['A_start_distance'] / h:.1f} h -> {np.linalg.norm(x1[a] - x1[a2]) / h:.1f} h")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[N_NODES])
    ap.add_argument("--steps", type=int, default=N_STEPS, help="steps of dt = 0.01")
    ap.add_argument("--quick", action="store_true", help="300 nodes, 40 steps (a smoke run)")
    a = ap.parse_args(argv)
    nodes, steps = ([300], 40) if a.quick else (a.nodes, a.steps)
    for n in nodes:
        res, p1 = quality_run(n, steps)
        print(f"**{n} random nodes**\n")
        print(step_table(res, p1, every=max(1, steps // 8)))
        print()
        print(summary(res))
        print()


if __name__ == "__main__":
    main()
