"""Sharp viscosity interfaces: constrained natural neighbours against plain ones and Taylor-Hood.

Prints the tables of docs/stokes.md ("Sharp interfaces: constrained natural
neighbours") for three discretisations on the same nodes:

- ``NEM``: natural-neighbour velocity (with bubbles) and P1 pressure on the plain
  Delaunay triangulation (``delaunay_mesh(points)``); its functions
  are C1 across the interface;
- ``C-NEM``: the same pair with the interface nodes joined as segments
  (``delaunay_mesh(points, segments=...)``): constrained natural neighbours, whose
  functions may kink across the interface;
- ``C-NEM2``: the quadratic natural-neighbour velocity (``ElementNaturalNeighbour2``,
  the constrained coordinates in quadratic Bernstein form, dofs at the nodes and edge
  midpoints as P2's) and P1 pressure on the constrained triangles (``method="nem2"``);
- ``Taylor-Hood``: scikit-fem's P2-P1 on the constrained triangles.

Studies:

1. SolCx (viscosity 1 / 1e6 at x = 0.5, free slip; ``examples/ex07_solcx.py``'s
   nodes): velocity and pressure L2 errors (one 7-point rule for all) and rates, and
   the largest nodal pressure error within 2 h of the interface and elsewhere (the exact pressure
   jumps at x = 0.5: interface nodes are compared with the nearer one-sided limit);
   then the velocity error of NEM, C-NEM and C-NEM2 against Taylor-Hood's at the
   same number of velocity unknowns (Taylor-Hood solved on a quarter of the nodes as
   well, its error interpolated log-log in the unknowns; about four velocity
   unknowns of Taylor-Hood per node and component against one; C-NEM2 has Taylor-Hood's
   unknowns on the same triangles).
2. The sinking block (``examples/ex08_sinking_block.py``, the block outline as
   segments): the scaled sinking speed at the block centre against a Taylor-Hood
   reference on four times as many nodes, for viscosity ratios 1e-4 ... 1e4.

    python benchmarks/constrained_interfaces.py [--quick]

``--quick``: SolCx on 250 and 1000 nodes, the block on 800 nodes at three ratios
(a smoke run).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import ex07_solcx  # noqa: E402
import ex08_sinking_block  # noqa: E402

from skfem_nem.models.analytic import SolCx  # noqa: E402
from skfem_nem.models.stokes import solve_stokes, stokes_spaces  # noqa: E402

METHODS = ("NEM", "C-NEM", "C-NEM2", "Taylor-Hood")
#: the Stokes method of each discretisation (all but NEM on the constrained mesh)
KINDS = {"NEM": "nem", "C-NEM": "nem", "C-NEM2": "nem2", "Taylor-Hood": "taylor-hood"}
SOLCX_SIZES = (250, 1000, 4000, 16000)
BLOCK_RATIOS = (1e-4, 1e-2, 1.0, 1e2, 1e4)
QUICK = dict(solcx_sizes=SOLCX_SIZES[:2], block_nodes=800, block_ratios=(1e-4, 1.0, 1e4))


def spaces_for(method, meshes):
    """(spaces, mesh) of a method: meshes = (plain, constrained)."""
    mesh = meshes[0] if method == "NEM" else meshes[1]
    return stokes_spaces(mesh, KINDS[method]), mesh


def nodal_pressure_errors(exact, s, mesh, band):
    """Largest nodal pressure error within ``band`` of x = 0.5 and elsewhere."""
    x = mesh.p
    p = s.pressure_at_nodes()
    left = np.abs(p - exact.pressure(np.stack([np.minimum(x[0], 0.5 - 1e-12), x[1]])))
    right = np.abs(p - exact.pressure(np.stack([np.maximum(x[0], 0.5 + 1e-12), x[1]])))
    e = np.where(x[0] < 0.5, left, np.where(x[0] > 0.5, right, np.minimum(left, right)))
    near = np.abs(x[0] - 0.5) < band
    return float(e[near].max()), float(e[~near].max())


def solcx_row(exact, n, method, meshes):
    spaces, mesh = spaces_for(method, meshes)
    s = solve_stokes(spaces, exact.viscosity, exact.force, maxiter=5000)
    eu, ep = ex07_solcx.errors(ex07_solcx.error_spaces(spaces), s, exact)
    nodes = mesh.p.shape[1]
    near, far = nodal_pressure_errors(exact, s, mesh, 2 / np.sqrt(nodes))
    return dict(n=n, nodes=nodes, method=method, udofs=spaces.n_velocity, u_l2=eu, p_l2=ep,
                p_near=near, p_far=far, iterations=s.iterations)


def solcx_study(sizes=SOLCX_SIZES, contrast=1e6, verbose=False):
    """Rows (dicts) for every method and node count; Taylor-Hood also on n / 4
    (and n / 8 for the smallest n: the walls and the interface keep their nodes)."""
    exact = SolCx(1.0, contrast)
    th_sizes = sorted(set(sizes) | {n // 4 for n in sizes} | {min(sizes) // 8})
    rows = []
    for n in sorted(set(sizes) | set(th_sizes)):
        meshes = (ex07_solcx.make_mesh(n, constrained=False), ex07_solcx.make_mesh(n))
        for method in METHODS:
            if (method == "Taylor-Hood" and n in th_sizes) or n in sizes:
                rows.append(solcx_row(exact, n, method, meshes))
                if verbose:
                    print(rows[-1], file=sys.stderr, flush=True)
    return rows


def of(rows, method, sizes=None):
    return [r for r in rows if r["method"] == method and (sizes is None or r["n"] in sizes)]


def rates(rows, key):
    """Observed orders in h = 1 / sqrt(nodes) between consecutive rows."""
    h = 1 / np.sqrt([r["nodes"] for r in rows])
    e = np.array([r[key] for r in rows])
    return np.log(e[1:] / e[:-1]) / np.log(h[1:] / h[:-1])


def fitted_rate(rows, key):
    """Least-squares order in h = 1 / sqrt(nodes) over all rows."""
    h = 1 / np.sqrt([r["nodes"] for r in rows])
    return float(np.polyfit(np.log(h), np.log([r[key] for r in rows]), 1)[0])


def taylor_hood_at(rows, udofs):
    """Taylor-Hood's velocity error at ``udofs`` unknowns (log-log interpolation
    between its runs; NaN outside them)."""
    th = of(rows, "Taylor-Hood")
    d = np.log([r["udofs"] for r in th])
    e = np.log([r["u_l2"] for r in th])
    x = np.log(udofs)
    return float(np.exp(np.interp(x, d, e))) if d[0] <= x <= d[-1] else np.nan


def solcx_table(rows, sizes):
    out = ["| nodes | method | velocity unknowns | u L2 | rate | p L2 | rate | "
           "max nodal p error, interface band | elsewhere | CG its |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for method in METHODS:
        r = of(rows, method, sizes)
        ru, rp = rates(r, "u_l2"), rates(r, "p_l2")
        for i, x in enumerate(r):
            a, b = (f"{ru[i - 1]:.2f}", f"{rp[i - 1]:.2f}") if i else ("", "")
            out.append(f"| {x['nodes']} | {method} | {x['udofs']} | {x['u_l2']:.3e} | {a} | "
                       f"{x['p_l2']:.3e} | {b} | {x['p_near']:.3e} | {x['p_far']:.3e} | "
                       f"{x['iterations']} |")
    fits = [f"{m} {fitted_rate(of(rows, m, sizes), 'u_l2'):.2f} / "
            f"{fitted_rate(of(rows, m, sizes), 'p_l2'):.2f}" for m in METHODS]
    return "\n".join(out) + "\n\nFitted orders (velocity / pressure): " + ", ".join(fits) + "."


def equal_dofs(rows, sizes):
    """Rows of (nodes, velocity unknowns, NEM / TH, C-NEM / TH, C-NEM2 / TH) error
    ratios (C-NEM2 against Taylor-Hood on its own triangles: the same unknowns)."""
    out = []
    quadratic = {q["n"]: q for q in of(rows, "C-NEM2", sizes)}
    for nem, cnem in zip(of(rows, "NEM", sizes), of(rows, "C-NEM", sizes)):
        th = taylor_hood_at(rows, cnem["udofs"])
        q = quadratic.get(cnem["n"])
        out.append(dict(nodes=cnem["nodes"], udofs=cnem["udofs"], th=th,
                        nem=nem["u_l2"] / th, cnem=cnem["u_l2"] / th,
                        udofs2=q["udofs"] if q else None,
                        cnem2=q["u_l2"] / taylor_hood_at(rows, q["udofs"]) if q else np.nan))
    return out


def equal_dofs_table(rows, sizes):
    out = ["| nodes | velocity unknowns | Taylor-Hood u L2 (interpolated) | NEM / TH | "
           "C-NEM / TH | C-NEM2 unknowns | C-NEM2 / TH |", "|---|---|---|---|---|---|---|"]
    for r in equal_dofs(rows, sizes):
        out.append(f"| {r['nodes']} | {r['udofs']} | {r['th']:.3e} | {r['nem']:.1f} | "
                   f"{r['cnem']:.2f} | {r['udofs2'] or '-'} | "
                   + (f"{r['cnem2']:.2f} |" if r['udofs2'] else "- |"))
    return "\n".join(out)


def block_study(n=3000, ratios=BLOCK_RATIOS, verbose=False):
    """Scaled centre velocities |v_z| eta1 / drho of NEM, C-NEM and Taylor-Hood
    on n nodes, and of the Taylor-Hood reference on 4 n nodes."""
    plain = ex08_sinking_block.make_mesh(n, constrained=False)
    mesh = ex08_sinking_block.make_mesh(n)
    fine = ex08_sinking_block.make_mesh(4 * n, seed=1)
    scale = ex08_sinking_block.G * ex08_sinking_block.L ** 2
    rows = []
    for ratio in ratios:
        w = {m: ex08_sinking_block.centre_velocity(plain if m == "NEM" else mesh,
                                                    KINDS[m], ratio)[0] for m in METHODS}
        w["reference"] = ex08_sinking_block.centre_velocity(fine, "taylor-hood", ratio)[0]
        rows.append(dict(ratio=ratio, nodes=mesh.p.shape[1], ref_nodes=fine.p.shape[1],
                         **{m: abs(v) * scale for m, v in w.items()}))
        if verbose:
            print(rows[-1], file=sys.stderr, flush=True)
    return rows


def block_table(rows):
    out = ["| eta1/eta2 | " + " | ".join(METHODS) + f" | reference ({rows[0]['ref_nodes']} "
           "nodes) | " + " | ".join(f"{m} error" for m in METHODS) + " |",
           "|---" * (2 * len(METHODS) + 2) + "|"]
    for x in rows:
        err = [f"{x[m] / x['reference'] - 1:+.2%}" for m in METHODS]
        out.append(f"| {x['ratio']:.0e} | " + " | ".join(f"{x[m]:.4e}" for m in METHODS)
                   + f" | {x['reference']:.4e} | " + " | ".join(err) + " |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="coarse sizes (a smoke run)")
    ap.add_argument("--verbose", action="store_true", help="print each row as it is done")
    a = ap.parse_args(argv)
    sizes = QUICK["solcx_sizes"] if a.quick else SOLCX_SIZES
    rows = solcx_study(sizes, verbose=a.verbose)
    print("**SolCx, viscosity contrast 1e6**\n")
    print(solcx_table(rows, sizes))
    print("\n**Velocity error against Taylor-Hood at equal velocity unknowns**\n")
    print(equal_dofs_table(rows, sizes))
    n = QUICK["block_nodes"] if a.quick else 3000
    block = block_study(n, QUICK["block_ratios"] if a.quick else BLOCK_RATIOS, a.verbose)
    print(f"\n**Sinking block, {block[0]['nodes']} nodes: |v_z| eta1 / drho (m^2/s)**\n")
    print(block_table(block))


if __name__ == "__main__":
    main()
