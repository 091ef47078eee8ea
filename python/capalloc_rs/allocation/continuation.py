"""Path following of the optimal allocation map σ ↦ f(σ) (Proposition 5, Theorem 2) at the price
of a few optimal allocations: exact tangents, cubic Hermite predictors, and events found by
Newton's method on the KKT system extended by the event function (:mod:`.kkt_newton`).

On a segment with active set ``J`` every node carries the exact tangent ``df_J/dσ = x'/1ᵀx'``,
``dμ/dσ = 1/1ᵀx'`` (``x' = [η''_JJ]⁻¹1``) and, through the Hessian, the slopes of the event
functions: ``e_j = (g_j − μ)/|μ|`` for ``j ∉ J`` (enter when it reaches 0) with slope
``(H·df/dσ − dμ/dσ)_j/|μ|``, and ``e_i = γ_i`` for ``i ∈ J`` (leave) with slope ``df_i/dσ``.

* **Predictor.** From two nodes of the segment, the cubic Hermite interpolant of ``(f, μ)``
  through their values and tangents, extrapolated (third order); from one node, the tangent
  and, after a breakpoint, the second derivatives carried over from the segment before
  (:mod:`.path_curvature`; the event functions' too, for the events ahead).
* **Events ahead.** The event functions are extrapolated the same way (quadratic Taylor with the
  second derivative from the slopes at the last two nodes); when one is predicted to reach 0
  within the step, the step goes straight to that breakpoint: Newton on ``g_J = μ1`` closed by
  ``g_j = μ`` (enter) or ``γ_i = 0`` (leave), σ being an unknown.
* **Events missed.** After every step the event functions at both ends (values and slopes) give
  a cubic Hermite model on the step; its first root among all event functions, if any, starts
  the same breakpoint Newton (the step is then repeated towards the earlier event).
* **Monotonicity** (a share's slope ``df_i/dσ`` changing sign, no active-set change): detected
  between nodes and located by false position on corrected points (Illinois), as in the
  reference tracer.
* **Step control.** The step is scaled by ``(target/d)^{1/(p+1)}`` (clipped to [¼, 4]) from
  the predictor–corrector discrepancy ``d`` (``p`` = the predictor's order), up to
  ``σ_max/4`` (``σ_max/8`` before the fourth version), and shortened so that the tangent keeps
  every rate above ``¾·r_min``; a step that would leave less than a quarter of itself before
  σ_max goes to σ_max (fourth version: no short last node).

**Caps** (the box-simplex of :mod:`.channel_box`, sensors with finite caps ``c_i``): a second
block of event functions ``c_i − γ_i`` for the free sensors (slope ``−df_i/dσ``; *capped* when it
reaches 0, by Newton closed by ``γ_i = c_i``), and for a capped sensor ``j`` the first block is
``(μ − g_j)/|μ|`` (*uncapped* when it reaches 0, Newton closed by ``g_j = μ``). Capped sensors
are held at ``c_j`` and, like the inactive ones, have no tangent. When the last free sensor
reaches its cap below σ_max, μ jumps up to the least gradient of the sensors at their minimum,
and that sensor enters at the same σ. μ may change by orders of magnitude along a step there:
a crossing of a cubic event model that Newton does not find in the step, with the function
still positive at the step's end, is set aside as an artefact of the model — in every case
(strongly coupled networks in the paper's form stalled near σ = 0 on such crossings). The first
version (``method="continuation-v1"``: tangent-only predictors after a breakpoint, such a crossing
failing the step in the paper's case) is kept for comparison, and so is the second
(``method="continuation-v2"``): the current one evaluates η by points warm-started from the last
one, forms only the Hessian's block on the face (from 8 sensors on, below 25) and judges the
last Newton step of a node on the larger of the KKT and side-condition residuals
(:mod:`.kkt_newton`) — the same path, in fewer and cheaper evaluations. The fourth (the
current one; ``method="continuation-v3"`` keeps the third) takes longer steps where no event is
due (the longest step and the stretch to σ_max above): the same path in fewer nodes. The fifth
(the current one; ``method="continuation-v4"`` keeps the fourth) reaches each evaluation point
from the last (state order ≥ 65) by chord corrections on the last point's Schur form before the
Newton–Kleinman corrections (:meth:`CostPoint.warm` with ``chord_steps``): the same points to
rounding, mostly one Schur form each. The sixth (the current one; ``method="continuation-v5"``
keeps the fifth) asks fewer Hessian-vector products of each solve (:mod:`.kkt_newton`: node
tangents to :data:`~.kkt_newton.LEAN_TANGENT_TOL`, a new face's preconditioner seeded with the
old face's solves, the first tangent solve started from the derivative of the predictor) and
ends its warm starts below state order 65 at the working-precision floor
(``compensated=False``): the same path in fewer products and cheaper points.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .._progress import Progress
from ..errors import ConvergenceError, PathStallError
from .channel_box import ChannelBox
from .event_functions import _TINY, _Events, _hermite, _hermite_slope
from .false_position import illinois
from .filtration_path import _Path
from .filtration_result import Filtration
from .kkt_newton import PATH_CHORD_STEPS, KKTNewton, Node, Side
from .optimal import HVP_MIN_SENSORS
from .path_curvature import carried_events, carried_path

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
Retry = Callable[[float, int, float], "float | None"]
Stall = Callable[[Any, Any, float, float, float, int], PathStallError]

#: The predictor–corrector discrepancy (relative to the largest share, at least r_min) the step
#: control aims at: the Newton corrector then needs two or three evaluation points.
_TARGET = 1e-2


class _Follower:
    """The path follower (module docstring): the Newton solves, the predictor and the step."""

    def __init__(
        self, box: ChannelBox, sigma_max: float, tol: float, min_step: float, version: int
    ) -> None:
        krylov = len(box.net.sensors) >= HVP_MIN_SENSORS
        self.newton = KKTNewton(
            box.net,
            krylov=krylov,
            box=box,
            quick=version >= 3,
            chord_steps=PATH_CHORD_STEPS if version >= 5 else 0,
            lean=version >= 6,
        )
        #: Start the first tangent solve of a Newton solve from the predicted tangent (sixth
        #: version).
        self.lean = version >= 6
        self.n, self.r_min, self.lo = self.newton.n, self.newton.r_min, box.lo
        legacy = version == 1
        #: Tolerance of false crossings of the cubic event models (see ``_spurious``): always,
        #: except in the first version (``legacy``) on the paper's simplex.
        self.tolerant = not (legacy and box.paper)
        self.sigma_max = sigma_max
        self.tol_s = tol * max(sigma_max, 1.0)
        self.min_step = min_step
        self.h, self.h_max = sigma_max / 50.0, sigma_max / (4.0 if version >= 4 else 8.0)
        #: A step leaving less than a quarter of itself before σ_max goes to σ_max (version 4).
        self.stretch = version >= 4
        #: Second derivatives carried across the last breakpoint (:mod:`.path_curvature`; not
        #: in the first version, ``legacy``).
        self.curvature: tuple[Node, F64, float] | None = None
        self.carry = not legacy

    def _extrapolate(self, a: Node, prev: Node | None, sigma: float) -> tuple[F64, float]:
        """The predicted ``(f, μ)`` at σ from ``a`` (and ``prev``, same segment)."""
        pa = a.point
        if prev is None or not prev.sigma < a.sigma:
            ds = sigma - pa.sigma
            gamma, mu = pa.gamma + ds * pa.dgamma, pa.mu + ds * pa.dmu
            if self.curvature is not None and self.curvature[0] is a:
                gamma = gamma + 0.5 * ds * ds * self.curvature[1]
                mu = mu + 0.5 * ds * ds * self.curvature[2]
            return gamma, mu
        return self._between(prev, a, sigma)

    def _predicted_tangent(self, a: Node, prev: Node | None, sigma: float) -> F64 | None:
        """:meth:`_tangent0` of the predictor :meth:`_extrapolate` uses."""
        if prev is None or not prev.sigma < a.sigma:
            return self._tangent0(a, None, sigma)
        return self._tangent0(prev, a, sigma)

    def _tangent0(self, a: Node, b: Node | None, sigma: float) -> F64 | None:
        """With ``lean``, the predicted tangent ``x' = (df/dσ)/(dμ/dσ)`` at σ: the derivative of
        the predictor of :meth:`_extrapolate` (``b`` ``None``: from ``a`` and the previous node
        of its segment, :attr:`prev_of`) or of the interpolant of :meth:`_between` (``a``
        and ``b``); ``None`` otherwise."""
        if not self.lean:
            return None
        pa = a.point
        if b is not None and b.sigma > a.sigma:
            pb = b.point
            y = _hermite_slope(*_hermite_nodes(pa, pb), sigma)
            dg, dmu = y[: self.n], float(y[self.n])
        else:
            ds = sigma - pa.sigma
            dg, dmu = pa.dgamma, pa.dmu
            if self.curvature is not None and self.curvature[0] is a:
                dg, dmu = dg + ds * self.curvature[1], dmu + ds * self.curvature[2]
        if not (math.isfinite(dmu) and dmu != 0.0):
            return None
        return np.asarray(dg / dmu, dtype=np.float64)

    def _between(self, a: Node, b: Node, sigma: float) -> tuple[F64, float]:
        """``(f, μ)`` at σ on the cubic Hermite interpolant of two nodes of a segment."""
        pa, pb = a.point, b.point
        if not pb.sigma > pa.sigma:
            return pa.gamma + (sigma - pa.sigma) * pa.dgamma, pa.mu + (sigma - pa.sigma) * pa.dmu
        y = _hermite(*_hermite_nodes(pa, pb), np.array([sigma]))[0]
        return y[: self.n], float(y[self.n])

    def regular(
        self, a: Node, prev: Node | None, active: list[int], sigma: float, capped: Any = ()
    ) -> Node:
        """The node at σ, predicted and corrected; adapts the step to the discrepancy."""
        gamma0, mu0 = self._extrapolate(a, prev, sigma)
        t0 = self._predicted_tangent(a, prev, sigma)
        b = self.newton.solve(active, gamma0, mu0, Side("sigma", sigma), capped, t0)
        jj = np.array(active, dtype=np.intp)
        scale = max(float(np.max(np.abs(b.point.gamma[jj]))), self.r_min)
        d = float(np.max(np.abs(b.point.gamma[jj] - gamma0[jj]))) / scale
        order = 1 if prev is None else 3
        grow = 4.0 if d == 0.0 else 0.9 * (_TARGET / d) ** (1.0 / (order + 1))
        self.h = min(max(self.h * min(max(grow, 0.25), 4.0), self.min_step), self.h_max)
        return b

    def event(
        self, active: list[int], events: _Events, k: int, guess: Any, t0: F64 | None = None
    ) -> Node:
        """The breakpoint where the event function ``k`` vanishes (leave or cap if its sensor is
        active, else enter or uncap), by Newton from ``guess = (f, μ)`` (``t0``: the predicted
        tangent there, :meth:`_tangent0`)."""
        kind, sensor = events.kind(k)
        side = Side("enter" if kind == "uncap" else kind, float(sensor))  # type: ignore[arg-type]
        capped = np.flatnonzero(events.capped)
        return self.newton.solve(active, guess[0], guess[1], side, capped, t0)

    def advance(
        self, a: Node, prev: Node | None, active: list[int], events: _Events, step: float
    ) -> tuple[Node, int | None]:
        """The next node from ``a`` and the event there (``None``: a regular node): the event
        predicted within ``step`` if there is one, else the node at ``a.σ + step``; then any
        event missed on the way (first root of the cubic models) replaces it."""
        target = events.predicted(a, prev, step)
        b: Node | None = None
        which: int | None = None
        if target is not None:
            guess = self._extrapolate(a, prev, target[0])
            t0 = self._predicted_tangent(a, prev, target[0])
            b = self.event(active, events, target[1], guess, t0)
            which = target[1]
            if not (a.sigma - self.tol_s <= b.sigma <= min(self.sigma_max, a.sigma + 4 * step)):
                b = None  # Newton found a root behind us or far ahead: take a plain step
        if b is None:
            capped = np.flatnonzero(events.capped)
            b, which = self.regular(a, prev, active, a.sigma + step, capped), None
        spurious: list[int] = []
        for _ in range(2 * self.n + 2 + (2 * self.n if self.tolerant else 0)):
            hit = events.first_crossing(a, b, which if not spurious else [*spurious, which])
            if hit is None:
                return b, which
            guess = self._between(a, b, hit[0])
            try:
                c: Node | None = self.event(
                    active, events, hit[1], guess, self._tangent0(a, b, hit[0])
                )
            except ConvergenceError:
                c = None
                if not self._spurious(events, b, hit[1]):
                    raise
            if c is not None and a.sigma - self.tol_s <= c.sigma <= b.sigma + self.tol_s:
                b, which = c, hit[1]
            elif self._spurious(events, b, hit[1]):
                spurious.append(hit[1])
            else:
                raise ConvergenceError(f"event of sensor {hit[1]} not located in the step")
        raise ConvergenceError("events in one step could not be ordered")

    def _spurious(self, events: _Events, b: Node, k: int) -> bool:
        """Whether a crossing of event function ``k`` that Newton did not find in the step may
        be set aside as an artefact of its cubic model: only if the function is still positive
        at the step's end ``b`` (μ can change by orders of magnitude along a step, and jumps
        on the box-simplex; in strongly coupled networks a model crossing near σ = 0 that is
        not there stalled the path). In the first version (``"continuation-v1"``) only on the
        box-simplex: in the paper's case such a crossing fails the step (retried shorter)."""
        return self.tolerant and bool(events.at(b)[0][k] > _TINY)

    def locate_slope(
        self, a: Node, b: Node, active: list[int], i: int, sign: float, capped: Any = ()
    ) -> Node:
        """Where ``sign·df_i/dσ`` crosses from positive to non-positive in (a, b]: false position
        (Illinois) on corrected nodes, the bracket kept, to ``tol·max(σ_max, 1)``."""

        def at(s: float) -> tuple[Node, float]:
            t0 = self._tangent0(a, b, s)
            q = self.newton.solve(active, *self._between(a, b, s), Side("sigma", s), capped, t0)
            return q, sign * float(q.point.dgamma[i])

        lo, flo = a.sigma, max(sign * float(a.point.dgamma[i]), 1e-300)
        hi, fhi = b.sigma, sign * float(b.point.dgamma[i])
        return illinois(at, lo, flo, hi, fhi, b, self.tol_s)


