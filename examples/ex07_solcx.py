"""SolCx: Stokes flow with a viscosity jump of 1e6, NEM against Taylor-Hood.

The unit square, density ``sin(pi z) cos(pi x)``, viscosity 1 for x < 0.5
and 1e6 beyond, free slip on all walls (Zhong 1996; Duretz et al. 2011).
The analytic solution is :class:`skfem_nem.models.analytic.SolCx`. Random nodes,
with a row of nodes on the interface x = 0.5 joined as segments: the
natural-neighbour velocity is then constrained (it may kink across the
interface, as the exact one does). Natural-neighbour velocity (with
bubbles) and P1 pressure, the quadratic natural-neighbour velocity (``"nem2"``:
P2's unknowns) and P1 pressure, and scikit-fem's Taylor-Hood (P2-P1) are solved
on the same triangles. Prints the L2 errors of velocity and pressure (one 7-point
rule for all) and their observed rates, and draws the velocity field, the pressure
and the convergence plot.
"""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from skfem import Basis, ElementTriP1, Functional

from skfem_nem import NaturalNeighbourBasis, delaunay_mesh
from skfem_nem.basis import gauss_rule
from skfem_nem.models.analytic import SolCx
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.stokes import solve_stokes, stokes_spaces

SIZES = (250, 1000, 4000, 16000)


def nodes(n, seed=1):
    """n random nodes in the unit square plus nodes on the walls and on x = 0.5."""
    k = max(2, int(round(np.sqrt(n))))
    z = np.arange(0, k + 1) / k
    return box_nodes(n, lines=[np.c_[0.5 + 0 * z, z]], seed=seed)


def interface_segments(points):
    """The nodes on x = 0.5, bottom to top, joined: the interface as segments."""
    on = np.flatnonzero(points[:, 0] == 0.5)
    on = on[np.argsort(points[on, 1])]
    return np.c_[on[:-1], on[1:]]


def make_mesh(n, seed=1, constrained=True):
    """The triangulation of ``nodes(n, seed)``; with ``constrained`` the interface
    is a named set of segments (``mesh.boundaries["interface"]``), otherwise the
    plain Delaunay triangulation."""
    p = nodes(n, seed)
    if not constrained:
        return delaunay_mesh(p)
    return delaunay_mesh(p, segments={"interface": interface_segments(p)})


def error_spaces(spaces):
    """The velocity and pressure functions of ``spaces`` at the points of the 7-point
    rule (degree 5), the same for every method (natural-neighbour values are exact at
    any point)."""
    rule, ub = gauss_rule(7), spaces.ubasis
    kind = NaturalNeighbourBasis if isinstance(ub, NaturalNeighbourBasis) else Basis
    ub = kind(spaces.mesh, ub.elem, quadrature=rule)
    return SimpleNamespace(ubasis=ub, pbasis=Basis(spaces.mesh, ElementTriP1(), quadrature=rule))


def errors(spaces, s, exact):
    """L2 errors of velocity and pressure against the analytic solution, with the
    quadrature of ``spaces`` (:func:`error_spaces` for the 7-point rule)."""
    @Functional
    def velocity_error(w):
        ue = exact.velocity(w.x)
        return (w["u"][0] - ue[0]) ** 2 + (w["u"][1] - ue[1]) ** 2

    @Functional
    def pressure_error(w):
        return (w["p"] - exact.pressure(w.x)) ** 2

    return (np.sqrt(velocity_error.assemble(spaces.ubasis, u=s.u)),
            np.sqrt(pressure_error.assemble(spaces.pbasis, p=s.p)))


def run(sizes=SIZES, contrast=1e6, methods=("nem", "nem2", "taylor-hood"), seed=1,
        verbose=True, constrained=True):
    """Solve on each node count; returns a list of dict rows."""
    exact = SolCx(1.0, contrast)
    rows = []
    for n in sizes:
        mesh = make_mesh(n, seed, constrained)
        for method in methods:
            spaces = stokes_spaces(mesh, method)
            s = solve_stokes(spaces, exact.viscosity, exact.force)
            eu, ep = errors(error_spaces(spaces), s, exact)
            rows.append(dict(n=mesh.p.shape[1], method=method, h=1 / np.sqrt(mesh.p.shape[1]),
                             u_l2=eu, p_l2=ep, iterations=s.iterations,
                             dofs=spaces.n_velocity + spaces.n_pressure, solution=s))
            if verbose:
                print(f"{mesh.p.shape[1]:6d} {method:12s} u {eu:.3e}  p {ep:.3e}  "
                      f"CG its {s.iterations}", flush=True)
    return rows


def rates(rows, method, key):
    r = [x for x in rows if x["method"] == method]
    h = np.array([x["h"] for x in r])
    e = np.array([x[key] for x in r])
    return np.log(e[1:] / e[:-1]) / np.log(h[1:] / h[:-1])


def table(rows):
    out = ["| nodes | method | dofs | u L2 | rate | p L2 | rate | CG its |",
           "|---|---|---|---|---|---|---|---|"]
    for method in dict.fromkeys(x["method"] for x in rows):
        r = [x for x in rows if x["method"] == method]
        ru, rp = rates(rows, method, "u_l2"), rates(rows, method, "p_l2")
        for i, x in enumerate(r):
            a = f"{ru[i - 1]:.2f}" if i else "-"
            b = f"{rp[i - 1]:.2f}" if i else "-"
            out.append(f"| {x['n']} | {method} | {x['dofs']} | {x['u_l2']:.3e} | {a} | "
                       f"{x['p_l2']:.3e} | {b} | {x['iterations']} |")
    return "\n".join(out)


def visualize(rows, path="out/ex07_solcx.png"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.5))
    finest = [x for x in rows if x["method"] == "nem"][-1]["solution"]
    mesh = finest.spaces.mesh
    v = finest.velocity_at_nodes()
    sp_ = np.hypot(v[:, 0], v[:, 1])
    tc = ax[0].tripcolor(mesh.p[0], mesh.p[1], mesh.t.T, sp_, shading="gouraud")
    step = max(1, mesh.p.shape[1] // 400)
    ax[0].quiver(mesh.p[0, ::step], mesh.p[1, ::step], v[::step, 0], v[::step, 1])
    fig.colorbar(tc, ax=ax[0], label="|u|")
    ax[0].set_title("NEM velocity")
    tp = ax[1].tripcolor(mesh.p[0], mesh.p[1], mesh.t.T, finest.pressure_at_nodes(),
                         shading="gouraud", cmap="RdBu_r")
    fig.colorbar(tp, ax=ax[1], label="p")
    ax[1].set_title("NEM pressure")
    for a in ax[:2]:
        a.set_aspect("equal")
        a.axvline(0.5, color="k", lw=0.5)
    for method, mk in (("nem", "o"), ("nem2", "^"), ("taylor-hood", "s")):
        r = [x for x in rows if x["method"] == method]
        if not r:
            continue
        h = [x["h"] for x in r]
        ax[2].loglog(h, [x["u_l2"] for x in r], mk + "-", label=f"{method} velocity")
        ax[2].loglog(h, [x["p_l2"] for x in r], mk + "--", label=f"{method} pressure")
    ax[2].set_xlabel("h = 1 / sqrt(nodes)")
    ax[2].set_ylabel("L2 error")
    ax[2].legend()
    ax[2].set_title("SolCx, viscosity jump 1e6")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    rows = run()
    print(table(rows))
    print("wrote", visualize(rows))
