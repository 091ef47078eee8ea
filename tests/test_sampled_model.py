"""``_core.SampledModel``: the sampled system validated once in Rust and used by every sampled
function and by the schedule search (``capalloc_rs.sampled.SampledSystem.core``)."""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import _core, errors, sampled

A = np.array([[-1.0, 0.5, 0.0], [0.0, -2.0, 1.0], [0.2, 0.0, -0.5]])
Q = np.eye(3)
SENSORS = [np.array([[1.0], [0.0], [0.0]]), np.array([[0.0], [1.0], [1.0]])]
SLOTS = np.array([0, 1, 1], dtype=np.int64)


def test_model_is_validated_on_construction() -> None:
    with pytest.raises(errors.ShapeError):
        _core.SampledModel(A, np.eye(2), SENSORS)
    with pytest.raises(errors.NonFiniteError):
        _core.SampledModel(A * np.nan, Q, SENSORS)
    sm = _core.SampledModel(A, Q, SENSORS)
    assert (sm.n, sm.num_sensors) == (3, 2)
    with pytest.raises(errors.InvalidInputError, match="names sensor 2"):
        sm.cost(0.5, np.array([0, 2], dtype=np.int64))
    with pytest.raises(AttributeError):
        sm.n = 4  # type: ignore[misc]


def test_kept_discretisation_never_changes_a_result() -> None:
    # The model keeps the last (tau, r_tot)'s discretisation: alternating periods and lengths
    # must give bitwise the numbers of a fresh model each time.
    kept = _core.SampledModel(A, Q, SENSORS)
    cases = [(0.5, SLOTS), (0.7, SLOTS), (0.5, SLOTS), (0.5, SLOTS[:2]), (0.5, SLOTS)]
    for tau, slots in cases:
        fresh = _core.SampledModel(A, Q, SENSORS)
        assert kept.cost(tau, slots) == fresh.cost(tau, slots)
        assert kept.cost(tau, slots, "average") == fresh.cost(tau, slots, "average")
        np.testing.assert_array_equal(
            kept.discretise(tau, len(slots)).h, fresh.discretise(tau, len(slots)).h
        )


def test_search_builds_the_rust_model_once(monkeypatch: pytest.MonkeyPatch) -> None:
    built: list[Any] = []
    real = _core.SampledModel

    def counting(*args: Any) -> Any:
        built.append(args)
        return real(*args)

    monkeypatch.setattr(_core, "SampledModel", counting)
    net = capalloc_rs.Network.random(4, seed=11)
    # The certificate (certify=True) builds its own relaxed models, one per key sensor.
    res = capalloc_rs.best_schedule(net, 0.8, 12, progress=False, certify="relaxed")
    assert res.evaluations > 20  # many candidates were costed …
    assert len(built) == 1  # … on one model


def test_model_pickles_without_its_rust_model() -> None:
    m = sampled.sampled_system(capalloc_rs.Network.random(3, seed=2))
    before = sampled.sampled_cost(m, 0.5, [0, 1, 2])
    assert "_core_model" in m.__dict__
    back = pickle.loads(pickle.dumps(m))
    assert "_core_model" not in back.__dict__
    assert sampled.sampled_cost(back, 0.5, [0, 1, 2]) == before
