"""The traced optimal allocation map σ ↦ f(σ) (Theorem 2): :class:`Filtration`, with its
breakpoints, active sets, events and the checks of the theorem, evaluated exactly at any σ by
correcting from the traced nodes, and :class:`FiltrationEvent`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .._arrays import as_float_array
from .._json import ints, plain
from ..errors import InvalidInputError, ShapeError
from .channel_box import ChannelBox, channel_box
from .corrector import _Point, _Tracer
from .filtration_plot import plot_filtration

__all__ = ["EventKind", "Filtration", "FiltrationEvent"]

F64 = npt.NDArray[np.float64]
EventKind = Literal[
    "enter", "leave", "capped", "uncapped", "monotonicity-lost", "monotonicity-regained"
]


@dataclass(frozen=True)
class FiltrationEvent:
    """Something that happens along the path at ``sigma`` to ``sensor``.

    Attributes:
        sigma: where on the path (``σ = B − Σ b_i r_min,i``; ``r_tot − N·r_min`` in the paper's
            case).
        kind: ``"enter"`` (leaves its minimum), ``"leave"`` (back to its minimum),
            ``"capped"`` (reaches its cap ``r_max``), ``"uncapped"`` (falls from its cap),
            ``"monotonicity-lost"`` or ``"monotonicity-regained"``.
        sensor: the sensor concerned.
        mu: the KKT multiplier ``μ(σ) ≤ 0`` there, per channel unit (NaN when not recorded).
        budget: the budget ``B = σ + Σ b_i r_min,i`` there, in channel units per unit time
            (``r_tot`` in the paper's case; NaN when not recorded).
    """

    sigma: float
    kind: EventKind
    sensor: int
    mu: float = math.nan
    budget: float = math.nan

    @property
    def shadow_price(self) -> float:
        """``−μ ≥ 0`` at the event: by how much the optimum η* falls per extra channel unit of
        budget (``−dη*/dB``; ``−dη*/dr_tot`` in the paper's case) when the event happens."""
        return -float(self.mu)

    def to_dict(self) -> dict[str, Any]:
        """The event as plain JSON-ready values (``mu``, ``shadow_price`` and ``budget`` beside
        it)."""
        return {
            "sigma": plain(self.sigma),
            "kind": self.kind,
            "sensor": int(self.sensor),
            "mu": plain(float(self.mu)),
            "shadow_price": plain(self.shadow_price),
            "budget": plain(float(self.budget)),
        }


@dataclass(frozen=True, eq=False)
class Filtration:
    """The traced optimal allocation map on ``[0, sigma_max]``.

    With sample costs or rate limits the map is traced in channel units
    (:mod:`~capalloc_rs.allocation.channel_box`): ``σ = B − Σ b_i r_min,i`` and the shares are
    ``γ_i = b_i (r_i − r_min,i)``; :meth:`rates` gives the rates. In the paper's case these are
    ``σ = r_tot − N·r_min`` and ``γ = r − r_min``.

    Attributes:
        sigma_max: end of the path.
        breakpoints: ``σ_0 = 0 < σ_1 < … < σ_m = σ_max``: where the active set changes.
        active_sets: the free sensors on each ``[σ_k, σ_{k+1})`` (sorted sensor indices;
            neither at their minimum nor at their cap).
        entry_order: sensors in the order they first become active.
        events: every event along the path (enter, leave, monotonicity-lost/-regained).
        is_monotone: no sensor's share ever decreases (checked at every node and event).
        is_filtration: the active sets are nested (no sensor ever leaves).
        diagonally_dominant: ``[η''_JJ]⁻¹`` strictly diagonally dominant at every node (the paper's
            sufficient condition for strict monotonicity).
        node_sigma, node_gamma, node_mu, node_dgamma: the corrected path nodes (for plots and
            interpolation); ``allocation`` evaluates exactly at any σ by correcting from them.
        converged: ``True`` if the path was traced to the requested end; ``False`` if a budget
            stopped it first (then ``sigma_max`` is where it stopped).
        stopped: ``"completed"``, ``"max_nodes"`` or ``"time_limit"``.
        sigma_requested: the ``sigma_max`` asked for.
        capped_sets: the sensors at their caps on each ``[σ_k, σ_{k+1})`` (empty without caps).
        budget_min: ``Σ b_i r_min,i``, the budget at σ = 0 (``B = σ + budget_min``).
    """

    net: Any
    sigma_max: float
    tol: float
    breakpoints: F64
    active_sets: tuple[tuple[int, ...], ...]
    entry_order: tuple[int, ...]
    events: tuple[FiltrationEvent, ...]
    is_monotone: bool
    is_filtration: bool
    diagonally_dominant: bool
    node_sigma: F64
    node_gamma: F64
    node_mu: F64
    node_dgamma: F64
    node_segment: npt.NDArray[np.intp]
    converged: bool = True
    stopped: str = "completed"
    sigma_requested: float = math.nan
    capped_sets: tuple[tuple[int, ...], ...] = ()
    budget_min: float = math.nan

    def __repr__(self) -> str:
        """One line (under 200 characters): the span, the first breakpoints, the first sensors to
        enter and the checks (the dataclass repr printed every node array)."""
        order = list(self.entry_order)
        shown = ", ".join(map(str, order[:4])) + (", …" if len(order) > 4 else "")
        bps = [f"{b:.4g}" for b in self.breakpoints[1:-1]]
        bp_text = ", ".join(bps[:2]) + (f", … ({len(bps)} in all)" if len(bps) > 2 else "")
        return (
            f"Filtration(σ ∈ [0, {self.sigma_max:.6g}], breakpoints [{bp_text}], "
            f"entry order [{shown}], is_filtration={self.is_filtration}, "
            f"is_monotone={self.is_monotone}, stopped={self.stopped!r})"
        )

    def to_dict(self) -> dict[str, Any]:
        """The path as plain JSON-ready values: the keys of ``capalloc filtration --json``
        (``sigma_max``, ``breakpoints``, ``active_sets``, ``entry_order``, ``events``, the checks
        of Theorem 2, ``converged`` and ``stopped``) and ``sigma_requested``; the node arrays
        are left out (see the ``node_*`` attributes)."""
        return {
            "sigma_max": plain(self.sigma_max),
            "breakpoints": plain(self.breakpoints),
            "active_sets": [ints(s) for s in self.active_sets],
            "entry_order": ints(self.entry_order),
            "events": [e.to_dict() for e in self.events],
            "is_monotone": bool(self.is_monotone),
            "is_filtration": bool(self.is_filtration),
            "diagonally_dominant": bool(self.diagonally_dominant),
            "converged": bool(self.converged),
            "stopped": self.stopped,
            "sigma_requested": plain(self.sigma_requested),
            "capped_sets": [ints(s) for s in self.capped_sets],
            "budget_min": plain(self.budget_min),
        }

    # -------------------------------------------------------------------------- evaluation

    def _segment(self, s: float) -> int:
        if not (-1e-15 <= s <= self.sigma_max * (1 + 1e-15) + 1e-300):
            raise InvalidInputError(f"σ = {s} is outside [0, {self.sigma_max}]")
        k = int(np.searchsorted(self.breakpoints, s, side="right")) - 1
        return min(max(k, 0), len(self.active_sets) - 1)

    @cached_property
    def _box(self) -> ChannelBox:
        """The problem in channel units the path was traced on."""
        return channel_box(self.net)

    def _exact(self, s: float) -> _Point:
        s = float(s)
        k = self._segment(s)
        active = list(self.active_sets[k])
        capped = list(self.capped_sets[k]) if self.capped_sets else []
        idx = np.flatnonzero((self.node_segment == k) & (self.node_sigma <= s + 1e-300))
        i = int(idx[-1]) if idx.size else int(np.flatnonzero(self.node_segment == k)[0])
        ds = s - float(self.node_sigma[i])
        guess = self.node_gamma[i] + ds * self.node_dgamma[i]
        mu0 = float(self.node_mu[i])
        tracer = _Tracer(self.net, self.tol, box=self._box)
        if s == 0.0 or len(active) == 0:
            return tracer.correct(active, s, np.zeros(len(self.net.sensors)), mu0, capped)
        return tracer.correct(active, s, guess, mu0, capped)

    def _map(self, sigma: Any, fn: Any) -> Any:
        arr = as_float_array("sigma", sigma, tuple(range(8)))
        if arr.size == 0:
            raise ShapeError("sigma is empty")
        if arr.ndim == 0:
            return fn(self._exact(float(arr)))
        return np.array([fn(self._exact(float(s))) for s in arr.ravel()]).reshape(
            arr.shape + np.shape(fn(self._exact(float(arr.ravel()[0]))))
        )

    def allocation(self, sigma: Any) -> Any:
        """``f(σ) = γ*(σ)`` (length N; shape ``(*σ.shape, N)`` for array input), exact to the
        corrector tolerance."""
        return self._map(sigma, lambda p: p.gamma)

    def mu(self, sigma: Any) -> Any:
        """The KKT multiplier ``μ(σ) ≤ 0``."""
        return self._map(sigma, lambda p: p.mu)

    def shadow_price(self, sigma: Any) -> Any:
        """The shadow price ``−μ(σ) ≥ 0`` of capacity: by how much the optimum η* falls per
        extra channel unit of budget, ``−dη*/dB`` at ``B = σ + Σ b_i r_min,i`` (in the paper's
        case ``−dη*/dr_tot`` at ``r_tot = σ + N·r_min``; the same shapes as :meth:`mu`)."""
        return self._map(sigma, lambda p: -p.mu)

    def rates(self, sigma: Any) -> Any:
        """The optimal rates ``r*(σ) = (γ*(σ) + b ∘ r_min)/b`` (samples per unit time of each
        sensor; the same shapes as :meth:`allocation`)."""
        return self._map(sigma, lambda p: self._box.rates(p.gamma))

    def budget(self, sigma: Any) -> Any:
        """The budget ``B = σ + Σ b_i r_min,i`` (channel units per unit time) at σ."""
        arr = as_float_array("sigma", sigma, tuple(range(8)))
        out = arr + self._box.budget_min
        return float(out) if out.ndim == 0 else out

    def derivative(self, sigma: Any) -> Any:
        """The right derivative ``∂₊f(σ)``: ``x'/(1ᵀx')`` on the active set to the right of σ
        (``x' = [η''_JJ]⁻¹ 1``), zero elsewhere (Proposition 5)."""
        return self._map(sigma, lambda p: p.dgamma)

    def plot(
        self, ax: Any = None, *, rates: bool = False, log: bool = False, budget: bool = False
    ) -> Any:
        """Draws each sensor's allocation γ_i (or rate r_i with ``rates=True``) against σ (or
        against the budget ``r_tot = σ + N·r_min`` with ``budget=True``; with sample costs or
        rate limits ``B = σ + Σ b_i r_min,i`` in channel units), with the breakpoints marked and
        labelled by the sensors that enter (``+i``), leave (``−i``), reach their caps (``^i``)
        or fall from them (``vi``).
        Needs matplotlib (``pip install 'capalloc-rs[plot]'``; else
        :class:`~capalloc_rs.errors.MissingDependencyError`). Returns the axes.

        Readable with many sensors: events at the same σ share one label, labels too close to
        the previous one move down a row (see
        :mod:`capalloc_rs.allocation.filtration_plot`), up to 10 sensors get the
        ``tab10`` colours and more get ``tab20`` with a line style per 20, and the legend takes
        a column per 20 sensors. ``log=True`` puts the values on a logarithmic scale, so that one
        large share does not flatten the rest: symmetric-log for the shares γ_i (linear below
        1e-3 of the largest, so zero shares stay visible), plain log for the rates.

        Raises:
            InvalidInputError: ``budget`` is not True or False.
            MissingDependencyError: matplotlib is not installed.
        """
        if not isinstance(budget, bool | np.bool_):
            raise InvalidInputError(f"budget must be True or False, got {budget!r}")
        return plot_filtration(self, ax, rates, log, bool(budget))