def _hermite_nodes(pa: Any, pb: Any) -> tuple[float, float, F64, F64, F64, F64]:
    """The data of the cubic Hermite interpolant of ``(γ, μ)`` between two path points: their σ,
    the stacked values ``(γ, μ)`` and derivatives ``(γ', μ')`` at each."""
    return (
        pa.sigma,
        pb.sigma,
        np.append(pa.gamma, pa.mu),
        np.append(pa.dgamma, pa.dmu),
        np.append(pb.gamma, pb.mu),
        np.append(pb.dgamma, pb.dmu),
    )


def _slope_signs(node: Node, active: list[int]) -> dict[int, float]:
    """+1 for the active shares rising at ``node`` (slope > 0), −1 for the others."""
    return {i: 1.0 if node.point.dgamma[i] > 0.0 else -1.0 for i in active}


def _leave_cap(p: Any, active: list[int], h: float, lo: F64, overshoot: float) -> float:
    """``h`` shortened so that the tangent keeps every active rate above ``r_min·(1 −
    overshoot)`` (a falling share is carried just past its leave point, never to r ≤ 0;
    ``lo``: each sensor's minimum)."""
    jj = np.array(active, dtype=np.intp)
    falling = jj[p.dgamma[jj] < 0.0]
    if falling.size == 0:
        return h
    room = (p.gamma[falling] + overshoot * lo[falling]) / -p.dgamma[falling]
    return float(min(h, np.min(room))) if np.min(room) > 0.0 else h


