"""The sampled system at a finite period τ: exact periodic steady state of a concrete schedule.

**Model.** ``dx = A x dt + G dw`` (``Q = G Gᵀ``) is observed through a channel with ``r_tot`` slots
per period ``τ``. Slot ``l`` lasts ``τ₀ = τ/r_tot`` and carries one sample of sensor ``R_l``:
``y = c̄_{R_l}ᵀ x + v``, ``v ~ N(0, I)``. Over a slot the state moves by Van Loan's discretisation,
``x ← E x + w``, ``E = e^{Aτ₀}``, ``w ~ N(0, H)``, ``H = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds``.

**Scaling (re-derived from the paper, eq. (barc)).** ``c̄_i = ĉ_i √τ`` with ``τ`` the *period* and
``ĉ_i`` the network's sensor matrix. One period then moves the covariance by
``τ[AΣ + ΣAᵀ − Σ W(r) Σ + Q] + O(τ²)`` with ``W(r) = Σ_i r_i ĉ_i ĉ_iᵀ`` and ``r_i`` the number of
slots of sensor ``i`` per period — so the rates of the fast-sampling cost ``η(r) = net.cost(r)`` are
exactly the schedule's counts, and ``η̄(τ, R) → η(counts)`` as ``τ → 0`` with an ``O(τ)`` error
(Corollary 1; verified by the tests with observed order 1.0): the convention of docs/concepts.md.

**Slot and period maps.** ``φ_i(S) = ((E S Eᵀ + H)⁻¹ + c̄_i c̄_iᵀ)⁻¹`` maps the posterior covariance
after one slot to the posterior after the next; ``Φ_R = φ_{R_{r_tot}} ∘ … ∘ φ_{R_1}``.

**Conventions for η̄ (the paper's slot indexing is ambiguous).**

* ``which="boundary"`` (default, the paper's ``η̄(τ, R) = tr Σ(∞; τ, R)``): ``Σ(∞; τ, R)`` is the
  fixed point of ``Φ_R`` — the posterior covariance at the period boundary, *just after the update
  of the last slot* ``R_{r_tot}``. It depends on where the period starts (rotating a schedule
  changes it).
* ``which="average"``: ``(1/r_tot) Σ_l tr Σ_l⁺``, the mean over the posterior covariances just after
  each slot's update. Invariant under rotation; the figure to use for a schedule that runs forever.

Both tend to ``η(counts)`` with first-order error; two orderings of the same counts differ by
``O(τ)`` at the boundary.

**Algorithm.** The Rust core writes each slot map as a Riccati triplet, composes the period by the
star product, and doubles (``t ← t ⋆ t``) to ``Σ(∞; τ, R)`` in ``≈ log₂(periods)`` steps; the
per-slot covariances follow from one pass of the slot maps (Joseph form).

**Existence (Proposition 1).** The steady state exists and does not depend on ``Σ(0)`` if
``(A, [c̄_1 … c̄_N])`` is observable and ``τ ∈ 𝒯`` (no two distinct eigenvalues with
``e^{λ_iτ} = e^{λ_jτ}``). With ``check=True`` (default) violations raise
:class:`~capalloc_rs.errors.UnobservableError` / :class:`~capalloc_rs.errors.AliasingError`
before any number is computed. Both conditions are only sufficient; ``check=False`` skips them, and
then the doubling itself still reports a steady state that does not exist
(:class:`~capalloc_rs.errors.ConvergenceError`).

**Network objects.** Functions take a :class:`capalloc_rs.Network` or any object with attributes
``A``/``a`` (n×n), ``Q``/``q`` (or ``G``/``g``, with ``Q = G Gᵀ``), ``sensors`` (the full-size
``n × p_i`` matrices ``ĉ_i``, unit measurement noise) and ``r_min`` (optional, default 0).
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
from ..errors import (
    AliasingError,
    FeatureUnavailableError,
    InvalidInputError,
    ShapeError,
    UnobservableError,
)
from ..network import accepts_path, require_paper_form
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


def _readonly(a: F64) -> F64:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class SampledSystem:
    """A network's raw matrices for the sampled system: ``A``, ``Q = G Gᵀ``, the sensors ``ĉ_i``
    and ``r_min``, validated once (build it with :func:`sampled_system`).

    It carries the same validated system in Rust (:attr:`core`, a ``_core.SampledModel``, which
    has no ``r_min`` and does not pickle); this wrapper adds ``r_min`` and pickling."""

    A: F64
    Q: F64
    sensors: tuple[F64, ...]
    r_min: float

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def n_sensors(self) -> int:
        """Number of sensors ``N``."""
        return len(self.sensors)

    @property
    def core(self) -> _core.SampledModel:
        """The system validated once in Rust (built on first use, then kept with this object):
        the sampled functions and the schedule search evaluate through it, so a search converts
        and checks ``(A, Q, sensors)`` once rather than for every candidate schedule."""
        core = self.__dict__.get("_core_model")
        if core is None:
            core = _core.SampledModel(self.A, self.Q, list(self.sensors))
            object.__setattr__(self, "_core_model", core)
        return core

    def __getstate__(self) -> dict[str, Any]:
        # The Rust model is rebuilt on first use after unpickling (it does not pickle).
        return {k: v for k, v in self.__dict__.items() if k != "_core_model"}

    def __repr__(self) -> str:
        return f"SampledSystem(n={self.n}, n_sensors={self.n_sensors}, r_min={self.r_min:g})"


def _attr(net: Any, *names: str) -> Any:
    """The first of ``names`` that ``net`` has (``None`` if none)."""
    for name in names:
        v = getattr(net, name, None)
        if v is not None:
            return v
    return None


def sampled_system(net: Any) -> SampledSystem:
    """The :class:`SampledSystem` of a network object (a :class:`SampledSystem` passes through).

    Duck-typed: ``A`` or ``a``; ``Q``/``q`` or else ``G``/``g`` (``Q = G Gᵀ``); ``sensors``;
    ``r_min`` (default 0) — :class:`capalloc_rs.Network` has all of them.

    Raises:
        InvalidInputError: ``net`` lacks ``A`` or ``sensors``, or both ``Q`` and ``G``.
        ShapeError: the matrices do not fit together, or there is no sensor.
        FeatureUnavailableError: the network has an error weight (``error_weight``): the sampled
            figures are plain traces in this version, never silently so for a weighted network.
    """
    if isinstance(net, SampledSystem):
        return net
    if getattr(net, "error_weight", None) is not None:
        raise FeatureUnavailableError(
            "the sampled functions (sampled cost, schedules, Monte Carlo) do not support a "
            "weighted error tr(M Σ) in this version: the network has an error weight"
        )
    require_paper_form(net, "the sampled system")
    a_raw = _attr(net, "A", "a")
    sensors_raw = _attr(net, "sensors")
    if a_raw is None or sensors_raw is None:
        raise InvalidInputError(
            f"the network must have attributes A (or a) and sensors, got {type(net).__name__}"
        )
    a = as_matrix("net.A", a_raw)
    q_raw = _attr(net, "Q", "q")
    if q_raw is None:
        g_raw = _attr(net, "G", "g")
        if g_raw is None:
            raise InvalidInputError("the network must have an attribute Q (= G Gᵀ) or G")
        g = as_matrix("net.G", g_raw)
        q = g @ g.T
    else:
        q = as_matrix("net.Q", q_raw)
    n = a.shape[0]
    if a.shape != (n, n) or q.shape != (n, n):
        raise ShapeError(f"A and Q must be n×n with the same n, got {a.shape} and {q.shape}")
    sensors = []
    for i, c in enumerate(list(sensors_raw)):
        ci = np.asarray(c, dtype=np.float64)
        if ci.ndim == 1:
            ci = ci.reshape(-1, 1)
        ci = as_matrix(f"sensor {i}", ci)
        if ci.shape[0] != n or ci.shape[1] == 0:
            raise ShapeError(f"sensor {i} must be n×p with n = {n}, p >= 1, got {ci.shape}")
        sensors.append(_readonly(np.array(ci)))
    if not sensors:
        raise ShapeError("the network has no sensors")
    r_min = float(getattr(net, "r_min", 0.0))
    return SampledSystem(_readonly(np.array(a)), _readonly(np.array(q)), tuple(sensors), r_min)


def _check_tau(tau: float) -> float:
    t = as_real("tau", tau)
    if t <= 0:
        raise InvalidInputError(f"tau (the period) must be > 0, got {t}")
    return t


def as_schedule(m: SampledSystem, schedule: Schedule | Sequence[int] | npt.ArrayLike) -> Schedule:
    """Coerces ``schedule`` to a :class:`Schedule` over the model's ``N`` sensors and validates it
    (indices in range, every sensor at least ``⌈r_min⌉`` slots) — :class:`ScheduleError`."""
    s = schedule if isinstance(schedule, Schedule) else Schedule(schedule, m.n_sensors)
    s.validate(m.n_sensors, m.r_min)
    return s


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
    """One slot of a period ``τ`` with ``r_tot`` slots: ``τ₀ = τ/r_tot``, ``E = e^{Aτ₀}``,
    ``H = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds``, ``c̄_i = ĉ_i √τ``."""

    tau: float
    r_tot: int
    tau0: float
    E: F64
    H: F64
    cbar: tuple[F64, ...]

    def __repr__(self) -> str:
        return f"Discretisation(tau={self.tau:g}, r_tot={self.r_tot}, n={self.E.shape[0]})"


@accepts_path
def discretise(net: Any, tau: float, r_tot: int) -> Discretisation:
    """Van Loan's discretisation of one slot (see :class:`Discretisation`)."""
    m = sampled_system(net)
    t = _check_tau(tau)
    r = as_count("r_tot", r_tot, minimum=1)
    d = m.core.discretise(t, r)
    return Discretisation(
        t, r, t / r, _readonly(d.e), _readonly(d.h), tuple(_readonly(c) for c in d.cbar)
    )


