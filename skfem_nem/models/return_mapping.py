"""Pointwise visco-elasto-plastic stress update (Maxwell body, objective rotation, von Mises
return mapping), in 2D and 3D.

Why a module of its own: the update acts on stress tensors at points, whatever carries them
(the 2D mesh's integration points, the 3D mesh's vertex cells) and whatever solved for the
velocity; :mod:`.rheology` wraps it around the Stokes solver. Tensors have shape (d, d, ...)
with d = 2 or 3 (``[i, j] = du_i/dx_j`` for velocity gradients); the 2D formulas are the ones
the 2D runs were measured with, bit for bit.

The invariant is ``II(t) = sqrt(s_ij s_ij / 2)`` of the deviator ``s`` (of the symmetric
part): ``sqrt(J2)``, so a yield stress ``Y`` is the shear yield stress ``k``, and a von Mises
tensile yield stress ``sigma0`` is ``k = sigma0 / sqrt(3)`` (in 3D exactly; in 2D in plane
strain).
"""
from __future__ import annotations

from typing import Optional, Tuple, Union

import numpy as np

__all__ = ["ArrayLike", "maxwell_coefficients", "strain_rate", "spin", "deviator",
           "second_invariant", "rotate_stress", "return_map", "vep_update"]

ArrayLike = Union[float, np.ndarray]

#: below this angle (rad) Rodrigues' coefficients are taken from their series (the closed
#: forms lose digits to cancellation; the series' first dropped terms are below 1e-17 here)
SMALL_ANGLE = 1e-4


def maxwell_coefficients(eta: ArrayLike, mu: ArrayLike, dt: float) -> Tuple[np.ndarray, np.ndarray]:
    """``(eta_ve, 1 - Z)`` of the backward-Euler Maxwell step.

    ``eta_ve = 1 / (1/eta + 1/(mu dt))`` (Pa s) and ``1 - Z = eta / (mu dt +
    eta) = eta_ve / (mu dt)`` (dimensionless); ``mu = inf`` gives
    ``(eta, 0)``, ``eta = inf`` gives ``(mu dt, 1)``.
    """
    eta = np.asarray(eta, dtype=float)
    mu = np.asarray(mu, dtype=float)
    with np.errstate(divide="ignore"):
        eta_ve = 1.0 / (1.0 / eta + 1.0 / (mu * dt))
        keep = np.where(np.isinf(mu), 0.0, eta_ve / (mu * dt))
    return eta_ve, keep


def strain_rate(grad: np.ndarray) -> np.ndarray:
    """Symmetric part of the velocity gradient (d, d, ...) (``[i, j] = du_i/dx_j``), 1/s."""
    return 0.5 * (grad + np.swapaxes(grad, 0, 1))


def spin(grad: np.ndarray) -> np.ndarray:
    """Antisymmetric part ``W = (grad u - grad u^T) / 2`` (d, d, ...), 1/s."""
    return 0.5 * (grad - np.swapaxes(grad, 0, 1))


def deviator(t: np.ndarray) -> np.ndarray:
    """Deviator ``t - tr(t) / d I`` of (d, d, ...) tensors."""
    out = np.array(t, dtype=float, copy=True)
    d = t.shape[0]
    h = 0.5 * (t[0, 0] + t[1, 1]) if d == 2 else np.trace(t, axis1=0, axis2=1) / d
    for i in range(d):
        out[i, i] -= h
    return out


def second_invariant(t: np.ndarray) -> np.ndarray:
    """``sqrt(s_ij s_ij / 2)`` of the deviator s of the symmetric part of (d, d, ...)
    tensors, shape (...)."""
    if t.shape[0] == 2:
        d = deviator(t)
        return np.sqrt(0.5 * (d[0, 0] ** 2 + d[1, 1] ** 2) + 0.25 * (d[0, 1] + d[1, 0]) ** 2)
    # 3D: entry by entry, without the deviator and symmetric part as whole arrays (four
    # temporaries of nine values a point: 0.38 s a call at 100,000 nodes)
    t = np.asarray(t, dtype=float)
    h = (t[0, 0] + t[1, 1] + t[2, 2]) / 3.0
    return np.sqrt(0.5 * ((t[0, 0] - h) ** 2 + (t[1, 1] - h) ** 2 + (t[2, 2] - h) ** 2)
                   + 0.25 * ((t[0, 1] + t[1, 0]) ** 2 + (t[0, 2] + t[2, 0]) ** 2
                             + (t[1, 2] + t[2, 1]) ** 2))