class _Run:
    """The state of one traced path: the follower, the record, the current node ``a`` (and the
    previous one of the segment), the active set, its event functions and slope signs."""

    def __init__(self, fol: _Follower, active: list[int], a: Node, box: ChannelBox) -> None:
        self.fol = fol
        self.box = box
        self.path = _Path(active, a.point, box.budget_min)
        self.failures = 0
        self.done = False  # every sensor at its cap: nothing left to trace
        self.new_segment(active, a, [])

    def new_segment(self, active: list[int], a: Node, capped: list[int]) -> None:
        """Start a segment with free set ``active`` and capped set ``capped`` at ``a``."""
        self.active, self.capped, self.a = active, capped, a
        self.prev: Node | None = None
        self.events = _Events(active, self.fol.n, a.point.mu, capped, self.box.cap)
        self.signs = _slope_signs(a, active)

    def slope_change(self, b: Node) -> Node | None:
        """The earliest located sign change of an active share's slope in (a, b], recorded as a
        monotonicity event (the node there becomes ``a``); ``None`` if no slope changed."""
        changed = [
            i
            for i, sg in self.signs.items()
            if (b.point.dgamma[i] <= 0.0 if sg > 0 else b.point.dgamma[i] >= 0.0)
        ]
        if not changed:
            return None
        located = [
            (self.fol.locate_slope(self.a, b, self.active, i, self.signs[i], self.capped), i)
            for i in changed
        ]
        loc, i = min(located, key=lambda t: t[0].sigma)
        lost = self.signs[i] > 0
        self.path.node(loc.point)
        self.path.monotonicity(loc.point, i, lost)
        self.signs[i] = -self.signs[i]
        self.a, self.prev = loc, None
        return loc

    def accept(self, b: Node, which: int | None) -> None:
        """Record ``b``: a node of the segment, or the breakpoint of event ``which`` (a
        breakpoint found up to ``tol`` before the node is put at the node: σ never decreases)."""
        if b.sigma < self.a.sigma:
            b = replace(b, point=replace(b.point, sigma=self.a.sigma))
        self.path.node(b.point)
        if which is None:
            self.path.is_monotone &= bool(np.all(b.point.dgamma >= -1e-12))
            self.prev, self.a = self.a, b
            return
        kind, sensor = self.events.kind(which)
        active, capped, _ = self.path.change(b.point, kind, sensor, self.active, self.capped)
        if not active:
            self._refill(b, capped)
            return
        start = self.fol.newton.retangent(b, active)
        before, a = self.events, self.a
        self.fol.curvature = carried_path((a, b), start, active) if self.fol.carry else None
        self.path.segment_start(start.point, active)
        self.new_segment(active, start, capped)
        if self.fol.carry:
            self.events.carried = carried_events(before, self.events, (a, b), start)

    def _refill(self, b: Node, capped: list[int]) -> None:
        """The last free sensor reached its cap at ``b``: the sensor at its minimum with the
        least gradient enters there (μ jumps up to its gradient), or the path is done if every
        sensor is capped."""
        lower = [i for i in range(self.fol.n) if i not in capped]
        if not lower:
            self.done = True
            self.a = b
            return
        j = min(lower, key=lambda i: float(b.g[i]))
        mu = float(b.g[j])
        start = self.fol.newton.solve([j], b.point.gamma, mu, Side("sigma", b.sigma), capped)
        active, capped, _ = self.path.change(start.point, "enter", j, [], capped)
        self.path.segment_start(start.point, active)
        self.new_segment(active, start, capped)


