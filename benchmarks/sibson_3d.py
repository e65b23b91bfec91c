"""3D Sibson interpolation: skfem-nem's interpolator and Box 1 coordinates against natinterp3d.

natinterp3d (PyPI, exact 3D Sibson coordinates in C with OpenMP; an optional benchmark
peer, never a dependency: ``pip install natinterp3d``) and
skfem-nem interpolate the same values at the same queries: ``--points`` random nodes in the
unit cube (plus its corners), ``--queries`` random points inside, seed 0. Ours two ways:
``NaturalNeighbourInterpolator(points, values)(queries)``, the like of natinterp3d's call
(Sibson's values by Watson's decomposition, :mod:`skfem_nem.coordinates.interp_watson3d`, the
tetrahedralisation built inside the call), and ``sibson_coordinates`` (the whole sparse
matrix of coordinates, by Watson's decomposition too for a batch this large,
:mod:`skfem_nem.coordinates.watson3d`, its flagged queries by the paper's Box 1) times the
values. All are timed warm (a first small call loads the kernels; the one-time load is
printed apart), best of ``--repeat``, with all threads; the coordinates' time is split into
the Delaunay tetrahedralisation (the package's own ``Delaunay3D``, once per node set;
Qhull's time on the same points printed beside it) and the coordinates. Printed beside the
times: how many queries' values differ by more than 1e-10, and each method's worst
violation of linear precision (``|sum_i phi_i(x) x_i - x|`` over the queries; natinterp3d's
weights from its ``get_weights``). On the default set the two differ at 20 of the 100,000
queries, by up to about 1e-5; at every one of them natinterp3d's weights miss linear
precision (by up to 5e-6) while ours hold it to 3e-16.

    python benchmarks/sibson_3d.py [--points 20000] [--queries 100000] [--repeat 3]
"""
import argparse
import time

import numpy as np
from scipy.spatial import Delaunay

from skfem_nem import NaturalNeighbourInterpolator, sibson_coordinates
from skfem_nem.geometry.delaunay3d import Delaunay3D


def data(n_points: int, n_queries: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    corners = np.array(np.meshgrid([0.0, 1.0], [0.0, 1.0], [0.0, 1.0],
                                   indexing="ij")).reshape(3, -1).T
    p = np.vstack([corners, rng.random((n_points - 8, 3))])
    q = 0.02 + 0.96 * rng.random((n_queries, 3))
    f = np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + p[:, 2] ** 2
    return p, q, f


def best(fn, repeat: int):
    """(result, best seconds) of ``repeat`` calls."""
    out, t = None, np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t = min(t, time.perf_counter() - t0)
    return out, t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=20000)
    ap.add_argument("--queries", type=int, default=100000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    try:
        import natinterp3d
    except ImportError:
        raise SystemExit("natinterp3d is not installed: pip install natinterp3d") from None
    p, q, f = data(a.points, a.queries)
    t0 = time.perf_counter()
    small_p, small_q, small_f = data(200, 100, seed=1)
    sibson_coordinates(Delaunay3D(small_p), small_q)
    natinterp3d.Interpolator(small_p).interpolate(small_q, small_f)
    NaturalNeighbourInterpolator(small_p, small_f)(np.tile(small_q, (20, 1)))
    print(f"one-time kernel load: {time.perf_counter() - t0:.1f} s\n")

    tri, t_del = best(lambda: Delaunay3D(p), a.repeat)
    t_qhull = best(lambda: Delaunay(p), a.repeat)[1]
    Phi, t_ours = best(lambda: sibson_coordinates(tri, q), a.repeat)
    ours = Phi @ f
    values, t_itp = best(lambda: NaturalNeighbourInterpolator(p, f)(q), a.repeat)
    itp_diff = float(np.abs(values - ours).max())
    theirs, t_peer = best(lambda: natinterp3d.Interpolator(p).interpolate(q, f), a.repeat)
    diff = np.abs(ours - theirs)
    lin_ours = float(np.abs(Phi @ p - q).max())
    W = natinterp3d.get_weights(q, p)
    miss_peer = np.abs(W @ p - q).max(axis=1)
    lin_peer = float(miss_peer.max())
    # the differing queries at which natinterp3d's weights are not linearly precise
    peer_off = int(((diff > 1e-10) & (miss_peer > 1e-12)).sum())
    total = t_del + t_ours
    rows = ["| method | Delaunay s | coordinates s | total s | total / natinterp3d | "
            "linear precision |", "|---|---|---|---|---|---|",
            f"| skfem-nem NaturalNeighbourInterpolator (Watson) | | | {t_itp:.3f} | "
            f"{t_itp / t_peer:.2f} | |",
            f"| skfem-nem sibson_coordinates | {t_del:.3f} | {t_ours:.3f} | {total:.3f} | "
            f"{total / t_peer:.2f} | {lin_ours:.1e} |",
            f"| natinterp3d | | | {t_peer:.3f} | 1.00 | {lin_peer:.1e} |"]
    print(f"{a.points:,} points, {a.queries:,} queries, best of {a.repeat}; the values "
          f"differ by more than 1e-10 at {int((diff > 1e-10).sum())} queries (at most "
          f"{diff.max():.1e}), at {peer_off} of them natinterp3d's weights miss linear "
          f"precision; Qhull's Delaunay of the points takes {t_qhull:.3f} s; the interpolator's "
          f"values differ from the coordinates' by at most {itp_diff:.1e}\n")
    print("\n".join(rows))
    return {"ours": total, "interpolator": t_itp, "interpolator_difference": itp_diff,
            "coordinates": t_ours, "delaunay": t_del, "qhull": t_qhull,
            "peer": t_peer,
            "difference": float(diff.max()), "differing": int((diff > 1e-10).sum()),
            "differing_peer_imprecise": peer_off,
            "linear_ours": lin_ours, "linear_peer": lin_peer}


if __name__ == "__main__":
    main()
