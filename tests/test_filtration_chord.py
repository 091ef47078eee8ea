"""Chord corrections in the warm-started evaluation points (``CostPoint.warm(r, chord_steps=k)``,
used by the filtration from its fifth version on, from state order 65): the same points as
the plain warm start and the cold solve to rounding, fewer Schur forms, and the same filtration
as ``"continuation-v4"``. Costs are checked by counting Schur forms (never by wall time)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from filtration_paths import assert_same_path

from capalloc_rs import Network, errors
from capalloc_rs.allocation import filtration
from capalloc_rs.allocation.kkt_newton import PATH_CHORD_MIN_ORDER
from capalloc_rs.allocation.oracle import CountingOracle


def _rel(a: Any, b: Any) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("move", [1e-6, 1e-4, 1e-2, 0.2])
def test_chord_point_equals_the_plain_warm_and_the_cold_point(move: float) -> None:
    net = Network.random(20, 2, eps=0.05, seed=3)
    r0 = 1.0 + np.linspace(0.0, 2.0, 20)
    r1 = r0 * (1.0 + move * np.sin(np.arange(20.0)))
    p0 = net.at(r0)
    cold, plain, chord = net.at(r1), p0.warm(r1), p0.warm(r1, chord_steps=8)
    assert chord.warm_started and chord.warm_fallback is None
    # Σ to within both error bounds (the cold one's is an independent solve), η and ∇η to
    # rounding, a Hessian-vector product to 1e-10.
    d = _rel(chord.sigma, cold.sigma)
    assert d <= chord.forward_error + cold.forward_error
    assert abs(chord.value - cold.value) <= chord.value_error + cold.value_error
    assert _rel(chord.gradient, cold.gradient) <= 1e-11
    assert _rel(chord.gradient, plain.gradient) <= 1e-11
    v = np.cos(np.arange(20.0))
    assert _rel(chord.hvp(v), cold.hvp(v)) <= 1e-10
    assert cold.warm_factorizations == 0 and plain.warm_chord_steps == 0
    assert chord.warm_factorizations <= plain.warm_factorizations
    if move <= 1e-2:
        assert chord.warm_factorizations == 1 and chord.warm_chord_steps >= 1


@pytest.mark.parametrize("bad", [-1, 1.5, True, 65, "2"])
def test_chord_steps_is_validated(bad: Any) -> None:
    net = Network.random(3, 2, eps=0.05, seed=3)
    p = net.at(np.ones(3))
    with pytest.raises(errors.InvalidInputError, match="chord_steps"):
        p.warm(np.full(3, 1.1), chord_steps=bad)


class _Schur(CountingOracle):
    """Counts the Schur forms of the warm starts too."""

    def at(self, r: Any) -> Any:
        return _SchurPoint(super().at(r), self.counts)


class _SchurPoint:
    def __init__(self, point: Any, counts: dict[str, int]) -> None:
        self._point, self._counts = point, counts
        counts["schur"] = counts.get("schur", 0) + int(point.warm_factorizations)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._point, name)

    def warm(self, r: Any, **kw: Any) -> Any:
        return _SchurPoint(self._point.warm(r, **kw), self._counts)


@pytest.mark.parametrize(("n_sub", "sigma_max"), [(5, 15.0), (20, 60.0), (35, 60.0)])
def test_chord_path_is_the_path_of_the_fourth_version(n_sub: int, sigma_max: float) -> None:
    # The fifth version (chord corrections before each warm start's Newton–Kleinman corrections,
    # from state order PATH_CHORD_MIN_ORDER) against "continuation-v4": the same events, active sets
    # and entry order, the breakpoints within 1e-10 relative, the same evaluation points, and
    # from that order on (N = 35, n = 70) fewer Schur forms; below it the same ones.
    net = Network.random(n_sub, 2, eps=0.05, seed=3)
    new, old = _Schur(net), _Schur(net)
    f = filtration(new, sigma_max, progress=False, method="continuation-v5")
    g = filtration(old, sigma_max, progress=False, method="continuation-v4")
    assert_same_path(f, g)
    assert new.counts["points"] == old.counts["points"]
    if net.n >= PATH_CHORD_MIN_ORDER:
        assert new.counts["schur"] < old.counts["schur"]
    else:
        assert new.counts == old.counts
    # The nodes meet the KKT conditions with the network's own (cold) gradient.
    for k in range(0, f.node_sigma.size, 3):
        gamma, mu = f.node_gamma[k], float(f.node_mu[k])
        active = list(f.active_sets[int(f.node_segment[k])])
        grad = np.asarray(net.gradient(gamma + net.r_min))
        assert np.max(np.abs(grad[active] - mu)) <= 1e-11 * abs(mu)
