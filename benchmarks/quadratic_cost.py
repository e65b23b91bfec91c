"""Time to a given H1 error: quadratic natural neighbours against P2, Poisson on the unit square.

``-Laplace u = 2 pi^2 sin(pi x) sin(pi y)``, ``u = 0`` on the boundary (exact solution
``sin(pi x) sin(pi y)``), on the Delaunay triangles of random nodes (``box_nodes``). Each method
runs from its basis to its solution, timed whole (basis, assembly, solver set-up and solve), with
its H1 seminorm error:

* ``NEM2``: ``ElementNaturalNeighbour2``, solved by ``natural_neighbour_solver`` (CG with the
  two-level preconditioner, ``skfem_nem.basis.two_level``);
* ``P2``: scikit-fem's ``ElementTriP2`` on the same triangles, CG with one V-cycle of pyamg's
  smoothed aggregation.

CG stops at a relative residual of 1e-10 for both (below the discretisation error at every size
here). Printed: per size and method the unknowns, the error, the seconds by stage, and the time
ratio NEM2 / P2 at equal error, P2's time interpolated in log-log between its sizes. A small run
first loads numba's kernels (not timed). Each case runs ``--repeat`` times (on a new mesh of the
same nodes each time), and the run of the smallest total counts: the machine's noise only
slows a run down.

``--hilbert``: the nodes numbered along a Hilbert curve before the triangulation (as a mesher
numbers them; the same triangles): the natural-neighbour basis and assembly read their
stencils' nodes near each other in memory, where random numbering scatters them (P2's cost
does not depend on it).

Run ``python benchmarks/quadratic_cost.py [--nodes 2000 8000 32000] [--repeat 3]
[--hilbert]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse.linalg as spla

TOL = 1e-10


def forms():
    from skfem import BilinearForm, Functional, LinearForm
    from skfem.helpers import dot, grad

    @BilinearForm
    def laplace(u, v, w):
        return dot(grad(u), grad(v))

    @LinearForm
    def load(v, w):
        return 2 * np.pi ** 2 * np.sin(np.pi * w.x[0]) * np.sin(np.pi * w.x[1]) * v

    @Functional
    def h1_error(w):
        x, y = w.x
        ex = np.pi * np.cos(np.pi * x) * np.sin(np.pi * y)
        ey = np.pi * np.sin(np.pi * x) * np.cos(np.pi * y)
        return (w["u"].grad[0] - ex) ** 2 + (w["u"].grad[1] - ey) ** 2

    return laplace, load, h1_error


def run(n: int, method: str, hilbert: bool = False) -> dict:
    """One solve of the problem on n random nodes (``hilbert``: numbered along a Hilbert
    curve): unknowns, H1 error, seconds by stage."""
    import pyamg
    from skfem import Basis, ElementTriP2, condense

    from skfem_nem import (ElementNaturalNeighbour2, NaturalNeighbourBasis, delaunay_mesh,
                           natural_neighbour_solver)
    from skfem_nem.geometry.nodesets import box_nodes, hilbert_order

    laplace, load, h1_error = forms()
    nodes = box_nodes(n, seed=0)
    mesh = delaunay_mesh(nodes[hilbert_order(nodes)] if hilbert else nodes)
    t0 = time.perf_counter()
    basis = (NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2()) if method == "NEM2"
             else Basis(mesh, ElementTriP2()))
    t1 = time.perf_counter()
    A, b = laplace.assemble(basis), load.assemble(basis)
    D = basis.get_dofs().all()
    AI, bI, x, I = condense(A, b, D=D)
    t2 = time.perf_counter()
    if method == "NEM2":
        solver = natural_neighbour_solver(basis, D, tol=TOL)
        x[I] = solver(AI, bI)
        its = solver.iterations
    else:
        ml = pyamg.smoothed_aggregation_solver(AI, symmetry="symmetric", max_coarse=500)
        count = [0]
        x[I], _ = spla.cg(AI, bI, rtol=TOL, maxiter=5000,
                          M=spla.LinearOperator(AI.shape, matvec=lambda r: ml.solve(
                              r, maxiter=1, cycle="V", tol=1e-30)),
                          callback=lambda *_: count.__setitem__(0, count[0] + 1))
        its = count[0]
    t3 = time.perf_counter()
    err = float(np.sqrt(h1_error.assemble(basis, u=basis.interpolate(x))))
    return {"n": n, "method": method, "dofs": int(I.size), "error": err, "its": its,
            "basis": t1 - t0, "assembly": t2 - t1, "solve": t3 - t2, "total": t3 - t0}


def p2_time_at(error: float, p2: list) -> float:
    """P2's total time at ``error``, log-log interpolated (extrapolated at the ends)."""
    e = np.log([r["error"] for r in p2])
    t = np.log([r["total"] for r in p2])
    k = int(np.clip(np.searchsorted(-e, -np.log(error)), 1, len(p2) - 1))
    s = (np.log(error) - e[k - 1]) / (e[k] - e[k - 1])
    return float(np.exp(t[k - 1] + s * (t[k] - t[k - 1])))


def main(argv=None) -> list:
    """Print the table; returns its rows (dicts of :func:`run`)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[2000, 8000, 32000])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each case; the fastest "
                    "counts (default 3)")
    ap.add_argument("--hilbert", action="store_true", help="number the nodes along a "
                    "Hilbert curve first")
    a = ap.parse_args(argv)
    if len(a.nodes) < 2:
        ap.error("--nodes needs two sizes or more (P2's time is interpolated between them)")
    if a.repeat < 1:
        ap.error(f"--repeat must be at least 1, got {a.repeat}")
    for m in ("NEM2", "P2"):
        run(200, m)                                   # warm-up: kernels loaded
    rows = [min((run(n, m, a.hilbert) for _ in range(a.repeat)), key=lambda r: r["total"])
            for n in a.nodes for m in ("NEM2", "P2")]
    p2 = [r for r in rows if r["method"] == "P2"]
    print("| nodes | method | unknowns | H1 error | CG its | basis s | assembly s | solve s "
          "| total s | NEM2 / P2 at equal error |\n|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = (f"{r['total'] / p2_time_at(r['error'], p2):.2f}" if r["method"] == "NEM2"
                 else "")
        print(f"| {r['n']:,} | {r['method']} | {r['dofs']:,} | {r['error']:.3e} | {r['its']} "
              f"| {r['basis']:.2f} | {r['assembly']:.2f} | {r['solve']:.2f} | {r['total']:.2f} "
              f"| {ratio} |")
    return rows


if __name__ == "__main__":
    main()
