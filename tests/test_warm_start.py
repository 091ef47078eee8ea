"""Warm-started evaluation points (``CostPoint.warm``) and their use by the Newton variants: the
same numbers as cold solves (checked against ``Network.at`` at the same rates), the same
diagnostics, a cold fallback that says why, and the same optimum from ``optimal_allocation``."""

from __future__ import annotations

import numpy as np
import pytest

import capalloc_rs as ca
from capalloc_rs.allocation import oracle


def _net(n_sensors: int = 40) -> ca.Network:
    return ca.Network.random(n_sensors, 2, eps=0.05, seed=3)


def test_warm_point_equals_the_cold_point() -> None:
    net = _net()
    r0 = np.full(40, 3.0)
    r1 = r0 * (1 + 0.01 * np.random.default_rng(0).standard_normal(40))
    warm = net.at(r0).warm(r1)
    cold = net.at(r1)
    assert warm.warm_started and warm.warm_fallback is None
    assert not cold.warm_started
    assert warm.value == pytest.approx(cold.value, rel=1e-13)
    np.testing.assert_allclose(warm.gradient, cold.gradient, rtol=1e-11, atol=0)
    v = np.random.default_rng(1).standard_normal(40)
    np.testing.assert_allclose(warm.hvp(v), cold.hvp(v), rtol=1e-10, atol=1e-14)
    # the error bounds are filled and hold against the cold solution
    assert 0 < warm.value_error < 1e-8 * warm.value
    assert abs(warm.value - cold.value) <= warm.value_error + cold.value_error
    assert np.linalg.norm(warm.sigma - cold.sigma) <= warm.forward_error * np.linalg.norm(
        cold.sigma
    ) + cold.forward_error * np.linalg.norm(cold.sigma)


def test_a_far_start_falls_back_to_the_cold_solve_and_says_why() -> None:
    net = _net(8)
    r0 = np.full(8, 1.0)
    far = net.at(r0).warm(r0 * 1e4)
    assert far.warm_fallback is not None and not far.warm_started
    assert far.value == net.at(r0 * 1e4).value  # the cold solve, bitwise


def test_warm_start_rejects_bad_rates_like_the_cold_point() -> None:
    net = _net(8)
    p = net.at(np.full(8, 1.0))
    with pytest.raises(ca.InvalidInputError):
        p.warm(np.full(8, -1.0))
    with pytest.raises(ca.ShapeError):
        p.warm(np.ones(3))


def test_newton_reaches_the_same_optimum_warm_or_cold(monkeypatch: pytest.MonkeyPatch) -> None:
    """n = 80: Newton–CG's points are warm-started; with ``warm=False`` every point is cold.
    Same optimum (η to 1e-13, r within the certified neighbourhood), both optimal to η's own
    accuracy."""
    net = _net()
    seen: list[bool] = []
    orig = ca.network.CostPoint.warm

    def spy(self: ca.network.CostPoint, r: np.ndarray) -> ca.network.CostPoint:
        p = orig(self, r)
        seen.append(p.warm_started)
        return p

    monkeypatch.setattr(ca.network.CostPoint, "warm", spy)
    warm = ca.optimal_allocation(net, 120.0, hessian="hvp")
    assert seen and any(seen)
    seen.clear()
    cold = ca.optimal_allocation(net, 120.0, hessian="hvp", warm=False)
    assert not seen
    assert warm.eta == pytest.approx(cold.eta, rel=1e-13)
    np.testing.assert_allclose(warm.r, cold.r, rtol=0, atol=1e-7)
    # both optimal to the accuracy of η itself (the gap is below η's error bound at this size)
    assert warm.optimality <= 1e-11 * warm.eta and cold.optimality <= 1e-11 * cold.eta


def test_filtration_is_the_same_warm_or_cold(monkeypatch: pytest.MonkeyPatch) -> None:
    """n = 64: the path's corrector points are warm-started; with the threshold raised, cold.
    Same entry order and breakpoints (to 1e-10 relative)."""
    net = ca.Network.random(32, 2, eps=0.05, seed=3)
    warm = ca.filtration(net, 3.0, progress=False)
    monkeypatch.setattr(oracle, "WARM_START_MIN_ORDER", 10**9)
    cold = ca.filtration(net, 3.0, progress=False)
    assert list(warm.entry_order) == list(cold.entry_order) and len(warm.breakpoints) > 2
    np.testing.assert_allclose(warm.breakpoints, cold.breakpoints, rtol=1e-10, atol=0)


@pytest.mark.parametrize("scale", [1e12, 1e14, 1e16, 1e18])
def test_warm_start_at_extreme_rates_agrees_with_the_cold_solve(scale: float) -> None:
    """From a solved point to rates 1e12…1e18 times larger: the warm start falls back, and the
    result is the cold one — the same value, or the same refusal (never a number the cold solve
    would not give)."""
    net = _net(8)
    r0 = np.full(8, 1.0)
    try:
        cold: float | type[Exception] = net.at(r0 * scale).value
    except (ca.NumericalError, ca.InputError) as e:
        cold = type(e)
    if isinstance(cold, float):
        warm = net.at(r0).warm(r0 * scale)
        assert warm.value == pytest.approx(cold, rel=1e-12)
    else:
        with pytest.raises(cold):
            net.at(r0).warm(r0 * scale)
