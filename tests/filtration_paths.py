"""Shared check of the filtration tests: two path followers traced the same path."""

from __future__ import annotations

from typing import Any

import numpy as np


def assert_same_path(f: Any, g: Any, rtol: float = 1e-10) -> None:
    """``f`` and ``g`` (two :class:`~capalloc_rs.allocation.Filtration` results of one network)
    have the same events (kind and sensor, in order), active sets and entry order, and their
    breakpoints agree to ``rtol`` (relative, with the same absolute floor)."""
    assert [(e.kind, e.sensor) for e in f.events] == [(e.kind, e.sensor) for e in g.events]
    assert f.active_sets == g.active_sets and f.entry_order == g.entry_order
    np.testing.assert_allclose(f.breakpoints, g.breakpoints, rtol=rtol, atol=rtol)
