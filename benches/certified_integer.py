"""Exact integer counts (P1): branch-and-bound against brute force and today's greedy, side by side
in one process.

For each size ``N`` (``Network.random(N, 2, eps=0.05, seed=3)``, ``r_tot = 3N``, paper's case):
``integer_allocation(method="branch-and-bound")``, ``method="greedy"`` and, for ``N ≤ 5``, brute
force (every composition of ``r_tot`` costed with ``net.cost_many``). The table gives the best
wall time of ``--repeat`` runs, η, the proven lower bound, the gap (absolute and relative to η),
the relaxations solved, the evaluations of η at integer counts (``cost_many`` rows: the greedy's
fill and exchange rounds; the branch-and-bound's rounded start, screened exchanges and node
roundings) and what stopped the search; branch-and-bound is checked never worse than
greedy and equal to brute force where it runs. Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/certified_integer.py [--sizes 4 5 10 20 50] [--repeat 1]
[--time-limit 60]``; :func:`section` prints the table for ``benches/compare_certified.py``.
"""

from __future__ import annotations

import argparse
import itertools
import math
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network
from capalloc_rs.allocation import integer_allocation

BRUTE_MAX_N = 5


def _brute(net: Any, r_tot: int) -> tuple[np.ndarray, float]:
    """The best of every composition of ``r_tot`` into ``N`` positive counts."""
    n = len(net.sensors)
    rows = np.array(
        [
            (*c, r_tot - sum(c))
            for c in itertools.product(range(1, r_tot), repeat=n - 1)
            if sum(c) < r_tot
        ],
        dtype=float,
    )
    vals = np.asarray(net.cost_many(rows))
    i = int(np.argmin(vals))
    return rows[i], float(vals[i])


def _compositions(n: int, r_tot: int) -> int:
    """The number of compositions of ``r_tot`` into ``n`` positive counts (brute force's
    evaluations)."""
    return math.comb(r_tot - 1, n - 1)


def _row(name: str, n: int, t: float, res: Any, ref: float) -> str:
    gap = res.eta - res.lower_bound
    return (
        f"| {n} | {name} | {t:.3f} | {t / ref:.2f} | {res.eta:.12g} | {res.lower_bound:.12g} | "
        f"{gap:.2e} | {gap / abs(res.eta):.1e} | {res.nodes} | {res.evaluations} | "
        f"{res.proven_optimal} | {res.stopped or '—'} |"
    )


def _size(n: int, args: Any) -> None:
    """The table rows of one size."""
    net = Network.random(n, 2, eps=0.05, seed=3)
    r_tot = 3 * n
    t_g, greedy = best_of(lambda: integer_allocation(net, r_tot, method="greedy"), args.repeat)
    t_b, bb = best_of(
        lambda: integer_allocation(
            net, r_tot, method="branch-and-bound", time_limit=args.time_limit
        ),
        args.repeat,
    )
    assert bb.eta <= greedy.eta, (n, bb.eta, greedy.eta)
    print(_row("branch-and-bound", n, t_b, bb, t_g))
    print(_row("greedy", n, t_g, greedy, t_g))
    if n <= BRUTE_MAX_N:
        t_x, (_, best) = best_of(lambda: _brute(net, r_tot), args.repeat)
        assert bb.eta <= best * (1 + 1e-9) and bb.lower_bound <= best, (n, bb, best)
        print(
            f"| {n} | brute force | {t_x:.3f} | {t_x / t_g:.2f} | {best:.12g} | "
            f"{best:.12g} | 0 | 0 | — | {_compositions(n, r_tot)} | True | — |"
        )


def section(args: Any) -> None:
    """Prints the Markdown table (``args``: ``sizes``, ``repeat``, ``time_limit``, each optional:
    defaults 4 5 10 20, 1 and 60 s)."""
    args = argparse.Namespace(
        sizes=getattr(args, "sizes", None) or [4, 5, 10, 20],
        repeat=getattr(args, "repeat", 1),
        time_limit=getattr(args, "time_limit", 60.0),
    )
    print("### Integer counts: branch-and-bound vs brute force vs greedy\n")
    print(
        "| N | method | time [s] | × greedy | η | lower bound | gap | gap/η | nodes | "
        "evaluations | proven | stopped |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        _size(n, args)
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[4, 5, 10, 20, 50])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=60.0)
    section(ap.parse_args())


if __name__ == "__main__":
    main()
