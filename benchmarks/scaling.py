"""How the Stokes solvers scale: SolCx against mesh size and viscosity contrast,
and the step of the sinking-plate app, with the old and the new solver.

**SolCx** (``skfem_nem.models.analytic.SolCx``, the random nodes of
``examples/ex07_solcx.py``, without interface segments or, with ``--segments``, with
the interface x = 0.5 as segments as in the example, natural-neighbour
velocity with bubbles, free slip, ``tol`` 1e-10): for each node count and
contrast the system is assembled once and each solver runs in a forked child
process (so that its peak memory is its own): iterations, seconds (best of
``--repeat``), the relative velocity difference ``|u - u_ref| / |u_ref|`` to
the direct solve (to ``"schur"`` where the direct solve is skipped) and the
peak resident memory the solve added (``ru_maxrss`` of the child minus the
resident size at the fork). A solve still running after ``--max-seconds`` is
stopped and reported as such; a size whose reference solve takes longer than
that is skipped with the solvers that follow it.

**Sinking plate**: ``skfem-nem sinking-plate --nodes N --max-steps 3 --solver S``
in a subprocess for each ``N`` and solver; the mean seconds of steps 2 and 3 (step 1
compiles kernels) split as the diagnostics split them (basis, Stokes assembly and
linear solver summed over the Picard iterations, the mesh's evolution, the whole
step), best of ``--repeat``; the step's microseconds per node and their ratio to the
first size's (linear cost: 1), Picard iterations, the plate depth after step 3 and the
peak memory of the run's process. ``--plate-solvers schur schur:refactor schur:strict``
measures the default solver against itself factorising every solve (``REUSE_FACTOR``
off), against itself solving the Picard iterations' Stokes systems to the final
solves' ``LINEAR_TOL`` (``PICARD_LINEAR_FACTOR`` 0); ``schur:double`` against its
factors in double precision (``FACTOR_DTYPE``); ``schur:whole`` against the whole
viscous block's factors at every size (``SPLIT_MIN_UNKNOWNS`` out of reach).

Prints markdown tables. Quick run::

    python benchmarks/scaling.py --sizes 1000 4000 --plate-nodes 1500 --repeat 1
"""
import argparse
import csv
import multiprocessing as mp
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex07_solcx import make_mesh, nodes  # noqa: E402

from skfem_nem import delaunay_mesh  # noqa: E402
from skfem_nem.models.analytic import SolCx  # noqa: E402
from skfem_nem.models.stokes import assemble_stokes, solve_stokes, stokes_spaces  # noqa: E402
from skfem_nem.models.stokes_solvers import SOLVERS  # noqa: E402

SOLVER_ORDER = ("direct", "schur", "schur-amg", "minres", "fgmres")
# the direct solve of the whole system is run up to this many nodes (it took
# 96 s at 10,000 nodes)
DIRECT_MAX_NODES = 5000
# variants of the plate's solver "schur", by the module setting each changes: factorising
# the viscous block at every solve, as before the factorisation was kept between the
# Picard iterations (stokes_solvers.REUSE_FACTOR); solving every Picard iteration to the
# final solves' LINEAR_TOL, as before those stopped near the Picard tolerance
# (rheology.PICARD_LINEAR_FACTOR); factorising the viscous block in double precision, as
# before the single-precision factors (stokes_solvers.FACTOR_DTYPE); factorising the whole
# block, as before the factors per velocity component (stokes_solvers.SPLIT_MIN_UNKNOWNS)
VARIANTS = {"schur:refactor": "import skfem_nem.models.stokes_solvers as s; "
                              "s.REUSE_FACTOR = False; ",
            "schur:strict": "import skfem_nem.models.rheology as r; "
                            "r.PICARD_LINEAR_FACTOR = 0.0; ",
            "schur:double": "import numpy; import skfem_nem.models.stokes_solvers as s; "
                            "s.FACTOR_DTYPE = numpy.float64; ",
            "schur:whole": "import skfem_nem.models.stokes_solvers as s; "
                           "s.SPLIT_MIN_UNKNOWNS = 10 ** 12; "}


