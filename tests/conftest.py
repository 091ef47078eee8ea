"""Shared fixtures: deterministic random problems."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_care(
    rng: np.random.Generator, n: int, m: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A stabilisable/detectable CARE instance (a, b, q, r) with a well-conditioned solution."""
    m = m or max(1, n // 2)
    a = rng.standard_normal((n, n)) / np.sqrt(n)
    b = rng.standard_normal((n, m))
    c = rng.standard_normal((n, n))
    q = c @ c.T / n + np.eye(n)
    r = np.eye(m) + 0.1 * np.diag(rng.random(m))
    return a, b, q, r
