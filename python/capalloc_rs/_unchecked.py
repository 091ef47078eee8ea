"""The one warning of ``check=False`` (the CLI's ``--no-check``), shared by the API and the CLI,
and warnings attributed to the user's code."""

from __future__ import annotations

import os
import sys
import warnings

from .errors import UncheckedExistenceWarning

__all__ = ["UNCHECKED_MESSAGE", "warn_outside", "warn_unchecked"]

UNCHECKED_MESSAGE = (
    "check=False: Proposition 1's hypotheses (the used sensors observe A, τ does not alias two "
    "eigenvalues) are not checked, so the periodic steady state is not guaranteed to exist"
)


_PACKAGE = os.path.dirname(os.path.abspath(__file__))


def _in_package(filename: str) -> bool:
    """Whether ``filename`` is a module of the package or of one of its subpackages."""
    return os.path.abspath(filename).startswith(_PACKAGE + os.sep)


def warn_outside(message: str, category: type[Warning]) -> None:
    """``warnings.warn`` attributed to the first caller outside the package."""
    level, frame = 1, sys._getframe(0)
    while frame is not None and _in_package(frame.f_code.co_filename):
        level, frame = level + 1, frame.f_back  # type: ignore[assignment]
    warnings.warn(message, category, stacklevel=level)


def warn_unchecked() -> None:
    """Emits :class:`~capalloc_rs.errors.UncheckedExistenceWarning` (from a public function
    called with ``check=False``), attributed to the first caller outside the package."""
    warn_outside(UNCHECKED_MESSAGE, UncheckedExistenceWarning)
