"""Timoshenko's cantilever beam with natural-neighbour trial functions.

A beam of length L and depth D (plane stress, Young's modulus E, Poisson's
ratio nu) occupies 0 <= x <= L, -D/2 <= y <= D/2. It carries a parabolic shear
traction of resultant P on its end x = L and is held at x = 0. The exact
solution (Timoshenko & Goodier, Theory of Elasticity, 3rd ed., 1970; the
standard meshfree benchmark, used for NEM by Sukumar, Moran & Belytschko 1998)
with I = D^3 / 12 is

    u_x = -P y / (6 E I) [(6 L - 3 x) x + (2 + nu) (y^2 - D^2 / 4)]
    u_y =  P / (6 E I) [3 nu y^2 (L - x) + (4 + 5 nu) D^2 x / 4 + (3 L - x) x^2]
    s_xx = -P (L - x) y / I,   s_yy = 0,   s_xy = P / (2 I) (D^2 / 4 - y^2)

so the tip deflection is u_y(L, 0) = P L^3 / (3 E I) + (4 + 5 nu) P L D^2 / (24 E I)
(upwards, as the load). The exact displacements are imposed at all nodes of
the end x = 0 (the "clamp" is the exact solution there), the exact traction
(0, s_xy) on the end x = L through ``NaturalNeighbourFacetBasis``; the long
sides are traction-free. :func:`equilibrium_residual` checks by finite
differences that this field is in equilibrium, traction-free on the long
sides and carries the load P.

The vector NEM basis ``ElementVector(ElementNaturalNeighbour())`` is assembled
with scikit-fem's ``linear_elasticity`` and compared with vector P1 and P2 on
the same Delaunay mesh, on random and on graded nodes (density inversely
proportional to the distance from the clamped end, plus a minimum): tip
deflection, relative L2 displacement error and relative energy error.

The patch test of the paper's integration question: a linear displacement
field imposed at all boundary nodes must be reproduced at the interior nodes.
With Gauss quadrature on the Delaunay triangles it is reproduced only up to
the quadrature error (natural-neighbour functions are not polynomials
there); with the default gradient smoothing to round-off. :data:`patch` holds
the largest interior nodal error for smoothing and the 1, 3, 4, 6, 7, 12 and
13-point rules. ``NEM`` is the default basis (smoothed), ``NEM-3`` and
``NEM-13`` the Gauss rules.
"""
import time
from pathlib import Path

import numpy as np
from skfem import (Basis, ElementTriP1, ElementTriP2, ElementVector, FacetBasis,
                   Functional, LinearForm, condense, solve)
from skfem.helpers import sym_grad
from skfem.models.elasticity import linear_elasticity

from skfem_nem import (ElementNaturalNeighbour, NaturalNeighbourBasis,
                       NaturalNeighbourFacetBasis, delaunay_mesh)

L, D = 48.0, 12.0
E, NU, P = 3.0e7, 0.3, 1000.0
I = D ** 3 / 12.0
# plane stress Lame parameters
LAM = E * NU / (1.0 - NU ** 2)
MU = E / (2.0 * (1.0 + NU))

SIZES = (200, 800, 3200)
METHODS = ("NEM", "NEM-3", "NEM-13", "P1", "P2")
PATCH_RULES = ("smoothed", 1, 3, 4, 6, 7, 12, 13)
SEED = 0


# --------------------------------------------------------------------------
# the exact solution
# --------------------------------------------------------------------------

def exact_u(x, y):
    ux = -P * y / (6 * E * I) * ((6 * L - 3 * x) * x + (2 + NU) * (y ** 2 - D ** 2 / 4))
    uy = P / (6 * E * I) * (3 * NU * y ** 2 * (L - x) + (4 + 5 * NU) * D ** 2 * x / 4
                            + (3 * L - x) * x ** 2)
    return np.array([ux, uy])


def exact_strain(x, y):
    """Symmetric gradient of exact_u: (2, 2, ...)."""
    exx = -P * y * (L - x) / (E * I)
    eyy = NU * P * y * (L - x) / (E * I)
    exy = (1 + NU) * P / (2 * E * I) * (D ** 2 / 4 - y ** 2)
    return np.array([[exx, exy], [exy, eyy]])


def exact_stress(x, y):
    sxx = -P * (L - x) * y / I
    sxy = P / (2 * I) * (D ** 2 / 4 - y ** 2)
    return np.array([[sxx, sxy], [sxy, 0 * sxx]])


TIP = exact_u(L, 0.0)[1]


def stress_of_strain(e):
    tr = e[0, 0] + e[1, 1]
    return 2 * MU * e + LAM * tr * np.eye(2).reshape((2, 2) + (1,) * (e.ndim - 2))


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


# --------------------------------------------------------------------------
# node sets
# --------------------------------------------------------------------------

