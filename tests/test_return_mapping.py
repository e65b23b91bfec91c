"""The pointwise visco-elasto-plastic update in 3D: Maxwell build-up under a constant strain
rate, the exact rotation of a prestressed solid, yield at the von Mises stress in uniaxial
compression; and the 3D invariants against their definitions."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from skfem_nem.models.return_mapping import (deviator, rotate_stress, second_invariant,
                                             vep_update)

ETA, MU = 1e21, 1e10          # Pa s, Pa: Maxwell time 1e11 s


def shear_3d(rate):
    e = np.zeros((3, 3, 1))
    e[0, 2, 0] = e[2, 0, 0] = rate
    return e


@pytest.mark.parametrize("steps", [50, 100, 200])
def test_maxwell_build_up_converges_to_the_exact_curve(steps):
    """tau(t) = 2 eta eps (1 - exp(-t / t_M)) under a constant shear rate; backward Euler is
    first order: halving dt halves the error."""
    t_end, rate = 2e11, 1e-15
    dt = t_end / steps
    tau = np.zeros((3, 3, 1))
    for _ in range(steps):
        tau, _ = vep_update(shear_3d(rate), None, tau, ETA, MU, np.inf, dt)
    exact = 2 * ETA * rate * (1 - np.exp(-t_end * MU / ETA))
    err = abs(tau[0, 2, 0] - exact) / exact
    assert err < 0.6 / steps and err > 0.1 / steps      # first order, no better
    assert np.abs(tau - np.swapaxes(tau, 0, 1)).max() == 0
    assert abs(np.trace(tau[..., 0])) < 1e-9 * exact


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3), st.floats(0.01, 3.0),
       st.lists(st.floats(-1, 1), min_size=6, max_size=6))
def test_exact_rotation_of_a_prestressed_solid(axis, angle, entries):
    """No strain rate, a rigid spin about any axis: the elastic stress turns with the body
    (R tau R^T, R the rotation by angle about axis) to round-off, after any number of steps."""
    axis = np.array(axis)
    if np.linalg.norm(axis) < 1e-3:
        return
    axis /= np.linalg.norm(axis)
    a, b, c, d, e, f = entries
    tau0 = deviator(np.array([[a, d, e], [d, b, f], [e, f, c]]))[..., None] * 1e6
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    steps, T = 7, 1e3
    W = (angle / T * K)[..., None]
    tau = tau0
    for _ in range(steps):
        tau, _ = vep_update(np.zeros((3, 3, 1)), W, tau, np.inf, MU, np.inf, T / steps,
                            rotation="exact")
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    assert np.abs(tau[..., 0] - R @ tau0[..., 0] @ R.T).max() <= 1e-13 * np.abs(tau0).max() + 1e-9
    assert abs(second_invariant(tau)[0] - second_invariant(tau0)[0]) <= \
        1e-12 * second_invariant(tau0)[0]


def test_jaumann_rotation_is_first_order_in_3d():
    tau0 = deviator(np.diag([1.0, -2.0, 1.0]))[..., None]
    W = np.zeros((3, 3, 1))
    W[1, 0, 0], W[0, 1, 0] = 1.0, -1.0
    errs = []
    for steps in (20, 40):
        tau = tau0
        for _ in range(steps):
            tau = rotate_stress(tau, W, 1.0 / steps)
        exact = rotate_stress(tau0, W, 1.0, "exact")
        errs.append(np.abs(tau - exact).max())
    assert 1.7 < errs[0] / errs[1] < 2.3


def test_yield_at_the_von_mises_stress_in_uniaxial_compression():
    """An incompressible uniaxial shortening: elastic until the von Mises stress sqrt(3 J2)
    reaches the tensile yield stress sigma0 (shear yield k = sigma0 / sqrt(3)), then the
    axial stress stays at sigma0 while the body flows."""
    sigma0, rate, dt = 1e8, 1e-14, 1e10
    k = sigma0 / np.sqrt(3)
    eps = np.diag([-rate, rate / 2, rate / 2])[..., None]
    tau = np.zeros((3, 3, 1))
    axial = []
    for _ in range(400):
        tau, plastic = vep_update(eps, None, tau, 1e30, MU, k, dt)
        axial.append(tau[1, 1, 0] - tau[0, 0, 0])   # sigma_yy - sigma_xx = axial compression
    axial = np.array(axial)
    assert axial[0] < sigma0 and np.all(np.diff(axial[axial < sigma0 * (1 - 1e-9)]) > 0)
    assert np.abs(axial[-100:] - sigma0).max() < 1e-9 * sigma0
    assert abs(np.sqrt(3) * second_invariant(tau)[0] - sigma0) < 1e-9 * sigma0
    assert plastic[0, 0, 0] < 0                       # the flow is plastic shortening


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=9, max_size=9))
def test_3d_invariant_is_sqrt_j2(entries):
    t = np.array(entries).reshape(3, 3)
    s = deviator(0.5 * (t + t.T))
    J2 = 0.5 * np.sum(s * s)
    assert abs(second_invariant(t[..., None])[0] - np.sqrt(J2)) <= 1e-12 * (1 + np.sqrt(J2))
    assert abs(np.trace(deviator(t))) <= 1e-12 * (1 + np.abs(t).max())
