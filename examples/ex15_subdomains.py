"""Subdomains with different conductivities: a P0 coefficient through ``with_element``.

-div(k grad u) = 1 in the unit disk, u = 0 on the circle, with k = 10 in the
core r < 1/2 and k = 1 outside. The flux k u' = -r/2 is continuous, so the
exact solution is u = (1 - r^2)/4 outside and u(1/2) + (1/4 - r^2)/20 inside:
its slope drops tenfold across the interface. As in scikit-fem, k is a
piecewise-constant field on the triangles, ``p0 = basis.with_element(ElementTriP0())``,
passed to the form as ``k=p0.interpolate(k)``: the companion basis has the very
quadrature points of the natural-neighbour basis. Random nodes with a ring of
nodes on the interface; plain NEM smooths the kink away, NEM with the ring as
segments of a constrained triangulation (``delaunay_mesh(points, segments=...)``)
keeps it, as P1 does on the same triangles.
"""
from pathlib import Path

import numpy as np
from skfem import (Basis, BilinearForm, ElementTriP0, ElementTriP1, Functional, LinearForm,
                   condense, solve)
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh

A_CORE = 0.5
K_CORE = 10.0


def exact(x, y):
    r2 = x ** 2 + y ** 2
    return np.where(r2 < A_CORE ** 2, (1 - A_CORE ** 2) / 4 + (A_CORE ** 2 - r2) / (4 * K_CORE),
                    (1 - r2) / 4)


def nodes(n=900, ring=48, seed=3):
    """Random nodes in the unit disk, clear of the interface ring and the circle."""
    rng = np.random.default_rng(seed)
    k = int(2 * np.sqrt(np.pi * n))
    t = 2 * np.pi * np.arange(k) / k
    s = 2 * np.pi * np.arange(ring) / ring
    p = rng.uniform(-1, 1, (4 * n, 2))
    r = np.hypot(*p.T)
    h = 1.0 / np.sqrt(n)
    p = p[(r < 1 - 1.2 * h) & (np.abs(r - A_CORE) > 0.7 * h)][:n]
    return np.r_[np.c_[np.cos(t), np.sin(t)], A_CORE * np.c_[np.cos(s), np.sin(s)], p], k


points, n_circle = nodes()
ring = n_circle + np.arange(48)
segments = {"interface": np.c_[ring, np.roll(ring, -1)]}
meshes = {"NEM, plain": delaunay_mesh(points),
          "NEM, interface as segments": delaunay_mesh(points, segments=segments)}


@BilinearForm
def conduction(u, v, w):
    return w["k"] * dot(grad(u), grad(v))


@BilinearForm
def conduction_coded(u, v, w):
    return np.where(w.x[0] ** 2 + w.x[1] ** 2 < A_CORE ** 2, K_CORE, 1.0) * dot(grad(u), grad(v))


@LinearForm
def unit_load(v, w):
    return v


@Functional
def l2_error(w):
    return (w["u"] - exact(*w.x)) ** 2


def solve_with_p0(basis):
    """The solution with k a P0 field of the companion basis, and the largest difference
    of that stiffness matrix from the one with k coded in the form."""
    mesh = basis.mesh
    p0 = basis.with_element(ElementTriP0())
    k = p0.ones()
    k[mesh.elements_satisfying(lambda x: x[0] ** 2 + x[1] ** 2 < A_CORE ** 2)] = K_CORE
    A = conduction.assemble(basis, k=p0.interpolate(k))
    diff = abs(A - conduction_coded.assemble(basis)).max() / abs(A).max()
    u = solve(*condense(A, unit_load.assemble(basis), D=basis.get_dofs()))
    return u, diff


results = {}
for name, mesh in meshes.items():
    u, diff = solve_with_p0(NaturalNeighbourBasis(mesh))
    err = np.sqrt(l2_error.assemble(NaturalNeighbourBasis(mesh, npoints=7), u=u))
    results[name] = {"u": u, "L2": float(err), "coded vs P0": float(diff)}
p1_mesh = meshes["NEM, interface as segments"]
u1, diff1 = solve_with_p0(Basis(p1_mesh, ElementTriP1()))
results["P1"] = {"u": u1, "coded vs P0": float(diff1), "L2": float(np.sqrt(
    l2_error.assemble(Basis(p1_mesh, ElementTriP1(), intorder=5), u=u1)))}

FIGURE = "out/ex15_subdomains.png"


def visualize(path=FIGURE):
    """Draw the constrained NEM solution and the errors along a radius; returns the
    Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    name = "NEM, interface as segments"
    basis = NaturalNeighbourBasis(meshes[name])
    basis.plot(results[name]["u"], ax=ax[0], colorbar=True)
    ax[0].plot(A_CORE * np.cos(np.linspace(0, 2 * np.pi, 200)),
               A_CORE * np.sin(np.linspace(0, 2 * np.pi, 200)), "w--", lw=0.8)
    ax[0].set_title(f"{name}: k = {K_CORE:g} inside the dashed circle")
    ax[0].set_aspect("equal")
    r = np.linspace(0.0, 0.98, 300)
    line = np.array([r * np.cos(0.2), r * np.sin(0.2)])
    for label, mesh in [*meshes.items(), ("P1", p1_mesh)]:
        b = Basis(mesh, ElementTriP1()) if label == "P1" else NaturalNeighbourBasis(mesh)
        ax[1].plot(r, b.probes(line) @ results[label]["u"] - exact(*line),
                   label=f"{label}: L2 error {results[label]['L2']:.1e}")
    ax[1].axvline(A_CORE, color="0.6", ls=":")
    ax[1].set(xlabel="r (along the angle 0.2)", ylabel="u_h - u", title="error along a radius")
    ax[1].legend(fontsize=8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | L2 error | P0 field vs coded k (stiffness, relative) |\n|---|---|---|")
    for name, r in results.items():
        print(f"| {name} | {r['L2']:.3e} | {r['coded vs P0']:.1e} |")
    visualize()
    print("figure written to", FIGURE)
