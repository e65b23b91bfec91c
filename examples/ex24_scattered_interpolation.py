"""Scattered-data interpolation of Franke's function, method by method.

Franke's test function, sampled at 800 random points of the unit square (and along its
sides, so that the hull is the square), is interpolated on a 201 x 201 grid with
``NaturalNeighbourInterpolator``: Sibson's and Laplace's natural-neighbour interpolants,
Sibson's and Farin's C1 interpolants (``"sibson1"``, ``"farin"``, from gradients estimated at
the data points) and piecewise-linear interpolation on the same Delaunay triangles; scipy's
Clough-Tocher interpolant (C1, cubic on each triangle) for comparison. The C1 interpolants
are the most accurate here; the linear one shows its kinks along the triangle edges in the
contours.
The exact gradients of the interpolants (``itp.gradient``) are compared with Franke's.
"""
from pathlib import Path

import numpy as np
from scipy.interpolate import CloughTocher2DInterpolator

from skfem_nem import NaturalNeighbourInterpolator, Triangulation


def franke(x, y):
    return (0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
            + 0.75 * np.exp(-(9 * x + 1) ** 2 / 49 - (9 * y + 1) / 10)
            + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
            - 0.2 * np.exp(-(9 * x - 4) ** 2 - (9 * y - 7) ** 2))


def franke_gradient(x, y, h=1e-6):
    """Franke's gradient by central differences of the closed form (accurate to ~1e-10)."""
    return np.stack([(franke(x + h, y) - franke(x - h, y)) / (2 * h),
                     (franke(x, y + h) - franke(x, y - h)) / (2 * h)], axis=-1)


rng = np.random.default_rng(7)
s = np.sort(rng.random(30))
sides = np.r_[np.c_[s, 0 * s], np.c_[1 - s, 1 + 0 * s], np.c_[0 * s, 1 - s],
              np.c_[1 + 0 * s, s], [[0, 0], [1, 0], [1, 1], [0, 1]]]
points = np.r_[sides, rng.random((800, 2))]
values = franke(*points.T)
tri = Triangulation(points)                     # built once, shared by the methods

gx, gy = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
exact = franke(gx, gy)
METHODS = ["sibson", "laplace", "sibson1", "farin", "linear"]
fields, interpolants = {}, {}
for method in METHODS:
    interpolants[method] = NaturalNeighbourInterpolator(tri, values, method=method)
    fields[method] = interpolants[method](gx, gy)
fields["Clough-Tocher (scipy)"] = CloughTocher2DInterpolator(points, values)(gx, gy)

errors = {k: np.abs(v - exact).max() for k, v in fields.items()}
rms = {k: np.sqrt(np.mean((v - exact) ** 2)) for k, v in fields.items()}

# gradients at interior grid points (Sibson's is undefined at the data points, NaN there)
inner = (gx > 0.02) & (gx < 0.98) & (gy > 0.02) & (gy < 0.98)
exact_grad = franke_gradient(gx[inner], gy[inner])
grad_rms = {}
for method in METHODS:
    g = interpolants[method].gradient(gx[inner], gy[inner])
    ok = np.isfinite(g).all(axis=-1)
    grad_rms[method] = np.sqrt(np.mean(np.sum((g - exact_grad)[ok] ** 2, axis=-1)))


FIGURE = "out/ex24_scattered_interpolation.png"


def visualize(path=FIGURE):
    """The data points and each interpolant's error on the grid; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 4, figsize=(17, 9), constrained_layout=True)
    ax[0, 0].contourf(gx, gy, exact, levels=20, cmap="viridis")
    ax[0, 0].plot(points[:, 0], points[:, 1], ".", ms=2, color="w")
    ax[0, 0].set_title(f"Franke's function\nand the {len(points)} data points")
    for a, (name, field) in zip(ax.ravel()[1:], fields.items()):
        im = a.imshow(field - exact, origin="lower", extent=(0, 1, 0, 1), cmap="RdBu_r",
                      vmin=-0.02, vmax=0.02)
        a.contour(gx, gy, field, levels=12, colors="k", linewidths=0.4)
        a.set_title(f"{name}\nerror max {errors[name]:.1e}, rms {rms[name]:.1e}")
    fig.colorbar(im, ax=ax[:, 3], shrink=0.6, label="interpolant - exact")
    for a in ax.ravel():
        a.set_aspect("equal")
    ax[1, 3].set_axis_off()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for name in fields:
        grad = f"   gradient rms {grad_rms[name]:.3e}" if name in grad_rms else ""
        print(f"{name:22s} max error {errors[name]:.3e}   rms error {rms[name]:.3e}{grad}")
    visualize()
    print("figure written to", FIGURE)
