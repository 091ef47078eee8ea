"""How the ``capalloc`` command ends: exit statuses, the one-line error, the warnings.

User mistakes and failures end with one line ``capalloc: error: …`` on stderr and status
:data:`EXIT_ERROR` (under ``--json`` also ``{"error": {"type": …, "message": …}}`` on stdout);
Ctrl-C with one line and status :data:`EXIT_INTERRUPTED`; each distinct warning is printed once as
``capalloc: warning: …``.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import warnings
from collections.abc import Sequence

from .._unchecked import UNCHECKED_MESSAGE
from ..errors import UncheckedExistenceWarning

__all__ = [
    "EXIT_ERROR",
    "EXIT_INTERRUPTED",
    "one_line",
    "report",
    "report_warnings",
    "say",
    "silence_stdout",
]

#: Exit status for user mistakes and numerical failures.
EXIT_ERROR = 2
#: Exit status after Ctrl-C (128 + SIGINT, as shells report it).
EXIT_INTERRUPTED = 130


def say(line: str, *, stdout: bool = False) -> None:
    """Prints one line on stderr (or stdout), flushed; a closed or broken stream is ignored."""
    with contextlib.suppress(OSError, ValueError):
        print(line, file=sys.stdout if stdout else sys.stderr, flush=True)


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (OSError: ``file: reason``)."""
    if isinstance(exc, OSError) and exc.filename:
        msg = f"{exc.filename}: {exc.strerror or exc}"
    else:
        msg = str(exc) or type(exc).__name__
    return " ".join(msg.split())


def report(message: str, kind: str, as_json: bool) -> None:
    """``capalloc: error: …`` on stderr; under ``--json`` also the error as JSON on stdout."""
    if as_json:
        say(json.dumps({"error": {"type": kind, "message": message}}), stdout=True)
    say(f"capalloc: error: {message}")


def silence_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the flush at interpreter exit does
    not fail again (the recipe of Python's documentation on SIGPIPE)."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def report_warnings(caught: Sequence[warnings.WarningMessage]) -> None:
    """Each distinct warning once, on one line ``capalloc: warning: …`` on stderr (``--no-check``
    says the API's check=False warning in the CLI's words)."""
    seen: set[str] = set()
    for w in caught:
        msg = str(w.message)
        if isinstance(w.message, UncheckedExistenceWarning) and msg == UNCHECKED_MESSAGE:
            msg = msg.replace("check=False", "--no-check", 1)
        if msg not in seen:
            seen.add(msg)
            say(f"capalloc: warning: {' '.join(msg.split())}")
