"""Drawing the optimal allocation map and its filtration: each sensor's share γ_i(σ) (Hermite
interpolation of the traced nodes) with the breakpoints of Theorem 2 marked and labelled by the
sensors that enter (``+i``), leave (``−i``), reach their caps (``^i``) or fall from them
(``vi``), labels stacked in rows so that none overlaps. With sample costs the shares are in
channel units and the rates ``r = (γ + b∘r_min)/b``; the budget axis is ``B = σ + Σ b_i r_min,i``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from .._optional import require
from .channel_box import channel_box

__all__ = ["hermite", "plot_filtration"]

F64 = npt.NDArray[np.float64]


def hermite(f: Any, grid: F64) -> F64:
    """Cubic Hermite interpolation of the nodes of the filtration ``f`` at ``grid`` (for drawing
    only)."""
    out = np.empty((grid.size, f.node_gamma.shape[1]))
    for m, s in enumerate(grid):
        i = int(
            np.clip(
                np.searchsorted(f.node_sigma, s, side="right") - 1,
                0,
                f.node_sigma.size - 2,
            )
        )
        s0, s1 = f.node_sigma[i], f.node_sigma[i + 1]
        if s1 <= s0 or f.node_segment[i] != f.node_segment[i + 1]:
            out[m] = f.node_gamma[i] + (s - s0) * f.node_dgamma[i]
            continue
        h = s1 - s0
        t = (s - s0) / h
        h00, h10 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t
        h01, h11 = -2 * t**3 + 3 * t**2, t**3 - t**2
        out[m] = (
            h00 * f.node_gamma[i]
            + h10 * h * f.node_dgamma[i]
            + h01 * f.node_gamma[i + 1]
            + h11 * h * f.node_dgamma[i + 1]
        )
    return np.maximum(out, 0.0)


def plot_filtration(f: Any, ax: Any, rates: bool, log: bool, budget: bool = False) -> Any:
    """Draws the filtration ``f`` on ``ax`` (a new figure's axes when ``None``); see
    :meth:`Filtration.plot <capalloc_rs.Filtration.plot>`. With ``budget`` the x-axis is the
    budget ``B = σ + Σ b_i r_min,i`` (``r_tot = σ + N·r_min`` in the paper's case) instead of σ
    (the same curves, shifted).

    Raises:
        MissingDependencyError: matplotlib is not installed.
    """
    plt = require("matplotlib.pyplot", "Filtration.plot")
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4.5))
    grid = np.union1d(np.linspace(0.0, f.sigma_max, 400), f.node_sigma)
    box = channel_box(f.net)
    shares = hermite(f, grid)
    vals = _rates(box, shares) if rates else shares
    count = vals.shape[1]
    shift = _shift(box, count) if budget else 0.0
    cmap = plt.get_cmap("tab10" if count <= 10 else "tab20")
    period = 10 if count <= 10 else 20
    styles = ("-", "--", ":", "-.")
    for i in range(count):
        ax.plot(
            grid + shift,
            vals[:, i],
            label=f"sensor {i}",
            color=cmap(i % period),
            ls=styles[(i // period) % len(styles)],
            lw=1.4,
        )
    if log and vals.size and float(np.min(vals)) > 0:  # rates: a log scale
        ticker = require("matplotlib.ticker", "Filtration.plot")
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(ticker.ScalarFormatter())
        ax.yaxis.set_minor_formatter(ticker.ScalarFormatter())
    elif log:  # shares γ_i, zero before a sensor enters: symmetric log
        top = float(np.max(np.abs(vals))) if vals.size else 1.0
        ax.set_yscale("symlog", linthresh=max(1e-3 * top, 1e-300))
    ax.set_xlim(shift, f.sigma_max + shift)
    texts = []
    for x, text in _breakpoint_labels(f.events, f.sigma_max):
        ax.axvline(x + shift, color="0.6", ls="--", lw=0.8)
        texts.append(
            ax.annotate(
                text,
                (x + shift, 1.0),
                xycoords=ax.get_xaxis_transform(),  # x in data, y in axes fraction
                textcoords="offset points",
                xytext=(2, -10),
                fontsize=7,
                color="0.3",
            )
        )
    ax.set_xlabel(_xlabel(box.paper, budget))
    ax.set_ylabel(
        "r_i" if rates else "γ_i = r_i − r_min" if box.paper else "γ_i = b_i (r_i − r_min,i)"
    )
    ax.set_title("optimal allocation map and its filtration")
    ax.legend(
        fontsize=7 if count > 10 else 8,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0.0,
        ncol=max(1, math.ceil(count / 20)),
    )
    ax.figure.tight_layout()
    _stack_labels(ax, texts)
    return ax


def _rates(box: Any, shares: F64) -> F64:
    """The rates of the shares (``γ + r_min`` in the paper's case, as before)."""
    if box.paper:
        return np.asarray(shares + float(box.lo[0]), dtype=np.float64)
    return np.asarray(box.rates(shares), dtype=np.float64)


def _shift(box: Any, count: int) -> float:
    """``Σ b_i r_min,i`` (``N·r_min`` in the paper's case, as before)."""
    return count * float(box.lo[0]) if box.paper else float(box.budget_min)


def _xlabel(paper: bool, budget: bool) -> str:
    if paper:
        return "budget r_tot = σ + N·r_min" if budget else "σ = r_tot − N·r_min"
    return "budget B = σ + Σ b_i r_min,i" if budget else "σ = B − Σ b_i r_min,i"


#: The label of each kind of active-set change at a breakpoint.
_MARKS = {"enter": "+", "leave": "−", "capped": "^", "uncapped": "v"}


def _breakpoint_labels(events: Any, sigma_max: float) -> list[tuple[float, str]]:
    """One ``(σ, "+3,−5,^2")`` label per distinct breakpoint σ > 0 (events within 1e-9·σ_max
    of each other share it), in σ order."""
    out: list[tuple[float, list[str]]] = []
    for ev in sorted(
        (e for e in events if e.kind in _MARKS and e.sigma > 0),
        key=lambda e: e.sigma,
    ):
        mark = f"{_MARKS[ev.kind]}{ev.sensor}"
        if out and ev.sigma - out[-1][0] <= 1e-9 * max(sigma_max, 1.0):
            out[-1][1].append(mark)
        else:
            out.append((float(ev.sigma), [mark]))
    return [(x, ",".join(marks)) for x, marks in out]


def _label_rows(spans: list[tuple[float, float]], rows: int = 8) -> list[int]:
    """A row for each label of horizontal extent ``(start, end)`` (in σ order) so that labels on
    one row do not overlap: the first row whose last label ends before this one starts; past
    ``rows`` rows, the row that ends first."""
    ends: list[float] = []
    out = []
    for start, end in spans:
        free = [r for r, e in enumerate(ends) if e < start]
        if free:
            r = free[0]
        elif len(ends) < rows:
            ends.append(-math.inf)
            r = len(ends) - 1
        else:
            r = int(np.argmin(ends))
        ends[r] = end
        out.append(r)
    return out


def _stack_labels(ax: Any, texts: list[Any]) -> None:
    """Moves breakpoint labels down by rows (:func:`_label_rows`) so that none overlaps another,
    measured as drawn (extents from the figure's renderer, in pixels)."""
    if not texts:
        return
    try:
        renderer = ax.figure.canvas.get_renderer()
        boxes = [t.get_window_extent(renderer) for t in texts]
    except (AttributeError, RuntimeError, TypeError):  # a backend without a renderer: as drawn
        return
    spans = [(b.x0 - 2.0, b.x1 + 2.0) for b in boxes]
    for t, row in zip(texts, _label_rows(spans), strict=True):
        t.set_position((2, -10 - 9 * row))
