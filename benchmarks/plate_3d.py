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
  its nodes) at the output times, and the largest relative difference from the finest run;
* with ``--cfl`` and several values (one resolution, ``--end-time``): the time-step study.
  The depth at the output times for each ``cfl``, and its limit as the mean time step goes
  to zero, a straight line through the three finest runs' depths against their mean dt
  (taken as first order in dt), with each run's difference from that limit; the steps are
  the command's default midpoint steps, ``--no-midpoint`` gives one solve a step.

Run ``python benchmarks/plate_3d.py [--nodes 5000 10000] [--steps 3 | --end-time 300]``, or
``python benchmarks/plate_3d.py --nodes 4000 --end-time 250 --cfl 0.35 0.5 0.75 1``; other
options go to the command (``--plate-density 3``: the command refuses what it does not
know).
A midpoint step (two solves, the second of 4 to 5 Picard iterations) takes about 28 s at
10,000 nodes on two quiet cores; a whole default run (10,032 nodes) about 9 and a half
minutes with the compilation of numba's kernels. ``--viscosity-mean geometric`` runs the
blend of the plate's edge that the tables before it ran with (docs/stokes_3d.md).
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def run_measured(cmd) -> float:
    """Run ``cmd`` (its output discarded); its own peak resident memory (MB), from its
    rusage as it is reaped (``RUSAGE_CHILDREN`` would give the largest of every child so
    far). Linux counts into a child's peak the resident memory of the process that started
    it, a floor: this script's own (numpy only) is some tens of MB. ``CalledProcessError``
    if it fails."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return usage.ru_maxrss / 1024


def run_child(nodes: int, steps, end_time, out: Path, cfl=None, extra=()) -> dict:
    """One run in a child process (``extra``: more options of the command); its
    diagnostics and peak memory (MB)."""
    cmd = [sys.executable, "-m", "skfem_nem.apps.cli", "sinking-plate", "--dim", "3",
           "--nodes", str(nodes), "-o", str(out), "--quiet"]
    if cfl is not None:
        cmd += ["--cfl", str(cfl)]
    cmd += list(extra)
    if steps is not None:
        cmd += ["--max-steps", str(steps)]
    if end_time is not None:
        # the output times cap the time step: one output at the end for a time-step study
        every = end_time if cfl is not None else end_time / 6
        cmd += ["--end-time", str(end_time), "--output-interval", str(every)]
    peak = run_measured(cmd)
    with open(out / "diagnostics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    d = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    return {"nodes": int(d["nodes"][0]), "tetrahedra": int(np.median(d["tetrahedra"])),
            "steps": len(rows), "step_s": float(np.median(d["seconds"])),
            "its": float(np.median(d["solver_iterations"])), "peak_mb": peak,
            "picard": float(np.median(d["picard_iterations"])) if "picard_iterations" in d
            else 1.0,
            # the depth is the mean sinking of the plate's nodes: zero at the start
            "time": np.r_[0.0, d["time"]], "depth": np.r_[0.0, d["plate_depth"]], "cfl": cfl,
            "mean_dt": float(d["time"][-1] / len(rows))}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[5000, 10000])
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--end-time", type=float, default=None)
    ap.add_argument("--cfl", type=float, nargs="+", default=None)
    a, extra = ap.parse_known_args(argv)
    if (a.steps is None) == (a.end_time is None):
        ap.error("give exactly one of --steps and --end-time")
    study = a.cfl is not None and len(a.cfl) > 1
    if study and (len(a.nodes) != 1 or a.end_time is None or len(a.cfl) < 3):
        ap.error("a time-step study (several --cfl) takes one --nodes, --end-time and at "
                 "least three cfl values")
    cfls = sorted(a.cfl) if a.cfl is not None else [None]
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sorted(a.nodes):
            for c in cfls:
                runs.append(run_child(n, a.steps, a.end_time, Path(tmp) / f"{n}-{c}", c,
                                      extra))
    out = {"steps": steps_table(runs)}
    print(out["steps"])
    if study:
        out["cfl"], out["limit"] = cfl_table(runs, a.end_time)
        print("\n" + out["cfl"])
    elif a.end_time is not None and len(runs) > 1:
        out["depth"], out["worst"] = depth_table(runs, a.end_time)
        print("\n" + out["depth"])
        print(f"\nlargest relative difference from the {runs[-1]['nodes']:,}-node run: "
              f"{100 * out['worst']:.1f}%")
    return out


def steps_table(runs: list) -> str:
    """A row per run: size, steps, the median step and its cost per node, iterations,
    memory (and the cfl where one was given)."""
    base = runs[0]["step_s"] / runs[0]["nodes"]
    lines = ["| nodes | tetrahedra | steps | s a step | s a step per 1,000 nodes | "
             "per node / smallest | Picard its | FGMRES its | peak MB |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        per = r["step_s"] / r["nodes"]
        name = f"{r['nodes']:,}" + ("" if r["cfl"] is None else f" (cfl {r['cfl']:g})")
        lines.append(f"| {name} | {r['tetrahedra']:,} | {r['steps']} | "
                     f"{r['step_s']:.2f} | {1000 * per:.2f} | {per / base:.2f} | "
                     f"{r['picard']:.0f} | {r['its']:.0f} | {r['peak_mb']:,.0f} |")
    return "\n".join(lines)


def output_times(end_time: float) -> np.ndarray:
    """The six output times of a run to ``end_time``."""
    return np.linspace(0, end_time, 7)[1:]


def depth_table(runs: list, end_time: float):
    """The depth of each resolution at the output times, and the largest relative
    difference from the finest."""
    head = "| time | " + " | ".join(f"depth, {r['nodes']:,} nodes" for r in runs) + " |"
    rows = [head, "|---" * (len(runs) + 1) + "|"]
    worst = 0.0
    for t in output_times(end_time):
        vals = [float(np.interp(t, r["time"], r["depth"])) for r in runs]
        worst = max(worst, max(abs(v - vals[-1]) / abs(vals[-1]) for v in vals))
        rows.append(f"| {t:.4g} | " + " | ".join(f"{v:.4f}" for v in vals) + " |")
    return "\n".join(rows), worst


def cfl_table(runs: list, end_time: float):
    """The depth of each cfl's run at the output times, its limit as the mean dt goes to
    zero (a line through the three smallest cfl's depths against their mean dt) and each
    run's difference from it; returns the table and the limits."""
    fit = runs[:3]
    dt = np.array([r["mean_dt"] for r in fit])
    head = ("| time | " + " | ".join(f"cfl {r['cfl']:g} (mean dt {r['mean_dt']:.3g})"
                                     for r in runs) + " | limit dt -> 0 |")
    rows = [head, "|---" * (len(runs) + 2) + "|"]
    limits = []
    for t in output_times(end_time):
        vals = [float(np.interp(t, r["time"], r["depth"])) for r in runs]
        limit = float(np.polyfit(dt, vals[:3], 1)[1])
        limits.append(limit)
        cells = [f"{v:.6f} ({100 * (v / limit - 1):+.1f}%)" for v in vals]
        rows.append(f"| {t:.4g} | " + " | ".join(cells) + f" | {limit:.6f} |")
    return "\n".join(rows), np.array(limits)


if __name__ == "__main__":
    main()
