"""The Stokes solve on PETSc over MPI: assembly, solve, iterations and memory per rank.

SolCx at a viscosity contrast of 1e6 (``examples/ex07_solcx.py``'s nodes, the interface
as segments, free slip), Donea-Huerta's flow (``--flow donea-huerta``: random nodes in
the unit square, no slip) or, in 3D, the sinker (``--flow sinker``: eight spheres at a
viscosity ratio of 1e4 in the unit cube, random nodes, no slip; tetrahedra),
natural-neighbour velocity with bubbles, tol 1e-10, solved
with ``solve_stokes(..., solver="petsc")`` under ``mpiexec -n R`` for each rank count
``R`` and node count; or (``--flow plate``) the first step of the sinking plate
(``skfem-nem sinking-plate --solver petsc --nodes N`` for each size N, random nodes drawn
before the outline's and thinning: the mesh has about 0.9 N nodes; its
Picard iterations, the fields joined, the node motion and flips on every rank); or
(``--flow plate3d``) the first step of the 3D plate (``skfem-nem sinking-plate --dim 3
--solver petsc --nodes N``'s configuration: its midpoint step, two Picard solves);
``--steps K`` runs the plate's first K steps (the last one timed, the peak over all: from
the second step on, a step runs beside what the last one kept). Each run is a fresh
``mpiexec`` of this script (``--worker``), so its peak memory is its own.
Reported, the slowest rank's seconds (best of ``--repeat``):

- ``spaces``: the bases (natural-neighbour coordinates at the quadrature points). By
  default each rank builds them on its part of the triangles (or tetrahedra) alone
  (``stokes_spaces(mesh, elements="owned")``: divided); ``--spaces whole`` builds them
  for the whole mesh on every rank (replicated, the distributed assembly then takes its
  part of them);
- ``assembly``: this rank's share of the system (its part of the cells) and its
  reduction to the free dofs (``solve_stokes``' ``assembly_seconds``);
- ``solve``: PETSc's part of ``solve_stokes`` (the rows summed into PETSc, FGMRES);
  for the plate, the assemblies and solves of all its Picard iterations;
- FGMRES iterations, the triangles each rank assembled, the peak resident memory of
  the largest rank, its ratio to the first rank count's, and the relative velocity and
  pressure difference to the run on the first rank count.

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
from types import SimpleNamespace

import numpy as np

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parents[1] / "examples"))


def flow(name: str, nodes: int):
    """The mesh, viscosity, force and walls of the flow ``name`` at about ``nodes`` nodes
    (seeded: the same on every rank)."""
    from skfem_nem import delaunay_mesh
    from skfem_nem.geometry import box_nodes_3d
    from skfem_nem.geometry.nodesets import box_nodes
    from skfem_nem.models.analytic import DoneaHuerta, SolCx
    from skfem_nem.models.analytic3d import Sinker
    if name == "sinker":
        ex = Sinker(8, contrast=1e4, seed=0)
        return (delaunay_mesh(box_nodes_3d(nodes, seed=0)), ex.viscosity, ex.force,
                {"free_slip": None, "no_slip": "all"})
    if name == "solcx":
        from ex07_solcx import make_mesh
        ex = SolCx(1.0, 1e6)
        return make_mesh(nodes, constrained=True), ex.viscosity, ex.force, {}
    return (delaunay_mesh(box_nodes(nodes, seed=1)), 1.0, DoneaHuerta.force,
            {"free_slip": None, "no_slip": "all"})


def stokes_solve(name: str, nodes: int, divided: bool, comm):
    """One solve of the flow ``name``: the seconds of spaces, assembly and solve on this
    rank, the solution, and the node count. The system is assembled once, by the solve
    (its ``assembly_seconds``: the assembly and the reduction to the free dofs), so the
    peak memory is a user's."""
    from skfem_nem.models.stokes import solve_stokes, stokes_spaces
    mesh, eta, force, walls = flow(name, nodes)
    comm.Barrier()
    t0 = time.perf_counter()
    spaces = stokes_spaces(mesh, "nem", elements="owned" if divided else None)
    t1 = time.perf_counter()
    sol = solve_stokes(spaces, eta, force, solver="petsc", tol=1e-10, **walls)
    return ([t1 - t0, sol.info["assembly_seconds"], sol.info["solver_seconds"]], sol,
            mesh.p.shape[1])


def plate_step(nodes: int, out: str, comm, steps: int = 1):
    """The first ``steps`` steps of the sinking plate drawing ``nodes`` random nodes (the
    bases built per part, the fields joined, the evolution on every rank): this rank's
    seconds of the last step's bases, assemblies and solves, its last Stokes solution,
    and the node count."""
    from skfem_nem.apps.sinking_plate import PlateConfig, SinkingPlate
    sim = SinkingPlate(PlateConfig(nodes=nodes, solver="petsc"), Path(out) / "plate")
    n = sim.lm.nodes.shape[0]
    comm.Barrier()
    for _ in range(steps):
        row = sim.step(min(sim.dt_next, 1.0))
    if comm.Get_size() > 1:
        sim.check_replicated()
    times = [row["basis_seconds"], row["assembly_seconds"], row["solver_seconds"]]
    last = sim.solution
    sol = SimpleNamespace(u=last.u, p=last.p, iterations=row["solver_iterations"],
                          residual=float("nan"), info={"assembled_triangles": last.cells})
    return times, sol, n


