"""Non-convex domains with constrained natural neighbours: an L-shape and a slit.

The domain's outline is given to :func:`~skfem_nem.delaunay_mesh` as segments
and the notch or slit as a hole, so the natural neighbours of a point are the
nodes it sees inside the domain. Printed (docs/verification.md, section 7):

1. boundary interpolation: the largest deviation, at random points on the
   outline, of the interpolant of a smooth field from the linear
   interpolation between the two end nodes of the boundary facet, for the
   constrained coordinates and for the plain Delaunay ones (which reach
   across the notch);
2. Poisson with a smooth manufactured solution u = sin(2x + 1) cos(3y) + x y
   (Dirichlet data on the whole outline, including the slit's faces): L2 and
   H1 errors and rates for constrained NEM (smoothed integration, the
   default) and for scikit-fem's P1 on the same triangles.

    python benchmarks/nonconvex.py [--sizes 500 2000 8000 32000] [--quick]
"""
from __future__ import annotations

import argparse

import numpy as np
from skfem import Basis, ElementTriP1, Functional, LinearForm, condense, solve
from skfem.helpers import dot, grad

from skfem_nem import NaturalNeighbourBasis, Triangulation, delaunay_mesh
from skfem_nem import natural_neighbour_coordinates

SLIT_WIDTH = 0.02


def exact(x, y):
    return np.sin(2 * x + 1) * np.cos(3 * y) + x * y


def exact_grad(x, y):
    return np.array([2 * np.cos(2 * x + 1) * np.cos(3 * y) + y,
                     -3 * np.sin(2 * x + 1) * np.sin(3 * y) + x])


@LinearForm
def load(v, w):
    return 13.0 * np.sin(2 * w.x[0] + 1) * np.cos(3 * w.x[1]) * v


def _laplace(u, v, w):
    return dot(grad(u), grad(v))


@Functional
def l2_error(w):
    return (w["uh"] - exact(*w.x)) ** 2


@Functional
def h1_error(w):
    g = w["uh"].grad - exact_grad(*w.x)
    return g[0] ** 2 + g[1] ** 2


def outline(corners, h):
    """Nodes along the closed polygon ``corners`` at spacing about h, and its
    edges as segments (node i to node i + 1)."""
    pts = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        k = max(1, int(np.ceil(np.hypot(*(b - a)) / h)))
        pts.append(a + (b - a) * np.arange(k)[:, None] / k)
    p = np.concatenate(pts)
    n = p.shape[0]
    return p, np.column_stack([np.arange(n), (np.arange(n) + 1) % n])


def inside(corners, q):
    """Even-odd rule: (m,) True for the points q inside the polygon."""
    result = np.zeros(q.shape[0], dtype=bool)
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        cross = (a[1] > q[:, 1]) != (b[1] > q[:, 1])
        xs = a[0] + (q[:, 1] - a[1]) * (b[0] - a[0]) / np.where(b[1] != a[1], b[1] - a[1], 1)
        result ^= cross & (q[:, 0] < xs)
    return result


def distance(corners, q):
    d = np.full(q.shape[0], np.inf)
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        ab = b - a
        s = np.clip(((q - a) @ ab) / (ab @ ab), 0, 1)
        d = np.minimum(d, np.hypot(*(a + s[:, None] * ab - q).T))
    return d


def domain(name, n, seed=0):
    """Nodes, outline segments and a hole point of the L-shape ([0,1]^2 without
    (1/2,1)^2) or the slit square ([0,1]^2 without a slit of width SLIT_WIDTH
    from the bottom to y = 1/2 at x = 1/2), with about n nodes."""
    if name == "L-shape":
        corners = np.array([[0, 0], [1, 0], [1, .5], [.5, .5], [.5, 1], [0, 1]], float)
        hole, area = [.75, .75], 0.75
    else:
        w = SLIT_WIDTH / 2
        corners = np.array([[0, 0], [.5 - w, 0], [.5 - w, .5], [.5 + w, .5], [.5 + w, 0],
                            [1, 0], [1, 1], [0, 1]], float)
        hole, area = [.5, .25], 1.0 - SLIT_WIDTH / 2
    h = np.sqrt(area / n)
    bnd, seg = outline(corners, h)
    rng = np.random.default_rng(seed)
    g = np.arange(h / 2, 1, h)
    q = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) + rng.uniform(-.3, .3, (g.size ** 2, 2)) * h
    q = q[inside(corners, q) & (distance(corners, q) > 0.4 * h)]
    return np.concatenate([bnd, q]), seg, np.array([hole])


