"""Schedule search: the screened search (``best_schedule``'s default) against the exhaustive one
(``method="exhaustive"``), side by side in one process.

Networks ``Network.random(N, 2, eps=0.05, seed=3)``, period τ = 0.2, ``r_tot`` = 3N (N = 5, 10,
20), N = 50 with ``r_tot`` = 100 and N = 100 with ``r_tot`` = 300. Printed per case: both wall
times (best of ``--repeats``) and their ratio, both ``η̄`` and their relative difference, moves,
exact evaluations and why each search stopped. The exhaustive search is run only where it takes
seconds unless ``--slow-reference`` (N = 50: minutes; N = 100: hours). Run with
``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/compare_schedule.py [--sizes 5 10 20 50 100] [--repeats 3]
[--slow-reference]``.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

from capalloc_rs import BestSchedule, Network, best_schedule

R_TOT = {5: 15, 10: 30, 20: 60, 50: 100, 100: 300}


def timed(method: str, net: Network, r_tot: int, repeats: int) -> tuple[float, BestSchedule]:
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = best_schedule(net, 0.2, r_tot, progress=False, method=method)
        best = min(best, time.perf_counter() - t0)
    assert out is not None
    return best, out


def line(n: int, r_tot: int, new: tuple[float, Any], ref: tuple[float, Any] | None) -> str:
    t_new, b_new = new
    cells = [f"N = {n}, r_tot = {r_tot}", f"{t_new:.2f} s"]
    if ref is None:
        cells += ["not run", "—", f"{b_new.eta_bar:.10g}", "—", "—"]
    else:
        t_ref, b_ref = ref
        diff = (b_new.eta_bar - b_ref.eta_bar) / b_ref.eta_bar
        cells += [
            f"{t_ref:.2f} s",
            f"{t_ref / t_new:.1f}×",
            f"{b_new.eta_bar:.10g}",
            f"{b_ref.eta_bar:.10g}",
            f"{diff:+.1e}",
        ]
    ref_moves = "—" if ref is None else f"{ref[1].moves} / {ref[1].evaluations}"
    cells += [f"{b_new.moves} / {b_new.evaluations}", ref_moves, b_new.stopped]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="*", default=[5, 10, 20, 50, 100])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--slow-reference", action="store_true")
    args = ap.parse_args()
    print(
        "| case | screened | exhaustive | ratio | η̄ screened | η̄ exhaustive | Δ/η̄ "
        "| moves / evals (screened) | moves / evals (exhaustive) | stopped |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        r_tot = R_TOT.get(n, 3 * n)
        net = Network.random(n, 2, eps=0.05, seed=3)
        reps = args.repeats if n <= 20 else 1
        new = timed("screened", net, r_tot, reps)
        ref = None
        if n <= 20 or args.slow_reference:
            ref = timed("exhaustive", net, r_tot, 1 if n >= 20 else reps)
        print(line(n, r_tot, new, ref), flush=True)


if __name__ == "__main__":
    main()
