"""The Stokes solve on PETSc over MPI: assembly, solve, iterations and memory per rank.

SolCx at a viscosity contrast of 1e6 (``examples/ex07_solcx.py``'s nodes, the interface
as segments, natural-neighbour velocity with bubbles, free slip, tol 1e-10), solved with
``solve_stokes(..., solver="petsc")`` under ``mpiexec -n R`` for each rank count ``R``
and node count. Each run is a fresh ``mpiexec`` of this script (``--worker``), so its
peak memory is its own. Reported, the slowest rank's seconds (best of ``--repeat``):

- ``spaces``: the bases (natural-neighbour coordinates at the quadrature points), built
  on every rank: replicated, like the mesh;
- ``assembly``: this rank's share of the system (its strip of triangles,
  ``StokesSpaces.restricted``), the part that distributed assembly divides;
- ``solve``: the rest of ``solve_stokes`` (walls, the rows summed into PETSc, FGMRES);
- FGMRES iterations, the triangles each rank assembled, the peak resident memory of
  the largest rank, and the relative velocity and pressure difference to the run on
  the first rank count.

Needs petsc4py and mpi4py (``docs/parallel.md``) and ``mpiexec`` on the path. Prints a
markdown table. Quick run::

    python benchmarks/mpi.py --sizes 10000 --ranks 1 2
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parents[1] / "examples"))


def worker(nodes: int, repeat: int, out: str) -> None:
    """Runs on every rank: times spaces, assembly and solve; rank 0 writes the JSON
    summary and the solution to ``out``."""
    from ex07_solcx import make_mesh
    from skfem_nem.models.analytic import SolCx
    from skfem_nem.models.stokes import assemble_stokes, solve_stokes, stokes_spaces
    from skfem_nem.parallel.petsc import import_petsc, owned_elements
    comm = import_petsc().COMM_WORLD.tompi4py()
    ex = SolCx(1.0, 1e6)
    best = None
    for _ in range(repeat):
        comm.Barrier()
        t0 = time.perf_counter()
        spaces = stokes_spaces(make_mesh(nodes, constrained=True), "nem")
        t1 = time.perf_counter()
        mine = owned_elements(spaces.mesh)
        assemble_stokes(spaces if mine is None else spaces.restricted(mine), ex.viscosity,
                        ex.force)
        t2 = time.perf_counter()
        sol = solve_stokes(spaces, ex.viscosity, ex.force, solver="petsc", tol=1e-10)
        t3 = time.perf_counter()
        # solve_stokes assembles the same share again: the solve is the rest
        times = np.array([t1 - t0, t2 - t1, max(t3 - t2 - (t2 - t1), 0.0)])
        slowest = np.array(comm.allgather(times)).max(axis=0)
        best = slowest if best is None else np.minimum(best, slowest)
    peak = comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    triangles = comm.allgather(sol.info["assembled_triangles"])
    if comm.Get_rank() == 0:
        np.savez(Path(out) / "solution.npz", u=sol.u, p=sol.p)
        summary = {"nodes": int(spaces.mesh.p.shape[1]), "ranks": comm.Get_size(),
                   "spaces": best[0], "assembly": best[1], "solve": best[2],
                   "iterations": sol.iterations, "triangles": triangles,
                   "peak_mb": max(peak), "residual": sol.residual}
        (Path(out) / "summary.json").write_text(json.dumps(summary))


def launch(ranks: int, nodes: int, repeat: int, out: str) -> dict:
    """One ``mpiexec -n ranks`` run of the worker; its summary and solution."""
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    root = ["--allow-run-as-root"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []
    cmd = ["mpiexec", *root, "-n", str(ranks), sys.executable, str(HERE), "--worker",
           "--nodes", str(nodes), "--repeat", str(repeat), "--out", out]
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    summary = json.loads((Path(out) / "summary.json").read_text())
    with np.load(Path(out) / "solution.npz") as z:
        summary["u"], summary["p"] = z["u"], z["p"]
    return summary


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def table(sizes, ranks, repeat) -> None:
    """The markdown table, a row per size and rank count, printed as they come."""
    print(f"SolCx, contrast 1e6, tol 1e-10, seconds of the slowest rank (best of {repeat})\n")
    print("| nodes | ranks | spaces s | assembly s | solve s | FGMRES its | triangles per "
          "rank | peak MB per rank | du, dp vs first |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        first = None
        for r in ranks:
            with tempfile.TemporaryDirectory() as tmp:
                s = launch(r, n, repeat, tmp)
            first = s if first is None else first
            diff = f"{rel(s['u'], first['u']):.1e}, {rel(s['p'], first['p']):.1e}"
            tri = "/".join(str(t) for t in s["triangles"])
            print(f"| {s['nodes']} | {r} | {s['spaces']:.2f} | {s['assembly']:.2f} | "
                  f"{s['solve']:.2f} | {s['iterations']} | {tri} | {s['peak_mb']:.0f} | "
                  f"{diff} |", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 30000, 100000])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--nodes", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(args.nodes, args.repeat, args.out)
    else:
        table(args.sizes, args.ranks, args.repeat)


if __name__ == "__main__":
    main()
