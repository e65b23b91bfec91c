"""Prandtl's punch: the von Mises limit load on natural-neighbour velocity.

A rigid flat punch of half-width a = 1 is pushed with velocity V into a
rigid-plastic von Mises half-space (plane strain, shear yield stress k =
sigma0 / sqrt(3)), modelled as the box [-5, 5] x [-4, 0] with the punch on
the top side, traction-free elsewhere on top, no slip on the other walls.
The material is elastic-perfectly plastic (shear modulus ``mu``, von Mises
yield, incompressible), loaded by pushing the punch in increments (one
:func:`skfem_nem.models.rheology.vep_step` per increment: the incremental elastic
step with return mapping and Picard iterations); the load comes from the
reaction forces of the prescribed punch velocity. The mean punch pressure
rises elastically and levels off at the limit load; Prandtl's solution is
``(2 + pi) k``.
"""
from pathlib import Path

import numpy as np

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.rheology import Material, vep_step
from skfem_nem.models.stokes import stokes_spaces

K = 1.0          # shear yield stress
V = 1.0          # punch velocity
A = 1.0          # punch half-width
PRANDTL = 2 + np.pi


def nodes(n=2500, seed=0):
    """Nodes graded towards the punch edges (x = +-1, z = 0)."""
    def density(p):
        d = np.minimum(np.hypot(p[:, 0] - A, p[:, 1]), np.hypot(p[:, 0] + A, p[:, 1]))
        return 1.0 / (1.0 + d / 0.15)

    top = np.linspace(-5, 5, 161)[:, None] * [1, 0] + [0, 0]
    return box_nodes(n, 10.0, 4.0, density=density, seed=seed, origin=(-5.0, -4.0),
                     lines=[top], boundary_spacing=0.25)


def setup(n=2500, seed=0):
    """Mesh, spaces and the prescribed punch/wall dofs."""
    mesh = delaunay_mesh(nodes(n, seed))
    sp_ = stokes_spaces(mesh, "nem")
    P = mesh.p
    nd = sp_.ubasis.dofs.nodal_dofs
    top = np.flatnonzero(np.abs(P[1]) < 1e-12)
    under = top[np.abs(P[0, top]) <= A + 1e-12]
    walls = np.flatnonzero((np.abs(P[0]) > 5 - 1e-12) | (P[1] < -4 + 1e-12))
    dofs = np.concatenate([nd[0, under], nd[1, under], nd[0, walls], nd[1, walls]])
    vals = np.concatenate([0 * under, -V + 0 * under, 0 * walls, 0 * walls]).astype(float)
    return mesh, sp_, (dofs, vals), nd[1, under]


def load_curve(n=2500, mu=100.0, steps=24, du=0.004, seed=0, verbose=True):
    """Elastic-perfectly plastic punch pushed in ``steps`` increments of
    ``du`` (punch displacement, units of a): rows of displacement and mean
    punch pressure / k (the load-displacement curve)."""
    mesh, sp_, bc, zdofs = setup(n, seed)
    ne, nq = sp_.quadrature_points.shape[1:]
    mat = Material(viscosity=np.inf, shear_modulus=mu, yield_stress=K)
    tau = np.zeros((2, 2, ne, nq))
    eta_guess = None
    rows = [dict(displacement=0.0, load=0.0, iterations=0, yielded=0)]
    dt = du / V
    for k in range(1, steps + 1):
        r = vep_step(sp_, mat, tau, dt, prescribed=bc, free_slip=None, no_slip=None,
                     pressure_mean=False, tol=1e-5, maxiter=300, rotation="none",
                     eta_guess=eta_guess)
        tau, eta_guess = r.tau, r.eta_eff
        F = -r.solution.info["reaction"][zdofs].sum()
        q = F / (2 * A) / K
        rows.append(dict(displacement=k * du, load=q, iterations=r.iterations,
                         yielded=int(r.yielded.sum())))
        if verbose:
            print(f"displacement {k * du:.4f}  mean pressure / k {q:.4f} "
                  f"({q / PRANDTL - 1:+.2%} of Prandtl)  Picard {r.iterations}  "
                  f"yielded points {int(r.yielded.sum())}", flush=True)
    return rows


FIGURE = "out/ex11_prandtl_punch.png"


def visualize(rows, path=FIGURE):
    """The load curve against Prandtl's limit load; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4))
    d = np.array([r["displacement"] for r in rows])
    q = np.array([r["load"] for r in rows])
    ax.plot(d, q, "o-", label="NEM, elastic-perfectly plastic")
    ax.axhline(PRANDTL, color="k", ls="--", label="Prandtl (2 + pi) k")
    ax.set_xlabel("punch displacement / a")
    ax.set_ylabel("mean punch pressure / k")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    rows = load_curve()
    visualize(rows)
    print("wrote", FIGURE)
