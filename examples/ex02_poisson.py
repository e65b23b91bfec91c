"""Poisson's equation with natural-neighbour trial functions.

The scikit-fem workflow of a P1 script, with one line changed: the basis.
Nodes are graded as in the paper's Fig. 6 (density inversely proportional to
the distance from a line), so many Delaunay triangles are elongated. The
manufactured solution u = sin(pi x) sin(pi y) gives the right-hand side; the
L2 and energy errors of NEM and of P1 on the same triangles are printed.
"""
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementTriP1, Functional, LinearForm, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh


def graded_nodes(n=1500, seed=0, line=0.5, floor=0.02):
    """Random nodes in the unit square, density ~ 1 / (distance to y = line + floor),
    plus nodes along the sides (so the convex hull is the square)."""
    rng = np.random.default_rng(seed)
    pts = []
    while len(pts) < n:
        c = rng.random((4 * n, 2))
        d = np.abs(c[:, 1] - line) + floor
        keep = rng.random(4 * n) < floor / d
        pts.extend(c[keep][: n - len(pts)])
    k = int(np.sqrt(n)) // 2
    s = np.linspace(0, 1, k + 1)[1:-1]
    side = np.r_[np.c_[s, 0 * s], np.c_[s, 1 + 0 * s], np.c_[0 * s, s], np.c_[1 + 0 * s, s]]
    return np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], side, np.array(pts)]


def exact(x, y):
    return np.sin(np.pi * x) * np.sin(np.pi * y)


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return 2 * np.pi ** 2 * exact(*w.x) * v


@Functional
def l2_error(w):
    return (w["u"] - exact(*w.x)) ** 2


@Functional
def energy_error(w):
    x, y = w.x
    ux = np.pi * np.cos(np.pi * x) * np.sin(np.pi * y)
    uy = np.pi * np.sin(np.pi * x) * np.cos(np.pi * y)
    return (w["u"].grad[0] - ux) ** 2 + (w["u"].grad[1] - uy) ** 2


mesh = delaunay_mesh(graded_nodes())
results = {}
solutions = {}
for name, basis in [("NEM", NaturalNeighbourBasis(mesh)),   # the one line that changes
                    ("P1", Basis(mesh, ElementTriP1()))]:
    A = laplace.assemble(basis)
    b = load.assemble(basis)
    u = solve(*condense(A, b, D=basis.get_dofs()))
    solutions[name] = (basis, u)
    results[name] = {"L2": np.sqrt(l2_error.assemble(basis, u=u)),
                     "energy": np.sqrt(energy_error.assemble(basis, u=u))}


FIGURE = "out/ex02_poisson.png"


def visualize(path=FIGURE):
    """Draw the mesh, the NEM solution and its nodal error; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    mesh.draw(ax=ax[0])
    ax[0].set_title(f"graded Delaunay mesh: {mesh.nvertices} nodes, {mesh.nelements} triangles")
    basis, u = solutions["NEM"]
    basis.plot(u, ax=ax[1], nrefs=2, colorbar=True)
    ax[1].set_title(f"NEM solution (L2 error {results['NEM']['L2']:.2e})")
    err = u - exact(*mesh.p)
    lim = np.abs(err).max()
    im = ax[2].tripcolor(mesh.p[0], mesh.p[1], mesh.t.T, err, shading="gouraud", cmap="RdBu_r",
                         vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=ax[2])
    ax[2].set_title("NEM nodal error")
    for a in ax:
        a.set_aspect("equal")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | L2 error | energy error |\n|---|---|---|")
    for name, r in results.items():
        print(f"| {name} | {r['L2']:.3e} | {r['energy']:.3e} |")
    visualize()
    print("figure written to", FIGURE)
