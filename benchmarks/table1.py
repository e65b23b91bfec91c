"""The paper's Table 1, reproduced and extended: NEM matrix cost / quadratic FEM matrix cost.

Braun & Sambridge (Nature 1995), Table 1, compare the time to form the natural
element method's elasticity stiffness matrix with the time to form the
quadratic-triangle (6-node) finite element matrix with 3 Gauss points on the
same triangulation: 1.1 / 1.2 / 1.36 at 32 / 200 / 1,800 elements (their
"method 1", DESIGN.md section 5). Building the Delaunay triangulation is
reported separately there, and is here too.

What is measured, for each number of triangles (default about 32, 200, 1,800,
32,768 and 500,000; nodes: uniform random in the unit square plus its 4
corners, seed 0, n = (triangles + 6) / 2 so that the Delaunay triangulation has
exactly 2 n - 6 triangles) and for two problems:

* ``elasticity``: ``linear_elasticity(*lame_parameters(1e3, 0.3))`` with
  ``ElementVector(ElementNaturalNeighbour())`` (NEM, Sibson, the default
  smoothed gradients: three cells per triangle, one point each; and, as the
  column "NEM Gauss-3", the paper's 3-point Gauss rule, ``npoints=3``)
  against ``ElementVector(ElementTriP2())`` and, for reference,
  ``ElementVector(ElementTriP1())`` (``intorder=2``: the same 3-point rule);
* ``laplace``: ``laplace`` with the scalar elements.

The paper's "method 2" column (their Box 1: 2.1 / 2.1 / 2.22) is the same NEM
basis with ``method="lasserre"`` (:mod:`skfem_nem.coordinates.lasserre`: second-order
Voronoi volumes by Lasserre's recursion, on Qhull's triangulation, which is
adopted once per mesh like the method 1 triangulation and not timed).

For each method: wall time of the basis construction (NEM: coordinates +
derivatives at the quadrature points + stencil grouping; FEM: ``Basis(mesh,
elem, intorder=2)``) and of ``form.assemble(basis)``, each the median of
several repeats (at least 3, and until the measured runs add up to
``--min-time`` seconds, at most 1000: hundreds of repeats for the
millisecond runs on 32 and 200 triangles; a run longer than ``--budget``
seconds is not repeated). The
ratio is median(NEM basis + assembly) / median(P2 basis + assembly). The
NEM's one-off adoption of the mesh (``Triangulation`` from the ``MeshTri``
plus its Delaunay check, cached on the mesh) is excluded from the NEM times
and shown in its own column, as the paper reports its triangulation cost
separately. scikit-fem's numbering of the mesh's facets and edges, which P2's dofs
and the NEM's smoothing cells both read and scikit-fem caches on the mesh, is built
before the timing too (at 100,000 nodes in 3D it takes about 5 s, which only the
first of the repeated runs would otherwise pay). Numba compilation is excluded: every
process first runs its method on a tiny mesh. Numba uses its default number of threads unless
``--threads`` is given; scikit-fem's assembly is single threaded.

Peak memory: each (problem, size, method) runs in a fresh subprocess that
loads the mesh from a file written by the parent (so the Delaunay build's
transient peak is not in the child), adopts the triangulation, runs the
warm-up, reads ``ru_maxrss`` (the baseline) and then runs the method; the
peak is the ``ru_maxrss`` increase over the baseline during the first
repeat. It is meaningful only where it is well above the allocator noise
(a few MB).

The process CPU time (all threads) of basis + assembly is recorded too; its
NEM / P2 ratio is printed next to the wall-clock one: it is insensitive to
other processes competing for the cores (the load average is printed), and
it charges the NEM for both cores its parallel coordinate kernel uses.

The bars: ratio NEM / P2 <= 1.0 at every size (consistent integration may
not make the default NEM dearer than quadratic FEM); NEM peak memory <= 2x P2's
(checked where P2's peak is at least 10 MB). A verdict line is printed for each.

``--dim 3`` measures the same on Delaunay tetrahedra (the 3D Table 1 of the paper's
claim that "all the theory described is equally valid in three dimensions"): ``--sizes``
are then numbers of nodes (uniform random in the unit cube plus its 8 corners, seed 0;
default 1,000, 10,000 and 100,000), NEM is the smoothed Box 1 basis (one smoothing cell
per tetrahedron, 4 points), P2 and P1 are ``ElementTetP2`` / ``ElementTetP1`` with
scikit-fem's order-2 rule (4 points), and the columns of the 2D-only variants (Gauss-3,
method 2) are left out.

Run ``python benchmarks/table1.py [--sizes 32 200 1800 32768 500000]
[--problems elasticity laplace] [--min-time 0.5] [--threads N]``. The
whole default run takes 4-7 minutes on 2 cores; the 500,000-triangle NEM
elasticity child peaks near 6 GB. Run it on an otherwise idle machine.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import time

PAPER = {32: 1.1, 200: 1.2, 1800: 1.36}
PAPER2 = {32: 2.1, 200: 2.1, 1800: 2.22}
METHODS = ("nem", "nem3", "nem2", "p2", "p1")
METHODS_3D = ("nem", "p2", "p1")
SIZES_3D = [1000, 10000, 100000]
RATIO_BAR = 1.0
MEMORY_BAR = 2.0
MEMORY_FLOOR_MB = 10.0


def nodes_for(triangles: int) -> int:
    """Nodes (random + 4 corners) whose Delaunay triangulation has ``triangles``."""
    return max(4, (int(triangles) + 7) // 2)


def points(n: int, dim: int = 2):
    """``n`` nodes: the unit square's (cube's) corners and uniform random ones, seed 0."""
    import numpy as np
    rng = np.random.default_rng(0)
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * dim, indexing="ij")).reshape(dim, -1).T
    if dim == 2:
        corners = corners[[0, 2, 1, 3]]     # (0,0), (1,0), (0,1), (1,1) as before
    return np.vstack([corners, rng.random((n - len(corners), dim))])


def _peak_mb() -> float:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def _setup(problem: str, method: str, dim: int = 2):
    """(form, make_basis) for one problem and method."""
    from skfem import (Basis, ElementTetP1, ElementTetP2, ElementTriP1, ElementTriP2,
                       ElementVector)
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    from skfem.models.poisson import laplace

    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis

    vector = problem == "elasticity"
    form = linear_elasticity(*lame_parameters(1e3, 0.3)) if vector else laplace
    p2, p1 = (ElementTetP2, ElementTetP1) if dim == 3 else (ElementTriP2, ElementTriP1)
    base = {"nem": ElementNaturalNeighbour, "nem3": ElementNaturalNeighbour,
            "nem2": ElementNaturalNeighbour, "p2": p2, "p1": p1}[method]()
    elem = ElementVector(base) if vector else base
    if method == "nem":
        return form, lambda mesh: NaturalNeighbourBasis(mesh, elem)
    if method == "nem3":
        return form, lambda mesh: NaturalNeighbourBasis(mesh, elem, npoints=3)
    if method == "nem2":
        return form, lambda mesh: NaturalNeighbourBasis(mesh, elem, method="lasserre")
    return form, lambda mesh: Basis(mesh, elem, intorder=2)


def run_child(meshfile: str, problem: str, method: str, min_time: float, budget: float,
              threads: int | None, max_repeat: int = 1000, dim: int = 2) -> dict:
    import numpy as np
    from skfem import MeshTet, MeshTri

    import skfem_nem
    from skfem_nem.geometry.meshes import adopt as _adopt

    if threads:
        import numba
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    form, make_basis = _setup(problem, method, dim)

    # warm-up on a tiny mesh: numba compilation / cache loading, first-call costs
    tiny = skfem_nem.delaunay_mesh(points(40, dim))
    for _ in range(2):
        form.assemble(make_basis(tiny))

    import numba
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel region has run in this process
        layer = "none"

    with np.load(meshfile) as f:
        mesh = (MeshTet if dim == 3 else MeshTri)(f["p"], f["t"])
    t0 = time.perf_counter()
    _adopt(mesh, "lasserre" if method == "nem2" or dim == 3 else "area")  # cached on the mesh
    t_adopt = time.perf_counter() - t0
    # scikit-fem's numbering of the mesh's facets and edges (cached on the mesh; P2's dofs
    # and the NEM's smoothing cells read it), untimed as the adoption is
    mesh.t2f, mesh.facets
    if dim == 3:
        mesh.t2e, mesh.edges
    gc.collect()
    base_peak, base_rss = _peak_mb(), _rss_mb()

    tb, ta, tc = [], [], []
    out = {"triangles": int(mesh.nelements), "nodes": int(mesh.nvertices),
           "adopt_s": t_adopt, "threading_layer": layer, "baseline_mb": base_peak,
           "baseline_gap_mb": base_peak - base_rss}
    while True:
        c0 = time.process_time()
        s0 = time.perf_counter()
        basis = make_basis(mesh)
        s1 = time.perf_counter()
        K = form.assemble(basis)
        s2 = time.perf_counter()
        tc.append(time.process_time() - c0)
        tb.append(s1 - s0)
        ta.append(s2 - s1)
        if len(tb) == 1:
            out["peak_mb"] = _peak_mb() - base_peak
            out["ndofs"] = int(K.shape[0])
            out["nnz"] = int(K.nnz)
            if method in ("nem", "nem3", "nem2"):
                sz = basis.stencil_sizes
                out["stencil_mean"] = float(sz.mean())
                out["stencil_max"] = int(sz.max())
                out["groups"] = len(basis.groups)
        del basis, K
        if tb[-1] + ta[-1] > 0.05:
            gc.collect()  # free cyclic garbage before the next big run (slow: skip if tiny)
        elapsed = float(np.sum(tb) + np.sum(ta))  # measured time only
        n = len(tb)
        if tb[-1] + ta[-1] > budget:
            break
        if n >= 3 and elapsed >= min_time:
            break
        if n >= max_repeat:
            break
    tot = np.add(tb, ta)
    out.update(repeats=len(tb), basis_s=float(np.median(tb)), assembly_s=float(np.median(ta)),
               total_s=float(np.median(tot)), cpu_s=float(np.median(tc)))
    return out


def _fmt_t(t: float) -> str:
    if t >= 10:
        return f"{t:.1f}"
    if t >= 0.1:
        return f"{t:.2f}"
    if t >= 0.001:
        return f"{t:.4f}"
    return f"{t:.2e}"


def _fmt_mb(m: float) -> str:
    return f"{m:,.0f}" if m >= 10 else f"{m:.1f}"


def table(problem: str, rows: list[dict]) -> list[str]:
    fe = "vector P2" if problem == "elasticity" else "P2"
    p1 = "vector P1" if problem == "elasticity" else "P1"
    lines = [f"### {'2D linear elasticity' if problem == 'elasticity' else 'Scalar Laplace'}: "
             f"NEM (Sibson) vs {fe}, 3-point rule", "",
             f"| triangles | nodes | stencil mean / max | NEM basis s | NEM assembly s "
             f"| {fe} basis s | {fe} assembly s | ratio NEM/P2 | ratio CPU time | paper ratio "
             f"| peak MB NEM / P2 (ratio) | {p1} basis+asm s | NEM mesh adoption s "
             f"| repeats NEM/P2/P1 | method 2 basis+asm s | ratio method 2/P2 "
             f"| paper ratio method 2 | ratio NEM Gauss-3/P2 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        nem, p2, p1r, nem2 = r["nem"], r["p2"], r["p1"], r["nem2"]
        ratio = nem["total_s"] / p2["total_s"]
        mem = f"{_fmt_mb(nem['peak_mb'])} / {_fmt_mb(p2['peak_mb'])}"
        if p2["peak_mb"] >= MEMORY_FLOOR_MB:
            mem += f" ({nem['peak_mb'] / p2['peak_mb']:.2f})"
        paper = PAPER.get(r["target"], None)
        lines.append(
            f"| {nem['triangles']:,} | {nem['nodes']:,} "
            f"| {nem['stencil_mean']:.2f} / {nem['stencil_max']} "
            f"| {_fmt_t(nem['basis_s'])} | {_fmt_t(nem['assembly_s'])} "
            f"| {_fmt_t(p2['basis_s'])} | {_fmt_t(p2['assembly_s'])} "
            f"| {ratio:.2f} | {nem['cpu_s'] / p2['cpu_s']:.2f} "
            f"| {paper if paper is not None else '-'} | {mem} "
            f"| {_fmt_t(p1r['total_s'])} | {_fmt_t(nem['adopt_s'])} "
            f"| {nem['repeats']}/{p2['repeats']}/{p1r['repeats']} "
            f"| {_fmt_t(nem2['total_s'])} | {nem2['total_s'] / p2['total_s']:.2f} "
            f"| {PAPER2.get(r['target'], '-')} | {r['nem3']['total_s'] / p2['total_s']:.2f} |")
    lines.append("")
    ratios = [(r["nem"]["total_s"] / r["p2"]["total_s"], r["nem"]["triangles"]) for r in rows]
    worst = max(ratios)
    ok = worst[0] <= RATIO_BAR
    lines.append(f"- time bar (NEM/P2 <= {RATIO_BAR} at every size): "
                 f"{'PASS' if ok else 'FAIL'} (worst {worst[0]:.2f} at {worst[1]:,} triangles; "
                 f"{sum(x <= RATIO_BAR for x, _ in ratios)}/{len(ratios)} sizes within)")
    mem = [(r["nem"]["peak_mb"] / r["p2"]["peak_mb"], r["nem"]["triangles"]) for r in rows
           if r["p2"]["peak_mb"] >= MEMORY_FLOOR_MB]
    if mem:
        worst = max(mem)
        ok = worst[0] <= MEMORY_BAR
        lines.append(f"- memory bar (NEM peak <= {MEMORY_BAR:g}x P2 peak, sizes where P2 peak "
                     f">= {MEMORY_FLOOR_MB:g} MB): {'PASS' if ok else 'FAIL'} "
                     f"(worst {worst[0]:.2f} at {worst[1]:,} triangles)")
    else:
        lines.append(f"- memory bar: not evaluated (P2 peak below {MEMORY_FLOOR_MB:g} MB "
                     f"at every size)")
    return lines


def table_3d(problem: str, rows: list[dict]) -> list[str]:
    """The 3D table: NEM (smoothed Box 1) against P2 and P1 on the same tetrahedra."""
    fe = "vector P2" if problem == "elasticity" else "P2"
    lines = [f"### 3D {'linear elasticity' if problem == 'elasticity' else 'Laplace'}: "
             f"NEM (Sibson, Box 1, smoothed) vs {fe} on Delaunay tetrahedra", "",
             "| tetrahedra | nodes | stencil mean / max | entries a row NEM / P2 | NEM basis s "
             "| NEM assembly s | P2 basis + assembly s | P1 basis + assembly s | ratio NEM/P2 "
             "| ratio CPU time | peak MB NEM / P2 | NEM mesh adoption s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        nem, p2, p1 = r["nem"], r["p2"], r["p1"]
        lines.append(
            f"| {nem['triangles']:,} | {nem['nodes']:,} "
            f"| {nem['stencil_mean']:.1f} / {nem['stencil_max']} "
            f"| {nem['nnz'] / nem['ndofs']:.0f} / {p2['nnz'] / p2['ndofs']:.0f} "
            f"| {_fmt_t(nem['basis_s'])} | {_fmt_t(nem['assembly_s'])} "
            f"| {_fmt_t(p2['total_s'])} | {_fmt_t(p1['total_s'])} "
            f"| {nem['total_s'] / p2['total_s']:.2f} | {nem['cpu_s'] / p2['cpu_s']:.2f} "
            f"| {_fmt_mb(nem['peak_mb'])} / {_fmt_mb(p2['peak_mb'])} "
            f"| {_fmt_t(nem['adopt_s'])} |")
    lines.append("")
    worst = max((r["nem"]["total_s"] / r["p2"]["total_s"], r["nem"]["nodes"]) for r in rows)
    lines.append(f"- time bar (NEM/P2 <= {RATIO_BAR} at every size): "
                 f"{'PASS' if worst[0] <= RATIO_BAR else 'FAIL'} (worst {worst[0]:.2f} at "
                 f"{worst[1]:,} nodes)")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=None,
                    help="target numbers of triangles (2D; default 32 200 1800 32768 "
                         "500000) or nodes (--dim 3; default 1000 10000 100000)")
    ap.add_argument("--dim", type=int, choices=(2, 3), default=2)
    ap.add_argument("--problems", nargs="+", choices=("elasticity", "laplace"),
                    default=["elasticity", "laplace"])
    ap.add_argument("--min-time", type=float, default=0.5,
                    help="repeat each method until this many seconds (and >= 3 repeats)")
    ap.add_argument("--budget", type=float, default=30.0,
                    help="do not repeat a method whose single run takes longer")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's)")
    ap.add_argument("--child", nargs=3, metavar=("MESHFILE", "PROBLEM", "METHOD"),
                    help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(run_child(*a.child, a.min_time, a.budget, a.threads, dim=a.dim)))
        return
    if a.sizes is None:
        a.sizes = SIZES_3D if a.dim == 3 else [32, 200, 1800, 32768, 500000]
    methods = METHODS_3D if a.dim == 3 else METHODS

    import numpy as np

    import skfem_nem

    load0 = os.getloadavg()
    results = {p: [] for p in a.problems}
    with tempfile.TemporaryDirectory() as tmp:
        for target in a.sizes:
            target = int(target)
            n = target if a.dim == 3 else nodes_for(target)
            mesh = skfem_nem.delaunay_mesh(points(n, a.dim))
            meshfile = os.path.join(tmp, f"mesh{target}.npz")
            np.savez(meshfile, p=mesh.p, t=mesh.t)
            del mesh
            for problem in a.problems:
                row = {"target": target}
                for method in methods:
                    cmd = [sys.executable, __file__, "--child", meshfile, problem, method,
                           "--min-time", str(a.min_time), "--budget", str(a.budget),
                           "--dim", str(a.dim)]
                    if a.threads:
                        cmd += ["--threads", str(a.threads)]
                    res = subprocess.run(cmd, capture_output=True, text=True)
                    if res.returncode:
                        sys.exit(f"{problem} {method} at {target} triangles failed:\n{res.stderr}")
                    row[method] = json.loads(res.stdout.strip().splitlines()[-1])
                    print(f"# {problem} {target:,} {method}: "
                          f"{row[method]['total_s']:.4g} s x{row[method]['repeats']}, "
                          f"+{row[method]['peak_mb']:.0f} MB", file=sys.stderr, flush=True)
                    if row[method]["baseline_gap_mb"] > 20:
                        gap = row[method]['baseline_gap_mb']
                        print(f"# warning: a transient peak {gap:.0f} MB "
                              f"above the resident memory before the run may hide part of its "
                              f"peak", file=sys.stderr)
                results[problem].append(row)

    import numba
    load1 = os.getloadavg()
    layers = sorted({r["nem"]["threading_layer"] for p in a.problems for r in results[p]})
    print(f"numba threads: {a.threads or numba.config.NUMBA_NUM_THREADS} (threading layer "
          f"{'/'.join(layers)}; scikit-fem assembly: 1 thread); {os.cpu_count()} CPUs; "
          f"1-min load average {load0[0]:.2f} at start, {load1[0]:.2f} at end. Times: wall-clock "
          f"medians, seconds; 'ratio CPU time' = median process CPU time (all threads) of NEM "
          f"basis + assembly over P2's, less sensitive to other load.\n")
    for problem in a.problems:
        print("\n".join((table_3d if a.dim == 3 else table)(problem, results[problem])))
        print()


if __name__ == "__main__":
    main()
