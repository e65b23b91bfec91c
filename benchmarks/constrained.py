"""Cost of constrained natural neighbours next to the plain ones, on the same nodes.

Nodes: n uniform random in the unit square plus interfaces carried by nodes:
eight horizontal lines and a circle, each with about sqrt(n) nodes joined as
segments (about 9 sqrt(n) segments in all: a layered model with an inclusion).
Queries: 3 per node, uniform inside the triangles, spatially sorted, as in
``benchmarks/coordinates.py``. For each size: seconds to build the Delaunay
triangulation and the constrained one (segment insertion by flips included),
and microseconds per query for Sibson coordinates + gradients on the plain
and on the constrained triangulation, 1 and 2 threads (best of ``--repeat``).

    python benchmarks/constrained.py [--sizes 1e4 1e5 1e6] [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import numba
import numpy as np

from skfem_nem import Triangulation, sibson_coordinates


# the layer interfaces: above and below the circular inclusion (radius 0.2 about the centre)
LINES = np.r_[np.linspace(.05, .26, 4), np.linspace(.74, .95, 4)]


def layered_nodes(n, seed=0):
    """n random nodes (those not too close to an interface), the interface nodes,
    and the segments joining them."""
    rng = np.random.default_rng(seed)
    k = max(8, int(np.sqrt(n)))
    lines = [np.c_[np.linspace(0, 1, k), np.full(k, y)] for y in LINES]
    th = np.linspace(0, 2 * np.pi, k, endpoint=False)
    circle = np.c_[.5 + .2 * np.cos(th), .5 + .2 * np.sin(th)]
    q = rng.random((n, 2))
    gap = 0.3 / k
    far = (np.abs(q[:, 1, None] - LINES[None]).min(1) > gap) & (
        np.abs(np.hypot(q[:, 0] - .5, q[:, 1] - .5) - .2) > gap)
    segs = [j * k + np.c_[np.arange(k - 1), np.arange(1, k)] for j in range(len(lines))]
    segs.append(len(lines) * k + np.c_[np.arange(k), (np.arange(k) + 1) % k])
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1.]])
    return np.concatenate(lines + [circle, corners, q[far]]), np.concatenate(segs)


def queries(tri, rng):
    m = 3 * tri.npoints
    t = rng.integers(0, tri.ntriangles, m)
    lam = rng.dirichlet(np.ones(3), m)
    q = np.einsum("mk,mkd->md", lam, tri.nodes[tri.triangles[t]])
    k = max(1, int(np.sqrt(m / 4)))
    order = np.lexsort((q[:, 0], np.minimum((q[:, 1] * k).astype(int), k - 1)))
    return np.ascontiguousarray(q[order])


def best(f, repeat):
    b = np.inf
    for _ in range(repeat):
        s = time.perf_counter()
        f()
        b = min(b, time.perf_counter() - s)
    return b


def run_size(n, repeat):
    p, segs = layered_nodes(n)
    t_plain = best(lambda: Triangulation(p), repeat)
    t_cdt = best(lambda: Triangulation(p, segments=segs), repeat)
    plain, cdt = Triangulation(p), Triangulation(p, segments=segs)
    q = queries(plain, np.random.default_rng(1))
    row = {"n": p.shape[0], "segments": segs.shape[0], "m": q.shape[0],
           "dt_s": t_plain, "cdt_s": t_cdt}
    for threads in (1, 2):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        for name, tri in (("plain", plain), ("constrained", cdt)):
            sibson_coordinates(tri, q[:2000], gradient=True)
            s = best(lambda: sibson_coordinates(tri, q, gradient=True), repeat)
            row[f"{name}_{threads}t"] = s / q.shape[0] * 1e6
    return row


def table(rows):
    out = ["| nodes | segments | queries | Delaunay s | constrained s | plain us/q 1t "
           "| constrained us/q 1t | ratio | plain us/q 2t | constrained us/q 2t | ratio |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['n']:,} | {r['segments']:,} | {r['m']:,} | {r['dt_s']:.3f} "
                   f"| {r['cdt_s']:.3f} | {r['plain_1t']:.3f} | {r['constrained_1t']:.3f} "
                   f"| {r['constrained_1t'] / r['plain_1t']:.2f} | {r['plain_2t']:.3f} "
                   f"| {r['constrained_2t']:.3f} | {r['constrained_2t'] / r['plain_2t']:.2f} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one small size, one repeat")
    a = ap.parse_args(argv)
    sizes, repeat = ([2000], 1) if a.quick else (a.sizes, a.repeat)
    print(table([run_size(int(n), repeat) for n in sizes]))


if __name__ == "__main__":
    main()
