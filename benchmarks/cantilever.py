"""Timoshenko's cantilever: convergence of NEM, its Gauss rules, P1 and P2; the patch test.

The beam of ``examples/ex03_cantilever.py`` on random and graded nodes
(density 1 / (x + D/4) + 1 / L, denser at the clamp), 200 -> 3200 nodes, with

* ``NEM``: the default vector basis (smoothed gradients);
* ``NEM-3``, ``NEM-13``: Gauss rules with 3 (the paper's) and 13 points;
* ``P1``, ``P2``: vector Lagrange elements on the same Delaunay mesh;

tip deflection, relative L2 and energy errors, rates (h ~ 1/sqrt(nodes)) and
seconds (basis, assembly, solve). Before that, a check of the exact solution
by finite differences of the displacement only (equilibrium, traction-free
long sides, the resultant P, the closed-form stress), and after it the patch
test: a linear displacement imposed at all boundary nodes of 800 random
nodes, the largest interior nodal error per integration rule (smoothed, or
1, 3, 4, 6, 7, 12, 13 Gauss points). The tables of ``docs/verification.md``
(section 4).

    python benchmarks/cantilever.py [--quick]

``--quick``: 200 and 800 nodes, the patch test on 200 (a smoke run).
"""
import argparse
import sys
from pathlib import Path

import numpy as np
from skfem import ElementVector, condense, solve
from skfem.models.elasticity import linear_elasticity

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex03_cantilever import (D, I, LAM, MU, P, TIP, L, beam_errors, beam_nodes,  # noqa: E402
                             error_basis, exact_u, interpolant, solve_beam,
                             stress_of_strain, tip_deflection)

from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis, delaunay_mesh  # noqa: E402

SIZES = (200, 800, 3200)
METHODS = ("NEM", "NEM-3", "NEM-13", "P1", "P2")
PATCH_RULES = ("smoothed", 1, 3, 4, 6, 7, 12, 13)
KINDS = ("random", "graded")


def exact_stress(x, y):
    sxx = -P * (L - x) * y / I
    sxy = P / (2 * I) * (D ** 2 / 4 - y ** 2)
    return np.array([[sxx, sxy], [sxy, 0 * sxx]])


def equilibrium_residual(h=1e-3):
    """Checks of exact_u by central finite differences only (no closed-form
    stresses): max |div sigma| inside relative to max |sigma| / L, max
    traction on the long sides relative to max |sigma|, the resultant of the
    end traction relative to P, and max |sigma(u) - exact_stress|."""
    rng = np.random.default_rng(1)
    x = rng.uniform(0.1 * L, 0.9 * L, 200)
    y = rng.uniform(-0.4 * D, 0.4 * D, 200)

    def strain(x, y):
        dx = (exact_u(x + h, y) - exact_u(x - h, y)) / (2 * h)
        dy = (exact_u(x, y + h) - exact_u(x, y - h)) / (2 * h)
        g = np.array([[dx[0], dy[0]], [dx[1], dy[1]]])
        return 0.5 * (g + g.transpose(1, 0, *range(2, g.ndim)))

    def stress(x, y):
        return stress_of_strain(strain(x, y))

    smax = P * L * D / 2 / I
    div = np.array([(stress(x + h, y)[i, 0] - stress(x - h, y)[i, 0]) / (2 * h)
                    + (stress(x, y + h)[i, 1] - stress(x, y - h)[i, 1]) / (2 * h)
                    for i in range(2)])
    xs = np.linspace(0.05 * L, 0.95 * L, 50)
    side = max(np.abs(stress(xs, s * D / 2 + 0 * xs)[:, 1]).max() for s in (-1, 1))
    ys = np.linspace(-D / 2, D / 2, 2001)
    t = stress(L + 0 * ys, ys)[:, 0]  # traction on x = L, normal (1, 0)
    resultant = np.trapezoid(t, ys)
    mismatch = np.abs(stress(x, y) - exact_stress(x, y)).max()
    return {"div": np.abs(div).max() / (smax / L), "sides": side / smax,
            "resultant": np.abs(resultant - [0, P]).max() / P, "stress": mismatch / smax}


