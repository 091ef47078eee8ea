"""The sampled system at a finite period τ: exact periodic steady state of a concrete schedule.

**Model.** ``dx = A x dt + G dw`` (``Q = G Gᵀ``) is observed through a channel that carries a
budget of ``B`` channel units per period ``τ``; one unit lasts ``τ₀ = τ/B``. A sample of sensor
``i`` costs ``b_i`` units (``net.costs``, default 1): its slot lasts ``b_i τ₀`` and carries
``y = c̄_iᵀ x + v``, ``v ~ N(0, I)``. Over sensor ``i``'s slot the state moves by Van Loan's
discretisation, ``x ← E_i x + w``, ``E_i = e^{A b_i τ₀}``, ``w ~ N(0, H_i)``,
``H_i = ∫₀^{b_i τ₀} e^{As} Q e^{Aᵀs} ds`` (one pair per distinct cost). A schedule ``R_1 … R_L``
uses ``U = Σ_l b_{R_l} ≤ B`` units; the rest ``(B − U) τ₀`` of the period is *idle* channel time
at its end: a pure prediction (``E_T``, ``H_T`` over it), no update. ``budget`` (every function's
keyword) is ``B``; its default is ``U``, what the schedule uses (no idle time). With unit costs
``B`` is the paper's ``r_tot``, the number of slots: the paper's case is computed exactly as
before sample costs existed.

**Scaling (re-derived from the paper, eq. (barc)).** ``c̄_i = ĉ_i √τ`` with ``τ`` the *period* and
``ĉ_i`` the network's sensor matrix (a sample's noise does not depend on its length). One period
moves the covariance by ``τ[AΣ + ΣAᵀ − Σ W(k) Σ + Q] + O(τ²)`` with ``W(k) = Σ_i k_i ĉ_i ĉ_iᵀ``
and ``k_i`` the number of samples of sensor ``i`` per period — so the rates of the fast-sampling
cost ``η(r) = net.cost(r)`` are exactly the schedule's counts (``Σ b_i k_i ≤ B``, the budget of
the rates), and ``η̄(τ, R) → η(counts)`` as ``τ → 0`` with an ``O(τ)`` error (Corollary 1;
verified by the tests with observed order 1.0, with and without costs).

**Slot and period maps.** ``φ_i(S) = ((E_i S E_iᵀ + H_i)⁻¹ + c̄_i c̄_iᵀ)⁻¹`` maps the posterior
after one slot to the posterior after the next; ``Φ_R = T ∘ φ_{R_L} ∘ … ∘ φ_{R_1}`` with ``T`` the
idle tail (``T(S) = E_T S E_Tᵀ + H_T``, the identity without idle time).

**Conventions for η̄ (the paper's slot indexing is ambiguous).** With an error weight ``M``
(``net.error_weight``) every ``tr`` below is ``tr(M ·)``.

* ``which="boundary"`` (default, the paper's ``η̄(τ, R) = tr Σ(∞; τ, R)``): ``Σ(∞; τ, R)`` is the
  fixed point of ``Φ_R`` — the covariance at the period boundary: *just after the update of the
  last slot* ``R_L`` (and after the idle tail, if any). It depends on where the period starts
  (rotating a schedule changes it).
* ``which="average"``: ``(1/L) Σ_l tr Σ_l⁺``, the mean over the posterior covariances just after
  each slot's update. Invariant under rotation without idle time; the figure to use for a
  schedule that runs forever.

Both tend to ``η(counts)`` with first-order error; two orderings of the same counts differ by
``O(τ)`` at the boundary.

**Algorithm.** The Rust core writes each slot map as a Riccati triplet, composes the period by the
star product (the tail last), and doubles (``t ← t ⋆ t``) to ``Σ(∞; τ, R)`` in
``≈ log₂(periods)`` steps; the per-slot covariances follow from one pass of the slot maps (Joseph
form).

**Existence (Proposition 1).** The steady state exists and does not depend on ``Σ(0)`` if
``(A, [c̄_1 … c̄_N])`` is observable and ``τ ∈ 𝒯`` (no two distinct eigenvalues with
``e^{λ_iτ} = e^{λ_jτ}``). With ``check=True`` (default) violations raise
:class:`~capalloc_rs.errors.UnobservableError` / :class:`~capalloc_rs.errors.AliasingError`
before any number is computed. Both conditions are only sufficient; ``check=False`` skips them, and
then the doubling itself still reports a steady state that does not exist
(:class:`~capalloc_rs.errors.ConvergenceError`).

**Network objects.** Functions take a :class:`capalloc_rs.Network` or any object with attributes
``A``/``a`` (n×n), ``Q``/``q`` (or ``G``/``g``, with ``Q = G Gᵀ``), ``sensors`` (the full-size
``n × p_i`` matrices ``ĉ_i``, unit measurement noise), ``r_min`` (optional, default 0) and
optionally ``costs``, ``rate_min``, ``rate_max``, ``error_weight``
(:mod:`~capalloc_rs.sampled.channel`). A schedule must give every sensor between ``⌈r_min,i⌉``
and ``⌊r_max,i⌋`` samples and stay within the budget (:class:`~capalloc_rs.errors.ScheduleError`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .. import _core
from .._arrays import F64, as_count, as_matrix, as_real
from .._json import plain
from .._unchecked import warn_unchecked
from ..errors import AliasingError, InvalidInputError, UnobservableError
from ..network import accepts_path
from .channel import SampledSystem, _readonly, sampled_system
from .schedule import Schedule

__all__ = [
    "Which",
    "SampledSystem",
    "Discretisation",
    "SampledCovariance",
    "sampled_system",
    "as_schedule",
    "check_existence",
    "discretise",
    "period_triplet",
    "sampled_cost",
    "sampled_covariance",
    "propagate",
    "fixed_point_iteration",
]

Which = Literal["boundary", "average"]

#: Relative rank tolerance of the observability staircase.
OBSERVABILITY_RTOL = 1e-10
#: Aliasing tolerance in cycles: ``(λ_i − λ_j)τ/(2πi)`` within this of a nonzero integer.
ALIASING_TOL = 1e-8


def _check_tau(tau: float) -> float:
    t = as_real("tau", tau)
    if t <= 0:
        raise InvalidInputError(f"tau (the period) must be > 0, got {t}")
    return t


def as_schedule(
    m: SampledSystem,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    budget: float | None = None,
) -> Schedule:
    """Coerces ``schedule`` to a :class:`Schedule` over the model's ``N`` sensors and validates it
    (indices in range, every sensor between ``⌈r_min,i⌉`` and ``⌊r_max,i⌋`` samples, within
    ``budget`` channel units when given) — :class:`ScheduleError`."""
    s = schedule if isinstance(schedule, Schedule) else Schedule(schedule, m.n_sensors)
    if m.rate_min is None and m.rate_max is None and m.costs is None and budget is None:
        s.validate(m.n_sensors, m.r_min)
    else:
        r_min = m.r_min if m.rate_min is None else m.rate_min
        s.validate(m.n_sensors, r_min, costs=m.costs, budget=budget, r_max=m.rate_max)
    return s


def _check_budget(budget: float | None) -> float | None:
    """``None`` or a positive finite budget (channel units per period)."""
    if budget is None:
        return None
    b = as_real("budget", budget)
    if b <= 0:
        raise InvalidInputError(f"budget (channel units per period) must be > 0, got {b}")
    return b


@accepts_path
def check_existence(
    net: Any, tau: float, schedule: Schedule | Sequence[int] | npt.ArrayLike | None = None
) -> None:
    """Checks the hypotheses of Proposition 1 for a schedule (``None``: all sensors).

    * observability of ``(A, [c̄_i : i used by the schedule])`` — an orthogonal staircase rank test
      on ``span{C, AᵀC, …}`` with relative tolerance ``OBSERVABILITY_RTOL`` (``c̄_i = ĉ_i√τ``, the
      scaling does not matter);
    * ``τ ∈ 𝒯``: no distinct eigenvalues with ``(λ_i − λ_j)τ/(2πi)`` within ``ALIASING_TOL`` of a
      nonzero integer (always true when ``|Im λ_i − Im λ_j|·τ < 2π``).

    Raises:
        InvalidInputError, NonFiniteError: τ ≤ 0 or not finite.
        ScheduleError: the schedule names an unknown sensor or starves one.
        UnobservableError, AliasingError: a hypothesis of Proposition 1 fails.
    """
    m = sampled_system(net)
    t = _check_tau(tau)
    if schedule is None:
        used = list(range(m.n_sensors))
    else:
        s = as_schedule(m, schedule)
        used = sorted(set(s.slots))
    c = np.hstack([m.sensors[i] for i in used])
    dim = _core.sampled_unobservable_dimension(m.A, c, OBSERVABILITY_RTOL)
    if dim > 0:
        raise UnobservableError(
            f"(A, [c̄_i for i in {used}]) is not observable: the sensors the schedule uses leave an "
            f"unobservable subspace of dimension {dim} (Proposition 1 needs observability; rank "
            f"tolerance {OBSERVABILITY_RTOL:g})"
        )
    pair = _core.sampled_aliasing_pair(m.A, t, ALIASING_TOL)
    if pair is not None:
        raise AliasingError(
            f"tau = {t:g} is not in 𝒯: the eigenvalues {pair.first:.6g} and "
            f"{pair.second:.6g} of A alias (e^{{λ_i τ}} = e^{{λ_j τ}}; their imaginary parts "
            f"differ by a multiple of 2π/τ). Choose another τ, or pass check=False if you know the "
            f"slots within the period still observe these modes"
        )


@dataclass(frozen=True)
class Discretisation:
    """The slots of a period ``τ`` of ``r_tot`` channel units (the budget ``B``; for unit costs
    the number of slots): ``τ₀ = τ/r_tot``, one channel unit ``E = e^{Aτ₀}``,
    ``H = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds``, ``c̄_i = ĉ_i √τ``, and each sensor's slot of ``b_i``
    units, ``E_slots[i] = e^{A b_i τ₀}``, ``H_slots[i]`` (``r_tot`` is a float when it is not a
    whole number of units)."""

    tau: float
    r_tot: int | float
    tau0: float
    E: F64
    H: F64
    cbar: tuple[F64, ...]
    E_slots: tuple[F64, ...] = ()
    H_slots: tuple[F64, ...] = ()

    def __repr__(self) -> str:
        return f"Discretisation(tau={self.tau:g}, r_tot={self.r_tot:g}, n={self.E.shape[0]})"


@accepts_path
def discretise(net: Any, tau: float, r_tot: int | float) -> Discretisation:
    """Van Loan's discretisation of the slots of a period of ``r_tot`` channel units (see
    :class:`Discretisation`; an integer for unit costs as before, any positive budget ``B``
    otherwise)."""
    m = sampled_system(net)
    t = _check_tau(tau)
    if isinstance(r_tot, float) and not float(r_tot).is_integer():
        r: int | float = as_real("r_tot", r_tot, positive=True)
    else:
        r = as_count("r_tot", r_tot, minimum=1)
    d = m.core.discretise(t, r)
    ro = _readonly
    return Discretisation(
        t,
        r,
        t / r,
        ro(d.e),
        ro(d.h),
        tuple(ro(c) for c in d.cbar),
        tuple(ro(e) for e in d.es),
        tuple(ro(h) for h in d.hs),
    )


def _prepare(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    check: bool,
    budget: float | None = None,
) -> tuple[SampledSystem, float, Schedule, dict[str, Any]]:
    """The system, τ, the validated schedule and the core's keywords for ``budget``."""
    m = sampled_system(net)
    t = _check_tau(tau)
    b = _check_budget(budget)
    s = as_schedule(m, schedule, b)
    if check:
        check_existence(m, t, s)
    return m, t, s, ({} if b is None else {"budget": b})


