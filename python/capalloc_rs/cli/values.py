"""Argument values the commands check beyond their argparse type: slot counts and schedules."""

from __future__ import annotations

import math

from ..errors import InvalidInputError

__all__ = ["int_arg", "parse_slots"]


def int_arg(name: str, v: float) -> int:
    """``v`` as a slot count (``8.0`` is 8).

    Raises:
        InvalidInputError: ``v`` is not an integer.
    """
    if v != math.floor(v):
        raise InvalidInputError(f"{name} must be an integer number of slots, got {v:g}")
    return int(v)


def parse_slots(s: str) -> list[int]:
    """The sensor indices of ``--schedule 0,1,0,2``.

    Raises:
        InvalidInputError: not comma-separated integers, or empty.
    """
    try:
        slots = [int(x) for x in s.replace(" ", "").split(",") if x != ""]
    except ValueError:
        raise InvalidInputError(
            f"--schedule must be comma-separated sensor indices like 0,1,0,2; got {s!r}"
        ) from None
    if not slots:
        raise InvalidInputError("--schedule is empty")
    return slots
