"""vep_step on tetrahedra (the 3D natural-neighbour Stokes spaces): a uniform Maxwell
build-up, the exact rotation of a prestressed elastic solid, and yield at the von Mises
stress in uniaxial compression, each against the pointwise update of the same uniform
flow (linear velocities are reproduced exactly by the natural-neighbour velocity)."""
import numpy as np
import pytest

from skfem_nem import delaunay_mesh
from skfem_nem.geometry.nodesets3d import box_nodes_3d
from skfem_nem.models.return_mapping import deviator, second_invariant, vep_update
from skfem_nem.models.rheology import Material, prescribed_velocity, vep_step
from skfem_nem.models.stokes import stokes_spaces

ETA, MU = 1e21, 1e10


@pytest.fixture(scope="module")
def spaces():
    return stokes_spaces(delaunay_mesh(box_nodes_3d(250, seed=0)))


def run(spaces, grad, material, steps, dt, tau0=None, rotation="jaumann"):
    """vep_step under the linear flow u = grad x on every wall, and the pointwise update."""
    d, ne, nq = spaces.quadrature_points.shape
    walls = prescribed_velocity(spaces, "all", lambda x: grad @ x)
    tau = np.zeros((3, 3, ne, nq)) if tau0 is None else np.broadcast_to(
        tau0[..., None, None], (3, 3, ne, nq)).copy()
    ref = np.zeros((3, 3, 1)) if tau0 is None else tau0[..., None].copy()
    eps, W = 0.5 * (grad + grad.T), 0.5 * (grad - grad.T)
    for _ in range(steps):
        step = vep_step(spaces, material, tau, dt, prescribed=walls, free_slip=None,
                        rotation=rotation, u_guess=None)
        tau = step.tau
        ref, _ = vep_update(eps[..., None], W[..., None], ref, material.viscosity,
                            material.shear_modulus, material.yield_stress, dt, rotation)
    return tau, ref, step


def test_maxwell_build_up(spaces):
    E = 1e-15 * deviator(np.array([[-1.0, 0.2, 0.3], [0.2, 0.5, 0.0], [0.3, 0.0, 0.5]]))
    tau, ref, _ = run(spaces, E, Material(viscosity=ETA, shear_modulus=MU), 4, 2e10)
    assert np.abs(tau - ref[..., None]).max() <= 1e-9 * np.abs(ref).max()
    assert 0.3 < ref[0, 1, 0] / (2 * ETA * 0.2e-15) < 1.0   # part of the way up the curve


def test_prestressed_solid_turns_with_its_rigid_rotation(spaces):
    w = 1e-3                                   # rad/s about the axis (1, 2, 2) / 3
    a = np.array([1.0, 2.0, 2.0]) / 3
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    tau0 = deviator(np.array([[3.0, 1.0, 0.0], [1.0, -1.0, 0.5], [0.0, 0.5, -2.0]])) * 1e6
    elastic = Material(viscosity=np.inf, shear_modulus=MU)
    tau, ref, _ = run(spaces, w * K, elastic, 3, 100.0, tau0=tau0, rotation="exact")
    angle = 3 * 100.0 * w
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    assert np.abs(ref[..., 0] - R @ tau0 @ R.T).max() < 1e-9 * np.abs(tau0).max()
    assert np.abs(tau - ref[..., None]).max() < 1e-6 * np.abs(tau0).max()


def test_yield_at_the_von_mises_stress_in_uniaxial_compression(spaces):
    sigma0 = 1e8
    E = 1e-14 * np.diag([-1.0, 0.5, 0.5])
    mat = Material(viscosity=1e30, shear_modulus=MU, yield_stress=sigma0 / np.sqrt(3))
    tau, ref, step = run(spaces, E, mat, 4, 2e11)   # yields in the second step
    axial = tau[1, 1] - tau[0, 0]
    assert np.abs(axial - sigma0).max() < 1e-8 * sigma0
    assert np.abs(np.sqrt(3) * second_invariant(tau) - sigma0).max() < 1e-8 * sigma0
    assert step.yielded.all() and np.abs(tau - ref[..., None]).max() < 1e-8 * sigma0