def _quantiles(density, a, b, m):
    s = np.linspace(a, b, 2001)
    c = np.r_[0.0, np.cumsum(0.5 * (density(s[1:]) + density(s[:-1])) * np.diff(s))]
    return np.interp(np.arange(1, m) / m * c[-1], c, s)


def beam_nodes(n, kind="random", seed=SEED):
    """About n nodes in the beam: corners, nodes on the four sides spaced like
    the local mean node distance, random interior nodes. ``graded``: node
    density 1 / (x + D/4) + 1 / L (denser at the clamp)."""
    rng = np.random.default_rng([seed, n, 0 if kind == "random" else 1])
    if kind == "random":
        density = lambda x: np.ones_like(x)  # noqa: E731
    else:
        density = lambda x: 1.0 / (x + D / 4) + 1.0 / L  # noqa: E731
    s = np.linspace(0.0, L, 4001)
    total = np.trapezoid(density(s), s) * D
    per_area = lambda x: n * density(x) / total  # noqa: E731
    m = max(int(round(np.trapezoid(np.sqrt(per_area(s)), s))), 2)
    xs = _quantiles(lambda x: np.sqrt(per_area(x)), 0.0, L, m)  # long sides
    m0, m1 = (max(int(round(D * np.sqrt(per_area(np.array([v]))[0]))), 2) for v in (0.0, L))
    y0 = np.linspace(-D / 2, D / 2, m0 + 1)
    y1 = np.linspace(-D / 2, D / 2, m1 + 1)
    boundary = np.r_[np.c_[0 * y0, y0], np.c_[L + 0 * y1, y1],
                     np.c_[xs, -D / 2 + 0 * xs], np.c_[xs, D / 2 + 0 * xs]]
    k = n - len(boundary)
    c = np.r_[0.0, np.cumsum(0.5 * (density(s[1:]) + density(s[:-1])) * np.diff(s))]
    inner = np.c_[np.interp(rng.random(k) * c[-1], c, s), (rng.random(k) - 0.5) * D]
    return np.r_[boundary, inner]


# --------------------------------------------------------------------------
# solving
# --------------------------------------------------------------------------

@LinearForm
def end_traction(v, w):
    x, y = w.x
    return P / (2 * I) * (D ** 2 / 4 - y ** 2) * v[1]


@Functional
def l2_error(w):
    e = w["uh"] - exact_u(*w.x)
    return e[0] ** 2 + e[1] ** 2


@Functional
def l2_norm(w):
    u = exact_u(*w.x)
    return u[0] ** 2 + u[1] ** 2


def _energy_density(e):
    return 2 * MU * (e[0, 0] ** 2 + e[1, 1] ** 2 + 2 * e[0, 1] ** 2) \
        + LAM * (e[0, 0] + e[1, 1]) ** 2


@Functional
def energy_error(w):
    return _energy_density(sym_grad(w["uh"]) - exact_strain(*w.x))


@Functional
def energy_norm(w):
    return _energy_density(exact_strain(*w.x))


def vector_element(method):
    if method.startswith("NEM"):
        return ElementVector(ElementNaturalNeighbour())
    return ElementVector(ElementTriP1() if method == "P1" else ElementTriP2())


def make_basis(mesh, method):
    if method == "NEM":
        return NaturalNeighbourBasis(mesh, vector_element(method))
    if method.startswith("NEM"):
        return NaturalNeighbourBasis(mesh, vector_element(method),
                                     npoints=int(method.split("-")[1]))
    return Basis(mesh, vector_element(method))


def interpolant(basis, fun):
    """Dof vector of the vector field fun(x, y) -> (2, ...) at the dof locations."""
    w = np.zeros(basis.N)
    for c, idx in enumerate(basis.split_indices()):
        w[idx] = fun(*basis.doflocs[:, idx])[c]
    return w


def solve_beam(mesh, method):
    """Returns the dof vector, the basis and the seconds (basis, assembly, solve)."""
    t0 = time.perf_counter()
    basis = make_basis(mesh, method)
    end = mesh.facets_satisfying(lambda x: np.isclose(x[0], L))
    if method.startswith("NEM"):
        fbasis = NaturalNeighbourFacetBasis(mesh, vector_element(method), facets=end)
    else:
        fbasis = FacetBasis(mesh, vector_element(method), facets=end)
    K = linear_elasticity(LAM, MU).assemble(basis)
    f = end_traction.assemble(fbasis)
    clamp = basis.get_dofs(lambda x: np.isclose(x[0], 0.0))
    u = solve(*condense(K, f, x=interpolant(basis, exact_u), D=clamp))
    return u, basis, time.perf_counter() - t0


def error_basis(mesh, method):
    if method.startswith("NEM"):
        return NaturalNeighbourBasis(mesh, vector_element(method), npoints=7)
    return Basis(mesh, vector_element(method), intorder=6)


