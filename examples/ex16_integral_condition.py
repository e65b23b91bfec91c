"""A pure Neumann problem closed by an integral condition on the boundary.

-Laplace(u) = 2 pi^2 cos(pi x) cos(pi y) on the unit square with zero normal
flux on all sides fixes u only up to a constant; the condition that u has mean
zero over the boundary, the integral of u over the sides (a linear form on
``NaturalNeighbourFacetBasis``, as on scikit-fem's ``FacetBasis``) set to
zero with a Lagrange multiplier, closes it. The exact solution is
u = cos(pi x) cos(pi y). NEM and P1 on the same random nodes, P2 on a
coarser set with about as many unknowns.
"""
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from skfem import (Basis, BilinearForm, ElementTriP1, ElementTriP2, FacetBasis, Functional,
                   LinearForm, solve)
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, NaturalNeighbourFacetBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes


def exact(x, y):
    return np.cos(np.pi * x) * np.cos(np.pi * y)


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return 2 * np.pi ** 2 * exact(*w.x) * v


@LinearForm
def boundary_integral(v, w):
    return v


@Functional
def l2_error(w):
    return (w["u"] - exact(*w.x)) ** 2


def solve_neumann(basis, facet_basis):
    """The saddle-point system [[A, c], [c^T, 0]] with c the boundary integral of
    each function; returns the solution and the multiplier."""
    A = laplace.assemble(basis)
    c = boundary_integral.assemble(facet_basis)
    K = sp.bmat([[A, sp.csr_matrix(c[:, None])], [sp.csr_matrix(c[None, :]), None]], "csr")
    x = solve(K, np.r_[load.assemble(basis), 0.0])
    return x[:-1], x[-1], c


mesh = delaunay_mesh(box_nodes(900, seed=11))
coarse = delaunay_mesh(box_nodes(200, seed=11))
cases = {"NEM": (NaturalNeighbourBasis(mesh), NaturalNeighbourFacetBasis(mesh)),
         "P1": (Basis(mesh, ElementTriP1()), FacetBasis(mesh, ElementTriP1())),
         "P2": (Basis(coarse, ElementTriP2()), FacetBasis(coarse, ElementTriP2()))}
results = {}
for name, (basis, fbasis) in cases.items():
    u, lam, c = solve_neumann(basis, fbasis)
    eb = (NaturalNeighbourBasis(mesh, npoints=7) if name == "NEM"
          else Basis(basis.mesh, basis.elem, intorder=5))
    results[name] = {"u": u, "dofs": int(basis.N), "multiplier": float(lam),
                     "boundary mean": float(c @ u / 4.0),
                     "L2": float(np.sqrt(l2_error.assemble(eb, u=u)))}

FIGURE = "out/ex16_integral_condition.png"


def visualize(path=FIGURE):
    """Draw the NEM solution and the errors along the bottom side; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    basis = cases["NEM"][0]
    basis.plot(results["NEM"]["u"], ax=ax[0], colorbar=True, levels=9)
    ax[0].set_title(f"NEM ({results['NEM']['dofs']} nodes), boundary mean "
                    f"{results['NEM']['boundary mean']:.0e}")
    ax[0].set_aspect("equal")
    s = np.linspace(0, 1, 300)
    line = np.array([s, 0 * s])
    for name, (b, _) in cases.items():
        ax[1].plot(s, b.probes(line) @ results[name]["u"] - exact(*line),
                   label=f"{name}: {results[name]['dofs']} dofs, L2 error "
                         f"{results[name]['L2']:.2e}")
    ax[1].set(xlabel="x (y = 0)", ylabel="u_h - u", title="error along the bottom side")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | dofs | L2 error | boundary mean of u_h |\n|---|---|---|---|")
    for name, r in results.items():
        print(f"| {name} | {r['dofs']} | {r['L2']:.3e} | {r['boundary mean']:.1e} |")
    visualize()
    print("figure written to", FIGURE)
