"""Robustness of the sinking-plate run over its parameter space.

Runs the sinking plate (``skfem_nem.apps.sinking_plate``) to ``end_time`` for every
combination of node count, seed, plate density, yield stress and lower-layer
viscosity given (the default grid: nodes 300, 1000, 3000; seeds 0-4; plate density
1.5 and 3; yield stress 0.05 and 0.3; lower-layer viscosity 1 and 100: 120 runs), all
other parameters at their defaults, and reports for each run whether it completed, the
time reached, the largest plate-area deviation, outline crossings, the smallest angle,
the final node count, injections, removals and merges, retried steps, the pieces the
plate ended in (it breaks where it necks through) and the wall time; and, from each
run's diagnostics, the smallest node count over the run relative to the initial mesh's,
the longest edge over the run relative to the initial mesh's and the steps accepted with
an unconverged predictor-corrector (none may be).

``--grid resolution`` takes the resolution grid instead (nodes 300, 1500, 3000; seeds 0
and 1; lower-layer viscosity 0.1, 0.3, 1 and 10; scenarios ``default``, plates near a wall
``wall-left`` and ``wall-right`` (plate x 1.2 and 8.8), ``thin-long`` (thickness 0.05,
length 2.5) and ``narrow`` (box width 3): 120 runs), where the flow stretches the mesh the
most; ``--scenario`` picks scenarios of either grid.

A run that stops (the mesh cannot continue, a solver fails) is reported with its reason,
never aborts the study. Each run writes its outputs in its own folder under ``--out``;
the rows go to ``robustness.csv`` there as runs finish (a study can be resumed: finished
runs are read back, not redone) and the markdown table is printed.
With ``--continue-stopped`` the study's stopped runs are continued from the checkpoints
their stops wrote, with today's code (a run's new row replaces the old one).

    python benchmarks/robustness.py [--nodes 300 1000 3000] [--seeds 0 1 2 3 4]
        [--plate-density 1.5 3] [--yield-stress 0.05 0.3] [--eta-lower 1 100]
        [--grid old|resolution] [--scenario default narrow ...] [--jobs 2]
        [--end-time 1000] [--out out/robustness] [--continue-stopped]

A study spread over several folders (runs on several machines, or continued from a
stop's checkpoint) is reported as one with ``--report``: the CSVs given are merged (the
first that holds a setting gives its row) and the summary by node count and lower-layer
viscosity (the table of ``docs/sinking_plate.md``) and the whole table are printed::

    python benchmarks/robustness.py --report continued/robustness.csv out/robustness.csv

The rows of the whole grid as measured for ``docs/sinking_plate.md`` are kept in
``benchmarks/results/robustness.csv``.
"""
from __future__ import annotations

import argparse
import csv
import itertools
import multiprocessing
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

COLUMNS = ["nodes", "seed", "plate_density", "yield_stress", "eta_lower", "scenario",
           "completed", "t_reached", "steps", "max_area_deviation", "outline_crossings",
           "min_angle", "final_nodes", "min_node_ratio", "max_edge_ratio", "unconverged",
           "injected", "removed", "merged", "retries", "inverted", "non_delaunay", "pieces",
           "seconds", "stop"]
#: the varied parameters (the first five columns); "scenario" names a set of overrides
VARIED = COLUMNS[:5]
GRID = {"nodes": [300, 1000, 3000], "seeds": [0, 1, 2, 3, 4], "plate_density": [1.5, 3.0],
        "yield_stress": [0.05, 0.3], "eta_lower": [1.0, 100.0], "scenario": ["default"]}
#: the resolution grid (``--grid resolution``): a weak lower layer, plates near a wall,
#: thin long plates and narrow boxes, where the flow stretches the mesh the most
RESOLUTION_GRID = {"nodes": [300, 1500, 3000], "seeds": [0, 1], "plate_density": [1.5],
                   "yield_stress": [0.12], "eta_lower": [0.1, 0.3, 1.0, 10.0],
                   "scenario": ["default", "wall-left", "wall-right", "thin-long", "narrow"]}
