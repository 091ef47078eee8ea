"""The Armijo line search of the allocation methods: the acceptance rule itself, on a cost whose
values along the search line are known in closed form, and monotonicity of η across every accepted
step of Newton (both variants) and projected gradient on real problems where the full step is
sometimes rejected."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from capalloc_rs import Network
from capalloc_rs.allocation import NOISE_DECREASE, STAGNATION_GAP, first_order, optimal_allocation
from capalloc_rs.allocation import newton as alloc_mod

ARMIJO_C = 1e-4  # the sufficient-decrease constant documented in allocation.newton._armijo


@dataclass
class Quadratic:
    """``η(r) = Σ w_i (r_i − c_i)²`` with ``r_min = 0``: along ``γ + t d`` the cost is exactly
    ``φ(t) = φ(0) + t·φ'(0) + t²·Σ w_i d_i²``. Counts its evaluations."""

    w: np.ndarray
    c: np.ndarray
    r_min: float = 0.0
    calls: int = field(default=0)

    @property
    def sensors(self) -> list[int]:
        return list(range(self.w.size))

    def cost(self, r: Any) -> float:
        self.calls += 1
        r = np.asarray(r, dtype=float)
        return float(np.sum(self.w * (r - self.c) ** 2))


def armijo_step(q: Quadratic, gamma: np.ndarray, d: np.ndarray) -> float:
    """The first ``t ∈ {1, 1/2, 1/4, …}`` with ``φ(t) ≤ φ(0) + 1e-4·t·φ'(0)`` (closed form)."""
    f0 = float(np.sum(q.w * (gamma - q.c) ** 2))
    slope = float(np.sum(2 * q.w * (gamma - q.c) * d))
    curv = float(np.sum(q.w * d * d))
    t = 1.0
    while f0 + t * slope + t * t * curv > f0 + ARMIJO_C * t * slope:
        t *= 0.5
    return t


def test_acceptance_rule_backtracks_past_an_increase() -> None:
    # φ(t) = ¼ − 2t + 8t² (minimum at t = 1/8): φ(1) = 6.25 and φ(1/2) = 1.25 exceed φ(0) = ¼,
    # φ(1/4) = ¼ equals it (not a sufficient decrease), φ(1/8) = 1/8 is accepted. Exact in binary.
    q = Quadratic(w=np.array([1.0, 1.0]), c=np.array([3.5, 3.0]))
    gamma = np.array([3.0, 3.0])
    d = np.array([2.0, -2.0])
    f0 = q.cost(gamma)
    slope = float(np.sum(2 * q.w * (gamma - q.c) * d))
    assert (f0, slope) == (0.25, -2.0)
    t = armijo_step(q, gamma, d)
    assert t == 0.125
    q.calls = 0
    new, f, ok = alloc_mod._armijo(q, 0.0, gamma, d, f0, slope)
    assert ok
    np.testing.assert_array_equal(new, gamma + t * d)
    assert f == 0.125 and f == q.cost(new)
    assert q.calls == 4 + 1  # t = 1, 1/2, 1/4, 1/8, and the check above


def test_acceptance_rule_takes_the_full_step_when_it_decreases_enough() -> None:
    q = Quadratic(w=np.array([1.0, 3.0]), c=np.array([2.0, 0.5]))
    gamma = np.array([1.0, 1.0])
    d = np.array([0.5, -0.5])
    f0 = q.cost(gamma)
    slope = float(np.sum(2 * q.w * (gamma - q.c) * d))
    assert armijo_step(q, gamma, d) == 1.0
    new, f, ok = alloc_mod._armijo(q, 0.0, gamma, d, f0, slope)
    assert ok and f < f0
    np.testing.assert_array_equal(new, gamma + d)


def test_acceptance_rule_refuses_an_ascent_direction() -> None:
    # The caller claims descent (slope < 0) but η increases for every t > 0 along d: no step may be
    # accepted — the search must give up and return the start unchanged.
    q = Quadratic(w=np.array([1.0, 1.0]), c=np.array([0.0, 0.0]))
    gamma = np.array([1.0, 1.0])
    d = np.array([0.5, 0.5])
    f0 = q.cost(gamma)
    new, f, ok = alloc_mod._armijo(q, 0.0, gamma, d, f0, -1e-3)
    assert not ok
    assert f == f0
    np.testing.assert_array_equal(new, gamma)


