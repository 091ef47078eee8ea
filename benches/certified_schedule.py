"""How good is a schedule: ``best_schedule(method="exact")`` (branch-and-bound with relaxed
slots) against brute force over every schedule, and the proven lower bound of ``best_schedule``
on larger networks — side by side in one process.

Small cases: ``Network.random(N, n=2, p=1, eps=0.2, seed=11)``, τ = 0.2, both figures; brute
force costs every schedule with every sensor at least once (the paper's case) in the Rust core.
Printed: both wall times (best of ``--repeats``) and their ratio, the nodes the exact search
bounded, both ``η̄`` and whether they agree. Larger cases: ``Network.random(N, 2, eps=0.2,
seed=3)``, ``r_tot = 2N`` (N = 5, 10, 20): the searched ``η̄``, the lower bound and the gap
relative to ``η̄``, with the default bound and with ``certify="grouped"`` (its time is the
whole call, search included). Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/certified_schedule.py [--repeats 3]``; the lead's
``benches/compare_certified.py`` calls :func:`section`.
"""

from __future__ import annotations

import argparse
import itertools
import math
from functools import partial
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network, best_schedule
from capalloc_rs.sampled import sampled_system

SMALL = [(3, 7, "boundary"), (3, 7, "average"), (3, 9, "boundary"), (3, 9, "average")]
SMALL += [(4, 7, "boundary")]
LARGE = [5, 10, 20]
TAU = 0.2


def brute_force(net: Network, r_tot: int, which: str) -> float:
    """The least ``η̄`` over every schedule of ``r_tot`` slots using every sensor."""
    m = sampled_system(net)
    n = m.n_sensors
    best = math.inf
    for s in itertools.product(range(n), repeat=r_tot):
        if len(set(s)) == n:
            best = min(best, float(m.core.cost(TAU, np.asarray(s, dtype=np.int64), which)))
    return best


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


def large_table(repeats: int) -> None:
    print(
        "| N | r_tot | figure | time | η̄ (best_schedule) | lower bound | gap / η̄ "
        "| time grouped | grouped bound | gap / η̄ |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in LARGE:
        net = Network.random(n, 2, eps=0.2, seed=3)
        for which in ("boundary", "average"):
            run = partial(best_schedule, net, TAU, 2 * n, which=which, progress=False)
            t, res = best_of(run, repeats)
            t_g, grp = best_of(partial(run, certify="grouped"), 1)
            print(
                f"| {n} | {2 * n} | {which} | {t:.2f} s | {res.eta_bar:.8g} "
                f"| {res.lower_bound:.8g} | {res.gap / res.eta_bar:.1%} "
                f"| {t_g:.2f} s | {grp.lower_bound:.8g} | {grp.gap / grp.eta_bar:.1%} |"
            )


def section(args: Any) -> None:
    """The Markdown tables of this benchmark (``args.repeats``: best of that many runs)."""
    repeats = int(getattr(args, "repeats", 1))
    print("### Certified schedules: exact branch-and-bound vs brute force (τ = 0.2)\n")
    small_table(repeats)
    print("\n### Proven lower bound of best_schedule on larger networks (τ = 0.2)\n")
    large_table(repeats)
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    section(ap.parse_args())


if __name__ == "__main__":
    main()
