"""Periodic steady state of a sampled schedule: doubling (capalloc_rs) against the fixed-point
iteration a user would write (numpy, slot by slot, period after period).

Problem: four weakly coupled scalar subsystems (n = 4, N = 4 sensors; ``a_i`` = −0.25 … −0.4,
coupling 0.05, sensors ``ĉ_i = 0.05 e_i``, ``G = I``), period τ = 0.02, ``r_tot`` = 10, 100, 1000
slots, round-robin schedule. The slow closed loop (time constant ≈ 3) is what makes the plain
iteration need thousands of periods at this τ.

* **reference**: ``sampled_covariance`` (doubling), cross-checked against capalloc's own Rust
  fixed-point iteration run to a relative change of 1e-15.
* **numpy iteration**: ``S ← E S Eᵀ + H``, ``S ← S − S c (cᵀ S c + 1)⁻¹ cᵀ S`` per slot, from S = 0.
  To compare at *equal accuracy* it is stopped by an oracle at the first period whose iterate is
  within ``max(1e-12, 3·d)`` (relative, Frobenius) of the reference, ``d`` the disagreement between
  doubling and the Rust iteration (the rounding floor of the problem: ≈ 1e-12 at r_tot = 1000,
  where one period is 1000 slot maps with ``E ≈ I``) — the least work any stopping rule could do, so
  the ratio is a lower bound. (A user's rule, relative change ≤ tol, needs more periods.)
* **doubling**: ``capalloc_rs.sampled_cost`` (boundary), including input validation and the
  Proposition 1 checks; ``sampled_covariance`` adds the per-slot covariances.
* **Rust iteration**: the same fixed-point iteration in Rust, for the algorithmic factor alone.

Usage: ``python benches/compare_sampled.py [--quick] [--markdown] [--extended]``. ``--quick``
skips ``r_tot = 1000`` for the numpy iteration (it takes tens of seconds); ``--extended`` also
measures both methods against the fixed point of the same slot maps iterated in extended precision
(``numpy.longdouble``; minutes).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from capalloc_rs import Network, Schedule, sampled_cost, sampled_covariance
from capalloc_rs.sampled import discretise, fixed_point_iteration

TAU = 0.02
ACCURACY = 1e-12


def median_time(fn: Callable[[], Any], budget: float, min_reps: int = 5) -> float:
    fn()
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < min_reps or time.perf_counter() - start < budget:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def numpy_iteration(
    e: np.ndarray,
    h: np.ndarray,
    cs: list[np.ndarray],
    ref: np.ndarray,
    accuracy: float,
    max_periods: int,
) -> tuple[int, float, float]:
    """The user's loop; returns (periods to reach ``accuracy``, achieved error, seconds)."""
    n = e.shape[0]
    s = np.zeros((n, n))
    nref = np.linalg.norm(ref)
    t0 = time.perf_counter()
    for k in range(1, max_periods + 1):
        for c in cs:
            s = e @ s @ e.T + h
            sc = s @ c
            s = s - sc @ np.linalg.solve(c.T @ sc + np.eye(c.shape[1]), sc.T)
        err = float(np.linalg.norm(s - ref) / nref)
        if err <= accuracy:
            return k, err, time.perf_counter() - t0
    raise RuntimeError("numpy iteration did not reach the accuracy")


def bench_network() -> Network:
    rng = np.random.default_rng(3)
    a = np.diag([-0.25, -0.3, -0.35, -0.4]) + 0.05 * rng.standard_normal((4, 4)) * (1 - np.eye(4))
    sensors = [0.05 * np.eye(4)[:, [i]] for i in range(4)]
    return Network(a, np.eye(4), sensors)