def _prepare(
    net: Any, tau: float, schedule: Schedule | Sequence[int] | npt.ArrayLike, check: bool
) -> tuple[SampledSystem, float, Schedule]:
    m = sampled_system(net)
    t = _check_tau(tau)
    s = as_schedule(m, schedule)
    if check:
        check_existence(m, t, s)
    return m, t, s


@accepts_path
def period_triplet(
    net: Any, tau: float, schedule: Schedule | Sequence[int] | npt.ArrayLike
) -> tuple[F64, F64, F64]:
    """The period map ``Φ_R(X) = H + A X (I + G X)⁻¹ Aᵀ`` as its triplet ``(A, G, H)`` (the star
    product of the slot triplets)."""
    m, t, s = _prepare(net, tau, schedule, check=False)
    tr = m.core.period_triplet(t, s.as_array())
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
            (``posteriors[-1]`` reproduces ``boundary`` up to ``residual``).
        priors: ``(r_tot, n, n)``: the prior covariance of slot ``l`` (after its prediction).
        eta_boundary: ``tr Σ(∞; τ, R)`` — the paper's ``η̄(τ, R)``.
        eta_average: ``(1/r_tot) Σ_l tr posteriors[l]``.
        doubling_steps: doubling steps (the last one composes ``2^steps`` periods).
        rel_change: the doubling's last relative change of ``H``.
        spectral_radius: of the closed-loop monodromy at the steady state (``< 1``).
        residual: ``‖Φ_R(Σ) − Σ‖_F/‖Σ‖_F`` evaluated slot by slot.
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

    def eta(self, which: Which = "boundary") -> float:
        """``eta_boundary`` or ``eta_average``."""
        return _pick(which, self.eta_boundary, self.eta_average)

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain JSON-ready values: ``schedule`` as its list of slots, the
        covariances as nested lists (non-finite numbers as ``None``).

        Returns:
            ``{"tau", "schedule", "boundary", "posteriors", "priors", "eta_boundary",
            "eta_average", "doubling_steps", "rel_change", "spectral_radius", "residual"}``.
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
) -> SampledCovariance:
    """The periodic steady state ``Σ(∞; τ, R)`` and the covariances of every slot.

    Doubling of the period triplet until ``‖H_{k+1} − H_k‖_F ≤ tol·‖H_{k+1}‖_F`` (quadratic
    convergence: the result is accurate to rounding), at most ``max_steps`` steps.

    Raises:
        ScheduleError, InvalidInputError, NonFiniteError: bad schedule or τ.
        UnobservableError, AliasingError: Proposition 1's hypotheses fail (with ``check=True``).
        ConvergenceError: the steady state does not exist (the covariance grows without bound, or
            the limit reached from Σ = 0 is not stabilising).
    """
    m, t, s = _prepare(net, tau, schedule, check)
    ss = m.core.steady_state(
        t,
        s.as_array(),
        as_real("tol", tol, positive=True),
        as_count("max_steps", max_steps, minimum=1),
    )
    eta_b = float(np.trace(ss.boundary))
    eta_a = float(np.trace(ss.posteriors, axis1=1, axis2=2).mean())
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
) -> float:
    """``η̄(τ, R)``: ``tr Σ(∞; τ, R)`` at the period boundary (``which="boundary"``, the paper's
    definition) or ``(1/r_tot) Σ_l tr Σ_l⁺`` averaged over the posteriors after each slot
    (``which="average"``). See the module docstring for the conventions and
    :func:`sampled_covariance` for errors."""
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    if not check:
        warn_unchecked()
    m, t, s = _prepare(net, tau, schedule, check)
    return float(
        m.core.cost(
            t,
            s.as_array(),
            which,
            as_real("tol", tol, positive=True),
            as_count("max_steps", max_steps, minimum=1),
        )
    )


