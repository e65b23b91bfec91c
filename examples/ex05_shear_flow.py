"""Nodes carried by a cellular shear flow: the evolving Delaunay mesh of Fig. 6.

Braun & Sambridge (1995, Fig. 6) follow a falling plate dragging a viscous
fluid: the plate pulls fluid down in the middle of the box and a return flow
rises at the sides. Here the same pattern is prescribed instead of solved
for: two counter-rotating cells,

    psi = -sin(2 pi x) sin(pi y) / (2 pi),   (u, v) = (d psi / dy, -d psi / dx),

which is divergence free, sinks along x = 1/2, rises along the side walls and
has no normal flow through the walls of the unit square (maximum speed 1).
Its rotation rate varies across each cell, so the flow shears the mesh
continuously: near the cell centres a node turns once in 2 time units, near
the walls and the separatrix it hardly turns at all.

2000 random nodes plus nodes on the sides are moved for 200 steps (time 2:
one turn of the cell centres) with :class:`skfem_nem.LagrangianMesh`:
predictor-corrector update, free-slip walls, Lawson flips after every step.
Each node carries its initial position as a node field (the paper colours the
fluid by initial depth). From the run the script finds

* ``B/B'``: two nodes connected by a Delaunay edge at the start that end
  farthest apart ("moved apart by the divergent flow"), and
* ``A/A'``: two nodes connected by an edge at the end that started farthest
  apart ("originally far apart ... eventually become neighbours"),

both among interior nodes, and plots the mesh at the start, middle and end,
coloured by the initial height, with both pairs marked, next to the minimum
angle and the flips of every step. Mesh quality step by step, and for other
node counts: ``benchmarks/shear_flow.py``.
"""
from pathlib import Path

import numpy as np

from skfem_nem import LagrangianMesh

N_NODES = 2000
N_STEPS = 200
T_END = 2.0
SEED = 0
FIGURE = "out/ex05_shear_flow.png"


def velocity(x):
    """Two counter-rotating cells, sinking at x = 1/2."""
    X, Y = np.pi * x[:, 0], np.pi * x[:, 1]
    return np.c_[-0.5 * np.sin(2 * X) * np.cos(Y), np.cos(2 * X) * np.sin(Y)]


def box_nodes(n, seed=SEED):
    """n random nodes in the unit square, ~sqrt(n) jittered nodes per side, the corners."""
    rng = np.random.default_rng(seed)
    k = int(round(np.sqrt(n)))
    s = (np.arange(1, k) + 0.5 * (rng.random((4, k - 1)) - 0.5)) / k
    z, o = np.zeros(k - 1), np.ones(k - 1)
    return np.vstack([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                      np.c_[s[0], z], np.c_[s[1], o], np.c_[z, s[2]], np.c_[o, s[3]],
                      rng.random((n, 2))])


def edges(triangles):
    """(ne, 2) unique sorted edges of a triangulation."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def find_pairs(x0, x1, edges0, edges1, interior):
    """The B/B' pair (an edge at the start, farthest apart at the end) and the
    A/A' pair (an edge at the end, farthest apart at the start), interior nodes only."""
    e0 = edges0[interior[edges0].all(axis=1)]
    e1 = edges1[interior[edges1].all(axis=1)]
    d_end = np.linalg.norm(x1[e0[:, 0]] - x1[e0[:, 1]], axis=1)
    d_start = np.linalg.norm(x0[e1[:, 0]] - x0[e1[:, 1]], axis=1)
    b, a = e0[np.argmax(d_end)], e1[np.argmax(d_start)]
    return {"A": tuple(int(i) for i in a), "B": tuple(int(i) for i in b),
            "A_start_distance": float(d_start.max()), "B_end_distance": float(d_end.max())}


