"""Analytic solutions used to verify the models.

- :class:`SolCx`: Stokes flow in the unit square with a viscosity jump
  (Zhong 1996; Duretz et al. 2011), free slip on all walls.
- :class:`DoneaHuerta`: a manufactured Stokes flow in the unit square with
  constant viscosity and no slip (Donea and Huerta 2003, section 6.8), smooth,
  for convergence rates.
- :func:`viscoelastic_buildup`: Maxwell stress under constant strain rate
  (Gerya and Yuen 2007), optionally capped by a yield stress.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DoneaHuerta", "SolCx", "viscoelastic_buildup"]


class SolCx:
    """The SolCx Stokes solution, computed here from its stream function.

    Unit square, z vertical (the second coordinate), gravity ``g`` downward,
    density ``rho = sin(pi z) cos(pi x)``, so the body force is
    ``f = (0, -rho g)``; viscosity ``eta_left`` for x < ``xc`` and
    ``eta_right`` beyond; free slip on all walls; pressure of mean zero.

    Derivation: with stream function ``psi = Psi(x) sin(pi z)``
    (``u_x = d psi/dz``, ``u_z = -d psi/dx``) the momentum equations give
    ``eta (D^2 - pi^2)^2 Psi = g pi sin(pi x)`` in each half, a constant
    coefficient ODE solved by ``(a + b x) e^{pi x} + (c + d x) e^{-pi x}``
    plus ``g sin(pi x) / (4 pi^3 eta)``. Free slip at x = 0, 1 asks
    ``Psi = Psi'' = 0``; at the interface ``Psi``, ``Psi'``, the shear stress
    ``eta (Psi'' + pi^2 Psi)`` and the normal stress
    ``eta (Psi''' - 3 pi^2 Psi')`` are continuous. The eight coefficients
    come from that 8 x 8 linear system. Pressure:
    ``p = cos(pi z) (eta (Psi''' - pi^2 Psi') + g cos(pi x)) / pi``.
    """

    def __init__(self, eta_left: float = 1.0, eta_right: float = 1e6, xc: float = 0.5,
                 g: float = 1.0):
        for name, v in (("eta_left", eta_left), ("eta_right", eta_right)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v}")
        if not 0 < xc < 1:
            raise ValueError(f"xc must lie in (0, 1), got {xc}")
        self.eta = (float(eta_left), float(eta_right))
        self.xc = float(xc)
        self.g = float(g)
        k = np.pi
        self.k = k
        # unknowns: a_L (4), a_R (4); basis centred at xc for conditioning
        M = np.zeros((8, 8))
        r = np.zeros(8)
        row = 0

        def bas(x, n):
            return self._basis(x, n)

        def part(x, n, side):
            return self._part(x, n, side)

        for side, xb in ((0, 0.0), (1, 1.0)):
            for n in (0, 2):
                M[row, 4 * side:4 * side + 4] = bas(xb, n)
                r[row] = -part(xb, n, side)
                row += 1
        eL, eR = self.eta
        for coef in ((0, None), (1, None), ("shear", None), ("normal", None)):
            kind = coef[0]
            if kind in (0, 1):
                cL = bas(xc, kind)
                cR = bas(xc, kind)
                rhs = part(xc, kind, 1) - part(xc, kind, 0)
                M[row, :4], M[row, 4:] = cL, -cR
            elif kind == "shear":
                cL = eL * (bas(xc, 2) + k ** 2 * bas(xc, 0))
                cR = eR * (bas(xc, 2) + k ** 2 * bas(xc, 0))
                rhs = (eR * (part(xc, 2, 1) + k ** 2 * part(xc, 0, 1))
                       - eL * (part(xc, 2, 0) + k ** 2 * part(xc, 0, 0)))
                M[row, :4], M[row, 4:] = cL, -cR
            else:
                cL = eL * (bas(xc, 3) - 3 * k ** 2 * bas(xc, 1))
                cR = eR * (bas(xc, 3) - 3 * k ** 2 * bas(xc, 1))
                rhs = (eR * (part(xc, 3, 1) - 3 * k ** 2 * part(xc, 1, 1))
                       - eL * (part(xc, 3, 0) - 3 * k ** 2 * part(xc, 1, 0)))
                M[row, :4], M[row, 4:] = cL, -cR
            r[row] = rhs
            row += 1
        # scale rows for conditioning
        s = np.abs(M).max(axis=1)
        self.coef = np.linalg.solve(M / s[:, None], r / s)

    def _basis(self, x, n):
        """n-th derivatives of e^{k s}, s e^{k s}, e^{-k s}, s e^{-k s}, s = x - xc."""
        k = self.k
        s = np.asarray(x, dtype=float) - self.xc
        ep, em = np.exp(k * s), np.exp(-k * s)
        return np.array([k ** n * ep,
                         (s * k ** n + n * k ** (n - 1)) * ep,
                         (-k) ** n * em,
                         (s * (-k) ** n + n * (-k) ** (n - 1)) * em])

    def _part(self, x, n, side):
        A = self.g / (4 * np.pi ** 3 * self.eta[side])
        return A * np.pi ** n * np.sin(np.pi * np.asarray(x, dtype=float) + n * np.pi / 2)

    def Psi(self, x, n=0):
        """n-th x-derivative of the stream-function profile at x (any shape)."""
        x = np.asarray(x, dtype=float)
        out = np.empty_like(x)
        for side in (0, 1):
            sel = (x < self.xc) if side == 0 else (x >= self.xc)
            c = self.coef[4 * side:4 * side + 4]
            out[sel] = np.tensordot(c, self._basis(x[sel], n), axes=1) + self._part(x[sel], n, side)
        return out

    def viscosity(self, x) -> np.ndarray:
        """eta at points x (2, ...)."""
        return np.where(np.asarray(x[0]) < self.xc, self.eta[0], self.eta[1])

    def density(self, x) -> np.ndarray:
        return np.sin(np.pi * x[1]) * np.cos(np.pi * x[0])

    def force(self, x) -> np.ndarray:
        """Body force (2, ...) = (0, -rho g)."""
        return np.stack([np.zeros_like(np.asarray(x[0], dtype=float)), -self.g * self.density(x)])

    def velocity(self, x) -> np.ndarray:
        """(2, ...) velocity at points x (2, ...)."""
        k = self.k
        return np.stack([k * self.Psi(x[0]) * np.cos(k * x[1]),
                         -self.Psi(x[0], 1) * np.sin(k * x[1])])

    def velocity_gradient(self, x) -> np.ndarray:
        """(2, 2, ...) with [i, j] = d u_i / d x_j."""
        k = self.k
        P0, P1, P2 = self.Psi(x[0]), self.Psi(x[0], 1), self.Psi(x[0], 2)
        c, s = np.cos(k * x[1]), np.sin(k * x[1])
        return np.array([[k * P1 * c, -k ** 2 * P0 * s],
                         [-P2 * s, -k * P1 * c]])

    def pressure(self, x) -> np.ndarray:
        """Pressure (mean zero) at points x (2, ...)."""
        k = self.k
        eta = self.viscosity(x)
        return np.cos(k * x[1]) * (eta * (self.Psi(x[0], 3) - k ** 2 * self.Psi(x[0], 1))
                                   + self.g * np.cos(np.pi * x[0])) / k


class DoneaHuerta:
    """Donea and Huerta's manufactured Stokes flow (Finite Element Methods
    for Flow Problems, 2003, section 6.8.1) on the unit square, viscosity 1::

        u_x =  x^2 (1 - x)^2 (2 y - 6 y^2 + 4 y^3)
        u_y = -y^2 (1 - y)^2 (2 x - 6 x^2 + 4 x^3)
        p   =  x (1 - x) - 1/6

    Divergence-free, zero on the whole boundary (no slip), pressure of mean
    zero; the body force ``f = -div(2 eps(u)) + grad p = -lap u + grad p``
    makes it a solution. Methods take points x of shape (2, ...).
    """

    @staticmethod
    def velocity(x):
        X, Y = x[0], x[1]
        return np.stack([X ** 2 * (1 - X) ** 2 * (2 * Y - 6 * Y ** 2 + 4 * Y ** 3),
                         -Y ** 2 * (1 - Y) ** 2 * (2 * X - 6 * X ** 2 + 4 * X ** 3)])

    @staticmethod
    def _factors(x):
        """u_x = a(x) b'(y), u_y = -a'(x) b(y) with a(s) = b(s) = s^2 (1 - s)^2:
        the values and first three derivatives of a at x[0] and of b at x[1]."""
        def f(s):
            return (s ** 2 * (1 - s) ** 2, 2 * s - 6 * s ** 2 + 4 * s ** 3,
                    2 - 12 * s + 12 * s ** 2, -12 + 24 * s)
        return f(x[0]), f(x[1])

    @staticmethod
    def velocity_gradient(x):
        """(2, 2, ...): [i, j] = d u_i / d x_j."""
        (a, da, dda, _), (b, db, ddb, _) = DoneaHuerta._factors(x)
        return np.stack([np.stack([da * db, a * ddb]), np.stack([-dda * b, -da * db])])

    @staticmethod
    def pressure(x):
        return x[0] * (1 - x[0]) - 1.0 / 6.0

    @staticmethod
    def force(x):
        (a, da, dda, d3a), (b, db, ddb, d3b) = DoneaHuerta._factors(x)
        lap_ux = dda * db + a * d3b
        lap_uy = -(d3a * b + da * ddb)
        return np.stack([-lap_ux + (1 - 2 * x[0]), -lap_uy + 0 * x[1]])


def viscoelastic_buildup(t, eta: float, mu: float, strain_rate: float,
                         yield_stress: float = np.inf):
    """Maxwell shear stress under constant strain rate from zero stress.

    ``sigma(t) = 2 eta edot (1 - exp(-mu t / eta))``, capped at the yield
    stress if given (perfect plasticity: once reached the stress stays at
    the cap). Units: t in s, eta in Pa s, mu in Pa, edot in 1/s, result Pa.
    """
    t = np.asarray(t, dtype=float)
    s = 2.0 * eta * strain_rate * (1.0 - np.exp(-mu * t / eta))
    return np.minimum(s, yield_stress)
