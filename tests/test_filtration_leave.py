"""A share that falls to r_min with a small r_min: the path records the leave and goes on.

The bug (found with the strongly coupled pair of ``test_filtration.py``, coupling (0, 1) set to 0
and (1, 0) scaled by 0.8, r_min = 0.01): the tangent predictor carried sensor 1's falling share
past its leave point to γ₁ = −0.104, i.e. a rate r₁ = −0.094 < 0, and the corrector evaluated the
cost there — ``filtration(net, 40)`` raised the *input* error "rates must be positive, got
r[1] = -0.0935" about a rate the user never gave. Steps are now shortened so that the predictor
keeps every rate above ¾·r_min, and the corrector rejects iterates below r_min/2 (a failed step
is retried shorter) instead of evaluating η outside its domain."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from capalloc_rs import Network, errors
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.allocation.oracle import PointCache  # the corrector evaluates through it

A = [-0.20838170032607684, -0.906305380654115]
G = [1.7959169092564846, 0.5702646676969306]
C = [0.23313877612885026, 0.3794600065963211]
A10 = -1.2025898262948136 * 0.8


def scalar_network(a: list[float], g: list[float], c: list[float], coupling: Any, eps: float,
                   r_min: float) -> Network:  # fmt: skip
    """Scalar subsystems ``a_i, g_i, c_i`` coupled by ``ε·coupling[i][j]``."""
    m = len(a)
    blocks = {(i, j): np.array([[coupling[i][j]]]) for i in range(m) for j in range(m) if i != j}
    return Network.from_blocks(
        [np.array([[v]]) for v in a],
        [np.array([[v]]) for v in g],
        [np.array([[v]]) for v in c],
        couplings=blocks,
        eps=eps,
        r_min=r_min,
    )


def one_way_coupled() -> Network:
    return scalar_network(A, G, C, [[0.0, 0.0], [A10, 0.0]], 1.0, 0.01)


def pointwise_share(net: Network, sigma: float, i: int) -> float:
    n = len(net.sensors)
    return float(optimal_allocation(net, sigma + n * net.r_min).gamma[i])


def bisect_leave(net: Network, i: int, lo: float, hi: float) -> float:
    """Where sensor i's pointwise optimal share reaches 0 (independent of the path tracer)."""
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if pointwise_share(net, mid, i) > 0.0 else (lo, mid)
    return 0.5 * (lo + hi)


def test_share_falling_to_a_small_r_min_leaves_and_the_path_goes_on() -> None:
    net = one_way_coupled()
    f = filtration(net, 40.0, progress=False)
    assert f.converged and f.sigma_max == 40.0
    assert [(ev.kind, ev.sensor) for ev in f.events] == [
        ("enter", 1),
        ("enter", 0),
        ("monotonicity-lost", 1),
        ("leave", 1),
    ]
    assert f.active_sets == ((1,), (0, 1), (0,))
    assert not f.is_filtration and not f.is_monotone
    s_leave = float(f.breakpoints[2])
    # Against pointwise optima (optimal_allocation, not the tracer): sensor 1's share is
    # positive just before the breakpoint and exactly at r_min just after; the breakpoint agrees
    # with a bisection on pointwise optima (measured 6.9e-11; events are located to
    # tol·σ_max = 4e-9).
    assert pointwise_share(net, s_leave - 1e-3, 1) > 1e-4
    after = optimal_allocation(net, s_leave + 1e-3 + 2 * net.r_min)
    assert after.r[1] == net.r_min and after.gamma[1] == 0.0
    assert s_leave == pytest.approx(bisect_leave(net, 1, 6.0, 9.0), abs=4e-9)
    # The path on both sides and beyond against pointwise optima.
    for s in [1.0, 3.0, 7.0, s_leave - 1e-6, s_leave + 1e-6, 8.0, 20.0, 40.0]:
        want = optimal_allocation(net, s + 2 * net.r_min).gamma
        np.testing.assert_allclose(f.allocation(s), want, atol=1e-9 * max(s, 1.0))
    # Every node's rates stayed in the domain (the bug evaluated r₁ = −0.094).
    assert np.all(f.node_gamma + net.r_min > 0.0)


def test_smaller_r_min_still_leaves() -> None:
    # The predictor's bound scales with r_min: at r_min = 1e-6 the share is carried to within
    # 2.5e-7 past its leave point — still no input error, and the same breakpoint as pointwise.
    net = scalar_network(A, G, C, [[0.0, 0.0], [A10, 0.0]], 1.0, 1e-6)
    f = filtration(net, 40.0, progress=False)
    assert [ev.kind for ev in f.events][-1] == "leave" and f.active_sets[-1] == (0,)
    assert float(f.breakpoints[-2]) == pytest.approx(bisect_leave(net, 1, 6.0, 9.0), abs=4e-9)


coef = st.floats(-1.5, 0.5)
positive = st.floats(0.3, 2.0)
out = st.floats(0.1, 1.0)
couple = st.floats(-2.0, 2.0)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    m=st.integers(2, 3),
    a=st.lists(coef, min_size=3, max_size=3),
    g=st.lists(positive, min_size=3, max_size=3),
    c=st.lists(out, min_size=3, max_size=3),
    coupling=st.lists(st.lists(couple, min_size=3, max_size=3), min_size=3, max_size=3),
    eps=st.floats(0.2, 1.5),
    log_r_min=st.floats(-3.0, 0.0),
)
@example(  # the bug's network
    m=2, a=[*A, 0.0], g=[*G, 1.0], c=[*C, 1.0],
    coupling=[[0.0, 0.0, 0.0], [A10, 0.0, 0.0], [0.0, 0.0, 0.0]], eps=1.0, log_r_min=-2.0,
)  # fmt: skip
def test_filtration_never_raises_an_input_error(
    m: int,
    a: list[float],
    g: list[float],
    c: list[float],
    coupling: list[list[float]],
    eps: float,
    log_r_min: float,
) -> None:
    try:
        net = scalar_network(a[:m], g[:m], c[:m], coupling, eps, 10.0**log_r_min)
    except errors.InputError:
        return  # e.g. not detectable: not the filtration's concern
    try:
        f = filtration(net, 40.0, progress=False)
    except errors.ConvergenceError:
        return  # allowed by the contract (names σ); never observed on these networks
    for ev in f.events:
        if ev.kind == "leave":  # each leave agrees with pointwise optima on both sides
            assert pointwise_share(net, ev.sigma - 1e-3, ev.sensor) > 0.0
            assert pointwise_share(net, ev.sigma + 1e-3, ev.sensor) == 0.0


