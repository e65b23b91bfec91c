"""The sinking block (Gerya 2010): one Stokes solve over 8 decades of viscosity ratio.

A 512 km box with free slip on all walls; a 128 km square block centred at
(256, 384) km, denser than the fluid by ``drho``; fluid viscosity
``eta1 = 1e21`` Pa s, block viscosity ``eta2`` from ``1e-4 eta1`` to
``1e4 eta1``; g = 10 m/s^2. The scaled sinking velocity at the block centre,
``|v_z| eta1 / drho``, depends on ``eta1 / eta2`` only (a weak block lets
the fluid through, a strong one sinks as a rigid body).

The problem is solved nondimensionally (lengths / L, viscosity / eta1,
force / (drho g)), so the nondimensional velocity ``w`` gives
``|v_z| eta1 / drho = w g L^2``. Natural-neighbour velocity (with bubbles,
P1 pressure) and Taylor-Hood on the same triangles; a Taylor-Hood solution on
about four times as many nodes is the reference. The block's outline carries
nodes joined as segments, so the natural-neighbour velocity may kink across it
(constrained natural neighbours).
"""
from pathlib import Path

import numpy as np

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes, line_segments, polyline_nodes
from skfem_nem.models.stokes import solve_stokes, stokes_spaces

L = 512e3          # m
G = 10.0           # m / s^2
ETA1 = 1e21        # Pa s
CENTRE = (0.5, 0.75)
HALF = 0.125
RATIOS = 10.0 ** np.arange(-4, 5)   # eta1 / eta2


def outline(n):
    """Nodes along the block's outline, 0.7 h apart (h: the mean spacing)."""
    cx, cz = CENTRE
    square = [[cx - HALF, cz - HALF], [cx + HALF, cz - HALF], [cx + HALF, cz + HALF],
              [cx - HALF, cz + HALF]]
    return polyline_nodes(square, 0.7 / np.sqrt(n), closed=True)


def nodes(n, seed=0):
    """Random nodes in the unit box, the walls and the block's outline."""
    line = outline(n)
    return box_nodes(n, lines=[np.r_[line, line[:1]]], seed=seed)


def make_mesh(n, seed=0, constrained=True):
    """The triangulation of ``nodes(n, seed)``, the outline as segments
    (``mesh.boundaries["block"]``) unless ``constrained`` is False."""
    p = nodes(n, seed)
    if not constrained:
        return delaunay_mesh(p)
    return delaunay_mesh(p, segments={"block": line_segments(p, outline(n), closed=True)})


def inside(x):
    return (np.abs(x[0] - CENTRE[0]) <= HALF) & (np.abs(x[1] - CENTRE[1]) <= HALF)


def centre_velocity(mesh, method, ratio):
    """Nondimensional vertical velocity at the block centre."""
    spaces = stokes_spaces(mesh, method)

    def eta(x):
        return np.where(inside(x), 1.0 / ratio, 1.0)

    def force(x):
        return np.stack([0 * x[0], -inside(x).astype(float)])

    s = solve_stokes(spaces, eta, force, maxiter=5000)
    P = spaces.ubasis.probes(np.array([[CENTRE[0]], [CENTRE[1]]]))
    return float((P @ s.u)[1]), s.iterations


def run(n=3000, ratios=RATIOS, reference=True, verbose=True, constrained=True):
    """Rows of (ratio, NEM, Taylor-Hood, reference) scaled velocities."""
    mesh = make_mesh(n, constrained=constrained)
    fine = make_mesh(4 * n, seed=1) if reference else None
    rows = []
    scale = G * L ** 2
    for r in ratios:
        w_nem, it_nem = centre_velocity(mesh, "nem", r)
        w_th, it_th = centre_velocity(mesh, "taylor-hood", r)
        w_ref = centre_velocity(fine, "taylor-hood", r)[0] if reference else np.nan
        rows.append(dict(ratio=r, nem=abs(w_nem) * scale, th=abs(w_th) * scale,
                         ref=abs(w_ref) * scale, nem_w=w_nem, it_nem=it_nem, it_th=it_th,
                         nodes=mesh.p.shape[1]))
        if verbose:
            print(f"eta1/eta2 {r:8.0e}  NEM {abs(w_nem) * scale:.4e}  TH {abs(w_th) * scale:.4e}"
                  f"  ref {abs(w_ref) * scale:.4e}", flush=True)
    return rows


def table(rows):
    out = ["| eta1/eta2 | NEM | Taylor-Hood | reference (TH, 4x nodes) | NEM error | TH error |",
           "|---|---|---|---|---|---|"]
    for x in rows:
        out.append(f"| {x['ratio']:.0e} | {x['nem']:.4e} | {x['th']:.4e} | {x['ref']:.4e} | "
                   f"{abs(x['nem'] / x['ref'] - 1):.2%} | {abs(x['th'] / x['ref'] - 1):.2%} |")
    return "\n".join(out)


def visualize(rows, path="out/ex08_sinking_block.png"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    r = [x["ratio"] for x in rows]
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.loglog(r, [x["ref"] for x in rows], "k-", lw=3, alpha=0.4, label="Taylor-Hood, fine")
    ax.loglog(r, [x["th"] for x in rows], "s--", label="Taylor-Hood")
    ax.loglog(r, [x["nem"] for x in rows], "o-", label="NEM")
    ax.set_xlabel("eta1 / eta2")
    ax.set_ylabel("|v_z| eta1 / drho at the block centre (m^2/s)")
    ax.set_title(f"Sinking block, {rows[0]['nodes']} nodes")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    rows = run()
    print(table(rows))
    print("wrote", visualize(rows))
