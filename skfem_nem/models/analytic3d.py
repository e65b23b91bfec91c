"""Exact solutions of the Stokes problem in three dimensions, to verify against.

A manufactured solution with variable viscosity (:class:`Manufactured3D`) checks the
3D Stokes spaces' rates; Stokes' law with the wall correction of a sphere settling on
the axis of a cylinder (Haberman & Sayre 1958, :func:`settling_velocity`) checks a
buoyancy-driven flow around a stiff inclusion. Kept beside
:mod:`skfem_nem.models.analytic` (the 2D solutions).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Manufactured3D", "Sinker", "relative_errors", "stokes_law", "haberman_sayre",
           "settling_velocity"]


class Manufactured3D:
    """A smooth divergence-free flow in the unit cube with the viscosity
    ``eta = exp(a (x + y + z))``, ``a = ln(ratio) / 3`` (``ratio`` between the corners
    (0, 0, 0) and (1, 1, 1))::

        u = (2 sin(pi x) cos(pi y) cos(pi z), -cos(pi x) sin(pi y) cos(pi z),
             -cos(pi x) cos(pi y) sin(pi z)),
        p = P cos(pi x) cos(pi y) cos(pi z)   (mean zero; P = pressure_scale),

    and the body force ``f = -div(2 eta eps(u)) + grad p = -2 eps(u) grad eta
    - eta lap u + grad p`` that makes them solve the Stokes equations (``lap u =
    -3 pi^2 u``). On every face of the cube the normal velocity and the shear strain
    rate vanish, so free slip on all six walls is exact for any viscosity. Points are
    (3, ...) arrays.

    >>> m = Manufactured3D(20.0)
    >>> x = np.random.default_rng(0).random((3, 5))
    >>> g = m.velocity_gradient(x)
    >>> float(np.abs(np.trace(g)).max()) < 1e-14        # divergence free
    True
    """

    amplitudes = np.array([2.0, -1.0, -1.0])   # of the three components (sum zero)

    def __init__(self, ratio: float = 20.0, pressure_scale: float = 10.0):
        for name, v in (("ratio", ratio), ("pressure_scale", pressure_scale)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v}")
        self.ratio, self.pressure_scale = float(ratio), float(pressure_scale)
        self.a = np.log(self.ratio) / 3.0

    def viscosity(self, x) -> np.ndarray:
        return np.exp(self.a * (x[0] + x[1] + x[2]))

    @staticmethod
    def _sc(x):
        x = np.pi * np.asarray(x, dtype=float)
        return np.sin(x), np.cos(x)

    def velocity(self, x) -> np.ndarray:
        s, c = self._sc(x)
        prod = [s[i] * c[(i + 1) % 3] * c[(i + 2) % 3] for i in range(3)]
        return self.amplitudes.reshape((3,) + (1,) * (s.ndim - 1)) * np.array(prod)

    def velocity_gradient(self, x) -> np.ndarray:
        """(3, 3, ...) with ``[i, j] = d u_i / d x_j``."""
        s, c = self._sc(x)
        g = np.empty((3, 3) + s.shape[1:])
        for i in range(3):            # u_i = a_i sin(pi x_i) cos(pi x_j) cos(pi x_k)
            for j in range(3):
                k = 3 - i - j
                f = c[0] * c[1] * c[2] if i == j else -s[i] * s[j] * c[k]
                g[i, j] = np.pi * self.amplitudes[i] * f
        return g

    def pressure(self, x) -> np.ndarray:
        _, c = self._sc(x)
        return self.pressure_scale * c[0] * c[1] * c[2]

    def pressure_gradient(self, x) -> np.ndarray:
        s, c = self._sc(x)
        return -np.pi * self.pressure_scale * np.array(
            [s[0] * c[1] * c[2], c[0] * s[1] * c[2], c[0] * c[1] * s[2]])

    def force(self, x) -> np.ndarray:
        g = self.velocity_gradient(x)
        eps = 0.5 * (g + g.transpose(1, 0, *range(2, g.ndim)))
        eta = self.viscosity(x)
        grad_eta = self.a * eta                       # the same in every direction
        return (-2.0 * grad_eta * eps.sum(axis=1) + 3.0 * np.pi ** 2 * eta * self.velocity(x)
                + self.pressure_gradient(x))


class Sinker:
    """The "sinker" benchmark of solver robustness (May, Brown & Le Pourhiet 2015; Rudi et
    al. 2017): in the unit cube, ``count`` spheres of diameter ``omega`` at random centres,
    with the smooth indicator ``chi = prod_i [1 - exp(-delta max(0, |x - c_i| - omega/2)^2)]``
    (0 inside a sphere, 1 far from all), the viscosity
    ``(sqrt(DR) - 1/sqrt(DR)) (1 - chi) + 1/sqrt(DR)`` and the density ``1 - chi``:
    heavy spheres ``DR`` times stiffer than the fluid. No analytic solution; it measures
    how the iterations of a solver grow with the mesh and the contrast.

    >>> s = Sinker(4, seed=0)
    >>> x = np.array([[2.0], [2.0], [2.0]])          # far from every sphere
    >>> float(s.viscosity(x)[0]) == 1 / np.sqrt(s.contrast)
    True
    """

    def __init__(self, count: int = 8, contrast: float = 1e4, omega: float = 0.1,
                 delta: float = 200.0, seed: int = 0):
        if int(count) != count or count < 1:
            raise ValueError(f"count must be a positive integer, got {count}")
        for name, v in (("contrast", contrast), ("omega", omega), ("delta", delta)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v}")
        rng = np.random.default_rng(seed)
        self.centres = omega / 2 + (1 - omega) * rng.random((3, int(count)))
        self.contrast, self.omega, self.delta = float(contrast), float(omega), float(delta)

    def indicator(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        chi = np.ones(x.shape[1:])
        for c in self.centres.T:
            d = np.sqrt(((x - c.reshape((3,) + (1,) * (x.ndim - 1))) ** 2).sum(axis=0))
            chi = chi * (1.0 - np.exp(-self.delta * np.maximum(0.0, d - self.omega / 2) ** 2))
        return chi

    def viscosity(self, x) -> np.ndarray:
        r = np.sqrt(self.contrast)
        return (r - 1.0 / r) * (1.0 - self.indicator(x)) + 1.0 / r

    def force(self, x) -> np.ndarray:
        rho = 1.0 - self.indicator(x)
        return np.array([0.0 * rho, 0.0 * rho, -rho])


def relative_errors(spaces, solution, exact, intorder: int = 4) -> tuple:
    """Relative L2 errors ``(velocity, pressure)`` of a 3D Stokes ``solution`` on
    ``spaces`` against ``exact`` (``velocity(x)``, ``pressure(x)`` of (3, ...) points) at
    the points of the Gauss rule of order ``intorder`` on each tetrahedron; both pressures
    are taken with mean zero."""
    from skfem import Basis, ElementTetP1

    qb = Basis(spaces.mesh, ElementTetP1(), intorder=intorder)
    x = np.asarray(qb.global_coordinates())
    _, ne, nq = x.shape
    if spaces.method.startswith("nem"):
        uh = (spaces.ubasis.probes(x.reshape(3, -1)) @ solution.u).reshape(3, ne, nq)
    else:
        ub = Basis(spaces.mesh, spaces.ubasis.elem, intorder=intorder)
        uh = np.asarray(ub.interpolate(solution.u))
    ph = np.asarray(qb.interpolate(solution.p))
    dx = qb.dx
    ph = ph - (ph * dx).sum() / dx.sum()
    ue, pe = exact.velocity(x), exact.pressure(x)
    pe = pe - (pe * dx).sum() / dx.sum()
    eu = np.sqrt((((uh - ue) ** 2).sum(0) * dx).sum() / ((ue ** 2).sum(0) * dx).sum())
    ep = np.sqrt((((ph - pe) ** 2) * dx).sum() / ((pe ** 2) * dx).sum())
    return float(eu), float(ep)


def stokes_law(radius: float, drho: float, g: float, eta: float) -> float:
    """Settling velocity of a rigid sphere in an unbounded fluid, ``2 drho g a^2 / (9 eta)``."""
    return 2.0 * drho * g * radius ** 2 / (9.0 * eta)


def haberman_sayre(lam: float) -> float:
    """Wall factor ``v / v_Stokes`` of a rigid sphere on the axis of a long cylinder,
    ``lam`` = sphere radius / cylinder radius (Haberman & Sayre 1958): about 0.792 at 0.1
    and 0.595 at 0.2."""
    num = 1.0 - 2.1050 * lam + 2.0865 * lam ** 3 - 1.7068 * lam ** 5 + 0.72603 * lam ** 6
    return num / (1.0 - 0.75857 * lam ** 5)


def settling_velocity(radius: float, cylinder_radius: float, drho: float, g: float,
                      eta: float, viscosity_ratio: float = np.inf) -> float:
    """Settling velocity of a sphere on the axis of a cylinder: Stokes' law, the
    Hadamard-Rybczynski factor ``3 (1 + r) / (2 + 3 r)`` of a viscous sphere (1 for the
    rigid one, ``r`` infinite) and the Haberman & Sayre wall factor."""
    r = viscosity_ratio
    hr = 1.0 if np.isinf(r) else 3.0 * (1.0 + r) / (2.0 + 3.0 * r)
    return stokes_law(radius, drho, g, eta) * hr * haberman_sayre(radius / cylinder_radius)
