"""Sharp interfaces and a notch: constrained natural neighbours.

Two problems on random nodes. Left: heat conduction through two materials,
k = 1 for x < 1/2 and k = 10 beyond, u = 0 on the left wall and u = 1 on
the right one; the exact solution is linear on each side, its slope drops
tenfold at the interface. Sibson functions are smooth across every
edge, so plain NEM rounds the kink off; with the interface nodes joined as
segments (``delaunay_mesh(points, segments=...)``) the natural neighbours
of a point are the nodes it sees without crossing the interface, the
functions kink there, and the solution is exact to round-off. Right: an
L-shaped domain whose outline is given as segments and whose notch is a
hole; the natural neighbours of a point near the re-entrant corner are no
longer taken across the notch.

``visualize()`` draws the error of both solutions along the line y = 1/2,
and the natural neighbours of a point near the L's corner with and without
the outline as segments.
"""
from pathlib import Path

import numpy as np
from skfem import BilinearForm, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, Triangulation, delaunay_mesh
from skfem_nem import natural_neighbour_coordinates
from skfem_nem.geometry.nodesets import box_nodes

K_RIGHT = 10.0
SLOPE = 1.0 / (0.5 + 0.5 / K_RIGHT)     # the flux k u' is the same on both sides


def exact(x):
    return np.where(x < 0.5, SLOPE * x, SLOPE * (0.5 + (x - 0.5) / K_RIGHT))


nodes = box_nodes(400, seed=4)
nodes = nodes[np.abs(nodes[:, 0] - 0.5) > 0.01]
line = np.c_[np.full(21, 0.5), np.linspace(0, 1, 21)]
points = np.r_[line, nodes]
interface = np.c_[np.arange(20), np.arange(1, 21)]


@BilinearForm
def conduction(u, v, w):
    return np.where(w.x[0] < 0.5, 1.0, K_RIGHT) * dot(grad(u), grad(v))


def solve_layers(mesh):
    basis = NaturalNeighbourBasis(mesh)
    walls = basis.get_dofs(lambda x: (x[0] == 0) | (x[0] == 1)).all()
    A = conduction.assemble(basis)
    u = solve(*condense(A, np.zeros(basis.N), x=exact(mesh.p[0]), D=walls))
    return basis, u


meshes = {"constrained": delaunay_mesh(points, segments={"interface": interface}),
          "plain": delaunay_mesh(points)}
solutions = {name: solve_layers(m) for name, m in meshes.items()}
nodal_error = {name: np.abs(u - exact(meshes[name].p[0])).max()
               for name, (_, u) in solutions.items()}

# the L-shape: outline as segments, the notch as a hole
L_corners = np.array([[0, 0], [1, 0], [1, .5], [.5, .5], [.5, 1], [0, 1]], float)
rng = np.random.default_rng(1)
inner = rng.random((300, 2))
inner = inner[~((inner[:, 0] > .47) & (inner[:, 1] > .47)) & (inner.min(1) > .03)
              & (inner.max(1) < .97)]
edge = [a + (b - a) * s for a, b in zip(L_corners, np.roll(L_corners, -1, 0))
        for s in np.arange(8)[:, None] / 8]
L_points = np.r_[np.array(edge), inner]
L_outline = np.c_[np.arange(48), (np.arange(48) + 1) % 48]
L_mesh = delaunay_mesh(L_points, segments={"outline": L_outline}, holes=[[.75, .75]])
probe = np.array([[0.49, 0.53]])
neighbours = {
    "outline as segments": natural_neighbour_coordinates(
        Triangulation(L_points, segments=L_outline), probe).indices,
    "plain": natural_neighbour_coordinates(Triangulation(L_points), probe).indices}

FIGURE = "out/ex13_interfaces.png"


def visualize(path=FIGURE):
    """Draw the errors along y = 1/2 and the natural neighbours near the L's
    corner; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    x = np.linspace(0, 1, 401)
    for name, (basis, u) in solutions.items():
        v = basis.probes(np.c_[x, np.full_like(x, 0.5)].T) @ u
        ax[0].plot(x, v - exact(x), "-", lw=1.2,
                   label=f"{name} NEM (largest nodal error {nodal_error[name]:.1e})")
    ax[0].axvline(0.5, color="0.6", ls=":")
    ax[0].set(xlabel="x (y = 1/2)", ylabel="u_h - u",
              title="k = 1 | k = 10 across x = 1/2: error of the solution")
    ax[0].legend(fontsize=8)
    a = ax[1]
    a.triplot(L_points[:, 0], L_points[:, 1], L_mesh.t.T, lw=0.4, color="0.7")
    a.plot(*L_corners[[*range(6), 0]].T, "k-", lw=1.5)
    for (name, idx), style in zip(neighbours.items(), ("o", "x")):
        a.plot(*L_points[idx].T, style, ms=9 if style == "o" else 7, mfc="none",
               label=f"natural neighbours, {name}")
    a.plot(*probe.T, "r*", ms=12, label="query point")
    a.set(xlim=(0.3, 0.75), ylim=(0.3, 0.75), aspect="equal",
          title="near the L's corner: the notch stops the natural neighbours")
    a.legend(fontsize=8, loc="upper right")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for name, err in nodal_error.items():
        print(f"{name}: largest nodal error {err:.2e}")
    visualize()
    print("figure written to", FIGURE)
