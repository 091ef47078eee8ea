"""Monte Carlo validation of the sampled system: simulate the stochastic system slot by slot with
the periodic (steady-state) Kalman filter and measure its mean squared error.

The state moves exactly over each slot (``x ← E_i x + w``, ``w ~ N(0, H_i)``, Van Loan over the
slot's length ``b_i τ₀``, :mod:`~capalloc_rs.sampled.system`); sensor
``i = R_l`` measures ``y = c̄_iᵀ x + v``, ``v ~ N(0, I)``; the filter predicts ``x̂ ← E_i x̂`` and
updates ``x̂ ← x̂ + K_l (y − c̄_iᵀ x̂)`` with the periodic gains ``K_l = P_l c̄_i (I + c̄_iᵀ P_l c̄_i)⁻¹``
(``P_l`` the steady-state prior of slot ``l`` from :func:`~capalloc_rs.sampled.sampled_covariance`).
Idle channel time at the end of the period (a budget above what the schedule uses) is one more
prediction ``x ← E_T x + w``, ``w ~ N(0, H_T)``, without a measurement. With an error weight ``M``
every ``|e|²`` below is ``eᵀ M e``.

The error ``e = x − x̂`` then obeys ``e ← E e + w`` and ``e ← e − K_l (c̄_iᵀ e + v)``. By default only
this recursion is simulated: with the same noise draws it is *identical* to simulating ``x`` and
``x̂`` and subtracting (linearity), but it stays bounded when ``A`` is unstable, where ``x`` itself
would overflow over long horizons. ``track_state=True`` simulates ``x`` and ``x̂`` explicitly.

Each of ``runs`` independent replications starts in the stationary regime (``e ~ N(0, Σ(∞; τ, R))``
at a period boundary, optionally followed by ``burn_in`` periods) and averages ``|e|²`` over
``periods`` periods; the replication means are i.i.d., so their mean and Student-t interval give
the empirical MSE and its confidence interval.

A ``time_limit`` is checked before every period (all runs advance together, vectorised): when it is
hit, the estimate uses the periods completed so far (``periods_completed < periods``,
``stopped="time_limit"``) — still ``runs`` i.i.d. replication means, each over fewer periods — or,
if none was completed, is NaN.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import F64, MAX_SEED, as_count, as_real, numerical_errors
from .._json import plain
from .._progress import Progress, ProgressArg
from .._unchecked import warn_unchecked
from ..errors import InvalidInputError
from ..limits import check_time_limit
from ..network import accepts_path
from .schedule import Schedule
from .system import (
    Discretisation,
    SampledSystem,
    Which,
    discretise,
    sampled_covariance,
    sampled_system,
)

__all__ = ["MonteCarloResult", "simulate", "t_quantile"]


@dataclass(frozen=True)
class MonteCarloResult:
    """Empirical mean squared error of the periodic Kalman filter.

    Attributes:
        mse: the empirical MSE under ``which`` — mean of ``|e|²`` (``eᵀ M e`` for a network with
            an error weight ``M``: the estimate of ``tr(M Σ̄)``) at the period boundaries
            (``"boundary"``) or over the posteriors after every slot (``"average"``).
        ci_low, ci_high: the two-sided ``level`` confidence interval (Student t over the
            replication means).
        stderr: the standard error of ``mse``.
        level: the confidence level.
        predicted: ``η̄(τ, R)`` under ``which`` from the exact steady state, for comparison.
        per_slot: ``(r_tot,)`` empirical mean of ``|e|²`` after each slot's update.
        runs, periods, burn_in, seed, which: the settings (``periods`` as requested).
        stopped: ``"completed"``, or ``"time_limit"`` when the time budget ended the simulation
            early.
        periods_completed: the recorded periods the estimate is over (``periods`` unless
            stopped; 0 — and every estimate NaN — if the budget ran out before the first).
    """

    mse: float
    ci_low: float
    ci_high: float
    stderr: float
    level: float
    predicted: float
    per_slot: F64
    runs: int
    periods: int
    burn_in: int
    seed: int | None
    which: str
    stopped: str = "completed"
    periods_completed: int = -1

    def __post_init__(self) -> None:
        if self.periods_completed < 0:  # constructed without it: everything was simulated
            object.__setattr__(self, "periods_completed", self.periods)

    @property
    def converged(self) -> bool:
        """``True`` if every requested period was simulated."""
        return self.stopped == "completed"

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the confidence interval."""
        return self.ci_low <= value <= self.ci_high

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (NaN, e.g. with no period simulated, as
        ``None``): the keys of the CLI's ``--json`` (``"ci"`` is ``[ci_low, ci_high]``,
        ``"predicted_in_ci"`` is :meth:`contains` of ``predicted``) and the other fields.

        Returns:
            ``{"mse", "ci", "level", "predicted", "predicted_in_ci", "runs", "periods",
            "periods_completed", "seed", "ci_low", "ci_high", "stderr", "per_slot", "burn_in",
            "which", "stopped", "converged"}``.
        """
        out: dict[str, Any] = plain(
            {
                "mse": self.mse,
                "ci": [self.ci_low, self.ci_high],
                "level": self.level,
                "predicted": self.predicted,
                "predicted_in_ci": bool(self.contains(self.predicted)),
                "runs": self.runs,
                "periods": self.periods,
                "periods_completed": self.periods_completed,
                "seed": self.seed,
                "ci_low": self.ci_low,
                "ci_high": self.ci_high,
                "stderr": self.stderr,
                "per_slot": self.per_slot,
                "burn_in": self.burn_in,
                "which": self.which,
                "stopped": self.stopped,
                "converged": self.converged,
            }
        )
        return out

    def __repr__(self) -> str:
        return (
            f"MonteCarloResult(mse={self.mse:.6g}, ci=[{self.ci_low:.6g}, {self.ci_high:.6g}], "
            f"predicted={self.predicted:.6g}, runs={self.runs}, "
            f"periods={self.periods_completed}/{self.periods}, stopped={self.stopped!r})"
        )


def t_quantile(p: float, df: int) -> float:
    """Quantile of Student's t with ``df`` degrees of freedom by the Cornish–Fisher expansion
    around the normal quantile (Abramowitz & Stegun 26.7.5; error < 1e-3 for df ≥ 5)."""
    if df < 1:
        raise InvalidInputError(f"df must be >= 1, got {df}")
    z = NormalDist().inv_cdf(p)
    g1 = (z**3 + z) / 4
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
    g4 = (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160
    v = float(df)
    return z + g1 / v + g2 / v**2 + g3 / v**3 + g4 / v**4


def _psd_sqrt(m: F64) -> F64:
    """``L`` with ``L Lᵀ = m`` for symmetric positive semidefinite ``m`` (eigendecomposition, so
    singular ``m`` is fine)."""
    w, v = np.linalg.eigh((m + m.T) / 2)
    return np.asarray(v * np.sqrt(np.clip(w, 0.0, None)), dtype=np.float64)


@accepts_path
@numerical_errors
def simulate(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    periods: int,
    seed: int | None = None,
    *,
    runs: int = 32,
    which: Which = "boundary",
    level: float = 0.95,
    burn_in: int = 0,
    track_state: bool = False,
    check: bool = True,
    time_limit: float | None = None,
    progress: ProgressArg = None,
    budget: float | None = None,
) -> MonteCarloResult:
    """Monte Carlo estimate of the filter's MSE, vectorised over ``runs`` replications.

    Deterministic for a given ``seed`` (``numpy.random.default_rng(seed)``). See the module
    docstring for the model, the filter and the interval.

    ``time_limit`` (seconds, ``None``: no limit) covers the whole call and is checked before every
    period (burn-in included); hitting it is not an error: the result says
    ``stopped="time_limit"`` and is over the ``periods_completed`` recorded periods. ``progress``:
    ``None`` (a tqdm bar over periods on stderr if it is a terminal and tqdm is installed),
    ``True``/``False``, or a callable receiving ``{"period", "elapsed"}`` after every period.
    ``budget``: the channel units per period (default what the schedule uses; see
    :func:`~capalloc_rs.sampled.sampled_covariance`).

    Raises:
        InvalidInputError: ``periods < 1``, ``runs < 2``, ``level`` outside (0, 1), bad ``which``,
            a negative ``seed``, a ``time_limit`` that is not positive seconds, or more work than
            ``limits.MAX_MONTE_CARLO_STEPS`` (``runs × (burn_in + periods) × slots``) or memory than
            ``limits.MAX_MONTE_CARLO_ELEMENTS`` (``runs × (n + slots)``).
        UnobservableError, AliasingError, ScheduleError, ConvergenceError: as
            :func:`capalloc_rs.sampled_covariance` (the existence check and the steady state).
    """
    started = time.monotonic()
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    seconds = check_time_limit(time_limit)
    deadline = math.inf if seconds is None else started + seconds
    periods = as_count("periods", periods, minimum=1)
    runs = as_count("runs", runs, minimum=2)
    burn_in = as_count("burn_in", burn_in)
    level = as_real("level", level)
    if not 0.0 < level < 1.0:
        raise InvalidInputError(f"level must be in (0, 1), got {level}")
    if seed is not None:
        seed = as_count("seed", seed, maximum=MAX_SEED)
    if not check:
        warn_unchecked()
    cov = sampled_covariance(net, tau, schedule, check=check, budget=budget)
    m = sampled_system(net)
    sched = cov.schedule
    steps = runs * (burn_in + periods) * sched.r_tot
    if steps > limits.MAX_MONTE_CARLO_STEPS:
        raise InvalidInputError(
            f"runs × (burn_in + periods) × slots = {runs} × {burn_in + periods} × {sched.r_tot} "
            f"= {steps} simulated steps, more than capalloc_rs.limits.MAX_MONTE_CARLO_STEPS = "
            f"{limits.MAX_MONTE_CARLO_STEPS}"
        )
    held = runs * (cov.boundary.shape[0] + sched.r_tot)
    if held > limits.MAX_MONTE_CARLO_ELEMENTS:
        raise InvalidInputError(
            f"runs = {runs} needs {held} values in memory at once (runs × (n + slots)), more than "
            f"capalloc_rs.limits.MAX_MONTE_CARLO_ELEMENTS = {limits.MAX_MONTE_CARLO_ELEMENTS}"
        )
    d = _discretisation(m, tau, sched, budget)
    slot_steps = _slot_steps(d, sched, cov)
    n = d.E.shape[0]
    gains = []
    for pos, i in enumerate(sched.slots):
        p = cov.priors[pos]
        c = d.cbar[i]
        s = np.eye(c.shape[1]) + c.T @ p @ c
        gains.append(np.linalg.solve(s, (p @ c).T).T)  # K = P c̄ S⁻¹
    kts = [k.T for k in gains]
    cbars = [d.cbar[i] for i in sched.slots]

    rng = np.random.default_rng(seed)
    e = rng.standard_normal((runs, n)) @ _psd_sqrt(cov.boundary).T
    x = np.zeros((runs, n))
    xhat = np.zeros((runs, n))
    if track_state:
        x = e.copy()  # x̂ = 0, x ~ N(0, Σ(∞)): the same stationary error
    boundary_sum = np.zeros(runs)
    slot_sum = np.zeros((runs, sched.r_tot))
    stopped = "completed"
    done = 0  # recorded periods completed
    with Progress(progress, "Monte Carlo", total=burn_in + periods) as bar:
        for k in range(burn_in + periods):
            if time.monotonic() >= deadline:
                stopped = "time_limit"
                break
            record = k >= burn_in
            e, x, xhat = _period(
                e, x, xhat, rng, slot_steps, cbars, kts, slot_sum, record, track_state, m.weight
            )
            if record:
                boundary_sum += _sq(e, m.weight)
                done += 1
            bar.update(k + 1, period=k + 1)
    with np.errstate(invalid="ignore", divide="ignore"):  # done = 0: NaN estimates
        per_run = boundary_sum / done if which == "boundary" else slot_sum.mean(axis=1) / done
        mse = float(per_run.mean())
        stderr = float(per_run.std(ddof=1) / math.sqrt(runs))
        per_slot = slot_sum.mean(axis=0) / done
    half = t_quantile(0.5 + level / 2, runs - 1) * stderr
    per_slot.setflags(write=False)
    return MonteCarloResult(
        mse=mse,
        ci_low=mse - half,
        ci_high=mse + half,
        stderr=stderr,
        level=level,
        predicted=cov.eta(which),
        per_slot=per_slot,
        runs=runs,
        periods=periods,
        burn_in=burn_in,
        seed=seed,
        which=which,
        stopped=stopped,
        periods_completed=done,
    )


def _sq(e: F64, weight: F64 | None) -> F64:
    """``|e|²`` per run (``eᵀ M e`` with a weight)."""
    if weight is None:
        return np.asarray(np.einsum("ij,ij->i", e, e), dtype=np.float64)
    return np.asarray(np.einsum("ij,jk,ik->i", e, weight, e), dtype=np.float64)


#: Per slot ``(Eᵀ, L_Hᵀ)`` (``L_H L_Hᵀ = H``), and the idle tail's pair last (or ``None``).
_Steps = tuple[list[tuple[F64, F64]], tuple[F64, F64] | None]


def _discretisation(
    m: SampledSystem, tau: float, sched: Schedule, budget: float | None
) -> Discretisation:
    """The slots of the period: of ``r_tot`` slots in the paper's case, else of the budget
    (default what the schedule uses)."""
    if budget is None and m.costs is None:
        return discretise(m, tau, sched.r_tot)
    return discretise(m, tau, float(sched.budget_used(m.costs) if budget is None else budget))


def _slot_steps(d: Discretisation, sched: Schedule, cov: Any) -> _Steps:
    """The transitions and noise factors of every slot (one per sensor, shared) and of the idle
    tail."""
    per_sensor: dict[int, tuple[F64, F64]] = {}
    for i in sorted(set(sched.slots)):
        per_sensor[i] = (d.E_slots[i].T, _psd_sqrt(d.H_slots[i]).T)
    tail = None if cov.tail is None else (cov.tail[0].T, _psd_sqrt(cov.tail[1]).T)
    return [per_sensor[i] for i in sched.slots], tail


def _period(
    e: F64,
    x: F64,
    xhat: F64,
    rng: np.random.Generator,
    steps: _Steps,
    cbars: list[F64],
    kts: list[F64],
    slot_sum: F64,
    record: bool,
    track_state: bool,
    weight: F64 | None,
) -> tuple[F64, F64, F64]:
    """One period of every run, slot by slot (adds ``|e|²`` after each update to ``slot_sum``
    when ``record``), then the idle tail; returns the new ``e, x, x̂``."""
    runs, n = e.shape
    for pos, (c, kt) in enumerate(zip(cbars, kts, strict=True)):
        et, lht = steps[0][pos]
        w = rng.standard_normal((runs, n)) @ lht
        v = rng.standard_normal((runs, c.shape[1]))
        if track_state:
            x = x @ et + w
            y = x @ c + v
            xhat = xhat @ et
            xhat = xhat + (y - xhat @ c) @ kt
            e = x - xhat
        else:
            e = e @ et + w
            e = e - (e @ c + v) @ kt
        if record:
            slot_sum[:, pos] += _sq(e, weight)
    if steps[1] is not None:
        et, lht = steps[1]
        w = rng.standard_normal((runs, n)) @ lht
        if track_state:
            x = x @ et + w
            xhat = xhat @ et
            e = x - xhat
        else:
            e = e @ et + w
    return e, x, xhat
