"""Progress reporting for the long searches (:func:`capalloc_rs.best_schedule`,
:func:`capalloc_rs.filtration`).

``progress`` arguments accept:

* ``None`` (default): a tqdm bar on stderr when stderr is a terminal and tqdm is installed,
  nothing otherwise;
* ``True`` / ``False``: a tqdm bar if tqdm is installed / nothing;
* a callable: called with a dict of the current figures after every step (e.g. ``moves``,
  ``eta_bar``, ``elapsed`` for the schedule search) — for logging or a custom display.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

from .errors import InvalidInputError

__all__ = ["ProgressArg", "Progress"]

ProgressArg = bool | Callable[[dict[str, Any]], object] | None


def _tqdm() -> Any:
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm


class Progress:
    """One progress display: :meth:`update` after each step, :meth:`close` at the end (also used
    as a context manager)."""

    def __init__(self, spec: ProgressArg, desc: str, total: float | None = None) -> None:
        self._callback: Callable[[dict[str, Any]], object] | None = None
        self._bar: Any = None
        self._start = time.monotonic()
        if callable(spec) and not isinstance(spec, bool):
            self._callback = spec
            return
        if spec is not None and not isinstance(spec, bool):
            raise InvalidInputError(
                f"progress must be None, True, False or a callable, got {spec!r}"
            )
        want = spec if spec is not None else _stderr_is_terminal()
        tqdm = _tqdm() if want else None
        if tqdm is not None:
            self._bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False)

    def update(self, position: float | None = None, **figures: Any) -> None:
        """Reports the current figures; ``position`` sets the bar's position (its ``n``)."""
        if self._callback is not None:
            self._callback({**figures, "elapsed": time.monotonic() - self._start})
        if self._bar is not None:
            if position is not None:
                self._bar.n = position
            self._bar.set_postfix(figures, refresh=False)
            self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _stderr_is_terminal() -> bool:
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):
        return False