#: the configurations a scenario changes (all else default)
SCENARIOS = {"default": {}, "wall-left": {"plate_x": 1.2}, "wall-right": {"plate_x": 8.8},
             "thin-long": {"plate_thickness": 0.05, "plate_length": 2.5},
             "narrow": {"width": 3.0, "plate_x": 1.5}}


def settings(args):
    """The grid of runs: dicts of the varied parameters."""
    for n, s, d, y, e, sc in itertools.product(args.nodes, args.seeds, args.plate_density,
                                               args.yield_stress, args.eta_lower,
                                               args.scenario):
        yield {"nodes": int(n), "seed": int(s), "plate_density": float(d),
               "yield_stress": float(y), "eta_lower": float(e), "scenario": sc}


def name_of(setting) -> str:
    name = "n{nodes}-s{seed}-d{plate_density:g}-y{yield_stress:g}-e{eta_lower:g}".format(
        **setting)
    scenario = setting.get("scenario") or "default"
    return name if scenario == "default" else f"{name}-{scenario}"


def config_of(setting, **more):
    """The run's configuration: the varied parameters and the scenario's overrides."""
    from skfem_nem.apps.sinking_plate import PlateConfig
    varied = {k: setting[k] for k in VARIED}
    return PlateConfig(**varied, **SCENARIOS[setting.get("scenario") or "default"], **more)


def initial_measures(cfg):
    """The node count and the longest edge of the run's initial mesh (what the node
    counts and edges over the run are compared with)."""
    from skfem_nem.apps.sinking_plate import initial_nodes
    from skfem_nem.evolution import LagrangianMesh
    nodes, outline, interface = initial_nodes(cfg)
    segs = None
    if cfg.segments:
        segs = np.r_[np.c_[outline, np.roll(outline, -1)],
                     np.c_[interface[:-1], interface[1:]]]
    lm = LagrangianMesh(nodes, segments=segs)
    return lm.nodes.shape[0], lm.longest_edge()


def run_one(setting, end_time: float, out: str) -> dict:
    """One run; returns its row (a stopped run is a row too)."""
    from skfem_nem.apps.sinking_plate import SinkingPlate

    cfg = config_of(setting, end_time=end_time, output_interval=end_time, checkpoint_every=50)
    t0 = time.perf_counter()
    sim = SinkingPlate(cfg, Path(out) / name_of(setting))
    return _finish(sim, setting, sim.plate_area_centroid()[0], t0)


def continue_one(row: dict, end_time: float, out: str) -> dict:
    """Continue the stopped run of ``row`` from the checkpoint its stop wrote, with
    today's code, to ``end_time``; returns its new row (the wall time adds up both
    parts)."""
    from skfem_nem.apps.sinking_plate import SinkingPlate, stored_config

    setting = setting_of(row)
    folder = Path(out) / name_of(setting)
    t0 = time.perf_counter() - float(row.get("seconds") or 0.0)
    sim = SinkingPlate.restart(folder, stored_config(folder, {"end_time": end_time}))
    return _finish(sim, setting, sim.plate_area0, t0)


def _finish(sim, setting, area0: float, t0: float) -> dict:
    """Run ``sim`` to its end (or its stop: then a checkpoint) and return its row, the
    plate's area measured against ``area0``."""
    import warnings

    from skfem_nem.apps.output import read_csv_columns
    stop = ""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim.run(progress=False)
    except Exception as err:  # the study records why a run stopped and goes on
        stop = (str(err).splitlines() or [type(err).__name__])[0][:160]
        sim.checkpoint()
    seconds = time.perf_counter() - t0
    d = read_csv_columns(sim.out / "diagnostics.csv")
    n0, L0 = initial_measures(sim.cfg)
    row = dict(setting)
    if "longest_edge" in d:
        row.update(min_node_ratio=round(float(d["nodes"].min() / n0), 4),
                   max_edge_ratio=round(float(d["longest_edge"].max() / L0), 3),
                   unconverged=int(np.count_nonzero(d["predictor_converged"] == 0)))
    row.update(completed=not stop, t_reached=float(sim.lm.time), steps=len(d["time"]),
               max_area_deviation=float(np.abs(d["plate_area"] / area0 - 1).max()),
               outline_crossings=int(d["outline_crossings"].max()),
               min_angle=float(d["min_angle"].min()), final_nodes=int(d["nodes"][-1]),
               injected=int(d["injected"].sum()), removed=int(d["removed"].sum()),
               merged=int(d["merged"].sum()), retries=int(d["retries"].sum()),
               **mesh_checks(d), pieces=len(sim.outlines.loops),
               seconds=round(seconds, 1), stop=stop)
    return row


