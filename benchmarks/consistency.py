"""Consistent integration: gradient smoothing against Gauss rules, P1 and P2.

Prints the tables of docs/verification.md (sections 1-3 and 6) for the
default natural-neighbour basis (gradients smoothed over three cells per
Delaunay triangle, :mod:`skfem_nem.basis.smoothing`) next to Gauss quadrature of
the gradients with 3, 6 and 13 points per triangle and scikit-fem's P1 and P2
on the same triangles (section 4 also the quadratic natural-neighbour velocity,
``ElementNaturalNeighbour2``, up to 8,000 nodes):

1. Poisson, u = sin(pi x) sin(pi y), the uniform and graded node sets of
   ``examples/ex04_nem_vs_fem.py``, 250 -> 64,000 nodes: L2 and H1 errors,
   rates between levels, seconds (basis + assembly + direct solve);
2. the cost to reach an H1 error (log-log interpolation between levels);
3. linear patch tests (Laplace and plane elasticity; random, graded and
   thin-triangle node sets in 2D; random nodes in the unit cube in 3D):
   largest nodal error over the largest value;
4. Stokes, Donea-Huerta's manufactured flow (no slip), 500 -> 32,000 nodes:
   velocity and pressure L2 errors for the default NEM pair, the same pair
   with the 6-point Gauss rule (the former default), scikit-fem's MINI
   element and Taylor-Hood on the same triangles; the numerical inf-sup
   constant of the NEM pair; the spurious flow of a uniform prestress.

Times are wall-clock seconds, the best of ``--repeat`` runs, on whatever
threads numba uses; run on an otherwise idle machine.

    python benchmarks/consistency.py [--sizes 250 1000 4000 16000 64000]
        [--stokes-sizes 500 2000 8000 32000] [--repeat 2] [--only poisson patch stokes]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from skfem import (Basis, BilinearForm, ElementTriMini, ElementTriP1, ElementVector, LinearForm,
                   condense, solve)
from skfem.helpers import ddot, div, dot, sym_grad

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from ex04_nem_vs_fem import error_basis, errors, laplace, load, make_basis, node_set  # noqa: E402
from helpers import cube_nodes  # noqa: E402
from test_consistency import (_stokes_l2p as _l2p, _stokes_l2u as _l2u,  # noqa: E402
                              elasticity_patch_error, graded, laplace_patch_error, thin)

from skfem_nem import (ElementNaturalNeighbour, ElementNaturalNeighbour2,  # noqa: E402
                       NaturalNeighbourBasis, delaunay_mesh)
from skfem_nem.models.analytic import DoneaHuerta  # noqa: E402
from skfem_nem.geometry.nodesets import box_nodes  # noqa: E402
from skfem_nem.models.stokes import inf_sup_constant, solve_stokes, stokes_spaces  # noqa: E402

POISSON_METHODS = ("NEM", "NEM-3", "NEM-6", "NEM-13", "P1", "P2")
#: the quadratic natural-neighbour velocity up to this many nodes: its direct solves grow
#: steeply (a viscous row holds 200 entries, Taylor-Hood's 22: 62 s at 8,283 nodes here,
#: 313 s and 7.2 GB for SolCx at 16,430 nodes). Its Poisson study is
#: examples/ex21_quadratic.py
QUADRATIC_MAX_NODES = 8000


def rate(n0, n1, e0, e1):
    return -2.0 * np.log(e1 / e0) / np.log(n1 / n0)


def best_time(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


# ---------------------------------------------------------------------------
# 1-2. Poisson
# ---------------------------------------------------------------------------

def poisson(sizes, repeat):
    rows = []
    for kind in ("uniform", "graded"):
        for n in sizes:
            p = node_set(kind, n)
            mesh = delaunay_mesh(p)
            nem7 = error_basis(mesh, "NEM")
            for m in POISSON_METHODS:
                def run():
                    b = make_basis(mesh, m)
                    return solve(*condense(laplace.assemble(b), load.assemble(b),
                                           D=b.get_dofs())), b
                sec, (u, b) = best_time(run, repeat)
                e0, e1 = errors(nem7 if m.startswith("NEM") else error_basis(mesh, m), u)
                rows.append(dict(kind=kind, method=m, nodes=len(p), dofs=b.N, l2=e0, h1=e1,
                                 seconds=sec))
                print(f"# poisson {kind} {len(p)} {m}: {e0:.3e} {e1:.3e} {sec:.3f}s",
                      file=sys.stderr, flush=True)
    return rows


def poisson_table(rows):
    out = ["| nodes | method | nodes | dofs | L2 error | rate | H1 error | rate | seconds |",
           "|---|---|---|---|---|---|---|---|---|"]
    for kind in ("uniform", "graded"):
        for m in POISSON_METHODS:
            rs = [r for r in rows if r["kind"] == kind and r["method"] == m]
            for i, r in enumerate(rs):
                r0 = rs[i - 1] if i else None
                rl = f"{rate(r0['nodes'], r['nodes'], r0['l2'], r['l2']):.2f}" if r0 else ""
                rh = f"{rate(r0['nodes'], r['nodes'], r0['h1'], r['h1']):.2f}" if r0 else ""
                out.append(f"| {kind} | {m} | {r['nodes']} | {r['dofs']} | {r['l2']:.3e} | {rl} "
                           f"| {r['h1']:.3e} | {rh} | {r['seconds']:.3f} |")
    return "\n".join(out)


def cost_table(rows, targets=(("h1", 0.05), ("h1", 0.03), ("l2", 3e-4))):
    """Dofs and seconds to reach each target, by log-log interpolation."""
    head = " | ".join(f"dofs, seconds for {n.upper()} {t:g}" for n, t in targets)
    out = [f"| nodes | method | {head} |", "|---|---|" + "---|" * len(targets)]
    for kind in ("uniform", "graded"):
        for m in POISSON_METHODS:
            rs = [r for r in rows if r["kind"] == kind and r["method"] == m]
            cells = []
            for norm, t in targets:
                e = [r[norm] for r in rs]
                if e[0] <= t:
                    cells.append(f"<= {rs[0]['dofs']}, <= {rs[0]['seconds']:.3f}")
                    continue
                for i in range(len(e) - 1):
                    if e[i] > t >= e[i + 1]:
                        s = np.log(t / e[i]) / np.log(e[i + 1] / e[i])
                        d, sec = (np.exp((1 - s) * np.log(rs[i][k]) + s * np.log(rs[i + 1][k]))
                                  for k in ("dofs", "seconds"))
                        cells.append(f"{d:.0f}, {sec:.3f}")
                        break
                else:
                    cells.append("not reached")
            out.append(f"| {kind} | {m} | " + " | ".join(cells) + " |")
    return "\n".join(out)


# ---------------------------------------------------------------------------
# 3. patch tests
# ---------------------------------------------------------------------------

def patch_table():
    sets2 = {"random (2,000)": box_nodes(2000, seed=4), "graded (2,000)": graded(2000),
             "thin (41 x 5)": thin()}
    rules2 = (("smoothed", {}), ("Gauss 3", {"npoints": 3}), ("Gauss 6", {"npoints": 6}),
              ("Gauss 13", {"npoints": 13}))
    vec = ElementVector(ElementNaturalNeighbour())
    out = ["| dim | nodes | problem | " + " | ".join(r for r, _ in rules2) + " |",
           "|---|---|---|" + "---|" * len(rules2)]
    for name, p in sets2.items():
        mesh = delaunay_mesh(p)
        lap = [laplace_patch_error(NaturalNeighbourBasis(mesh, **kw), p) for _, kw in rules2]
        ela = [elasticity_patch_error(NaturalNeighbourBasis(mesh, vec, **kw), p)
               for _, kw in rules2]
        out.append(f"| 2D | {name} | Laplace | " + " | ".join(f"{e:.1e}" for e in lap) + " |")
        out.append(f"| 2D | {name} | elasticity | " + " | ".join(f"{e:.1e}" for e in ela) + " |")
    p = cube_nodes(300, per_face=25)
    mesh = delaunay_mesh(p)
    rules3 = (("smoothed", {}), ("Gauss 4 (intorder 2)", {"intorder": 2}),
              ("Gauss 11 (intorder 4)", {"intorder": 4}))
    lap = [laplace_patch_error(NaturalNeighbourBasis(mesh, **kw), p) for _, kw in rules3]
    ela = [elasticity_patch_error(NaturalNeighbourBasis(mesh, vec, **kw), p) for _, kw in rules3]
    out.append("")
    out.append(f"3D, random nodes in the unit cube ({len(p)}): "
               + ", ".join(f"{r}: Laplace {a:.1e}, elasticity {b:.1e}"
                           for (r, _), a, b in zip(rules3, lap, ela)))
    return "\n".join(out)


# ---------------------------------------------------------------------------
# 4. Stokes
# ---------------------------------------------------------------------------

@BilinearForm
def _visc(u, v, w):
    return 2.0 * ddot(sym_grad(u), sym_grad(v))


@BilinearForm
def _bdiv(u, q, w):
    return -div(u) * q


@LinearForm
def _rhs(v, w):
    return dot(DoneaHuerta.force(w.x), v)


def _mini(mesh):
    """scikit-fem's MINI element (P1 + bubble / P1), direct solve; (u, p, ubasis)."""
    ub = Basis(mesh, ElementVector(ElementTriMini()), intorder=4)
    pb = ub.with_element(ElementTriP1())
    mean = LinearForm(lambda q, w: q).assemble(pb)
    K = sp.bmat([[_visc.assemble(ub), _bdiv.assemble(ub, pb).T, None],
                 [_bdiv.assemble(ub, pb), None, mean[:, None]],
                 [None, mean[None, :], None]], "csr")
    F = np.r_[_rhs.assemble(ub), np.zeros(pb.N + 1)]
    x = solve(*condense(K, F, D=ub.get_dofs().all()))
    return x[:ub.N], x[ub.N:ub.N + pb.N], ub


