"""A stiff sphere settling on the axis of a cylinder: 3D Stokes flow on natural neighbours.

A sphere of radius a = 0.2, a thousand times more viscous than the fluid and heavier by
``drho g = 1``, sits at the centre of a cylinder of radius 1 and length 4 with no-slip
walls and ends (each end 1.8 cylinder radii from the sphere, where its effect is below
0.5%). Stokes' law with the Haberman & Sayre (1958) wall factor gives the settling
velocity, 0.595 of the unbounded one. Nodes: rings on the wall, discs on the ends, a
Fibonacci lattice on the sphere and random interior nodes graded from the sphere's
spacing ``hs`` to the wall's ``hw``. Natural-neighbour velocity (Box 1, smoothed, with
bubbles), P1 pressure, FGMRES with AMG. The sphere's surface triangles are walls
(``delaunay_mesh(points, faces=...)``): no natural neighbour is seen through them, so
the velocity kinks at the surface, and the sphere settles at 0.954 of the reference
velocity on 2,481 nodes, 0.994 on 22,517.

The viscosity and weight belong to the tetrahedra inside the walls. The nodes beside the
surface keep a little further from it than its triangles' circumradius, which makes every
triangle a Delaunay face. The sphere is then a polyhedron of slightly smaller volume, and
the velocity converges to the reference like ``hs^2`` (``benchmarks/stokes_3d.py
--sphere``; without walls the stiff sphere dragged a layer of fluid along and ran 30%
slow).
"""
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from skfem_nem import delaunay_mesh
from skfem_nem.models.analytic3d import settling_velocity
from skfem_nem.models.stokes import solve_stokes, stokes_spaces

A, R, HALF_LENGTH, RATIO = 0.2, 1.0, 2.0, 1e3
RESOLUTION = (0.08, 0.3)          # (hs, hw): spacing on the sphere and at the wall
FIGURE = Path(__file__).resolve().parents[1] / "docs" / "figures" / "ex22_settling_sphere.png"


def fibonacci_sphere(m, r):
    """``m`` nearly even points on the sphere of radius ``r`` about the origin."""
    k = np.arange(m) + 0.5
    phi, th = np.arccos(1 - 2 * k / m), np.pi * (1 + 5 ** 0.5) * k
    return r * np.c_[np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)]


def surface(hs):
    """The sphere's nodes (a Fibonacci lattice at spacing ``hs``) and triangles."""
    s = fibonacci_sphere(int(1.1 * 4 * np.pi * A ** 2 / hs ** 2), A)
    return s, ConvexHull(s).simplices