def extended_reference(
    e: np.ndarray, h: np.ndarray, cs: list[np.ndarray], max_periods: int = 100_000
) -> np.ndarray:
    """The fixed point of the same slot maps (same double-precision E, H, c̄) iterated in
    ``numpy.longdouble`` until the change is below 1e-19."""
    el, hl = e.astype(np.longdouble), h.astype(np.longdouble)
    cl = [c.astype(np.longdouble)[:, 0] for c in cs]
    s = np.zeros_like(el)
    for _ in range(max_periods):
        old = s.copy()
        for c in cl:
            s = el @ s @ el.T + hl
            sc = s @ c
            s = s - np.outer(sc, sc) / (1 + c @ sc)
        if np.linalg.norm((s - old).astype(float)) <= 1e-19 * np.linalg.norm(s.astype(float)):
            break
    return s


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--markdown", action="store_true")
    parser.add_argument("--extended", action="store_true")
    args = parser.parse_args()
    budget = 0.3 if args.quick else 1.0
    net = bench_network()
    rows = []
    for r_tot in (10, 100, 1000):
        sched = Schedule.round_robin(4, r_tot)
        cov = sampled_covariance(net, TAU, sched)
        ref = cov.boundary
        rust_ref, rust_periods = fixed_point_iteration(net, TAU, sched, tol=1e-15)
        agree = float(np.linalg.norm(rust_ref - ref) / np.linalg.norm(ref))
        t_dbl = median_time(lambda s=sched: sampled_cost(net, TAU, s), budget)
        t_cov = median_time(lambda s=sched: sampled_covariance(net, TAU, s), budget)
        t_rust_it = median_time(
            lambda s=sched: fixed_point_iteration(net, TAU, s, tol=1e-15), budget, min_reps=3
        )
        accuracy = max(ACCURACY, 3 * agree)
        d = discretise(net, TAU, r_tot)
        e, h = np.asarray(d.E), np.asarray(d.H)
        cs = [np.asarray(d.cbar[i]) for i in sched]
        if args.quick and r_tot > 100:
            periods, err, t_np = rust_periods, float("nan"), float("nan")
        else:
            periods, err, t_np = numpy_iteration(e, h, cs, ref, accuracy, 10 * rust_periods + 1000)
        ext_dbl = ext_it = float("nan")
        if args.extended:
            x = extended_reference(e, h, cs)
            nx = float(np.linalg.norm(x.astype(float)))
            ext_dbl = float(np.linalg.norm((ref - x).astype(float))) / nx
            ext_it = float(np.linalg.norm((rust_ref - x).astype(float))) / nx
        rows.append(
            dict(
                r_tot=r_tot,
                periods=periods,
                steps=cov.doubling_steps,
                agree=agree,
                accuracy=accuracy,
                ext_dbl=ext_dbl,
                ext_it=ext_it,
                err=err,
                t_np=t_np,
                t_dbl=t_dbl,
                t_cov=t_cov,
                t_rust_it=t_rust_it,
            )
        )
    hdr = (
        "| r_tot | accuracy | iteration periods | doubling steps | numpy iteration | "
        "doubling (`sampled_cost`) | speed-up | `sampled_covariance` | "
        "Rust iteration (Δ ≤ 1e-15) | doubling vs Rust iteration |"
    )
    if args.markdown:
        print(hdr)
        print("|" + "---|" * 10)
    for r in rows:
        speed = r["t_np"] / r["t_dbl"]
        cells = [
            f"{r['r_tot']}",
            f"{r['accuracy']:.0e}",
            f"{r['periods']}",
            f"{r['steps']}",
            f"{r['t_np'] * 1e3:.1f} ms",
            f"{r['t_dbl'] * 1e6:.0f} µs",
            f"{speed:,.0f}×",
            f"{r['t_cov'] * 1e6:.0f} µs",
            f"{r['t_rust_it'] * 1e3:.2f} ms",
            f"{r['agree']:.1e}",
        ]
        if args.markdown:
            print("| " + " | ".join(cells) + " |")
        else:
            print(
                f"r_tot={r['r_tot']:5d} periods={r['periods']:5d} steps={r['steps']:2d} "
                f"numpy={r['t_np'] * 1e3:9.1f} ms (err {r['err']:.1e}) "
                f"doubling={r['t_dbl'] * 1e6:7.0f} µs speed-up={speed:9,.0f}x "
                f"covariance={r['t_cov'] * 1e6:7.0f} µs rust-iter={r['t_rust_it'] * 1e3:8.2f} ms "
                f"(rust-iter/doubling {r['t_rust_it'] / r['t_dbl']:,.0f}x, agree {r['agree']:.1e})"
            )
        if args.extended:
            print(
                f"  r_tot={r['r_tot']}: vs extended-precision fixed point: doubling "
                f"{r['ext_dbl']:.1e}, Rust iteration {r['ext_it']:.1e}"
            )


if __name__ == "__main__":
    main()
