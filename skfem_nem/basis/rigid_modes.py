"""Rigid-body modes of a vector basis: the translations and rotations, dof by dof.

Why a module of its own: algebraic multigrid of a vector problem (a viscous block, an
elastic stiffness) needs them as its near null space at two depths of the package, the
smoothed aggregation of the Stokes solvers (:mod:`skfem_nem.models.stokes_amg`, PETSc's GAMG)
and the coarse level of the quadratic two-level method (:mod:`.two_level`), so they live in
the lower layer both can import.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rigid_modes", "velocity_components"]


def velocity_components(ubasis) -> np.ndarray:
    """0, 1 (or 2), the component (``u^1``, ``u^2``, ``u^3``) of each dof of a vector
    basis."""
    d = ubasis.mesh.dim()
    comp = np.zeros(ubasis.N, dtype=int)
    dofs = ubasis.dofs
    for dofs_ in (dofs.nodal_dofs, dofs.facet_dofs, dofs.edge_dofs, dofs.interior_dofs):
        for c in range(1, d):   # rows: u^1, u^2 (, u^3) of each entity
            comp[dofs_[c::d].ravel()] = c
    return comp


def rigid_modes(ubasis, free: np.ndarray) -> np.ndarray:
    """(len(free), 3) rigid-body modes (two translations, one rotation) of a 2D
    vector velocity basis, or (len(free), 6) in 3D (three translations, three
    rotations), restricted to the dofs ``free``. Dofs without a location (scikit-fem
    places the MINI elements' bubbles at NaN) are zero in every mode: a rigid motion is
    linear, and the linear part of such a space holds it with its bubbles at zero."""
    loc = np.asarray(ubasis.doflocs)  # (dim, nu)
    comp = velocity_components(ubasis)
    d = loc.shape[0]
    pairs = [(0, 1)] if d == 2 else [(0, 1), (1, 2), (2, 0)]
    Bm = np.zeros((ubasis.N, d + len(pairs)))
    for c in range(d):
        Bm[comp == c, c] = 1.0
    for k, (a, b) in enumerate(pairs):   # rotation in the (a, b) plane
        Bm[comp == a, d + k] = -loc[b, comp == a]
        Bm[comp == b, d + k] = loc[a, comp == b]
    Bm[~np.isfinite(loc).all(axis=0)] = 0.0
    return Bm[free]