def plate3d_step(nodes: int, out: str, comm, steps: int = 1):
    """The first ``steps`` (midpoint) steps of the 3D plate drawing ``nodes`` nodes (the
    bases built per part of the tetrahedra, the fields joined, the evolution on every
    rank): this rank's seconds of the last step's bases, assemblies and solves, its last
    solve (velocity and pressure at the nodes) and the node count."""
    from skfem_nem.apps.plate3d_config import Plate3DConfig
    from skfem_nem.apps.sinking_plate_3d import SinkingPlate3D
    sim = SinkingPlate3D(Plate3DConfig(nodes=nodes, solver="petsc"), Path(out) / "plate3d")
    n = sim.lm.nodes.shape[0]
    comm.Barrier()
    for _ in range(steps):
        row = sim.step(sim.dt_next)
    if comm.Get_size() > 1:
        sim.check_replicated()
    times = [row["basis_seconds"], row["assembly_seconds"], row["solver_seconds"]]
    last = sim.solution()
    sol = SimpleNamespace(u=last.velocity.ravel(), p=last.pressure,
                          iterations=row["solver_iterations"], residual=float("nan"),
                          info={"assembled_triangles": last.cells})
    return times, sol, n


def worker(name: str, nodes: int, divided: bool, repeat: int, out: str,
           steps: int = 1) -> None:
    """Runs on every rank: times spaces, assembly and solve; rank 0 writes the JSON
    summary and the solution to ``out``."""
    from skfem_nem.parallel.heap import map_large_blocks
    from skfem_nem.parallel.petsc import import_petsc
    comm = import_petsc().COMM_WORLD.tompi4py()
    map_large_blocks()   # (once MPI has started, as the plate over MPI; every rank count)
    best = sol = None
    for _ in range(repeat):
        sol = None  # (the last repetition's let go before the next is built)
        step = {"plate": plate_step, "plate3d": plate3d_step}.get(name)
        times, sol, n = (step(nodes, out, comm, steps) if step is not None
                         else stokes_solve(name, nodes, divided, comm))
        slowest = np.array(comm.allgather(np.array(times))).max(axis=0)
        best = slowest if best is None else np.minimum(best, slowest)
    peak = comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    triangles = comm.allgather(sol.info["assembled_triangles"])
    if comm.Get_rank() == 0:
        np.savez(Path(out) / "solution.npz", u=sol.u, p=sol.p)
        summary = {"nodes": int(n), "ranks": comm.Get_size(),
                   "spaces": best[0], "assembly": best[1], "solve": best[2],
                   "iterations": sol.iterations, "triangles": triangles,
                   "peak_mb": max(peak), "residual": sol.residual}
        (Path(out) / "summary.json").write_text(json.dumps(summary))


def launch(ranks: int, args, nodes: int, out: str) -> dict:
    """One ``mpiexec -n ranks`` run of the worker; its summary and solution."""
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    root = ["--allow-run-as-root"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []
    cmd = ["mpiexec", *root, "-n", str(ranks), sys.executable, str(HERE), "--worker",
           "--flow", args.flow, "--spaces", args.spaces, "--nodes", str(nodes),
           "--repeat", str(args.repeat), "--steps", str(args.steps), "--out", out]
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    summary = json.loads((Path(out) / "summary.json").read_text())
    with np.load(Path(out) / "solution.npz") as z:
        summary["u"], summary["p"] = z["u"], z["p"]
    return summary


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def table(args) -> None:
    """The markdown table, a row per size and rank count, printed as they come."""
    what = {"solcx": "SolCx, contrast 1e6, free slip",
            "donea-huerta": "Donea-Huerta, no slip",
            "sinker": "the 3D sinker, 8 spheres, ratio 1e4, no slip",
            "plate": f"the sinking plate's first {args.steps} step(s) (the last one's "
                     f"seconds and last Picard solve's iterations)",
            "plate3d": f"the 3D plate's first {args.steps} (midpoint) step(s) (the last "
                       f"one's seconds and last Picard solve's iterations)"}[args.flow]
    tol = "the plate's tolerances" if args.flow.startswith("plate") else "tol 1e-10"
    print(f"{what}, spaces {args.spaces}, {tol}, seconds of the slowest rank "
          f"(best of {args.repeat})\n")
    print("| nodes | ranks | spaces s | assembly s | solve s | FGMRES its | cells per "
          "rank | peak MB per rank | memory ratio | du, dp vs first |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        first = None
        for r in args.ranks:
            with tempfile.TemporaryDirectory() as tmp:
                s = launch(r, args, n, tmp)
            first = s if first is None else first
            diff = f"{rel(s['u'], first['u']):.1e}, {rel(s['p'], first['p']):.1e}"
            tri = "/".join(str(t) for t in s["triangles"])
            print(f"| {s['nodes']} | {r} | {s['spaces']:.2f} | {s['assembly']:.2f} | "
                  f"{s['solve']:.2f} | {s['iterations']} | {tri} | {s['peak_mb']:.0f} | "
                  f"{s['peak_mb'] / first['peak_mb']:.2f} | {diff} |", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 30000, 100000])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--flow", choices=["solcx", "donea-huerta", "sinker", "plate", "plate3d"],
                    default="solcx")
    ap.add_argument("--spaces", choices=["divided", "whole"], default="divided",
                    help="bases on each rank's part (default) or whole on every rank")
    ap.add_argument("--steps", type=int, default=1,
                    help="plate flows: steps run; the last one timed, the peak over all")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--nodes", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.flow.startswith("plate") and args.spaces == "whole":
        ap.error("--spaces whole: the sinking plate over MPI always divides its bases")
    if args.steps < 1 or (args.steps != 1 and not args.flow.startswith("plate")):
        ap.error(f"--steps {args.steps}: a positive number of steps, of a plate flow only")
    if args.worker:
        worker(args.flow, args.nodes, args.spaces == "divided", args.repeat, args.out,
               args.steps)
    else:
        table(args)


if __name__ == "__main__":
    main()
