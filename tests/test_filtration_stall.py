"""The filtration's step control when the corrector fails (the contract stated in
``filtration``'s docstring): a failed step is retried from the same node with ¼ of its length;
the path is declared stalled (``PathStallError``, a ``ConvergenceError``) when the next retry
would be shorter than ``1e-14·σ_max``, or after 30 failures in a row whatever the step — so the
loop ends even if the step does not shrink."""

from __future__ import annotations

import math
import pickle
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import errors
from capalloc_rs.allocation import filtration

FMOD = sys.modules["capalloc_rs.allocation.filtration"]  # the module, not the function
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def three_subsystems() -> Any:
    return capalloc_rs.model_io.load(EXAMPLES / "three_subsystems.toml")


def test_retry_step_rule() -> None:
    retry = FMOD._retry_step
    assert retry(1.0, 1, 0.1) == 0.25
    assert retry(0.4, 1, 0.1) == 0.1  # exactly the floor is still tried
    assert retry(0.399, 1, 0.1) is None  # below the floor: stalled
    assert retry(math.nan, 1, 0.1) is None
    assert retry(1.0, 29, 1e-9) == 0.25
    assert retry(1.0, 30, 1e-9) is None  # the failure count alone ends it
    assert retry(1.0, 31, 1e-9) is None


def _spy(monkeypatch: pytest.MonkeyPatch) -> list[tuple[float, bool]]:
    """Records every corrector call as ``(σ, succeeded)``."""
    calls: list[tuple[float, bool]] = []
    correct = FMOD._Tracer.correct

    def spy(self: Any, active: Any, sigma: float, gamma0: Any, mu0: float, *caps: Any) -> Any:
        try:
            p = correct(self, active, sigma, gamma0, mu0, *caps)
        except errors.ConvergenceError:
            calls.append((sigma, False))
            raise
        calls.append((sigma, True))
        return p

    monkeypatch.setattr(FMOD._Tracer, "correct", spy)
    return calls


def test_stall_reports_where_and_the_step_contract(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _spy(monkeypatch)
    with pytest.raises(errors.PathStallError) as info:
        filtration(three_subsystems(), 1e9, progress=False, method="reference")
    err = info.value
    assert isinstance(err, errors.ConvergenceError)
    assert err.min_step == 1e-14 * 1e9
    assert err.min_step <= err.step < 4 * err.min_step
    assert f"stalled at σ = {err.sigma:.6g}" in str(err)
    assert f"step of {err.step:.1e}" in str(err) and f"{err.failures} failure(s)" in str(err)
    # From the corrector calls themselves: the path ends with `failures` failed calls in a row,
    # started from the node at err.sigma (the last success), the last one over err.step.
    run = 0
    while not calls[-1 - run][1]:
        run += 1
    assert run == err.failures >= 1
    assert calls[-1 - run][0] == err.sigma
    assert calls[-1][0] - err.sigma == pytest.approx(err.step, rel=1e-6)
    # Every failure is retried from the same node with ¼ of the step.
    fails = [k for k, (_, ok) in enumerate(calls[:-1]) if not ok and k > 0]
    assert len(fails) >= 5
    for k in fails:
        base = calls[k - 1][0]  # the node the failed step started from
        ulp = 4 * float(np.spacing(calls[k][0]))
        assert calls[k + 1][0] - base == pytest.approx(0.25 * (calls[k][0] - base), abs=ulp)


def test_stall_is_bounded_when_the_step_never_shrinks(monkeypatch: pytest.MonkeyPatch) -> None:
    # Whatever the floats do to the step (here: the shrink factor disabled), the failure count
    # ends the loop: 30 failures in a row at the same node, then the stall error.
    monkeypatch.setattr(FMOD, "_SHRINK", 1.0)
    calls = _spy(monkeypatch)
    with pytest.raises(errors.PathStallError) as info:
        filtration(three_subsystems(), 1e9, progress=False, method="reference")
    assert info.value.failures == 30
    assert [ok for _, ok in calls[-30:]] == [False] * 30 and calls[-31][1]
    assert info.value.step >= info.value.min_step


def test_stall_error_pickles_with_its_fields() -> None:
    err = errors.PathStallError("stalled", sigma=2.0, step=3e-5, min_step=1e-5, failures=4)
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is errors.PathStallError and str(back) == "stalled"
    assert (back.sigma, back.step, back.min_step, back.failures) == (2.0, 3e-5, 1e-5, 4)


def test_stall_at_the_start_counts_every_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    # A corrector that fails for every σ > 0: the path stalls at its first node, σ = 0, after
    # retries of ¼ each from the first step down to the floor — counted from the first failure.
    correct = FMOD._Tracer.correct
    tried: list[float] = []

    def failing(self: Any, active: Any, sigma: float, gamma0: Any, mu0: float, *caps: Any) -> Any:
        if sigma > 0.0:
            tried.append(sigma)
            raise errors.ConvergenceError("forced")
        return correct(self, active, sigma, gamma0, mu0, *caps)

    monkeypatch.setattr(FMOD._Tracer, "correct", failing)
    with pytest.raises(errors.PathStallError) as info:
        filtration(three_subsystems(), 8.0, progress=False, method="reference")
    err = info.value
    assert err.sigma == 0.0 and err.failures == len(tried) >= 2
    assert err.step == tried[-1] and err.min_step == 1e-14 * 8.0
    assert err.min_step <= err.step < 4 * err.min_step
    np.testing.assert_allclose(np.array(tried[1:]) / np.array(tried[:-1]), 0.25, rtol=1e-12)
