"""Model-file paths accepted wherever a :class:`~capalloc_rs.Network` is.

:func:`accepts_path` wraps a public function whose first argument is the network: a ``str`` or
:class:`os.PathLike` there is loaded with :meth:`Network.load` (TOML, JSON or ``.npz``; a bad file
raises :class:`~capalloc_rs.errors.ModelFormatError`, an unreadable one
:class:`~capalloc_rs.errors.InvalidInputError` naming ``net``) before the call.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

from ..errors import InvalidInputError
from .model import Network

__all__ = ["accepts_path", "as_network"]

_F = TypeVar("_F", bound=Callable[..., Any])


def as_network(net: Any) -> Any:
    """``net`` itself, or the network loaded from the model file ``net`` names."""
    if isinstance(net, str | os.PathLike):
        try:
            return Network.load(net)
        except OSError as exc:
            raise InvalidInputError(
                f"net = {os.fsdecode(net)!r} is not a Network and not a readable model file "
                f"({exc.strerror or exc})"
            ) from exc
    return net


def accepts_path(fn: _F) -> _F:
    """Decorator: the first argument (or ``net=``) may be a model-file path."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if args:
            args = (as_network(args[0]), *args[1:])
        elif "net" in kwargs:
            kwargs["net"] = as_network(kwargs["net"])
        return fn(*args, **kwargs)

    return cast(_F, wrapper)
