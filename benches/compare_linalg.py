"""Side-by-side timings of capalloc_rs.linalg against scipy.linalg, in one process.

For each size n the same random, well-conditioned problem is solved by both libraries; we report the
median of repeated runs and the ratio scipy/ours (> 1 means we are faster), after checking that both
give the same answer. Usage: ``python benches/compare_linalg.py [--quick] [--markdown]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import scipy.linalg as sla

import capalloc_rs.linalg as cl


def median_time(
    fn: Callable[[], Any], budget: float, min_reps: int = 5, max_reps: int = 2000
) -> float:
    fn()  # warm-up
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < max_reps and (len(times) < min_reps or time.perf_counter() - start < budget):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def care_problem(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    m = max(1, n // 2)
    a = rng.standard_normal((n, n)) / np.sqrt(n)
    b = rng.standard_normal((n, m))
    c = rng.standard_normal((n, n))
    return a, b, c @ c.T / n + np.eye(n), np.eye(m)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="shorter time budget per case")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = parser.parse_args()
    budget = 0.3 if args.quick else 1.5
    rng = np.random.default_rng(0)
    rows: list[tuple[str, int, float, float]] = []
    safety: list[tuple[int, float]] = []

    for n in (4, 8, 16, 64, 200, 400):
        a, b, q, r = care_problem(rng, n)
        x_ours = cl.solve_continuous_are(a, b, q, r)
        x_ref = sla.solve_continuous_are(a, b, q, r)
        assert np.linalg.norm(x_ours - x_ref) <= 1e-8 * np.linalg.norm(x_ref)
        t_ours = median_time(partial(cl.solve_continuous_are, a, b, q, r), budget)
        t_ref = median_time(partial(sla.solve_continuous_are, a, b, q, r), budget)
        rows.append(("care", n, t_ours, t_ref))
        # What balancing and refinement cost: the Schur solution (with its error bound) alone.
        bare = partial(cl.care, a, b, q, r, balance=False, newton_steps=0)
        t_bare = median_time(bare, budget)
        rows.append(("care, bare Schur", n, t_bare, t_ref))
        safety.append((n, t_ours / t_bare - 1.0))

    # The generalised form: E = I + 0.1·N/√n (well conditioned), and the cross term alone.
    for n in (8, 64, 200):
        a, b, q, r = care_problem(rng, n)
        e = np.eye(n) + 0.1 * rng.standard_normal((n, n)) / np.sqrt(n)
        s = 0.1 * rng.standard_normal((n, b.shape[1]))
        q = q + s @ np.linalg.solve(r, s.T)  # Q − S R⁻¹ Sᵀ stays as before: a well-posed problem
        for name, kw in (("care, e=E", {"e": e}), ("care, s=S", {"s": s})):
            x_ours = cl.solve_continuous_are(a, b, q, r, **kw)
            x_ref = sla.solve_continuous_are(a, b, q, r, **kw)
            assert np.linalg.norm(x_ours - x_ref) <= 1e-8 * np.linalg.norm(x_ref)
            t_ours = median_time(partial(cl.solve_continuous_are, a, b, q, r, **kw), budget)
            t_ref = median_time(partial(sla.solve_continuous_are, a, b, q, r, **kw), budget)
            rows.append((name, n, t_ours, t_ref))

    for n in (4, 16, 64, 200):
        a = rng.standard_normal((n, n)) - np.sqrt(n) * np.eye(n)
        q = rng.standard_normal((n, n))
        q = q + q.T
        x_ours = cl.solve_continuous_lyapunov(a, q)
        x_ref = sla.solve_continuous_lyapunov(a, q)
        assert np.linalg.norm(x_ours - x_ref) <= 1e-8 * np.linalg.norm(x_ref)
        t_ours = median_time(partial(cl.solve_continuous_lyapunov, a, q), budget)
        t_ref = median_time(partial(sla.solve_continuous_lyapunov, a, q), budget)
        rows.append(("lyapunov", n, t_ours, t_ref))

    for n in (4, 16, 64, 200):
        a = rng.standard_normal((n, n))
        _, _, sdim = cl.schur(a, sort="lhp")
        _, _, sdim_ref = sla.schur(a, output="real", sort="lhp")
        assert sdim == sdim_ref
        t_ours = median_time(partial(cl.schur, a, sort="lhp"), budget)
        t_ref = median_time(partial(sla.schur, a, output="real", sort="lhp"), budget)
        rows.append(("schur+reorder (lhp)", n, t_ours, t_ref))

    if args.markdown:
        print("| routine | n | capalloc_rs | scipy | scipy / ours |")
        print("|---|---:|---:|---:|---:|")
        for name, n, t_ours, t_ref in rows:
            cells = [name, str(n), f"{t_ours * 1e3:.3f} ms", f"{t_ref * 1e3:.3f} ms"]
            print("| " + " | ".join(cells) + f" | {t_ref / t_ours:.2f}× |")
    else:
        print(f"{'routine':<22}{'n':>5}{'ours [ms]':>12}{'scipy [ms]':>12}{'scipy/ours':>12}")
        for name, n, t_ours, t_ref in rows:
            ratio = t_ref / t_ours
            print(f"{name:<22}{n:>5}{t_ours * 1e3:>12.3f}{t_ref * 1e3:>12.3f}{ratio:>12.2f}")
    print("CARE: cost of balancing + refinement over the Schur solution with its error bound:")
    print("  " + ", ".join(f"n={n}: {100 * c:+.0f} %" for n, c in safety))


if __name__ == "__main__":
    main()