def stokes(sizes, repeat):
    rows = []
    for n in sizes:
        mesh = delaunay_mesh(box_nodes(n, seed=1))
        vb = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour()), npoints=7)
        vb2 = NaturalNeighbourBasis(mesh, ElementVector(ElementNaturalNeighbour2()), npoints=7)
        pe = Basis(mesh, ElementTriP1(), intorder=4)
        for label, kw in (("NEM (smoothed)", {}), ("NEM Gauss-6", {"npoints": 6}),
                          ("NEM2 (smoothed)", {"method": "nem2"}),
                          ("Taylor-Hood", {"method": "taylor-hood"})):
            if label.startswith("NEM2") and n > QUADRATIC_MAX_NODES:
                continue

            def run():
                return solve_stokes(stokes_spaces(mesh, **kw), 1.0, DoneaHuerta.force,
                                    free_slip=None, no_slip="all", tol=1e-12)
            sec, s = best_time(run, repeat)
            ub = (vb2 if label.startswith("NEM2") else vb if label.startswith("NEM")
                  else Basis(mesh, s.spaces.ubasis.elem, intorder=6))
            eu = np.sqrt(_l2u.assemble(ub, u=ub.interpolate(s.u)))
            ep = np.sqrt(_l2p.assemble(pe, p=pe.interpolate(s.p)))
            rows.append(dict(method=label, nodes=mesh.nvertices, u=eu, p=ep, seconds=sec))
        sec, (u, p, ub) = best_time(lambda: _mini(mesh), repeat)
        ue = Basis(mesh, ub.elem, intorder=6)
        rows.append(dict(method="MINI (scikit-fem)", nodes=mesh.nvertices, seconds=sec,
                         u=np.sqrt(_l2u.assemble(ue, u=ue.interpolate(u))),
                         p=np.sqrt(_l2p.assemble(pe, p=pe.interpolate(p)))))
        print(f"# stokes {n} done", file=sys.stderr, flush=True)
    return rows