def boundary_interpolation(p, seg, tri, seed=1):
    """Largest deviation of the interpolant of ``exact`` from the linear
    interpolation along the outline, at 20 random points per segment."""
    rng = np.random.default_rng(seed)
    s = rng.random((seg.shape[0], 20)).ravel()
    a, b = np.repeat(seg[:, 0], 20), np.repeat(seg[:, 1], 20)
    x = p[a] * (1 - s)[:, None] + p[b] * s[:, None]
    lin = exact(*p[a].T) * (1 - s) + exact(*p[b].T) * s
    Phi = natural_neighbour_coordinates(tri, x)
    return float(np.abs(Phi @ exact(*p.T) - lin).max())


def poisson(mesh, method):
    """(L2 error, H1 error) of the Dirichlet problem for ``exact``."""
    if method == "NEM":
        basis, ebasis = NaturalNeighbourBasis(mesh), NaturalNeighbourBasis(mesh, npoints=7)
    else:
        basis = Basis(mesh, ElementTriP1())
        ebasis = Basis(mesh, ElementTriP1(), intorder=6)
    from skfem import BilinearForm
    A = BilinearForm(_laplace).assemble(basis)
    D = basis.get_dofs().all()
    u = solve(*condense(A, load.assemble(basis), x=exact(*mesh.p), D=D))
    uh = ebasis.interpolate(u)
    return (np.sqrt(l2_error.assemble(ebasis, uh=uh)),
            np.sqrt(h1_error.assemble(ebasis, uh=uh)))


def study(sizes):
    rows = []
    for name in ("L-shape", "slit"):
        for n in sizes:
            p, seg, hole = domain(name, n)
            mesh = delaunay_mesh(p, segments={"outline": seg}, holes=hole)
            bi_c = boundary_interpolation(p, seg, Triangulation(p, segments=seg))
            bi_u = boundary_interpolation(p, seg, Triangulation(p))
            rows.append((name, p.shape[0], bi_c, bi_u, *poisson(mesh, "NEM"),
                         *poisson(mesh, "P1")))
    return rows


def rate(n0, n1, e0, e1):
    return -2.0 * np.log(e1 / e0) / np.log(n1 / n0)


def table(rows):
    out = ["| domain | nodes | boundary interp. C-NEM | plain NEM | NEM L2 | rate | NEM H1 | rate "
           "| P1 L2 | P1 H1 |", "|---|---|---|---|---|---|---|---|---|---|"]
    prev = None
    for r in rows:
        name, n, bc, bu, l2, h1, pl2, ph1 = r
        rl2 = rh1 = ""
        if prev is not None and prev[0] == name:
            rl2 = f"{rate(prev[1], n, prev[4], l2):.2f}"
            rh1 = f"{rate(prev[1], n, prev[5], h1):.2f}"
        out.append(f"| {name} | {n} | {bc:.1e} | {bu:.1e} | {l2:.2e} | {rl2} | {h1:.2e} | {rh1} "
                   f"| {pl2:.2e} | {ph1:.2e} |")
        prev = r
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[500, 2000, 8000, 32000])
    ap.add_argument("--quick", action="store_true", help="two small levels")
    args = ap.parse_args(argv)
    sizes = [300, 1200] if args.quick else args.sizes
    print(table(study(sizes)))


if __name__ == "__main__":
    main()
