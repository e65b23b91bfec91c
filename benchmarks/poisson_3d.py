"""Poisson's equation in 3D: convergence of NEM, P1 and P2 on Delaunay tetrahedra.

The problem and node sets of ``examples/ex06_poisson_3d.py`` (the unit cube,
u = sin(pi x) sin(pi y) sin(pi z)) on 250, 700 and 2000 interior nodes
(``--more``: and 6000): L2 and H1-seminorm errors, observed rates with
h ~ n^(-1/3) between consecutive sets and fitted over all, seconds (basis,
assembly, solve). The tables of ``docs/ndim.md``.

    python benchmarks/poisson_3d.py [--quick] [--more]

``--quick``: 250 and 700 interior nodes (a smoke run).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex06_poisson_3d import METHODS, cube_nodes, solve_on  # noqa: E402

from skfem_nem import delaunay_mesh  # noqa: E402

SIZES = (250, 700, 2000)          # interior nodes; --more adds 6000


def rates(nodes, err):
    """Observed orders between consecutive sets and fitted over all (h ~ n^(-1/3))."""
    h = np.asarray(nodes, float) ** (-1 / 3)
    e = np.asarray(err)
    step = np.log(e[1:] / e[:-1]) / np.log(h[1:] / h[:-1])
    return step, np.polyfit(np.log(h), np.log(e), 1)[0]


def study(sizes=SIZES):
    out = {m: {"nodes": [], "tets": [], "l2": [], "h1": [], "dofs": [], "seconds": []}
           for m in METHODS}
    last = None
    for n in sizes:
        mesh = delaunay_mesh(cube_nodes(n))
        for m in METHODS:
            basis, u, e = solve_on(mesh, m)
            r = out[m]
            r["nodes"].append(mesh.nvertices)
            r["tets"].append(mesh.nelements)
            for key in ("l2", "h1", "dofs", "seconds"):
                r[key].append(e[key])
            if m == "NEM":
                last = (mesh, basis, u)
    for r in out.values():
        for key in list(r):
            r[key] = np.array(r[key])
        r["rate_l2"], r["fit_l2"] = rates(r["nodes"], r["l2"])
        r["rate_h1"], r["fit_h1"] = rates(r["nodes"], r["h1"])
    return out, last


def table(results):
    lines = ["| nodes | tetrahedra | method | dofs | L2 error | rate | H1 error | rate | s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for k in range(len(results["NEM"]["nodes"])):
        for m in METHODS:
            r = results[m]
            rl = f"{r['rate_l2'][k - 1]:.2f}" if k else "-"
            rh = f"{r['rate_h1'][k - 1]:.2f}" if k else "-"
            lines.append(f"| {r['nodes'][k]:,} | {r['tets'][k]:,} | {m} | {r['dofs'][k]:,} "
                         f"| {r['l2'][k]:.3e} | {rl} | {r['h1'][k]:.3e} | {rh} "
                         f"| {r['seconds'][k]:.2f} |")
    lines.append("")
    lines.append("| method | fitted L2 order | fitted H1 order |")
    lines.append("|---|---|---|")
    for m in METHODS:
        lines.append(f"| {m} | {results[m]['fit_l2']:.2f} | {results[m]['fit_h1']:.2f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="250 and 700 nodes (a smoke run)")
    ap.add_argument("--more", action="store_true", help="add 6000 interior nodes")
    a = ap.parse_args(argv)
    sizes = SIZES[:2] if a.quick else SIZES + ((6000,) if a.more else ())
    print(table(study(sizes)[0]))


if __name__ == "__main__":
    main()
