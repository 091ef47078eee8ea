"""The public model-file API, :mod:`capalloc_rs.model_io`: networks to and from TOML, JSON and
``.npz`` files and the schema's dicts.

TOML/JSON schema (version 1). Matrices are lists of rows; a sensor matrix with one column may be
written as a flat list. Indices count from 0. Unknown keys are errors (they are usually typos).

Top level:

* ``format = "capalloc-network"`` (optional; if present it must be this string);
* ``version = 1`` (optional);
* ``r_min`` — the minimum rate, ``≥ 0`` (optional, default 1.0; 0 lets a sensor be switched off,
  see :mod:`capalloc_rs.network.sensor_limits`);
* ``weight`` — the matrix ``M`` (``n × n``, symmetric ⪰ 0) of the weighted error ``tr(M Σ)``
  (optional, default the plain trace);
* in each sensor's table (a subsystem's, or a ``[[sensors]]`` table of the general form),
  optionally: ``cost`` — the sample cost ``b_i > 0`` in channel units (default 1), ``r_min`` —
  this sensor's minimum rate (default the top-level ``r_min``), ``r_max`` — its rate cap
  (``> r_min``; default none; TOML's ``inf`` is none too);

then **either** the block form (the paper's model)

* ``eps`` — coupling strength ``ε`` (optional, default 0.0);
* ``[[subsystems]]`` — one table per subsystem with ``A`` (``n_i × n_i``), the process noise
  and the sensor. The noise is ``G`` (``n_i × m_i``, any ``m_i ≥ 1``; a flat list is one column)
  **or** the standard model's ``B_w`` (``n_i × m_i``) with ``W`` (``m_i × m_i`` ⪰ 0, default
  ``I``), read as ``G = B_w W^{1/2}``. The sensor is ``c`` (``n_i × p_i``: sensor ``i`` measures
  ``c_iᵀ x_i`` with unit noise) **or** the standard model's ``C`` (``p_i × n_i``, outputs
  ``y_i = C x_i``; a flat list is one output) with ``R`` (``p_i × p_i`` ≻ 0, the covariance of a
  sample's noise, default ``I``), read as ``c = Cᵀ R^{-1/2}`` (see
  :mod:`capalloc_rs.network.stochastic`);
* ``[[couplings]]`` (optional) — tables with ``i``, ``j`` (``i ≠ j``) and ``A`` (``n_i × n_j``):
  the block ``A_ij`` of ``A`` is ``ε·A``;

**or** the general form

* ``A``, the noise ``G`` (``n × m``) or ``B_w`` and ``W``, and ``[[sensors]]`` — tables with
  ``c`` (``n × p_i``) or ``C`` (``p_i × n``) and ``R``, as in the block form.

Files are written with ``G`` and ``c`` (a model read from ``B_w``, ``W``, ``C``, ``R`` is saved in
its whitened form, which defines the same network).

Example (the paper's Example 1; ``examples/example1.toml``)::

    format = "capalloc-network"
    version = 1
    r_min = 1.0

    [[subsystems]]
    A = [[-1.0, 0.0], [0.0, -2.0]]
    G = [[2.23606797749979, 0.0], [-1.3416407864998738, 1.4832396974191326]]
    c = [1.0, 1.0]

JSON has the same structure (``{"subsystems": [{"A": …, "G": …, "c": …}], …}``).

``.npz`` files hold the arrays ``format``, ``version``, ``r_min``, ``weight`` (optional),
``costs``, ``rate_min``, ``rate_max`` (optional, one entry per sensor) and
either ``A``, ``G``,
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
