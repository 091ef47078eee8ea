"""Scale: the reference algorithms against the current ones, side by side in one process.

Every row of the scale table — optimal allocations, filtrations and best schedules of
``Network.random(N, 2, eps=0.05, seed=3)`` — is run twice: with the algorithm the package had before
the scale work (kept selectable by a keyword, named in each row) and with the default one. Printed
per row: both times (best of the repeats), their ratio, and whether the results agree (η, η̄,
breakpoints). Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/compare_scale.py [--only allocation filtration schedule] [--quick]
[--slow-reference]``. ``--quick`` keeps the rows that take seconds; ``--slow-reference`` also runs
the reference schedule search where it takes minutes (N ≥ 50).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network, best_schedule, filtration, optimal_allocation

#: Keywords that select the reference (pre-scale-work) algorithm of each task.
REFERENCE_ALLOCATION: dict[str, Any] = {"start": "uniform", "engine": "python"}
REFERENCE_FILTRATION: dict[str, Any] = {"method": "reference"}
REFERENCE_SCHEDULE: dict[str, Any] = {"method": "exhaustive"}


def fmt_time(t: float) -> str:
    if not math.isfinite(t):
        return "not run"
    return f"{t * 1e3:.2f} ms" if t < 1.0 else f"{t:.2f} s"


def rel(a: float, b: float) -> float:
    return abs(a - b) / max(abs(b), 1e-300)


@dataclass
class Row:
    task: str
    size: str
    ref: float
    new: float
    agree: str
    note: str = ""

    def line(self) -> str:
        ratio = f"{self.ref / self.new:.1f}×" if math.isfinite(self.ref) else "—"
        return (
            f"| {self.task} | {self.size} | {fmt_time(self.ref)} | {fmt_time(self.new)} | {ratio} "
            f"| {self.agree} | {self.note} |"
        )


def net_of(n_sub: int) -> Network:
    return Network.random(n_sub, 2, eps=0.05, seed=3)


def allocation_rows(sizes: list[int]) -> list[Row]:
    rows = []
    for n_sub in sizes:
        net = net_of(n_sub)
        r_tot = 3.0 * n_sub
        rep = 20 if n_sub <= 10 else 5 if n_sub <= 50 else 1
        t_cold, _ = best_of(lambda: net.cost(np.full(n_sub, 3.0)), rep)  # noqa: B023
        t_ref, ref = best_of(
            lambda: optimal_allocation(net, r_tot, **REFERENCE_ALLOCATION),  # noqa: B023
            rep,
        )
        t_new, new = best_of(lambda: optimal_allocation(net, r_tot), rep)  # noqa: B023
        agree = f"Δη/η {rel(new.eta, ref.eta):.0e}, max Δr {np.max(np.abs(new.r - ref.r)):.0e}"
        note = f"{t_ref / t_cold:.1f} → {t_new / t_cold:.1f} cold costs"
        rows.append(
            Row("optimal_allocation", f"N = {n_sub}, r_tot = {r_tot:g}", t_ref, t_new, agree, note)
        )
    return rows


def filtration_rows(cases: list[tuple[int, float]]) -> list[Row]:
    rows = []
    for n_sub, sigma_max in cases:
        net = net_of(n_sub)
        rep = 3 if n_sub <= 5 else 1
        t_opt, _ = best_of(lambda: optimal_allocation(net, n_sub * net.r_min + sigma_max), 3)  # noqa: B023
        t_ref, ref = best_of(lambda: filtration(net, sigma_max, **REFERENCE_FILTRATION), rep)  # noqa: B023
        t_new, new = best_of(lambda: filtration(net, sigma_max), rep)  # noqa: B023
        b_ref = np.array([e.sigma for e in ref.events])
        b_new = np.array([e.sigma for e in new.events])
        if b_ref.shape == b_new.shape:
            diff = float(
                np.max(np.abs(b_new - b_ref) / np.maximum(np.abs(b_ref), 1.0), initial=0.0)
            )
            agree = f"{len(b_new)} events, max Δσ {diff:.0e}"
        else:
            agree = f"DIFFERENT events: {len(b_ref)} vs {len(b_new)}"
        note = f"{t_ref / t_opt:.0f} → {t_new / t_opt:.1f} pointwise optima"
        rows.append(
            Row("filtration", f"N = {n_sub}, σ_max = {sigma_max:g}", t_ref, t_new, agree, note)
        )
    return rows


def schedule_rows(cases: list[tuple[int, int]], slow_reference: bool) -> list[Row]:
    rows = []
    for n_sub, r_tot in cases:
        net = net_of(n_sub)
        run_ref = slow_reference or n_sub <= 20
        t_new, new = best_of(lambda: best_schedule(net, 0.2, r_tot, progress=False), 1)  # noqa: B023
        t_ref, ref = math.inf, None
        if run_ref:
            t_ref, ref = best_of(
                lambda: best_schedule(net, 0.2, r_tot, progress=False, **REFERENCE_SCHEDULE),  # noqa: B023
                1,
            )
        if ref is None:
            agree = f"η̄ {new.eta_bar:.8g}"
        else:
            verdict = "no worse" if new.eta_bar <= ref.eta_bar * (1 + 1e-12) else "WORSE"
            agree = f"η̄ {verdict} (Δ/η̄ {(new.eta_bar - ref.eta_bar) / ref.eta_bar:+.1e})"
        note = f"moves {ref.moves if ref else '—'} → {new.moves}, stopped {new.stopped}"
        rows.append(
            Row("best_schedule", f"N = {n_sub}, r_tot = {r_tot}", t_ref, t_new, agree, note)
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--only", nargs="*", default=["allocation", "filtration", "schedule"])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--slow-reference", action="store_true")
    args = ap.parse_args()
    rows: list[Row] = []
    if "allocation" in args.only:
        rows += allocation_rows([5, 10, 20, 50] if args.quick else [5, 10, 20, 50, 200])
    if "filtration" in args.only:
        rows += filtration_rows(
            [(5, 15.0), (20, 60.0)] if args.quick else [(5, 15.0), (20, 60.0), (50, 100.0)]
        )
    if "schedule" in args.only:
        cases = [(5, 15), (10, 30), (20, 60)]
        if not args.quick:
            cases += [(50, 100), (100, 300)]
        rows += schedule_rows(cases, args.slow_reference)
    print("| task | size | reference | current | ratio | results | note |")
    print("|---|---|---:|---:|---:|---|---|")
    for row in rows:
        print(row.line())


if __name__ == "__main__":
    main()
