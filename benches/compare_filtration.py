"""Tracing the filtration exactly vs. the obvious alternative: a 1,000-point grid of pointwise
optimal allocations (our Newton), and for small N the same grid with the SLSQP + scipy-CARE +
finite-difference route (timed on 40 points and scaled to 1,000, labelled as such).

Breakpoint accuracy: a grid locates a breakpoint only to its spacing; the traced breakpoints are
located by root-finding. The reference breakpoints come from bisection on pointwise Newton solutions
to 1e-12. Usage: ``python benches/compare_filtration.py [--sizes 5 20]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from compare_allocation import slsqp

from capalloc_rs import Network
from capalloc_rs.allocation import filtration, optimal_allocation


def bisect_breakpoint(net: Network, j: int, lo: float, hi: float) -> float:
    n = len(net.sensors)
    for _ in range(80):
        if hi - lo <= 1e-12 * max(hi, 1.0):
            break
        mid = 0.5 * (lo + hi)
        on = optimal_allocation(net, mid + n * net.r_min).gamma[j] > 0
        lo, hi = (lo, mid) if on else (mid, hi)
    return 0.5 * (lo + hi)


def grid_breakpoints(net: Network, grid: np.ndarray, gammas: np.ndarray) -> dict[int, float]:
    out: dict[int, float] = {}
    for j in range(gammas.shape[1]):
        on = np.flatnonzero(gammas[:, j] > 1e-9)
        if on.size and on[0] > 0:
            out[j] = 0.5 * (grid[on[0] - 1] + grid[on[0]])
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="*", default=[5, 20])
    parser.add_argument("--points", type=int, default=1000)
    args = parser.parse_args()
    print(
        "| N | σ_max | breakpoints | trace | max bp error (trace) | Newton grid "
        f"({args.points} pts) | max bp error (grid) | grid / trace | SLSQP grid (est.) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_sub in args.sizes:
        net = Network.random(n_sub, 2, eps=0.05, seed=n_sub)
        sigma_max = 3.0 * n_sub
        t0 = time.perf_counter()
        f = filtration(net, sigma_max)
        t_trace = time.perf_counter() - t0
        grid = np.linspace(0.0, sigma_max, args.points)
        t0 = time.perf_counter()
        gammas = np.array([optimal_allocation(net, s + n_sub).gamma for s in grid])
        t_grid = time.perf_counter() - t0
        grid_bp = grid_breakpoints(net, grid, gammas)
        err_trace, err_grid = 0.0, 0.0
        for k, s_k in enumerate(f.breakpoints[1:-1], start=1):
            j = f.events[k].sensor
            ref = bisect_breakpoint(net, j, max(s_k - 0.1, 0.0), s_k + 0.1)
            err_trace = max(err_trace, abs(s_k - ref))
            if j in grid_bp:
                err_grid = max(err_grid, abs(grid_bp[j] - ref))
        slsqp_cell = "–"
        if n_sub <= 5:
            pts = np.linspace(0.0, sigma_max, 40)
            t0 = time.perf_counter()
            for s in pts:
                slsqp(net, s + n_sub)
            t_s = (time.perf_counter() - t0) * args.points / pts.size
            slsqp_cell = f"{t_s:.0f} s ({t_s / t_trace:.0f}× trace)"
        print(
            f"| {n_sub} | {sigma_max:g} | {f.breakpoints.size - 2} | {t_trace * 1e3:.0f} ms | "
            f"{err_trace:.1e} | {t_grid:.2f} s | {err_grid:.1e} | {t_grid / t_trace:.0f}× | "
            f"{slsqp_cell} |"
        )


if __name__ == "__main__":
    main()