def run(n_nodes=N_NODES, n_steps=N_STEPS, t_end=T_END, seed=SEED, on_step=None):
    """Carry the nodes through the flow (calling ``on_step(lm)`` after each
    step); returns the mesh, snapshots and the pairs."""
    p = box_nodes(n_nodes, seed)
    lm = LagrangianMesh(p, node_fields={"x0": p})
    dt = t_end / n_steps
    snaps = {0: (lm.nodes.copy(), lm.triangles.copy())}
    for step in range(1, n_steps + 1):
        lm.advance(velocity, dt)
        if on_step is not None:
            on_step(lm)
        if step in (n_steps // 2, n_steps):
            snaps[step] = (lm.nodes.copy(), lm.triangles.copy())
    on_wall = ((p == 0) | (p == 1)).any(axis=1)
    pairs = find_pairs(p, lm.nodes, edges(snaps[0][1]), edges(lm.triangles), ~on_wall)
    h = 1 / np.sqrt(p.shape[0])
    return {"mesh": lm, "start": p, "snapshots": snaps, "pairs": pairs, "h": h, "dt": dt}


result = run()
lm = result["mesh"]
history = lm.history
pairs = result["pairs"]


def visualize(path=FIGURE, res=None):
    """The mesh at the start, middle and end with both pairs, and the minimum
    angle and flips per step; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = result if res is None else res
    y0 = res["start"][:, 1]
    (a, a2), (b, b2) = res["pairs"]["A"], res["pairs"]["B"]
    fig = plt.figure(figsize=(13, 10.5), constrained_layout=True)
    gs = fig.add_gridspec(2, 2)
    axes = [fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, 0])]
    hist = res["mesh"].history
    times = {s: (hist[s - 1]["time"] if s else 0.0) for s in res["snapshots"]}
    last = max(res["snapshots"])
    for ax, (step, (P, T)) in zip(axes, res["snapshots"].items()):
        tpc = ax.tripcolor(P[:, 0], P[:, 1], T, y0, shading="gouraud", cmap="magma")
        ax.triplot(P[:, 0], P[:, 1], T, lw=0.25, color="k", alpha=0.6)
        for i, j, c, mk, lab in ((a, a2, "#00e5ff", "o", "A"), (b, b2, "#7CFC00", "s", "B")):
            neighbours = step == (last if lab == "A" else 0)
            ax.plot(P[[i, j], 0], P[[i, j], 1], ls="-" if neighbours else ":", color=c,
                    lw=2 if neighbours else 1)
            ax.plot(P[[i, j], 0], P[[i, j], 1], mk, color=c, ms=8, mec="k")
            ax.annotate(lab, P[i], xytext=(5, 5), textcoords="offset points", color=c,
                        fontsize=12, fontweight="bold")
            ax.annotate(lab + "'", P[j], xytext=(5, 5), textcoords="offset points", color=c,
                        fontsize=12, fontweight="bold")
        ax.set_title(f"step {step}, t = {times[step]:.2f}: {P.shape[0]} nodes, "
                     f"{T.shape[0]} triangles")
        ax.set_aspect("equal")
        ax.set_xlim(-0.02, 1.02)
        ax.set_ylim(-0.02, 1.02)
    fig.colorbar(tpc, ax=axes, shrink=0.5, label="initial height y0 of the nodes")
    ax = fig.add_subplot(gs[1, 1])
    t = [r["time"] for r in hist]
    ax.semilogy(t, [r["min_angle"] for r in hist], color="C0")
    ax.set_xlabel("time")
    ax.set_ylabel("minimum angle (degrees)", color="C0")
    ax2 = ax.twinx()
    ax2.plot(t, [r["flips"] for r in hist], color="C3", lw=0.8)
    ax2.set_ylabel("flips per step", color="C3")
    ax.set_title("mesh quality and flips per step")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    h = result["h"]
    print(f"{lm.triangulation.npoints} nodes, {len(history)} steps of dt = {result['dt']:.4f} "
          f"(max displacement {result['dt'] / h:.2f} h per step)")
    print(f"total flips {sum(r['flips'] for r in history)}, substeps beyond the first "
          f"{sum(r['substeps'] - 1 for r in history)}, "
          f"relocated {sum(r['relocated'] for r in history)}, "
          f"Delaunay at the end: {lm.triangulation.is_delaunay()}")
    (a, a2), (b, b2) = pairs["A"], pairs["B"]
    x0, x1 = result["start"], lm.nodes
    print(f"B/B' = nodes {b}, {b2}: neighbours at the start "
          f"({np.linalg.norm(x0[b] - x0[b2]) / h:.1f} h "
          f"apart), {pairs['B_end_distance'] / h:.1f} h apart at the end")
    print(f"A/A' = nodes {a}, {a2}: {pairs['A_start_distance'] / h:.1f} h apart at the start, "
          f"neighbours at the end ({np.linalg.norm(x1[a] - x1[a2]) / h:.1f} h apart)")
    visualize()
    print("figure written to", FIGURE)
