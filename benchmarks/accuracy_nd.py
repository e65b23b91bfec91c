"""Accuracy of the Box 1 (Lasserre) coordinates in 2, 3 and 4 dimensions.

For random nodes in the unit cube of each dimension and random queries in its
middle (and, separately, queries within 1e-9 of a node and on interior
Delaunay faces), prints the worst violation of the defining identities --
partition of unity, linear precision ``sum_i phi_i x_i = x``, ``sum_i grad
phi_i = 0``, ``sum_i x_i grad phi_i^T = I`` (the gradient identities relative
to the largest gradient) -- the worst gap between the gradients and central
finite differences (relative to the largest gradient of the query; step 1e-4 times the distance
to the nearest node, at most
1e-6), and in 2D the worst difference from the area method. In 3D the
sum of the second-order volumes is compared with the Voronoi cell volume of
the inserted point (scipy/Qhull), the paper's own check.

Run ``python benchmarks/accuracy_nd.py`` (about 20 s, 1 thread).
"""
from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import ConvexHull, Delaunay, Voronoi, cKDTree

from skfem_nem import sibson_coordinates
from skfem_nem.coordinates.lasserre import sibson_coordinates_nd

SIZES = {2: 2000, 3: 1000, 4: 300}


def identities(p, q, fd_check=True):
    d = p.shape[1]
    F, G = sibson_coordinates(p, q, gradient=True)
    G = [g.toarray() for g in G]
    F = F.toarray()
    gmax = max(np.abs(g).max() for g in G)
    out = {"pu": np.abs(F.sum(1) - 1).max(), "lin": np.abs(F @ p - q).max(),
           "gsum": max(np.abs(g.sum(1)).max() for g in G) / gmax,
           "glin": max(np.abs(G[k] @ p - np.eye(d)[k]).max() for k in range(d)) / gmax}
    # central differences with a step of 1e-4 times the distance to the nearest
    # node (at most 1e-6): the coordinates have a kink at the nodes
    h = np.minimum(1e-6, 1e-4 * cKDTree(p).query(q)[0])[:, None]
    fd = np.nan
    for k in range(d if fd_check else 0):
        fd = 0.0 if np.isnan(fd) else fd
        e = np.zeros(d)
        e[k] = 1.0
        D = (sibson_coordinates(p, q + h * e).toarray()
             - sibson_coordinates(p, q - h * e).toarray()) / (2 * h)
        fd = max(fd, (np.abs(D - G[k]).max(1) / np.abs(G[k]).max(1)).max())
    out["fd"] = fd
    return out


def voronoi_check(p, q):
    """max relative |sum_i V_i - volume of x's Voronoi cell| (3D)."""
    V = np.asarray(sibson_coordinates_nd(p, q, _raw=True).sum(axis=1)).ravel()
    worst = 0.0
    for x, v in zip(q, V):
        vor = Voronoi(np.r_[p, x[None]])
        cell = vor.regions[vor.point_region[-1]]
        worst = max(worst, abs(ConvexHull(vor.vertices[cell]).volume - v) / v)
    return worst


def main():
    numba.set_num_threads(1)
    rng = np.random.default_rng(0)
    print("| d | nodes | queries | where | sum phi - 1 | sum phi x - x | sum grad phi "
          "| sum x grad phi - I | grad vs finite diff. | vs area method (2D) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for d, n in SIZES.items():
        p = rng.random((n, d))
        tri = Delaunay(p)
        cases = {"inside": 0.3 + 0.4 * rng.random((200, d))}
        s = tri.simplices[tri.find_simplex(cases["inside"][:100])]
        k = rng.integers(0, d + 1, s.shape[0])
        keep = np.ones(s.shape, bool)
        keep[np.arange(s.shape[0]), k] = False
        face = p[s[keep].reshape(s.shape[0], d)]
        cases["on faces"] = np.einsum("mk,mkd->md", rng.dirichlet(np.ones(d), s.shape[0]), face)
        near = p[np.flatnonzero((np.abs(p - 0.5) < 0.2).all(1))[:50]]
        cases["1e-9 from a node"] = near + 1e-9 * rng.standard_normal(near.shape)
        for where, q in cases.items():
            # within 1e-9 of a node a finite difference is round-off (step 1e-13)
            r = identities(p, q, fd_check=not where.startswith("1e-9"))
            area = "-"
            if d == 2:
                A = sibson_coordinates(p, q).toarray()
                B = sibson_coordinates(p, q, method='lasserre').toarray()
                area = f"{np.abs(A - B).max():.1e}"
            print(f"| {d} | {n:,} | {q.shape[0]} | {where} | {r['pu']:.1e} | {r['lin']:.1e} "
                  f"| {r['gsum']:.1e} | {r['glin']:.1e} | {r['fd']:.1e} | {area} |"
                  .replace("nan", "-"))
    p = rng.random((220, 3))
    q = 0.35 + 0.3 * rng.random((40, 3))
    print(f"\n3D, 220 nodes (the paper's check), 40 queries: max relative |sum_i V_i - "
          f"Voronoi cell volume| = {voronoi_check(p, q):.1e}")


if __name__ == "__main__":
    main()