def mesh_checks(d) -> dict:
    """The most inverted triangles and non-Delaunay edges at the end of any step, from a
    run's diagnostics columns ``d``."""
    return {"inverted": int(d["inverted_triangles"].max()),
            "non_delaunay": int(d["non_delaunay_edges"].max())}


def _safe_run(job, end_time, out):
    """The row of ``job``: a setting to run, or the row of a stopped run to continue."""
    stopped_row = "completed" in job
    setting = setting_of(job) if stopped_row else job
    try:
        if stopped_row:
            return continue_one(job, end_time, out)
        return run_one(setting, end_time, out)
    except Exception:  # a failure before the first step: still a row
        row = dict(setting, completed=False, stop=traceback.format_exc().splitlines()[-1])
        return {k: row.get(k, "") for k in COLUMNS}


def _results(todo, args):
    """The rows of the runs ``todo`` (settings to run, rows of stopped runs to
    continue: :func:`_safe_run`) as they finish: in this process for one job, else
    in fresh (spawned) processes: forking a process whose numba threads are running
    is not safe."""
    if args.jobs == 1:
        for s in todo:
            yield _safe_run(s, args.end_time, args.out)
        return
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.jobs, mp_context=ctx) as pool:
        futures = [pool.submit(_safe_run, s, args.end_time, args.out) for s in todo]
        for fut in as_completed(futures):
            yield fut.result()


def read_done(path: Path) -> dict:
    """Rows of the runs already in ``path`` (resuming a study), by name."""
    if not path.exists():
        return {}
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    return {name_of(setting_of(r)): r for r in rows}


def setting_of(row: dict) -> dict:
    """The varied parameters of a study row."""
    return {"nodes": int(row["nodes"]), "seed": int(row["seed"]),
            "plate_density": float(row["plate_density"]),
            "yield_stress": float(row["yield_stress"]), "eta_lower": float(row["eta_lower"]),
            "scenario": row.get("scenario") or "default"}


def stopped(done: dict, out: Path, grid) -> list:
    """The rows of ``done`` (by name) of the settings ``grid`` whose runs stopped and left
    a checkpoint in ``out`` to continue from."""
    rows = [done.get(name_of(s)) for s in grid]
    return [r for r in rows if r is not None and str(r["completed"]) != "True"
            and (out / name_of(setting_of(r)) / "checkpoint.json").exists()]


def _rewrite(log: Path, rows) -> None:
    """Write ``rows`` to ``log`` with today's columns (missing ones empty)."""
    with open(log, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in COLUMNS})


