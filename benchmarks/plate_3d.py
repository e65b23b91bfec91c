"""The 3D sinking plate at several resolutions: time and memory per step, and the plate's
depth against time.

Each node count runs ``skfem-nem sinking-plate --dim 3 --nodes N`` in a child process (its
own kernels loaded from numba's cache; the first solve, before the first step, is not a
step), for ``--steps`` steps or to ``--end-time``. Printed, in one run:

* per resolution: nodes, tetrahedra, steps, the median wall time of a step (its Stokes
  solves included) and per 1,000 nodes, its ratio to the smallest resolution's, the median
  Picard iterations of a step and FGMRES iterations of a solve, and the child's peak
  resident memory;
* with two resolutions or more and ``--end-time``: the plate's depth (the mean sinking of
  its nodes) at the output times, and the largest relative difference from the finest run.

Run ``python benchmarks/plate_3d.py [--nodes 5000 10000] [--steps 3 | --end-time 300]``.
An elasto-plastic step (5 to 7 Picard iterations) takes about 23 s at 10,000 nodes on two
quiet cores; a whole default run (10,032 nodes) about 10 minutes with numba's kernels cached,
12 with their compilation.
"""
from __future__ import annotations

import argparse
import csv
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def run_child(nodes: int, steps, end_time, out: Path) -> dict:
    """One run in a child process; its diagnostics and peak memory (MB)."""
    cmd = [sys.executable, "-m", "skfem_nem.apps.cli", "sinking-plate", "--dim", "3",
           "--nodes", str(nodes), "-o", str(out), "--quiet"]
    if steps is not None:
        cmd += ["--max-steps", str(steps)]
    if end_time is not None:
        cmd += ["--end-time", str(end_time), "--output-interval", str(end_time / 6)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    with open(out / "diagnostics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    d = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    return {"nodes": int(d["nodes"][0]), "tetrahedra": int(np.median(d["tetrahedra"])),
            "steps": len(rows), "step_s": float(np.median(d["seconds"])),
            "its": float(np.median(d["solver_iterations"])), "peak_mb": peak,
            "picard": float(np.median(d["picard_iterations"])) if "picard_iterations" in d
            else 1.0,
            "time": d["time"], "depth": d["plate_depth"]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[5000, 10000])
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--end-time", type=float, default=None)
    a = ap.parse_args(argv)
    if (a.steps is None) == (a.end_time is None):
        ap.error("give exactly one of --steps and --end-time")
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sorted(a.nodes):
            runs.append(run_child(n, a.steps, a.end_time, Path(tmp) / str(n)))
    base = runs[0]["step_s"] / runs[0]["nodes"]
    lines = ["| nodes | tetrahedra | steps | s a step | s a step per 1,000 nodes | "
             "per node / smallest | Picard its | FGMRES its | peak MB |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        per = r["step_s"] / r["nodes"]
        lines.append(f"| {r['nodes']:,} | {r['tetrahedra']:,} | {r['steps']} | "
                     f"{r['step_s']:.2f} | {1000 * per:.2f} | {per / base:.2f} | "
                     f"{r['picard']:.0f} | {r['its']:.0f} | {r['peak_mb']:,.0f} |")
    out = {"steps": "\n".join(lines)}
    print(out["steps"])
    if a.end_time is not None and len(runs) > 1:
        fine = runs[-1]
        times = np.linspace(0, a.end_time, 7)[1:]
        head = "| time | " + " | ".join(f"depth, {r['nodes']:,} nodes" for r in runs) + " |"
        rows = [head, "|---" * (len(runs) + 1) + "|"]
        worst = 0.0
        for t in times:
            vals = [float(np.interp(t, r["time"], r["depth"])) for r in runs]
            worst = max(worst, max(abs(v - vals[-1]) / abs(vals[-1]) for v in vals))
            rows.append(f"| {t:.4g} | " + " | ".join(f"{v:.4f}" for v in vals) + " |")
        out["depth"] = "\n".join(rows)
        out["worst"] = worst
        print("\n" + out["depth"])
        print(f"\nlargest relative difference from the {fine['nodes']:,}-node run: "
              f"{100 * worst:.1f}%")
    return out


if __name__ == "__main__":
    main()
