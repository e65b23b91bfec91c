"""NEM against P1 and P2 on the same Delaunay mesh: convergence, cost, quadrature.

The Poisson problem -Δu = f on the unit square with the manufactured solution
u = sin(pi x) sin(pi y) and u = 0 on the whole boundary is solved on two
families of irregular node sets (Braun & Sambridge 1995 advertise NEM for
exactly such node sets):

* ``uniform``: uniformly random interior nodes, evenly spaced boundary nodes;
* ``graded``: random nodes with a density inversely proportional to the
  distance from the line y = 1/2 plus a minimum density (the grading of the
  paper's Fig. 6), boundary nodes spaced to match.

For each node set the Delaunay mesh is built once (:func:`skfem_nem.delaunay_mesh`)
and the problem is solved on it with

* ``NEM``: Sibson natural-neighbour trial functions with gradients smoothed
  over three cells per Delaunay triangle (the default of
  ``NaturalNeighbourBasis``: consistent integration, :mod:`skfem_nem.basis.smoothing`);
* ``NEM-3``: the same trial functions with the paper's 3-point Gauss rule per
  triangle (``npoints=3``);
* ``NEM-13``: with the 13-point rule;
* ``P1`` and ``P2``: scikit-fem's Lagrange elements on the same triangles.

Errors are integrated with rules finer than the assembly rule (7 points for
NEM, ``intorder=6`` for P1/P2): the L2 error and the H1-seminorm (energy)
error. Rates use h ~ 1/sqrt(number of nodes). The time of a solve is basis +
assembly + direct solve (the mesh is shared and not counted).

What it shows: NEM's interpolant converges at the optimal rates (L2 2,
energy 1); with Gauss quadrature the Galerkin solution inherits its error on
Delaunay triangles -- natural-neighbour functions are not polynomials on the
triangles, their derivatives are only piecewise smooth inside them -- so with
the paper's 3-point rule the error stops decreasing after a few thousand
nodes, and the 13-point rule only delays the floor. Gradient smoothing (the
default) passes the patch test to round-off and converges at the optimal
rates with errors below P1's on the same nodes.

``python examples/ex04_nem_vs_fem.py`` prints the convergence tables, the cost
of reaching a given error (:func:`efficiency_table`) and the quadrature-rule
table on 4000 nodes (:func:`quadrature_study`), and writes
``out/ex04_nem_vs_fem.png``; ``--more`` adds the quadrature table on 16000
nodes and the thin-triangle study (:func:`thin_triangle_study`). These are
the tables of ``docs/verification.md``.
"""
import sys
import time
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementTriP1, ElementTriP2, Functional, LinearForm
from skfem import MeshTri, condense, solve
from skfem.helpers import dot, grad
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTri

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh

SIZES = (250, 1000, 4000, 16000)
METHODS = ("NEM", "NEM-3", "NEM-13", "P1", "P2")
SEED = 0


# --------------------------------------------------------------------------
# node sets
# --------------------------------------------------------------------------

def _quantiles(density, a, b, m):
    """The m - 1 points inside [a, b] that cut it into m pieces of equal mass
    of density(s): their spacing is inversely proportional to the density."""
    s = np.linspace(a, b, 2001)
    c = np.r_[0.0, np.cumsum(0.5 * (density(s[1:]) + density(s[:-1])) * np.diff(s))]
    return np.interp(np.arange(1, m) / m * c[-1], c, s)


