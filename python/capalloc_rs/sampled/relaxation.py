"""Provable lower bounds on ``η̄(τ, R)`` over every schedule: slot maps relaxed to maps that are
``⪯`` them pointwise, and the monotonicity of the Riccati maps.

**Maps.** A prediction over ``t`` is ``P_t(S) = e^{At} S e^{Aᵀt} + H_t``; an update with
information ``J ⪰ 0`` is ``U_J(S) = S − S (I + J S)⁻¹ J S = (S⁻¹ + J)⁻¹``. Sensor ``i``'s slot is
``φ_i = U_{c̄_i c̄_iᵀ} ∘ P_{b_i τ₀}``; a schedule's period map is
``Φ_R = P_{idle} ∘ φ_{R_L} ∘ … ∘ φ_{R_1}`` (:mod:`capalloc_rs.sampled.system`). Every map here is
a Riccati map ``X ↦ H + A X (I + G X)⁻¹ Aᵀ`` (a *triplet* ``(A, G, H)``; composition is the star
product).

**Facts used** (for ``S, S' ⪰ 0``): (i) ``P_t`` and ``U_J`` are monotone: ``S ⪯ S'`` ⇒
``P_t(S) ⪯ P_t(S')``, ``U_J(S) ⪯ U_J(S')``; (ii) ``J ⪰ J'`` ⇒ ``U_J(S) ⪯ U_{J'}(S)`` (more
information, smaller posterior), and ``U_J(S) ⪯ S = U_0(S)``; (iii) ``P_s ∘ P_t = P_{s+t}``.

**Theorem (relaxation).** Let ``Ψ`` be monotone with ``Ψ(S) ⪯ Φ_R(S)`` for all ``S ⪰ 0``, and let
``Σ̄ ⪰ 0`` be any fixed point of ``Φ_R`` (the periodic steady state of ``R``, the boundary
covariance; it exists under Proposition 1). Then ``Ψᵏ(0) ⪯ Σ̄`` for every ``k ≥ 0``.
*Proof.* ``Ψ⁰(0) = 0 ⪯ Σ̄``; if ``Ψᵏ(0) ⪯ Σ̄`` then ``Ψᵏ⁺¹(0) ⪯ Φ_R(Ψᵏ(0)) ⪯ Φ_R(Σ̄) = Σ̄`` (first the
pointwise order, then the monotonicity of ``Φ_R``). ∎  Since ``tr(M ·)`` is monotone for
``M ⪰ 0``, ``tr(M Ψᵏ(0)) ≤ tr(M Σ̄)``: every iterate — no convergence needed — is a lower bound.
The doubling ``t ← t ⋆ t`` of ``Ψ``'s triplet gives ``Ψ^{2^k}(0)`` (its ``H``), an increasing
sequence; it stops when ``H`` changes by less than ``1e-13`` relatively.

**The relaxed period (every schedule, any costs).** Let the costs ``b_i`` be integer multiples of
a grid ``g`` (exactly, as rationals — each cost read as the simplest fraction within a relative
``1e-14``, so ``0.1`` is ``1/10`` — the largest such ``g``), ``K = ⌊B/g⌋`` grid units. A slot
ends at a partial sum of costs, so every schedule's updates happen at grid times ``k g τ₀`` with
``k`` in the set 𝒦 of reachable sums (``k g = Σ_i n_i b_i``, ``n_i ≥ 0``, computed by a knapsack
over the grid). Write ``Φ_R`` grid unit by grid unit (fact iii): each unit is ``P_{gτ₀}`` followed
by ``U_{c̄_i c̄_iᵀ}`` (a slot ends there) or the identity (inside a slot or idle), and the
remainder ``(B − Kg)τ₀`` a prediction. ``Ψ`` does the same with ``U_J`` at every ``k ∈ 𝒦`` and
the identity elsewhere, where ``J ⪰ c̄_i c̄_iᵀ`` for every sensor ``i`` a schedule may use
(``⌊r_max,i⌋ ≥ 1``). By (ii) each unit of ``Ψ`` is ``⪯`` the same unit of ``Φ_R``, and by (i)
and induction over the units ``Ψ(S) ⪯ Φ_R(S)`` — the theorem applies to every schedule at once:
**boundary bound** ``η̄_boundary(τ, R) ≥ tr(M Ψᵏ(0))`` for every feasible ``R``.

**The information** ``J``: ``J = λ W`` with ``W = Σ_i c̄_i c̄_iᵀ`` over the usable sensors and
``λ = max_i λ_max(c̄_iᵀ W⁻¹ c̄_i) ≤ 1`` (then ``λW ⪰ c̄_i c̄_iᵀ``; ``λ`` is rounded up by a relative
``1e-9``; ``W`` singular: ``λ = 1``), and ``J = μ I`` with ``μ = max_i ‖c̄_i‖₂²``; the larger of the
two bounds is reported (both are theorems).

**Average bound.** The posterior after slot ``l`` is ``Σ_l⁺ = (φ_{R_l} ∘ … ∘ φ_{R_1})(Σ̄)``,
ending at a grid time ``k_l ∈ 𝒦``; the same argument gives ``Σ_l⁺ ⪰ X_{k_l}``, the state of ``Ψ``
at grid time ``k_l`` started from ``Ψᵏ(0)`` (``⪯ Σ̄``). So ``η̄_average = (1/L) Σ_l tr(M Σ_l⁺)`` is
at least the mean of the ``L`` smallest values ``tr(M X_k)``, ``k ∈ 𝒦``, which is increasing in
``L``: the bound uses the least number of slots a feasible schedule can have.

All reported bounds are multiplied by ``1 − BOUND_RTOL`` to absorb rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import reduce

import numpy as np

from .._arrays import F64
from .channel import ScheduleLimits
from .system import SampledSystem, discretise

__all__ = [
    "BOUND_RTOL",
    "Triplet",
    "dominating_factor",
    "dominating_information",
    "relaxed_lower_bound",
]

#: Relative safety margin subtracted from every reported lower bound (rounding of the maps).
BOUND_RTOL = 1e-9
#: Most grid units the relaxed period may have (finer grids: no bound is reported).
MAX_GRID_UNITS = 20_000
#: Most doubling steps (the last composes ``2^64`` periods).
MAX_DOUBLINGS = 64
#: The doubling stops when ``H`` changes by less than this, relatively.
DOUBLING_RTOL = 1e-13


@dataclass(frozen=True)
class Triplet:
    """The Riccati map ``X ↦ H + A X (I + G X)⁻¹ Aᵀ``."""

    a: F64
    g: F64
    h: F64

    @staticmethod
    def identity(n: int) -> Triplet:
        """The identity map."""
        z = np.zeros((n, n))
        return Triplet(np.eye(n), z, z)

    @staticmethod
    def prediction(e: F64, h: F64) -> Triplet:
        """``S ↦ E S Eᵀ + H``."""
        return Triplet(np.asarray(e), np.zeros_like(e), np.asarray(h))

    @staticmethod
    def update(j: F64) -> Triplet:
        """``S ↦ (S⁻¹ + J)⁻¹``."""
        n = j.shape[0]
        return Triplet(np.eye(n), np.asarray(j), np.zeros((n, n)))

    def then(self, other: Triplet) -> Triplet:
        """The star product: ``other ∘ self`` (``self`` first)."""
        n = self.a.shape[0]
        w = np.eye(n) + other.g @ self.h  # W = I + G₂H₁
        a = other.a @ np.linalg.solve(w.T, self.a)  # A₂ W⁻ᵀ A₁
        g = self.g + self.a.T @ np.linalg.solve(w, other.g @ self.a)  # G₁ + A₁ᵀ W⁻¹ G₂ A₁
        h = other.h + other.a @ self.h @ np.linalg.solve(w, other.a.T)  # H₂ + A₂ H₁ W⁻¹ A₂ᵀ
        return Triplet(a, 0.5 * (g + g.T), 0.5 * (h + h.T))

    def apply(self, x: F64) -> F64:
        """``H + A X (I + G X)⁻¹ Aᵀ``."""
        n = x.shape[0]
        y = self.h + self.a @ np.linalg.solve((np.eye(n) + self.g @ x).T, x.T).T @ self.a.T
        return np.asarray(0.5 * (y + y.T))


def power_from_zero(t: Triplet) -> F64:
    """``Ψ^{2^k}(0)`` by doubling, until ``H`` settles (at most ``MAX_DOUBLINGS`` steps); the last
    finite iterate if it grows without bound (still ``⪯`` every fixed point ``Φ_R`` above it)."""
    h = t.h
    for _ in range(MAX_DOUBLINGS):
        nxt = t.then(t)
        if not np.all(np.isfinite(nxt.h)):
            return h
        change = float(np.linalg.norm(nxt.h - t.h))
        t = nxt
        if change <= DOUBLING_RTOL * float(np.linalg.norm(t.h)):
            break
    return t.h


def dominating_information(cbar: list[F64]) -> list[F64]:
    """Matrices ``J ⪰ c̄_i c̄_iᵀ`` for every given ``c̄_i``: the scaled sum ``λ W`` and ``μ I``
    (module docstring)."""
    n = cbar[0].shape[0]
    w = sum((c @ c.T for c in cbar), np.zeros((n, n)))
    try:
        lam = max(float(np.linalg.eigvalsh(c.T @ np.linalg.solve(w, c)).max()) for c in cbar)
        lam = min(1.0, lam * (1 + BOUND_RTOL))
        if not math.isfinite(lam) or lam <= 0:
            lam = 1.0
    except np.linalg.LinAlgError:
        lam = 1.0
    mu = max(float(np.linalg.eigvalsh(c.T @ c).max()) for c in cbar) * (1 + BOUND_RTOL)
    return [lam * w, mu * np.eye(n)]


def _rational(b: float) -> Fraction:
    """``b`` as a fraction: the simplest one with a denominator up to ``10⁶`` within a relative
    ``1e-14`` of it (``0.1`` is ``1/10``; the slot lengths then differ from the grid's by
    rounding only, absorbed by ``BOUND_RTOL``), else its exact binary value."""
    near = Fraction(b).limit_denominator(10**6)
    return near if abs(float(near) - b) <= 1e-14 * abs(b) else Fraction(b)


def _grid(costs: F64, budget: float) -> tuple[Fraction, int] | None:
    """The largest ``g`` with every cost an integer multiple of it, and ``⌊B/g⌋``; ``None`` if
    that is more than ``MAX_GRID_UNITS`` units."""
    fr = [_rational(float(b)) for b in costs]
    den = reduce(math.lcm, (f.denominator for f in fr))
    g = Fraction(reduce(math.gcd, (int(f * den) for f in fr)), den)
    units = math.floor(Fraction(budget) * (1 + Fraction(1, 10**12)) / g)
    return None if units > MAX_GRID_UNITS else (g, units)


def _reachable(steps: list[int], units: int) -> list[int]:
    """The grid times ``k ∈ 1..units`` that are sums of the given steps (a knapsack)."""
    ok = [False] * (units + 1)
    ok[0] = True
    for k in range(1, units + 1):
        ok[k] = any(s <= k and ok[k - s] for s in steps)
    return [k for k in range(1, units + 1) if ok[k]]


@dataclass(frozen=True)
class RelaxedPeriod:
    """The relaxed period ``Ψ`` of the module docstring: ``units`` grid steps of ``gτ₀`` (its
    prediction ``step``), an update at each ``k`` in ``updates``, then ``tail``."""

    step: Triplet
    tail: Triplet
    units: int
    updates: frozenset[int]


def relaxed_period(m: SampledSystem, tau: float, lim: ScheduleLimits) -> RelaxedPeriod | None:
    """The grid of the relaxed period for the model, τ and limits (``None``: grid too fine)."""
    costs = m.sample_costs
    usable = [i for i in range(m.n_sensors) if lim.hi is None or lim.hi[i] >= 1]
    grid = _grid(costs[usable], lim.budget)
    if grid is None:
        return None
    g, units = grid
    if units == 0:
        return None
    d = discretise(m, tau, float(Fraction(lim.budget) / g))
    steps = sorted({round(_rational(float(costs[i])) / g) for i in usable})
    rem = (Fraction(lim.budget) - units * g) * Fraction(tau) / Fraction(lim.budget)
    tail = Triplet.identity(m.n)
    if rem > 0 and float(rem) > 1e-15 * tau:
        dt = discretise(m, float(rem), 1)
        tail = Triplet.prediction(dt.E, dt.H)
    return RelaxedPeriod(
        Triplet.prediction(d.E, d.H), tail, units, frozenset(_reachable(steps, units))
    )


def _power(t: Triplet, k: int) -> Triplet:
    """``t ∘ … ∘ t`` (``k ≥ 1`` times) by binary powering: ``O(log k)`` star products (the
    powers of one map commute, so the grouping does not matter but for rounding)."""
    out: Triplet | None = None
    while True:
        if k & 1:
            out = t if out is None else out.then(t)
        k >>= 1
        if not k:
            assert out is not None
            return out
        t = t.then(t)


def _period(p: RelaxedPeriod, j: F64) -> tuple[Triplet, list[Triplet]]:
    """``Ψ`` as one triplet, and the triplet of each grid unit: each run of equal consecutive
    units composed by :func:`_power` (one run of ``r_tot`` updates in the paper's case)."""
    upd = p.step.then(Triplet.update(j))
    flags = [k in p.updates for k in range(1, p.units + 1)]
    unit = [upd if f else p.step for f in flags]
    total = Triplet.identity(j.shape[0])
    k = 0
    while k < len(flags):
        run = k
        while run < len(flags) and flags[run] == flags[k]:
            run += 1
        total = total.then(_power(unit[k], run - k))
        k = run
    return total.then(p.tail), unit


def _bounds_for(
    m: SampledSystem, p: RelaxedPeriod, j: F64, min_slots: int, which: str
) -> tuple[float, float]:
    """(boundary bound, average bound) for one dominating information ``J`` (the average one,
    an orbit of the relaxed period, only for ``which="average"``; else ``nan``)."""
    total, unit = _period(p, j)
    x = power_from_zero(total)
    boundary = m.trace(x)
    if which != "average":
        return boundary, math.nan
    values = []
    s = x
    for k, u in enumerate(unit, start=1):
        s = u.apply(s)
        if k in p.updates:
            values.append(m.trace(s))
    values.sort()
    take = max(1, min(min_slots, len(values)))
    average = float(np.mean(values[:take])) if values else math.nan
    return boundary, average


def relaxed_lower_bound(m: SampledSystem, tau: float, lim: ScheduleLimits, which: str) -> float:
    """A proven lower bound on ``η̄`` (``which``) over every schedule within ``lim`` (module
    docstring: the relaxed period with every possible update time given all the information);
    ``nan`` if none can be computed (a grid finer than ``MAX_GRID_UNITS`` units)."""
    p = relaxed_period(m, tau, lim)
    if p is None:
        return math.nan
    usable = [i for i in range(m.n_sensors) if lim.hi is None or lim.hi[i] >= 1]
    cbar = [np.sqrt(tau) * m.sensors[i] for i in usable]
    least = max(1, sum(lim.lo))
    if lim.plain:
        least = int(round(lim.budget))
    best = -math.inf
    for j in dominating_information(cbar):
        boundary, average = _bounds_for(m, p, j, least, which)
        v = boundary if which == "boundary" else average
        if math.isfinite(v):
            best = max(best, v)
    return best * (1 - BOUND_RTOL) if math.isfinite(best) else math.nan


def dominating_factor(cbar: list[F64], tau: float, n: int) -> F64:
    """A factor ``ĉ`` (n × k, k ≥ 1) with ``τ ĉĉᵀ ⪰ J``, ``J`` the information dominating every
    ``c̄ c̄ᵀ`` of ``cbar`` (:func:`dominating_information`); zero when ``J = 0``."""
    j = dominating_information(cbar)[0]
    w, v = np.linalg.eigh(0.5 * (j + j.T))
    keep = w > 0
    # Round the factor's eigenvalues up (relative 1e-12): ĉĉᵀ τ ⪰ J up to the last bit.
    c = v[:, keep] * np.sqrt(w[keep] * (1 + 1e-12) / tau)
    return c if c.shape[1] else np.zeros((n, 1))
