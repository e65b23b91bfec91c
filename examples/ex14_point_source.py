"""A point source in a disk: the Green's function, NEM against P1 and P2.

-Laplace(u) = delta(x) in the unit disk with u = 0 on the circle has the exact
solution u = -ln(r) / (2 pi). The load of the point source is
``basis.point_source(x)``, the values of the test functions at the source, for
the natural-neighbour basis as for scikit-fem's. Nodes are random, one at the
source; the L2 error is measured away from the singularity, in the annulus
0.2 < r < 1 (the polygon of the boundary nodes, whose sides cut the circle,
adds the same small error to all three). NEM and P1 use the same nodes, P2 a
coarser set with about as many unknowns.
"""
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementTriP1, ElementTriP2, Functional, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh

#: the annulus where errors are measured (the singularity at r = 0 is left out)
R_INNER = 0.2


def disk_nodes(n, seed=0):
    """A node at the centre, nodes on the unit circle and n random nodes inside."""
    rng = np.random.default_rng(seed)
    k = int(2 * np.sqrt(np.pi * n))
    t = 2 * np.pi * np.arange(k) / k
    circle = np.c_[np.cos(t), np.sin(t)]
    p = rng.uniform(-1, 1, (3 * n, 2))
    r = np.hypot(*p.T)
    inner = p[(r < 1 - 1.5 / np.sqrt(n)) & (r > 1.0 / np.sqrt(n))][:n]
    return np.r_[[[0.0, 0.0]], circle, inner]


def exact(x, y):
    return -np.log(np.hypot(x, y)) / (2 * np.pi)


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@Functional
def annulus_l2(w):
    r = np.hypot(*w.x)
    return np.where(r > R_INNER, (w["u"] - exact(*w.x)) ** 2, 0.0)


def green(basis):
    """The discrete Green's function of the centre."""
    A = laplace.assemble(basis)
    b = basis.point_source(np.array([0.0, 0.0]))
    return solve(*condense(A, b, D=basis.get_dofs()))


mesh = delaunay_mesh(disk_nodes(1000))
coarse = delaunay_mesh(disk_nodes(250))
cases = {"NEM": NaturalNeighbourBasis(mesh),
         "P1": Basis(mesh, ElementTriP1()),
         "P2": Basis(coarse, ElementTriP2())}
solutions = {name: green(b) for name, b in cases.items()}
error_bases = {"NEM": NaturalNeighbourBasis(mesh, npoints=7),
               "P1": Basis(mesh, ElementTriP1(), intorder=5),
               "P2": Basis(coarse, ElementTriP2(), intorder=5)}
errors = {name: float(np.sqrt(annulus_l2.assemble(error_bases[name], u=solutions[name])))
          for name in cases}
dofs = {name: int(b.N) for name, b in cases.items()}

FIGURE = "out/ex14_point_source.png"


def visualize(path=FIGURE):
    """Draw the NEM Green's function and the errors along a radius; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    cases["NEM"].plot(solutions["NEM"], ax=ax[0], colorbar=True, vmax=0.6)
    ax[0].set_title(f"NEM Green's function ({dofs['NEM']} nodes)")
    ax[0].set_aspect("equal")
    r = np.linspace(R_INNER, 0.97, 200)
    line = np.array([r * np.cos(0.3), r * np.sin(0.3)])
    for name, b in cases.items():
        ax[1].plot(r, b.probes(line) @ solutions[name] - exact(*line),
                   label=f"{name}: {dofs[name]} dofs, L2 error (r > {R_INNER}) "
                         f"{errors[name]:.2e}")
    ax[1].set(xlabel="r (along the angle 0.3)", ylabel="u_h - u",
              title="error away from the source")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print(f"| method | dofs | L2 error for r > {R_INNER} |\n|---|---|---|")
    for name in cases:
        print(f"| {name} | {dofs[name]} | {errors[name]:.3e} |")
    visualize()
    print("figure written to", FIGURE)