FMOD = sys.modules["capalloc_rs.allocation.filtration"]  # the module, not the function


def three_with_a_leave() -> Network:
    """Three scalar subsystems (from a random scan): all three active, then sensor 1 falls and
    leaves at σ ≈ 4.34 while sensors 0 and 2 rise — one of them with a slope below 1."""
    return scalar_network(
        [0.015603280704548972, -0.9504002076878566, 0.28584036704194915],
        [1.7819696677383023, 0.37503743579562765, 1.9263028291652335],
        [0.7921043292576108, 0.8682217233160283, 0.5311411742337196],
        [
            [0.0, 1.1798616645970266, 1.6455981002702305],
            [1.5884227060284157, 0.0, -0.8925417256163253],
            [-1.3160984644928164, 0.5934054205004582, 0.0],
        ],
        0.7780783803578288,
        0.05225027416955275,
    )


@pytest.mark.parametrize("make", [one_way_coupled, three_with_a_leave])
def test_predictor_keeps_rates_above_three_quarters_of_r_min(
    make: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The stated step rule: every prediction handed to the corrector keeps the active rates
    # above ¾·r_min (the bug predicted r₁ = −0.094 with r_min = 0.01); so on these paths the
    # corrector never fails and the leave is crossed by a prediction just past γ_i = 0.
    net = make()
    guesses: list[float] = []
    failures: list[float] = []
    correct = FMOD._Tracer.correct

    def spy(self: Any, active: Any, sigma: float, gamma0: Any, mu0: float, *caps: Any) -> Any:
        guesses.append(float(np.min(np.asarray(gamma0)[list(active)])))
        try:
            return correct(self, active, sigma, gamma0, mu0, *caps)
        except errors.ConvergenceError:
            failures.append(sigma)
            raise

    monkeypatch.setattr(FMOD._Tracer, "correct", spy)
    f = filtration(net, 40.0, progress=False, method="reference")
    assert [ev.kind for ev in f.events][-1] == "leave"
    assert failures == []
    assert min(guesses) >= -0.25 * net.r_min * (1 + 1e-9)
    assert min(guesses) < 0.0  # a prediction did cross the leave point
    leave = [ev for ev in f.events if ev.kind == "leave"][0]
    assert pointwise_share(net, leave.sigma - 1e-3, leave.sensor) > 0.0
    assert pointwise_share(net, leave.sigma + 1e-3, leave.sensor) == 0.0


def test_corrector_never_evaluates_below_half_r_min(monkeypatch: pytest.MonkeyPatch) -> None:
    # A prediction (or Newton iterate) with a rate below r_min/2 is a corrector failure (the
    # caller retries a shorter step), never an evaluation of η there.
    net = one_way_coupled()
    evaluated: list[float] = []
    vgh = PointCache.value_gradient_hessian

    def spy(self: Any, r: Any) -> Any:
        evaluated.append(float(np.min(r)))
        return vgh(self, r)

    monkeypatch.setattr(PointCache, "value_gradient_hessian", spy)
    tracer = FMOD._Tracer(net, 1e-10)
    f = filtration(net, 7.0, progress=False)  # just before sensor 1 leaves (σ ≈ 7.448)
    p = f.node_gamma[-1]
    mu = float(f.node_mu[-1])
    for below in (0.6, 1.0, 50.0):  # γ₁ = −0.6·r_min, −r_min (r₁ = 0), −50·r_min
        evaluated.clear()
        guess = np.array([p[0] + p[1] + below * net.r_min, -below * net.r_min])
        with pytest.raises(errors.ConvergenceError, match="did not converge"):
            tracer.correct([0, 1], 7.0, guess, mu)
        assert evaluated == []
    # Just inside the bound the corrector evaluates and converges back to the node.
    evaluated.clear()
    guess = np.array([p[0] + p[1] + 0.45 * net.r_min, -0.45 * net.r_min])
    q = tracer.correct([0, 1], 7.0, guess, mu)
    assert min(evaluated) == pytest.approx(0.55 * net.r_min, rel=1e-12)
    np.testing.assert_allclose(q.gamma, p, atol=1e-9)


@pytest.mark.parametrize("make", [one_way_coupled, three_with_a_leave])
def test_continuation_and_reference_agree_through_a_leave(make: Any) -> None:
    # The leave is solved by Newton on the KKT system closed by γ_i = 0 (continuation) and
    # located by false position on pointwise solves (reference): the same events, to 1e-9.
    net = make()
    new = filtration(net, 40.0, progress=False)
    ref = filtration(net, 40.0, progress=False, method="reference")
    assert "leave" in [ev.kind for ev in new.events]
    assert [(e.kind, e.sensor) for e in new.events] == [(e.kind, e.sensor) for e in ref.events]
    assert new.active_sets == ref.active_sets
    for a, b in zip(new.events, ref.events, strict=True):
        assert a.sigma == pytest.approx(b.sigma, rel=1e-9, abs=1e-12)
