"""The filtration's problem in channel units: the box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}``.

A network with sample costs ``b_i`` and rate limits ``r_min,i ≤ r_i ≤ r_max,i`` is, in the
variable ``s = b ∘ r`` (channel units per unit time spent on each sensor), the network with unit
costs and sensors ``ĉ_i/√b_i`` (``net.in_channel_units()``) on the box-simplex
``{lo ≤ s ≤ hi, Σ s_i = B}``, ``lo = b ∘ r_min``, ``hi = b ∘ r_max``. With ``γ = s − lo`` and
``σ = B − Σ lo`` the filtration follows ``γ*(σ)`` on ``{0 ≤ γ ≤ c, Σγ = σ}``, ``c = hi − lo``
(``inf`` where a sensor has no cap), ``σ ∈ [0, Σ c]``. Each sensor is in one of three states
along the path — at its minimum (``γ_i = 0``, ``g_i ≥ μ``), free (``g_i = μ``) or at its cap
(``γ_i = c_i``, ``g_i ≤ μ``) — and the rates are ``r = (γ + lo)/b``.

In the paper's case (unit costs, one common ``r_min``, no cap) the box is the network itself with
``lo = r_min·1`` and ``c = ∞``: every formula of the tracers then computes exactly what it did
without the box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import InvalidInputError

__all__ = ["ChannelBox", "channel_box"]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ChannelBox:
    """The filtration's problem in channel units (module docstring).

    Attributes:
        net: the network the tracers evaluate, in channel units (unit costs; the network itself
            in the paper's case).
        lo: ``b ∘ r_min``, where ``γ = 0`` (length N).
        cap: ``c = b ∘ (r_max − r_min)``, the largest ``γ_i`` (``inf``: no cap).
        costs: ``b`` (ones in the paper's case).
        paper: whether the network is in the paper's form.
        source: the network as given (in rates).
    """

    net: Any
    lo: F64
    cap: F64
    costs: F64
    paper: bool
    source: Any

    @property
    def r_min(self) -> float:
        """The smallest ``lo_i`` (the common ``r_min`` in the paper's case): the scale below
        which a share counts as small."""
        return float(np.min(self.lo))

    @property
    def has_caps(self) -> bool:
        """Whether some sensor has a finite cap (cap events can happen)."""
        return bool(np.any(np.isfinite(self.cap)))

    @property
    def budget_min(self) -> float:
        """``Σ lo = Σ b_i r_min,i``: the budget at ``σ = 0`` (channel units per unit time)."""
        return float(np.sum(self.lo))

    @property
    def width(self) -> float:
        """The largest σ, where every sensor is at its cap (``inf`` if one has none):
        ``budget_range[1] − budget_range[0]`` of the network (``Σ c`` without it)."""
        span = getattr(self.source, "budget_range", None)
        if self.paper or span is None:
            return float(np.sum(self.cap))
        return float(span[1]) - float(span[0])

    def rates(self, gamma: F64) -> F64:
        """The rates ``r = (γ + lo)/b`` of shares ``γ`` (last axis: the sensors), within the
        network's ``[r_min, r_max]`` (a share at its cap gives ``r_max`` exactly, not the
        rounding of ``(b r_max − b r_min + b r_min)/b``)."""
        r = np.asarray((np.asarray(gamma) + self.lo) / self.costs, dtype=np.float64)
        if self.paper:
            return r
        limits = self.source
        return np.asarray(np.clip(r, limits.rate_min, limits.rate_max), dtype=np.float64)

    def check_sigma_max(self, sigma_max: float) -> None:
        """Raises InvalidInputError naming ``sigma_max`` when it lies beyond ``Σ c`` (every
        sensor at its cap before it)."""
        width = self.width
        if math.isfinite(width) and sigma_max > width:
            raise InvalidInputError(
                f"sigma_max = {sigma_max:.17g} is beyond the feasible budgets: every sensor is "
                f"at its cap at σ = Σ b_i r_max,i − Σ b_i r_min,i = {width:.17g} (from "
                f"net.budget_range); the largest feasible sigma_max is {width:.17g}"
            )


def channel_box(net: Any) -> ChannelBox:
    """The channel-unit problem of ``net``: the network itself when it is in the paper's form
    (or is an oracle without costs and limits), else ``net.in_channel_units()`` with its bounds."""
    n = len(net.sensors)
    if getattr(net, "is_paper_form", True):
        ones = np.ones(n)
        lo = np.full(n, float(net.r_min))
        return ChannelBox(net, lo, np.full(n, math.inf), ones, True, net)
    cn = net.in_channel_units()
    lo = np.asarray(cn.rate_min, dtype=np.float64)
    cap = np.asarray(cn.rate_max, dtype=np.float64) - lo
    costs = np.asarray(net.costs, dtype=np.float64)
    return ChannelBox(cn, lo, cap, costs, False, net)
