"""The screened local search of :func:`~capalloc_rs.best_schedule` (``method="screened"``): moves
ranked by the first-order sensitivity of ``η̄`` and only the promising ones costed exactly.

For the current schedule one Rust call (``SampledModel.screen``, ``capalloc::sampled::
sensitivity``) computes the periodic steady state, the adjoint of the cost (one Stein equation
``Λ = MᵀΛM + C``, ``M`` the closed-loop monodromy, pulled back slot by slot) and from it the
predicted change ``⟨μ_l, d_l⟩`` of every reassignment and adjacent swap (the local change ``d_l``
exact, its propagation through the steady state linear) and the exact cost of every rotation
(``tr`` of the posterior after the slot before the new start: the periodic orbit is the same).

The moves predicted to improve are ranked per kind (a reassignment is a large change of one slot
and its prediction optimistic; a swap's is close to exact) and packed into batches of
non-overlapping moves. Exact costings (``SampledModel.candidate_costs``: on the star-product tree
of the current schedule, only the changed segments recomposed, then one doubling each, in
parallel; for the boundary figure a doubling stops once its monotone iterates ``tr(M H_k) ≤ η̄``
prove the candidate dearer than the current schedule — ``PRUNE`` —, so that only candidates that
could be taken are costed to the end), in order until one improves by the relative margin 1e-13
of the exhaustive search: both kinds' whole batches together, then the whole batch of each kind
(and the best rotation, exact already); half of each batch and the best single moves; the next
predicted single moves, a bounded number. The cheapest improving candidate is taken; a kind's batch
doubles after its whole batch is taken. Order ``"adaptive"`` (the default): both together come
first only while both kinds' batches are being taken; otherwise the whole batch of the kind taken
last comes alone (of both kinds if neither), then the other kind's and both together — late in a
search the swaps alone improve and the reassignment batch and the joint one fail, so this halves
the exact costings. Order ``"fixed"`` (``method="screened_fixed"``) is the order of before.
The accepted candidate's recomposed segments and steady state are kept, so that its own screen
neither recomposes nor doubles again.

**Shifts, displacement steps, stall** (the default ``method="screened"``; ``"screened-v3"``
is the search above, adjacent swaps only). The swaps' batches and single moves are replaced by
*shifts* (:mod:`.shifts`: the sample of slot ``a`` moved to slot ``b``, the samples in between one
slot back; for every slot its best predicted shift), and when none of those improves, the swaps'
own rounds follow in the same screen. On large problems (more than ``DISPLACE_NEIGHBOURS``
neighbours) every screen first tries the *displacement steps* of :class:`.shifts.Displacement`
(all samples moved at once along the screen's one-slot derivatives and re-sorted; at N = 100
their predictions are within 1–5 % of the exact changes, and a swap moves a sample only one
slot per screen), and the search stops (``"stalled"``) once ``STALL_SCREENS`` screens together
lowered ``η̄`` by less than ``STALL_RTOL`` (relative).

When no screened move improves (a *screened minimum*), the exhaustive neighbourhood of one step
of the exhaustive search (:mod:`capalloc_rs.sampled.exhaustive`) confirms it (``confirm``): it
either finds an improving move, taken before the screened search goes on, or proves a local
minimum of the exhaustive neighbourhood.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .exhaustive import SearchContext
from .moves import _interleave, _Move, _pack, _ranked, _with
from .schedule import Schedule
from .shifts import Displacement
from .system import SampledSystem

__all__ = ["ScreenedOptions", "neighbours", "screened_confirms", "screened_search"]

#: Moves in the first batch; the batch doubles after a whole batch is accepted (at most
#: ``MAX_BATCH``) and falls back to the size accepted otherwise.
INITIAL_BATCH = 8
MAX_BATCH = 256

#: Best single moves costed exactly with every batch.
SINGLES = 2

#: When no batch or top single move improves: the next predicted moves costed, this many per
#: round, at most ``EXPAND_LIMIT`` per screen.
EXPAND_CHUNK = 8
EXPAND_LIMIT = 32

#: ``confirm=None`` confirms a screened minimum with the exhaustive neighbourhood when it has at
#: most this many neighbours (``r_tot·N`` reassignments + swaps + rotations).
CONFIRM_MAX_NEIGHBOURS = 1000

#: On problems whose neighbourhood has at most this many neighbours (3 sensors × 7 slots: 34) the
#: screened method starts from the exhaustive method's candidates and runs the exhaustive search
#: too, keeping the best: there it is never worse than ``method="exhaustive"``.
PORTFOLIO_MAX_NEIGHBOURS = 64

#: Exact costings cut a candidate's doubling short once it proves the candidate dearer than the
#: current schedule (``capalloc::sampled::pruned``; boundary objective): the same moves are taken.
PRUNE = True


#: Above this many neighbours (:func:`neighbours`; N = 100, r_tot = 300: 30 599) the default
#: search (``ScreenedOptions.max_shift > 1``) starts every screen with the displacement steps
#: of :func:`.shifts.displaced` and stops once it stalls (``STALL_SCREENS``, ``STALL_RTOL``).
DISPLACE_NEIGHBOURS = 10_000

#: The default search on a large problem stops (``stopped="stalled"``) when the last
#: ``STALL_SCREENS`` screens together lowered ``η̄`` by less than ``STALL_RTOL`` (relative).
STALL_SCREENS = 3
STALL_RTOL = 1e-5

#: The orders of the exact costings of a screen (``ScreenedOptions.order``).
ORDERS = ("adaptive", "fixed")


@dataclass
class ScreenedOptions:
    """How the screened search confirms its minima: ``confirm`` (``True``, ``False``, ``None`` =
    when the neighbourhood has at most ``CONFIRM_MAX_NEIGHBOURS`` neighbours); ``order`` of the
    exact costings: ``"fixed"`` (both kinds' batches together first, every screen: the search
    of before) or ``"adaptive"`` (together only while both kinds' batches are being taken)."""

    confirm: bool | None = None
    order: str = "adaptive"
    max_shift: int = 1


@dataclass
class _Batches:
    """The batch size of each kind (reassignments, swaps) and whether the last move taken came
    from that kind's batch (``hot``): while both are, the screen costs them together first."""

    sizes: list[int]
    hot: list[bool]
    adaptive: bool
    max_shift: int = 1
    displacement: Displacement | None = None

    def order(self) -> tuple[bool, bool]:
        """Which kinds' batches come first (both: together first, the order of ``"fixed"``)."""
        return (True, True) if not self.adaptive else (self.hot[0], self.hot[1])


@dataclass
class _Round:
    """One exact costing: the candidate schedules, the moves each stands for, the kind whose
    batch (``size`` moves) each is (``None``: single moves), their costs."""

    schedules: list[list[int]]
    moves: list[int]
    kinds: list[int | None]
    costs: list[float]


#: The kind of the candidate made of both kinds' whole batches.
BOTH = 2

#: A candidate: its schedule, the moves it stands for, the kind whose batch it is (or ``None``).
_Cand = tuple[list[int], int, int | None]


def _cost_round(ctx: SearchContext, state: Any, cands: list[_Cand]) -> _Round:
    left = ctx.time_left()
    arrays = [np.asarray(c[0], dtype=np.int64) for c in cands]
    # Candidates proved dearer than the current schedule are cut short (+inf): none of them
    # could be accepted, so the search takes the same moves.
    kw: dict[str, Any] = {"time_limit": left, "incumbent": state.cost if PRUNE else None}
    if ctx.lim.core_budget is not None:  # without: the call of before sample costs
        kw["budget"] = ctx.lim.core_budget
    cc = ctx.m.core.candidate_costs(ctx.t, arrays, ctx.which, **kw)
    state.evaluations += int(cc.evaluated)
    return _Round(
        [c[0] for c in cands],
        [c[1] for c in cands],
        [c[2] for c in cands],
        list(map(float, cc.costs)),
    )


def _accept(state: Any, rnd: _Round, n_sensors: int) -> int | None:
    """Takes the cheapest candidate of ``rnd`` if it improves (relative margin 1e-13); returns
    its index (``None``: none improves)."""
    if not rnd.costs:
        return None
    k = int(np.argmin(rnd.costs))
    thr = state.cost - 1e-13 * abs(state.cost)
    if not rnd.costs[k] < thr:
        return None
    state.current = Schedule(rnd.schedules[k], n_sensors)
    state.cost = rnd.costs[k]
    state.moves += rnd.moves[k]
    return k


def _rounds(
    slots: list[int],
    ranked: tuple[list[_Move], list[_Move]],
    packed: list[list[_Move]],
    sizes: list[int],
    hot: tuple[bool, bool] = (True, True),
) -> list[list[_Cand]]:
    """The exact costings of one screen, in order until one improves: both kinds' whole batches
    together; the whole batch of each kind; half of each batch and the best single moves; then
    the next predicted single moves (the two kinds interleaved, ``EXPAND_CHUNK`` at a time, at
    most ``EXPAND_LIMIT``). Unless both kinds are ``hot`` (their batches taken last), the whole
    batches of the hot kind (of both if neither is) come first, then the other whole batch and
    both together."""
    whole: list[_Cand] = []
    half: list[_Cand] = []
    for kind, (pk, size) in enumerate(zip(packed, sizes, strict=True)):
        size = min(size, len(pk))
        if size >= 2:
            whole.append((_with(slots, pk[:size]), size, kind))
        if size // 2 >= 2:
            half.append((_with(slots, pk[: size // 2]), size // 2, kind))
    together: list[_Cand] = []
    if len(whole) == 2:
        # Both kinds' batches together, where they do not overlap.
        used = {x for mv in packed[0][: sizes[0]] for x in mv.span()}
        swaps = [mv for mv in packed[1][: sizes[1]] if used.isdisjoint(mv.span())]
        # At most as many moves as the larger batch (which the move budget already caps).
        both = (packed[0][: sizes[0]] + swaps)[: max(sizes)]
        together.append((_with(slots, both), len(both), BOTH))
    singles: list[_Cand] = [(_with(slots, [mv]), 1, None) for rk in ranked for mv in rk[:SINGLES]]
    rest = _interleave(ranked[1][SINGLES:], ranked[0][SINGLES:])[:EXPAND_LIMIT]
    expand: list[list[_Cand]] = [
        [(_with(slots, [mv]), 1, None) for mv in rest[k : k + EXPAND_CHUNK]]
        for k in range(0, len(rest), EXPAND_CHUNK)
    ]
    return [r for r in [*_first(whole, together, hot), half + singles, *expand] if r]


def _first(whole: list[_Cand], together: list[_Cand], hot: tuple[bool, bool]) -> list[list[_Cand]]:
    """The first costings of a screen (see :func:`_rounds`)."""
    if all(hot):
        return [together, whole]
    if not any(hot):
        return [whole, together]
    first = [c for c in whole if hot[c[2] or 0]]
    return [first, [c for c in whole if not hot[c[2] or 0]] + together]


def _best_rotation(sc: Any) -> tuple[int, float] | None:
    """The cheapest rotation ``(k, exact cost)`` if it is below the current cost."""
    rotate = np.asarray(sc.rotate)
    if len(rotate) < 2:
        return None
    k = int(np.argmin(rotate[1:])) + 1
    return (k, float(rotate[k])) if rotate[k] < sc.current else None


def _screen_step(ctx: SearchContext, state: Any, batches: _Batches) -> bool:
    """One screen and its exact costings (``batches``: the batch size of each kind, doubled after
    a whole batch is taken, halved after a half one); returns whether a move was taken."""
    m, lim = ctx.m, ctx.lim
    slots = [int(v) for v in state.current.slots]
    sc = m.core.screen(
        ctx.t,
        np.asarray(slots, dtype=np.int64),
        ctx.which,
        lim.min_count,
        **lim.core_kwargs(),
        time_limit=ctx.time_left(),
    )
    if sc is None:  # the deadline passed during the screen: no move (the search stops)
        return False
    state.cost = float(sc.current)
    steps = batches.displacement
    if steps is not None and steps.active and _displace(ctx, state, steps, sc.swap, slots):
        return True
    rotation = _best_rotation(sc)
    # The default search: shifts first, then (at their screened minimum) the adjacent swaps.
    for shift in (batches.max_shift, 1) if batches.max_shift > 1 else (1,):
        if shift == 1 and batches.max_shift > 1 and time.monotonic() >= ctx.deadline:
            break
        first = rotation if shift == batches.max_shift else None
        if _try_rounds(ctx, state, batches, sc, slots, shift, first):
            return True
    if rotation is not None:
        k = rotation[0]
        return (
            _accept(state, _Round([slots[k:] + slots[:k]], [1], [None], [rotation[1]]), m.n_sensors)
            is not None
        )
    return False


def _try_rounds(
    ctx: SearchContext,
    state: Any,
    batches: _Batches,
    sc: Any,
    slots: list[int],
    max_shift: int,
    rotation: tuple[int, float] | None,
) -> bool:
    """The exact costings of one screen (:func:`_rounds`) with the swaps (``max_shift = 1``)
    or the shifts; returns whether a move was taken."""
    m = ctx.m
    ranked = _ranked(sc, slots, max_shift)
    sizes = [min(b, ctx.max_moves - state.moves) for b in batches.sizes]
    packed = [
        _pack(rk, slots, m.n_sensors, ctx.lim, b) for rk, b in zip(ranked, sizes, strict=True)
    ]
    rounds = _rounds(slots, ranked, packed, sizes, batches.order())
    for k, cands in enumerate(rounds):
        if k > 0 and time.monotonic() >= ctx.deadline:
            break
        rnd = _cost_round(ctx, state, cands)
        if k == 0 and rotation is not None and rotation[1] < min(rnd.costs, default=math.inf):
            # Exact already (the same periodic orbit): taken without another evaluation.
            rnd = _Round([slots[rotation[0] :] + slots[: rotation[0]]], [1], [None], [rotation[1]])
        taken = _accept(state, rnd, m.n_sensors)
        if taken is not None:
            _resize(batches, rnd, taken, sizes, packed)
            return True
    return False


def _displace(
    ctx: SearchContext, state: Any, steps: Displacement, swap: Any, slots: list[int]
) -> bool:
    """The displacement steps of ``steps`` costed exactly together; the cheaper is taken if it
    improves (one move). Returns whether it was."""
    ks, schedules = steps.candidates(swap, slots)
    cands: list[_Cand] = [(sch, 1, None) for sch in schedules]
    taken = _accept(state, _cost_round(ctx, state, cands), ctx.m.n_sensors) if cands else None
    steps.update(ks, taken)
    return taken is not None


def _resize(
    batches: _Batches, rnd: _Round, taken: int, sizes: list[int], packed: list[list[_Move]]
) -> None:
    """After candidate ``taken`` of ``rnd``: a kind's batch doubles after its whole batch is
    taken and falls back to the size taken otherwise; the kinds taken become the hot ones."""
    kind = rnd.kinds[taken]
    kinds = (0, 1) if kind == BOTH else () if kind is None else (kind,)
    for kd in kinds:
        whole = kind == BOTH or rnd.moves[taken] >= min(sizes[kd], len(packed[kd]))
        batches.sizes[kd] = (
            min(2 * batches.sizes[kd], MAX_BATCH) if whole else max(rnd.moves[taken], 2)
        )
    batches.hot = [kd in kinds for kd in (0, 1)]


def _stalled(costs: list[float]) -> bool:
    """Whether the last ``STALL_SCREENS`` screens together lowered the cost by less than
    ``STALL_RTOL`` (relative)."""
    if len(costs) <= STALL_SCREENS:
        return False
    before, now = costs[-1 - STALL_SCREENS], costs[-1]
    return bool(before - now < STALL_RTOL * abs(now))


def neighbours(m: SampledSystem, r: int, which: str) -> int:
    """The size of the exhaustive neighbourhood: ``r·N`` reassignments (no-ops included),
    ``r − 1`` swaps and, for the boundary figure, ``r`` rotations."""
    return r * m.n_sensors + (r - 1) + (r if which == "boundary" else 0)


def screened_confirms(m: SampledSystem, r: int, which: str, options: ScreenedOptions) -> bool:
    """Whether screened minima are confirmed by the exhaustive neighbourhood."""
    if options.confirm is not None:
        return options.confirm
    return neighbours(m, r, which) <= CONFIRM_MAX_NEIGHBOURS


def screened_search(
    ctx: SearchContext,
    state: Any,
    options: ScreenedOptions,
    exhaustive_step: Callable[[], str | None],
) -> str:
    """The screened local search, from and into ``state`` (``current``, ``cost``, ``moves``,
    ``evaluations``); ``exhaustive_step`` is one step of the exhaustive search (``None`` when it
    moved, else why it stopped). Returns why the search stopped: ``"local_minimum"`` (confirmed
    by the exhaustive neighbourhood), ``"screened_minimum"`` (no screened move improves and the
    confirmation was not asked for), ``"max_moves"`` or ``"time_limit"``."""
    r = len(state.current.slots)
    shift = options.max_shift
    large = shift > 1 and neighbours(ctx.m, r, ctx.which) > DISPLACE_NEIGHBOURS
    batches = _Batches(
        [INITIAL_BATCH, INITIAL_BATCH],
        [True, True],
        options.order == "adaptive",
        shift,
        Displacement(min(shift, r - 1), min(shift, r - 1), True) if large else None,
    )  # reassignments, swaps (or shifts)
    confirm = screened_confirms(ctx.m, r, ctx.which, options)
    bar, deadline = ctx.bar, ctx.deadline
    costs: list[float] = []  # after each screen that moved
    while True:
        if state.moves >= ctx.max_moves:
            return "max_moves"
        if time.monotonic() >= deadline:
            return "time_limit"
        if large and _stalled(costs):
            return "stalled"
        moved = _screen_step(ctx, state, batches)
        costs.append(state.cost)
        bar.update(
            phase="search",
            moves=state.moves,
            eta_bar=state.cost,
            best=min(state.best, state.cost),
            evaluations=state.evaluations,
        )
        if moved:
            continue
        if time.monotonic() >= deadline:
            return "time_limit"  # the costings may have been cut short: no minimum is claimed
        if not confirm:
            return "screened_minimum"
        if time.monotonic() >= deadline:
            return "time_limit"
        bar.update(
            phase="confirm",
            moves=state.moves,
            eta_bar=state.cost,
            best=min(state.best, state.cost),
            evaluations=state.evaluations,
        )
        stopped = exhaustive_step()
        if stopped is not None:
            return stopped
