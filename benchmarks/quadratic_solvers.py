"""Solvers for the quadratic natural-neighbour Laplacian: CG iterations as the mesh grows.

A study for a solver whose iterations do not grow with the quadratic natural-neighbour
matrices (``ElementNaturalNeighbour2``): their rows hold about 110 entries (P2: about 14), and
pyamg's smoothed aggregation on the whole matrix, fine for P2, needs more and more iterations.
A two-level method takes the nodes as its coarse level: nodal values with each edge's value
the average of its nodes' (``skfem_nem.basis.two_level``), which interpolate the values and
reproduce linear fields:

* ``two-level``: ``TwoLevelPreconditioner``, Chebyshev smoothing (degree ``--degree``,
  preconditioned by the node stars, ``natural_neighbour_solver``'s, or by Jacobi) on the
  quadratic matrix, the Galerkin product ``P^T A P`` on the nodes as
  coarse matrix, solved by one V-cycle of pyamg's smoothed aggregation (or exactly,
  ``--exact-coarse``);
* ``SA``: one V-cycle of pyamg's smoothed aggregation on the whole quadratic matrix;
* ``P2 SA``: the same for scikit-fem's P2 on the same triangles, the baseline.

Each preconditions CG on ``-Laplace u = 2 pi^2 sin(pi x) sin(pi y)`` on the unit square with
``u = 0`` on the boundary (random interior nodes, ``box_nodes``) to a relative residual of
1e-8. Printed: unknowns, entries per row, CG iterations and the set-up and solve seconds of
each (warm: a small problem runs first, so numba's kernels are loaded before).

``--linear``: the linear natural-neighbour basis (``ElementNaturalNeighbour``) against P1 on the
same problem, both with one V-cycle of smoothed aggregation.

Run ``python benchmarks/quadratic_solvers.py [--nodes 2000 8000 32000] [--degree 3] [--linear]``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))    # quadratic_cost: the problem

# CG's relative residual
TOL = 1e-8
# pyamg's coarsest level (as the two-level method's)
MAX_COARSE = 500


def problem(n: int, quadratic: bool):
    """The condensed Laplacian and load of the quadratic natural-neighbour basis
    (``quadratic``) or P2 on the Delaunay triangles of n random nodes, with the
    prolongation from the interior nodes (None for P2)."""
    from quadratic_cost import forms
    from skfem import Basis, ElementTriP2

    from skfem_nem import ElementNaturalNeighbour2, NaturalNeighbourBasis, delaunay_mesh
    from skfem_nem.geometry.nodesets import box_nodes

    laplace, load, _ = forms()                 # the problem of quadratic_cost.py
    mesh = delaunay_mesh(box_nodes(n, seed=0))
    basis = (NaturalNeighbourBasis(mesh, ElementNaturalNeighbour2()) if quadratic
             else Basis(mesh, ElementTriP2()))
    A, b = laplace.assemble(basis), load.assemble(basis)
    interior = basis.complement_dofs(basis.get_dofs().all())
    P = stars = None
    if quadratic:
        from skfem_nem.basis.two_level import nested_prolongation, star_dofs
        boundary = np.unique(mesh.facets[:, mesh.boundary_facets()])
        nodes = np.setdiff1d(np.arange(mesh.p.shape[1]), boundary)
        P = nested_prolongation(basis)[interior][:, nodes].tocsr()
        stars = star_dofs(basis, interior)
    return A[interior][:, interior].tocsr(), b[interior], P, stars


def linear_problem(n: int, nem: bool):
    """The condensed Laplacian and load of the linear natural-neighbour basis (``nem``) or
    P1 on the Delaunay triangles of n random nodes."""
    from quadratic_cost import forms
    from skfem import Basis, ElementTriP1

    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh
    from skfem_nem.geometry.nodesets import box_nodes

    laplace, load, _ = forms()
    mesh = delaunay_mesh(box_nodes(n, seed=0))
    basis = (NaturalNeighbourBasis(mesh, ElementNaturalNeighbour()) if nem
             else Basis(mesh, ElementTriP1()))
    A, b = laplace.assemble(basis), load.assemble(basis)
    interior = basis.complement_dofs(basis.get_dofs().all())
    return A[interior][:, interior].tocsr(), b[interior]


def linear_row(n: int) -> list:
    """The linear natural-neighbour matrix and P1's, each with one SA V-cycle."""
    out = []
    for name, nem in (("NEM (linear) SA", True), ("P1 SA", False)):
        A, b = linear_problem(n, nem)
        out.append((name, A, pcg(A, b, sa)))
    return out


def sa(A):
    """One V-cycle of pyamg's smoothed aggregation on A."""
    import pyamg
    ml = pyamg.smoothed_aggregation_solver(A, symmetry="symmetric", max_coarse=MAX_COARSE)
    return lambda r: ml.solve(r, maxiter=1, cycle="V", tol=1e-30)


def pcg(A, b, make) -> dict:
    """CG preconditioned by ``make(A)``: iterations, set-up and solve seconds."""
    t0 = time.perf_counter()
    M = make(A)
    t1 = time.perf_counter()
    its = [0]
    _, info = spla.cg(A, b, M=spla.LinearOperator(A.shape, matvec=M), rtol=TOL, maxiter=5000,
                      callback=lambda *_: its.__setitem__(0, its[0] + 1))
    t2 = time.perf_counter()
    return {"its": its[0] if info == 0 else f">{its[0]}", "setup": t1 - t0, "solve": t2 - t1}


def row(n: int, degree: int, exact: bool, sa_below: int) -> list:
    from skfem_nem.basis.two_level import TwoLevelPreconditioner, star_smoother
    A, b, P, stars = problem(n, True)
    coarse = "direct" if exact else "sa"

    def two_level(M, smoother):
        return TwoLevelPreconditioner(M, P, degree, coarse,
                                      star_smoother(M, *stars) if smoother else None)

    out = [("two-level, stars", A, pcg(A, b, lambda M: two_level(M, True))),
           ("two-level, Jacobi", A, pcg(A, b, lambda M: two_level(M, False)))]
    if A.shape[0] < sa_below:
        out.append(("SA", A, pcg(A, b, sa)))
    A2, b2, _, _ = problem(n, False)
    out.append(("P2 SA", A2, pcg(A2, b2, sa)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[2000, 8000, 32000])
    ap.add_argument("--degree", type=int, default=3)
    ap.add_argument("--exact-coarse", action="store_true")
    ap.add_argument("--sa-below", type=int, default=40000,
                    help="run SA on the whole quadratic matrix below this many unknowns")
    ap.add_argument("--linear", action="store_true",
                    help="the linear natural-neighbour basis against P1 instead (SA on both)")
    a = ap.parse_args(argv)
    rows = (lambda n: linear_row(n)) if a.linear else (
        lambda n: row(n, a.degree, a.exact_coarse, a.sa_below))
    rows(300)    # warm-up: kernels loaded
    coarse = "exact" if a.exact_coarse else "one SA V-cycle"
    print("| nodes | method | unknowns | entries a row | CG iterations | set-up s | solve s |"
          "\n|---|---|---|---|---|---|---|")
    for n in a.nodes:
        for name, M, r in rows(n):
            print(f"| {n:,} | {name} | {M.shape[0]:,} | {M.nnz / M.shape[0]:.0f} | {r['its']} "
                  f"| {r['setup']:.2f} | {r['solve']:.2f} |", flush=True)
    if not a.linear:
        print(f"\nTwo-level: Chebyshev degree {a.degree}, coarse level {coarse}.")


if __name__ == "__main__":
    main()
