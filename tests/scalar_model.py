"""Decoupled scalar subsystems with closed-form Riccati solutions: an independent oracle.

Subsystem i: ``dx = a x dt + √q dw``, sensor ``y = c x`` with rate r. The filter ARE
``2aΣ − r c² Σ² + q = 0`` has the positive root ``Σ(r) = (a + s)/(r c²)``, ``s = √(a² + r c² q)``.
Differentiating: ``s' = c² q / (2s)``,
``Σ'(r) = q/(2 s r) − (a + s)/(r² c²)``,
``Σ''(r) = −q (s' r + s)/(2 s² r²) − (s' r² − 2 r (a + s))/(r⁴ c²)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq


@dataclass(frozen=True)
class ScalarNetwork:
    a: np.ndarray
    c: np.ndarray
    q: np.ndarray
    r_min: float = 1.0

    @property
    def sensors(self) -> list[int]:
        return list(range(self.a.size))

    def _parts(self, r):
        r = np.asarray(r, dtype=float)
        s = np.sqrt(self.a**2 + r * self.c**2 * self.q)
        return r, s

    def sigma_i(self, r):
        r, s = self._parts(r)
        return (self.a + s) / (r * self.c**2)

    def cost(self, r) -> float:
        return float(np.sum(self.sigma_i(r)))

    def gradient(self, r):
        r, s = self._parts(r)
        return self.q / (2 * s * r) - (self.a + s) / (r**2 * self.c**2)

    def hessian(self, r):
        r, s = self._parts(r)
        ds = self.c**2 * self.q / (2 * s)
        d2 = -self.q * (ds * r + s) / (2 * s**2 * r**2) - (ds * r**2 - 2 * r * (self.a + s)) / (
            r**4 * self.c**2
        )
        return np.diag(d2)

    def cost_many(self, rows):
        return np.array([self.cost(row) for row in np.atleast_2d(rows)])

    # Closed-form optimum: γ_i(μ) = max(0, g_i⁻¹(μ) − r_min), Σγ_i(μ) = σ solved for μ.
    def _inverse_grad(self, i: int, mu: float) -> float:
        def f(r: float) -> float:
            e = np.zeros(self.a.size)
            e[:] = 1.0
            e[i] = r
            return float(self.gradient(e)[i] - mu)

        lo = self.r_min
        if f(lo) >= 0:
            return lo
        hi = 2 * lo
        while f(hi) < 0:
            hi *= 2
            if hi > 1e12:
                return hi
        return float(brentq(f, lo, hi, xtol=1e-15, rtol=1e-15, maxiter=500))

    def gamma_of_mu(self, mu: float) -> np.ndarray:
        return np.array([self._inverse_grad(i, mu) - self.r_min for i in range(self.a.size)])

    def optimum(self, sigma: float) -> tuple[np.ndarray, float]:
        g0 = self.gradient(np.full(self.a.size, self.r_min))
        lo = float(np.min(g0))
        if sigma == 0:
            return np.zeros(self.a.size), lo
        mu = brentq(
            lambda m: float(np.sum(self.gamma_of_mu(m))) - sigma,
            lo,
            -1e-300,
            xtol=1e-300,
            rtol=1e-15,
            maxiter=500,
        )
        return self.gamma_of_mu(mu), float(mu)

    def breakpoints(self) -> list[tuple[float, int]]:
        """(σ_k, sensor entering at σ_k): sensor j enters when μ reaches g_j(r_min)."""
        g0 = self.gradient(np.full(self.a.size, self.r_min))
        order = np.argsort(g0)
        out = [(0.0, int(order[0]))]
        for j in order[1:]:
            out.append((float(np.sum(self.gamma_of_mu(float(g0[j])))), int(j)))
        return out


def random_scalar_network(seed: int, n: int = 5) -> ScalarNetwork:
    rng = np.random.default_rng(seed)
    return ScalarNetwork(
        a=rng.uniform(-2, 1, n), c=rng.uniform(0.3, 2, n), q=rng.uniform(0.2, 3, n), r_min=1.0
    )