def test_sufficient_decrease_constant_is_1e_4() -> None:
    # φ(t) = f0 + t·s + t²·q with q/(−s) = 1.9997: φ(1) > f0 is rejected; at t = ½ the decrease
    # is 7.5e-5·|s|, which meets 1e-4·t·|s| = 5e-5·|s| but not 2e-4·t·|s| (nor 1e-4/t·|s|).
    q = Quadratic(w=np.array([1.0, 1.0]), c=np.array([3.0 + 1.00015, 3.0]))
    gamma = np.array([3.0, 3.0])
    d = np.array([2.0, -2.0])
    f0 = q.cost(gamma)
    slope = float(np.sum(2 * q.w * (gamma - q.c) * d))
    t = armijo_step(q, gamma, d)
    assert t == 0.5
    new, f, ok = alloc_mod._armijo(q, 0.0, gamma, d, f0, slope)
    assert ok
    np.testing.assert_array_equal(new, gamma + t * d)
    assert f0 + 2 * ARMIJO_C * t * slope < f <= f0 + ARMIJO_C * t * slope


def test_noise_level_predicted_decrease_takes_the_full_step() -> None:
    # With full_step_in_noise (Newton), a predicted decrease of at most NOISE_DECREASE·|η| is not
    # searched: comparing η values would measure rounding, so the full step is returned with its
    # cost, even if that cost is higher (progress is then judged by the certificate).
    q = Quadratic(w=np.array([1.0, 1.0]), c=np.array([0.0, 0.0]))
    gamma = np.array([7.0, 7.0])
    d = np.array([0.5, 0.5])  # an ascent direction: the search itself would refuse it
    f0 = q.cost(gamma)
    assert f0 == 98.0
    slope = -NOISE_DECREASE * f0  # exactly at the threshold (inclusive)
    new, f, ok = alloc_mod._armijo(q, 0.0, gamma, d, f0, slope, full_step_in_noise=True)
    assert ok and f == q.cost(gamma + d) and f > f0
    np.testing.assert_array_equal(new, gamma + d)
    # Twice the threshold: searched, and refused.
    new2, f2, ok2 = alloc_mod._armijo(q, 0.0, gamma, d, f0, 2 * slope, full_step_in_noise=True)
    assert not ok2 and f2 == f0
    np.testing.assert_array_equal(new2, gamma)
    # Without the flag the same call searches and refuses.
    _, _, ok3 = alloc_mod._armijo(q, 0.0, gamma, d, f0, slope)
    assert not ok3


def test_first_trial_goes_through_the_evaluation_point() -> None:
    # `first` evaluates the full step (Newton passes its cached CostPoint so the accepted trial is
    # the next step's point); later trials use net.cost.
    q = Quadratic(w=np.array([1.0, 1.0]), c=np.array([3.5, 3.0]))
    gamma, d = np.array([3.0, 3.0]), np.array([2.0, -2.0])
    seen: list[np.ndarray] = []

    def first(r: np.ndarray) -> float:
        seen.append(r.copy())
        return float(np.sum(q.w * (r - q.c) ** 2))

    q.calls = 0
    new, _, ok = alloc_mod._armijo(q, 0.0, gamma, d, q.cost(gamma), -2.0, first=first)
    assert ok and len(seen) == 1 and q.calls == 1 + 3  # the start, then t = 1/2, 1/4, 1/8
    np.testing.assert_array_equal(seen[0], gamma + d)
    np.testing.assert_array_equal(new, gamma + 0.125 * d)


# -- monotonicity along real runs -----------------------------------------------------------------


@dataclass
class Search:
    f0: float
    f: float
    f_check: float
    ok: bool
    full: bool
    noise: bool


@pytest.fixture
def searches(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Search]]:
    """Records every line search: the cost before, the cost reported at the returned point, and
    that cost evaluated again directly with ``net.cost`` (an independent check of the report)."""
    log: list[Search] = []
    original = alloc_mod._armijo

    def recording(
        net: Any, r_min: float, gamma: Any, d: Any, f0: float, slope: float, **kw: Any
    ) -> Any:
        new, f, ok = original(net, r_min, gamma, d, f0, slope, **kw)
        full = bool(np.allclose(new, np.maximum(gamma + d, 0.0), rtol=0, atol=1e-15 * max(1, f0)))
        noise = bool(kw.get("full_step_in_noise")) and -slope <= NOISE_DECREASE * abs(f0)
        log.append(Search(f0, f, float(net.cost(new + r_min)), ok, full, noise))
        return new, f, ok

    monkeypatch.setattr(alloc_mod, "_armijo", recording)
    monkeypatch.setattr(first_order, "_armijo", recording)
    yield log


