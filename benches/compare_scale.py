"""Scale: the reference algorithms against the current ones, side by side in one process.

Every row of the scale table — optimal allocations, filtrations and best schedules of
``Network.random(N, 2, eps=0.05, seed=3)`` — is run twice: with the algorithm the package had before
the scale work (kept selectable by a keyword, named in each row) and with the default one. Printed
per row: both times (best of the repeats), their ratio, and whether the results agree (η, η̄,
breakpoints). Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/compare_scale.py [--only allocation filtration schedule] [--quick]
[--slow-reference]``. ``--quick`` keeps the rows that take seconds; ``--slow-reference`` also runs
the reference schedule search where it takes minutes (N ≥ 50) and the original filtration tracer
(``method="reference"``) next to the continuation's two versions. The filtration rows compare the
continuation's previous version (``method="continuation-v5"``) with the current one, in seconds
and in units of one pointwise ``optimal_allocation`` timed interleaved with them, with the
evaluation points, Hessians (full + principal blocks) and Hessian-vector products of each path.
The schedule rows compare the exhaustive reference with the default, then the screened search's
previous version (``method="screened-v3"``: adjacent swaps, no displacement steps) with the
default; at N = 100 both sides run under ``SCHEDULE_TIME_LIMIT_N100`` (the default stops by
itself within it, ``stopped="stalled"``).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network, best_schedule, filtration, optimal_allocation
from capalloc_rs.allocation.oracle import CountingOracle

#: Keywords that select the reference (pre-scale-work) algorithm of each task.
REFERENCE_ALLOCATION: dict[str, Any] = {"start": "uniform", "engine": "python"}
REFERENCE_FILTRATION: dict[str, Any] = {"method": "continuation-v5"}
#: The original filtration tracer (events by false position on pointwise solves), with
#: ``--slow-reference`` (about a minute at N = 50).
ORIGINAL_FILTRATION: dict[str, Any] = {"method": "reference"}
REFERENCE_SCHEDULE: dict[str, Any] = {"method": "exhaustive"}
#: The screened search as it was before its shifts and displacement steps (adjacent swaps):
#: run at every size, next to the default.
PREVIOUS_SCHEDULE: dict[str, Any] = {"method": "screened-v3"}
#: The N = 100 rows run under this time limit (seconds), both sides: ``"screened-v3"`` takes
#: minutes there (it reaches its 10 000-move budget after about six).
SCHEDULE_TIME_LIMIT_N100 = 60.0


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


def _events_agree(ref: Any, new: Any) -> str:
    """Same events (kind, sensor) and the largest breakpoint difference, relative to max(σ, 1)."""
    if [(e.kind, e.sensor) for e in ref.events] != [(e.kind, e.sensor) for e in new.events]:
        return f"DIFFERENT events: {len(ref.events)} vs {len(new.events)}"
    b_ref = np.array([e.sigma for e in ref.events])
    b_new = np.array([e.sigma for e in new.events])
    diff = float(np.max(np.abs(b_new - b_ref) / np.maximum(np.abs(b_ref), 1.0), initial=0.0))
    return f"{len(b_new)} events, max Δσ {diff:.0e}"


def _counts(net: Network, sigma_max: float, options: dict[str, Any]) -> str:
    """Evaluation points / Hessians (full + principal blocks) / Hessian-vector products of one
    path."""
    oracle = CountingOracle(net)
    filtration(oracle, sigma_max, progress=False, **options)
    c = oracle.counts
    return f"{c['points']}/{c['hessians']}+{c['hessian_blocks']}/{c['hvps']}"


def filtration_rows(cases: list[tuple[int, float]], original: bool) -> list[Row]:
    """The continuation's previous version (``method="continuation-v5"``) against the current one,
    and with ``original`` the original tracer (``method="reference"``) too. The unit is one
    ``optimal_allocation(net, N·r_min + σ_max)``, timed (best of 5) before each path and kept
    at its best, so that both tracers are divided by the same unit."""
    rows = []
    for n_sub, sigma_max in cases:
        net = net_of(n_sub)
        r_tot = n_sub * net.r_min + sigma_max
        rep = 3 if n_sub <= 20 else 2
        t_opt, t_ref, t_new = math.inf, math.inf, math.inf
        ref = new = None
        for _ in range(rep):  # interleaved: the machine's load moves all three alike
            t_opt = min(t_opt, best_of(lambda: optimal_allocation(net, r_tot), 5)[0])  # noqa: B023
            t, ref = best_of(lambda: filtration(net, sigma_max, **REFERENCE_FILTRATION), 1)  # noqa: B023
            t_ref = min(t_ref, t)
            t, new = best_of(lambda: filtration(net, sigma_max), 1)  # noqa: B023
            t_new = min(t_new, t)
        counts = f"{_counts(net, sigma_max, REFERENCE_FILTRATION)} → {_counts(net, sigma_max, {})}"
        note = (
            f"{t_ref / t_opt:.1f} → {t_new / t_opt:.1f} pointwise optima "
            f"({t_opt * 1e3:.1f} ms); points/Hessians+blocks/HVPs {counts}"
        )
        size = f"N = {n_sub}, σ_max = {sigma_max:g}"
        rows.append(
            Row("filtration v5 → current", size, t_ref, t_new, _events_agree(ref, new), note)
        )
        if original:
            t_orig, orig = best_of(lambda: filtration(net, sigma_max, **ORIGINAL_FILTRATION), 1)  # noqa: B023
            note = f"{t_orig / t_opt:.0f} → {t_new / t_opt:.1f} pointwise optima"
            rows.append(
                Row(
                    "filtration original → current",
                    size,
                    t_orig,
                    t_new,
                    _events_agree(orig, new),
                    note,
                )
            )
    return rows


def _verdict(new: Any, ref: Any) -> str:
    verdict = "no worse" if new.eta_bar <= ref.eta_bar * (1 + 1e-12) else "WORSE"
    return f"η̄ {verdict} (Δ/η̄ {(new.eta_bar - ref.eta_bar) / ref.eta_bar:+.1e})"


def previous_schedule_rows(cases: list[tuple[int, int]]) -> list[Row]:
    """The screened search's previous version against the default, one process."""
    rows = []
    for n_sub, r_tot in cases:
        net = net_of(n_sub)
        kw: dict[str, Any] = {"progress": False}
        if n_sub >= 100:
            kw["time_limit"] = SCHEDULE_TIME_LIMIT_N100
        t_old, old = best_of(lambda: best_schedule(net, 0.2, r_tot, **kw, **PREVIOUS_SCHEDULE), 1)  # noqa: B023
        t_new, new = best_of(lambda: best_schedule(net, 0.2, r_tot, **kw), 1)  # noqa: B023
        note = (
            f"moves {old.moves} → {new.moves}, evaluations {old.evaluations} → "
            f"{new.evaluations}, stopped {old.stopped} → {new.stopped}"
        )
        size = f"N = {n_sub}, r_tot = {r_tot}" + (
            f" (time_limit = {SCHEDULE_TIME_LIMIT_N100:g})" if "time_limit" in kw else ""
        )
        rows.append(
            Row(
                "best_schedule screened-v3 → screened",
                size,
                t_old,
                t_new,
                _verdict(new, old),
                note,
            )
        )
    return rows


