"""The sinking plate's figures: the mesh coloured by the nodes' initial depth (the
paper's Fig. 6) at the first output and at the end, the plate's plastic strain and
stress at the end, and the diagnostics over time. Drawn from a run's state
(:class:`~skfem_nem.apps.sinking_plate.SinkingPlate`) and its files, so a stopped or
restarted run draws the same pictures."""
from __future__ import annotations

import numpy as np

from ..models.rheology import from_ip_field, second_invariant
from .output import read_csv_columns

__all__ = ["plate_figures"]


def plate_figures(sim) -> list:
    """fig6.png, plate_strain.png and diagnostics.png (if the run has diagnostics) in
    ``sim.out``; returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    paths = [_mesh_figure(sim), _strain_figure(sim)]
    d = read_csv_columns(sim.out / "diagnostics.csv") \
        if (sim.out / "diagnostics.csv").exists() else None
    if d and len(d["time"]):
        paths.append(_diagnostics_figure(d, sim.out / "diagnostics.png"))
    return paths


def _outline(a, polys, style, lw):
    for poly in polys:
        a.plot(np.r_[poly[:, 0], poly[:1, 0]], np.r_[poly[:, 1], poly[:1, 1]], style, lw=lw)


def _mesh_figure(sim):
    """fig6.png: the mesh coloured by the initial depth, at the first output and now."""
    import matplotlib.pyplot as plt
    c, lm = sim.cfg, sim.lm
    panels = []
    f0 = sim.out / "first_output.npz"
    if f0.exists():
        d = np.load(f0)
        panels.append((d["nodes"], d["triangles"], d["depth"], float(d["time"])))
    panels.append((lm.nodes, lm.triangles, c.height - lm.node_fields["z0"], lm.time))
    fig, ax = plt.subplots(len(panels), 1, figsize=(12, 2.2 * len(panels) + 0.6),
                           squeeze=False)
    for a, (P, T, depth, t) in zip(ax[:, 0], panels):
        tp = a.tripcolor(P[:, 0], P[:, 1], T, depth, shading="gouraud", cmap="viridis_r")
        a.triplot(P[:, 0], P[:, 1], T, lw=0.15, color="k", alpha=0.5)
        a.set_aspect("equal")
        a.set_xlim(0, c.width)
        a.set_ylim(0, c.height)
        a.set_title(f"t = {t:.4g}: mesh coloured by the nodes' initial depth")
        fig.colorbar(tp, ax=a, fraction=0.02, pad=0.01, label="initial depth")
    _outline(ax[-1, 0], sim.outlines.polygons(lm.nodes), "r-", 0.8)
    fig.tight_layout()
    p = sim.out / "fig6.png"
    fig.savefig(p, dpi=150)
    plt.close(fig)
    return p


def _strain_figure(sim):
    """plate_strain.png: the plate's accumulated plastic strain and stress invariant
    (over the yield stress) now, every piece."""
    import matplotlib.pyplot as plt
    c, lm = sim.cfg, sim.lm
    P, T = lm.nodes, lm.triangles
    polys = sim.outlines.polygons(P)
    inplate = sim.outlines.inside(P, P[T].mean(axis=1))
    lo = np.min([q.min(axis=0) for q in polys], axis=0)
    hi = np.max([q.max(axis=0) for q in polys], axis=0)
    pad = 0.3 * (hi - lo).max()
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5))
    S = lm.ip_fields["stress"]
    vals = [(lm.ip_fields["plastic_strain"].mean(axis=1), "accumulated plastic strain",
             "magma_r"),
            (second_invariant(from_ip_field(S)).mean(axis=1) / c.yield_stress,
             "stress invariant / yield stress", "viridis")]
    for a, (v, lab, cmap) in zip(ax, vals):
        tp = a.tripcolor(P[:, 0], P[:, 1], T[inplate], facecolors=v[inplate], cmap=cmap)
        _outline(a, polys, "k-", 0.5)
        a.set_xlim(lo[0] - pad, hi[0] + pad)
        a.set_ylim(lo[1] - pad / 3, hi[1] + pad / 3)
        a.set_aspect("equal")
        a.set_title(f"t = {lm.time:.4g}: {lab}")
        fig.colorbar(tp, ax=a, fraction=0.03, pad=0.01)
    fig.tight_layout()
    p = sim.out / "plate_strain.png"
    fig.savefig(p, dpi=150)
    plt.close(fig)
    return p


def _diagnostics_figure(d, p):
    """diagnostics.png: six diagnostics over time."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(2, 3, figsize=(13, 6))
    keys = [("plate_depth", "plate centroid depth"),
            ("plate_area", "plate area"), ("max_plastic_strain", "max plastic strain"),
            ("flips", "flips per step"), ("nodes", "nodes (injection)"),
            ("min_angle", "minimum angle (deg)")]
    for a, (k, lab) in zip(ax.ravel(), keys):
        a.plot(d["time"], d[k], "-")
        a.set_xlabel("t")
        a.set_title(lab)
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p
