"""How good is a schedule: ``best_schedule(method="exact")`` (branch-and-bound with relaxed
slots) against brute force over every schedule, and the proven lower bound of ``best_schedule``
on larger networks — side by side in one process.

Small cases: ``Network.random(N, n=2, p=1, eps=0.2, seed=11)``, τ = 0.2, both figures; brute
force costs every schedule with every sensor at least once (the paper's case) in the Rust core.
Unequal costs: the same networks with sample costs ``1, 2, 3(, 1)`` and a budget ``B`` (any
length, the rest of the period idle; brute force over every schedule within ``B`` using every
sensor). 12 unit-cost slots (3 and 4 sensors, no brute force): the exact search in the Rust kernel
against the Python tree from the same incumbent (time, nodes, proven?). Printed: both wall times
(best of ``--repeats``) and their ratio, the nodes the exact search bounded, both ``η̄`` and whether
they agree. Larger cases: ``Network.random(N, 2, eps=0.2, seed=3)``, ``r_tot = 2N`` (N = 5, 10, 20):
the searched ``η̄`` (search time, ``certify=False``) and the gap relative to ``η̄`` and the time of
each certificate alone (``certify="relaxed"``, the default, ``"grouped"``: the bound functions timed
side by side in one process). Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/certified_schedule.py [--repeats 3]``; the lead's
``benches/compare_certified.py`` calls :func:`section`.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from functools import partial
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network, best_schedule
from capalloc_rs.sampled import SampledSystem, ScheduleLimits, sampled_system, schedule_limits
from capalloc_rs.sampled.exact import exact_search
from capalloc_rs.sampled.grouped import grouped_lower_bound
from capalloc_rs.sampled.relaxation import relaxed_lower_bound

SMALL = [(3, 7, "boundary"), (3, 7, "average"), (3, 9, "boundary"), (3, 9, "average")]
SMALL += [(4, 7, "boundary")]
#: (sensors, costs, budget, figure) of the unequal-cost cases.
COSTS = [
    (3, (1.0, 2.0, 3.0), 10.0, "boundary"),
    (3, (1.0, 2.0, 3.0), 10.0, "average"),
    (3, (1.0, 2.0, 3.0), 12.0, "boundary"),
    (4, (1.0, 2.0, 3.0, 1.0), 9.0, "boundary"),
    (4, (1.0, 2.0, 3.0, 1.0), 9.0, "average"),
]
LARGE = [5, 10, 20]
TAU = 0.2
#: (sensors, slots, figure) of the 12-slot unit-cost cases (no brute force: 4¹² = 16.8 M costs).
TWELVE = [(3, 12, "boundary"), (3, 12, "average"), (4, 12, "boundary"), (4, 12, "average")]
#: Node limit of the 12-slot cases (the default 200 000 stops 4 × 12 before its proof).
TWELVE_NODES = 5_000_000
#: Wall-clock limit of the Python tree on the 12-slot cases (it does not prove 4 × 12 in 600 s).
PYTHON_LIMIT = 120.0


def brute_force(net: Network, r_tot: int, which: str) -> float:
    """The least ``η̄`` over every schedule of ``r_tot`` slots using every sensor."""
    m = sampled_system(net)
    n = m.n_sensors
    best = math.inf
    for s in itertools.product(range(n), repeat=r_tot):
        if len(set(s)) == n:
            best = min(best, float(m.core.cost(TAU, np.asarray(s, dtype=np.int64), which)))
    return best


def brute_force_costs(net: Network, budget: float, which: str) -> float:
    """The least ``η̄`` over every schedule within ``budget`` using every sensor."""
    m = sampled_system(net)
    n, b = m.n_sensors, m.sample_costs
    best = math.inf
    for length in range(n, int(budget / b.min()) + 1):
        for s in itertools.product(range(n), repeat=length):
            if len(set(s)) == n and sum(b[i] for i in s) <= budget:
                slots = np.asarray(s, dtype=np.int64)
                best = min(best, float(m.core.cost(TAU, slots, which, budget=budget)))
    return best


def costs_table(repeats: int) -> None:
    print("| N | costs | B | figure | exact | brute force | ratio | nodes | η̄ exact | agree |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, costs, budget, which in COSTS:
        base = Network.random(n, n=2, p=1, eps=0.2, seed=11)
        net = Network(base.a, base.g, list(base.sensors), r_min=1.0, costs=list(costs))
        run = partial(best_schedule, net, TAU, budget, which=which, method="exact", progress=False)
        t_ex, ex = best_of(run, repeats)
        t_bf, bf = best_of(partial(brute_force_costs, net, budget, which), 1)
        ok = ex.proven_optimal and abs(ex.eta_bar - bf) <= 1e-10 * bf
        print(
            f"| {n} | {'/'.join(f'{c:g}' for c in costs)} | {budget:g} | {which} | {t_ex:.2f} s "
            f"| {t_bf:.2f} s | {t_bf / t_ex:.1f}× | {ex.nodes} | {ex.eta_bar:.10g} "
            f"| {'yes' if ok else 'NO'} |"
        )


def small_table(repeats: int) -> None:
    print(
        "| N × slots | figure | exact | brute force | ratio | nodes | η̄ exact | η̄ brute | agree |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for n, r, which in SMALL:
        net = Network.random(n, n=2, p=1, eps=0.2, seed=11)
        run = partial(best_schedule, net, TAU, r, which=which, method="exact", progress=False)
        t_ex, ex = best_of(run, repeats)
        t_bf, bf = best_of(partial(brute_force, net, r, which), 1)
        ok = ex.proven_optimal and abs(ex.eta_bar - bf) <= 1e-10 * bf
        print(
            f"| {n} × {r} | {which} | {t_ex:.2f} s | {t_bf:.2f} s | {t_bf / t_ex:.1f}× "
            f"| {ex.nodes} | {ex.eta_bar:.10g} | {bf:.10g} | {'yes' if ok else 'NO'} |"
        )


def _exact(m: SampledSystem, r: int, which: str, impl: str, limit: float) -> Any:
    """The exact search of ``r`` unit-cost slots from the screened search's schedule."""
    lim = schedule_limits(m, r)
    net_start = screened_start(m, r, which)
    cost = float(m.core.cost(TAU, net_start.as_array(), which))
    deadline = time.monotonic() + limit
    return exact_search(
        m, TAU, which, lim, net_start, cost, TWELVE_NODES, deadline, exact_impl=impl
    )


