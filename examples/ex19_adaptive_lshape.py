"""Adaptive refinement on an L-shape: a gradient-recovery indicator, NEM against P1.

Laplace(u) = 0 on the L-shape (-1, 1)^2 without its first quadrant, with u on the
boundary taken from the singular solution u = r^(2/3) sin(2 theta / 3) of the
re-entrant corner (theta measured from the positive y axis). Its gradient blows
up at the corner, so uniform refinement converges at the rate dofs^(-1/3) in the
energy norm. The indicator of a triangle is the gradient-recovery (Zienkiewicz-Zhu)
estimate: the L2 norm over the triangle of the difference between the gradient the
forms see and its L2 projection onto continuous P1 fields (a ``with_element``
companion); the triangles holding half of the estimate are refined with
``mesh.refined(marked)`` (those meshes are not Delaunay: the basis integrates on
them and triangulates the nodes itself). The loop is driven by the NEM indicator;
P1 is solved on the very same meshes, and both are also run on uniformly refined
meshes. Errors are the energy norm of u - u_h, with exact gradients of the NEM
field (a 7-point Gauss basis).
"""
from pathlib import Path

import numpy as np
from skfem import (Basis, BilinearForm, ElementTriP1, ElementVector, Functional, MeshTri,
                   adaptive_theta, condense, solve)
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis

#: adaptive steps, and the share of the estimate marked at each
STEPS = 12
THETA = 0.5


def exact(x, y):
    theta = np.mod(np.arctan2(y, x) - np.pi / 2, 2 * np.pi)
    return np.hypot(x, y) ** (2 / 3) * np.sin(2 * theta / 3)


def exact_grad(x, y):
    r = np.maximum(np.hypot(x, y), 1e-300)
    theta = np.mod(np.arctan2(y, x) - np.pi / 2, 2 * np.pi)
    ur = 2 / 3 * r ** (-1 / 3) * np.sin(2 * theta / 3)
    ut = 2 / 3 * r ** (-1 / 3) * np.cos(2 * theta / 3)          # (1/r) du/dtheta
    phi = np.arctan2(y, x)
    return np.array([ur * np.cos(phi) - ut * np.sin(phi), ur * np.sin(phi) + ut * np.cos(phi)])


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@Functional
def energy_error(w):
    d = grad(w["u"]) - exact_grad(*w.x)
    return dot(d, d)


@Functional
def recovery(w):
    d = grad(w["u"]) - w["g"]
    return dot(d, d)


def solve_on(basis):
    """The discrete harmonic function with the exact boundary values."""
    u = basis.zeros()
    D = basis.get_dofs()
    u[D] = exact(*basis.mesh.p[:, D])
    return solve(*condense(laplace.assemble(basis), x=u, D=D))


def indicator(basis, u):
    """Per-triangle gradient-recovery estimate of the error of u on basis."""
    p1 = basis.with_element(ElementVector(ElementTriP1()))
    g = p1.project(basis.interpolate(u).grad)
    return np.sqrt(recovery.elemental(basis, u=u, g=p1.interpolate(g)))


def error(mesh, name, u):
    b = (NaturalNeighbourBasis(mesh, npoints=7) if name == "NEM"
         else Basis(mesh, ElementTriP1(), intorder=4))
    return float(np.sqrt(energy_error.assemble(b, u=u)))


def run(meshes):
    """Errors (NEM and P1) and dofs on a list of meshes."""
    out = {"NEM": [], "P1": [], "dofs": []}
    for m in meshes:
        out["NEM"].append(error(m, "NEM", solve_on(NaturalNeighbourBasis(m))))
        out["P1"].append(error(m, "P1", solve_on(Basis(m, ElementTriP1()))))
        out["dofs"].append(m.nvertices)
    return {k: np.array(v) for k, v in out.items()}


mesh = MeshTri.init_lshaped().refined(2)
adaptive = [mesh]
for _ in range(STEPS):
    basis = NaturalNeighbourBasis(adaptive[-1])
    eta = indicator(basis, solve_on(basis))
    adaptive.append(adaptive[-1].refined(adaptive_theta(eta, theta=THETA)))
uniform = [mesh.refined(k) for k in range(4)]
results = {"adaptive": run(adaptive), "uniform": run(uniform)}


def rate(r, name):
    """Slope of log(error) against log(dofs) over the last half of the meshes."""
    k = len(r["dofs"]) // 2
    return float(np.polyfit(np.log(r["dofs"][k:]), np.log(r[name][k:]), 1)[0])


FIGURE = "out/ex19_adaptive_lshape.png"


def visualize(path=FIGURE):
    """Draw the last adaptive mesh and the errors against dofs; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 5.2), constrained_layout=True)
    final = adaptive[-1]
    final.draw(ax=ax[0])
    ax[0].set_title(f"last adaptive mesh ({final.nvertices} nodes)")
    ax[0].set_aspect("equal")
    for kind, style in (("adaptive", "o-"), ("uniform", "s--")):
        r = results[kind]
        for name in ("NEM", "P1"):
            ax[1].loglog(r["dofs"], r[name], style,
                         label=f"{name}, {kind}: rate {rate(r, name):.2f}")
    ax[1].set(xlabel="dofs (nodes)", ylabel="energy norm of u - u_h",
              title="NEM against P1 on the same meshes")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for kind, r in results.items():
        print(f"\n{kind}\n| dofs | NEM | P1 |\n|---|---|---|")
        for n, a, b in zip(r["dofs"], r["NEM"], r["P1"]):
            print(f"| {n} | {a:.3e} | {b:.3e} |")
        print(f"rates: NEM {rate(r, 'NEM'):.2f}, P1 {rate(r, 'P1'):.2f}")
    visualize()
    print("figure written to", FIGURE)