def rectangle_nodes(n, rng, width=1.0, height=1.0, density=None, axis=1):
    """n nodes in [0, width] x [0, height]: the four corners, nodes on the four
    sides, random interior nodes.

    ``density`` is a relative node density (per unit area) as a function of
    the coordinate ``axis`` (0: x, 1: y), or None for a uniform density. The
    interior nodes are drawn from it exactly (inverse transform sampling of
    that coordinate, the other one uniform); the boundary nodes are spaced
    like the local mean distance between nodes, 1 / sqrt(nodes per unit area).
    """
    lengths = (width, height)
    if density is None:
        density = lambda s: np.ones_like(s)  # noqa: E731
    ell, across = lengths[axis], lengths[1 - axis]
    s = np.linspace(0.0, ell, 2001)
    total = np.trapezoid(density(s), s) * across
    per_area = n * density(s) / total
    # the two sides along the graded axis: line density sqrt(nodes per unit area)
    m = max(int(round(np.trapezoid(np.sqrt(per_area), s))), 1)
    along = _quantiles(lambda t: np.sqrt(n * density(t) / total), 0.0, ell, m)
    # the two sides across it: even spacing at their local density
    m0, m1 = (max(int(round(across * np.sqrt(d))), 1) for d in (per_area[0], per_area[-1]))
    across0 = np.linspace(0.0, across, m0 + 1)
    across1 = np.linspace(0.0, across, m1 + 1)[1:-1]
    boundary = np.r_[np.c_[across0, 0 * across0], np.c_[across1, ell + 0 * across1],
                     np.c_[0 * along, along], np.c_[across + 0 * along, along],
                     [[0.0, ell], [across, ell]]]
    k = n - len(boundary)
    c = np.r_[0.0, np.cumsum(0.5 * (density(s[1:]) + density(s[:-1])) * np.diff(s))]
    t = rng.random(k)
    inner = np.c_[rng.random(k) * across, np.interp(t * c[-1], c, s)]
    p = np.r_[boundary, inner]
    return np.ascontiguousarray(p[:, ::-1] if axis == 0 else p)


def graded_density(y, delta=0.01, minimum=2.0):
    """Inversely proportional to the distance from y = 1/2, plus a minimum."""
    return 1.0 / (np.abs(y - 0.5) + delta) + minimum


def node_set(kind, n, seed=SEED):
    rng = np.random.default_rng([seed, n, 0 if kind == "uniform" else 1])
    if kind == "uniform":
        return rectangle_nodes(n, rng)
    return rectangle_nodes(n, rng, density=graded_density)


# --------------------------------------------------------------------------
# the problem
# --------------------------------------------------------------------------

def exact(x, y):
    return np.sin(np.pi * x) * np.sin(np.pi * y)


def exact_grad(x, y):
    return np.array([np.pi * np.cos(np.pi * x) * np.sin(np.pi * y),
                     np.pi * np.sin(np.pi * x) * np.cos(np.pi * y)])


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return 2.0 * np.pi ** 2 * exact(*w.x) * v


@Functional
def l2_error(w):
    return (w["uh"] - exact(*w.x)) ** 2


@Functional
def h1_error(w):
    g = w["uh"].grad - exact_grad(*w.x)
    return g[0] ** 2 + g[1] ** 2


def make_basis(mesh, method):
    if method == "NEM":
        return NaturalNeighbourBasis(mesh)
    if method.startswith("NEM"):
        return NaturalNeighbourBasis(mesh, npoints=int(method.split("-")[1]))
    return Basis(mesh, ElementTriP1() if method == "P1" else ElementTriP2())


def error_basis(mesh, method):
    """A finer quadrature than any assembly rule here, for the error integrals."""
    if method.startswith("NEM"):
        return NaturalNeighbourBasis(mesh, npoints=7)
    return Basis(mesh, ElementTriP1() if method == "P1" else ElementTriP2(), intorder=6)


def errors(ebasis, u):
    uh = ebasis.interpolate(u)
    return (np.sqrt(l2_error.assemble(ebasis, uh=uh)),
            np.sqrt(h1_error.assemble(ebasis, uh=uh)))


def solve_poisson(mesh, method, ebasis=None):
    """Solve on ``mesh``; returns (dof vector, basis, seconds, L2 error, H1 error)."""
    t0 = time.perf_counter()
    basis = make_basis(mesh, method)
    A = laplace.assemble(basis)
    f = load.assemble(basis)
    u = solve(*condense(A, f, D=basis.get_dofs()))
    seconds = time.perf_counter() - t0
    ebasis = error_basis(mesh, method) if ebasis is None else ebasis
    return u, basis, seconds, *errors(ebasis, u)


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


# --------------------------------------------------------------------------
# module-level computation (checked by tests/test_examples_nem.py)
# --------------------------------------------------------------------------

results = {kind: convergence(kind) for kind in ("uniform", "graded")}

#: NEM error / P1 error at the finest level, per node set and norm
ratio_to_p1 = {kind: {norm: {m: results[kind][m][norm][-1] / results[kind]["P1"][norm][-1]
                             for m in ("NEM", "NEM-3", "NEM-13")}
                      for norm in ("l2", "h1")}
               for kind in results}


