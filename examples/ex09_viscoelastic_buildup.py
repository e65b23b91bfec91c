"""Viscoelastic stress build-up in pure shear (Gerya and Yuen 2007), with and without a yield cap.

A Maxwell body (eta = 1e22 Pa s, mu = 1e10 Pa) is shortened at a constant
rate edot = 1e-14 1/s from zero stress. The analytic stress is

    sigma(t) = 2 eta edot (1 - exp(-mu t / eta)),

about 200 MPa after 250 kyr (Maxwell time eta / mu = 31.7 kyr). With a von
Mises yield stress of 100 MPa the stress must flatten at the cap.

The box [0, 1] m^2 with random nodes is driven by the prescribed boundary
velocity (edot x, -edot y); each step is one full natural-neighbour Stokes
solve (:func:`skfem_nem.models.rheology.vep_step`) with the stress history stored at
the quadrature points. Time steps of 1 to 25 kyr measure the error against
dt; the area-weighted mean deviatoric stress sigma_xx is compared with the
analytic curve.
"""
from pathlib import Path

import numpy as np

from skfem_nem import delaunay_mesh
from skfem_nem.models.analytic import viscoelastic_buildup
from skfem_nem.geometry.nodesets import box_nodes
from skfem_nem.models.rheology import Material, deviator, prescribed_velocity, vep_step
from skfem_nem.models.stokes import stokes_spaces

ETA, MU, EDOT, YIELD = 1e22, 1e10, 1e-14, 1e8
KYR = 1e3 * 3.15576e7
T_END = 250 * KYR
DTS_KYR = (25.0, 12.5)        # error study (with DT_CURVE)
DT_CURVE = 6.25                # the plotted curves
N_NODES = 30


def run(spaces, dt, yield_stress=np.inf, t_end=T_END):
    """Times (s), area-mean deviatoric sigma_xx (Pa) and its rms spread over the box."""
    ne, nq = spaces.quadrature_points.shape[1:]
    bc = prescribed_velocity(spaces, "all", lambda x: np.stack([EDOT * x[0], -EDOT * x[1]]))
    mat = Material(ETA, MU, yield_stress)
    dx = np.asarray(spaces.pbasis.dx)
    tau = np.zeros((2, 2, ne, nq))
    ps = np.zeros((ne, nq))
    t, mean, spread = [0.0], [0.0], [0.0]
    for k in range(int(round(t_end / dt))):
        r = vep_step(spaces, mat, tau, dt, prescribed=bc, plastic_strain=ps, tol=1e-4)
        tau, ps = r.tau, r.plastic_strain
        s = deviator(tau)[0, 0]
        m = float((s * dx).sum() / dx.sum())
        t.append((k + 1) * dt)
        mean.append(m)
        spread.append(float(np.sqrt(((s - m) ** 2 * dx).sum() / dx.sum())))
    return np.array(t), np.array(mean), np.array(spread), ps


spaces = stokes_spaces(delaunay_mesh(box_nodes(N_NODES, seed=1)), "nem")
curves = {}
for Y in (np.inf, YIELD):
    curves[Y] = run(spaces, DT_CURVE * KYR, Y)
errors = []
for dtk in DTS_KYR + (DT_CURVE,):
    t, m, sp, _ = curves[np.inf] if dtk == DT_CURVE else run(spaces, dtk * KYR)
    ex = viscoelastic_buildup(t, ETA, MU, EDOT)
    errors.append((dtk, float(np.abs(m - ex).max()), float(m[-1]), float(sp.max())))
final = {Y: float(curves[Y][1][-1]) for Y in curves}
capped_plateau = float(np.abs(curves[YIELD][1][curves[YIELD][0] > 50 * KYR] - YIELD).max())


FIGURE = "out/ex09_viscoelastic_buildup.png"


def visualize(path=FIGURE):
    """Numerical vs analytic stress over time, with and without the yield cap,
    and the error against dt; returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    tt = np.linspace(0, T_END, 400)
    for Y, c, lab in ((np.inf, "C0", "no yield"), (YIELD, "C3", "yield 100 MPa")):
        t, m, sp, _ = curves[Y]
        a.plot(tt / KYR, viscoelastic_buildup(tt, ETA, MU, EDOT, Y) / 1e6, c, lw=1,
               label=f"analytic, {lab}")
        a.plot(t / KYR, m / 1e6, "o", color=c, ms=3, label=f"NEM, dt = {DT_CURVE:g} kyr, {lab}")
    a.set_xlabel("time (kyr)")
    a.set_ylabel("deviatoric stress sigma_xx (MPa)")
    a.legend(fontsize=8)
    d = np.array([e[0] for e in errors])
    err = np.array([e[1] for e in errors])
    b.loglog(d, err / 1e6, "o-", label="NEM max error over time")
    b.loglog(d, err[0] / 1e6 * d / d[0], "k--", lw=0.8, label="first order")
    b.set_xlabel("dt (kyr)")
    b.set_ylabel("max |error| (MPa)")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return fig


if __name__ == "__main__":
    for dtk, e, s, sp in errors:
        print(f"dt = {dtk:5.1f} kyr: max error {e / 1e6:6.3f} MPa, sigma(250 kyr) = "
              f"{s / 1e6:7.3f} MPa, rms spread <= {sp / 1e6:5.2f} MPa")
    print(f"capped: final {final[YIELD] / 1e6:.4f} MPa, max deviation from the cap after "
          f"50 kyr {capped_plateau / 1e6:.4f} MPa")
    visualize()
    print("wrote", FIGURE)
