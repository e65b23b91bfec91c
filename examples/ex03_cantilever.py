"""Timoshenko's cantilever beam with natural-neighbour trial functions.

A beam 0 <= x <= L, -D/2 <= y <= D/2 (plane stress, E, nu) is held at x = 0
and carries a parabolic shear traction of resultant P on its end x = L. The
exact solution (Timoshenko & Goodier 1970; the meshfree benchmark used for
NEM by Sukumar, Moran & Belytschko 1998), I = D^3 / 12:

    u_x = -P y / (6 E I) [(6 L - 3 x) x + (2 + nu) (y^2 - D^2 / 4)]
    u_y =  P / (6 E I) [3 nu y^2 (L - x) + (4 + 5 nu) D^2 x / 4 + (3 L - x) x^2]

The exact displacements are imposed at the nodes of x = 0, the exact
traction on x = L through ``NaturalNeighbourFacetBasis``. The vector NEM basis
``ElementVector(ElementNaturalNeighbour())`` (smoothed gradients, the
default) is assembled with scikit-fem's ``linear_elasticity`` on 800 random
nodes and compared with vector P1 on the same Delaunay mesh: tip deflection,
relative L2 and energy errors. Convergence on random and graded nodes, Gauss
rules, the patch test and a check of the exact solution:
``benchmarks/cantilever.py``.
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
N_NODES = 800
SEED = 0
FIGURE = "out/ex03_cantilever.png"


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


TIP = exact_u(L, 0.0)[1]


def stress_of_strain(e):
    tr = e[0, 0] + e[1, 1]
    return 2 * MU * e + LAM * tr * np.eye(2).reshape((2, 2) + (1,) * (e.ndim - 2))


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


@LinearForm
def end_traction(v, w):
    x, y = w.x
    return P / (2 * I) * (D ** 2 / 4 - y ** 2) * v[1]


@Functional
def l2_error(w):
    e = w["uh"] - exact_u(*w.x)
    return e[0] ** 2 + e[1] ** 2


def _energy_density(e):
    return 2 * MU * (e[0, 0] ** 2 + e[1, 1] ** 2 + 2 * e[0, 1] ** 2) \
        + LAM * (e[0, 0] + e[1, 1]) ** 2


@Functional
def energy_error(w):
    return _energy_density(sym_grad(w["uh"]) - exact_strain(*w.x))


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
    """Relative L2 and energy errors of the dof vector u."""
    eb = error_basis(mesh, method) if ebasis is None else ebasis
    uh, zero = eb.interpolate(u), eb.interpolate(0 * u)
    return tuple(np.sqrt(f.assemble(eb, uh=uh) / f.assemble(eb, uh=zero))
                 for f in (l2_error, energy_error))


def tip_deflection(basis, u):
    return float((basis.probes(np.array([[L], [0.0]])) @ u)[1])


def von_mises(basis, u):
    """Per-triangle mean von Mises stress (plane stress) of the field u."""
    e = sym_grad(basis.interpolate(u))
    s = stress_of_strain(np.asarray(e))
    vm = np.sqrt(s[0, 0] ** 2 - s[0, 0] * s[1, 1] + s[1, 1] ** 2 + 3 * s[0, 1] ** 2)
    return (vm * basis.dx).sum(axis=1) / basis.dx.sum(axis=1)


p = beam_nodes(N_NODES)
mesh = delaunay_mesh(p)


def solve_and_check(method):
    """The solution on ``mesh`` and its errors against the exact solution."""
    u, basis, _ = solve_beam(mesh, method)
    l2, energy = beam_errors(mesh, method, u)
    return {"u": u, "basis": basis, "l2": l2, "energy": energy,
            "tip_error": tip_deflection(basis, u) / TIP - 1.0}


#: method -> {"u", "basis", "tip_error", "l2", "energy"}
results = {m: solve_and_check(m) for m in ("NEM", "P1")}


def visualize(path=FIGURE, scale=200.0):
    """The NEM solution: deformed mesh coloured by the von Mises stress;
    returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    basis, u = results["NEM"]["basis"], results["NEM"]["u"]
    q = p + scale * u[basis.nodal_dofs].T
    fig, a = plt.subplots(figsize=(13, 3.6), constrained_layout=True)
    a.triplot(p[:, 0], p[:, 1], mesh.t.T, lw=0.2, color="0.7")
    tp = a.tripcolor(q[:, 0], q[:, 1], mesh.t.T, facecolors=von_mises(basis, u),
                     cmap="viridis", edgecolors="k", linewidth=0.1)
    fig.colorbar(tp, ax=a, label="von Mises stress")
    a.set_aspect("equal")
    a.set_title(f"NEM (smoothed gradients), {len(p)} random nodes: deformed x{scale:g}, "
                f"tip deflection {tip_deflection(basis, u):.5f} (exact {TIP:.5f})")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print(f"exact tip deflection {TIP:.6e}\n")
    print("| method | tip error | L2 error | energy error |\n|---|---|---|---|")
    for m, r in results.items():
        print(f"| {m} | {100 * r['tip_error']:+.2f}% | {r['l2']:.3e} | {r['energy']:.3e} |")
    visualize()
    print("figure written to", FIGURE)
