"""The optimal allocation map σ ↦ f(σ) and its filtration (Section IV, Theorem 2 of the paper).

For ``σ ∈ [0, σ_max]`` let ``f(σ) = γ*(σ)`` be the optimal allocation on the simplex of height σ and
``μ(σ)`` its KKT multiplier. On an interval where the active set ``J`` is fixed, ``f`` solves the
KKT system ``∂η/∂γ_J (f) = μ·1``, ``1ᵀ f_J = σ``, ``f_{J^c} = 0``; differentiating,

    df_J/dσ = x' / (1ᵀx'),   dμ/dσ = 1 / (1ᵀx'),   x' = [η''_JJ]⁻¹ 1       (Proposition 5).

We follow the path exactly: a tangent predictor along this ODE, then a Newton corrector back onto
the KKT system (``[[η''_JJ, −1], [1ᵀ, 0]] [δγ; δμ] = −[g_J − μ1; 1ᵀγ_J − σ]``). Active-set changes
are events located by root-finding to ``tol`` (relative to σ_max):

* **enter** — an inactive sensor's gradient reaches μ (``g_j − μ`` crosses 0): a breakpoint of
  Theorem 2;
* **leave** — an active sensor's share reaches 0 (``γ_i`` crosses 0): impossible under the paper's
  small-ε hypothesis, reported when coupling is stronger;
* **monotonicity-lost / -regained** — an active sensor's ``df_i/dσ`` changes sign.

Theorem 2's conclusions are *checked* along the path, not assumed: ``is_monotone`` (no share ever
decreases), ``is_filtration`` (the active sets are nested: no sensor leaves) and
``diagonally_dominant`` (the sufficient condition of the paper, ``[η''_JJ]⁻¹`` strictly diagonally
dominant at every node).

We start at σ = 0 with the sensor(s) whose gradient at ``r = r_min`` is most negative.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from . import limits
from ._arrays import as_count, as_float_array, as_real, numerical_errors, require_attrs
from ._netarg import accepts_path
from ._optional import require
from ._progress import Progress, ProgressArg
from .allocation import _simplex_qp, face_kkt_solve, value_gradient, value_gradient_hessian
from .errors import ConvergenceError, InvalidInputError, PathStallError, ShapeError
from .limits import check_time_limit

__all__ = ["Filtration", "FiltrationEvent", "filtration"]

F64 = npt.NDArray[np.float64]
EventKind = Literal["enter", "leave", "monotonicity-lost", "monotonicity-regained"]

#: Step control after a corrector failure (the contract stated in :func:`filtration`): the step is
#: multiplied by ``_SHRINK``; the path is stalled when the next step would be shorter than
#: ``_STALL_STEP·σ_max`` or after ``_MAX_FAILURES`` consecutive failures, whichever comes first.
#: From the largest step ``σ_max/40`` the floor is reached after at most 21 failures, so the
#: count only ends loops in which the step does not shrink (NaN, or a bug): the loop is bounded
#: by ``max_nodes·_MAX_FAILURES`` corrector calls whatever the floats.
_SHRINK = 0.25
_STALL_STEP = 1e-14
_MAX_FAILURES = 30
#: A predicted step stops where a falling share's rate is predicted to reach ``r_min·(1 − ¼)``: the
#: leave event (γ_i = 0) is then crossed without evaluating the cost outside its domain r > 0.
_LEAVE_OVERSHOOT = 0.25


@dataclass(frozen=True)
class FiltrationEvent:
    """Something that happens along the path at ``sigma`` to ``sensor``."""

    sigma: float
    kind: EventKind
    sensor: int


@dataclass(frozen=True)
class _Point:
    sigma: float
    gamma: F64
    mu: float
    dgamma: F64  # right derivative df/dσ with the active set of the segment
    dmu: float  # dμ/dσ = 1/(1ᵀx')
    dd: bool  # [η''_JJ]⁻¹ strictly diagonally dominant here
    iterations: int


class _Tracer:
    """Newton corrector and tangent for a fixed active set."""

    def __init__(self, net: Any, tol: float, max_newton: int = 30) -> None:
        self.net = net
        self.r_min = float(net.r_min)
        self.n = len(net.sensors)
        self.tol = tol
        self.max_newton = max_newton
        # Diagnostics of the last corrector call (for the stall message).
        self.last_residual = math.nan
        self.last_mu = math.nan

    def correct(self, active: list[int], sigma: float, gamma0: F64, mu0: float) -> _Point:
        jj = np.array(active, dtype=np.intp)
        gamma = np.zeros(self.n)
        gamma[jj] = gamma0[jj]
        mu = mu0
        for it in range(self.max_newton):
            if not np.all(gamma[jj] > -0.5 * self.r_min):
                break  # the rates γ + r_min must stay positive (and finite): η is defined there
            _, g, h = value_gradient_hessian(self.net, gamma + self.r_min)
            resid = np.concatenate([g[jj] - mu, [gamma[jj].sum() - sigma]])
            k = jj.size
            scale_g = max(abs(mu), float(np.max(np.abs(g[jj]))), 1e-300)
            self.last_residual = float(np.max(np.abs(resid[:k]))) / scale_g
            self.last_mu = mu
            converged = float(np.max(np.abs(resid[:k]))) <= 1e-13 * scale_g and abs(
                resid[k]
            ) <= 1e-14 * max(sigma, 1.0)
            if converged or it == self.max_newton - 1:
                if not converged:
                    break
                return self._point(jj, sigma, gamma, mu, h, it)
            hjj = h[np.ix_(jj, jj)]
            try:
                step, dmu = face_kkt_solve(0.5 * (hjj + hjj.T), -resid[:k], -resid[k])
            except np.linalg.LinAlgError:
                break
            gamma[jj] += step
            mu += dmu
            if not np.all(np.isfinite(gamma)) or np.any(gamma[jj] < -0.5 * max(sigma, 1e-300)):
                break
            if (
                float(np.max(np.abs(step))) <= 1e-15 * max(sigma, 1.0)
                and float(np.max(np.abs(resid[:k]))) <= 1e-10 * scale_g
            ):
                return self._point(jj, sigma, gamma, mu, h, it + 1)
        raise ConvergenceError(f"path corrector did not converge at σ = {sigma:.6g}")

    def _point(
        self, jj: npt.NDArray[np.intp], sigma: float, gamma: F64, mu: float, h: F64, its: int
    ) -> _Point:
        hjj = 0.5 * (h[np.ix_(jj, jj)] + h[np.ix_(jj, jj)].T)
        minv = np.linalg.inv(hjj)
        xp = minv @ np.ones(jj.size)
        dg = np.zeros(self.n)
        dg[jj] = xp / xp.sum()
        off = np.sum(np.abs(minv), axis=1) - np.abs(np.diag(minv))
        dd = bool(np.all(np.abs(np.diag(minv)) > off)) if jj.size > 1 else True
        return _Point(sigma, gamma.copy(), float(mu), dg, float(1.0 / xp.sum()), dd, its)

    def events(self, active: list[int], p: _Point) -> F64:
        """Event functions at p (positive = nothing happened): for j ∉ J, (g_j − μ)/|μ|; for
        i ∈ J, γ_i/σ_scale and the derivative df_i/dσ."""
        _, g = value_gradient(self.net, p.gamma + self.r_min)
        out = np.empty(2 * self.n)
        mask = np.zeros(self.n, dtype=bool)
        mask[active] = True
        scale = max(abs(p.mu), 1e-300)
        out[: self.n] = np.where(mask, p.gamma, (g - p.mu) / scale)
        out[self.n :] = np.where(mask, p.dgamma, 1.0)
        return out


@dataclass(frozen=True, eq=False)
class Filtration:
    """The traced optimal allocation map on ``[0, sigma_max]``.

    Attributes:
        sigma_max: end of the path.
        breakpoints: ``σ_0 = 0 < σ_1 < … < σ_m = σ_max``: where the active set changes.
        active_sets: the active set on each ``[σ_k, σ_{k+1})`` (sorted sensor indices).
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

    def __repr__(self) -> str:
        """One line: the path's span, breakpoints and properties (the dataclass repr printed
        every node array: ~15,000 characters for 8 sensors)."""
        order = list(self.entry_order)
        shown = ", ".join(map(str, order[:8])) + (", …" if len(order) > 8 else "")
        bps = [f"{b:.4g}" for b in self.breakpoints[1:-1]]
        bp_text = ", ".join(bps[:6]) + (f", … ({len(bps)} in all)" if len(bps) > 6 else "")
        return (
            f"Filtration(σ ∈ [0, {self.sigma_max:.6g}], breakpoints [{bp_text}], "
            f"entry order [{shown}], is_filtration={self.is_filtration}, "
            f"is_monotone={self.is_monotone}, converged={self.converged}, "
            f"stopped={self.stopped!r})"
        )

    # -------------------------------------------------------------------------- evaluation

    def _segment(self, s: float) -> int:
        if not (-1e-15 <= s <= self.sigma_max * (1 + 1e-15) + 1e-300):
            raise InvalidInputError(f"σ = {s} is outside [0, {self.sigma_max}]")
        k = int(np.searchsorted(self.breakpoints, s, side="right")) - 1
        return min(max(k, 0), len(self.active_sets) - 1)

    def _exact(self, s: float) -> _Point:
        s = float(s)
        k = self._segment(s)
        active = list(self.active_sets[k])
        idx = np.flatnonzero((self.node_segment == k) & (self.node_sigma <= s + 1e-300))
        i = int(idx[-1]) if idx.size else int(np.flatnonzero(self.node_segment == k)[0])
        ds = s - float(self.node_sigma[i])
        guess = self.node_gamma[i] + ds * self.node_dgamma[i]
        mu0 = float(self.node_mu[i])
        tracer = _Tracer(self.net, self.tol)
        if s == 0.0 or len(active) == 0:
            return tracer.correct(active, s, np.zeros(len(self.net.sensors)), mu0)
        return tracer.correct(active, s, guess, mu0)

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

    def derivative(self, sigma: Any) -> Any:
        """The right derivative ``∂₊f(σ)``: ``x'/(1ᵀx')`` on the active set to the right of σ
        (``x' = [η''_JJ]⁻¹ 1``), zero elsewhere (Proposition 5)."""
        return self._map(sigma, lambda p: p.dgamma)

    def _hermite(self, grid: F64) -> F64:
        """Cubic Hermite interpolation of the nodes (for drawing only)."""
        out = np.empty((grid.size, self.node_gamma.shape[1]))
        for m, s in enumerate(grid):
            i = int(
                np.clip(
                    np.searchsorted(self.node_sigma, s, side="right") - 1,
                    0,
                    self.node_sigma.size - 2,
                )
            )
            s0, s1 = self.node_sigma[i], self.node_sigma[i + 1]
            if s1 <= s0 or self.node_segment[i] != self.node_segment[i + 1]:
                out[m] = self.node_gamma[i] + (s - s0) * self.node_dgamma[i]
                continue
            h = s1 - s0
            t = (s - s0) / h
            h00, h10 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t
            h01, h11 = -2 * t**3 + 3 * t**2, t**3 - t**2
            out[m] = (
                h00 * self.node_gamma[i]
                + h10 * h * self.node_dgamma[i]
                + h01 * self.node_gamma[i + 1]
                + h11 * h * self.node_dgamma[i + 1]
            )
        return np.maximum(out, 0.0)

    def plot(self, ax: Any = None, *, rates: bool = False, log: bool = False) -> Any:
        """Draws each sensor's allocation γ_i (or rate r_i with ``rates=True``) against σ, with
        the breakpoints marked and labelled by the sensors that enter (``+i``) or leave (``−i``).
        Needs matplotlib (``pip install 'capalloc-rs[plot]'``; else
        :class:`~capalloc_rs.errors.MissingDependencyError`). Returns the axes.

        Readable with many sensors: events at the same σ share one label, labels too close to
        the previous one move down a row (:func:`_label_rows`), up to 10 sensors get the
        ``tab10`` colours and more get ``tab20`` with a line style per 20, and the legend takes
        a column per 20 sensors. ``log=True`` puts the values on a logarithmic scale, so that one
        large share does not flatten the rest: symmetric-log for the shares γ_i (linear below
        1e-3 of the largest, so zero shares stay visible), plain log for the rates."""
        plt = require("matplotlib.pyplot", "Filtration.plot")
        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4.5))
        grid = np.union1d(np.linspace(0.0, self.sigma_max, 400), self.node_sigma)
        vals = self._hermite(grid) + (float(self.net.r_min) if rates else 0.0)
        count = vals.shape[1]
        cmap = plt.get_cmap("tab10" if count <= 10 else "tab20")
        period = 10 if count <= 10 else 20
        styles = ("-", "--", ":", "-.")
        for i in range(count):
            ax.plot(
                grid,
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
        ax.set_xlim(0.0, self.sigma_max)
        texts = []
        for x, text in _breakpoint_labels(self.events, self.sigma_max):
            ax.axvline(x, color="0.6", ls="--", lw=0.8)
            texts.append(
                ax.annotate(
                    text,
                    (x, 1.0),
                    xycoords=ax.get_xaxis_transform(),  # x in data, y in axes fraction
                    textcoords="offset points",
                    xytext=(2, -10),
                    fontsize=7,
                    color="0.3",
                )
            )
        ax.set_xlabel("σ = r_tot − N·r_min")
        ax.set_ylabel("r_i" if rates else "γ_i = r_i − r_min")
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


def _breakpoint_labels(events: Any, sigma_max: float) -> list[tuple[float, str]]:
    """One ``(σ, "+3,−5")`` label per distinct breakpoint σ > 0 (events within 1e-9·σ_max of
    each other share it), in σ order."""
    out: list[tuple[float, list[str]]] = []
    for ev in sorted(
        (e for e in events if e.kind in ("enter", "leave") and e.sigma > 0),
        key=lambda e: e.sigma,
    ):
        mark = f"{'+' if ev.kind == 'enter' else '−'}{ev.sensor}"
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


def _locate(
    tracer: _Tracer,
    active: list[int],
    left: _Point,
    right_sigma: float,
    which: int,
    tol_s: float,
    sign: float,
) -> _Point:
    """Finds σ* in (left.sigma, right_sigma] where ``sign·event[which]`` crosses from positive to
    non-positive (Illinois false position, bracket kept) and returns the corrected point there."""

    def at(s: float) -> tuple[_Point, float]:
        ds = s - left.sigma
        p = tracer.correct(active, s, left.gamma + ds * left.dgamma, left.mu + ds * left.dmu)
        return p, sign * float(tracer.events(active, p)[which])

    a = left.sigma
    fa = max(sign * float(tracer.events(active, left)[which]), 1e-300)
    pb, fb = at(right_sigma)
    b = right_sigma
    side = 0
    for _ in range(200):
        if b - a <= tol_s:
            break
        s = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not (a < s < b):
            s = 0.5 * (a + b)
        ps, fs = at(s)
        if fs > 0:
            a, fa = s, fs
            if side == -1:
                fb *= 0.5
            side = -1
        else:
            b, fb, pb = s, fs, ps
            if side == 1:
                fa *= 0.5
            side = 1
    return pb


def _stall_error(
    tracer: _Tracer, p: _Point, sigma_max: float, step: float, min_step: float, failures: int
) -> PathStallError:
    """Why the path could not be followed past ``p`` and what to do about it."""
    r = p.gamma + tracer.r_min
    return PathStallError(
        f"path following stalled at σ = {p.sigma:.6g} of σ_max = {sigma_max:.6g}: the Newton "
        f"corrector cannot meet the KKT conditions g_J = μ·1 to 1e-13 relative even over a step "
        f"of {step:.1e} ({failures} failure(s) in a row, each retry ¼ of the step before; the "
        f"next would be below {_STALL_STEP:g}·σ_max = {min_step:.1e}; last relative residual "
        f"{tracer.last_residual:.1e}, |μ| = {abs(p.mu):.3e}, rates up to {float(np.max(r)):.3e}). "
        f"At these rates the gradient of η is no longer resolved that finely in double precision "
        f"(its rounding grows with the rates), so the allocation map is not computable beyond "
        f"about σ = {p.sigma:.6g}. Trace to a smaller sigma_max, or use "
        f"optimal_allocation(net, r_tot) for single points at larger capacity.",
        sigma=p.sigma,
        step=step,
        min_step=min_step,
        failures=failures,
    )


def _retry_step(h: float, failures: int, min_step: float) -> float | None:
    """The step to retry with after the ``failures``-th consecutive corrector failure, the last
    at step ``h``: ``h·_SHRINK``; ``None`` (the path is stalled) when that is shorter than
    ``min_step`` or not a number, or after ``_MAX_FAILURES`` failures."""
    retry = h * _SHRINK
    if not retry >= min_step or failures >= _MAX_FAILURES:
        return None
    return retry


def _leave_cap(p: _Point, active: list[int], h: float, r_min: float) -> float:
    """The step from ``p``: ``h``, shortened so that the tangent predictor keeps every active
    rate above ``r_min·(1 − _LEAVE_OVERSHOOT)``. A falling share is thereby carried just past
    its leave point γ_i = 0 (where the event is detected and located) instead of being predicted
    to a negative rate, outside the domain of η."""
    jj = np.array(active, dtype=np.intp)
    falling = jj[p.dgamma[jj] < 0.0]
    if falling.size == 0:
        return h
    room = (p.gamma[falling] + _LEAVE_OVERSHOOT * r_min) / -p.dgamma[falling]
    return float(min(h, np.min(room))) if np.min(room) > 0.0 else h


def _tied_start(net: Any, tied: list[int], r_min: float, n: int) -> list[int]:
    """The sensors that leave r_min first when several tie for the most negative gradient at
    σ = 0. For small σ the optimum is ``σ·d*`` with ``d* = argmin ½dᵀ∇²η_TT d`` over the unit
    simplex on the tied set T (the linear term ``gᵀd = μ`` is the same for every such d); only
    the support of d* is active — a tied sensor with a negative tangent would go below r_min."""
    _, _, h = value_gradient_hessian(net, np.full(n, r_min))
    tt = np.array(tied, dtype=np.intp)
    htt = 0.5 * (h[np.ix_(tt, tt)] + h[np.ix_(tt, tt)].T)
    htt = htt + 1e-12 * max(float(np.max(np.abs(np.diag(htt)))), 1e-300) * np.eye(tt.size)
    start = np.full(tt.size, 1.0 / tt.size)
    d = _simplex_qp(htt, np.zeros(tt.size), start, 1.0, max_iter=20 * tt.size + 100)
    return [int(i) for i, di in zip(tt, d, strict=True) if di > 0.0]


@accepts_path
@numerical_errors
def filtration(
    net: Any,
    sigma_max: float,
    *,
    tol: float = 1e-10,
    max_nodes: int | None = None,
    time_limit: float | None = None,
    progress: ProgressArg = None,
) -> Filtration:
    """Traces the optimal allocation map on ``[0, σ_max]`` with its breakpoints and active sets.

    Args:
        net: the network (``r_min``, ``sensors``, ``value_and_gradient``,
            ``value_gradient_hessian`` — a :class:`capalloc_rs.Network`).
        sigma_max: the largest σ = r_tot − N·r_min to trace to (> 0).
        tol: breakpoints are located to ``tol·max(σ_max, 1)``.
        max_nodes: budget of path nodes (default ``capalloc_rs.limits.FILTRATION_MAX_NODES``).
        time_limit: budget in seconds (default ``capalloc_rs.limits.FILTRATION_TIME_LIMIT``,
            ``None``: no limit), checked after every node.
        progress: ``None`` (a tqdm bar over σ on stderr if it is a terminal and tqdm is
            installed), ``True``/``False``, or a callable receiving ``{"sigma", "nodes",
            "active", "elapsed"}`` after every node.

    Hitting ``max_nodes`` or ``time_limit`` is not an error: the result covers ``[0, σ]`` up to
    where the path stopped, with ``converged=False`` and ``stopped`` naming the budget. Ctrl-C
    raises ``KeyboardInterrupt`` (between and inside the Rust evaluations).

    Step control: each path step is a tangent prediction corrected by Newton to the KKT system.
    The step grows after easy corrections (≤ 2 Newton iterations) up to ``σ_max/40``, shrinks after
    hard ones, never below ``1e-14·σ_max``, and is shortened so that the predictor keeps every
    rate above ``¾·r_min`` (a falling share is carried just past its leave point, never to a
    negative rate). When the corrector fails, the step is divided by 4 and retried from the same
    node; the path is declared stalled (:class:`~capalloc_rs.errors.PathStallError`) when the next
    step would be shorter than ``1e-14·σ_max`` — the last step tried then lies in
    ``[1e-14·σ_max, 4e-14·σ_max)`` unless σ_max or the rate bound shortened it — or after 30
    consecutive failures whatever the step (at most 21 are needed from ``σ_max/40``; the count
    bounds the loop even if the step does not shrink).

    Raises:
        PathStallError: a :class:`ConvergenceError`: the path cannot be followed past ``sigma``
            (its fields ``sigma``, ``step``, ``min_step`` and ``failures``; the message says
            where, why and what to do).
        ConvergenceError: the corrector failed while locating an event (the message names σ).
    """
    require_attrs("net", net, "sensors", "r_min")
    sigma_max = as_real("sigma_max", sigma_max, positive=True)
    tol = as_real("tol", tol)
    if not (math.isfinite(tol) and 0 < tol < 1e-2):
        raise InvalidInputError(f"tol must be in (0, 1e-2), got {tol}")
    started = time.monotonic()
    node_budget = as_count(
        "max_nodes", limits.FILTRATION_MAX_NODES if max_nodes is None else max_nodes, minimum=1
    )
    budget = check_time_limit(limits.FILTRATION_TIME_LIMIT if time_limit is None else time_limit)
    deadline = math.inf if budget is None else started + budget
    with Progress(progress, "filtration", total=float(sigma_max)) as bar:
        return _trace(net, float(sigma_max), tol, int(node_budget), deadline, bar)


def _trace(
    net: Any, sigma_max: float, tol: float, max_nodes: int, deadline: float, bar: Progress
) -> Filtration:
    """The path following of :func:`filtration` (arguments checked)."""
    n = len(net.sensors)
    r_min = float(net.r_min)
    tracer = _Tracer(net, tol)
    tol_s = tol * max(sigma_max, 1.0)

    _, g0 = value_gradient(net, np.full(n, r_min))
    gmin = float(np.min(g0))
    active = sorted(int(i) for i in np.flatnonzero(g0 <= gmin + 1e-12 * abs(gmin)))
    if len(active) > 1:
        active = _tied_start(net, active, r_min, n)
    events: list[FiltrationEvent] = [FiltrationEvent(0.0, "enter", i) for i in active]
    entry_order: list[int] = list(active)
    breakpoints = [0.0]
    sets: list[tuple[int, ...]] = []
    nodes: list[tuple[_Point, int]] = []
    is_monotone = True
    dd_all = True

    p = tracer.correct(active, 0.0, np.zeros(n), gmin)
    h = sigma_max / 200.0
    h_max = sigma_max / 40.0
    seg = 0
    nodes.append((p, seg))
    sets.append(tuple(active))
    ev_prev = tracer.events(active, p)
    stopped = "completed"
    min_step = _STALL_STEP * sigma_max
    failures = 0  # consecutive corrector failures at p
    while p.sigma < sigma_max:
        bar.update(p.sigma, sigma=p.sigma, nodes=len(nodes), active=len(active))
        if len(nodes) >= max_nodes:
            stopped = "max_nodes"
            break
        if time.monotonic() >= deadline:
            stopped = "time_limit"
            break
        s_new = min(p.sigma + _leave_cap(p, active, h, r_min), sigma_max)
        ds = s_new - p.sigma
        try:
            q = tracer.correct(active, s_new, p.gamma + ds * p.dgamma, p.mu + ds * p.dmu)
        except (ConvergenceError, np.linalg.LinAlgError):
            failures += 1
            retry = _retry_step(h, failures, min_step)
            if retry is None:
                raise _stall_error(tracer, p, sigma_max, ds, min_step, failures) from None
            h = retry
            continue
        failures = 0
        ev_new = tracer.events(active, q)
        down = np.flatnonzero((ev_prev > 0) & (ev_new <= 0))  # enter, leave, monotonicity lost
        up = n + np.flatnonzero((ev_prev[n:] < 0) & (ev_new[n:] >= 0))  # monotonicity regained
        if down.size == 0 and up.size == 0:
            nodes.append((q, seg))
            dd_all &= q.dd
            is_monotone &= bool(np.all(q.dgamma >= -1e-12))
            # Step control from the corrector's work.
            grow = 1.6 if q.iterations <= 2 else 0.7 if q.iterations >= 5 else 1.0
            h = min(max(h * grow, min_step), h_max)
            p, ev_prev = q, ev_new
            continue
        # Locate the earliest event in (p.sigma, s_new].
        located = [(_locate(tracer, active, p, s_new, int(w), tol_s, +1.0), int(w)) for w in down]
        located += [(_locate(tracer, active, p, s_new, int(w), tol_s, -1.0), int(w)) for w in up]
        loc, w = min(located, key=lambda t: t[0].sigma)
        sensor = w % n
        nodes.append((loc, seg))
        dd_all &= loc.dd
        if w >= n:  # a share's derivative changed sign: no active-set change
            lost = bool(w in down)
            events.append(
                FiltrationEvent(
                    loc.sigma, "monotonicity-lost" if lost else "monotonicity-regained", sensor
                )
            )
            is_monotone &= not lost
            p = loc
            ev_prev = tracer.events(active, p)
            ev_prev[w] = -1e-300 if lost else 1e-300  # crossed: only the reverse can fire next
            continue
        gam = loc.gamma.copy()
        if sensor in active:
            active = [i for i in active if i != sensor]
            events.append(FiltrationEvent(loc.sigma, "leave", sensor))
            is_monotone = False
            gam[sensor] = 0.0
        else:
            active = sorted([*active, sensor])
            events.append(FiltrationEvent(loc.sigma, "enter", sensor))
            if sensor not in entry_order:
                entry_order.append(sensor)
        seg += 1
        breakpoints.append(loc.sigma)
        sets.append(tuple(active))
        p = tracer.correct(active, loc.sigma, gam, loc.mu)
        nodes.append((p, seg))
        ev_prev = tracer.events(active, p)
        # The sensor that just changed sits exactly on its event: it must move away first.
        ev_prev[sensor] = 1e-300
        # A share may start decreasing right at the breakpoint (no crossing to detect).
        for i in active:
            if p.dgamma[i] < 0:
                events.append(FiltrationEvent(p.sigma, "monotonicity-lost", i))
                is_monotone = False
    requested = sigma_max
    if stopped != "completed":
        sigma_max = p.sigma  # the path covers [0, p.sigma]
    breakpoints.append(sigma_max)
    if len(breakpoints) > 2 and breakpoints[-2] >= sigma_max:  # an event exactly at σ_max
        breakpoints.pop(-2)
        sets.pop()
    node_sigma = np.array([pt.sigma for pt, _ in nodes])
    arrays = [
        node_sigma,
        np.array([pt.gamma for pt, _ in nodes]),
        np.array([pt.mu for pt, _ in nodes]),
        np.array([pt.dgamma for pt, _ in nodes]),
    ]
    segs = np.array([k for _, k in nodes], dtype=np.intp)
    bp = np.array(breakpoints)
    for arr in (*arrays, segs, bp):
        arr.setflags(write=False)
    leaves = any(ev.kind == "leave" for ev in events)
    return Filtration(
        net=net,
        sigma_max=float(sigma_max),
        tol=tol,
        breakpoints=bp,
        active_sets=tuple(sets),
        entry_order=tuple(entry_order),
        events=tuple(events),
        is_monotone=is_monotone and not leaves,
        is_filtration=not leaves,
        diagonally_dominant=dd_all,
        node_sigma=arrays[0],
        node_gamma=arrays[1],
        node_mu=arrays[2],
        node_dgamma=arrays[3],
        node_segment=segs,
        converged=stopped == "completed",
        stopped=stopped,
        sigma_requested=requested,
    )
