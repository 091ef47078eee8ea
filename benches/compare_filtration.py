"""The filtration by continuation (the default) against the reference tracer
(``method="reference"``), side by side in one process, in seconds and in units of one pointwise
optimal allocation of the same network (``optimal_allocation(net, N·r_min + σ_max)``, timed in the
same process): ``Network.random(N, 2, eps=0.05, seed=3)`` traced to σ_max = 15, 60, 100 at
N = 5, 20, 50. Both paths are checked to agree (events, active sets, breakpoints) and the cost is
also given as counts of evaluation points, Hessians and Hessian-vector products.

Usage: ``python benches/compare_filtration.py [--sizes 5 20 50] [--repeats 3]
[--reference-repeats 1]`` (the reference takes about a minute at N = 50; ``--no-reference``
skips it). Time with ``OPENBLAS_NUM_THREADS=1``; best of the repeats.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.allocation.oracle import CountingOracle

SIGMA_MAX = {5: 15.0, 20: 60.0, 50: 100.0}


def counts(net: Network, sigma_max: float) -> str:
    c = CountingOracle(net)
    filtration(c, sigma_max, progress=False)
    return f"{c.counts['points']} / {c.counts['hessians']} / {c.counts['hvps']}"


def agreement(new: Any, ref: Any) -> str:
    same = [(e.kind, e.sensor) for e in new.events] == [(e.kind, e.sensor) for e in ref.events]
    if not (same and new.active_sets == ref.active_sets):
        return "DIFFERENT events"
    rel = np.abs(new.breakpoints - ref.breakpoints) / np.maximum(np.abs(ref.breakpoints), 1.0)
    return f"same; max bp diff {float(np.max(rel)):.1e} rel"


def row(n_sub: int, args: argparse.Namespace) -> str:
    net = Network.random(n_sub, 2, eps=0.05, seed=3)
    sigma_max = SIGMA_MAX.get(n_sub, 2.0 * n_sub)
    r_tot = n_sub * net.r_min + sigma_max
    # Interleaved, best of each: both see the same load.
    t_opt, t_new, new = float("inf"), float("inf"), None
    for _ in range(args.repeats):
        t_opt = min(t_opt, best_of(lambda: optimal_allocation(net, r_tot), 2)[0])
        t, new = best_of(lambda: filtration(net, sigma_max, progress=False), 1)
        t_new = min(t_new, t)
    cells = [
        f"{n_sub}",
        f"{sigma_max:g}",
        f"{new.breakpoints.size - 2}",
        f"{t_opt * 1e3:.1f} ms",
        f"{t_new:.3f} s",
        f"{t_new / t_opt:.1f}",
        counts(net, sigma_max),
    ]
    if args.no_reference:
        return "| " + " | ".join([*cells, "–", "–", "–", "–"]) + " |"
    # The reference is counted in its (first) timed run: the counting costs microseconds.
    counted = CountingOracle(net)
    t_ref, ref = best_of(
        lambda: filtration(counted, sigma_max, progress=False, method="reference"),
        args.reference_repeats,
    )
    runs = max(args.reference_repeats, 1)
    c = {k: v // runs for k, v in counted.counts.items()}
    cells += [
        f"{t_ref:.2f} s",
        f"{t_ref / t_opt:.0f}",
        f"{c['points']} / {c['hessians']} / {c['hvps']}",
        agreement(new, ref),
    ]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="*", default=[5, 20, 50])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--reference-repeats", type=int, default=1)
    parser.add_argument("--no-reference", action="store_true")
    args = parser.parse_args()
    print(
        "| N | σ_max | breakpoints | one optimal allocation | continuation | ÷ allocation | "
        "points / Hessians / HVPs | reference | ÷ allocation | points / Hessians / HVPs | "
        "paths |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for n_sub in args.sizes:
        print(row(n_sub, args), flush=True)


if __name__ == "__main__":
    main()
