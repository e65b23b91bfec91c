"""Poisson's equation in 3D: natural-neighbour trial functions on Delaunay tetrahedra.

-Δu = f in the unit cube, u = 0 on its boundary, u = sin(pi x) sin(pi y) sin(pi z).
Nodes: the corners, random nodes on the edges and faces (spaced like the
interior ones) and 700 random interior nodes. On their Delaunay tetrahedra
(Qhull, :func:`skfem_nem.delaunay_mesh`) the problem is solved with ``NEM``
(Sibson functions from the paper's Box 1, the Lasserre method; smoothed gradients)
and with scikit-fem's ``P1`` / ``P2``; L2 and H1-seminorm errors with the
11-point rule. NEM is more accurate than P1 on the same tetrahedra, less than P2.

``visualize()`` draws one interior node's natural-neighbour function -- the
paper's Figs 3-4 -- as VTU for ParaView (``out/ex06_natural_neighbour_function.vtu``,
with the gradient) and as PNG slices through the node beside the errors
(``out/ex06_poisson_3d.png``); the NEM solution goes to ``out/ex06_poisson_3d.vtu``.
The convergence study is ``benchmarks/poisson_3d.py`` (the tables of ``docs/ndim.md``).
"""
import time
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementTetP1, ElementTetP2, Functional, LinearForm
from skfem import condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh, sibson_coordinates

N_NODES = 700                     # interior nodes
FIG_NODES = 250                   # of the mesh whose node function is drawn
METHODS = ("NEM", "P1", "P2")
SEED = 0
FIGURE = "out/ex06_poisson_3d.png"


def cube_nodes(n, seed=SEED):
    """Nodes of the unit cube: corners, edges, faces and n random interior nodes,
    the boundary ones as dense as the interior ones (spacing n^(-1/3))."""
    rng = np.random.default_rng(seed)
    k = n ** (1 / 3)
    corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    parts = [corners]
    for ax in range(3):
        a, b = [c for c in range(3) if c != ax]
        for va in (0.0, 1.0):
            for vb in (0.0, 1.0):
                e = np.zeros((max(1, int(round(k))), 3))
                e[:, ax] = rng.random(e.shape[0])
                e[:, a], e[:, b] = va, vb
                parts.append(e)
            f = rng.random((max(1, int(round(k * k))), 3))
            f[:, ax] = va
            parts.append(f)
    parts.append(rng.random((n, 3)))
    return np.concatenate(parts)


def exact(x):
    return np.sin(np.pi * x[0]) * np.sin(np.pi * x[1]) * np.sin(np.pi * x[2])


def exact_grad(x):
    s, c = np.sin(np.pi * x), np.cos(np.pi * x)
    return np.pi * np.stack([c[0] * s[1] * s[2], s[0] * c[1] * s[2], s[0] * s[1] * c[2]])


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def load(v, w):
    return 3 * np.pi ** 2 * exact(w.x) * v


@Functional
def l2_error(w):
    return (w["u"] - exact(w.x)) ** 2


@Functional
def h1_error(w):
    return ((w["u"].grad - exact_grad(w.x)) ** 2).sum(axis=0)


def solve_on(mesh, method):
    """Solve on one mesh; returns (basis, u, {"l2", "h1", "dofs", "seconds"})."""
    t0 = time.perf_counter()
    if method == "NEM":
        basis = NaturalNeighbourBasis(mesh)                   # smoothed gradients
        ebasis = NaturalNeighbourBasis(mesh, intorder=4)      # for the errors
    else:
        elem = ElementTetP1() if method == "P1" else ElementTetP2()
        basis = ebasis = Basis(mesh, elem, intorder=4)
    u = solve(*condense(laplace.assemble(basis), load.assemble(basis), D=basis.get_dofs()))
    seconds = time.perf_counter() - t0
    err = {"l2": np.sqrt(l2_error.assemble(ebasis, u=u)),
           "h1": np.sqrt(h1_error.assemble(ebasis, u=u)),
           "dofs": basis.N, "seconds": seconds}
    return basis, u, err


mesh = delaunay_mesh(cube_nodes(N_NODES))
solutions = {m: solve_on(mesh, m) for m in METHODS}
#: method -> {"l2", "h1", "dofs", "seconds"}
results = {m: s[2] for m, s in solutions.items()}
basis, u, _ = solutions["NEM"]


# --------------------------------------------------------------------------
# the paper's Figs 3-4: one node's natural-neighbour function in 3D
# --------------------------------------------------------------------------

fig_mesh = delaunay_mesh(cube_nodes(FIG_NODES))


