"""What a local basis update costs against a rebuilt basis, as the changed region grows.

Nodes: ``n`` uniform random in the unit square plus jittered nodes on its sides and the
corners (seed 0). One step of a :class:`~skfem_nem.LagrangianMesh` in a rotation confined to
a disc of radius ``R`` about the centre (angular speed ``(1 - r / R)^2``, zero outside: the
nodes outside stand still), with ``dt`` moving the fastest node by about 0.3 of the mean
spacing (flips follow). Then, on the new mesh (a fresh ``MeshTri`` for every repetition, so
that neither reuses the other's work; the mesh's own triangulation, which
:func:`~skfem_nem.geometry.meshes.triangulation_of` finds for any basis on it, is built
with its table of circumcircles before the clock starts and reported apart), best of ``--repeat``:

* ``update``: ``old.updated(mesh)`` from the basis of the mesh before the step
  (:meth:`~skfem_nem.NaturalNeighbourBasis.updated`), split into the recomputation of the
  ``k`` triangles whose stencils may have changed and the rest (copying the kept rows, the
  stencils, scikit-fem's mapping and dofs of the new mesh: linear in the triangles, at
  memory speed);
* ``rebuild``: ``NaturalNeighbourBasis(mesh)``.

The Laplace matrix is carried too: ``updated_matrix`` (the recomputed triangles'
contributions replaced) against ``laplace.assemble`` on the rebuilt basis.

The disc radii give ``k`` from a few hundred triangles up; ``all`` moves every node by the
cellular vortex ``psi = sin(pi x) sin(pi y) / pi`` instead; the recomputation's
microseconds per recomputed triangle stay flat (cost O(k)). Prints a markdown table::

    python benchmarks/basis_update.py --nodes 10000 100000 --radii 0.02 0.05 0.1 0.2 all
"""
import argparse
import time

import numpy as np
from skfem import BilinearForm, MeshTri
from skfem.helpers import dot, grad

from skfem_nem import LagrangianMesh, NaturalNeighbourBasis
from skfem_nem.basis.updates import updated_matrix
from skfem_nem.geometry.meshes import triangulation_of


@BilinearForm
def laplace(u, v, w):
    return dot(grad(u), grad(v))


def square(n, seed=0):
    """n random nodes, about sqrt(n) jittered nodes per side, the corners."""
    rng = np.random.default_rng(seed)
    k = int(np.sqrt(n))
    s = (np.arange(1, k) + 0.3 * rng.random(k - 1)) / k
    z, o = 0 * s, 1 + 0 * s
    return np.r_[[[0, 0], [1, 0], [1, 1], [0, 1]], np.c_[s, z], np.c_[s, o], np.c_[z, s],
                 np.c_[o, s], rng.random((n, 2))]


def cellular(x):
    """The cellular vortex psi = sin(pi x) sin(pi y) / pi: every node moves, none leaves."""
    X, Y = np.pi * x[:, 0], np.pi * x[:, 1]
    return np.c_[np.sin(X) * np.cos(Y), -np.cos(X) * np.sin(Y)]


def disc_vortex(radius):
    if radius == "all":
        return cellular

    def v(x):
        dx, dy = x[:, 0] - 0.5, x[:, 1] - 0.5
        s = np.clip(1.0 - np.hypot(dx, dy) / radius, 0.0, None) ** 2
        return np.c_[-dy * s, dx * s]
    return v


def measure(n, radius, repeat):
    """One row: k, the update's parts and the rebuild, best of ``repeat``."""
    lm = LagrangianMesh(square(n))
    old = NaturalNeighbourBasis(lm.mesh)
    # the fastest node (at r = R / 3; speed 1 in the cellular vortex) moves 0.3 spacings
    dt = 0.3 / np.sqrt(lm.nodes.shape[0]) / (1.0 if radius == "all" else 4 / 27 * radius)
    flips = lm.advance(disc_vortex(radius), dt)["flips"]
    p, t = lm.mesh.p, lm.mesh.t
    A = laplace.assemble(old)
    update, recompute, rebuild, adopt = np.inf, np.inf, np.inf, np.inf
    mat_update, assemble = np.inf, np.inf
    for _ in range(repeat):
        mesh, t0 = MeshTri(p, t, sort_t=False), time.perf_counter()
        triangulation_of(mesh).circumcircles
        adopt = min(adopt, time.perf_counter() - t0)
        new = old.updated(mesh)
        r = new.update_report
        update = min(update, r["seconds"])
        recompute = min(recompute, r["recompute_seconds"])
        mesh = MeshTri(p, t, sort_t=False)
        triangulation_of(mesh).circumcircles
        t0 = time.perf_counter()
        fresh = NaturalNeighbourBasis(mesh)
        rebuild = min(rebuild, time.perf_counter() - t0)
        t0 = time.perf_counter()
        updated_matrix(laplace, A, old, new)
        mat_update = min(mat_update, time.perf_counter() - t0)
        t0 = time.perf_counter()
        laplace.assemble(fresh)
        assemble = min(assemble, time.perf_counter() - t0)
    nt = t.shape[1]
    k = r["recomputed"]
    return {"nodes": p.shape[1], "triangles": nt, "radius": radius, "flips": flips,
            "k": k, "update": update, "recompute": recompute, "rest": update - recompute,
            "rebuild": rebuild, "adopt": adopt, "mat_update": mat_update, "assemble": assemble,
            "us_per_k": 1e6 * recompute / max(k, 1),
            "rest_ns_per_triangle": 1e9 * (update - recompute) / nt}


def table(rows):
    head = ("| nodes | triangles | disc radius | flips | recomputed k | k / triangles "
            "| update s | of which recompute s | rest s | rebuild s | rebuild / update "
            "| recompute us per k | rest ns per triangle | mesh's triangulation s "
            "| matrix update s | assembly s |")
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        out.append(f"| {r['nodes']:,} | {r['triangles']:,} | {r['radius']} | {r['flips']:,} "
                   f"| {r['k']:,} | {r['k'] / r['triangles']:.3f} | {r['update']:.3f} "
                   f"| {r['recompute']:.3f} | {r['rest']:.3f} | {r['rebuild']:.3f} "
                   f"| {r['rebuild'] / r['update']:.1f} | {r['us_per_k']:.1f} "
                   f"| {r['rest_ns_per_triangle']:.0f} | {r['adopt']:.3f} "
                   f"| {r['mat_update']:.3f} | {r['assemble']:.3f} |")
    return "\n".join(out)


def radius_arg(text):
    if text == "all":
        return text
    r = float(text)
    if not 0 < r <= 0.5:
        raise argparse.ArgumentTypeError(f"a disc radius in (0, 0.5] or 'all', got {text!r}")
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[10000, 100000])
    ap.add_argument("--radii", type=radius_arg, nargs="+", default=[0.02, 0.05, 0.1, 0.2, "all"],
                    help="disc radii (at most 0.5), or 'all' for the cellular vortex")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    measure(2000, 0.2, 1)  # compile the kernels
    rows = [measure(n, R, args.repeat) for n in args.nodes for R in args.radii]
    print(table(rows))
    return rows


if __name__ == "__main__":
    main()
