"""Figures of a 3D sinking-plate run: slices through the plate at the start and now, and
the diagnostics over time.

A slice is the material the nodes carry (upper fluid, lower fluid, plate) interpolated
by Sibson's coordinates on a grid in a plane: the vertical plane y = plate_y and the
horizontal plane through the plate's current centre. The start is drawn from the nodes'
initial positions (a node field), so no earlier state needs to be kept.
"""
from __future__ import annotations

import numpy as np

from ..coordinates import sibson_coordinates
from .output import read_csv_columns

__all__ = ["plate3d_figures", "slice_material"]

#: grid points along the longer side of a slice
SLICE_RESOLUTION = 240
#: colours of upper fluid, lower fluid and plate
COLOURS = ("#c6dbef", "#6baed6", "#b2182b")


def slice_material(nodes, plate, start_z, interface_z, plane, level, box, n=SLICE_RESOLUTION):
    """The material (0 upper fluid, 1 lower fluid, 2 plate) on a grid in the plane
    ``plane`` ("xz": y = level; "xy": z = level) through the box ``(width, depth,
    height)``: ``(image (rows, columns), extent)``. Sibson interpolation of the nodes'
    plate indicator and initial height; plate where the indicator exceeds 1/2."""
    w, d, h = box
    (a, b), fixed = ((w, h), 1) if plane == "xz" else ((w, d), 2)
    na, nb = n, max(2, int(round(n * b / a)))
    A, B = np.meshgrid(np.linspace(0, a, na), np.linspace(0, b, nb))
    pts = np.empty((A.size, 3))
    free = [k for k in range(3) if k != fixed]
    pts[:, free[0]], pts[:, free[1]] = A.ravel(), B.ravel()
    pts[:, fixed] = level
    Phi = sibson_coordinates(nodes, pts)
    s = (Phi @ plate).reshape(A.shape)
    z0 = (Phi @ start_z).reshape(A.shape)
    image = np.where(s > 0.5, 2.0, (z0 <= interface_z) * 1.0)
    return image, (0.0, a, 0.0, b)


def plate3d_figures(sim) -> list:
    """slices.png and diagnostics.png (if the run has diagnostics) in ``sim.out``;
    returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    paths = [_slices_figure(sim)]
    log = sim.out / "diagnostics.csv"
    d = read_csv_columns(log) if log.exists() else None
    if d and len(d["time"]):
        paths.append(_diagnostics_figure(d, sim.out / "diagnostics.png"))
    return paths


def slices(sim):
    """The four slices of the figure: ``[(title, plane, image, extent)]`` for the start
    and now, each vertical (y = plate_y) and horizontal (through the plate's centre)."""
    c, f = sim.cfg, sim.lm.node_fields
    box = (c.width, c.depth, c.height)
    plate, start = f["plate"], f["start"]
    out = []
    for when, nodes, t in (("start", start, 0.0), ("now", sim.lm.nodes, sim.lm.time)):
        zc = float(nodes[plate > 0.5, 2].mean()) if (plate > 0.5).any() else c.plate_z
        for plane, level, label in (("xz", c.plate_y, f"y = {c.plate_y:g}"),
                                    ("xy", zc, f"z = {zc:.3f}")):
            image, extent = slice_material(nodes, plate, start[:, 2], c.interface_z, plane,
                                           level, box)
            out.append((f"t = {t:.4g}, {label}", plane, image, extent))
    return out


def _slices_figure(sim):
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    panels = slices(sim)
    fig, ax = plt.subplots(2, 2, figsize=(12, 6.5), constrained_layout=True,
                           gridspec_kw={"width_ratios": [1, 1]})
    cmap = ListedColormap(COLOURS)
    for a, (title, plane, image, extent) in zip(ax.T.ravel(), panels):
        a.imshow(image, origin="lower", extent=extent, cmap=cmap, vmin=0, vmax=2,
                 interpolation="nearest")
        a.set(title=title, xlabel="x", ylabel="z" if plane == "xz" else "y", aspect="equal")
    fig.legend(handles=[Patch(color=col, label=lab) for col, lab in
                        zip(COLOURS, ("upper fluid", "lower fluid", "plate"))],
               loc="outside lower center", ncol=3)
    fig.suptitle(f"3D sinking plate: {sim.lm.nodes.shape[0]:,} nodes, step {sim.lm.step}")
    p = sim.out / "slices.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    return p


def _diagnostics_figure(d, path):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    ax[0].plot(d["time"], d["plate_depth"], "o-", ms=3)
    ax[0].set(xlabel="time", ylabel="mean sinking of the plate's nodes", title="plate depth")
    ax[1].plot(d["time"], 100 * d["plate_volume_change"], "o-", ms=3)
    ax[1].set(xlabel="time", ylabel="%", title="plate volume change")
    ax[2].plot(d["time"], d["seconds"], "o-", ms=3, label="step")
    ax[2].set(xlabel="time", ylabel="seconds", title="wall time per step")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