def node_function(node=None, k=33, mesh=fig_mesh):
    """One node's natural-neighbour function on a k x k x k grid over the box
    around its support (default: the node of ``mesh`` nearest the centre).
    Returns (node, grid points (k, k, k, 3), phi (k, k, k), grad (k, k, k, 3))."""
    P = mesh.p.T
    if node is None:
        node = int(np.argmin(np.linalg.norm(P - 0.5, axis=1)))
    # the support: the union of the circumspheres of the node's tetrahedra
    tets = P[mesh.t[:, np.any(mesh.t == node, axis=0)].T]          # (k, 4, 3)
    A = 2 * (tets[:, 1:] - tets[:, :1])
    rhs = (tets[:, 1:] ** 2).sum(-1) - (tets[:, :1] ** 2).sum(-1)
    c = np.linalg.solve(A, rhs[..., None])[..., 0]
    r = np.linalg.norm(c - tets[:, 0], axis=1)
    lo = np.clip((c - r[:, None]).min(0), 0, 1)
    hi = np.clip((c + r[:, None]).max(0), 0, 1)
    axes = [np.linspace(lo[d], hi[d], k) for d in range(3)]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    Phi, D = sibson_coordinates(P, X.reshape(-1, 3), gradient=True, undefined="nan")
    phi = Phi[:, node].toarray().reshape(k, k, k)
    g = np.stack([Dk[:, node].toarray().ravel() for Dk in D], axis=-1).reshape(k, k, k, 3)
    return node, X, phi, g


def node_slice(node, axis, k=121, mesh=fig_mesh, X=None):
    """The node's function on the plane through it normal to ``axis``, over the
    window of the grid X from :func:`node_function`: (extent, values (k, k))."""
    P = mesh.p.T
    lo, hi = X.reshape(-1, 3).min(0), X.reshape(-1, 3).max(0)
    a, b = [d for d in range(3) if d != axis]
    u, v = np.meshgrid(np.linspace(lo[a], hi[a], k), np.linspace(lo[b], hi[b], k))
    x = np.zeros((u.size, 3))
    x[:, a], x[:, b], x[:, axis] = u.ravel(), v.ravel(), P[node, axis]
    vals = sibson_coordinates(P, x)[:, node].toarray().reshape(k, k)
    return (lo[a], hi[a], lo[b], hi[b]), vals


def write_vtu(path, X, phi, g):
    """The grid as hexahedra with point data phi and grad phi (meshio VTU)."""
    import meshio
    k = X.shape[0]
    idx = np.arange(k ** 3).reshape(k, k, k)
    c = idx[:-1, :-1, :-1].ravel()
    o = [0, k * k, k * k + k, k, 1, k * k + 1, k * k + k + 1, k + 1]
    cells = np.stack([c + d for d in o], axis=1)
    g = np.nan_to_num(g.reshape(-1, 3))
    meshio.write(path, meshio.Mesh(X.reshape(-1, 3), [("hexahedron", cells)],
                                   point_data={"phi": phi.ravel(), "grad_phi": g}))


def visualize(path=FIGURE, k=33):
    """Write the node function (VTU, two PNG slices) and the solution (VTU)
    beside the three methods' errors; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import meshio

    out = Path(path).parent
    out.mkdir(parents=True, exist_ok=True)
    node, X, phi, g = node_function(k=k)
    write_vtu(str(out / "ex06_natural_neighbour_function.vtu"), X, phi, g)
    meshio.write(str(out / "ex06_poisson_3d.vtu"),
                 meshio.Mesh(mesh.p.T, [("tetra", mesh.t.T)],
                             point_data={"u": u, "exact": exact(mesh.p)}))
    p0 = fig_mesh.p[:, node]
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8), constrained_layout=True)
    names = "xyz"
    for a, axis in zip(ax[:2], (2, 0)):
        ext, img = node_slice(node, axis, X=X)
        im = a.imshow(img, origin="lower", extent=ext, cmap="viridis", vmin=0, vmax=1)
        a.contour(np.linspace(ext[0], ext[1], img.shape[1]),
                  np.linspace(ext[2], ext[3], img.shape[0]),
                  img, levels=[0.01, 0.1, 0.3, 0.5, 0.7, 0.9], colors="w", linewidths=0.6)
        a.plot(p0[[d for d in range(3) if d != axis][0]], p0[[d for d in range(3) if d != axis][1]],
               "r+")
        lab = [names[d] for d in range(3) if d != axis]
        a.set_xlabel(lab[0])
        a.set_ylabel(lab[1])
        a.set_title(f"natural-neighbour function of node {node} ({fig_mesh.nvertices} nodes),\n"
                    f"plane {names[axis]} = {p0[axis]:.3f} through the node")
        fig.colorbar(im, ax=a)
    x = np.arange(len(METHODS))
    for j, (norm, lab) in enumerate((("l2", "L2"), ("h1", "H1 seminorm"))):
        ax[2].bar(x + 0.4 * j - 0.2, [results[m][norm] for m in METHODS], 0.4, label=lab)
    ax[2].set_xticks(x, [f"{m}\n{results[m]['dofs']} dofs" for m in METHODS])
    ax[2].set_yscale("log")
    ax[2].set_title(f"unit cube, {mesh.nvertices} nodes: errors")
    ax[2].legend(fontsize=8)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    print("| method | dofs | L2 error | H1 error | seconds |\n|---|---|---|---|---|")
    for m, r in results.items():
        print(f"| {m} | {r['dofs']} | {r['l2']:.3e} | {r['h1']:.3e} | {r['seconds']:.2f} |")
    visualize()
    print("figure written to", FIGURE)
