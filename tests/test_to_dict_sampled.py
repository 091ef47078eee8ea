"""``to_dict()`` and ``repr`` of the finite-τ results (Schedule, SampledCovariance, BestSchedule,
Candidate, MonteCarloResult): plain JSON-ready values whose keys include exactly what the CLI's
``--json`` prints, numbers that survive a JSON round trip, short one-line reprs."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from cli_reference import mc_dict as _mc_dict
from cli_reference import schedule_dict as _schedule_dict

import capalloc_rs as ca

PLAIN_LEAVES = (bool, int, float, str, type(None))


def assert_plain(x: Any, where: str = "") -> None:
    """Only dicts with str keys, lists and plain leaves (no numpy scalars, arrays or tuples)."""
    if isinstance(x, dict):
        for k, v in x.items():
            assert type(k) is str, where
            assert_plain(v, f"{where}.{k}")
    elif isinstance(x, list):
        for k, v in enumerate(x):
            assert_plain(v, f"{where}[{k}]")
    else:
        assert type(x) in PLAIN_LEAVES, f"{where}: {type(x).__name__}"
        assert not (isinstance(x, float) and not math.isfinite(x)), where


def round_trips(d: dict[str, Any]) -> None:
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text) == d  # every number comes back equal (floats: shortest repr)


@pytest.fixture(scope="module")
def net() -> ca.Network:
    return ca.Network.random(3, seed=5)


@pytest.fixture(scope="module")
def best(net: ca.Network) -> ca.BestSchedule:
    return ca.best_schedule(net, 0.5, 7, progress=False)


@pytest.fixture(scope="module")
def mc(net: ca.Network, best: ca.BestSchedule) -> ca.MonteCarloResult:
    return ca.simulate(net, 0.5, best.schedule, periods=20, seed=3, runs=4, progress=False)


def test_best_schedule_keys_are_the_clis(best: ca.BestSchedule) -> None:
    d = best.to_dict()
    cli = _schedule_dict(best)  # without the optional eta_star
    assert set(d) - set(cli) == {"start", "elapsed"}
    assert {k: d[k] for k in cli} == json.loads(json.dumps(cli, allow_nan=False))
    assert_plain(d)
    round_trips(d)
    # numbers by the other route: the result's own fields
    assert d["eta_bar"] == best.eta_bar and d["eta_limit"] == best.eta_limit
    assert d["schedule"] == [int(i) for i in best.schedule.as_array()]
    assert d["counts"] == list(best.counts) and sum(d["counts"]) == d["r_tot"] == 7
    assert d["baselines"] == {k: c.eta_bar for k, c in best.candidates.items()}
    assert d["error_vs_limit"] == best.eta_bar - best.eta_limit


def test_best_schedule_without_a_limit_is_still_json(net: ca.Network) -> None:
    # A duck-typed network has no cost(): eta_limit is NaN, which JSON gets as null.
    class Plain:
        def __init__(self) -> None:
            self.a, self.g, self.sensors = np.array(net.a), np.array(net.g), list(net.sensors)

    b = ca.best_schedule(Plain(), 0.5, 6, progress=False)
    d = b.to_dict()
    assert math.isnan(b.eta_limit)
    assert d["eta_limit"] is None and d["relative_error_vs_limit"] is None
    assert_plain(d)
    round_trips(d)


def test_monte_carlo_keys_are_the_clis(mc: ca.MonteCarloResult) -> None:
    d = mc.to_dict()
    cli = _mc_dict(mc)
    extra = {"ci_low", "ci_high", "stderr", "per_slot", "burn_in", "which", "stopped", "converged"}
    assert set(d) - set(cli) == extra
    assert {k: d[k] for k in cli} == json.loads(json.dumps(cli, allow_nan=False))
    assert_plain(d)
    round_trips(d)
    assert d["mse"] == mc.mse and d["ci"] == [mc.ci_low, mc.ci_high]
    assert d["per_slot"] == [float(v) for v in mc.per_slot] and len(d["per_slot"]) == 7


def test_monte_carlo_with_no_period_is_json() -> None:
    nan = math.nan
    r = ca.MonteCarloResult(
        nan, nan, nan, nan, 0.95, 1.5, np.full(3, nan), 4, 10, 0, None, "boundary",
        stopped="time_limit", periods_completed=0,
    )  # fmt: skip
    d = r.to_dict()
    assert d["mse"] is None and d["ci"] == [None, None] and d["per_slot"] == [None] * 3
    assert d["predicted_in_ci"] is False and d["converged"] is False
    assert_plain(d)
    round_trips(d)


def test_sampled_covariance_and_schedule(net: ca.Network, best: ca.BestSchedule) -> None:
    cov = ca.sampled_covariance(net, 0.5, best.schedule)
    d = cov.to_dict()
    assert_plain(d)
    round_trips(d)
    np.testing.assert_array_equal(np.array(d["boundary"]), cov.boundary)
    np.testing.assert_array_equal(np.array(d["priors"]), cov.priors)
    assert d["eta_boundary"] == cov.eta_boundary == pytest.approx(np.trace(cov.boundary))
    assert d["schedule"] == list(best.schedule)
    s = best.schedule.to_dict()
    assert s == {
        "slots": list(best.schedule),
        "n_sensors": 3,
        "r_tot": 7,
        "counts": [int(c) for c in np.bincount(list(best.schedule), minlength=3)],
    }
    assert_plain(s)
    for name, c in best.candidates.items():
        cd = c.to_dict()
        assert cd["name"] == name and cd["schedule"] == list(c.schedule)
        assert_plain(cd)


def test_reprs_are_one_short_line(
    net: ca.Network, best: ca.BestSchedule, mc: ca.MonteCarloResult
) -> None:
    long = ca.Schedule.round_robin(40, 400)
    cov = ca.sampled_covariance(net, 0.5, best.schedule)
    objs = [best, mc, cov, long, *best.candidates.values()]
    objs += [ca.sampled.sampled_system(net), ca.sampled.discretise(net, 0.5, 7)]
    for x in objs:
        r = repr(x)
        assert "\n" not in r and len(r) < 200, r
        assert r.startswith(type(x).__name__ + "("), r
