"""The records the extension returns (``rust/python/results.rs``): frozen, named fields only, and
values that agree with an independent computation of the same quantity."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import scipy.linalg as sla

from capalloc_rs import _core

FIELDS: dict[str, set[str]] = {
    "CareSolution": {
        "x",
        "residual",
        "rcond",
        "closed_loop_abscissa",
        "newton_steps",
        "scaling",
        "forward_error",
        "trace_error",
        "axis_margin",
        "marginal",
    },
    "SchurForm": {"t", "z", "sdim"},
    "VanLoan": {"e", "h"},
    "ValueGradient": {"value", "gradient"},
    "ValueGradientBatch": {"values", "gradients"},
    "CostEvaluation": {
        "value",
        "sigma",
        "care_residual",
        "closed_loop_abscissa",
        "gradient",
        "hessian",
    },
    "SlotDiscretisation": {"e", "h", "cbar", "es", "hs", "tau0"},
    "PeriodTriplet": {"a", "g", "h"},
    "SteadyState": {
        "boundary",
        "posteriors",
        "priors",
        "steps",
        "rel_change",
        "spectral_radius",
        "residual",
        "idle",
        "tail_e",
        "tail_h",
    },
    "Propagation": {"priors", "posteriors"},
    "FixedPoint": {"sigma", "periods", "rel_change"},
    "Neighbourhood": {"current", "reassign", "swap", "rotate", "complete", "evaluated"},
    "GreedyPass": {"slots", "sigma"},
    "AliasingPair": {"first", "second"},
}

A = np.array([[-1.0, 0.5, 0.0], [0.0, -2.0, 1.0], [0.2, 0.0, -0.5]])
Q = np.eye(3)
SENSORS = [np.array([[1.0], [0.0], [0.0]]), np.array([[0.0], [1.0], [1.0]])]
SLOTS = np.array([0, 1, 1], dtype=np.int64)
TAU = 0.6


def _records() -> dict[str, Any]:
    model = _core.CostModel(A, np.eye(3), SENSORS)
    sm = _core.SampledModel(A, Q, SENSORS)
    r = np.array([1.0, 2.0])
    osc = np.array([[-0.1, 2.0], [-2.0, -0.1]])
    return {
        "CareSolution": _core.care(A, np.eye(3), Q),
        "SchurForm": _core.schur(A, "lhp"),
        "VanLoan": _core.van_loan(A, Q, 0.3),
        "ValueGradient": model.value_gradient(r),
        "ValueGradientBatch": model.value_gradient_many(np.array([r, 2 * r])),
        "CostEvaluation": model.evaluate(r, 2),
        "SlotDiscretisation": sm.discretise(TAU, 3),
        "PeriodTriplet": sm.period_triplet(TAU, SLOTS),
        "SteadyState": sm.steady_state(TAU, SLOTS),
        "Propagation": sm.propagate(TAU, SLOTS, np.eye(3)),
        "FixedPoint": sm.fixed_point(TAU, SLOTS, np.eye(3), 1e-13, 10**6),
        "Neighbourhood": sm.neighbourhood(TAU, SLOTS),
        "GreedyPass": sm.greedy_pass(TAU, 3, np.eye(3), 1),
        "AliasingPair": _core.sampled_aliasing_pair(osc, np.pi / 2.0),
    }


@pytest.fixture(scope="module")
def records() -> dict[str, Any]:
    return _records()


def test_every_record_class_is_covered(records: dict[str, Any]) -> None:
    assert set(records) == set(FIELDS)
    for name, rec in records.items():
        assert type(rec) is getattr(_core, name)
        assert type(rec).__module__ == "capalloc_rs._core"


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_records_have_exactly_the_documented_fields(records: dict[str, Any], name: str) -> None:
    public = {a for a in dir(records[name]) if not a.startswith("_")}
    assert public == FIELDS[name]


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_records_are_immutable(records: dict[str, Any], name: str) -> None:
    rec = records[name]
    for field in FIELDS[name]:
        before = getattr(rec, field)
        with pytest.raises(AttributeError):
            setattr(rec, field, 0)
        with pytest.raises(AttributeError):
            delattr(rec, field)
        after = getattr(rec, field)
        if isinstance(before, np.ndarray):
            assert after is before  # an array field is the same object on every read
        else:
            assert after == before or (after != after and before != before)  # equal (or NaN)
    with pytest.raises(AttributeError):
        rec.new_field = 1
    with pytest.raises(TypeError):
        type(rec)()  # no constructor from Python


def test_record_values_agree_with_independent_routes(records: dict[str, Any]) -> None:
    care = records["CareSolution"]
    ref = sla.solve_continuous_are(A, np.eye(3), Q, np.eye(3))
    np.testing.assert_allclose(care.x, ref, rtol=1e-12, atol=1e-14)
    assert care.marginal is False and care.closed_loop_abscissa < 0
    assert isinstance(care.newton_steps, int)

    form = records["SchurForm"]
    np.testing.assert_allclose(form.z @ form.t @ form.z.T, A, atol=1e-14)
    assert form.sdim == 3  # every eigenvalue of A is in the left half plane

    vl = records["VanLoan"]
    np.testing.assert_allclose(vl.e, sla.expm(0.3 * A), rtol=1e-13)

    vg, ev, batch = (
        records["ValueGradient"],
        records["CostEvaluation"],
        records["ValueGradientBatch"],
    )
    assert vg.value == ev.value == batch.values[0]
    np.testing.assert_array_equal(vg.gradient, ev.gradient)
    np.testing.assert_array_equal(batch.gradients[0], vg.gradient)
    assert ev.value == pytest.approx(np.trace(ev.sigma), rel=1e-14)
    assert ev.hessian is not None and ev.hessian.shape == (2, 2)

    d = records["SlotDiscretisation"]
    np.testing.assert_allclose(d.e, sla.expm(TAU / 3 * A), rtol=1e-13)
    assert isinstance(d.cbar, list) and len(d.cbar) == 2

    ss, fp = records["SteadyState"], records["FixedPoint"]
    np.testing.assert_allclose(ss.boundary, fp.sigma, rtol=1e-10)
    assert ss.posteriors.shape == ss.priors.shape == (3, 3, 3)
    assert 0 <= ss.spectral_radius < 1 and ss.steps >= 1

    prop = records["Propagation"]
    assert prop.priors.shape == prop.posteriors.shape == (3, 3, 3)

    nb = records["Neighbourhood"]
    assert nb.current == pytest.approx(np.trace(ss.boundary), rel=1e-12)
    assert nb.complete is True and nb.reassign.shape == (3, 2)

    gp = records["GreedyPass"]
    assert gp.slots.dtype == np.int64 and gp.slots.shape == (3,)

    pair = records["AliasingPair"]
    osc = np.array([[-0.1, 2.0], [-2.0, -0.1]])
    assert isinstance(pair.first, complex) and isinstance(pair.second, complex)
    got = sorted([pair.first, pair.second], key=lambda z: z.imag)
    np.testing.assert_allclose(got, np.sort_complex(np.linalg.eigvals(osc)), rtol=1e-14)
    assert _core.sampled_aliasing_pair(A, TAU) is None