def clearance(s, faces):
    """How far other nodes keep from the sphere: a little past the largest circumradius of
    its triangles, so that each is a Delaunay face (its smallest sphere holds no node)."""
    a, b, c = (s[faces[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    r = (np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - b, axis=1)
         * np.linalg.norm(a - c, axis=1) / (2 * area2))
    return 1.05 * r.max()


def nodes(hs, hw, seed=0):
    """Wall rings, end discs, the sphere's surface (first) and graded interior nodes; the
    surface's triangles."""
    rng = np.random.default_rng(seed)
    s, faces = surface(hs)
    nz, k = int(np.ceil(2 * HALF_LENGTH / hw)), int(np.ceil(2 * np.pi * R / hw))
    out = [s]
    for i, z in enumerate(np.linspace(-HALF_LENGTH, HALF_LENGTH, nz + 1)):
        t = 2 * np.pi * (np.arange(k) + 0.5 * (i % 2)) / k
        out.append(np.c_[R * np.cos(t), R * np.sin(t), np.full(k, z)])
    for z in (-HALF_LENGTH, HALF_LENGTH):
        d = rng.uniform(-R, R, (int(8 * R ** 2 / hw ** 2), 2))
        d = d[np.hypot(*d.T) < R - 0.5 * hw]
        out.append(np.c_[d, np.full(len(d), z)])
    box = rng.uniform([-R, -R, -HALF_LENGTH], [R, R, HALF_LENGTH],
                      (int(24 * R ** 2 * HALF_LENGTH / hs ** 3), 3))
    box = box[(np.hypot(box[:, 0], box[:, 1]) < R - 0.5 * hw)
              & (np.abs(box[:, 2]) < HALF_LENGTH - 0.5 * hw)]
    gap = np.abs(np.linalg.norm(box, axis=1) - A)          # from the sphere's surface
    h = hs + (hw - hs) * np.minimum(1.0, gap / (4 * A))
    out.append(box[(rng.random(len(box)) < (hs / h) ** 3) & (gap > clearance(s, faces))])
    return np.concatenate(out), faces


def settle(hs, hw, walls=True):
    """The solution, its mesh and the sphere's mean settling velocity (positive down);
    ``walls=False``: the same nodes without walls."""
    p, faces = nodes(hs, hw)
    mesh = delaunay_mesh(p, faces={"sphere": faces} if walls else None)
    spaces = stokes_spaces(mesh)
    inside = np.linalg.norm(mesh.p[:, mesh.t].mean(axis=1), axis=0) < A      # (ne,)

    def stiff(x):                      # 1 in the sphere's tetrahedra, at their points
        return np.where(inside[:, None], 1.0, 0.0) + 0 * x[0]
    sol = solve_stokes(spaces, lambda x: 1 + (RATIO - 1) * stiff(x),
                       lambda x: np.stack([0 * x[0], 0 * x[0], -stiff(x)]),
                       free_slip=None, no_slip="all", solver="fgmres", tol=1e-8)
    v = sol.velocity_at_nodes()
    ball = np.linalg.norm(mesh.p, axis=0) < A * (1 + 1e-9)
    return sol, mesh, float(-v[ball, 2].mean())


REFERENCE = settling_velocity(A, R, 1.0, 1.0, 1.0, viscosity_ratio=RATIO)
solution, mesh, velocity = settle(*RESOLUTION)


def visualize(path=FIGURE):
    """The speed and the flow in the plane y = 0, and the vertical velocity across the
    sphere's equator against the reference; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, z = np.linspace(-0.96 * R, 0.96 * R, 97), np.linspace(-1.2, 1.2, 121)
    X, Z = np.meshgrid(x, z)
    P = solution.spaces.ubasis.probes(np.stack([X.ravel(), 0 * X.ravel(), Z.ravel()]))
    U = (P @ solution.u).reshape(3, *X.shape) / REFERENCE
    fig, ax = plt.subplots(1, 2, figsize=(12, 5.6), constrained_layout=True)
    c = ax[0].pcolormesh(X, Z, np.hypot(U[0], U[2]), shading="auto", cmap="viridis")
    ax[0].streamplot(X, Z, U[0], U[2], color="w", density=1.1, linewidth=0.6)
    t = np.linspace(0, 2 * np.pi, 200)
    ax[0].plot(A * np.cos(t), A * np.sin(t), "r-", lw=1.2)
    ax[0].set(aspect="equal", xlabel="x", ylabel="z",
              title="speed / Haberman-Sayre velocity, plane y = 0")
    fig.colorbar(c, ax=ax[0])
    mid = np.argmin(np.abs(z))
    ax[1].plot(x, -U[2, mid], "b-", label="natural neighbours")
    ax[1].axhline(1.0, color="k", ls="--", label="Haberman-Sayre (rigid sphere)")
    ax[1].axvspan(-A, A, color="0.9", label="sphere")
    ax[1].set(xlabel="x (y = 0, z = 0)", ylabel="settling velocity / reference",
              title=f"{mesh.p.shape[1]:,} nodes: sphere at {velocity / REFERENCE:.3f}")
    ax[1].legend(loc="lower center")
    fig.savefig(path, dpi=110)
    return fig


if __name__ == "__main__":
    print(f"{mesh.p.shape[1]:,} nodes, {solution.iterations} FGMRES iterations")
    print(f"settling velocity {velocity:.5f}, Haberman-Sayre {REFERENCE:.5f} "
          f"(ratio {velocity / REFERENCE:.3f})")
    visualize()
    print("figure written to", FIGURE)
