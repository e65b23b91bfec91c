"""NEM against P1 and P2 on the same Delaunay mesh.

-Δu = f on the unit square, u = sin(pi x) sin(pi y), u = 0 on the boundary,
on 4000 ``graded`` nodes (denser towards y = 1/2, the grading of the paper's
Fig. 6; ``uniform``: evenly random). One Delaunay mesh, three trial spaces:
``NEM`` (Sibson functions, gradients smoothed over three cells per triangle:
the default, consistent integration; ``NEM-3`` / ``NEM-13``: Gauss rules with
3 / 13 points per triangle instead), scikit-fem's ``P1`` and ``P2``. Errors
(L2, H1 seminorm) use finer rules. NEM is more accurate than P1 on the same
nodes; P2, with four times the dofs, more than both. The convergence study,
cost, quadrature rules and thin triangles: ``benchmarks/nem_vs_fem.py``.
"""
import time
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementTriP1, ElementTriP2, Functional, LinearForm
from skfem import condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh

N_NODES = 4000
METHODS = ("NEM", "P1", "P2")
SEED = 0
FIGURE = "out/ex04_nem_vs_fem.png"


def _quantiles(density, a, b, m):
    """The m - 1 points inside [a, b] that cut it into m pieces of equal mass
    of density(s): their spacing is inversely proportional to the density."""
    s = np.linspace(a, b, 2001)
    c = np.r_[0.0, np.cumsum(0.5 * (density(s[1:]) + density(s[:-1])) * np.diff(s))]
    return np.interp(np.arange(1, m) / m * c[-1], c, s)


def rectangle_nodes(n, rng, width=1.0, height=1.0, density=None, axis=1):
    """n nodes in [0, width] x [0, height]: corners, sides spaced like the local
    mean node distance, random interior nodes drawn from ``density`` (per unit
    area, a function of coordinate ``axis``; None: uniform)."""
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


p = node_set("graded", N_NODES)
mesh = delaunay_mesh(p)
#: method -> (dof vector, basis, seconds, L2 error, H1 error)
solutions = {m: solve_poisson(mesh, m) for m in METHODS}


def visualize(path=FIGURE):
    """The graded mesh, the NEM nodal error and the errors of the three
    methods; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    ax[0].triplot(p[:, 0], p[:, 1], mesh.t.T, lw=0.2, color="k")
    ax[0].set_title(f"graded nodes: {len(p)} nodes, {mesh.nelements} triangles")
    err = solutions["NEM"][0] - exact(*p.T)
    lim = np.abs(err).max()
    tp = ax[1].tripcolor(p[:, 0], p[:, 1], mesh.t.T, err, shading="gouraud", cmap="RdBu_r",
                         vmin=-lim, vmax=lim)
    fig.colorbar(tp, ax=ax[1])
    ax[1].set_title("NEM nodal error")
    for a in ax[:2]:
        a.set_aspect("equal")
    x = np.arange(len(METHODS))
    for k, (norm, col) in enumerate((("L2", 3), ("H1 seminorm", 4))):
        ax[2].bar(x + 0.4 * k - 0.2, [solutions[m][col] for m in METHODS], 0.4, label=norm)
    ax[2].set_xticks(x, [f"{m}\n{solutions[m][1].N} dofs" for m in METHODS])
    ax[2].set_yscale("log")
    ax[2].set_title("errors on the same triangles")
    ax[2].legend()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | dofs | L2 error | H1 error | seconds |\n|---|---|---|---|---|")
    for m, (u, basis, sec, e0, e1) in solutions.items():
        print(f"| {m} | {basis.N} | {e0:.3e} | {e1:.3e} | {sec:.2f} |")
    visualize()
    print("figure written to", FIGURE)
