"""The public model-file API, :mod:`capalloc_rs.model_io`: networks to and from TOML, JSON and
``.npz`` files and the schema's dicts.

TOML/JSON schema (version 1). Matrices are lists of rows; a sensor matrix with one column may be
written as a flat list. Indices count from 0. Unknown keys are errors (they are usually typos).

Top level:

* ``format = "capalloc-network"`` (optional; if present it must be this string);
* ``version = 1`` (optional);
* ``r_min`` — the minimum rate, ``> 0`` (optional, default 1.0);

then **either** the block form (the paper's model)

* ``eps`` — coupling strength ``ε`` (optional, default 0.0);
* ``[[subsystems]]`` — one table per subsystem with ``A`` (``n_i × n_i``), ``G`` (``n_i × m_i``,
  any ``m_i ≥ 1``; a flat list is one column) and ``c`` (``n_i × p_i``): sensor ``i`` measures
  ``c_iᵀ x_i``;
* ``[[couplings]]`` (optional) — tables with ``i``, ``j`` (``i ≠ j``) and ``A`` (``n_i × n_j``):
  the block ``A_ij`` of ``A`` is ``ε·A``;

**or** the general form

* ``A``, ``G`` (``n × m``) and ``[[sensors]]`` — tables with ``c`` (``n × p_i``).

Example (the paper's Example 1; ``examples/example1.toml``)::

    format = "capalloc-network"
    version = 1
    r_min = 1.0

    [[subsystems]]
    A = [[-1.0, 0.0], [0.0, -2.0]]
    G = [[2.23606797749979, 0.0], [-1.3416407864998738, 1.4832396974191326]]
    c = [1.0, 1.0]

JSON has the same structure (``{"subsystems": [{"A": …, "G": …, "c": …}], …}``).

``.npz`` files hold the arrays ``format``, ``version``, ``r_min`` and either ``A``, ``G``,
``sensor_0`` … (general form) or ``eps``, ``A_0``, ``G_0``, ``c_0`` …, and ``coupling`` (the
unscaled ``n × n`` coupling matrix, zero diagonal blocks) for block networks.

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