@accepts_path
def propagate(
    net: Any, tau: float, schedule: Schedule | Sequence[int] | npt.ArrayLike, sigma0: Any
) -> tuple[F64, F64]:
    """One period of slot maps from the posterior ``sigma0``: ``(priors, posteriors)``, each
    ``(r_tot, n, n)``; ``posteriors[-1] = Φ_R(sigma0)``."""
    m, t, s = _prepare(net, tau, schedule, check=False)
    prop = m.core.propagate(t, s.as_array(), as_matrix("sigma0", sigma0))
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
) -> tuple[F64, int]:
    """The plain iteration ``Σ_{k+1} = Φ_R(Σ_k)`` (in Rust, slot by slot, Joseph form) from
    ``sigma0`` (default 0) until ``‖Σ_{k+1} − Σ_k‖_F ≤ tol·‖Σ_{k+1}‖_F``: ``(Σ, periods)``. A
    reference for :func:`sampled_covariance`; it needs ``O(1/(1 − ρ))`` periods."""
    m, t, s = _prepare(net, tau, schedule, check=False)
    s0 = np.zeros((m.n, m.n)) if sigma0 is None else as_matrix("sigma0", sigma0)
    fp = m.core.fixed_point(
        t,
        s.as_array(),
        s0,
        as_real("tol", tol, positive=True),
        as_count("max_periods", max_periods, minimum=1),
    )
    return fp.sigma, int(fp.periods)
