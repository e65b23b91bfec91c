"""The 3D plate's materials at the quadrature points: the nodes' plate indicator blended
across the plate's edge.

Why a module of its own: the blend is a modelling choice with measured consequences
(docs/stokes_3d.md), shared by the viscous and the elasto-plastic plate. The nodes carry
the plate indicator s (1 on the plate's nodes) and the height they started at; both are
interpolated linearly on the tetrahedra (the pressure's P1 functions, node i = dof i).

The viscosity's blend sets how fast the depth converges with the node spacing. The
harmonic mean (the default: the Maxwell compliance linear in s, as the elastic
compliance already is) leaves the blend as soft as the fluid it mostly lies in; the
geometric mean (the default before) makes it nearly as stiff as the plate, a plate
thicker by part of a node spacing. At 10,032 nodes the depth is 13-25% below the limit of
a vanishing spacing with the geometric mean and 4-8% above it with the harmonic one, and
between 6,131 and 10,032 nodes it differs by up to 4.0% and 3.0% (docs/stokes_3d.md, at
three resolutions). Harmonic averaging is also what geodynamic codes found best for
sinking and subducting slabs on smoothed interfaces (Schmeling et al. 2008, Deubelbeiss &
Kaus 2008). On the viscous plate's first solve at 5,166 and 9,953 nodes the geometric
mean moved the velocity by 13%, the nodes' viscosities interpolated by the velocity's
functions by 40%, a sharp plate (s > 1/2) by 36%, with 3.5 times the FGMRES iterations.
"""
from __future__ import annotations

import math

import numpy as np

from ..models.rheology import Material

__all__ = ["blended_viscosity", "plate_materials", "VISCOSITY_MEANS", "YIELD_INDICATOR"]

#: the blends of the viscosity across the plate's edge (``Plate3DConfig.viscosity_mean``)
VISCOSITY_MEANS = ("harmonic", "geometric")

#: the plate yields where the interpolated indicator reaches this (its half-way line,
#: the plate's edge); the blend outside is visco-elastic only
YIELD_INDICATOR = 0.5


def plate_materials(cfg, spaces, node_fields):
    """``(Material, body force (3, ne, nq), s (ne, nq))`` at the quadrature points of
    ``spaces`` for the configuration ``cfg`` (a
    :class:`~skfem_nem.apps.plate3d_config.Plate3DConfig`).

    With s the interpolated plate indicator (clipped to [0, 1]): the viscosity is the
    fluid's (by the interpolated initial height) and the plate's blended by
    ``cfg.viscosity_mean``, harmonic ``1 / ((1 - s) / eta_fluid + s / eta_plate)`` or
    geometric ``eta_fluid^(1 - s) eta_plate^s``; the compliance linear in s
    (``shear_modulus / s``: the fluid has no elasticity), the yield stress the plate's
    where ``s >= YIELD_INDICATOR`` and none elsewhere, the buoyancy
    ``-plate_density gravity s``."""
    s = np.clip(np.asarray(spaces.pbasis.interpolate(node_fields["plate"])), 0.0, 1.0)
    upper = np.asarray(spaces.pbasis.interpolate(node_fields["start"][:, 2])) \
        > cfg.interface_z
    eta = blended_viscosity(np.where(upper, cfg.eta_upper, cfg.eta_lower),
                            cfg.plate_viscosity, s, cfg.viscosity_mean)
    with np.errstate(divide="ignore"):
        mu = np.where(s > 0, cfg.shear_modulus / s, np.inf)
    Y = np.where(s >= YIELD_INDICATOR, cfg.yield_stress, np.inf)
    force = np.zeros((3,) + eta.shape)
    force[2] = -cfg.plate_density * cfg.gravity * s
    return Material(viscosity=eta, shear_modulus=mu, yield_stress=Y), force, s


def blended_viscosity(fluid, plate: float, s, mean: str):
    """The viscosity where a fraction ``s`` (array in [0, 1]) is plate of viscosity
    ``plate`` and the rest fluid of viscosity ``fluid`` (array of s's shape): ``mean``
    one of :data:`VISCOSITY_MEANS`; ``ValueError`` naming any other."""
    if mean == "harmonic":
        return 1.0 / ((1.0 - s) / fluid + s / plate)
    if mean == "geometric":
        return np.exp((1.0 - s) * np.log(fluid) + s * math.log(plate))
    raise ValueError(f"mean must be {' or '.join(map(repr, VISCOSITY_MEANS))}, got {mean!r}")