# --------------------------------------------------------------------------
# further studies (run by ``python ex04_nem_vs_fem.py``, not at import)
# --------------------------------------------------------------------------

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
# output
# --------------------------------------------------------------------------

def cost_to_reach(kind, method, norm, target):
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


def markdown_table(kind):
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


def efficiency_table(targets=(("l2", 3e-4), ("h1", 5e-2))):
    lines = ["| nodes | method | " + " | ".join(
        f"dofs for {n.upper()} {t:g} | seconds for {n.upper()} {t:g}" for n, t in targets) + " |",
        "|---|---|" + "---|---|" * len(targets)]
    for kind in results:
        for m in METHODS:
            cells = []
            for norm, t in targets:
                c = cost_to_reach(kind, m, norm, t)
                if c is None:
                    cells += ["not reached", ""]
                elif c[0] == results[kind][m]["dofs"][0]:
                    cells += [f"<= {c[0]:.0f}", f"<= {c[1]:.3f}"]
                else:
                    cells += [f"{c[0]:.0f}", f"{c[1]:.3f}"]
            lines.append(f"| {kind} | {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def visualize(path="out/ex04_nem_vs_fem.png"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 3, figsize=(15, 9.5), constrained_layout=True)
    style = {"NEM": ("C1", "D-"), "NEM-3": ("C3", "o--"), "NEM-13": ("C3", "o-"), "P1": ("C0", "s-"),
             "P2": ("C2", "^-"), "interpolant": ("0.5", "x:")}
    for row, kind in enumerate(results):
        r = results[kind]
        for col, (norm, title) in enumerate((("l2", "L2 error"), ("h1", "H1-seminorm error"))):
            a = ax[row, col]
            for m in METHODS + ("interpolant",):
                c, s = style[m]
                a.loglog(r[m]["dofs"], r[m][norm], s, color=c,
                         label=f"{m} (rate {r[m]['fit_' + norm]:.2f})")
            a.set_xlabel("number of dofs")
            a.set_title(f"{kind} nodes: {title}")
            a.grid(True, which="both", lw=0.3)
            a.legend(fontsize=8)
    for row, kind in enumerate(results):
        p = node_set(kind, SIZES[1])
        mesh = delaunay_mesh(p)
        a = ax[row, 2]
        a.triplot(p[:, 0], p[:, 1], mesh.t.T, lw=0.3, color="k")
        a.set_aspect("equal")
        a.set_title(f"{kind} nodes, {len(p)} nodes (Delaunay mesh)")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


if __name__ == "__main__":
    for kind in results:
        print(markdown_table(kind))
        print()
        print("NEM / P1 error at the finest level:",
              {n: {m: round(float(v), 3) for m, v in d.items()}
               for n, d in ratio_to_p1[kind].items()})
        print()
    print("**cost to reach a given error** (log-log interpolation between refinements)\n")
    print(efficiency_table())
    print()
    more = "--more" in sys.argv
    for n in (4000, 16000) if more else (4000,):
        print(f"**quadrature rules, NEM, {n} uniform random nodes**\n")
        print("| points | L2 error | H1 error | patch test: max nodal error / max abs(u) | "
              "seconds |")
        print("|---|---|---|---|---|")
        for r in quadrature_study(n):
            print(f"| {r['points']} | {r['l2']:.3e} | {r['h1']:.3e} | {r['patch']:.2e} | "
                  f"{r['seconds']:.2f} |")
        print()
    if more:  # about a minute more
        print("**thin triangles (L2 / H1 errors)**\n")
        rows = thin_triangle_study()
        ms = ("NEM", "NEM-3", "NEM-13", "P1", "P2", "NEM interpolant", "P1 interpolant")
        print("| grid | nodes | n | median aspect | max aspect | max angle | "
              + " | ".join(ms) + " |")
        print("|---" * (6 + len(ms)) + "|")
        for r in rows:
            print(f"| {r['grid']} | {r['nodes']} | {r['n']} | {r['aspect']:.1f} | "
                  f"{r['max_aspect']:.0f} | {r['max_angle']:.1f} | "
                  + " | ".join(f"{r[m][0]:.2e} / {r[m][1]:.2e}" for m in ms) + " |")
    print("\nfigure written to", visualize())
