"""Stokes assembly and solve times: NEM (bubble-enriched, P1 pressure) against
scikit-fem Taylor-Hood (P2-P1) on the same Delaunay triangulation.

Problem: SolCx (viscosity jump ``--contrast``, default 1e6), free slip. For
each node count prints a markdown table row per method: basis, assembly and
solve seconds, Schur-CG iterations, unknowns and the velocity L2 error.
Iteration counts of the factorisation-free solver ('schur-amg') against mesh size and
viscosity contrast follow.

    python benchmarks/stokes.py [--sizes 1000 10000 30000] [--contrast 1e6]
"""
import argparse
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex07_solcx import errors, nodes  # noqa: E402

from skfem_nem import delaunay_mesh  # noqa: E402
from skfem_nem.models.analytic import SolCx  # noqa: E402
from skfem_nem.models.stokes import assemble_stokes, solve_stokes, stokes_spaces  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 30000])
    ap.add_argument("--contrast", type=float, default=1e6)
    a = ap.parse_args(argv)
    exact = SolCx(1.0, a.contrast)
    # warm up numba kernels
    solve_stokes(stokes_spaces(delaunay_mesh(nodes(100)), "nem"), 1.0, exact.force)
    print(f"SolCx, viscosity contrast {a.contrast:.0e}, Schur-complement CG solver\n")
    print("| nodes | method | unknowns | basis s | assembly s | solve s | CG its | u L2 | "
          "total NEM / TH |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in a.sizes:
        mesh = delaunay_mesh(nodes(n))
        tot = {}
        for method in ("taylor-hood", "nem"):
            t0 = time.perf_counter()
            sp_ = stokes_spaces(mesh, method)
            t1 = time.perf_counter()
            sy = assemble_stokes(sp_, exact.viscosity, exact.force)
            t2 = time.perf_counter()
            s = solve_stokes(sp_, None, system=sy, solver="schur", maxiter=5000)
            t3 = time.perf_counter()
            tot[method] = t3 - t0
            eu, _ = errors(sp_, s, exact)
            ratio = f"{tot['nem'] / tot['taylor-hood']:.2f}" if method == "nem" else ""
            print(f"| {mesh.p.shape[1]} | {method} | {sp_.n_velocity + sp_.n_pressure} | "
                  f"{t1 - t0:.2f} | {t2 - t1:.2f} | {t3 - t2:.2f} | {s.iterations} | "
                  f"{eu:.2e} | {ratio} |", flush=True)
    print("\nIterative solve without factorisation (solver='schur-amg': pressure CG, viscous "
          "block by AMG-preconditioned CG), tol 1e-8, NEM: outer / inner iterations, seconds\n")
    print("| nodes | contrast 1 | contrast 1e2 | contrast 1e4 | contrast 1e6 |")
    print("|---|---|---|---|---|")
    for n in a.sizes[:2]:
        mesh = delaunay_mesh(nodes(n))
        sp_ = stokes_spaces(mesh, "nem")
        cells = []
        for c in (1.0, 1e2, 1e4, 1e6):
            ex = SolCx(1.0, c)
            t0 = time.perf_counter()
            try:
                s = solve_stokes(sp_, ex.viscosity, ex.force, solver="schur-amg", tol=1e-8,
                                 maxiter=3000)
                cells.append(f"{s.iterations} / {s.info['inner_iterations']['its']}, "
                             f"{time.perf_counter() - t0:.1f} s")
            except RuntimeError as err:
                cells.append("no convergence (" + str(err)[:60] + ")")
        print(f"| {mesh.p.shape[1]} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
