"""Consistent integration: the linear patch test with smoothed gradients.

A linear field u = 1 + 2x + 3y imposed on the boundary of random nodes, no
source: the exact solution is the field itself, which natural-neighbour
functions reproduce. With the paper's 3-point Gauss rule the Galerkin solution
misses it by the quadrature error (Sibson functions are not polynomials on
the triangles); with the default basis, whose gradients are smoothed over
three cells per triangle (one at each vertex: the vertex, its two edge
midpoints and the centroid), it is reproduced to round-off.

``visualize()`` draws the smoothing cells of a few triangles with their
integration points and the points on the cell edges where the functions
are evaluated, and the nodal errors of both integrations.
"""
from pathlib import Path

import numpy as np
from skfem import BilinearForm, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.basis.smoothing import cells_2d

nodes = box_nodes(300, seed=2)
mesh = delaunay_mesh(nodes)
exact = 1.0 + 2.0 * nodes[:, 0] + 3.0 * nodes[:, 1]


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


def nodal_error(basis):
    A = laplace.assemble(basis)
    u = solve(*condense(A, np.zeros(basis.N), x=exact, D=basis.get_dofs()))
    return np.abs(u - exact)


errors = {"smoothed (default)": nodal_error(NaturalNeighbourBasis(mesh)),
          "Gauss, 3 points": nodal_error(NaturalNeighbourBasis(mesh, npoints=3))}


def cell_polygons(elems):
    """(3 k, 4, 2) corners of the vertex cells of the triangles ``elems``."""
    V = mesh.p.T[mesh.t[:, elems].T]                        # (k, 3, 2)
    g = V.mean(axis=1)
    out = [np.stack([V[:, i], 0.5 * (V[:, i] + V[:, (i + 1) % 3]), g,
                     0.5 * (V[:, i] + V[:, (i + 2) % 3])], axis=1) for i in range(3)]
    return np.stack(out, axis=1).reshape(-1, 4, 2)


FIGURE = "out/ex12_smoothing.png"


def visualize(path=FIGURE):
    """Draw the smoothing cells and both rules' nodal errors; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    centre = np.array([0.5, 0.5])
    mid = mesh.p[:, mesh.t].mean(axis=1).T
    elems = np.argsort(((mid - centre) ** 2).sum(axis=1))[:6]
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    a = ax[0]
    a.triplot(nodes[:, 0], nodes[:, 1], mesh.t.T, lw=0.4, color="0.6")
    cells = PolyCollection(cell_polygons(elems), facecolors=plt.cm.tab20(np.arange(18) % 20),
                           edgecolors="k", linewidths=0.8, alpha=0.6)
    a.add_collection(cells)
    pts = cells_2d(mesh.p.T, mesh.t, mesh.t2f, mesh.facets, np.sort(elems))[0]
    a.plot(pts[:, 0], pts[:, 1], ".", color="C3", ms=5, label="edge points (values)")
    x = np.asarray(NaturalNeighbourBasis(mesh).global_coordinates())[:, elems].reshape(2, -1)
    a.plot(x[0], x[1], "x", color="k", ms=7, label="integration points")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.3 * (hi - lo).max()
    a.set_xlim(lo[0] - pad, hi[0] + pad)
    a.set_ylim(lo[1] - pad, hi[1] + pad)
    a.set_aspect("equal")
    a.legend(loc="lower left", fontsize=8)
    a.set_title("smoothing cells: one per vertex of each triangle")
    for a, (name, err) in zip(ax[1:], errors.items()):
        tp = a.tripcolor(nodes[:, 0], nodes[:, 1], mesh.t.T, np.log10(err + 1e-17),
                         shading="gouraud", vmin=-16, vmax=-1, cmap="magma")
        a.set_aspect("equal")
        a.set_title(f"{name}: max nodal error {err.max():.1e}")
    fig.colorbar(tp, ax=ax[1:], label="log10 |u - (1 + 2x + 3y)| at the nodes")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for name, err in errors.items():
        print(f"{name}: largest nodal error {err.max():.2e}")
    visualize()
    print("figure written to", FIGURE)