def stokes_table(rows):
    out = ["| method | nodes | velocity L2 | rate | pressure L2 | rate | seconds |",
           "|---|---|---|---|---|---|---|"]
    for m in dict.fromkeys(r["method"] for r in rows):
        rs = [r for r in rows if r["method"] == m]
        for i, r in enumerate(rs):
            r0 = rs[i - 1] if i else None
            ru = f"{rate(r0['nodes'], r['nodes'], r0['u'], r['u']):.2f}" if r0 else ""
            rp = f"{rate(r0['nodes'], r['nodes'], r0['p'], r['p']):.2f}" if r0 else ""
            out.append(f"| {m} | {r['nodes']} | {r['u']:.3e} | {ru} | {r['p']:.3e} | {rp} "
                       f"| {r['seconds']:.2f} |")
    return "\n".join(out)


def stokes_extras():
    lines = ["| nodes | inf-sup NEM (smoothed) | inf-sup NEM Gauss-6 | inf-sup NEM2 | "
             "inf-sup Taylor-Hood |", "|---|---|---|---|---|"]
    for n in (100, 200, 400, 900):
        mesh = delaunay_mesh(box_nodes(n, seed=3))
        vals = [inf_sup_constant(stokes_spaces(mesh, **kw))
                for kw in ({}, {"npoints": 6}, {"method": "nem2"}, {"method": "taylor-hood"})]
        lines.append(f"| {mesh.nvertices} | " + " | ".join(f"{v:.3f}" for v in vals) + " |")
    mesh = delaunay_mesh(box_nodes(800, seed=3))
    lines += ["", "| uniform prestress, 800 nodes, no slip | largest velocity |", "|---|---|"]
    for label, kw in (("NEM (smoothed)", {}), ("NEM Gauss-3", {"npoints": 3}),
                      ("NEM Gauss-6", {"npoints": 6}), ("NEM Gauss-13", {"npoints": 13}),
                      ("NEM2 (smoothed)", {"method": "nem2"})):
        S = stokes_spaces(mesh, **kw)
        tau0 = np.array([[0.3, 0.2], [0.2, -0.1]])[:, :, None, None] + np.zeros(
            (2, 2) + S.ubasis.dx.shape)
        s = solve_stokes(S, 1.0, 0.0, tau0=tau0, free_slip=None, no_slip="all", tol=1e-13)
        lines.append(f"| {label} | {np.abs(s.u).max():.1e} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[250, 1000, 4000, 16000, 64000])
    ap.add_argument("--stokes-sizes", type=int, nargs="+", default=[500, 2000, 8000, 32000])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", nargs="+", choices=("poisson", "patch", "stokes"),
                    default=("poisson", "patch", "stokes"))
    a = ap.parse_args(argv)
    # numba compilation outside the timings
    warm = delaunay_mesh(box_nodes(60, seed=0))
    for m in POISSON_METHODS[:4]:
        laplace.assemble(make_basis(warm, m))
    solve_stokes(stokes_spaces(warm), 1.0, DoneaHuerta.force, free_slip=None, no_slip="all")
    if "poisson" in a.only:
        rows = poisson(a.sizes, a.repeat)
        print("### Poisson\n")
        print(poisson_table(rows))
        print("\n### Cost to reach an error\n")
        print(cost_table(rows))
        print()
    if "patch" in a.only:
        print("### Patch tests: largest nodal error / largest value\n")
        print(patch_table())
        print()
    if "stokes" in a.only:
        print("### Stokes, Donea-Huerta\n")
        print(stokes_table(stokes(a.stokes_sizes, a.repeat)))
        print()
        print(stokes_extras())


if __name__ == "__main__":
    main()
