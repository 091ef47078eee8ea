"""Messages name the user's objects, not internal matrices (capalloc-rs issue 12, point 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import errors, linalg
from capalloc_rs.allocation import filtration

A = np.array([[-1.0, 0.3], [0.2, -2.0]])
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_care_with_huge_q_is_solved() -> None:
    # Q = 1e300·I used to fail with "A has a non-finite entry (-inf)": ‖Q‖_F overflowed in a
    # naive sum of squares. X ≈ sqrt(Q) here; check the Riccati residual independently.
    q = 1e300 * np.eye(2)
    x = linalg.care(A, np.eye(2), q).x
    res = A.T @ x + x @ A - x @ x + q
    assert np.linalg.norm(res / 1e300) <= 1e-13
    assert np.all(np.linalg.eigvals(A - x).real < 0)


def test_care_hamiltonian_overflow_names_q_and_g() -> None:
    with pytest.raises(errors.InvalidInputError) as info:
        linalg.care(A, np.eye(2), 1e308 * np.ones((2, 2)))
    msg = str(info.value)
    assert "Hamiltonian overflowed" in msg and "scale Q" in msg and "‖Q‖_F = inf" in msg
    assert "non-finite entry" not in msg and "A has" not in msg


def test_care_balances_tiny_q_against_huge_g() -> None:
    # sqrt(‖Q‖/‖G‖) = sqrt(1e-300/1e300) used to underflow to 0 and give 1/s = ∞ entries.
    x = linalg.care(A, 1e150 * np.eye(2), 1e-300 * np.eye(2)).x
    assert np.all(np.isfinite(x))


def test_huge_rates_are_named() -> None:
    net = capalloc_rs.Network(A, np.eye(2), [np.array([1.0, 0.0]), np.array([0.0, 1.0])])
    for r in ([1e200, 1.0], [1e150, 1.0]):
        with pytest.raises(errors.InvalidInputError) as info:
            net.cost(np.array(r))
        msg = str(info.value)
        assert "rates are too large" in msg and f"r[0] = {r[0]:.3e}".replace("+", "") in msg
        assert "smaller capacity r_tot" in msg
    # W = 1e308·I overflows W·Q in the Hamiltonian, but the equation rescaled by a power of four
    # is solved: Σ ≈ W^{-1/2} (A is negligible against the rates).
    assert net.cost(np.array([1e308, 1e308])) == pytest.approx(2e-154, rel=1e-12)
    # `capalloc solve examples/three_subsystems.toml --r-tot 1e308` (through optimal_allocation)
    # used to say "A has a non-finite entry (-inf)".
    three = capalloc_rs.model_io.load(EXAMPLES / "three_subsystems.toml")
    with pytest.raises(errors.InvalidInputError, match=r"rates are too large.*r\[0\] = 3.333e307"):
        capalloc_rs.optimal_allocation(three, 1e308)
    # … while an easy network is solved right up there: W = 5e307·I, Σ ≈ W^{-1/2}.
    big = capalloc_rs.optimal_allocation(net, 1e308)
    assert big.eta == pytest.approx(2 / np.sqrt(5e307), rel=1e-6)
    # Moderate rates are unaffected.
    assert net.cost(np.array([1e6, 1.0])) > 0


def test_filtration_stall_says_where_why_and_what_to_do() -> None:
    # `capalloc trace examples/three_subsystems.toml --sigma-max 1e9` used to say only
    # "path following stalled at σ = 698298".
    net = capalloc_rs.model_io.load(EXAMPLES / "three_subsystems.toml")
    with pytest.raises(errors.ConvergenceError) as info:
        filtration(net, 1e9, progress=False, method="reference")
    msg = str(info.value)
    assert "stalled at σ = " in msg and "σ_max = 1e+09" in msg
    assert "no longer resolved" in msg and "rates up to" in msg
    assert "smaller sigma_max" in msg
