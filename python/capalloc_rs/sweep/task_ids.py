"""Deterministic task ids of a sweep.

``"{network_index:08d}-{r_tot as 16 order-preserving hex digits}-{12 hex digits of
SHA-256(network_index, r_tot, compute, parameters, network digest)}"``: sorting by id sorts by
network, then capacity, and a changed network or parameter gives a new id, never a stale row.
The order-preserving digits map the IEEE-754 bits of ``r_tot`` to an unsigned integer that is
monotone in the float (flip every bit of a negative number, the sign bit of a positive one).
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Mapping
from typing import Any

from ..network import Network

__all__ = ["network_digest", "task_id"]


def _sortable(x: float) -> str:
    """16 hex digits whose string order is the numeric order of the float ``x``."""
    (bits,) = struct.unpack(">Q", struct.pack(">d", float(x)))
    bits = bits ^ 0xFFFFFFFFFFFFFFFF if bits >> 63 else bits | (1 << 63)
    return f"{bits:016x}"


def task_id(
    network_index: int, r_tot: float, compute: str, params: Mapping[str, Any], digest: str
) -> str:
    """The deterministic id of a task (see the module docstring)."""
    key = json.dumps(
        [int(network_index), repr(float(r_tot)), compute, dict(params), digest],
        sort_keys=True,
        separators=(",", ":"),
    )
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return f"{int(network_index):08d}-{_sortable(r_tot)}-{h}"


def network_digest(net: Network) -> str:
    """16 hex digits of the hash of the network's data."""
    return net._key()[:16]
