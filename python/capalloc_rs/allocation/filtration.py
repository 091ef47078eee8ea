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

**Sample costs and rate limits** (``not net.is_paper_form``). The path is traced in channel units
``s = b∘r`` (``net.in_channel_units()``, :mod:`.channel_box`) on the box-simplex
``{0 ≤ γ ≤ c, Σγ = σ}``, ``γ = s − b∘r_min``, ``c = b∘(r_max − r_min)``, ``σ = B − Σ b_i r_min,i``
over the budget B. Each sensor is at its minimum (``g_i ≥ μ``), free (``g_i = μ``) or at its
cap (``g_i ≤ μ``); the tangent is Proposition 5's on the free set F,
``df_F/dσ = H_FF⁻¹1/(1ᵀH_FF⁻¹1)``, and two events join the list: **capped** (a free share
reaches ``c_i``) and **uncapped** (a capped sensor's ``g_j − μ`` comes back to 0 from below).
When the last free sensor is capped below σ_max, the least gradient among the sensors at their
minimum enters there (μ jumps up to it).

*Theorem 2 with costs and caps.* For decoupled subsystems (``η = Σ_i η_i(r_i)``, each ``η_i``
convex) ``g_i(s_i) = η_i'(s_i/b_i)/b_i`` is nondecreasing and the KKT conditions give
``s_i(μ) = clip(g_i⁻¹(μ), b_i r_min,i, b_i r_max,i)``: each share and σ(μ) are nondecreasing in
μ, so μ is nondecreasing along the path and every share nondecreasing in σ — a monotone
filtration (caps only freeze shares: no leave, no uncapped), sensors entering in the order of
``η_i'(r_min,i)/b_i`` and capped in the order of ``η_i'(r_max,i)/b_i``. For coupled networks
``is_monotone`` (no share falls: no leave, no uncapped, no negative slope), ``is_filtration``
and ``diagonally_dominant`` (on the free set: it keeps the free shares growing, not a capped
sensor under its cap) are only checked along the path. In the paper's case the box is the
simplex itself and every number is computed exactly as without it.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import as_count, as_real, numerical_errors, require_attrs
from .._progress import Progress, ProgressArg
from ..errors import ConvergenceError, InvalidInputError, PathStallError
from ..limits import check_time_limit
from ..network import accepts_path
from .channel_box import ChannelBox, channel_box
from .continuation import trace_continuation
from .corrector import _Point, _Tracer
from .false_position import illinois
from .filtration_path import _Path
from .filtration_result import Filtration, FiltrationEvent
from .oracle import value_gradient, value_gradient_hessian
from .simplex import regularised_hessian, simplex_qp

__all__ = ["METHODS", "Filtration", "FiltrationEvent", "filtration"]

#: The path followers of :func:`filtration`: ``"continuation"`` (default; exact tangents, Hermite
#: predictors with second derivatives carried across breakpoints, events by Newton on the event
#: functions, false crossings of the event models tolerated, warm-started evaluations, longer
#: steps where no event is due, chord corrections in the warm starts, fewer products per solve
#: — :mod:`.continuation`), ``"continuation-v5"`` (the version before the leaner solves),
#: ``"continuation-v4"`` (the version before the chord corrections), ``"continuation-v3"`` (the
#: version before the longer steps), ``"continuation-v2"`` (the version before the warm starts,
#: kept for comparison), ``"continuation-v1"`` (its first version, kept for comparison: tangent-only
#: predictors after a breakpoint, false crossings failing the step in the paper's case) and
#: ``"reference"`` (the tangent-predictor tracer with events located by false position on
#: pointwise corrected solves, kept for comparison).
METHODS = (
    "continuation",
    "continuation-v5",
    "continuation-v4",
    "continuation-v3",
    "continuation-v2",
    "continuation-v1",
    "reference",
)
#: The continuation's versions (:func:`~.continuation.trace_continuation`) by method.
_VERSIONS = {
    "continuation": 6,
    "continuation-v5": 5,
    "continuation-v4": 4,
    "continuation-v3": 3,
    "continuation-v2": 2,
    "continuation-v1": 1,
}

F64 = npt.NDArray[np.float64]

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


def _locate(
    tracer: _Tracer,
    face: tuple[list[int], list[int]],
    left: _Point,
    right_sigma: float,
    which: int,
    tol_s: float,
    sign: float,
) -> _Point:
    """Finds σ* in (left.sigma, right_sigma] where ``sign·event[which]`` crosses from positive to
    non-positive (Illinois false position, bracket kept) and returns the corrected point there
    (``face``: the free and the capped sensors)."""
    active, capped = face

    def at(s: float) -> tuple[_Point, float]:
        ds = s - left.sigma
        gamma0, mu0 = left.gamma + ds * left.dgamma, left.mu + ds * left.dmu
        p = tracer.correct(active, s, gamma0, mu0, capped)
        return p, sign * float(tracer.events(active, p, capped)[which])

    a = left.sigma
    fa = max(sign * float(tracer.events(active, left, capped)[which]), 1e-300)
    pb, fb = at(right_sigma)
    return illinois(at, a, fa, right_sigma, fb, pb, tol_s)


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


def _leave_cap(p: _Point, active: list[int], h: float, lo: F64) -> float:
    """The step from ``p``: ``h``, shortened so that the tangent predictor keeps every active
    rate above ``r_min·(1 − _LEAVE_OVERSHOOT)`` (``lo``: each sensor's minimum). A falling
    share is thereby carried just past its leave point γ_i = 0 (where the event is detected and
    located) instead of being predicted to a negative rate, outside the domain of η."""
    jj = np.array(active, dtype=np.intp)
    falling = jj[p.dgamma[jj] < 0.0]
    if falling.size == 0:
        return h
    room = (p.gamma[falling] + _LEAVE_OVERSHOOT * lo[falling]) / -p.dgamma[falling]
    return float(min(h, np.min(room))) if np.min(room) > 0.0 else h


def _tied_start(net: Any, tied: list[int], r_min: F64, n: int) -> list[int]:
    """The sensors that leave r_min first when several tie for the most negative gradient at
    σ = 0. For small σ the optimum is ``σ·d*`` with ``d* = argmin ½dᵀ∇²η_TT d`` over the unit
    simplex on the tied set T (the linear term ``gᵀd = μ`` is the same for every such d); only
    the support of d* is active — a tied sensor with a negative tangent would go below r_min."""
    _, _, h = value_gradient_hessian(net, np.broadcast_to(r_min, (n,)).copy())
    tt = np.array(tied, dtype=np.intp)
    htt = regularised_hessian(h[np.ix_(tt, tt)])
    start = np.full(tt.size, 1.0 / tt.size)
    d = simplex_qp(htt, np.zeros(tt.size), start, 1.0, max_iter=20 * tt.size + 100)
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
    method: str = "continuation",
) -> Filtration:
    """Traces the optimal allocation map on ``[0, σ_max]`` with its breakpoints and active sets.

    Args:
        net: the network (``r_min``, ``sensors``, ``value_and_gradient``,
            ``value_gradient_hessian`` — a :class:`capalloc_rs.Network`).
        sigma_max: the largest σ = r_tot − N·r_min to trace to (> 0); with sample costs or
            rate limits σ = B − Σ b_i r_min,i in channel units, at most
            ``net.budget_range[1] − net.budget_range[0]`` (every sensor at its cap).
        tol: breakpoints are located to ``tol·max(σ_max, 1)``.
        max_nodes: budget of path nodes (default ``capalloc_rs.limits.FILTRATION_MAX_NODES``).
        time_limit: budget in seconds (default ``capalloc_rs.limits.FILTRATION_TIME_LIMIT``,
            ``None``: no limit), checked after every node.
        progress: ``None`` (a tqdm bar over σ on stderr if it is a terminal and tqdm is
            installed), ``True``/``False``, or a callable receiving ``{"sigma", "nodes",
            "active", "elapsed"}`` after every node.
        method: the path follower (:data:`METHODS`). ``"continuation"`` (default,
            :mod:`~capalloc_rs.allocation.continuation`): exact tangents, cubic Hermite
            predictors with step control from the predictor–corrector discrepancy, and every
            active-set change solved directly by Newton's method on the KKT system closed by its
            event function (``g_j = μ`` or ``γ_i = 0``, σ unknown) — to the corrector's precision,
            below ``tol``; a few times fewer evaluations of η than ``"reference"``. Its nodes meet
            ``g_J = μ1`` to 1e-13 relative, or are one last Newton step from a residual ≤ 1e-7
            reached superlinearly (the residual then about its square, or the rounding level of
            the gradient at very large rates, where the reference stalls; the node's tangent is
            then the one a step of relative size ≤ 1e-6 back). From 25 sensors on
            (:data:`~capalloc_rs.allocation.optimal.HVP_MIN_SENSORS`) the Hessian is formed only
            now and then, and ``diagonally_dominant`` is checked with the last one formed.
            After a breakpoint the predictors carry the second derivatives of the shares and
            event functions that keep their role (:mod:`~capalloc_rs.allocation.path_curvature`),
            and a crossing of a cubic event model that Newton does not find in the step, the
            function still positive at its end, is set aside as an artefact of the model (it
            stalled strongly coupled paths at σ = 0). Its evaluations of η are warm-started from
            the last one (from 8 sensors of order 2 on), and the last Newton step of a node is
            judged on the larger of the gradient's and the side condition's residuals, taken
            when they are predicted at 1e-12 after it (:mod:`~capalloc_rs.allocation.kkt_newton`).
            Where no event is due its steps grow up to ``σ_max/4``, and a step that would leave
            less than a quarter of itself before ``σ_max`` goes to ``σ_max``. From state order
            65 on each warm start first takes chord corrections on the last point's Schur form
            (:meth:`~capalloc_rs.network.CostPoint.warm` with ``chord_steps``), so that a point
            close to the last costs one Schur form. Its linear solves with Hessian-vector
            products take fewer products: the node tangents solved to 1e-7 relative (the
            tangent one last step back is no closer), a new face's preconditioner seeded with
            the old face's solves at the breakpoint, the first tangent solve of a Newton solve
            started from the predicted tangent; below state order 65 its warm starts end at the
            working-precision floor (``CostPoint.warm(r, compensated=False)``: without the
            double-double refinement, error bounds of 1e-11–4e-11 where the cold solve reports
            6e-12 and the refined warm start 1e-13). ``"continuation-v5"``: the version
            before these, kept for comparison (``benches/compare_scale.py``).
            ``"continuation-v4"``: the version before the chord corrections, kept for comparison.
            ``"continuation-v3"``: the version before the longer steps (up to ``σ_max/8``, a
            short last step kept), kept for comparison (``benches/compare_scale.py``).
            ``"continuation-v2"``: the version before the warm starts (cold evaluations below
            state order 64, the last step judged on the gradient's residual to 1e-13), kept for
            comparison (``benches/compare_scale.py``). ``"continuation-v1"``: the first version
            of the continuation (tangent-only predictors after a breakpoint; such a crossing
            fails the step in the paper's case), kept for comparison
            (``benches/compare_scale.py``). ``"reference"``: the original tracer (tangent
            predictor, events located by false position on pointwise corrected solves to
            ``tol``), kept for comparison (``benches/compare_filtration.py``).

    Hitting ``max_nodes`` or ``time_limit`` is not an error: the result covers ``[0, σ]`` up to
    where the path stopped, with ``converged=False`` and ``stopped`` naming the budget. Ctrl-C
    raises ``KeyboardInterrupt`` (between and inside the Rust evaluations).

    Step control (``"reference"``; ``"continuation"`` keeps the same failure contract, its steps
    are set by the discrepancy as described in its module): each path step is a tangent
    prediction corrected by Newton to the KKT system.
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
        InvalidInputError: ``method`` is not one of :data:`METHODS`, ``sigma_max`` lies beyond
            the feasible budgets (the message gives the largest feasible value), or another
            argument is out of range (named in the message).
    """
    require_attrs("net", net, "sensors", "r_min")
    if method not in METHODS:
        raise InvalidInputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
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
    box = channel_box(net)
    box.check_sigma_max(float(sigma_max))
    with Progress(progress, "filtration", total=float(sigma_max)) as bar:
        if method == "reference":
            return _trace(box, float(sigma_max), tol, int(node_budget), deadline, bar)
        return trace_continuation(
            box,
            float(sigma_max),
            tol,
            _start_set(box.net, len(box.lo), box.lo),
            (int(node_budget), deadline, _LEAVE_OVERSHOOT),
            bar,
            (_retry_step, _stall_error, _STALL_STEP * float(sigma_max)),
            version=_VERSIONS[method],
        )