def schedule_rows(cases: list[tuple[int, int]], slow_reference: bool) -> list[Row]:
    rows = []
    for n_sub, r_tot in cases:
        net = net_of(n_sub)
        run_ref = slow_reference or n_sub <= 20
        kw: dict[str, Any] = {"progress": False}
        if n_sub >= 100:
            kw["time_limit"] = SCHEDULE_TIME_LIMIT_N100
        t_new, new = best_of(lambda: best_schedule(net, 0.2, r_tot, **kw), 1)  # noqa: B023
        t_ref, ref = math.inf, None
        if run_ref:
            t_ref, ref = best_of(
                lambda: best_schedule(net, 0.2, r_tot, **kw, **REFERENCE_SCHEDULE),  # noqa: B023
                1,
            )
        if ref is None:
            agree = f"η̄ {new.eta_bar:.8g}"
        else:
            agree = _verdict(new, ref)
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
            [(5, 15.0), (20, 60.0)] if args.quick else [(5, 15.0), (20, 60.0), (50, 100.0)],
            args.slow_reference,
        )
    if "schedule" in args.only:
        cases = [(5, 15), (10, 30), (20, 60)]
        if not args.quick:
            cases += [(50, 100), (100, 300)]
        rows += schedule_rows(cases, args.slow_reference)
        rows += previous_schedule_rows(cases)
    print("| task | size | reference | current | ratio | results | note |")
    print("|---|---|---:|---:|---:|---|---|")
    for row in rows:
        print(row.line())


if __name__ == "__main__":
    main()