def trace_continuation(
    box: ChannelBox,
    sigma_max: float,
    tol: float,
    start: tuple[list[int], float],
    limits: tuple[int, float, float],
    bar: Progress,
    rules: tuple[Retry, Stall, float],
    version: int = 6,
) -> Filtration:
    """The filtration on ``[0, σ_max]`` by continuation (module docstring), from the active set
    and multiplier at σ = 0 (``start``), within ``limits = (max_nodes, deadline,
    leave_overshoot)``; ``rules = (retry, stall, min_step)`` are the tracer's failure contract
    (:func:`capalloc_rs.allocation.filtration.filtration`); ``version``: 1 the first version
    (``method="continuation-v1"``: no carried second derivatives, false model crossings
    tolerated only on the box-simplex), 2 the second (``"continuation-v2"``: cold evaluations
    below order 64, the last Newton step judged on the gradient's residual alone), 3 the third
    (``"continuation-v3"``: warm-started evaluations, the last step judged on both residuals:
    :mod:`.kkt_newton`), 4 the fourth (``"continuation-v4"``: longer steps where no event is due),
    5 the fifth (``"continuation-v5"``: chord corrections before each warm start's
    Newton–Kleinman ones), 6 the current one (leaner solves, warm starts without compensated
    refinement)."""
    retry, stall, min_step = rules
    max_nodes, deadline, overshoot = limits
    fol = _Follower(box, sigma_max, tol, min_step, version)
    active, mu0 = start
    first = fol.newton.solve(active, np.zeros(fol.n), mu0, Side("sigma", 0.0))
    run = _Run(fol, active, first, box)
    stopped = "completed"
    while run.a.sigma < sigma_max and not run.done:
        bar.update(
            run.a.sigma, sigma=run.a.sigma, nodes=len(run.path.nodes), active=len(run.active)
        )
        if len(run.path.nodes) >= max_nodes or time.monotonic() >= deadline:
            stopped = "max_nodes" if len(run.path.nodes) >= max_nodes else "time_limit"
            break
        a = run.a
        step = min(_leave_cap(a.point, run.active, fol.h, fol.lo, overshoot), sigma_max - a.sigma)
        if fol.stretch and step == fol.h and sigma_max - a.sigma <= 1.25 * step:
            step = sigma_max - a.sigma  # not limited by a falling share: no short last step
        try:
            b, which = fol.advance(a, run.prev, run.active, run.events, step)
        except (ConvergenceError, np.linalg.LinAlgError):
            run.failures += 1
            shorter = retry(fol.h, run.failures, min_step)
            if shorter is None:
                raise stall(fol.newton, a.point, sigma_max, step, min_step, run.failures) from None
            fol.h = shorter
            continue
        run.failures = 0
        if run.slope_change(b) is None:
            run.accept(b, which)
    end = sigma_max if stopped == "completed" else run.a.sigma
    return run.path.result(box, sigma_max, tol, stopped, end)