@accepts_path
def period_triplet(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    *,
    budget: float | None = None,
) -> tuple[F64, F64, F64]:
    """The period map ``Φ_R(X) = H + A X (I + G X)⁻¹ Aᵀ`` as its triplet ``(A, G, H)`` (the star
    product of the slot triplets, then the idle tail; ``budget``: see the module docstring)."""
    m, t, s, kw = _prepare(net, tau, schedule, False, budget)
    tr = m.core.period_triplet(t, s.as_array(), **kw)
    return tr.a, tr.g, tr.h


@dataclass(frozen=True)
class SampledCovariance:
    """The periodic steady state of a schedule at period τ.

    Attributes:
        tau: the period.
        schedule: the schedule.
        boundary: ``Σ(∞; τ, R)``, the posterior covariance at the period boundary (just after the
            last slot's update); the fixed point of ``Φ_R``.
        posteriors: ``(r_tot, n, n)``: the posterior covariance just after slot ``l``'s update
            (``posteriors[-1]``, followed by the idle tail, reproduces ``boundary`` up to
            ``residual``).
        priors: ``(r_tot, n, n)``: the prior covariance of slot ``l`` (after its prediction).
        eta_boundary: ``tr Σ(∞; τ, R)`` — the paper's ``η̄(τ, R)`` (``tr(M Σ)`` with a weight).
        eta_average: ``(1/r_tot) Σ_l tr posteriors[l]`` (``tr(M ·)`` with a weight).
        doubling_steps: doubling steps (the last one composes ``2^steps`` periods).
        rel_change: the doubling's last relative change of ``H``.
        spectral_radius: of the closed-loop monodromy at the steady state (``< 1``).
        residual: ``‖Φ_R(Σ) − Σ‖_F/‖Σ‖_F`` evaluated slot by slot.
        idle: the idle channel units at the end of the period (``budget − Σ_l b_{R_l}``).
        tail: ``(E_T, H_T)``, the prediction over the idle time (``(I, 0)`` without idle).
    """

    tau: float
    schedule: Schedule
    boundary: F64
    posteriors: F64
    priors: F64
    eta_boundary: float
    eta_average: float
    doubling_steps: int
    rel_change: float
    spectral_radius: float
    residual: float
    idle: float = 0.0
    tail: tuple[F64, F64] | None = None

    def eta(self, which: Which = "boundary") -> float:
        """``eta_boundary`` or ``eta_average``."""
        return _pick(which, self.eta_boundary, self.eta_average)

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain JSON-ready values: ``schedule`` as its list of slots, the
        covariances as nested lists (non-finite numbers as ``None``).

        Returns:
            ``{"tau", "schedule", "boundary", "posteriors", "priors", "eta_boundary",
            "eta_average", "doubling_steps", "rel_change", "spectral_radius", "residual",
            "idle"}``.
        """
        out: dict[str, Any] = plain(
            {
                "tau": self.tau,
                "schedule": list(self.schedule.slots),
                "boundary": self.boundary,
                "posteriors": self.posteriors,
                "priors": self.priors,
                "eta_boundary": self.eta_boundary,
                "eta_average": self.eta_average,
                "doubling_steps": self.doubling_steps,
                "rel_change": self.rel_change,
                "spectral_radius": self.spectral_radius,
                "residual": self.residual,
                "idle": self.idle,
            }
        )
        return out

    def __repr__(self) -> str:
        return (
            f"SampledCovariance(tau={self.tau:g}, r_tot={self.schedule.r_tot}, "
            f"eta_boundary={self.eta_boundary:.6g}, eta_average={self.eta_average:.6g}, "
            f"spectral_radius={self.spectral_radius:.3g})"
        )


def _pick(which: str, boundary: float, average: float) -> float:
    if which == "boundary":
        return boundary
    if which == "average":
        return average
    raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")


@accepts_path
def sampled_covariance(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    *,
    check: bool = True,
    tol: float = 1e-12,
    max_steps: int = 64,
    budget: float | None = None,
) -> SampledCovariance:
    """The periodic steady state ``Σ(∞; τ, R)`` and the covariances of every slot.

    Doubling of the period triplet until ``‖H_{k+1} − H_k‖_F ≤ tol·‖H_{k+1}‖_F`` (quadratic
    convergence: the result is accurate to rounding), at most ``max_steps`` steps. ``budget``:
    the channel units ``B`` of the period (default: what the schedule uses; for unit costs the
    number of slots) — the rest of the period after the schedule's samples is idle.

    Raises:
        ScheduleError, InvalidInputError, NonFiniteError: bad schedule, τ or budget (a schedule
            above the budget is a ScheduleError).
        UnobservableError, AliasingError: Proposition 1's hypotheses fail (with ``check=True``).
        ConvergenceError: the steady state does not exist (the covariance grows without bound, or
            the limit reached from Σ = 0 is not stabilising).
    """
    m, t, s, kw = _prepare(net, tau, schedule, check, budget)
    ss = m.core.steady_state(
        t,
        s.as_array(),
        as_real("tol", tol, positive=True),
        as_count("max_steps", max_steps, minimum=1),
        **kw,
    )
    if m.weight is None:
        eta_b = float(np.trace(ss.boundary))
        eta_a = float(np.trace(ss.posteriors, axis1=1, axis2=2).mean())
    else:
        eta_b = m.trace(ss.boundary)
        eta_a = float(np.einsum("ij,lij->l", m.weight, ss.posteriors).mean())
    tail = None if ss.idle == 0.0 else (_readonly(ss.tail_e), _readonly(ss.tail_h))
    return SampledCovariance(
        t,
        s,
        _readonly(ss.boundary),
        _readonly(ss.posteriors),
        _readonly(ss.priors),
        eta_b,
        eta_a,
        ss.steps,
        ss.rel_change,
        ss.spectral_radius,
        ss.residual,
        float(ss.idle),
        tail,
    )


@accepts_path
def sampled_cost(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    which: Which = "boundary",
    *,
    check: bool = True,
    tol: float = 1e-12,
    max_steps: int = 64,
    budget: float | None = None,
) -> float:
    """``η̄(τ, R)``: ``tr Σ(∞; τ, R)`` at the period boundary (``which="boundary"``, the paper's
    definition) or ``(1/r_tot) Σ_l tr Σ_l⁺`` averaged over the posteriors after each slot
    (``which="average"``); ``tr(M ·)`` for a network with an error weight ``M``. ``budget``: the
    channel units ``B`` per period (default: what the schedule uses, for unit costs its number
    of slots ``r_tot``; both coincide in the paper's case). See the module docstring for the
    conventions and :func:`sampled_covariance` for errors."""
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    if not check:
        warn_unchecked()
    m, t, s, kw = _prepare(net, tau, schedule, check, budget)
    return float(
        m.core.cost(
            t,
            s.as_array(),
            which,
            as_real("tol", tol, positive=True),
            as_count("max_steps", max_steps, minimum=1),
            **kw,
        )
    )


@accepts_path
def propagate(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    sigma0: Any,
    *,
    budget: float | None = None,
) -> tuple[F64, F64]:
    """One period of slot maps from the posterior ``sigma0``: ``(priors, posteriors)``, each
    ``(r_tot, n, n)``; ``posteriors[-1] = Φ_R(sigma0)`` without idle time (with idle time the
    tail's prediction follows it)."""
    m, t, s, kw = _prepare(net, tau, schedule, False, budget)
    prop = m.core.propagate(t, s.as_array(), as_matrix("sigma0", sigma0), **kw)
    return prop.priors, prop.posteriors


@accepts_path
def fixed_point_iteration(
    net: Any,
    tau: float,
    schedule: Schedule | Sequence[int] | npt.ArrayLike,
    sigma0: Any = None,
    *,
    tol: float = 1e-14,
    max_periods: int = 10_000_000,
    budget: float | None = None,
) -> tuple[F64, int]:
    """The plain iteration ``Σ_{k+1} = Φ_R(Σ_k)`` (in Rust, slot by slot, Joseph form, then the
    idle tail) from ``sigma0`` (default 0) until ``‖Σ_{k+1} − Σ_k‖_F ≤ tol·‖Σ_{k+1}‖_F``:
    ``(Σ, periods)``. A reference for :func:`sampled_covariance`; it needs ``O(1/(1 − ρ))``
    periods."""
    m, t, s, kw = _prepare(net, tau, schedule, False, budget)
    s0 = np.zeros((m.n, m.n)) if sigma0 is None else as_matrix("sigma0", sigma0)
    fp = m.core.fixed_point(
        t,
        s.as_array(),
        s0,
        as_real("tol", tol, positive=True),
        as_count("max_periods", max_periods, minimum=1),
        **kw,
    )
    return fp.sigma, int(fp.periods)
