"""The entry point of the ``capalloc`` console script: parse, run the command, end cleanly.

:func:`main` never raises (except with ``CAPALLOC_TRACEBACK=1``): see :mod:`capalloc_rs.cli.errors`
for how each kind of ending is reported.
"""

from __future__ import annotations

import json
import os
import sys
import warnings
from collections.abc import Sequence

from ..errors import CapallocError, UncheckedExistenceWarning
from .errors import (
    EXIT_ERROR,
    EXIT_INTERRUPTED,
    one_line,
    report,
    report_warnings,
    say,
    silence_stdout,
)
from .parser import Parser, build_parser

__all__ = ["main"]


def _usage_failure(exc: SystemExit, as_json: bool) -> int:
    """The status of ``--help``, ``--version`` or an argument error (already reported on stderr;
    under ``--json`` also as a JSON error on stdout)."""
    code = int(exc.code) if isinstance(exc.code, int) else EXIT_ERROR
    if code and as_json:
        msg = Parser.last_error or "invalid arguments"
        say(json.dumps({"error": {"type": "UsageError", "message": msg}}), stdout=True)
    sys.stdout.flush()
    return code


def _run(argv: list[str], as_json: bool) -> int:
    """Parses ``argv`` and runs its command, its warnings reported once each."""
    parser = build_parser()
    if not argv:  # like git: the help, and success
        parser.print_help()
        return 0
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, argument errors (already reported)
        return _usage_failure(exc, as_json)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UncheckedExistenceWarning)
        code = int(args.func(args))
    report_warnings(caught)
    sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
    return code


def _failure_message(exc: Exception) -> str:
    """The one line of a failure: the message of a user mistake, else an internal error."""
    if isinstance(exc, CapallocError | ValueError | OSError):
        # ValueError: what a library reports as a bad value; OSError: unreadable/unwritable
        # files. The API's advice in the CLI's words (the aliasing check: check=False →
        # --no-check).
        return one_line(exc).replace("pass check=False", "pass --no-check")
    if isinstance(exc, MemoryError):
        return "out of memory (try a smaller problem)"
    return (  # a bug: still one line, with the way to see the traceback
        f"internal error ({type(exc).__name__}: {one_line(exc)}); please report it, with "
        "the traceback shown by CAPALLOC_TRACEBACK=1"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``capalloc`` console script; returns the exit status.

    Never raises (except with ``CAPALLOC_TRACEBACK=1``): user mistakes and failures end with one
    line ``capalloc: error: …`` on stderr and status 2 (under ``--json`` also
    ``{"error": {"type": …, "message": …}}`` on stdout), Ctrl-C with one line and status 130, and
    a closed stdout pipe (``capalloc demo | head``) quietly with status 0.

    Args:
        argv: the arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status: 0, 2 (an error) or 130 (interrupted).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    Parser.last_error = None
    as_json = "--json" in args
    try:
        return _run(args, as_json)
    except KeyboardInterrupt:
        say("capalloc: interrupted")
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        silence_stdout()
        return 0
    except Exception as exc:  # every failure ends as one line (a bug says how to see more)
        if os.environ.get("CAPALLOC_TRACEBACK"):
            raise
        report(_failure_message(exc), type(exc).__name__, as_json)
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