def table(rows) -> str:
    """The markdown table of the rows."""
    head = ["nodes", "seed", "density", "yield", "eta_lower", "scenario", "completed", "t",
            "steps", "area dev.", "crossings", "min angle", "nodes at end", "fewest nodes",
            "longest edge", "unconverged", "injected", "removed", "merged", "retries",
            "pieces", "s", "stop"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        def f(k, fmt="{}"):
            v = r.get(k, "")
            try:
                return fmt.format(float(v)) if fmt != "{}" else str(v)
            except ValueError:
                return str(v)
        lines.append("| " + " | ".join([
            f("nodes"), f("seed"), f("plate_density", "{:g}"), f("yield_stress", "{:g}"),
            f("eta_lower", "{:g}"), r.get("scenario") or "default", f("completed"),
            f("t_reached", "{:.5g}"), f("steps"),
            f("max_area_deviation", "{:.1e}"), f("outline_crossings"),
            f("min_angle", "{:.2g}"), f("final_nodes"), f("min_node_ratio", "{:.3f}") or "-",
            f("max_edge_ratio", "{:.2f}") or "-", f("unconverged") or "-",
            f("injected"), f("removed"),
            f("merged"), f("retries"), f("pieces") or "1", f("seconds", "{:.0f}"),
            f("stop") or "-"]) + " |")
    return "\n".join(lines)


def summary(rows) -> str:
    done = [r for r in rows if str(r["completed"]) == "True"]
    dev = [float(r["max_area_deviation"]) for r in rows if r.get("max_area_deviation", "")
           != ""]
    return (f"{len(done)} of {len(rows)} runs completed; largest plate-area deviation "
            f"{max(dev) if dev else float('nan'):.2e}")


def merged(paths) -> list:
    """The rows of the study CSVs ``paths``, one per setting (the first file that holds
    it gives the row), sorted by setting."""
    rows = {}
    for path in paths:
        for name, row in read_done(Path(path)).items():
            if name not in rows:
                rows[name] = _with_mesh_checks(row, Path(path).parent / name)
    return sorted(rows.values(), key=sort_key)


def sort_key(row):
    """Rows by scenario, then by the varied parameters."""
    return (row.get("scenario") or "default",) + tuple(float(row[k]) for k in VARIED)


def _with_mesh_checks(row: dict, folder: Path) -> dict:
    """``row``, with the columns its study's CSV predates read from the run's folder:
    the mesh checks from its diagnostics, the pieces from its last checkpoint (left
    empty if the run's folder is not there)."""
    import json
    row = dict(row)
    if row.get("inverted", "") == "" and (folder / "diagnostics.csv").exists():
        from skfem_nem.apps.output import read_csv_columns
        row.update(mesh_checks(read_csv_columns(folder / "diagnostics.csv")))
    if row.get("pieces", "") == "" and (folder / "checkpoint.json").exists():
        meta = json.loads((folder / "checkpoint.json").read_text())
        row["pieces"] = len(meta.get("outlines", [None]))   # before breakup: one outline
    return row


def grid_summary(rows) -> str:
    """Markdown table: per node count and lower-layer viscosity, the runs measured (of the
    grid's 20: seeds x densities x yield stresses), completed, the largest plate-area
    deviation, the smallest angle, outline crossings, most pieces and retried steps."""
    groups = {}
    for r in rows:
        groups.setdefault((int(r["nodes"]), float(r["eta_lower"])), []).append(r)
    per = len(GRID["seeds"]) * len(GRID["plate_density"]) * len(GRID["yield_stress"])
    lines = [f"| nodes | eta_lower | runs measured (of {per}) | completed | largest area "
             f"deviation | smallest angle (deg) | outline crossings | inverted, non-Delaunay "
             f"| most pieces | retried steps |", "|" + "---|" * 10]
    for (n, e), rs in sorted(groups.items()):
        lines.append(
            f"| {n:,} | {e:g} | {len(rs)} | {sum(str(r['completed']) == 'True' for r in rs)} "
            f"| {max(float(r['max_area_deviation']) for r in rs):.1e} "
            f"| {min(float(r['min_angle']) for r in rs):.2g} "
            f"| {max(int(r['outline_crossings']) for r in rs)} | {_checked(rs)} "
            f"| {max(int(r.get('pieces') or 1) for r in rs)} "
            f"| {sum(int(r['retries']) for r in rs)} |")
    return "\n".join(lines)


def resolution_summary(rows) -> str:
    """Markdown table: per scenario and lower-layer viscosity, the runs, how many
    completed, the smallest node count over a run relative to its first, the longest edge
    over a run relative to the first mesh's, the smallest angle, accepted steps with an
    unconverged predictor-corrector, the largest plate-area deviation and retried steps
    (runs measured before these columns existed are left out)."""
    groups = {}
    for r in rows:
        if str(r.get("min_node_ratio", "")) != "":
            groups.setdefault((r.get("scenario") or "default", float(r["eta_lower"])),
                              []).append(r)
    lines = ["| scenario | eta_lower | runs | completed | fewest nodes / first | longest "
             "edge / first | smallest angle (deg) | unconverged steps | largest area "
             "deviation | retries (halvings) |", "|" + "---|" * 10]
    for (sc, e), rs in sorted(groups.items()):
        lines.append(
            f"| {sc} | {e:g} | {len(rs)} | {sum(str(r['completed']) == 'True' for r in rs)} "
            f"| {min(float(r['min_node_ratio']) for r in rs):.3f} "
            f"| {max(float(r['max_edge_ratio']) for r in rs):.2f} "
            f"| {min(float(r['min_angle']) for r in rs):.2g} "
            f"| {sum(int(r['unconverged']) for r in rs)} "
            f"| {max(float(r['max_area_deviation']) for r in rs):.1e} "
            f"| {sum(int(r['retries']) for r in rs)} |")
    return "\n".join(lines)


def _checked(rows) -> str:
    """Most inverted triangles and non-Delaunay edges over the rows, and how many rows
    are unchecked (their run's diagnostics missing)."""
    known = [r for r in rows if str(r.get("inverted", "")) != ""]
    text = (f"{max(int(r['inverted']) for r in known)}, "
            f"{max(int(r['non_delaunay']) for r in known)}") if known else "-"
    return text if len(known) == len(rows) else f"{text} ({len(rows) - len(known)} unchecked)"


def report(paths) -> list:
    """Print the merged study of the CSVs ``paths``: summary, whole table, counts."""
    rows = merged(paths)
    print(grid_summary(rows))
    print()
    print(resolution_summary(rows))
    print()
    print(table(rows))
    print()
    print(summary(rows))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grid", choices=("old", "resolution"), default="old",
                    help="the defaults of the lists below: the old grid of 120 runs, or "
                         "the resolution grid (weak lower layers, plates near walls, thin "
                         "long plates, narrow boxes: 120 runs)")
    ap.add_argument("--nodes", type=int, nargs="+")
    ap.add_argument("--seeds", type=int, nargs="+")
    ap.add_argument("--plate-density", type=float, nargs="+")
    ap.add_argument("--yield-stress", type=float, nargs="+")
    ap.add_argument("--eta-lower", type=float, nargs="+")
    ap.add_argument("--scenario", nargs="+", choices=sorted(SCENARIOS))
    ap.add_argument("--end-time", type=float, default=1000.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default="out/robustness")
    ap.add_argument("--continue-stopped", action="store_true",
                    help="also continue the study's stopped runs from the checkpoints "
                         "their stops wrote, with today's code")
    ap.add_argument("--report", nargs="+", metavar="CSV",
                    help="merge these study CSVs and print their tables (runs nothing)")
    args = ap.parse_args(argv)
    grid = RESOLUTION_GRID if args.grid == "resolution" else GRID
    for key, name in (("nodes", "nodes"), ("seeds", "seeds"), ("plate_density", "plate_density"),
                      ("yield_stress", "yield_stress"), ("eta_lower", "eta_lower"),
                      ("scenario", "scenario")):
        if getattr(args, name) is None:
            setattr(args, name, grid[key])
    if args.report:
        return report(args.report)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "robustness.csv"
    done = read_done(log)
    todo = [s for s in settings(args) if name_of(s) not in done]
    if args.continue_stopped:
        todo += stopped(done, out, settings(args))
    if done and set(next(iter(done.values()))) != set(COLUMNS):
        _rewrite(log, list(done.values()))    # a study begun with fewer columns
    new_file = not log.exists()
    with open(log, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        if new_file:
            w.writeheader()
        for k, row in enumerate(_results(todo, args), 1):
            w.writerow({c: row.get(c, "") for c in COLUMNS})   # (the last row of a run
            fh.flush()                                          # is the one read back)
            done[name_of(row)] = row
            print(f"[{k}/{len(todo)}] {name_of(row)}: completed {row['completed']}, "
                  f"t = {row.get('t_reached', '')}", flush=True)
    rows = [done[name_of(s)] for s in settings(args) if name_of(s) in done]
    rows.sort(key=sort_key)
    print()
    print(resolution_summary(rows))
    print()
    print(table(rows))
    print()
    print(summary(rows))
    return rows


if __name__ == "__main__":
    main()
