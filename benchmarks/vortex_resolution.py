"""Resolution of an evolving mesh held in a vortex for many turns.

A cellular vortex (free slip on the unit square's walls) turns its core about once every
2.5 time units and stretches every ring of nodes around it into a spiral. The mesh is
advanced to ``--end-time`` with and without the target spacing's injection (``inject``
factor 2, removal of crowded nodes on), and the script prints, every ``--every`` time
units, the node count and the longest edge relative to the first mesh's, the smallest
angle and the nodes injected and removed so far (one markdown table per node count)::

    python benchmarks/vortex_resolution.py [--nodes 300 2000] [--end-time 20] [--every 4]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from skfem_nem import LagrangianMesh


def vortex(x):
    """One divergence-free cell per unit square, tangential on the walls."""
    X, Y = x[:, 0], x[:, 1]
    return np.c_[np.sin(np.pi * X) ** 2 * np.sin(2 * np.pi * Y),
                 -np.sin(np.pi * Y) ** 2 * np.sin(2 * np.pi * X)]


def square(n: int, seed: int = 2) -> np.ndarray:
    """The corners, sqrt(n) - 1 jittered nodes on each wall and n random interior ones."""
    rng = np.random.default_rng(seed)
    k = max(int(np.sqrt(n)), 4)
    s = (np.arange(1, k) + 0.3 * rng.random(k - 1)) / k
    z = 0 * s
    return np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], np.c_[s, z], np.c_[s, z + 1],
                 np.c_[z, s], np.c_[z + 1, s], 0.01 + 0.98 * rng.random((n, 2))]


def run(n: int, inject, end_time: float, every: float):
    """Rows (time, nodes / first, longest edge / first, smallest angle, injected,
    removed) every ``every`` time units, and the wall time."""
    nodes = square(n)
    lm = LagrangianMesh(nodes, ip_fields={"one": np.ones(3)})
    n0, L0 = lm.nodes.shape[0], lm.longest_edge()
    dt = 0.25 * float(np.sqrt(1.0 / n0))          # a quarter of the mean spacing
    rows, injected, removed, fewest, longest = [], 0, 0, 1.0, 1.0
    t0 = time.perf_counter()
    next_row = every
    while lm.time < end_time - 1e-9:
        rep = lm.advance(vortex, min(dt, end_time - lm.time), inject=inject, merge=True,
                         maxiter=20)
        injected += rep["injected"]
        removed += rep["removed"]
        fewest = min(fewest, lm.nodes.shape[0] / n0)
        longest = max(longest, rep["longest_edge"] / L0)
        if lm.time >= next_row - 1e-9:
            rows.append((lm.time, lm.nodes.shape[0] / n0, rep["longest_edge"] / L0,
                         lm.min_angle(), injected, removed))
            next_row += every
    return rows, fewest, longest, time.perf_counter() - t0, lm.ip_integral("one")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[300, 2000])
    ap.add_argument("--end-time", type=float, default=20.0)
    ap.add_argument("--every", type=float, default=4.0)
    args = ap.parse_args(argv)
    out = {}
    for n in args.nodes:
        print(f"\n{n} interior nodes drawn\n")
        print("| t | injection | nodes / first | longest edge / first | smallest angle "
              "(deg) | injected | removed |")
        print("|---|---|---|---|---|---|---|")
        for label, inject in (("target spacing", 2.0), ("none", None)):
            rows, fewest, longest, seconds, one = run(n, inject, args.end_time, args.every)
            out[(n, label)] = (fewest, longest)
            for t, nr, er, ang, inj, rem in rows:
                print(f"| {t:.0f} | {label} | {nr:.3f} | {er:.2f} | {ang:.3g} | {inj} | {rem} |")
            print(f"| over the run | {label} | fewest {fewest:.3f} | longest {longest:.2f} | "
                  f"| | {seconds:.1f} s, integral of 1: {one:.15f} |")
    return out


if __name__ == "__main__":
    main()
