"""Multigrid cycles of pyamg hierarchies and the flexible conjugate gradients they need.

Why a module of its own: the Stokes solvers' viscous multigrid
(:mod:`skfem_nem.models.stokes_amg`), the two-level method of the quadratic basis
(:mod:`.two_level`) and the solver of the linear natural-neighbour matrices
(:func:`.solvers.natural_neighbour_solver`) share these cycles. A V-cycle is a fixed
linear map, for CG. A K-cycle (:func:`k_cycle`; Notay & Vassilevski 2008) makes each coarse
correction two flexible CG steps on the coarse level, and so corrects for the error that a
V-cycle's coarse levels add up: on the linear natural-neighbour Laplacian (random nodes, unit
square) CG with a smoothed-aggregation V-cycle took 19, 30 and 43 iterations at 9,904, 99,676
and 998,983 unknowns, flexible CG with a cycle whose coarse corrections are K-cycles 19, 22
and 24 (66 s against 112 s at the largest). A K-cycle is not a linear map: the outer method
must be flexible (:func:`flexible_cg`, or FGMRES).
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Optional

import numpy as np

from ..vectors import dot, norm

__all__ = ["K_CYCLE_TOL", "AMG_SEED", "flexible_cg", "k_cycle", "level_step",
           "polynomial_smoothers", "scalar_levels_as_csr", "seeded_global_random",
           "smoothed_aggregation", "v_cycle"]

# a K-cycle's coarse correction stops after its first CG step where that step has reduced
# the coarse residual below this fraction (Notay's threshold)
K_CYCLE_TOL = 0.25
# seed of the start vectors of pyamg's spectral-radius estimates (prolongator smoothing,
# Chebyshev bounds), which it draws from numpy's global generator: fixed, the same matrix
# gets the same hierarchy in every run (a run with the Stokes solver "fgmres" repeats bit
# for bit)
AMG_SEED = 0
# coarsest level of smoothed_aggregation (solved there by sparse LU: pyamg's default, a
# pseudo-inverse by dense SVD, took most of a solve on small problems)
MAX_COARSE = 500


@contextmanager
def seeded_global_random(seed: int = AMG_SEED):
    """numpy's global (legacy) generator seeded with ``seed`` inside the block, the
    caller's state restored after it: pyamg draws its random starts from that generator."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def v_cycle(ml, b: np.ndarray, level: int = 0) -> np.ndarray:
    """One V-cycle of pyamg's multilevel solver ``ml`` from zero for ``A x = b``
    (pyamg's own ``solve`` also computes two norms and a residual per cycle, which are
    not needed inside a Krylov method: 54 against 22 ms on the coarse level of SolCx at
    33,242 velocity unknowns); ``level``: the cycle from that level down, ``A`` its
    matrix (a caller that treats the finer levels itself)."""
    last = len(ml.levels) - 1

    def cycle(k, rhs):
        if k == last:
            return ml.coarse_solver(ml.levels[k].A, rhs)
        return level_step(ml, k, rhs, cycle)

    return cycle(level, b)


def level_step(ml, k: int, b: np.ndarray, correction) -> np.ndarray:
    """Level ``k`` of a cycle of ``ml`` from zero for ``A_k x = b`` (not the coarsest):
    pre-smoothing, the coarse correction ``correction(k + 1, r)`` of the restricted
    residual, post-smoothing. A V-cycle's correction is the next level's cycle; a K-cycle's
    (:func:`k_cycle`) two CG steps preconditioned by it."""
    lv = ml.levels[k]
    x = np.zeros_like(b)
    lv.presmoother(lv.A, x, b)
    x += lv.P @ correction(k + 1, lv.R @ (b - lv.A @ x))
    lv.postsmoother(lv.A, x, b)
    return x


def k_cycle(ml, b: np.ndarray, level: int = 0, steps: bool = True) -> np.ndarray:
    """A K-cycle of pyamg's multilevel solver ``ml`` for ``A x = b`` on ``level`` (Notay &
    Vassilevski 2008): two flexible CG steps on the level, each preconditioned by its
    cycle, whose coarse correction is again such a pair on the next level; the coarsest
    level is solved. The second step is skipped where the first has reduced the residual
    below :data:`K_CYCLE_TOL` of its own. ``steps=False``: the level's cycle alone (its
    smoothing and the pairs below it), for an outer Krylov method on that level, which
    would otherwise repeat the pair's work there. Not a linear map of ``b``: for flexible
    outer methods only. Each level's cost is at most doubled against a V-cycle, and with a
    coarsening of some 15 times a level the finest level's products still dominate."""
    levels, last = ml.levels, len(ml.levels) - 1

    def cycle(k, rhs):
        return level_step(ml, k, rhs, pair)

    def pair(k, r):
        if k == last:
            return ml.coarse_solver(levels[k].A, r)
        A = levels[k].A
        c1 = cycle(k, r)
        v1 = A @ c1
        rho1, a1 = dot(c1, v1), dot(c1, r)
        r2 = r - (a1 / rho1) * v1
        if norm(r2) <= K_CYCLE_TOL * norm(r):
            return (a1 / rho1) * c1
        c2 = cycle(k, r2)
        v2 = A @ c2
        g, a2 = dot(c2, v1), dot(c2, r2)
        rho2 = dot(c2, v2) - g * g / rho1
        return (a1 / rho1 - g * a2 / (rho1 * rho2)) * c1 + (a2 / rho2) * c2

    if steps or level == last:
        return pair(level, b)
    return cycle(level, b)


