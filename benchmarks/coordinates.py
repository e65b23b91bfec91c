"""Cost of natural-neighbour coordinates per query, against the peer figure.

Nodes: uniform random in the unit square (1e4, 1e5, 1e6 by default). Queries:
3 per node, uniform inside the triangles, spatially sorted (row-major buckets
of the triangle size), as in the peer measurement. For each size the script
reports microseconds per query for coordinates alone and with gradients, on 1
and 2 threads (best of ``--repeat`` runs), the per-core cost on 2 threads
(wall time x threads), the time to build the triangulation, and the peak
resident memory of a fresh process doing the whole size.

Peer figure (DESIGN.md section 5): CGAL 5.5 ``natural_neighbor_coordinates_2``
(C++, release, one core) takes about 0.7 us per query, coordinates only, at
1e5 nodes. The bar: coordinates + gradients at no more than 1 us per query per
core at 1e5 nodes, and time per query flat (within 1.5x) from 1e4 to 1e6.

Run ``python benchmarks/coordinates.py [--sizes 1e4 1e5 1e6] [--repeat 3]``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

CGAL_US = 0.7


def run_size(n: int, repeat: int) -> dict:
    import resource

    import numba
    import numpy as np

    from skfem_nem import Triangulation, sibson_coordinates

    rng = np.random.default_rng(0)
    p = rng.random((n, 2))
    t0 = time.perf_counter()
    tri = Triangulation(p)
    t_tri = time.perf_counter() - t0
    m = 3 * n
    t = rng.integers(0, tri.ntriangles, m)
    lam = rng.dirichlet(np.ones(3), m)
    q = np.einsum("mk,mkd->md", lam, p[tri.triangles[t]])
    k = max(1, int(np.sqrt(m / 4)))
    order = np.lexsort((q[:, 0], np.minimum((q[:, 1] * k).astype(int), k - 1)))
    q = np.ascontiguousarray(q[order])
    sibson_coordinates(tri, q[:2000], gradient=True)  # compile / load cache
    sibson_coordinates(tri, q[:2000])
    out = {"n": n, "m": m, "triangulation_s": t_tri}
    for threads in (1, 2):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        for grad in (False, True):
            best = np.inf
            for _ in range(repeat):
                s = time.perf_counter()
                Phi = sibson_coordinates(tri, q, gradient=grad)
                best = min(best, time.perf_counter() - s)
            out[f"us_{'grad' if grad else 'vals'}_{threads}t"] = best / m * 1e6
    out["mean_neighbours"] = (Phi[0] if isinstance(Phi, tuple) else Phi).nnz / m
    out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(run_size(a.child, a.repeat)))
        return
    rows = []
    for n in a.sizes:
        res = subprocess.run([sys.executable, __file__, "--child", str(int(n)),
                              "--repeat", str(a.repeat)], capture_output=True, text=True)
        if res.returncode:
            sys.exit(res.stderr)
        rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
    print("| nodes | queries | Delaunay s | nn/query | coords us/q 1t | coords+grad us/q 1t "
          "| coords us/q 2t | coords+grad us/q 2t | coords+grad us/q/core 2t "
          "| coords 1t / CGAL | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['n']:,} | {r['m']:,} | {r['triangulation_s']:.2f} | {r['mean_neighbours']:.2f} "
              f"| {r['us_vals_1t']:.3f} | {r['us_grad_1t']:.3f} | {r['us_vals_2t']:.3f} "
              f"| {r['us_grad_2t']:.3f} | {2 * r['us_grad_2t']:.3f} "
              f"| {r['us_vals_1t'] / CGAL_US:.2f} | {r['peak_mb']:.0f} |")
    if len(rows) > 1:
        g = [r["us_grad_1t"] for r in rows]
        print(f"\nflatness (coords+grad, 1 thread): largest/smallest time per query = "
              f"{max(g) / min(g):.2f} (bar: <= 1.5)")


if __name__ == "__main__":
    main()