def _start_set(net: Any, n: int, r_min: F64) -> tuple[list[int], float]:
    """The active set at σ = 0 (the sensor(s) with the most negative gradient at ``r_min``, one
    minimum per sensor) and that gradient, the multiplier μ(0)."""
    _, g0 = value_gradient(net, np.broadcast_to(r_min, (n,)).copy())
    gmin = float(np.min(g0))
    active = sorted(int(i) for i in np.flatnonzero(g0 <= gmin + 1e-12 * abs(gmin)))
    if len(active) > 1:
        active = _tied_start(net, active, r_min, n)
    return active, gmin


def _start(net: Any, tracer: _Tracer) -> tuple[list[int], _Point]:
    """The active set at σ = 0 and the corrected first node (reference tracer)."""
    active, gmin = _start_set(net, tracer.n, tracer.lo)
    return active, tracer.correct(active, 0.0, np.zeros(tracer.n), gmin)


def _budget_spent(nodes: int, max_nodes: int, deadline: float) -> str | None:
    """``"max_nodes"`` or ``"time_limit"`` when that budget is spent, else ``None``."""
    if nodes >= max_nodes:
        return "max_nodes"
    if time.monotonic() >= deadline:
        return "time_limit"
    return None


def _earliest(
    tracer: _Tracer,
    active: tuple[list[int], list[int]],
    p: _Point,
    s_new: float,
    crossings: tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]],
    tol_s: float,
) -> tuple[_Point, int]:
    """The earliest event in ``(p.sigma, s_new]`` among the event functions that went down
    (enter, leave, capped, uncapped, monotonicity lost) or up (monotonicity regained), located,
    with its index (``active``: the free and the capped sensors)."""
    down, up = crossings
    located = [(_locate(tracer, active, p, s_new, int(w), tol_s, +1.0), int(w)) for w in down]
    located += [(_locate(tracer, active, p, s_new, int(w), tol_s, -1.0), int(w)) for w in up]
    return min(located, key=lambda t: t[0].sigma)