def flexible_cg(A, b: np.ndarray, precondition: Callable, tol: float, maxiter: int,
                x0: Optional[np.ndarray] = None) -> tuple:
    """Flexible conjugate gradients (Notay's FCG(1)) for the symmetric positive definite
    ``A x = b``: each direction is made A-orthogonal to the last one explicitly, so that the
    preconditioner may change from one step to the next (a K-cycle). Stops when the
    residual norm is at most ``tol`` times that of ``b``; returns ``(x, iterations,
    converged)``. With a fixed symmetric preconditioner it is CG in exact arithmetic."""
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    r = b - A @ x if x0 is not None else b.copy()
    goal = tol * norm(b)
    if norm(r) <= goal:
        return x, 0, True
    d = q = None
    dq = 1.0
    for it in range(1, maxiter + 1):
        z = precondition(r)
        d = z if d is None else z - (dot(z, q) / dq) * d
        q = A @ d
        dq = dot(d, q)
        if not dq > 0:          # a breakdown: not positive definite (or z = 0)
            return x, it, False
        alpha = dot(d, r) / dq
        x += alpha * d
        r -= alpha * q
        if norm(r) <= goal:
            return x, it, True
    return x, maxiter, False


def smoothed_aggregation(A, modes: Optional[np.ndarray] = None, **options):
    """pyamg's smoothed-aggregation hierarchy of the symmetric ``A`` with ``modes`` as its
    near null space (None: the constants), coarsest level :data:`MAX_COARSE` solved by
    sparse LU, built under the fixed seed :data:`AMG_SEED` (numpy's global generator is
    restored afterwards); ``options`` go to pyamg (strength, smoothers, ...)."""
    import pyamg
    with seeded_global_random():
        ml = pyamg.smoothed_aggregation_solver(
            A, B=modes, symmetry="symmetric", max_coarse=MAX_COARSE, coarse_solver="splu",
            **options)
    polynomial_smoothers(ml, options.get("presmoother"), options.get("postsmoother"))
    return scalar_levels_as_csr(ml)


def polynomial_smoothers(ml, presmoother, postsmoother):
    """``ml`` with the levels' Chebyshev smoothers, as pyamg set them up from
    ``presmoother`` and ``postsmoother`` (its forms: a name, a ``(name, options)`` pair, or
    a list of them by level, the last for the levels below), made BLAS-free, in place.

    Why: pyamg's polynomial relaxation tests ``norm(x) == 0`` with a BLAS dot product, and
    OpenBLAS runs dot products of more than 10,000 entries on its threads, which then wait
    spinning for the next call and hold a core that numba's threads need. On SolCx with
    the quadratic velocity at 16,000 nodes the viscous block's products took 13.3 ms each
    inside the solve against 6.8 ms alone. The replacement applies the same polynomial, of
    the same coefficients (pyamg's, from the spectral radius it cached on the level's
    matrix), and tests ``x.any()``."""
    for k, lv in enumerate(ml.levels[:-1]):
        for name, spec in (("presmoother", presmoother), ("postsmoother", postsmoother)):
            spec = spec[min(k, len(spec) - 1)] if isinstance(spec, list) else spec
            name_of, kwargs = (spec, {}) if not isinstance(spec, tuple) else spec
            if name_of == "chebyshev":
                setattr(lv, name, _chebyshev(lv.A, **kwargs))
    return ml


def _chebyshev(A, lower_bound: float = 1.0 / 30.0, upper_bound: float = 1.1, degree: int = 3,
               iterations: int = 1):
    """pyamg's Chebyshev smoother of ``A`` (``setup_chebyshev``'s options and defaults),
    without BLAS."""
    from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
    from pyamg.util.linalg import approximate_spectral_radius
    rho = approximate_spectral_radius(A)
    coef = -chebyshev_polynomial_coefficients(rho * lower_bound, rho * upper_bound,
                                              degree)[:-1]

    def chebyshev(A, x, b):
        for _ in range(iterations):
            r = b - A @ x if x.any() else b
            h = coef[0] * r
            for c in coef[1:]:
                h = c * r + A @ h
            x += h
    return chebyshev


def scalar_levels_as_csr(ml):
    """``ml`` with its levels of 1 x 1 blocks as CSR matrices, in place. With one near
    null vector pyamg's aggregation makes the coarse levels BSR of 1 x 1 blocks, and its
    relaxation then runs the block kernels: a symmetric Gauss-Seidel sweep on the second
    level of the quadratic Poisson solver at 127,961 unknowns (6,856 rows, 109 entries a
    row) took 3.9 ms as BSR and 0.24 ms as CSR. The smoothers read each level's matrix
    when called, so they follow."""
    import scipy.sparse as sp
    for lv in ml.levels:
        for name in ("A", "P", "R"):
            M = getattr(lv, name, None)
            if sp.issparse(M) and M.format == "bsr" and M.blocksize == (1, 1):
                setattr(lv, name, sp.csr_matrix(M))
    return ml
