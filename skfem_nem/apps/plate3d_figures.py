"""Figures of a 3D sinking-plate run: slices through the plate at the start and now, the
plastic strain in slices and on the slab's surface, and the diagnostics over time.

A slice is the material the nodes carry (upper fluid, lower fluid, plate) interpolated
by Sibson's coordinates on a grid in a plane: the vertical plane y = plate_y and the
horizontal plane through the plate's current centre. The start is drawn from the nodes'
initial positions (a node field), so no earlier state needs to be kept. The plastic strain
lives at the vertex cells of the tetrahedra; it is drawn from its volume-weighted mean at
the nodes (``LagrangianMesh3D.ip_at_nodes``), in the plate only.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..coordinates import sibson_coordinates
from ..geometry.delaunay_nd import delaunay_of
from .output import read_csv_columns
from .plate3d_config import plate_box

__all__ = ["plate3d_figures", "slice_grid", "slice_material", "slice_plastic_strain",
           "level_surface", "plate_surface", "plastic_slices"]

#: grid points along the longer side of a slice
SLICE_RESOLUTION = 240
#: horizontal slices of the plan view of the plastic strain, and their grid points along x
PLAN_LEVELS = 16
PLAN_RESOLUTION = 160
#: colours of upper fluid, lower fluid and plate
COLOURS = ("#c6dbef", "#6baed6", "#b2182b")


def slice_grid(plane, level, box, n=SLICE_RESOLUTION):
    """Grid points in the plane ``plane`` ("xz": y = level; "xy": z = level) through the
    box ``(width, depth, height)``: ``(points (rows * columns, 3), (rows, columns),
    extent)``."""
    w, d, h = box
    (a, b), fixed = ((w, h), 1) if plane == "xz" else ((w, d), 2)
    na, nb = n, max(2, int(round(n * b / a)))
    A, B = np.meshgrid(np.linspace(0, a, na), np.linspace(0, b, nb))
    pts = np.empty((A.size, 3))
    free = [k for k in range(3) if k != fixed]
    pts[:, free[0]], pts[:, free[1]] = A.ravel(), B.ravel()
    pts[:, fixed] = level
    return pts, A.shape, (0.0, a, 0.0, b)


def slice_material(nodes, plate, start_z, interface_z, plane, level, box, n=SLICE_RESOLUTION):
    """The material (0 upper fluid, 1 lower fluid, 2 plate) on a grid in a plane
    (:func:`slice_grid`): ``(image (rows, columns), extent)``. Sibson interpolation of
    the nodes' plate indicator and initial height; plate where the indicator exceeds
    1/2. ``nodes``: (n, 3), or their Delaunay tetrahedralisation (``delaunay_of``), which
    several slices of one node set then share."""
    pts, shape, extent = slice_grid(plane, level, box, n)
    Phi = sibson_coordinates(nodes, pts)
    s = (Phi @ plate).reshape(shape)
    z0 = (Phi @ start_z).reshape(shape)
    return np.where(s > 0.5, 2.0, (z0 <= interface_z) * 1.0), extent


def slice_plastic_strain(nodes, plate, strain, plane, level, box, n=SLICE_RESOLUTION):
    """The nodes' plastic strain on a grid in a plane (:func:`slice_grid`), NaN outside
    the plate (interpolated indicator below 1/2): ``(image, extent)``. ``nodes`` as in
    :func:`slice_material`."""
    pts, shape, extent = slice_grid(plane, level, box, n)
    Phi = sibson_coordinates(nodes, pts)
    s = (Phi @ plate).reshape(shape)
    return np.where(s > 0.5, (Phi @ strain).reshape(shape), np.nan), extent


def level_surface(points, tets, s, level, values):
    """The surface ``s = level`` of a field linear on tetrahedra (marching tetrahedra):
    ``(triangles (k, 3, 3), on (k,))``, the triangles' corners and ``values`` (nodal)
    averaged over each triangle's corners, all interpolated linearly along the edges that
    the surface cuts. A tetrahedron with one node on the far side of the level gives a
    triangle, with two a quadrilateral (two triangles)."""
    above = s[tets] > level                                   # (m, 4)
    k = above.sum(axis=1)
    order = np.argsort(~above, axis=1, kind="stable")         # the nodes above first
    t = np.take_along_axis(tets, order, axis=1)
    out_p, out_v = [], []
    for count, polygon in ((1, ((0, 1), (0, 2), (0, 3))), (3, ((3, 0), (3, 1), (3, 2))),
                           (2, ((0, 2), (0, 3), (1, 3), (1, 2)))):
        tt = t[k == count]
        a, b = tt[:, [e[0] for e in polygon]], tt[:, [e[1] for e in polygon]]
        w = ((level - s[a]) / (s[b] - s[a]))[..., None]       # (m', corners, 1)
        corners = points[a] + w * (points[b] - points[a])
        v = values[a] + w[..., 0] * (values[b] - values[a])
        for tri in ((0, 1, 2),) if len(polygon) == 3 else ((0, 1, 2), (0, 2, 3)):
            out_p.append(corners[:, tri])
            out_v.append(v[:, tri].mean(axis=1))
    return np.concatenate(out_p), np.concatenate(out_v)


def plate_surface(sim):
    """The slab's surface now, where the nodes' plate indicator interpolated linearly
    crosses 1/2 (the plate of the slices), and the nodes' plastic strain on it:
    ``(triangles (k, 3, 3), plastic strain (k,))`` (:func:`level_surface`)."""
    lm = sim.lm
    return level_surface(lm.nodes, lm.mesh.t.T, lm.node_fields["plate"], 0.5,
                         lm.ip_at_nodes("plastic_strain"))


def plate3d_figures(sim) -> list:
    """slices.png and diagnostics.png (if the run has diagnostics) in ``sim.out``;
    returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    paths = [_slices_figure(sim), _plastic_figure(sim)]
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
    # the start: the nodes drawn then (nodes added later come last; their interpolated
    # start positions are no node set of their own, and lie off the walls by round-off)
    n0 = sim.lm.nodes.shape[0] - sum(h.get("injected", 0) for h in sim.lm.history)
    out = []
    for t, keep, nodes in ((0.0, slice(0, n0), f["start"][:n0]),
                           (sim.lm.time, slice(None), sim.lm.nodes)):
        plate, start_z = f["plate"][keep], f["start"][keep, 2]
        zc = float(nodes[plate > 0.5, 2].mean()) if (plate > 0.5).any() else c.plate_z
        tri = delaunay_of(nodes)            # one tetrahedralisation for both slices
        for plane, level, label in (("xz", c.plate_y, f"y = {c.plate_y:g}"),
                                    ("xy", zc, f"z = {zc:.3f}")):
            image, extent = slice_material(tri, plate, start_z, c.interface_z, plane,
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


def plastic_slices(sim, levels=PLAN_LEVELS):
    """The plastic strain now: in the vertical slice y = plate_y, and in plan view the
    largest value through the plate (over ``levels`` horizontal slices from the lowest to
    the highest plate node), ``[(title, plane, image, extent)]``."""
    c, lm = sim.cfg, sim.lm
    plate, box = lm.node_fields["plate"], (c.width, c.depth, c.height)
    strain = lm.ip_at_nodes("plastic_strain")
    # one tetrahedralisation of the nodes for all the slices (a build each took 0.6 s of
    # the figures at 98,601 nodes, 17 times)
    tri = delaunay_of(lm.nodes)
    image, extent = slice_plastic_strain(tri, plate, strain, "xz", c.plate_y, box)
    out = [(f"plastic strain, t = {lm.time:.4g}, y = {c.plate_y:g}", "xz", image, extent)]
    z = lm.nodes[plate > 0.5, 2] if (plate > 0.5).any() else np.array([c.plate_z])
    plan = [slice_plastic_strain(tri, plate, strain, "xy", level, box,
                                 n=PLAN_RESOLUTION)[0]
            for level in np.linspace(z.min(), z.max(), levels)]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # all-NaN columns: no plate
        top = np.nanmax(np.stack(plan), axis=0)
    out.append((f"largest through the plate, t = {lm.time:.4g} (plan view)", "xy", top,
                (0.0, c.width, 0.0, c.depth)))
    return out


def _plastic_figure(sim):
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    c = sim.cfg
    panels = plastic_slices(sim)
    triangles, values = plate_surface(sim)
    top = max(float(np.nanmax([np.nanmax(p[2]) if np.isfinite(p[2]).any() else 0.0
                               for p in panels])), float(values.max(initial=0.0)), 1e-12)
    fig = plt.figure(figsize=(13, 8), constrained_layout=True)
    grid = fig.add_gridspec(2, 2, height_ratios=[1, 1.4])
    lo, hi = plate_box(c)
    pad = 4 * c.plate_thickness
    for k, (title, plane, image, extent) in enumerate(panels):
        a = fig.add_subplot(grid[0, k])
        im = a.imshow(image, origin="lower", extent=extent, cmap="magma_r", vmin=0, vmax=top,
                      interpolation="nearest")
        a.set(title=title, xlabel="x", ylabel="z" if plane == "xz" else "y", aspect="equal",
              xlim=(lo[0] - pad, hi[0] + pad))
        if plane == "xz":
            a.set_ylim(0, c.height)
        else:
            a.set_ylim(lo[1] - pad, hi[1] + pad)
    fig.colorbar(im, ax=fig.axes, shrink=0.6, label="plastic strain")
    ax = fig.add_subplot(grid[1, :], projection="3d")
    cmap = plt.get_cmap("magma_r")
    ax.add_collection3d(Poly3DCollection(triangles, facecolors=cmap(values / top),
                                         edgecolor="none"))
    used = triangles.reshape(-1, 3) if triangles.size else sim.lm.nodes
    ax.set(xlim=(used[:, 0].min(), used[:, 0].max()), ylim=(used[:, 1].min(), used[:, 1].max()),
           zlim=(used[:, 2].min(), used[:, 2].max()), xlabel="x", ylabel="y", zlabel="z",
           title="the slab's surface, coloured by plastic strain")
    ax.set_box_aspect(np.ptp(used, axis=0) * [1, 1, 2])
    ax.view_init(elev=40, azim=-60)
    fig.suptitle(f"3D sinking plate: plastic strain at step {sim.lm.step}")
    p = sim.out / "plastic_strain.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    return p


def _diagnostics_figure(d, path):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 4, figsize=(16, 3.6), constrained_layout=True)
    ax[0].plot(d["time"], d["plate_depth"], "o-", ms=3)
    ax[0].set(xlabel="time", ylabel="mean sinking of the plate's nodes", title="plate depth")
    ax[1].plot(d["time"], 100 * d["plate_volume_change"], "o-", ms=3)
    ax[1].set(xlabel="time", ylabel="%", title="plate volume change")
    # (a run restarted from a viscous one's checkpoint has no plastic strain before)
    ax[2].plot(d["time"], d.get("max_plastic_strain", np.zeros_like(d["time"])), "o-", ms=3)
    ax[2].set(xlabel="time", ylabel="largest plastic strain", title="plastic strain")
    ax[3].plot(d["time"], d["seconds"], "o-", ms=3, label="step")
    ax[3].set(xlabel="time", ylabel="seconds", title="wall time per step")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