class _Segment:
    """The reference tracer's current segment: free and capped sensors, the node ``p`` and the
    event functions there."""

    def __init__(self, tracer: _Tracer, active: list[int], p: _Point) -> None:
        self.tracer = tracer
        self.active, self.p = active, p
        self.capped: list[int] = []
        self.ev = tracer.events(active, p)
        self.done = False

    @property
    def face(self) -> tuple[list[int], list[int]]:
        """The free and the capped sensors."""
        return self.active, self.capped

    def kind(self, w: int) -> str:
        """What event function ``w`` (< N, or ≥ 2N: the cap block) reaching 0 means."""
        n = self.tracer.n
        if w >= 2 * n:
            return "cap"
        if w in self.active:
            return "leave"
        return "uncap" if w in self.capped else "enter"

    def change(self, path: _Path, loc: _Point, w: int) -> None:
        """Record the active-set change of event function ``w`` at ``loc`` and start the next
        segment there (or, when every free sensor is capped, from the least gradient of the
        sensors at their minimum; ``done`` when there is none)."""
        n = self.tracer.n
        sensor = w % n
        active, capped, gam = path.change(loc, self.kind(w), sensor, self.active, self.capped)
        mu = loc.mu
        if not active:
            lower = [i for i in range(n) if i not in capped]
            if not lower:
                self.done, self.p = True, loc
                return
            _, g = self.tracer.oracle.value_gradient(loc.gamma + self.tracer.lo)
            sensor = min(lower, key=lambda i: float(g[i]))
            mu = float(g[sensor])
            loc = replace(loc, mu=mu)  # μ jumps up to the entering sensor's gradient
            active, capped, gam = path.change(loc, "enter", sensor, [], capped)
        self.active, self.capped = active, capped
        self.p = self.tracer.correct(active, loc.sigma, gam, mu, capped)
        path.segment_start(self.p, active)
        self.ev = self.tracer.events(active, self.p, capped)
        # The sensor that just changed sits exactly on its event: it must move away first.
        self.ev[sensor] = 1e-300
        if self.ev.size > 2 * n:
            self.ev[2 * n + sensor] = 1.0