def beam_errors(mesh, method, u, ebasis=None):
    eb = error_basis(mesh, method) if ebasis is None else ebasis
    uh = eb.interpolate(u)
    l2 = np.sqrt(l2_error.assemble(eb, uh=uh) / l2_norm.assemble(eb))
    en = np.sqrt(energy_error.assemble(eb, uh=uh) / energy_norm.assemble(eb))
    return l2, en


def tip_deflection(basis, u):
    return float((basis.probes(np.array([[L], [0.0]])) @ u)[1])


#: (nodes, mesh, basis, dof vector) of the NEM-3 solutions on the second
#: node set of each kind, for the figure
fields = {}


def cantilever(kind, sizes=SIZES, methods=METHODS):
    out = {m: {k: [] for k in ("nodes", "dofs", "tip", "l2", "energy", "seconds")}
           for m in methods}
    for n in sizes:
        p = beam_nodes(n, kind)
        mesh = delaunay_mesh(p)
        nem7 = None
        for m in methods:
            u, basis, sec = solve_beam(mesh, m)
            if m == "NEM" and n == sizes[min(1, len(sizes) - 1)]:
                fields[kind] = (p, mesh, basis, u)
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


# --------------------------------------------------------------------------
# module-level computation (checked by tests/test_examples_nem.py)
# --------------------------------------------------------------------------

exact_checks = equilibrium_residual()
results = {kind: cantilever(kind) for kind in ("random", "graded")}
patch = patch_test()


def von_mises(basis, u):
    """Per-triangle mean von Mises stress (plane stress) of the field u."""
    e = sym_grad(basis.interpolate(u))
    s = stress_of_strain(np.asarray(e))
    vm = np.sqrt(s[0, 0] ** 2 - s[0, 0] * s[1, 1] + s[1, 1] ** 2 + 3 * s[0, 1] ** 2)
    return (vm * basis.dx).sum(axis=1) / basis.dx.sum(axis=1)


def visualize(path="out/ex03_cantilever.png", scale=200.0):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 9), constrained_layout=True)
    gs = fig.add_gridspec(3, 2)
    for row, kind in enumerate(results):
        p, mesh, basis, u = fields[kind]
        vm = von_mises(basis, u)
        nodal = u[basis.nodal_dofs].T  # (nnodes, 2)
        q = p + scale * nodal
        a = fig.add_subplot(gs[row, :])
        a.triplot(p[:, 0], p[:, 1], mesh.t.T, lw=0.2, color="0.7")
        tp = a.tripcolor(q[:, 0], q[:, 1], mesh.t.T, facecolors=vm, cmap="viridis",
                         edgecolors="k", linewidth=0.1)
        fig.colorbar(tp, ax=a, label="von Mises stress")
        a.set_aspect("equal")
        a.set_title(f"NEM (smoothed gradients), {kind} nodes ({len(p)}): deformed x{scale:g}, "
                    f"tip deflection {tip_deflection(basis, u):.5f} (exact {TIP:.5f})")
    a = fig.add_subplot(gs[2, 0])
    r = results["random"]
    for m, s in zip(METHODS, ("D-", "o--", "o-", "s-", "^-")):
        a.loglog(r[m]["dofs"], r[m]["energy"], s, label=m)
    a.set_xlabel("number of dofs")
    a.set_ylabel("relative energy error")
    a.set_title("random nodes: energy error")
    a.grid(True, which="both", lw=0.3)
    a.legend()
    a = fig.add_subplot(gs[2, 1])
    a.semilogy([str(k) for k in patch], list(patch.values()), "o-")
    a.set_xlabel("integration (smoothed, or Gauss points per triangle)")
    a.set_ylabel("max interior nodal error / max |u|")
    a.set_title("patch test (linear displacement)")
    a.grid(True, which="both", lw=0.3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print("exact solution checks:", {k: f"{v:.1e}" for k, v in exact_checks.items()})
    print(f"exact tip deflection {TIP:.6e}\n")
    for kind, r in results.items():
        print(f"**{kind} nodes**\n")
        print("| method | nodes | dofs | tip deflection | tip error | L2 error | rate | "
              "energy error | rate | seconds |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for m in METHODS:
            d = r[m]
            for i in range(len(d["nodes"])):
                rl = f"{d['rate_l2'][i - 1]:.2f}" if i else ""
                re = f"{d['rate_energy'][i - 1]:.2f}" if i else ""
                print(f"| {m} | {d['nodes'][i]} | {d['dofs'][i]} | {d['tip'][i]:.6e} | "
                      f"{100 * d['tip_error'][i]:+.2f}% | {d['l2'][i]:.3e} | {rl} | "
                      f"{d['energy'][i]:.3e} | {re} | {d['seconds'][i]:.3f} |")
        print()
    print("**patch test, 800 random nodes**\n")
    print("| points | max interior nodal error / max abs(u) |")
    print("|---|---|")
    for q, v in patch.items():
        print(f"| {q} | {v:.2e} |")
    print("\nfigure written to", visualize())