def screened_start(m: SampledSystem, r: int, which: str) -> Any:
    """The schedule of the default (screened) search: the exact search's incumbent."""
    return best_schedule(m, TAU, r, which=which, progress=False, certify=False).schedule


def twelve_table(repeats: int) -> None:
    """12 unit-cost slots: the Rust kernel (``exact_impl="rust"``) and the Python tree
    (``"python"``, stopped at ``PYTHON_LIMIT`` s) from the same incumbent, in one process."""
    print("| N × slots | figure | rust | nodes | proven | python | nodes | proven | ratio | η̄ |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, r, which in TWELVE:
        m = sampled_system(Network.random(n, n=2, p=1, eps=0.2, seed=11))
        t_r, ex = best_of(partial(_exact, m, r, which, "rust", math.inf), repeats)
        t_p, py = best_of(partial(_exact, m, r, which, "python", PYTHON_LIMIT), 1)
        assert ex.complete and ex.lower_bound <= ex.eta_bar
        assert py.eta_bar >= ex.eta_bar * (1 - 1e-10) and py.lower_bound <= ex.eta_bar
        print(
            f"| {n} × {r} | {which} | {t_r:.2f} s | {ex.nodes} | {'yes' if ex.complete else 'no'} "
            f"| {t_p:.2f} s | {py.nodes} | {'yes' if py.complete else 'no'} "
            f"| {t_p / t_r:.1f}× | {ex.eta_bar:.10g} |"
        )


def large_table(repeats: int) -> None:
    print(
        "| N | r_tot | figure | search | η̄ | relaxed: gap / η̄ | time | default: gap / η̄ "
        "| time | grouped: gap / η̄ | time |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n in LARGE:
        net = Network.random(n, 2, eps=0.2, seed=3)
        m = sampled_system(net)
        lim = schedule_limits(m, 2 * n)
        for which in ("boundary", "average"):
            run = partial(best_schedule, net, TAU, 2 * n, which=which, progress=False)
            t, res = best_of(partial(run, certify=False), 1)
            row = f"| {n} | {2 * n} | {which} | {t:.2f} s | {res.eta_bar:.8g} "
            bounds = {
                "relaxed": partial(relaxed_lower_bound, m, TAU, lim, which),
                "default": partial(default_bound, m, lim, which),
                "grouped": partial(grouped_lower_bound, m, TAU, lim, which),
            }
            for name, fn in bounds.items():
                t_b, lb = best_of(fn, repeats if name != "grouped" else 1)
                assert lb <= res.eta_bar, (name, lb, res.eta_bar)
                row += f"| {(res.eta_bar - lb) / res.eta_bar:.1%} | {t_b:.2f} s "
            print(row + "|")


def default_bound(m: SampledSystem, lim: ScheduleLimits, which: str) -> float:
    """The default certificate of ``best_schedule``: the larger of the relaxed and the cheap
    grouped bounds."""
    grouped = grouped_lower_bound(m, TAU, lim, which, cheap=True)
    relaxed = relaxed_lower_bound(m, TAU, lim, which)
    return relaxed if math.isnan(grouped) else max(relaxed, grouped)


def section(args: Any) -> None:
    """The Markdown tables of this benchmark (``args.repeats``: best of that many runs)."""
    repeats = int(getattr(args, "repeats", 1))
    print("### Certified schedules: exact branch-and-bound vs brute force (τ = 0.2)\n")
    small_table(repeats)
    print("\n### Unequal sample costs: exact branch-and-bound vs brute force (τ = 0.2)\n")
    costs_table(repeats)
    print("\n### 12 unit-cost slots: the Rust kernel and the Python tree (τ = 0.2)\n")
    twelve_table(repeats)
    print("\n### Proven lower bound of best_schedule on larger networks (τ = 0.2)\n")
    large_table(repeats)
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    section(ap.parse_args())


if __name__ == "__main__":
    main()