def assert_monotone(log: list[Search]) -> None:
    assert log, "no line search ran"
    for k, s in enumerate(log):
        assert s.f == pytest.approx(s.f_check, rel=1e-12), k
        if not s.ok:
            assert s.f == s.f0, k
        elif s.noise:  # at the rounding level of η: any change is rounding
            assert abs(s.f - s.f0) <= 1e-12 * abs(s.f0), k
        else:  # equality: a decrease below half an ulp of η (Armijo's bound rounds to f0)
            assert s.f <= s.f0, (k, s)


@dataclass
class PseudoHuber:
    """``η(r) = Σ w_i √(1 + (r_i − c_i)²)``: convex, but far from ``c`` its curvature is tiny, so
    the Newton step of the quadratic model overshoots (in one dimension the iteration is
    ``x ← −x³``) and the full step *increases* η — the line search must backtrack. Offers what
    both Newton variants use: cost/gradient/Hessian and an ``at(r)`` evaluation point."""

    w: np.ndarray
    c: np.ndarray
    r_min: float = 1.0

    @property
    def sensors(self) -> list[int]:
        return list(range(self.w.size))

    def cost(self, r: Any) -> float:
        x = np.asarray(r, dtype=float) - self.c
        return float(np.sum(self.w * np.sqrt(1.0 + x * x)))

    def gradient(self, r: Any) -> np.ndarray:
        x = np.asarray(r, dtype=float) - self.c
        return np.asarray(self.w * x / np.sqrt(1.0 + x * x))

    def hessian(self, r: Any) -> np.ndarray:
        x = np.asarray(r, dtype=float) - self.c
        return np.diag(self.w / (1.0 + x * x) ** 1.5)

    def at(self, r: Any) -> Any:
        net = self

        class Point:
            value = net.cost(r)
            gradient = net.gradient(r)

            @staticmethod
            def hvp(v: Any) -> Any:
                return net.hessian(r) @ np.asarray(v, dtype=float)

            @staticmethod
            def hessian() -> Any:
                return net.hessian(r)

        return Point()


def pseudo_huber() -> PseudoHuber:
    return PseudoHuber(w=np.array([1.0, 1.3, 0.8, 1.1]), c=np.array([2.0, 9.0, 4.0, 6.0]))


@pytest.mark.parametrize("hessian", ["exact", "hvp"])
def test_newton_never_increases_eta_where_the_full_step_overshoots(
    searches: list[Search], hessian: str
) -> None:
    net = pseudo_huber()
    sigma = 40.0
    start = np.array([sigma, 0.0, 0.0, 0.0])  # far from c: the quadratic model is very flat
    res = optimal_allocation(net, sigma + 4, gamma0=start, hessian=hessian)  # type: ignore[arg-type]
    assert res.hessian == hessian and res.gap <= 1e-12 * res.eta

    # The optimum by an independent route: KKT for a separable cost, w_i x_i/√(1+x_i²) = μ on the
    # active set, solved for μ by bisection (all sensors are active here).
    def total(mu: float) -> float:
        x = mu / np.sqrt(net.w**2 - mu**2)  # inverse of w x/√(1+x²) = μ
        return float(np.sum(np.maximum(net.c + x - net.r_min, 0.0)))

    lo, hi = -float(np.min(net.w)), float(np.min(net.w))  # μ ranges over (−min w, min w)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if total(mid) < sigma else (lo, mid)
    x = lo / np.sqrt(net.w**2 - lo**2)
    np.testing.assert_allclose(res.r, net.c + x, atol=1e-8)
    assert_monotone(searches)
    overshoots = [s for s in searches if s.ok and not s.full]
    assert len(overshoots) >= 2, "the full step was always accepted"


@pytest.mark.parametrize("seed", [0, 1])
def test_projected_gradient_never_increases_eta(searches: list[Search], seed: int) -> None:
    net = Network.random(6, 2, eps=0.3, seed=seed)
    res = optimal_allocation(net, 36.0, method="projected-gradient")
    assert res.gap <= STAGNATION_GAP * res.eta
    assert_monotone(searches)
    assert any(not s.full for s in searches if s.ok), "the full step was always accepted"