def rotate_stress(tau: np.ndarray, W: np.ndarray, dt: float,
                  method: str = "jaumann") -> np.ndarray:
    """Advance the stress (d, d, ...) by the objective rotation with spin W (d, d, ...) over dt.

    ``"jaumann"``: ``tau + dt (W tau - tau W)`` (first order: invariants change
    by O((w dt)^2) per step); ``"exact"``: ``R tau R^T`` with ``R = exp(W dt)``
    (:func:`_rotation`: the solution of the Jaumann rate equation for a constant
    spin; invariants kept exactly).
    """
    if method == "jaumann":
        Wt = np.einsum("ik...,kj...->ij...", W, tau)
        tW = np.einsum("ik...,kj...->ij...", tau, W)
        return tau + dt * (Wt - tW)
    if method == "exact":
        R = _rotation(W, dt)
        return np.einsum("ik...,kl...,jl...->ij...", R, tau, R)
    raise ValueError(f"rotation must be 'jaumann' or 'exact', got {method!r}")


def return_map(tau_trial: np.ndarray, yield_stress: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """Radial return of trial stresses (d, d, ...) onto the von Mises surface ``II = Y``.

    Returns ``(tau, factor)``: ``tau = factor * tau_trial`` with ``factor =
    min(1, Y / II(tau_trial))`` (shape (...); 1 where elastic/viscous).
    """
    II = second_invariant(tau_trial)
    Y = np.asarray(yield_stress, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(II > Y, Y / np.where(II > 0, II, 1.0), 1.0)
    return tau_trial * factor, factor


def vep_update(eps: np.ndarray, W: Optional[np.ndarray], tau_old: np.ndarray, eta: ArrayLike,
               mu: ArrayLike, yield_stress: ArrayLike, dt: float,
               rotation: str = "jaumann") -> Tuple[np.ndarray, np.ndarray]:
    """Pointwise visco-elasto-plastic stress update for a known strain rate.

    Parameters
    ----------
    eps
        Strain rate (d, d, ...) (1/s).
    W
        Spin (d, d, ...) (1/s) or None (no rotation).
    tau_old
        Stress at the start of the step (d, d, ...), Pa.
    eta, mu, yield_stress
        Viscosity (Pa s), shear modulus (Pa), yield stress (Pa), broadcast
        to the trailing shape.
    dt
        Time step (s).

    Returns
    -------
    (tau_new, plastic_rate): the stress (d, d, ...) after the step and the
    plastic strain-rate tensor (d, d, ...) (1/s).
    """
    if not (np.isscalar(dt) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"time step dt must be a positive finite number, got {dt!r}")
    eta_ve, keep = maxwell_coefficients(eta, mu, dt)
    chi = keep / eta_ve
    tau_rot = tau_old if (W is None or rotation == "none") else rotate_stress(tau_old, W, dt,
                                                                               rotation)
    edot = eps + 0.5 * chi * tau_rot
    tau_new, _ = return_map(2.0 * eta_ve * edot, yield_stress)
    return tau_new, edot - tau_new / (2.0 * eta_ve)




def _rotation(W: np.ndarray, dt: float) -> np.ndarray:
    """``exp(W dt)`` of spins W (d, d, ...): in 2D the rotation by ``w dt``, ``w = W[1, 0]``;
    in 3D Rodrigues' formula about the axial vector of W."""
    if W.shape[0] == 2:
        a = 0.5 * (W[1, 0] - W[0, 1]) * dt
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s], [s, c]])
    K = 0.5 * (W - np.swapaxes(W, 0, 1)) * dt
    theta = np.sqrt(K[2, 1] ** 2 + K[0, 2] ** 2 + K[1, 0] ** 2)
    small = theta < SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    eye = np.eye(3).reshape((3, 3) + (1,) * (W.ndim - 2))
    return eye + a * K + b * np.einsum("ik...,kj...->ij...", K, K)
