"""SolCx with the quadratic natural-neighbour velocity against Taylor-Hood: time and memory.

The cost table of docs/quadratic.md ("Cost"): SolCx at a viscosity contrast of 1e6 on the
constrained triangles of ``examples/ex07_solcx.py`` (the interface x = 0.5 as segments), one
solve to a relative residual of 1e-8, for

* ``C-NEM2, schur``: the quadratic natural-neighbour velocity (``method="nem2"``) with the
  factorised viscous block (``solver="schur"``);
* ``C-NEM2, fgmres``: the same with FGMRES preconditioned by the two-level method on the
  viscous block (``models.stokes_two_level``), no factorisation;
* ``Taylor-Hood``: scikit-fem's P2-P1 on the same triangles, ``solver="schur"`` (its best).

Each case runs in a process of its own: a small SolCx first (numba's kernels loaded from
their cache, stated apart as ``load s``), then the measured one. Printed per case: velocity
unknowns, iterations, the basis, assembly and solver seconds of the measured solve, the peak
resident memory it added (MB) and the velocity and pressure L2 errors; then the ratios of
each C-NEM2 row to Taylor-Hood's at the same nodes.

    python benchmarks/quadratic_stokes.py [--nodes 1000 4000 16000] [--cases ...]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: the cases: (method, solver) by name
CASES = {"C-NEM2, schur": ("nem2", "schur"), "C-NEM2, fgmres": ("nem2", "fgmres"),
         "Taylor-Hood": ("taylor-hood", "schur")}
#: SolCx's viscosity contrast
CONTRAST = 1e6
#: the solve's relative residual: the errors are those of a solve to 1e-10 to 7 digits
#: (C-NEM2 at 4,000 nodes), and FGMRES with the two-level method stalled near 7.7e-10 at
#: 16,000 nodes (rounding at the contrast of 1e6)
TOL = 1e-8
#: nodes of the warm-up solve (loads the kernels)
WARM_NODES = 250


def _rss_mb() -> float:
    """Current resident set size of this process, MB."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def one(nodes: int, case: str) -> dict:
    """The measured solve of ``case`` on ``nodes`` nodes (run in a process of its own)."""
    sys.path.insert(0, str(HERE.parent / "examples"))
    import ex07_solcx

    from skfem_nem.models.analytic import SolCx
    from skfem_nem.models.stokes import solve_stokes, stokes_spaces
    method, solver = CASES[case]
    exact = SolCx(1.0, CONTRAST)

    def run(n):
        mesh = ex07_solcx.make_mesh(n)
        t0 = time.perf_counter()
        spaces = stokes_spaces(mesh, method)
        t1 = time.perf_counter()
        s = solve_stokes(spaces, exact.viscosity, exact.force, solver=solver, tol=TOL,
                         maxiter=5000)
        return spaces, s, t1 - t0, time.perf_counter() - t0

    t = time.perf_counter()
    run(WARM_NODES)
    load = time.perf_counter() - t
    base = _rss_mb()
    spaces, s, basis, total = run(nodes)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - base
    eu, ep = ex07_solcx.errors(ex07_solcx.error_spaces(spaces), s, exact)
    return dict(nodes=nodes, case=case, unknowns=int(spaces.n_velocity),
                iterations=int(s.iterations),
                basis=basis, assembly=s.info["assembly_seconds"],
                solver=s.info["solver_seconds"], total=total, peak_mb=peak, u_l2=eu,
                p_l2=ep, load=load)


def measure(nodes: int, case: str) -> dict:
    """:func:`one` in a new process (its peak memory its own)."""
    done = subprocess.run([sys.executable, __file__, "--one", str(nodes), case], check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(rows) -> str:
    """The markdown table of the rows, with each C-NEM2 row's ratios to Taylor-Hood's."""
    th = {r["nodes"]: r for r in rows if r["case"] == "Taylor-Hood"}
    out = ["| nodes | case | velocity unknowns | its | basis s | assembly s | solver s | "
           "total s | peak MB | u L2 | p L2 | time / TH | memory / TH |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ref = th.get(r["nodes"])
        ratio = ("", "") if ref is None or r is ref else (
            f"{r['total'] / ref['total']:.1f}",
            f"{r['peak_mb'] / ref['peak_mb']:.1f}" if ref["peak_mb"] > 0 else "-")
        out.append(f"| {r['nodes']:,} | {r['case']} | {r['unknowns']:,} | {r['iterations']} | "
                   f"{r['basis']:.2f} | {r['assembly']:.2f} | {r['solver']:.2f} | "
                   f"{r['total']:.2f} | {r['peak_mb']:.0f} | {r['u_l2']:.3e} | "
                   f"{r['p_l2']:.3e} | {ratio[0]} | {ratio[1]} |")
    loads = ", ".join(f"{r['case']} {r['load']:.1f} s" for r in rows[:len(CASES)])
    return "\n".join(out) + f"\n\nKernel load and warm-up ({WARM_NODES} nodes), apart: {loads}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[1000, 4000, 16000])
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    ap.add_argument("--one", nargs=2, metavar=("NODES", "CASE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(int(args.one[0]), args.one[1])))
        return
    rows = []
    for n in args.nodes:
        for case in args.cases:
            rows.append(measure(n, case))
            print(rows[-1], file=sys.stderr, flush=True)
    print(table(rows))


if __name__ == "__main__":
    main()
