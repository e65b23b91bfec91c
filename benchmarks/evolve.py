"""Cost of one step of the evolving mesh, and the numerical diffusion of the remap.

**Cost** (default mode). Nodes: ``n`` uniform random in the unit square plus
about ``sqrt(n)`` jittered nodes on each side and the 4 corners (seed 0).
Velocity: the cellular vortex ``psi = sin(pi x) sin(pi y) / pi`` (divergence
free, no normal flow through the walls, maximum speed 1). Time step:
``dt = 0.1 h`` with ``h = 1 / sqrt(nodes)`` the mean spacing, so the largest
displacement per step is about 0.1 h. Walls: ``"box"``.

For each size (in a fresh process, after a numba warm-up on a small mesh) the
same ``--steps`` steps are run three times from the same start:

* ``move+repair``: :meth:`LagrangianMesh.advance` with no fields (predictor-
  corrector, walls, inversion check, Lawson flips, minimum angle);
* ``+cons`` / ``+avg``: the same with one 3-component integration-point field
  (a stress tensor) remapped by the ``"conservative"`` / ``"average"`` rule.

Reported per step (median over the steps): wall time of ``advance``, and the
same without the velocity callback (the callback's own time, summed over its
1 + iterations calls per step, is subtracted: that is the library's share).
Also flips per step, substeps beyond the first and relocated nodes (totals),
the one-off construction of the ``LagrangianMesh``, the rebuild with
``scipy.spatial.Delaunay`` on the same nodes (the current nodes after the
first, middle and last ``+cons`` step, interleaved with the steps so that both
see the same machine load; median; CPU times are printed too) and the time to
form the NEM stiffness matrix on the same (initial) mesh:
``NaturalNeighbourBasis(lm.mesh, ElementVector(ElementNaturalNeighbour()))``
plus ``linear_elasticity(*lame_parameters(1e3, 0.3)).assemble(basis)``. The
stiffness matrix is skipped where the extrapolation from the largest smaller
measured size (linear in the number of nodes; a 1e5-node probe if there is
none) exceeds ``--k-memory`` GB or ``--k-time`` seconds.

The bars: the step (``+cons``, without the velocity callback) at least 5x
faster than the Qhull rebuild at 1e5 nodes, and at most 0.05 of the NEM
matrix formation time at every size where that was measured.

**Diffusion** (``--diffusion``). A time-reversible round trip: nodes (``--nodes``
random + sides, walls ``"box"``) follow the cellular vortex for a time ``T``
and then the reversed vortex for ``T`` (same dt; the trapezoidal predictor-
corrector is time symmetric, so every node returns to its start to round-off
and the triangulation returns to the same Delaunay one). Integration-point
values do not change without flips, so whatever changed is remap diffusion.
Three patterns are carried as the components of one field (the rules act on
each component separately), sampled at the start's integration points:

* ``bump``: a Gaussian exp(-r^2 / (2 s^2)), s = 0.06, centred at (0.5, 0.2)
  (in the sheared ring of the vortex, not its nearly rigid core);
* ``step``: 1 for x < 0.5, 0 otherwise (a line through the vortex centre,
  wound into a spiral by the flow);
* ``linear``: x + 2 y of the initial position (linear in the material, not in
  the deformed mesh).

After the round trip, against the values sampled at the same points: the
relative loss of the peak, the relative change of the L2 norm, the relative L2
error, the range (new extrema), the relative change of the integral, and the
part of that change made by the remap itself (the integral of the field just
after each step's flips minus the integral of the pre-flip field on the moved
triangles; the rest is the Lagrangian transport: values at points, areas
changing between flips). Per flip: divided by the number of flips. A rigid
rotation of a disc of nodes (``walls=None``) is run first as a check: no flips,
the field unchanged.

``peak MB`` is the peak resident memory of the process for that size (the
stiffness matrix included where it was formed).

``--dim 3`` (given first) runs :mod:`evolve_3d` with the options that follow.

Run ``python benchmarks/evolve.py [--sizes 1e4 1e5 1e6] [--steps 10]`` (about
4 minutes, 3 GB) and ``python benchmarks/evolve.py --diffusion [--nodes 1000
4000] [--durations 0.25 0.5 1]`` (about 1 minute). Results: docs/evolution.md.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import time

QHULL_BAR = 5.0
STIFFNESS_BAR = 0.05
A3 = ((2 / 3, 1 / 6, 1 / 6), (1 / 6, 2 / 3, 1 / 6), (1 / 6, 1 / 6, 2 / 3))


# --------------------------------------------------------------------------
# the set-up shared by both modes
# --------------------------------------------------------------------------

def box_nodes(n: int, seed: int = 0):
    """n random nodes in the unit square, ~sqrt(n) jittered nodes per side, the corners."""
    import numpy as np
    rng = np.random.default_rng(seed)
    k = max(2, int(round(np.sqrt(n))))
    s = (np.arange(1, k) + 0.5 * (rng.random((4, k - 1)) - 0.5)) / k
    z, o = np.zeros(k - 1), np.ones(k - 1)
    return np.vstack([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                      np.c_[s[0], z], np.c_[s[1], o], np.c_[z, s[2]], np.c_[o, s[3]],
                      rng.random((n, 2))])


def vortex(x):
    """The cellular vortex psi = sin(pi x) sin(pi y) / pi: (u, v) = (psi_y, -psi_x)."""
    import numpy as np
    X, Y = np.pi * x[:, 0], np.pi * x[:, 1]
    return np.c_[np.sin(X) * np.cos(Y), -np.cos(X) * np.sin(Y)]


def ip_points(lm):
    """(nt, 3, 2) integration points of the current triangles (slot k near vertex k)."""
    import numpy as np
    return np.einsum("kj,tjd->tkd", np.array(A3), lm.nodes[lm.triangles])


def triangle_areas(P, T):
    import numpy as np
    e1, e2 = P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


class TimedVelocity:
    """A velocity callback that adds up its own wall time."""

    def __init__(self, f):
        self.f, self.seconds, self.calls = f, 0.0, 0

    def __call__(self, x):
        s = time.perf_counter()
        v = self.f(x)
        self.seconds += time.perf_counter() - s
        self.calls += 1
        return v


def _peak_mb() -> float:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# --------------------------------------------------------------------------
# cost of a step
# --------------------------------------------------------------------------

def _stiffness_setup():
    from skfem import ElementVector
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from skfem_nem import ElementNaturalNeighbour, NaturalNeighbourBasis
    form = linear_elasticity(*lame_parameters(1e3, 0.3))

    def run(mesh):
        basis = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()))
        return form.assemble(basis)
    return run


def warm_up():
    """Compile / load every numba kernel a step uses, on a small mesh."""
    import numpy as np
    from scipy.spatial import Delaunay

    from skfem_nem import LagrangianMesh
    p = box_nodes(400, seed=1)
    dt = 0.1 / np.sqrt(p.shape[0])
    for remap in ("conservative", "average"):
        lm = LagrangianMesh(p, ip_fields={"s": np.zeros((3, 3))}, remap=remap)
        for _ in range(3):
            lm.advance(vortex, dt)
        try:
            lm.advance(vortex, 30 * dt)  # a large step: the substep and relocation paths
        except ValueError:
            pass
    LagrangianMesh(p).advance(vortex, dt)
    Delaunay(p)
    _stiffness_setup()(LagrangianMesh(p[:60]).mesh)


def run_config(p, steps, remap, budget, qhull=False):
    """``steps`` advances from nodes p; remap None: no fields. With ``qhull``,
    ``scipy.spatial.Delaunay`` is timed on the current nodes after the first,
    middle and last step (interleaved, so that both see the same machine load)."""
    import numpy as np
    from scipy.spatial import Delaunay

    from skfem_nem import LagrangianMesh
    s = time.perf_counter()
    lm = LagrangianMesh(p, remap=remap or "conservative")
    if remap is not None:
        x = ip_points(lm)
        lm.ip_fields["stress"] = np.stack([np.sin(5 * x[..., 0]), np.cos(3 * x[..., 1]),
                                           x.sum(axis=-1)], axis=-1)
    build = time.perf_counter() - s
    dt = 0.1 / np.sqrt(p.shape[0])
    vel = TimedVelocity(vortex)
    wall, excl, cpu, reports, qw, qc = [], [], [], [], [], []
    start = time.perf_counter()
    for i in range(steps):
        v0 = vel.seconds
        c = time.process_time()
        s = time.perf_counter()
        reports.append(lm.advance(vel, dt))
        w = time.perf_counter() - s
        cpu.append(time.process_time() - c - (vel.seconds - v0))
        wall.append(w)
        excl.append(w - (vel.seconds - v0))
        last = i == steps - 1 or time.perf_counter() - start > budget
        if qhull and (i in (0, steps // 2) or last):
            c = time.process_time()
            s = time.perf_counter()
            Delaunay(lm.nodes)
            qw.append(time.perf_counter() - s)
            qc.append(time.process_time() - c)
        if last:
            break
    disp = float(np.abs(lm.nodes - p).max(axis=1).max() / len(reports) / (1 / np.sqrt(p.shape[0])))
    out = {"build_s": build, "steps_done": len(reports), "step_s": float(np.median(wall)),
           "excl_s": float(np.median(excl)), "excl_cpu_s": float(np.median(cpu)),
           "velocity_calls": vel.calls / len(reports),
           "flips": float(np.mean([r["flips"] for r in reports])),
           "substeps": int(sum(r["substeps"] - 1 for r in reports)),
           "relocated": int(sum(r["relocated"] for r in reports)),
           "min_angle": float(reports[-1]["min_angle"]), "disp_h": disp,
           "triangles": int(lm.triangles.shape[0]),
           "delaunay": bool(lm.triangulation.is_delaunay())}
    if qhull:
        out["qhull_s"], out["qhull_cpu_s"] = float(np.median(qw)), float(np.median(qc))
    return out, lm


def run_size(n: int, steps: int, stiffness: bool, budget: float) -> dict:
    warm_up()
    p = box_nodes(n)
    out = {"n": int(p.shape[0]), "steps": steps}
    if stiffness:
        from skfem_nem import LagrangianMesh
        mesh = LagrangianMesh(p).mesh
        gc.collect()
        base = _peak_mb()
        s = time.perf_counter()
        K = _stiffness_setup()(mesh)
        out["stiffness_s"] = time.perf_counter() - s
        out["stiffness_mb"] = _peak_mb() - base
        out["nnz"] = int(K.nnz)
        del K, mesh
        gc.collect()
    for name, remap in (("none", None), ("cons", "conservative"), ("avg", "average")):
        res, lm = run_config(p, steps, remap, budget, qhull=name == "cons")
        out[name] = res
        del lm
        gc.collect()
    out["qhull_s"], out["qhull_cpu_s"] = out["cons"]["qhull_s"], out["cons"]["qhull_cpu_s"]
    out["peak_mb"] = _peak_mb()
    out["load"] = os.getloadavg()[0]
    return out


def _fmt_t(t):
    if t is None:
        return "--"
    if t >= 10:
        return f"{t:.1f}"
    return f"{t:.2f}" if t >= 0.1 else f"{t:.4f}" if t >= 1e-3 else f"{t:.1e}"


def cost_main(a):
    rows, notes = [], []
    k_per_node = None  # (seconds, MB) per node of the stiffness matrix, from the last measurement
    for n in sorted(int(x) for x in a.sizes):
        n_total = box_nodes(n).shape[0] if n <= 10 ** 7 else n
        stiff = True
        if k_per_node is None and n > 2e5:
            probe = _child(["--child", "100000", "--steps", "1", "--budget", "60"])
            k_per_node = (probe["stiffness_s"] / probe["n"], probe["stiffness_mb"] / probe["n"])
        if k_per_node is not None:
            est_s, est_mb = k_per_node[0] * n_total, k_per_node[1] * n_total
            if est_s > a.k_time or est_mb > 1024 * a.k_memory:
                stiff = False
                notes.append(f"{n_total:,} nodes: NEM stiffness matrix skipped, extrapolated "
                             f"{est_s:.0f} s and {est_mb / 1024:.1f} GB (limits {a.k_time:.0f} s, "
                             f"{a.k_memory:.0f} GB)")
        t0 = time.perf_counter()
        r = _child(["--child", str(n), "--steps", str(a.steps), "--budget", str(a.budget)]
                   + ([] if stiff else ["--no-stiffness"]))
        r["elapsed"] = time.perf_counter() - t0
        if "stiffness_s" in r:
            k_per_node = (r["stiffness_s"] / r["n"], r["stiffness_mb"] / r["n"])
        for name in ("none", "cons", "avg"):
            if r[name]["steps_done"] < a.steps:
                notes.append(f"{r['n']:,} nodes, {name}: only {r[name]['steps_done']} of "
                             f"{a.steps} steps within the budget of {a.budget:.0f} s")
        rows.append(r)
    print("| nodes | triangles | flips/step | substeps / relocated | move+repair s/step "
          "| excl. velocity | +cons excl. v | +avg excl. v | LagrangianMesh() s | Qhull rebuild s "
          "| Qhull / (+cons) | NEM K s | (+cons) / K | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        c = r["cons"]["excl_s"]
        K = r.get("stiffness_s")
        print(f"| {r['n']:,} | {r['none']['triangles']:,} | {r['none']['flips']:.1f} "
              f"| {sum(r[k]['substeps'] for k in ('none', 'cons', 'avg'))} / "
              f"{sum(r[k]['relocated'] for k in ('none', 'cons', 'avg'))} "
              f"| {_fmt_t(r['none']['step_s'])} | {_fmt_t(r['none']['excl_s'])} "
              f"| {_fmt_t(c)} | {_fmt_t(r['avg']['excl_s'])} | {_fmt_t(r['none']['build_s'])} "
              f"| {_fmt_t(r['qhull_s'])} | {r['qhull_s'] / c:.1f} | {_fmt_t(K)} "
              f"| {'--' if K is None else f'{c / K:.4f}'} | {r['peak_mb']:,.0f} |")
    print()
    for r in rows:
        print(f"{r['n']:,} nodes: {r['steps']} steps, dt = 0.1 h, largest mean displacement "
              f"per step {r['none']['disp_h']:.3f} h, velocity callback "
              f"{r['none']['velocity_calls']:.1f} calls per step "
              f"({_fmt_t(r['none']['step_s'] - r['none']['excl_s'])} s), min angle after "
              f"{r['none']['min_angle']:.3f} deg, Delaunay after: "
              f"{all(r[k]['delaunay'] for k in ('none', 'cons', 'avg'))}"
              + (f", stiffness {r['stiffness_mb']:,.0f} MB, nnz {r['nnz']:,}" if "nnz" in r else "")
              + f"; CPU time: step (+cons, excl. v) {_fmt_t(r['cons']['excl_cpu_s'])} s, Qhull "
              f"{_fmt_t(r['qhull_cpu_s'])} s, "
              f"ratio {r['qhull_cpu_s'] / r['cons']['excl_cpu_s']:.1f}"
              f"; load average {r['load']:.1f}; process {r['elapsed']:.0f} s")
    for s in notes:
        print(s)
    print()
    at = [r for r in rows if 0.5e5 <= r["n"] <= 2e5]
    if at:
        q = at[0]["qhull_s"] / at[0]["cons"]["excl_s"]
        print(f"verdict: step (conservative remap, without the velocity callback) {q:.1f}x faster "
              f"than a Qhull rebuild at {at[0]['n']:,} nodes (bar >= {QHULL_BAR:.0f}x): "
              f"{'PASS' if q >= QHULL_BAR else 'FAIL'}")
    else:
        print("verdict: Qhull bar not checked (no size near 1e5)")
    ks = [(r["n"], r["cons"]["excl_s"] / r["stiffness_s"]) for r in rows if "stiffness_s" in r]
    if ks:
        worst = max(k for _, k in ks)
        print("verdict: step / NEM matrix formation "
              + ", ".join(f"{k:.4f} at {n:,}" for n, k in ks)
              + f" (bar <= {STIFFNESS_BAR}): {'PASS' if worst <= STIFFNESS_BAR else 'FAIL'}")
    print(f"(median of up to {a.steps} steps per configuration; wall times on a shared machine "
          f"with {_ncpu()} CPUs)")


def _ncpu():
    return len(os.sched_getaffinity(0))


def _child(args):
    res = subprocess.run([sys.executable, __file__] + args, capture_output=True, text=True)
    if res.returncode:
        sys.exit(res.stderr)
    return json.loads(res.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------
# numerical diffusion of the remap
# --------------------------------------------------------------------------

PATTERNS = ("bump", "step", "linear")


def patterns(x):
    """(..., 3) the three test patterns at points x (..., 2)."""
    import numpy as np
    X, Y = x[..., 0], x[..., 1]
    bump = np.exp(-((X - 0.5) ** 2 + (Y - 0.2) ** 2) / (2 * 0.06 ** 2))
    step = (X < 0.5).astype(float)
    return np.stack([bump, step, X + 2 * Y], axis=-1)


def rigid_disc_check(n: int = 2000, turns: float = 1.0, steps: int = 200, seed: int = 0) -> dict:
    """Rigid rotation of a disc of nodes (walls=None) about its centre."""
    import numpy as np

    from skfem_nem import LagrangianMesh
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.random(n)) * 0.5
    a = 2 * np.pi * rng.random(n)
    m = int(np.sqrt(n) * 3)
    b = 2 * np.pi * (np.arange(m) + 0.3 * rng.random(m)) / m
    p = 0.5 + np.r_[np.c_[r * np.cos(a), r * np.sin(a)], 0.5 * np.c_[np.cos(b), np.sin(b)]]
    lm = LagrangianMesh(p, walls=None)
    lm.ip_fields["s"] = patterns(ip_points(lm))
    F0, T0 = lm.ip_fields["s"].copy(), lm.triangles.copy()
    dt = 2 * np.pi * turns / steps
    for _ in range(steps):
        lm.advance(lambda x: np.c_[-(x[:, 1] - 0.5), x[:, 0] - 0.5], dt)
    return {"nodes": p.shape[0], "flips": sum(h["flips"] for h in lm.history),
            "same_triangles": bool(np.array_equal(lm.triangles, T0)),
            "field_unchanged": bool(np.array_equal(lm.ip_fields["s"], F0)),
            "return_error": float(np.abs(lm.nodes - p).max())}


def diffusion_round_trip(n: int = 4000, duration: float = 1.0, remap: str = "conservative",
                         fraction: float = 0.1, seed: int = 0) -> dict:
    """Vortex for ``duration``, reversed vortex for ``duration``; see the module docs."""
    import numpy as np

    from skfem_nem import LagrangianMesh
    p = box_nodes(n, seed)
    lm = LagrangianMesh(p, remap=remap)
    lm.ip_fields["s"] = patterns(ip_points(lm))
    I0 = lm.ip_integral("s")
    F0 = lm.ip_fields["s"].copy()
    T0 = np.sort(np.sort(lm.triangles, axis=1), axis=0)
    dt = fraction / np.sqrt(p.shape[0])
    nsteps = max(1, int(round(duration / dt)))
    remap_dI = np.zeros(3)
    for leg in (1.0, -1.0):
        for _ in range(nsteps):
            T, F = lm.triangles.copy(), lm.ip_fields["s"].copy()
            lm.advance(lambda x: leg * vortex(x), dt)
            # integral of the pre-flip field on the moved triangles vs after the flips
            moved = np.einsum("t,tc->c", triangle_areas(lm.nodes, T), F.mean(axis=1))
            remap_dI += lm.ip_integral("s") - moved
    xq = ip_points(lm)
    exact = patterns(xq)
    F = lm.ip_fields["s"]
    w = np.repeat(triangle_areas(lm.nodes, lm.triangles)[:, None] / 3, 3, axis=1)
    flips = sum(h["flips"] for h in lm.history)
    out = {"remap": remap, "nodes": int(p.shape[0]), "duration": duration, "steps": 2 * nsteps,
           "flips": int(flips), "substeps": int(sum(h["substeps"] - 1 for h in lm.history)),
           "relocated": int(sum(h["relocated"] for h in lm.history)),
           "return_error": float(np.abs(lm.nodes - p).max()),
           "same_delaunay": bool(np.array_equal(
               np.sort(np.sort(lm.triangles, axis=1), axis=0), T0)),
           "patterns": {}}
    I1 = lm.ip_integral("s")
    for c, name in enumerate(PATTERNS):
        f, g = F[..., c], exact[..., c]
        l2, l2e = np.sqrt((w * f * f).sum()), np.sqrt((w * g * g).sum())
        out["patterns"][name] = {
            "peak_loss": float((g.max() - f.max()) / np.abs(g).max()),
            "l2_change": float((l2 - l2e) / l2e),
            "l2_error": float(np.sqrt((w * (f - g) ** 2).sum()) / l2e),
            "range": (float(f.min()), float(f.max())),
            "initial_range": (float(F0[..., c].min()), float(F0[..., c].max())),
            "integral_change": float((I1[c] - I0[c]) / abs(I0[c])),
            "remap_integral_change": float(remap_dI[c] / abs(I0[c])),
        }
    return out


def diffusion_main(a):
    d = rigid_disc_check()
    print(f"rigid rotation of a disc ({d['nodes']} nodes, walls=None, one turn in 200 steps): "
          f"{d['flips']} flips, same triangles: {d['same_triangles']}, field unchanged: "
          f"{d['field_unchanged']} (position error after the turn {d['return_error']:.1e}: "
          f"the trapezoidal rule's phase error, a rotation by a slightly different angle)")
    print()
    runs = [diffusion_round_trip(n, T, remap, a.fraction)
            for n in a.nodes for T in a.durations for remap in ("conservative", "average")]
    print("Totals after the round trip:")
    print()
    print("| nodes | T | rule | steps | flips | pattern | peak loss | L2 norm change | L2 error "
          "| range (initial) | integral change | of which remap |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        for name, m in r["patterns"].items():
            lo, hi = m["range"]
            elo, ehi = m["initial_range"]
            print(f"| {r['nodes']:,} | {r['duration']:g} | {r['remap']} | {r['steps']} "
                  f"| {r['flips']:,} | {name} "
                  f"| {m['peak_loss']:+.2e} | {m['l2_change']:+.2e} | {m['l2_error']:.2e} "
                  f"| [{lo:.3f}, {hi:.3f}] ([{elo:.3f}, {ehi:.3f}]) "
                  f"| {m['integral_change']:+.1e} | {m['remap_integral_change']:+.1e} |")
    print()
    print("Per flip (total / flips):")
    print()
    print("| nodes | T | rule | pattern | peak loss | L2 norm change | L2 error "
          "| remap integral change |")
    print("|---|---|---|---|---|---|---|---|")
    for r in runs:
        f = max(r["flips"], 1)
        for name, m in r["patterns"].items():
            print(f"| {r['nodes']:,} | {r['duration']:g} | {r['remap']} | {name} "
                  f"| {m['peak_loss'] / f:+.1e} "
                  f"| {m['l2_change'] / f:+.1e} | {m['l2_error'] / f:.1e} "
                  f"| {m['remap_integral_change'] / f:+.1e} |")
    print()
    print("h = " + ", ".join(f"{1 / n ** 0.5:.4f} at {n:,} nodes"
                             for n in sorted({r['nodes'] for r in runs}))
          + f"; dt = {a.fraction:g} h, cellular vortex for T then reversed for T; "
          f"substeps {sum(r['substeps'] for r in runs)}, relocated "
          f"{sum(r['relocated'] for r in runs)}; largest return error "
          f"{max(r['return_error'] for r in runs):.1e}; same Delaunay triangulation at the end: "
          f"{all(r['same_delaunay'] for r in runs)}")
    for i in range(0, len(runs), 2):
        c, v = runs[i], runs[i + 1]
        e = {k: (c["patterns"][k]["l2_error"], v["patterns"][k]["l2_error"]) for k in PATTERNS}
        print(f"{c['nodes']:,} nodes, T = {c['duration']:g}: L2 error conservative / average: "
              + ", ".join(f"{k} {x / y:.2f}" for k, (x, y) in e.items())
              + f"; step: conservative range [{c['patterns']['step']['range'][0]:.3f}, "
              f"{c['patterns']['step']['range'][1]:.3f}], average "
              f"[{v['patterns']['step']['range'][0]:.3f}, {v['patterns']['step']['range'][1]:.3f}]")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:2] == ["--dim", "3"]:        # the 3D study has its own script and options
        from evolve_3d import main as main_3d
        return main_3d(argv[2:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dim", type=int, choices=[2], default=2,
                    help="2 (this study) or 3 (given first: benchmarks/evolve_3d.py)")
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--budget", type=float, default=300.0,
                    help="seconds per configuration and size before stopping early")
    ap.add_argument("--k-time", type=float, default=120.0)
    ap.add_argument("--k-memory", type=float, default=8.0)
    ap.add_argument("--diffusion", action="store_true")
    ap.add_argument("--nodes", nargs="+", type=int, default=[1000, 4000],
                    help="random nodes of the diffusion study (plus nodes on the sides)")
    ap.add_argument("--durations", nargs="+", type=float, default=[0.25, 0.5, 1.0])
    ap.add_argument("--fraction", type=float, default=0.1)
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--no-stiffness", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(run_size(a.child, a.steps, not a.no_stiffness, a.budget)))
    elif a.diffusion:
        diffusion_main(a)
    else:
        cost_main(a)


if __name__ == "__main__":
    main()
