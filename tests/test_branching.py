"""Pseudo-cost branching of the integer branch-and-bound: the coordinate chosen is fractional and
not fixed, the observed rises steer the choice, and with every coordinate integral or fixed it
falls back to a free one or to none."""

from __future__ import annotations

import numpy as np

from capalloc_rs.allocation.branching import PseudoCosts


def test_without_observations_the_most_balanced_fraction_wins() -> None:
    pc = PseudoCosts(3)
    lo, hi = np.array([1, 1, 1]), np.array([5, 5, 5])
    # Equal pseudo-costs: the product f²(1 − f)² is largest at f = ½.
    assert pc.choose(np.array([2.1, 3.5, 1.8]), lo, hi) == 1


def test_observed_rises_steer_the_choice() -> None:
    pc = PseudoCosts(3)
    lo, hi = np.array([1, 1, 1]), np.array([5, 5, 5])
    for up in (False, True):
        pc.record(0, up, 0.3, 10.0)  # splitting 0 raised the bound a lot
        pc.record(1, up, 0.5, 1e-6)  # splitting 1 hardly at all
    assert pc.choose(np.array([2.3, 3.5, 1.5]), lo, hi) == 0


def test_fixed_and_integral_coordinates() -> None:
    pc = PseudoCosts(3)
    r = np.array([2.0, 3.5, 1.0])
    # The fractional coordinate is fixed: none fractional and free, the first free one.
    assert pc.choose(r, np.array([1, 3, 1]), np.array([5, 3, 5])) == 0
    assert pc.choose(r, np.array([2, 3, 1]), np.array([2, 3, 1])) is None
    # A negative rise (a bound below its parent's) and a zero distance are not recorded.
    pc.record(1, True, 0.0, 1.0)
    pc.record(1, False, 0.5, -1.0)
    assert pc.count[1, 1] == 0 and pc.sum[0, 1] == 0.0 and pc.count[0, 1] == 1
