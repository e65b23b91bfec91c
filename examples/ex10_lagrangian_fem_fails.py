"""The sinking plate on a classical Lagrangian mesh: P2 FEM that moves but never reconnects.

The same initial nodes, triangles, materials and visco-elasto-plastic solve as
``skfem-nem sinking-plate`` (defaults), but with scikit-fem's Taylor-Hood
elements (P2 velocity, P1 pressure) and a mesh whose nodes move with the
flow while its connectivity stays fixed (the stress stays in its triangles,
so no remap is needed). The run stops when the first triangle inverts.
Reported: that time, the minimum angle of the FEM mesh over time, and the
natural-neighbour mesh's minimum angle at the same time and at the end
(read from a NEM run's ``diagnostics.csv`` when given, else computed here by
running NEM to the same time).

    python examples/ex10_lagrangian_fem_fails.py [NEM_OUTPUT_FOLDER]
"""
import sys
from pathlib import Path

import numpy as np
from skfem import MeshTri

from skfem_nem.apps.output import read_csv_columns
from skfem_nem.models.rheology import vep_step
from skfem_nem.apps.sinking_plate import PlateConfig, SinkingPlate, node_spacing
from skfem_nem.models.stokes import outline_flux, stokes_spaces


def min_angle(P, T):
    """Smallest angle (degrees) and smallest signed area of triangles T."""
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                  - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    ang = []
    for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
        e1, e2 = v - u, w - u
        cos = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
        ang.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return float(np.min(ang)), float(area.min())


def run_fem(cfg=None, out="out/ex10", max_steps=400, verbose=True):
    """Lagrangian Taylor-Hood run; returns a dict of histories and the failure time."""
    cfg = cfg or PlateConfig()
    sim = SinkingPlate(cfg, out)            # the same initial nodes and triangles
    P = sim.lm.nodes.copy()
    T = sim.lm.triangles.copy()
    outline = sim.outline
    ne = T.shape[0]
    tau = np.zeros((2, 2, ne, 3))
    ps = np.zeros((ne, 3))
    t, dt = 0.0, cfg.max_dt
    hist = {"time": [0.0], "min_angle": [min_angle(P, T)[0]], "depth": []}
    failed = None
    for step in range(1, max_steps + 1):
        mesh = MeshTri(np.ascontiguousarray(P.T), np.ascontiguousarray(T.T), sort_t=False)
        sp_ = stokes_spaces(mesh, "taylor-hood", npoints=3)
        # materials from the moving outline, as in the NEM run
        mat, force, plate = sim.materials(sp_, polygon=P[outline])
        r = vep_step(sp_, mat, tau, dt, f=force, plastic_strain=ps, tol=cfg.picard_tol,
                     constraints=outline_flux(sp_, outline))
        tau, ps = r.tau, r.plastic_strain
        nd = sp_.ubasis.dofs.nodal_dofs
        v = np.stack([r.solution.u[nd[0]], r.solution.u[nd[1]]], axis=1)
        on_wall = (P == P.min(0)) | (P == P.max(0))
        v = np.where(on_wall, 0.0, v)
        h = node_spacing(P, T)
        dt_next = min(cfg.max_dt, cfg.cfl * float((h / np.maximum(np.hypot(*v.T), 1e-300)).min()))
        P = P + dt * v
        t += dt
        ang, amin = min_angle(P, T)
        hist["time"].append(t)
        hist["min_angle"].append(ang)
        if verbose:
            print(f"step {step:4d}  t {t:8.2f}  FEM min angle {ang:.4f} deg  "
                  f"smallest area {amin:.2e}", flush=True)
        if amin <= 0:
            failed = t
            break
        dt = dt_next
        if t >= cfg.end_time:
            break
    return {"time": np.array(hist["time"]), "min_angle": np.array(hist["min_angle"]),
            "inverted_at": failed, "mesh": (P, T)}


def nem_min_angle(nem_out, times):
    d = read_csv_columns(Path(nem_out) / "diagnostics.csv")
    return np.interp(times, d["time"], d["min_angle"]), d["time"][-1], d["min_angle"][-1]


FIGURE = "out/ex10_lagrangian_fem_fails.png"


def visualize(fem, nem_out=None, path=FIGURE):
    """Minimum angle over time (FEM, and NEM from its diagnostics in nem_out)
    and the last FEM mesh; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(2, 1, figsize=(12, 6))
    ax[0].semilogy(fem["time"], fem["min_angle"], "s-",
                   label="Lagrangian P2 FEM (fixed connectivity)")
    if nem_out is not None and (Path(nem_out) / "diagnostics.csv").exists():
        d = read_csv_columns(Path(nem_out) / "diagnostics.csv")
        ax[0].semilogy(d["time"], d["min_angle"], "-", label="NEM (Delaunay kept by flips)")
    if fem["inverted_at"] is not None:
        ax[0].axvline(fem["inverted_at"], color="r", lw=0.8, label="first FEM inversion")
    ax[0].set_xlabel("t")
    ax[0].set_ylabel("minimum angle (deg)")
    ax[0].legend()
    P, T = fem["mesh"]
    ax[1].triplot(P[:, 0], P[:, 1], T, lw=0.2)
    ax[1].set_aspect("equal")
    ax[1].set_title(f"FEM mesh at t = {fem['time'][-1]:.4g}")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    nem_out = sys.argv[1] if len(sys.argv) > 1 else None
    fem = run_fem()
    if fem["inverted_at"] is not None:
        print(f"first FEM inversion at t = {fem['inverted_at']:.4g}")
    else:
        print("no FEM inversion within the run")
    if nem_out:
        at, tend, aend = nem_min_angle(nem_out, [fem["time"][-1]])
        print(f"NEM minimum angle at that time: {at[0]:.4f} deg; at t = {tend:.4g}: {aend:.4f} deg")
    visualize(fem, nem_out)
    print("wrote", FIGURE)