def _rss_kb() -> float:
    """Current resident set size of this process, kB."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024


def _child(conn, spaces, system, solver, repeat, maxiter):
    """Runs in the forked process: the solve ``repeat`` times, sends
    (iterations, best seconds, u, peak MB added, error)."""
    base = _rss_kb()
    best, s, err = np.inf, None, ""
    try:
        for _ in range(repeat):
            t = time.perf_counter()
            s = solve_stokes(spaces, None, system=system, solver=solver, tol=1e-10,
                             maxiter=maxiter)
            best = min(best, time.perf_counter() - t)
    except RuntimeError as e:
        err = str(e).split(":")[0]
    peak = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
    conn.send((None if s is None else s.iterations, best, None if s is None else s.u,
               peak, err))
    conn.close()


def measure(spaces, system, solver, repeat, max_seconds, maxiter):
    """One solver in a forked child; a dict of what it measured (``status``
    tells whether it finished)."""
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_child, args=(send, spaces, system, solver, repeat, maxiter))
    t0 = time.perf_counter()
    p.start()
    send.close()
    ready = recv.poll(max_seconds)
    if not ready:
        p.terminate()
        p.join()
        return dict(status=f"stopped after {max_seconds:.0f} s")
    its, sec, u, peak, err = recv.recv()
    p.join()
    if err:
        return dict(status=err, seconds=time.perf_counter() - t0)
    return dict(status="ok", iterations=its, seconds=sec, u=u, peak_mb=peak)


def solcx_table(sizes, contrasts, solvers, repeat, max_seconds, maxiter, segments=False):
    """Markdown rows of the SolCx study (printed as they come); ``segments``: the
    interface x = 0.5 as segments (constrained natural neighbours)."""
    print(f"SolCx ({'interface as segments' if segments else 'no segments'}), tol 1e-10: "
          f"iterations, seconds (best of {repeat}), relative velocity difference to the "
          "reference, peak memory added\n")
    print("| nodes | unknowns | contrast | solver | iterations | seconds | du (ref) | peak MB |")
    print("|---|---|---|---|---|---|---|---|")
    skip = set()
    for n in sizes:
        mesh = make_mesh(n, constrained=segments)
        sp_ = stokes_spaces(mesh, "nem")
        nn = mesh.p.shape[1]
        for contrast in contrasts:
            ex = SolCx(1.0, contrast)
            system = assemble_stokes(sp_, ex.viscosity, ex.force)
            ref, ref_name = None, ""
            for solver in solvers:
                if solver == "direct" and nn > DIRECT_MAX_NODES:
                    continue
                if (solver, contrast) in skip:
                    print(f"| {nn} | {sp_.n_velocity + sp_.n_pressure} | {contrast:.0e} | "
                          f"{solver} | skipped (over {max_seconds:.0f} s at a smaller size) "
                          f"| | | |", flush=True)
                    continue
                r = measure(sp_, system, solver, repeat, max_seconds, maxiter)
                if r["status"] != "ok":
                    if r["status"].startswith("stopped"):
                        skip.add((solver, contrast))
                    print(f"| {nn} | {sp_.n_velocity + sp_.n_pressure} | {contrast:.0e} | "
                          f"{solver} | {r['status']} | | | |", flush=True)
                    continue
                if ref is None:
                    ref, ref_name = r["u"], solver
                du = np.linalg.norm(r["u"] - ref) / np.linalg.norm(ref)
                print(f"| {nn} | {sp_.n_velocity + sp_.n_pressure} | {contrast:.0e} | {solver} | "
                      f"{r['iterations']} | {r['seconds']:.2f} | {du:.1e} ({ref_name}) | "
                      f"{r['peak_mb']:.0f} |", flush=True)


#: the parts of a plate step in its diagnostics, in the order of the table
STEP_PARTS = ("basis", "assembly", "solver", "evolution", "step")


def plate_run(n, solver, out):
    """One 3-step sinking-plate run: the mean seconds of steps 2-3 per part of
    :data:`STEP_PARTS`, the nodes, Picard iterations, the depth after step 3 and the
    peak resident memory (MB) of the run's process. ``solver`` is a solver of the
    command line, or one of :data:`VARIANTS` (of ``"schur"``)."""
    setup = VARIANTS.get(solver, "")
    cmd = [sys.executable, "-c", setup + "import resource, sys; from skfem_nem.apps.cli "
           "import main; rc = main(sys.argv[1:]); print('PEAK_KB', resource.getrusage("
           "resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); sys.exit(rc)",
           "sinking-plate", "--nodes", str(n), "--max-steps", "3", "--solver",
           solver.split(":")[0], "-o", out, "--quiet"]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True)
    peak = float(done.stderr.split("PEAK_KB")[-1].split()[0]) / 1024
    with open(Path(out) / "diagnostics.csv") as fh:
        rows = list(csv.DictReader(fh))
    later = rows[1:] or rows
    seconds = {p: np.mean([float(r[f"{p}_seconds"]) for r in later]) for p in STEP_PARTS}
    return {"seconds": seconds, "nodes": int(rows[-1]["nodes"]), "peak_mb": peak,
            "picard": sum(int(r["picard_iterations"]) for r in rows),
            "depth": float(rows[-1]["plate_depth"])}


def plate_table(sizes, solvers, repeat):
    """Markdown rows of the sinking-plate study: the step split into its parts, and
    the step's seconds per node against the first size's."""
    print("\nSinking plate, 3 steps: mean seconds of steps 2-3 (best of "
          f"{repeat}) for the basis, the Stokes assembly and the linear solver (summed over "
          "the Picard iterations), the mesh's evolution and the whole step; Picard "
          "iterations, plate depth after step 3, peak memory\n")
    print("| drawn nodes | nodes | solver | basis s | assembly s | solver s | evolution s | "
          "step s | step us per node | vs first | Picard its | plate depth | peak MB |")
    print("|---" * 13 + "|")
    first = {}
    for n in sizes:
        for solver in solvers:
            best = None
            for _ in range(repeat):
                with tempfile.TemporaryDirectory() as tmp:
                    r = plate_run(n, solver, tmp)
                if best is None or r["seconds"]["step"] < best["seconds"]["step"]:
                    best = r
            s = best["seconds"]
            per_node = s["step"] / best["nodes"] * 1e6
            first.setdefault(solver, per_node)
            print(f"| {n} | {best['nodes']} | {solver} | {s['basis']:.2f} | "
                  f"{s['assembly']:.2f} | {s['solver']:.2f} | {s['evolution']:.2f} | "
                  f"{s['step']:.2f} | {per_node:.0f} | {per_node / first[solver]:.2f} | "
                  f"{best['picard']} | {best['depth']:.6f} | {best['peak_mb']:.0f} |",
                  flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 10000, 100000])
    ap.add_argument("--contrasts", type=float, nargs="+", default=[1.0, 1e2, 1e4, 1e6])
    ap.add_argument("--solvers", nargs="+", default=list(SOLVER_ORDER),
                    help="first the reference (direct, else schur)")
    ap.add_argument("--plate-nodes", type=int, nargs="*", default=[1500, 6000, 24000])
    ap.add_argument("--plate-solvers", nargs="+", default=["auto", "fgmres"])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--max-seconds", type=float, default=600.0)
    ap.add_argument("--maxiter", type=int, default=3000)
    ap.add_argument("--segments", action="store_true",
                    help="SolCx with the interface x = 0.5 as segments")
    a = ap.parse_args(argv)
    for name in a.plate_solvers:
        if name not in SOLVERS and name not in VARIANTS:
            ap.error(f"--plate-solvers: unknown solver {name!r} (solvers: "
                     f"{', '.join(SOLVERS)}; variants: {', '.join(VARIANTS)})")
    # numba kernels compiled once, before the forks
    solve_stokes(stokes_spaces(delaunay_mesh(nodes(100)), "nem"), 1.0, SolCx(1.0, 1.0).force)
    solvers = sorted(a.solvers, key=lambda s: SOLVER_ORDER.index(s) if s in SOLVER_ORDER
                     else len(SOLVER_ORDER))
    if a.sizes:
        solcx_table(a.sizes, a.contrasts, solvers, a.repeat, a.max_seconds, a.maxiter,
                    a.segments)
    if a.plate_nodes:
        plate_table(a.plate_nodes, a.plate_solvers, a.repeat)


if __name__ == "__main__":
    main()
