"""``to_dict()`` and ``repr`` of the model and allocation results.

For :class:`Allocation` and :class:`Filtration` the dict has the keys the CLI's ``--json`` prints
(``cli_reference.allocation_dict`` / ``filtration_dict``: the old CLI's builders, the independent
route) with the same values
after the CLI's JSON conversion; every dict is strict JSON made of plain Python values only, and
its numbers give back the result's numbers exactly.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_reference import allocation_dict, filtration_dict

import capalloc_rs as ca
from capalloc_rs._json import plain

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PLAIN = (int, float, str, bool, type(None))


def assert_plain(x: Any, where: str = "") -> None:
    """Only int, float, str, bool, None, lists and dicts with str keys; no numpy type."""
    if isinstance(x, dict):
        for k, v in x.items():
            assert type(k) is str, f"{where}: key {k!r}"
            assert_plain(v, f"{where}.{k}")
    elif isinstance(x, list):
        for i, v in enumerate(x):
            assert_plain(v, f"{where}[{i}]")
    else:
        assert type(x) in PLAIN, f"{where}: {type(x).__name__}"
        assert not (isinstance(x, float) and not math.isfinite(x)), where


def strict_json(d: dict[str, Any]) -> dict[str, Any]:
    out = json.loads(json.dumps(d, allow_nan=False))
    assert out == d
    return out


@pytest.fixture(scope="module")
def net() -> ca.Network:
    return ca.Network.load(EXAMPLES / "three_subsystems.toml")


@pytest.mark.parametrize("hessian", ["exact", "hvp"])
def test_allocation_to_dict_has_the_cli_keys_and_values(net: ca.Network, hessian: str) -> None:
    a = ca.optimal_allocation(net, 9.0, hessian=hessian)  # type: ignore[arg-type]
    d = a.to_dict()
    assert_plain(d)
    strict_json(d)
    cli_view = plain(allocation_dict(a))
    assert set(cli_view) <= set(d)
    assert {k: d[k] for k in cli_view} == cli_view
    assert set(d) - set(cli_view) == {
        "eta_error",
        "certified",
        "optimality",
        "shadow_price",
        # issue 15: the budget, costs, the sensors at their bounds and the bound multipliers
        "budget",
        "costs",
        "at_minimum",
        "at_cap",
        "lower_multipliers",
        "upper_multipliers",
    }
    # The numbers round-trip exactly.
    np.testing.assert_array_equal(np.array(d["r"]), a.r)
    np.testing.assert_array_equal(np.array(d["gamma"]), a.gamma)
    np.testing.assert_array_equal(np.array(d["gradient"]), a.gradient)
    np.testing.assert_array_equal(np.array(d["active"]), a.active)
    assert d["eta"] == a.eta and d["mu"] == a.mu and d["r_tot"] == a.r_tot
    assert d["certificate"] == {"frank_wolfe_gap": a.gap, "kkt_residual": a.kkt_residual}
    assert d["hessian"] == hessian and d["certified"] is a.certified
    assert math.isclose(sum(d["r"]), 9.0, rel_tol=1e-14)


def test_integer_allocation_to_dict(net: ca.Network) -> None:
    res = ca.integer_allocation(net, 9)
    d = res.to_dict()
    assert_plain(d)
    strict_json(d)
    assert set(d) == {
        "counts",
        "eta",
        "exchanges",
        "evaluations",
        "lower_bound",
        "gap",
        "proven_optimal",
        "tolerance",
        "method",
        "nodes",
        "stopped",
    }
    assert d["lower_bound"] <= d["eta"] and d["gap"] == res.eta - res.lower_bound >= 0
    assert d["counts"] == [int(c) for c in res.counts] and sum(d["counts"]) == 9
    assert d["eta"] == res.eta == net.cost(np.array(d["counts"], dtype=float))


def test_filtration_to_dict_has_the_cli_keys_and_values(net: ca.Network) -> None:
    f = ca.filtration(net, 6.0, progress=False)
    d = f.to_dict()
    assert_plain(d)
    strict_json(d)
    cli_view = plain(filtration_dict(f))
    assert set(cli_view) <= set(d)
    # the events keep the old keys and values and gain ``mu`` and ``shadow_price`` beside them
    old_events = cli_view.pop("events")
    assert [{k: e[k] for k in ("sigma", "kind", "sensor")} for e in d["events"]] == old_events
    assert all(e["shadow_price"] == -e["mu"] > 0 for e in d["events"])
    assert {k: d[k] for k in cli_view} == cli_view
    np.testing.assert_array_equal(np.array(d["breakpoints"]), f.breakpoints)
    assert d["active_sets"] == [list(s) for s in f.active_sets]
    assert [(e["sigma"], e["kind"], e["sensor"]) for e in d["events"]] == [
        (e.sigma, e.kind, e.sensor) for e in f.events
    ]
    assert d["sigma_requested"] == 6.0 and d["converged"] is True


def test_filtration_event_to_dict() -> None:
    ev = ca.FiltrationEvent(np.float64(0.25), "enter", np.int64(3))  # type: ignore[arg-type]
    d = ev.to_dict()
    # the multiplier is not recorded: both are null in JSON
    assert d == {
        "sigma": 0.25,
        "kind": "enter",
        "sensor": 3,
        "mu": None,
        "shadow_price": None,
        "budget": None,
    }
    assert_plain(d)
    d = ca.FiltrationEvent(0.25, "capped", 3, np.float64(-0.5), np.float64(4.25)).to_dict()
    assert d == {
        "sigma": 0.25,
        "kind": "capped",
        "sensor": 3,
        "mu": -0.5,
        "shadow_price": 0.5,
        "budget": 4.25,
    }
    assert_plain(d)


def test_stopped_filtration_to_dict_is_strict_json(net: ca.Network) -> None:
    f = ca.filtration(net, 6.0, max_nodes=3, progress=False)
    d = f.to_dict()
    assert_plain(d)
    strict_json(d)
    assert d["converged"] is False and d["stopped"] == "max_nodes"
    assert d["sigma_max"] == f.sigma_max < 6.0


def test_network_report_to_dict(net: ca.Network) -> None:
    rep = net.check()
    d = rep.to_dict()
    assert_plain(d)
    strict_json(d)
    assert d["n"] == net.n and d["num_sensors"] == net.num_sensors
    assert d["ok"] is rep.ok and d["regular"] is rep.regular
    assert len(d["subsystems"]) == len(rep.subsystems)
    for s, sd in zip(rep.subsystems, d["subsystems"], strict=True):
        assert sd["observability_margin"] == s.observability_margin
        mode = s.least_controllable_mode
        assert sd["least_controllable_mode"] == (None if mode is None else [mode.real, mode.imag])


def test_network_report_without_unstable_modes_has_none_for_inf() -> None:
    # A stable network: no mode with Re λ ≥ 0, so the detectability margin is inf → None.
    net = ca.Network(np.diag([-1.0, -2.0]), np.eye(2), [np.array([1.0, 1.0])])
    rep = net.check()
    assert rep.detectability_margin == math.inf
    d = rep.to_dict()
    assert d["detectability_margin"] is None
    strict_json(d)


def test_cost_point_and_evaluation_to_dict(net: ca.Network) -> None:
    r = np.array([2.0, 3.0, 4.0])
    p = net.at(r)
    d = p.to_dict()
    assert_plain(d)
    strict_json(d)
    assert d["value"] == net.cost(r)
    np.testing.assert_array_equal(np.array(d["gradient"]), net.gradient(r))
    ev = net.evaluate(r, 2)
    e = ev.to_dict()
    assert_plain(e)
    strict_json(e)
    np.testing.assert_array_equal(np.array(e["hessian"]), ev.hessian)
    assert e["value"] == ev.value and net.evaluate(r, 0).to_dict()["gradient"] is None


def one_line(x: Any) -> str:
    text = repr(x)
    assert "\n" not in text and len(text) < 200, text
    return text


def test_reprs_are_one_short_line(net: ca.Network) -> None:
    big = ca.Network.random(12, 2, 1, eps=0.05, seed=3)
    a = ca.optimal_allocation(big, 36.0)
    assert one_line(a).startswith("Allocation(N=12,")
    assert one_line(ca.integer_allocation(net, 9)).startswith("IntegerAllocation(counts=[")
    assert one_line(ca.integer_allocation(big, 24)).count(",") < 16  # 10 counts shown, then …
    f = ca.filtration(big, 10.0, progress=False)
    assert one_line(f).startswith("Filtration(σ ∈ [0, 10]")
    one_line(f.events[0])
    assert one_line(big.check()).startswith("NetworkReport(n=24, N=12,")
    one_line(big.at(np.full(12, 2.0)))
    one_line(big.evaluate(np.full(12, 2.0), 2))
    one_line(big)