def _trace(
    box: ChannelBox, sigma_max: float, tol: float, max_nodes: int, deadline: float, bar: Progress
) -> Filtration:
    """The path following of :func:`filtration` (arguments checked)."""
    tracer = _Tracer(box.net, tol, box=box)
    n = tracer.n
    tol_s = tol * max(sigma_max, 1.0)
    active, p = _start(box.net, tracer)
    path = _Path(active, p, box.budget_min)
    seg = _Segment(tracer, active, p)
    h, h_max = sigma_max / 200.0, sigma_max / 40.0
    stopped = "completed"
    min_step = _STALL_STEP * sigma_max
    failures = 0  # consecutive corrector failures at p
    while seg.p.sigma < sigma_max and not seg.done:
        p = seg.p
        bar.update(p.sigma, sigma=p.sigma, nodes=len(path.nodes), active=len(seg.active))
        spent = _budget_spent(len(path.nodes), max_nodes, deadline)
        if spent is not None:
            stopped = spent
            break
        s_new = min(p.sigma + _leave_cap(p, seg.active, h, tracer.lo), sigma_max)
        ds = s_new - p.sigma
        try:
            q = tracer.correct(
                seg.active, s_new, p.gamma + ds * p.dgamma, p.mu + ds * p.dmu, seg.capped
            )
        except (ConvergenceError, np.linalg.LinAlgError):
            failures += 1
            retry = _retry_step(h, failures, min_step)
            if retry is None:
                raise _stall_error(tracer, p, sigma_max, ds, min_step, failures) from None
            h = retry
            continue
        failures = 0
        ev_new = tracer.events(seg.active, q, seg.capped)
        # enter, leave, capped, uncapped, monotonicity lost
        down = np.flatnonzero((seg.ev > 0) & (ev_new <= 0))
        up = n + np.flatnonzero((seg.ev[n : 2 * n] < 0) & (ev_new[n : 2 * n] >= 0))
        if down.size == 0 and up.size == 0:
            path.node(q)
            path.is_monotone &= bool(np.all(q.dgamma >= -1e-12))
            # Step control from the corrector's work.
            grow = 1.6 if q.iterations <= 2 else 0.7 if q.iterations >= 5 else 1.0
            h = min(max(h * grow, min_step), h_max)
            seg.p, seg.ev = q, ev_new
            continue
        loc, w = _earliest(tracer, seg.face, p, s_new, (down, up), tol_s)
        path.node(loc)
        if n <= w < 2 * n:  # a share's derivative changed sign: no active-set change
            lost = bool(w in down)
            path.monotonicity(loc, w - n, lost)
            seg.p = loc
            seg.ev = tracer.events(seg.active, loc, seg.capped)
            seg.ev[w] = -1e-300 if lost else 1e-300  # crossed: only the reverse can fire next
            continue
        seg.change(path, loc, w)
    # A budget stops the path at p: it covers [0, p.sigma].
    end = sigma_max if stopped == "completed" else seg.p.sigma
    return path.result(box, sigma_max, tol, stopped, end)
