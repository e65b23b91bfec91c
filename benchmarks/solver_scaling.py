"""``natural_neighbour_solver`` as the unknowns grow: Poisson and elasticity, linear and quadratic.

For each case and each size: the unknowns, the matrix's entries a row, the multigrid's levels,
flexible CG's iterations to a relative residual of 1e-8 (and their ratio to the smallest
size's), the set-up and solve seconds; beside them, CG with one V-cycle of pyamg's smoothed
aggregation on the same matrix (pyamg's defaults, the rigid-body modes for elasticity) where
``--baseline`` asks for it. Warm: a small problem of each case runs first, so numba's kernels
are loaded before (their one-time load is not in the table).

The problems, on the Delaunay triangles of random nodes in the unit square (``box_nodes``;
``--nodes jittered``: a square grid with each inner node moved by up to 0.3 spacings in x
and y, nodes of one spacing everywhere, where random nodes come closer and closer together
as they grow in number):

* ``poisson``: ``-Laplace u = 2 pi^2 sin(pi x) sin(pi y)``, ``u = 0`` on the boundary;
* ``elasticity``: linear elasticity (E = 1, nu = 0.3) clamped at x = 0 under its own weight.

``--dofs`` sets the unknowns aimed at: the nodes are chosen for each basis (the quadratic one has
about four dofs a node, a vector basis a component a dimension). ``--dim 3``: the same in the
unit cube on Delaunay tetrahedra (``box_nodes_3d``; the linear basis only, the weight along -z).

Run ``python benchmarks/solver_scaling.py [--dofs 1e4 1e5 1e6] [--cases linear-poisson
linear-elasticity quadratic-poisson quadratic-elasticity] [--dim 3] [--baseline]
[--nodes random|jittered]``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))    # quadratic_cost: the Poisson forms

CASES = ("linear-poisson", "linear-elasticity", "quadratic-poisson", "quadratic-elasticity")
# flexible CG's and the baseline CG's relative residual
TOL = 1e-8
NODE_SETS = ("random", "jittered")
# the largest move of a jittered grid's inner node, in grid spacings along x and along y
JITTER = 0.3


def jittered_nodes(m: int, seed: int = 0) -> np.ndarray:
    """About ``m`` nodes of the unit square: a square grid, each inner node moved by up to
    :data:`JITTER` spacings along x and along y (uniformly at random)."""
    k = max(2, int(round(np.sqrt(m))) - 1)
    g = np.linspace(0.0, 1.0, k + 1)
    p = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    inner = ((p > 0) & (p < 1)).all(axis=1)
    p[inner] += np.random.default_rng(seed).uniform(-JITTER, JITTER, (inner.sum(), 2)) / k
    return p


def _forms(elasticity: bool, dim: int):
    """The bilinear and linear form of the case (Poisson: quadratic_cost.py's)."""
    from skfem import LinearForm
    from skfem.models.elasticity import linear_elasticity

    if elasticity:
        @LinearForm
        def weight(v, w):
            return -v[dim - 1]
        return linear_elasticity(1.0, 0.3), weight
    from quadratic_cost import forms
    return forms()[:2]


def problem(case: str, dofs: float, dim: int = 2, nodes: str = "random"):
    """The basis, condensed matrix and load, and the Dirichlet dofs of ``case`` at about
    ``dofs`` unknowns in ``dim`` dimensions, on ``nodes`` (:data:`NODE_SETS`; jittered in
    2D only)."""
    from skfem import ElementVector, condense

    from skfem_nem import (ElementNaturalNeighbour, ElementNaturalNeighbour2,
                           NaturalNeighbourBasis, delaunay_mesh)
    from skfem_nem.geometry import box_nodes_3d
    from skfem_nem.geometry.nodesets import box_nodes

    quadratic, elasticity = case.startswith("quadratic"), case.endswith("elasticity")
    per_node = (4 if quadratic else 1) * (dim if elasticity else 1)
    elem = ElementNaturalNeighbour2() if quadratic else ElementNaturalNeighbour()
    elem = ElementVector(elem) if elasticity else elem
    if nodes == "jittered":
        points = jittered_nodes(int(dofs / per_node))
    else:
        points = (box_nodes if dim == 2 else box_nodes_3d)(int(dofs / per_node), seed=0)
    basis = NaturalNeighbourBasis(delaunay_mesh(points), elem)
    a, f = _forms(elasticity, dim)
    D = (basis.get_dofs(lambda x: x[0] < 1e-12).all() if elasticity
         else basis.get_dofs().all())
    A, b = condense(a.assemble(basis), f.assemble(basis), D=D)[:2]
    return basis, A.tocsr(), b, D


def ours(basis, A, b, D) -> dict:
    """natural_neighbour_solver: levels, iterations, set-up and solve seconds together."""
    from skfem_nem import natural_neighbour_solver
    s = natural_neighbour_solver(basis, D, tol=TOL)
    t0 = time.perf_counter()
    s(A, b)
    t1 = time.perf_counter()
    return {"levels": s.levels, "its": s.iterations, "seconds": t1 - t0}


def baseline(basis, A, b, D) -> dict:
    """CG with one V-cycle of pyamg's smoothed aggregation (pyamg's defaults)."""
    from skfem import ElementVector

    from skfem_nem.basis.multigrid import smoothed_aggregation, v_cycle
    from skfem_nem.basis.rigid_modes import rigid_modes
    free = np.setdiff1d(np.arange(basis.N), D)
    modes = rigid_modes(basis, free) if isinstance(basis.elem, ElementVector) else None
    t0 = time.perf_counter()
    ml = smoothed_aggregation(A, modes)
    count = [0]
    _, info = spla.cg(A, b, rtol=TOL, maxiter=5000,
                      M=spla.LinearOperator(A.shape, matvec=lambda r: v_cycle(ml, r),
                                            dtype=float),
                      callback=lambda *_: count.__setitem__(0, count[0] + 1))
    t1 = time.perf_counter()
    return {"levels": len(ml.levels), "its": count[0] if info == 0 else f">{count[0]}",
            "seconds": t1 - t0}


def table(case: str, rows: list, with_baseline: bool) -> str:
    """A markdown table of ``rows`` (dicts of :func:`measure`)."""
    head = ["unknowns", "entries a row", "levels", "flexible CG its", "its / smallest",
            "seconds (set-up + solve)"]
    if with_baseline:
        head += ["SA V-cycle + CG: its", "seconds"]
    lines = [f"{case}:", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    first = rows[0]["ours"]["its"]
    for r in rows:
        o = r["ours"]
        cells = [f"{r['unknowns']:,}", f"{r['per_row']:.0f}", str(o["levels"]), str(o["its"]),
                 f"{o['its'] / first:.2f}", f"{o['seconds']:.2f}"]
        if with_baseline:
            cells += [str(r["base"]["its"]), f"{r['base']['seconds']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def measure(case: str, dofs: float, with_baseline: bool, dim: int = 2,
            nodes: str = "random") -> dict:
    basis, A, b, D = problem(case, dofs, dim, nodes)
    row = {"unknowns": A.shape[0], "per_row": A.nnz / A.shape[0], "ours": ours(basis, A, b, D)}
    if with_baseline:
        row["base"] = baseline(basis, A, b, D)
    return row


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dofs", type=float, nargs="+", default=[1e4, 1e5])
    ap.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    ap.add_argument("--dim", type=int, choices=(2, 3), default=2)
    ap.add_argument("--baseline", action="store_true")
    ap.add_argument("--nodes", choices=NODE_SETS, default="random")
    a = ap.parse_args(argv)
    if any(d < 1000 for d in a.dofs):
        ap.error("--dofs: at least 1000 unknowns")
    if a.dim == 3 and a.nodes == "jittered":
        ap.error("--nodes jittered: a grid of the unit square (give --dim 2)")
    if a.dim == 3 and any(c.startswith("quadratic") for c in a.cases):
        ap.error("--dim 3: the quadratic basis is on triangles only (give --cases "
                 "linear-poisson linear-elasticity)")
    out = {}
    for case in a.cases:
        measure(case, 2000, False, a.dim)          # warm: numba's kernels loaded
        rows = [measure(case, d, a.baseline, a.dim, a.nodes) for d in a.dofs]
        out[case] = rows
        print(table(f"{case}, {a.dim}D, {a.nodes} nodes", rows, a.baseline), end="\n\n",
              flush=True)
    return out


if __name__ == "__main__":
    main()
