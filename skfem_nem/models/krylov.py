"""Krylov methods and vector products shared by the Stokes solvers and their
multigrid: restarted flexible GMRES, restarted MINRES, a few preconditioned CG steps and
the Lanczos bound of a Chebyshev smoother (the BLAS-free products of :mod:`skfem_nem.vectors`
are re-exported).

Kept apart from :mod:`skfem_nem.models.stokes_solvers` because they are linear
algebra on vectors and callables alone, with no knowledge of the Stokes blocks;
:mod:`skfem_nem.models.stokes_amg` and the solvers both use them.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
import scipy.linalg as sla

from ..vectors import dot, norm

__all__ = ["FGMRES_RESTART", "LANCZOS_STEPS", "MINRES_MAX_RTOL", "MINRES_TOL_FACTOR", "cg_steps",
           "dot", "fgmres", "largest_eigenvalue", "minres_steps", "norm", "restarted_minres"]

# FGMRES restart length: it keeps two vectors of the system's size per iteration
# up to this many, so memory stays linear in the unknowns (730 MB at 300,000
# unknowns, against 2.6 GB for the factorisation of "schur"). At 100,000 nodes and
# a contrast of 1e6 a restart every 50 iterations stalled (no convergence in 760),
# every 150 converged in 285
FGMRES_RESTART = 150
# MINRES stops when its preconditioned residual norm is below this factor
# times tol (its own estimate drifts from the true residual; stokes_solvers.solve_minres)
MINRES_TOL_FACTOR = 10
# MINRES restart asks for at most this relative reduction of the residual
MINRES_MAX_RTOL = 0.5
# Lanczos steps of largest_eigenvalue: the bound of a Chebyshev smoother. pyamg's own
# estimate takes 15 Lanczos steps and restarts up to 5 times; on the scaled viscous blocks
# of the 3D plate (9,956 nodes) 20 steps from a random start find its estimate to 1e-3
LANCZOS_STEPS = 20
# Lanczos stops early when the new vector's norm falls below this fraction of the largest
# diagonal entry so far: the start spans an invariant subspace (a small or a reducible
# operator), whose Ritz values are exact
LANCZOS_BREAKDOWN = 1e-12


def cg_steps(A, precondition: Callable, b: np.ndarray, steps: int) -> np.ndarray:
    """``steps`` preconditioned conjugate-gradient steps from zero for ``A x = b`` (no
    stopping test: a fixed small number of steps approximates ``A^-1 b`` inside a flexible
    outer method); ``precondition`` applies the preconditioner to a residual."""
    x = np.zeros_like(b)
    r = b.copy()
    z = precondition(r)
    d = z.copy()
    rz = dot(r, z)
    for k in range(steps):
        Ad = A @ d
        dAd = dot(d, Ad)
        if not dAd > 0:
            break
        alpha = rz / dAd
        x += alpha * d
        if k == steps - 1:
            break
        r -= alpha * Ad
        z = precondition(r)
        rz, rz_old = dot(r, z), rz
        d = z + (rz / rz_old) * d
    return x


def fgmres(matvec: Callable, precondition: Callable, b: np.ndarray, x0: Optional[np.ndarray],
           tol: float, maxiter: int, restart: int = FGMRES_RESTART,
           stall: Optional[float] = None, scale: Optional[float] = None):
    """Restarted flexible GMRES (Saad 1993), right-preconditioned.

    Flexible because the preconditioned vectors are kept and the update is
    built from them, so ``precondition`` may change from one application to
    the next (scipy's ``gmres`` assumes a fixed preconditioner). Classical
    Gram-Schmidt applied twice (two matrix-vector products with the basis
    per pass instead of a loop). Products with the basis and norms go
    through ``einsum``, not BLAS: a threaded BLAS waiting for cores that
    numba's threads or other jobs hold made the solves of the sinking plate
    5-7 times slower. Returns the solution, the number of
    iterations and the true relative residual ``|b - K x| / |b|``, the
    stopping test (checked at every restart). ``stall``: also stop when a
    restart cycle leaves the true residual above this fraction of the last.
    ``scale``: the norm the residual is relative to, in place of ``|b|``.
    """
    n = b.size
    bnorm = (norm(b) if scale is None else scale) or 1.0
    x = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    r = b - matvec(x) if x0 is not None else b.copy()
    its = 0
    V = np.empty((restart + 1, n))
    Z = np.empty((restart, n))
    last = np.inf
    while True:
        beta = norm(r)
        if beta <= tol * bnorm or its >= maxiter or (stall is not None
                                                      and beta > stall * last):
            return x, its, beta / bnorm
        last = beta
        H = np.zeros((restart + 1, restart))
        rot = np.zeros((restart, 2))                 # Givens cosines and sines
        g = np.zeros(restart + 1)
        g[0] = beta
        V[0] = r / beta
        for j in range(restart):
            Z[j] = precondition(V[j])
            w = matvec(Z[j])
            its += 1
            for _ in range(2):
                h = np.einsum("ij,j->i", V[:j + 1], w)
                w -= np.einsum("i,ij->j", h, V[:j + 1])
                H[:j + 1, j] += h
            H[j + 1, j] = norm(w)
            if H[j + 1, j] > 0:
                V[j + 1] = w / H[j + 1, j]
            for i in range(j):
                ci, si = rot[i]
                H[i, j], H[i + 1, j] = ci * H[i, j] + si * H[i + 1, j], \
                    -si * H[i, j] + ci * H[i + 1, j]
            d = np.hypot(H[j, j], H[j + 1, j])
            rot[j] = (H[j, j] / d, H[j + 1, j] / d) if d > 0 else (1.0, 0.0)
            H[j, j], H[j + 1, j] = d, 0.0
            g[j], g[j + 1] = rot[j, 0] * g[j], -rot[j, 1] * g[j]
            if abs(g[j + 1]) <= tol * bnorm or its >= maxiter or H[j, j] == 0:
                break
        k = j + 1
        y = sla.solve_triangular(H[:k, :k], g[:k], check_finite=False)
        x += np.einsum("i,ij->j", y, Z[:k])
        r = b - matvec(x)


def restarted_minres(matvec: Callable, K, M, rhs: np.ndarray, tol: float, maxiter: int):
    """MINRES restarted on the true residual.

    MINRES's own residual estimate drifts from the true one on these badly
    conditioned systems: restart it on the true residual until the
    preconditioned residual norm (the norm MINRES minimises) meets
    ``MINRES_TOL_FACTOR * tol`` or ``maxiter`` iterations are spent. Returns
    the solution, that relative norm, the number of restarts and of
    iterations.
    """
    count = [0]
    bnorm = float(np.sqrt(abs(rhs @ M.matvec(rhs)))) or 1.0
    x = np.zeros_like(rhs)
    r = rhs.copy()
    res_m = 1.0
    restarts = 0
    while count[0] < maxiter:
        res_m = float(np.sqrt(abs(r @ M.matvec(r)))) / bnorm
        if res_m <= MINRES_TOL_FACTOR * tol:
            break
        x = x + minres_steps(K.matvec, M.matvec, r,
                             min(MINRES_MAX_RTOL, MINRES_MAX_RTOL * tol / res_m),
                             maxiter - count[0], count)
        r = rhs - matvec(x)
        restarts += 1
    return x, res_m, restarts, count[0]


def minres_steps(A: Callable, M: Callable, b: np.ndarray, rtol: float, maxiter: int,
                 count: list) -> np.ndarray:
    """Preconditioned MINRES from zero for ``A x = b`` (Paige & Saunders 1975; ``A``
    symmetric, ``M`` symmetric positive definite, both as callables) until its
    preconditioned residual norm ``sqrt(r . M r)``, which its recurrence gives, falls to
    ``rtol`` of the start's, or ``maxiter`` steps; ``count[0]`` counts the steps.

    Why not scipy's: its stopping test is relative to its estimate of ``|A| |x|``, which a
    viscosity contrast of 1e6 makes large. On SolCx at that contrast (quadratic velocity,
    250 nodes) it stopped after 15 steps, 3 after each restart, with the preconditioned
    residual at 1e-7 and growing, and 3,000 steps did not reach 1e-8."""
    x = np.zeros_like(b)
    r1, r2 = b.copy(), b.copy()
    y = M(b)
    beta1 = float(np.sqrt(max(dot(b, y), 0.0)))
    if beta1 == 0.0:
        return x
    beta, oldb, dbar, epsln, phibar = beta1, 0.0, 0.0, 0.0, beta1
    cs, sn = -1.0, 0.0
    w, w2 = np.zeros_like(b), np.zeros_like(b)
    for k in range(maxiter):
        v = y / beta
        y = A(v)
        if k:
            y = y - (beta / oldb) * r1
        alfa = dot(v, y)
        y = y - (alfa / beta) * r2
        r1, r2 = r2, y
        y = M(r2)
        oldb, beta = beta, float(np.sqrt(max(dot(r2, y), 0.0)))
        # the last rotation on the new column of the tridiagonal, then the next rotation
        oldeps = epsln
        delta = cs * dbar + sn * alfa
        gbar = sn * dbar - cs * alfa
        epsln, dbar = sn * beta, -cs * beta
        gamma = max(float(np.hypot(gbar, beta)), np.finfo(float).eps)
        cs, sn = gbar / gamma, beta / gamma
        phi, phibar = cs * phibar, sn * phibar
        w1, w2 = w2, w
        w = (v - oldeps * w1 - delta * w2) / gamma
        x += phi * w
        count[0] += 1
        if phibar <= rtol * beta1 or beta == 0.0:
            break
    return x


def largest_eigenvalue(matvec: Callable, n: int, steps: int = LANCZOS_STEPS,
                       seed: int = 0) -> float:
    """An upper estimate of the largest eigenvalue of a symmetric positive semi-definite
    operator of size ``n``: ``steps`` Lanczos steps (fully reorthogonalised) from a random
    start drawn with ``seed``, the largest Ritz value plus its residual norm (an
    eigenvalue lies within that of the Ritz value; the largest Ritz value approaches the
    largest eigenvalue from below)."""
    steps = max(1, min(steps, n))
    V = np.empty((steps + 1, n))
    alpha, beta = np.zeros(steps), np.zeros(steps)
    v = np.random.default_rng(seed).standard_normal(n)
    V[0] = v / norm(v)
    k = steps
    for j in range(steps):
        w = np.asarray(matvec(V[j]), dtype=float)
        alpha[j] = dot(w, V[j])
        for _ in range(2):
            w -= np.einsum("i,ij->j", np.einsum("ij,j->i", V[:j + 1], w), V[:j + 1])
        beta[j] = norm(w)
        if beta[j] <= LANCZOS_BREAKDOWN * abs(alpha[:j + 1]).max():
            k = j + 1
            break
        V[j + 1] = w / beta[j]
    theta, S = sla.eigh_tridiagonal(alpha[:k], beta[:k - 1])
    return float(theta[-1] + beta[k - 1] * abs(S[-1, -1]))
