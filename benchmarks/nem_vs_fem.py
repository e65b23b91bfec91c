"""NEM against P1 and P2 on the same Delaunay meshes: convergence, cost, quadrature.

The Poisson problem of ``examples/ex04_nem_vs_fem.py`` (u = sin(pi x) sin(pi y)
on the unit square; its ``uniform`` and ``graded`` node sets) solved with

* ``NEM``: gradient smoothing (the default, consistent integration);
* ``NEM-3``, ``NEM-13``: the paper's 3-point Gauss rule per triangle, 13 points;
* ``P1``, ``P2``: scikit-fem's Lagrange elements on the same triangles;

and the natural-neighbour interpolant of the exact solution. Rates use
h ~ 1/sqrt(nodes); seconds are basis + assembly + direct solve. Prints the
tables of ``docs/verification.md``: convergence (250 -> 16000 nodes), the
cost to reach an error, the quadrature rules on 4000 nodes (``--more``: and
16000) with the Laplace patch test, and (``--more``) thin triangles.

    python benchmarks/nem_vs_fem.py [--quick] [--more]

``--quick``: two coarse levels and the rules on 1000 nodes (a smoke run).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np
from skfem import MeshTri, condense, solve
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTri

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from ex04_nem_vs_fem import (SEED, error_basis, errors, exact, laplace, load,  # noqa: E402
                             node_set, solve_poisson)

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh  # noqa: E402

SIZES = (250, 1000, 4000, 16000)
METHODS = ("NEM", "NEM-3", "NEM-13", "P1", "P2")
KINDS = ("uniform", "graded")


def rates(nodes, err):
    """Observed orders between successive refinements, h ~ 1/sqrt(nodes)."""
    nodes, err = np.asarray(nodes, float), np.asarray(err, float)
    return -2.0 * np.diff(np.log(err)) / np.diff(np.log(nodes))


def fitted_rate(nodes, err):
    """Least-squares order over all refinements, h ~ 1/sqrt(nodes)."""
    return -2.0 * np.polyfit(np.log(nodes), np.log(err), 1)[0]


def convergence(kind, sizes=SIZES, methods=METHODS):
    out = {m: {k: [] for k in ("nodes", "dofs", "l2", "h1", "seconds")} for m in methods}
    out["interpolant"] = {k: [] for k in ("nodes", "dofs", "l2", "h1")}
    for n in sizes:
        p = node_set(kind, n)
        mesh = delaunay_mesh(p)
        nem7 = NaturalNeighbourBasis(mesh, npoints=7)
        for m in methods:
            u, basis, sec, e0, e1 = solve_poisson(
                mesh, m, ebasis=nem7 if m.startswith("NEM") else None)
            for k, v in zip(("nodes", "dofs", "l2", "h1", "seconds"),
                            (len(p), basis.N, e0, e1, sec)):
                out[m][k].append(v)
        e0, e1 = errors(nem7, exact(*p.T))  # the natural-neighbour interpolant
        for k, v in zip(("nodes", "dofs", "l2", "h1"), (len(p), len(p), e0, e1)):
            out["interpolant"][k].append(v)
    for m in out:
        for k in out[m]:
            out[m][k] = np.array(out[m][k])
        out[m]["rate_l2"] = rates(out[m]["nodes"], out[m]["l2"])
        out[m]["rate_h1"] = rates(out[m]["nodes"], out[m]["h1"])
        out[m]["fit_l2"] = fitted_rate(out[m]["nodes"], out[m]["l2"])
        out[m]["fit_h1"] = fitted_rate(out[m]["nodes"], out[m]["h1"])
    return out


def ratio_to_p1(results):
    """NEM error / P1 error at the finest level, per node set, norm and rule."""
    return {kind: {norm: {m: r[m][norm][-1] / r["P1"][norm][-1]
                          for m in ("NEM", "NEM-3", "NEM-13")}
                   for norm in ("l2", "h1")}
            for kind, r in results.items()}


def composite_rule(levels):
    """The 3-point rule on each of the 4**levels congruent sub-triangles of the
    reference triangle: (X, W) with 3 * 4**levels points."""
    ref = MeshTri.init_refdom().refined(levels)
    X0, W0 = get_quadrature(RefTri, 2)
    P = ref.p[:, ref.t]                                   # (2, 3, nsub)
    J = np.stack([P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]], axis=1)  # (2, 2, nsub)
    X = P[:, 0][:, :, None] + np.einsum("ijs,jq->isq", J, X0)
    det = np.abs(J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0])
    return X.reshape(2, -1), (det[:, None] * W0[None, :]).ravel()


def quadrature_study(n=4000, kind="uniform",
                     rules=("smoothed", 1, 3, 4, 6, 7, 12, 13, "48c")):
    """NEM errors of the manufactured solution and the Laplace patch test
    (an exactly linear field imposed on the boundary: largest interior nodal
    error / largest value) per quadrature rule; "smoothed" is the default
    (gradient smoothing), "48c" is :func:`composite_rule` with 16
    sub-triangles."""
    p = node_set(kind, n)
    mesh = delaunay_mesh(p)
    nem7 = NaturalNeighbourBasis(mesh, npoints=7)
    rows = []
    for q in rules:
        t0 = time.perf_counter()
        if q == "smoothed":
            basis = NaturalNeighbourBasis(mesh)
        elif isinstance(q, str):
            basis = NaturalNeighbourBasis(mesh, quadrature=composite_rule(
                int(np.log(int(q[:-1]) / 3) / np.log(4) + 0.5)))
        else:
            basis = NaturalNeighbourBasis(mesh, npoints=q)
        A = laplace.assemble(basis)
        f = load.assemble(basis)
        D = basis.get_dofs()
        u = solve(*condense(A, f, D=D))
        sec = time.perf_counter() - t0
        e0, e1 = errors(nem7, u)
        lin = 1.0 + 2.0 * p[:, 0] + 3.0 * p[:, 1]
        ul = solve(*condense(A, 0 * f, x=lin, D=D))
        rows.append({"points": q, "l2": e0, "h1": e1, "seconds": sec,
                     "patch": np.abs(ul - lin).max() / np.abs(lin).max()})
    return rows


def anisotropic_nodes(nx=101, ny=5, jitter=0.3, jitter_y=None, seed=SEED):
    """A jittered nx x ny grid on the unit square: x-spacing dx = 1/(nx-1),
    y-spacing dy = 1/(ny-1). Interior x are moved by up to jitter * dx, interior
    y by up to jitter * dx too (the rows stay nearly straight), or by up to
    jitter_y * dy if given; boundary nodes stay on their sides. The Delaunay
    triangles are long needles between the rows and flat slivers inside them."""
    rng = np.random.default_rng([seed, nx, ny])
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny))
    x, y = x.ravel(), y.ravel()
    dx, dy = 1.0 / (nx - 1), 1.0 / (ny - 1)
    ix = (x > 0) & (x < 1)
    iy = (y > 0) & (y < 1)
    x = x + ix * jitter * dx * rng.uniform(-1, 1, x.size)
    y = y + iy * (jitter * dx if jitter_y is None else jitter_y * dy) * rng.uniform(-1, 1, y.size)
    return np.c_[x, y]


def triangle_quality(mesh):
    """Per triangle: aspect ratio (longest edge / height onto it) and largest angle (deg)."""
    P = mesh.p[:, mesh.t]  # (2, 3, nt)
    e = np.stack([P[:, 1] - P[:, 0], P[:, 2] - P[:, 1], P[:, 0] - P[:, 2]])  # (3, 2, nt)
    ln = np.linalg.norm(e, axis=1)
    area = 0.5 * np.abs(e[0, 0] * e[2, 1] - e[0, 1] * e[2, 0])
    aspect = ln.max(axis=0) ** 2 / (2 * area)
    cosang = np.stack([-(e[i] * e[i - 1]).sum(0) / (ln[i] * ln[i - 1]) for i in range(3)])
    return aspect, np.degrees(np.arccos(np.clip(cosang, -1, 1))).max(axis=0)


def thin_triangle_study(grids=((101, 5), (201, 9), (401, 17)), jitter=0.3,
                        methods=("NEM", "NEM-3", "NEM-13", "P1", "P2")):
    """NEM vs FEM on strongly anisotropic node sets against random node sets
    with the same number of nodes."""
    rows = []
    for nx, ny in grids:
        for label, p in (("anisotropic", anisotropic_nodes(nx, ny, jitter)),
                         ("random", node_set("uniform", nx * ny))):
            mesh = delaunay_mesh(p)
            aspect, angle = triangle_quality(mesh)
            nem7 = NaturalNeighbourBasis(mesh, npoints=7)
            row = {"grid": f"{nx}x{ny}", "nodes": label, "n": len(p),
                   "aspect": np.median(aspect), "max_aspect": aspect.max(),
                   "max_angle": angle.max()}
            for m in methods:
                _, _, _, e0, e1 = solve_poisson(mesh, m, nem7 if m.startswith("NEM") else None)
                row[m] = (e0, e1)
            row["NEM interpolant"] = errors(nem7, exact(*p.T))
            row["P1 interpolant"] = errors(error_basis(mesh, "P1"), exact(*p.T))
            rows.append(row)
    return rows


# --------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------

def cost_to_reach(results, kind, method, norm, target):
    """(dofs, seconds) at which ``method`` reaches the error ``target``, by
    log-log interpolation between the measured refinements; None if it does
    not within them, (dofs, seconds) of the coarsest if already there."""
    d = results[kind][method]
    e = d[norm]
    if e[0] <= target:
        return d["dofs"][0], d["seconds"][0]
    for i in range(len(e) - 1):
        if e[i] > target >= e[i + 1]:
            t = np.log(target / e[i]) / np.log(e[i + 1] / e[i])
            return tuple(float(np.exp((1 - t) * np.log(d[k][i]) + t * np.log(d[k][i + 1])))
                         for k in ("dofs", "seconds"))
    return None


def markdown_table(results, kind):
    r = results[kind]
    lines = [f"**{kind} nodes**", "",
             "| method | nodes | dofs | L2 error | rate | H1 error | rate | seconds |",
             "|---|---|---|---|---|---|---|---|"]
    for m in METHODS + ("interpolant",):
        d = r[m]
        for i in range(len(d["nodes"])):
            rl = f"{d['rate_l2'][i - 1]:.2f}" if i else ""
            rh = f"{d['rate_h1'][i - 1]:.2f}" if i else ""
            sec = f"{d['seconds'][i]:.3f}" if "seconds" in d else ""
            lines.append(f"| {m} | {d['nodes'][i]} | {d['dofs'][i]} | {d['l2'][i]:.3e} | {rl} | "
                         f"{d['h1'][i]:.3e} | {rh} | {sec} |")
    lines.append("")
    lines.append("fitted rates (L2 / H1): " + ", ".join(
        f"{m} {r[m]['fit_l2']:.2f} / {r[m]['fit_h1']:.2f}" for m in METHODS + ("interpolant",)))
    return "\n".join(lines)


def efficiency_table(results, targets=(("l2", 3e-4), ("h1", 5e-2))):
    lines = ["| nodes | method | " + " | ".join(
        f"dofs for {n.upper()} {t:g} | seconds for {n.upper()} {t:g}" for n, t in targets) + " |",
        "|---|---|" + "---|---|" * len(targets)]
    for kind in results:
        for m in METHODS:
            cells = []
            for norm, t in targets:
                c = cost_to_reach(results, kind, m, norm, t)
                if c is None:
                    cells += ["not reached", ""]
                elif c[0] == results[kind][m]["dofs"][0]:
                    cells += [f"<= {c[0]:.0f}", f"<= {c[1]:.3f}"]
                else:
                    cells += [f"{c[0]:.0f}", f"{c[1]:.3f}"]
            lines.append(f"| {kind} | {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def quadrature_table(n):
    lines = [f"**quadrature rules, NEM, {n} uniform random nodes**", "",
             "| points | L2 error | H1 error | patch test: max nodal error / max abs(u) | "
             "seconds |", "|---|---|---|---|---|"]
    for r in quadrature_study(n):
        lines.append(f"| {r['points']} | {r['l2']:.3e} | {r['h1']:.3e} | {r['patch']:.2e} | "
                     f"{r['seconds']:.2f} |")
    return "\n".join(lines)


def thin_table(grids):
    ms = ("NEM", "NEM-3", "NEM-13", "P1", "P2", "NEM interpolant", "P1 interpolant")
    lines = ["**thin triangles (L2 / H1 errors)**", "",
             "| grid | nodes | n | median aspect | max aspect | max angle | "
             + " | ".join(ms) + " |",
             "|---" * (6 + len(ms)) + "|"]
    for r in thin_triangle_study(grids):
        lines.append(f"| {r['grid']} | {r['nodes']} | {r['n']} | {r['aspect']:.1f} | "
                     f"{r['max_aspect']:.0f} | {r['max_angle']:.1f} | "
                     + " | ".join(f"{r[m][0]:.2e} / {r[m][1]:.2e}" for m in ms) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two coarse levels (a smoke run)")
    ap.add_argument("--more", action="store_true",
                    help="the rules on 16000 nodes and the thin-triangle study")
    a = ap.parse_args(argv)
    sizes = SIZES[:2] if a.quick else SIZES
    results = {kind: convergence(kind, sizes) for kind in KINDS}
    ratios = ratio_to_p1(results)
    for kind in KINDS:
        print(markdown_table(results, kind))
        print()
        print("NEM / P1 error at the finest level:",
              {n: {m: round(float(v), 3) for m, v in d.items()} for n, d in ratios[kind].items()})
        print()
    print("**cost to reach a given error** (log-log interpolation between refinements)\n")
    print(efficiency_table(results))
    print()
    for n in (1000,) if a.quick else (4000, 16000) if a.more else (4000,):
        print(quadrature_table(n))
        print()
    if a.more:
        print(thin_table(((101, 5), (201, 9), (401, 17))))


if __name__ == "__main__":
    main()
