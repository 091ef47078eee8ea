"""The public model-file API, :mod:`capalloc_rs.model_io`: networks to and from TOML, JSON and
``.npz`` files and the schema's dicts.

The formats themselves (writing, and reading into constructor arguments) are in
:mod:`capalloc_rs.network.io` and :mod:`capalloc_rs.network.schema`, which know nothing of the
:class:`~capalloc_rs.Network` class; this module joins the two.
"""

from __future__ import annotations

import os
from typing import Any

from .io import dumps_json, dumps_toml, model_errors, save, to_dict
from .model import Network
from .schema import FORMAT, VERSION, parse

__all__ = ["FORMAT", "VERSION", "to_dict", "from_dict", "dumps_toml", "dumps_json", "save", "load"]


def from_dict(d: Any, source: str = "model") -> Network:
    """A network from the schema's dict.

    Args:
        d: the dict (as read from TOML or JSON).
        source: where ``d`` came from, for error messages.

    Returns:
        The network.

    Raises:
        ModelFormatError: malformed data (the message names ``source`` and the field).
        InputError: an invalid model (the network's own errors, prefixed with ``source``).
    """
    spec = parse(d, source)
    with model_errors(source):
        return Network._from_spec(spec)


def load(path: str | os.PathLike[str], format: str | None = None) -> Network:
    """Reads a network from TOML, JSON or ``.npz`` (by ``format`` or the extension): see
    :meth:`Network.load <capalloc_rs.Network.load>`."""
    return Network.load(path, format)