def cantilever(kind, sizes=SIZES, methods=METHODS):
    out = {m: {k: [] for k in ("nodes", "dofs", "tip", "l2", "energy", "seconds")}
           for m in methods}
    for n in sizes:
        p = beam_nodes(n, kind)
        mesh = delaunay_mesh(p)
        nem7 = None
        for m in methods:
            u, basis, sec = solve_beam(mesh, m)
            if m.startswith("NEM") and nem7 is None:
                nem7 = error_basis(mesh, m)
            l2, en = beam_errors(mesh, m, u, nem7 if m.startswith("NEM") else None)
            for k, v in zip(("nodes", "dofs", "tip", "l2", "energy", "seconds"),
                            (len(p), basis.N, tip_deflection(basis, u), l2, en, sec)):
                out[m][k].append(v)
    for m in out:
        for k in out[m]:
            out[m][k] = np.array(out[m][k])
        out[m]["tip_error"] = out[m]["tip"] / TIP - 1.0
        nodes = out[m]["nodes"].astype(float)
        for norm in ("l2", "energy"):
            out[m]["rate_" + norm] = -2 * np.diff(np.log(out[m][norm])) / np.diff(np.log(nodes))
    return out


def patch_test(n=800, kind="random", rules=PATCH_RULES):
    """Largest interior nodal error / largest displacement, per quadrature rule,
    for a linear displacement imposed at all boundary nodes (no loads)."""
    p = beam_nodes(n, kind)
    mesh = delaunay_mesh(p)

    def linear(x, y):
        return 1e-3 * np.array([1.0 + x / L + 2.0 * y / D, 2.0 - 0.5 * x / L + y / D])

    out = {}
    for q in rules:
        rule = {} if q == "smoothed" else {"npoints": q}
        basis = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()), **rule)
        K = linear_elasticity(LAM, MU).assemble(basis)
        D_ = basis.get_dofs()
        exact = interpolant(basis, linear)
        u = solve(*condense(K, 0 * exact, x=exact, D=D_))
        interior = basis.complement_dofs(D_)
        out[q] = np.abs(u - exact)[interior].max() / np.abs(exact).max()
    return out


def convergence_table(kind, r):
    lines = [f"**{kind} nodes**", "",
             "| method | nodes | dofs | tip deflection | tip error | L2 error | rate | "
             "energy error | rate | seconds |", "|---|---|---|---|---|---|---|---|---|---|"]
    for m, d in r.items():
        for i in range(len(d["nodes"])):
            rl = f"{d['rate_l2'][i - 1]:.2f}" if i else ""
            re = f"{d['rate_energy'][i - 1]:.2f}" if i else ""
            lines.append(f"| {m} | {d['nodes'][i]} | {d['dofs'][i]} | {d['tip'][i]:.6e} | "
                         f"{100 * d['tip_error'][i]:+.2f}% | {d['l2'][i]:.3e} | {rl} | "
                         f"{d['energy'][i]:.3e} | {re} | {d['seconds'][i]:.3f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="200 and 800 nodes (a smoke run)")
    a = ap.parse_args(argv)
    print("exact solution checks:", {k: f"{v:.1e}" for k, v in equilibrium_residual().items()})
    print(f"exact tip deflection {TIP:.6e}\n")
    for kind in KINDS:
        print(convergence_table(kind, cantilever(kind, SIZES[:2] if a.quick else SIZES)))
        print()
    n = 200 if a.quick else 800
    print(f"**patch test, {n} random nodes**\n")
    print("| points | max interior nodal error / max abs(u) |\n|---|---|")
    for q, v in patch_test(n).items():
        print(f"| {q} | {v:.2e} |")


if __name__ == "__main__":
    main()
