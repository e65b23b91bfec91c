"""Natural-neighbour interpolation of scattered data.

Samples of a smooth function at scattered nodes in the unit square are
interpolated on a regular grid with Sibson and Laplace natural-neighbour
coordinates and, for comparison, with piecewise-linear interpolation on the
same Delaunay triangles (``scipy.interpolate.griddata(method="linear")``).
All three are second-order accurate and reproduce linear functions exactly;
the natural-neighbour interpolants are smooth (Sibson's is C1 away from the
nodes: compare the kinked contours of the linear interpolant), so their
gradients are meaningful everywhere -- the script checks Sibson's against the
exact gradient.
"""
from pathlib import Path

import numpy as np
from scipy.interpolate import griddata

from skfem_nem import Triangulation, laplace_coordinates, sibson_coordinates


def f(x, y):
    return np.sin(3 * x) * np.cos(2 * y) + 0.5 * x * y


def grad_f(x, y):
    return (3 * np.cos(3 * x) * np.cos(2 * y) + 0.5 * y,
            -2 * np.sin(3 * x) * np.sin(2 * y) + 0.5 * x)


rng = np.random.default_rng(42)
# random interior samples plus samples along the sides of the square (the
# interpolants are linear along convex-hull edges, so the sides need nodes too)
s = np.sort(rng.random(24))
boundary = np.r_[np.c_[s, 0 * s], np.c_[1 - s, 1 + 0 * s], np.c_[0 * s, 1 - s],
                 np.c_[1 + 0 * s, s], [[0, 0], [1, 0], [1, 1], [0, 1]]]
nodes = np.r_[boundary, rng.random((400, 2))]
values = f(*nodes.T)

tri = Triangulation(nodes)
gx, gy = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
grid = np.c_[gx.ravel(), gy.ravel()]
exact = f(*grid.T)

# interior grid points (the gradient is not defined on the hull or at nodes)
inner = np.all((grid > 0) & (grid < 1), axis=1)
Phi, (Dx, Dy) = sibson_coordinates(tri, grid, gradient=True, undefined="nan")
sibson = Phi @ values
laplace = laplace_coordinates(tri, grid) @ values
linear = griddata(nodes, values, grid, method="linear")

errors = {
    "sibson": np.abs(sibson - exact).max(),
    "laplace": np.abs(laplace - exact).max(),
    "linear": np.abs(linear - exact).max(),
}
rms = {
    "sibson": np.sqrt(np.mean((sibson - exact) ** 2)),
    "laplace": np.sqrt(np.mean((laplace - exact) ** 2)),
    "linear": np.sqrt(np.mean((linear - exact) ** 2)),
}
ex, ey = grad_f(*grid[inner].T)
grad_error = np.hypot((Dx @ values)[inner] - ex, (Dy @ values)[inner] - ey).max()


FIGURE = "out/ex01_interpolation.png"


def visualize(path=FIGURE):
    """Draw the triangulation and the three interpolants' errors; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(10, 9.5), constrained_layout=True)
    ax[0, 0].triplot(nodes[:, 0], nodes[:, 1], tri.triangles, lw=0.4, color="k")
    ax[0, 0].plot(nodes[:, 0], nodes[:, 1], ".", ms=3, color="C3")
    ax[0, 0].set_title(f"Delaunay triangulation of {len(nodes)} scattered nodes")
    fields = [("sibson", sibson), ("laplace", laplace), ("linear", linear)]
    for a, (name, field) in zip([ax[0, 1], ax[1, 0], ax[1, 1]], fields):
        im = a.imshow((field - exact).reshape(gx.shape), origin="lower",
                      extent=(0, 1, 0, 1), cmap="RdBu_r", vmin=-0.02, vmax=0.02)
        a.contour(gx, gy, field.reshape(gx.shape), levels=12, colors="k", linewidths=0.5)
        a.set_title(f"{name}: contours of the interpolant,\ncolour = error "
                    f"(max {errors[name]:.2e}, rms {rms[name]:.2e})")
    fig.colorbar(im, ax=ax[1, :], shrink=0.6, label="interpolant - exact")
    for a in ax.ravel():
        a.set_aspect("equal")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for name in errors:
        print(f"{name:8s} max error {errors[name]:.3e}   rms error {rms[name]:.3e}")
    print(f"Sibson gradient max error (interior grid points) {grad_error:.3e}")
    visualize()
    print("figure written to", FIGURE)
