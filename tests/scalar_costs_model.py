"""Decoupled scalar subsystems with sample costs and rate caps: an independent closed-form oracle
of the filtration on the box-simplex (no Rust needed).

Subsystem i: ``dx = a x dt + √q dw``, sensor ``y = c x`` at rate r, samples costing ``b_i`` channel
units, ``r_min,i ≤ r_i ≤ r_max,i``, budget ``Σ b_i r_i = B``. Its error is
``η_i(r) = Σ_i(r) = (a + √(a² + q c² r))/(c² r)`` (tests/scalar_model.py), convex and decreasing,
with the explicit derivative ``η_i'(r) = q/(2 s r) − (a + s)/(r² c²)``, ``s = √(a² + r c² q)``.

KKT of ``min Σ η_i(r_i)`` on the weighted box-simplex: ``η_i'(r_i) = μ b_i`` for the free sensors,
``≥`` at the minimum, ``≤`` at the cap. ``η_i'`` being increasing, each rate is a nondecreasing
function of μ: ``r_i(μ) = clip(η_i'⁻¹(μ b_i), r_min,i, r_max,i)``. Sensor i leaves its minimum at
``μ = η_i'(r_min,i)/b_i`` and reaches its cap at ``μ = η_i'(r_max,i)/b_i``; the budget
``B(μ) = Σ b_i r_i(μ)`` is nondecreasing, so the breakpoints are ``σ_k = B(μ_k) − Σ b_i r_min,i``
at these μ_k in increasing order — the events in that order (the path is monotone: no sensor
ever falls back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scalar_model import ScalarNetwork
from scipy.optimize import brentq


@dataclass(frozen=True)
class ChannelScalarNetwork(ScalarNetwork):
    """The same subsystems in channel units ``s = b∘r``: sensors ``c/√b``, bounds ``b∘r_min``,
    ``b∘r_max`` (the duck type of ``Network.in_channel_units()``)."""

    lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hi: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def rate_min(self) -> np.ndarray:
        return self.lo

    @property
    def rate_max(self) -> np.ndarray:
        return self.hi


@dataclass(frozen=True)
class CostedScalarNetwork:
    """Scalar subsystems (``a``, ``c``, ``q``) with costs ``b`` and bounds ``[r_lo, r_hi]``."""

    a: np.ndarray
    c: np.ndarray
    q: np.ndarray
    b: np.ndarray
    r_lo: np.ndarray
    r_hi: np.ndarray

    # -- the attributes of a Network with costs and limits (the shared interface)
    @property
    def sensors(self) -> list[int]:
        return list(range(self.a.size))

    @property
    def costs(self) -> np.ndarray:
        return self.b

    @property
    def rate_min(self) -> np.ndarray:
        return self.r_lo

    @property
    def rate_max(self) -> np.ndarray:
        return self.r_hi

    @property
    def r_min(self) -> float | np.ndarray:
        return float(self.r_lo[0]) if np.all(self.r_lo == self.r_lo[0]) else self.r_lo

    @property
    def is_paper_form(self) -> bool:
        return False

    @property
    def budget_range(self) -> tuple[float, float]:
        return float(self.b @ self.r_lo), float(self.b @ self.r_hi)

    def budget_of(self, r: np.ndarray) -> float:
        return float(self.b @ r)

    def in_channel_units(self) -> ChannelScalarNetwork:
        return ChannelScalarNetwork(
            self.a, self.c / np.sqrt(self.b), self.q, 1.0, self.b * self.r_lo, self.b * self.r_hi
        )

    def _plain(self) -> ScalarNetwork:
        return ScalarNetwork(self.a, self.c, self.q)

    def cost(self, r: np.ndarray) -> float:
        return self._plain().cost(r)

    def gradient(self, r: np.ndarray) -> np.ndarray:
        return self._plain().gradient(r)

    def hessian(self, r: np.ndarray) -> np.ndarray:
        return self._plain().hessian(r)

    # -- the closed form (module docstring)
    def eta_prime(self, i: int, r: float) -> float:
        """``η_i'(r)`` (explicit)."""
        s = math.sqrt(self.a[i] ** 2 + r * self.c[i] ** 2 * self.q[i])
        return self.q[i] / (2 * s * r) - (self.a[i] + s) / (r**2 * self.c[i] ** 2)

    def rate_of_mu(self, i: int, mu: float) -> float:
        """``r_i(μ) = clip(η_i'⁻¹(μ b_i), r_min,i, r_max,i)``."""
        target = mu * self.b[i]
        lo, hi = float(self.r_lo[i]), float(self.r_hi[i])
        if self.eta_prime(i, lo) >= target:
            return lo
        if math.isfinite(hi) and self.eta_prime(i, hi) <= target:
            return hi
        top = hi if math.isfinite(hi) else 2 * lo
        while not math.isfinite(hi) and self.eta_prime(i, top) < target:
            top *= 2
        return float(
            brentq(lambda r: self.eta_prime(i, r) - target, lo, top, xtol=1e-15, rtol=1e-15)
        )

    def rates_of_mu(self, mu: float) -> np.ndarray:
        return np.array([self.rate_of_mu(i, mu) for i in range(self.a.size)])

    def sigma_of_mu(self, mu: float) -> float:
        """``σ(μ) = Σ b_i (r_i(μ) − r_min,i)``."""
        return float(self.b @ (self.rates_of_mu(mu) - self.r_lo))

    def events(self) -> list[tuple[float, str, int, float]]:
        """``(σ_k, kind, sensor, μ_k)`` of every enter and capped event, in path order (the
        first sensor enters at σ = 0)."""
        marks = []
        for i in range(self.a.size):
            marks.append((self.eta_prime(i, float(self.r_lo[i])) / self.b[i], "enter", i))
            if math.isfinite(self.r_hi[i]):
                marks.append((self.eta_prime(i, float(self.r_hi[i])) / self.b[i], "capped", i))
        marks.sort()
        return [
            (self.sigma_of_mu(mu) if k else 0.0, kind, i, mu)
            for k, (mu, kind, i) in enumerate(marks)
        ]

    def mu_of_sigma(self, sigma: float) -> float:
        """μ at σ (the least μ with σ(μ) = σ: inside a range where every free sensor is capped
        μ is not unique — the tracers take the least gradient of the next to enter)."""
        ev = self.events()
        mus = [mu for _, _, _, mu in ev]
        lo, hi = mus[0], mus[0]
        for mu in mus[1:]:
            if self.sigma_of_mu(mu) >= sigma:
                hi = mu
                break
            lo = hi = mu
        else:  # beyond the last event: μ closer to 0 until σ(μ) passes σ
            for _ in range(200):
                hi = 0.5 * hi
                if self.sigma_of_mu(hi) >= sigma:
                    break
        if self.sigma_of_mu(lo) >= sigma:
            return lo
        return float(brentq(lambda m: self.sigma_of_mu(m) - sigma, lo, hi, xtol=1e-300, rtol=1e-15))
