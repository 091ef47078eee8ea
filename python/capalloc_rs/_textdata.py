"""Reading a TOML or JSON file (model or sweep spec) into plain Python data, within the limits of
:mod:`capalloc_rs.limits`, with every failure — unreadable file, bad encoding, syntax, nesting,
number size — turned into one exception of the caller's class naming the file and the problem.

The nesting depth is measured on the text before it is parsed (the parsers recurse, so a deeply
nested file would otherwise end in :class:`RecursionError`); number literals are checked by the
parsers' hooks (JSON) or after parsing (TOML integers).
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from collections.abc import Callable
from typing import Any

from . import limits

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    try:
        import tomli as tomllib
    except ImportError:
        tomllib = None

__all__ = ["read_data", "parse_data", "nesting_depth"]

Fail = Callable[[str], Exception]


class _Problem(Exception):
    """A problem found while reading (turned into the caller's exception class at the end)."""


# Strings and comments are skipped whole; what is left of interest are the brackets.
_JSON_TOKENS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', re.S)
_TOML_TOKENS = re.compile(
    r'"""(?:[^\\]|\\.)*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*|[\[\]{}]',
    re.S,
)


def nesting_depth(text: str, fmt: str) -> int:
    """The deepest nesting of ``[``/``{`` outside strings and comments (an upper bound of the
    parsed data's depth; unbalanced text is left to the parser)."""
    depth = best = 0
    for m in (_JSON_TOKENS if fmt == "json" else _TOML_TOKENS).finditer(text):
        t = m.group()
        if t in ("[", "{"):
            depth += 1
            best = max(best, depth)
            if best > limits.MAX_NESTING:  # enough to refuse the file
                return best
        elif t in ("]", "}"):
            depth = max(depth - 1, 0)
    return best


def _number_literal(s: str) -> None:
    if len(s) > limits.MAX_NUMBER_CHARS:
        raise _Problem(
            f"a number literal of {len(s)} characters (longer than "
            f"capalloc_rs.limits.MAX_NUMBER_CHARS = {limits.MAX_NUMBER_CHARS}): {s[:20]}…"
        )


def _check_ints(x: Any) -> None:
    """Every integer within ±MAX_INTEGER (iterative: the depth is already bounded, but lists may
    be long)."""
    stack = [x]
    while stack:
        v = stack.pop()
        if isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list):
            stack.extend(v)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) > limits.MAX_INTEGER:
            raise _Problem(
                "an integer too large for a float64 computation (magnitude above "
                f"capalloc_rs.limits.MAX_INTEGER = {limits.MAX_INTEGER})"
            )


def parse_data(text: str, fmt: str, fail: Fail) -> Any:
    """Parses ``text`` as ``fmt`` (``"json"`` or ``"toml"``); every problem raises ``fail(msg)``."""
    try:
        return _parse(text, fmt)
    except _Problem as exc:
        raise fail(str(exc)) from None


def _parse(text: str, fmt: str) -> Any:
    brackets = text.count("[") + text.count("{")  # at C speed: bounds the scan below
    if brackets > limits.MAX_ARRAYS:
        raise _Problem(
            f"{brackets} arrays or tables (more than capalloc_rs.limits.MAX_ARRAYS = "
            f"{limits.MAX_ARRAYS})"
        )
    depth = nesting_depth(text, fmt)
    if depth > limits.MAX_NESTING:
        raise _Problem(
            f"nested more than capalloc_rs.limits.MAX_NESTING = {limits.MAX_NESTING} levels deep"
        )
    if fmt == "json":

        def pint(s: str) -> int:
            _number_literal(s)
            return int(s)

        def pfloat(s: str) -> float:
            _number_literal(s)
            return float(s)

        def pconst(s: str) -> float:
            raise _Problem(f"{s} is not a JSON number")

        try:
            data = json.loads(text, parse_int=pint, parse_float=pfloat, parse_constant=pconst)
        except (ValueError, RecursionError) as exc:
            raise _Problem(f"invalid JSON: {exc}") from None
    else:
        if tomllib is None:  # pragma: no cover
            raise _Problem("reading TOML needs Python ≥ 3.11 or the 'tomli' package")

        def tfloat(s: str) -> float:
            _number_literal(s)
            return float(s)

        try:
            data = tomllib.loads(text, parse_float=tfloat)
        except (ValueError, RecursionError) as exc:  # TOMLDecodeError is a ValueError
            raise _Problem(f"invalid TOML: {exc}") from None
    _check_ints(data)
    return data


def read_data(path: str | os.PathLike[str], fmt: str, fail: Fail) -> Any:
    """Reads and parses the file ``path`` (size-checked before reading, UTF-8)."""
    try:
        size = os.stat(path).st_size
    except OSError:
        size = 0  # let open() report it
    if size > limits.MAX_MODEL_FILE_BYTES:
        raise fail(
            f"the file has {size} bytes (more than capalloc_rs.limits.MAX_MODEL_FILE_BYTES = "
            f"{limits.MAX_MODEL_FILE_BYTES})"
        )
    with open(path, "rb") as fh:  # OSError propagates: the caller reports unreadable files
        raw = fh.read(limits.MAX_MODEL_FILE_BYTES + 1)
    if len(raw) > limits.MAX_MODEL_FILE_BYTES:
        raise fail(
            "the file is larger than capalloc_rs.limits.MAX_MODEL_FILE_BYTES = "
            f"{limits.MAX_MODEL_FILE_BYTES} bytes"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise fail(f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return parse_data(text, fmt, fail)


def finite_float(x: Any) -> float | None:
    """``float(x)`` for a real number that converts to a finite float, else ``None``."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    try:
        v = float(x)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None
