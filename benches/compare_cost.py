"""Side-by-side timings of the cost evaluator against what a user would otherwise write, in one
process.

Networks: ``Network.random(N, n=2, p=1, eps=0.1)`` for N = 5, 20, 50, 200 (state dimension 2N).
For each, the same rate vector is evaluated by

* **ours**: ``net.value_and_gradient(r)`` (one Riccati + one adjoint Lyapunov solve, Rust) and
  ``net.hessian(r)`` (N more Lyapunov solves on one Schur form);
* **scipy + FD**: ``scipy.linalg.solve_continuous_are`` for η and forward differences for the
  gradient (N + 1 Riccati solves, step ``1e-6·r_i``) — what one writes without derivatives;
* **scipy + adjoint**: scipy's CARE plus the same adjoint formula with
  ``scipy.linalg.solve_continuous_lyapunov`` — what one writes after reading docs/concepts.md;
* for the Hessian, **scipy analytic**: scipy's CARE and N + 1 scipy Lyapunov solves with the
  Hessian formula vectorised in numpy;
* for batches, ``net.cost_many`` / ``net.value_and_gradient_many`` on K rate vectors against a
  Python loop of our own one-at-a-time calls (bitwise identical results are checked); the two are
  timed alternately and the speed-up is the median of the per-pair ratios.

Times are medians of repeats (at least ``--min-reps``, within a time budget per case); ratios are
baseline time / our time (> 1: we are faster). When a baseline would take too long (the FD routes
at N = 200) it is timed as (number of Riccati solves) × (median time of one scipy CARE), and marked
``*``. Results of every route are checked against each other before timing.

Our single evaluations run on one thread, so BLAS is limited to one thread as well (set before
numpy is imported; override with ``OPENBLAS_NUM_THREADS`` etc. in the environment). Batches use
every core.

Usage: ``python benches/compare_cost.py [--quick] [--markdown] [--sizes 5 20 50]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import scipy.linalg as sla  # noqa: E402
from compare_linalg import median_time as _median_time  # noqa: E402

import capalloc_rs as cr  # noqa: E402

F = np.ndarray


def median_time(
    fn: Callable[[], Any], budget: float, min_reps: int = 3, max_reps: int = 1000
) -> float:
    """compare_linalg's timer with this script's repeat bounds."""
    return _median_time(fn, budget, min_reps, max_reps)


def paired_times(
    base: Callable[[], Any], ours: Callable[[], Any], budget: float, min_reps: int = 3
) -> tuple[float, float, float]:
    """Medians of alternating runs of ``base`` and ``ours``, and the median of the per-pair ratios
    (robust when the machine's load changes during the run)."""
    base()
    ours()
    tb: list[float] = []
    to: list[float] = []
    start = time.perf_counter()
    while len(tb) < min_reps or time.perf_counter() - start < budget:
        t0 = time.perf_counter()
        base()
        t1 = time.perf_counter()
        ours()
        t2 = time.perf_counter()
        tb.append(t1 - t0)
        to.append(t2 - t1)
    ratio = statistics.median(b / o for b, o in zip(tb, to, strict=True))
    return statistics.median(tb), statistics.median(to), ratio


# -- the baselines -----------------------------------------------------------------------------


class ScipyRoute:
    """η, ∇η and ∇²η written with scipy (filter-form CARE as scipy's control form)."""

    def __init__(self, net: cr.Network) -> None:
        self.a, self.q = np.array(net.a), np.array(net.q)
        self.c = np.array(net.sensor_matrix)
        self.sensors = [np.array(c) for c in net.sensors]
        self.outputs = net.outputs
        self.n = net.n

    def sigma(self, r: F) -> F:
        rinv = np.concatenate([np.full(p, 1.0 / ri) for p, ri in zip(self.outputs, r, strict=True)])
        return sla.solve_continuous_are(self.a.T, self.c, self.q, np.diag(rinv))

    def cost(self, r: F) -> float:
        return float(np.trace(self.sigma(r)))

    def value_gradient_fd(self, r: F) -> tuple[float, F]:
        f0 = self.cost(r)
        g = np.empty(len(r))
        for i in range(len(r)):
            h = 1e-6 * r[i]
            rp = r.copy()
            rp[i] += h
            g[i] = (self.cost(rp) - f0) / h
        return f0, g

    def _adjoint(self, r: F) -> tuple[F, F, F, F, list[F]]:
        s = self.sigma(r)
        u = [s @ c for c in self.sensors]
        w = sum(ri * c @ c.T for ri, c in zip(r, self.sensors, strict=True))
        acl = self.a - s @ w
        y = sla.solve_continuous_lyapunov(acl.T, -np.eye(self.n))
        return s, w, acl, y, u

    def value_gradient_adjoint(self, r: F) -> tuple[float, F]:
        s, _, _, y, u = self._adjoint(r)
        return float(np.trace(s)), np.array([-np.sum(ui * (y @ ui)) for ui in u])

    def hessian(self, r: F) -> F:
        s, w, acl, y, u = self._adjoint(r)
        sp = np.stack([sla.solve_continuous_lyapunov(acl, ui @ ui.T) for ui in u])  # (N, n, n)
        wsy = np.einsum("ab,ibc,cd->iad", w, sp, y, optimize=True)  # W Σ'_i Y
        t1 = np.einsum("iab,jba->ij", wsy, sp, optimize=True)  # tr(Y Σ'_i W Σ'_j)
        yu = np.column_stack([y @ ui for ui in u])  # Y Σ ĉ_j
        cmat = np.column_stack(self.sensors)  # p = 1 here
        # tr(Y Σ'_i C_j Σ) = ĉ_jᵀ Σ'_i (Y Σ ĉ_j)
        t2 = np.einsum("aj,iab,bj->ij", cmat, sp, yu, optimize=True)
        return -2.0 * (t1 + t2 + t2.T)


# -- the run -----------------------------------------------------------------------------------


def fmt_ms(t: float, est: bool = False) -> str:
    s = f"{t * 1e3:.3g}" if t < 1 else f"{t * 1e3:,.0f}"
    return s + ("*" if est else "")


def run_size(nn: int, budget: float, min_reps: int, fd_limit: float) -> tuple[list[str], list[str]]:
    """The two table rows (single evaluations, batches) for N = nn."""
    net = cr.Network.random(nn, n=2, p=1, eps=0.1, seed=nn)
    r = np.random.default_rng(nn).uniform(0.5, 3.0, nn)
    ref = ScipyRoute(net)
    big = nn >= 200
    reps = 1 if big else min_reps
    b = budget if not big else 0.0

    # correctness, side by side
    v, g = net.value_and_gradient(r)
    v_s, g_s = ref.value_gradient_adjoint(r)
    assert abs(v - v_s) <= 1e-9 * abs(v_s) and np.allclose(g, g_s, rtol=1e-7, atol=0)
    t_care = median_time(lambda: ref.sigma(r), b, reps)
    fd_est = (nn + 1) * t_care > fd_limit
    if not fd_est:
        _, g_fd = ref.value_gradient_fd(r)
        assert np.allclose(g, g_fd, rtol=1e-3, atol=0), np.abs(g / g_fd - 1).max()

    t_ours = median_time(lambda: net.value_and_gradient(r), b, reps)
    if fd_est:
        t_fd = (nn + 1) * t_care
    else:
        t_fd = median_time(lambda: ref.value_gradient_fd(r), b, reps)
    t_adj = median_time(lambda: ref.value_gradient_adjoint(r), b, reps)

    h = net.hessian(r)
    h_s = ref.hessian(r)
    assert np.linalg.norm(h - h_s) <= 1e-8 * np.linalg.norm(h_s)
    t_hess = median_time(lambda: net.hessian(r), b, reps)
    t_hess_s = median_time(lambda: ref.hessian(r), b, reps)
    single_row = [
        str(nn),
        str(2 * nn),
        fmt_ms(t_ours),
        fmt_ms(t_fd, fd_est),
        f"{t_fd / t_ours:,.0f}" + ("*" if fd_est else ""),
        fmt_ms(t_adj),
        f"{t_adj / t_ours:.1f}",
        fmt_ms(t_hess),
        fmt_ms(t_hess_s),
        f"{t_hess_s / t_hess:.1f}",
    ]

    # batches against our own one-at-a-time calls
    k = 4 if big else 32
    rates = np.random.default_rng(nn + 1).uniform(0.5, 3.0, (k, nn))
    vals = net.cost_many(rates)
    vals2, grads = net.value_and_gradient_many(rates)
    for i in range(k):
        assert vals[i] == net.cost(rates[i])
        vi, gi = net.value_and_gradient(rates[i])
        assert vals2[i] == vi and np.array_equal(grads[i], gi)

    def loop_cost() -> None:
        for row in rates:
            net.cost(row)

    def loop_vg() -> None:
        for row in rates:
            net.value_and_gradient(row)

    t_loop_c, t_many_c, q_c = paired_times(loop_cost, lambda: net.cost_many(rates), b, reps)
    t_loop_g, t_many_g, q_g = paired_times(
        loop_vg, lambda: net.value_and_gradient_many(rates), b, reps
    )
    batch_row = [
        str(nn),
        str(k),
        fmt_ms(t_loop_c),
        fmt_ms(t_many_c),
        f"{q_c:.2f}",
        fmt_ms(t_loop_g),
        fmt_ms(t_many_g),
        f"{q_g:.2f}",
    ]
    return single_row, batch_row


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="shorter time budget per case")
    parser.add_argument("--markdown", action="store_true", help="print Markdown tables")
    parser.add_argument("--sizes", type=int, nargs="+", default=[5, 20, 50, 200])
    parser.add_argument("--min-reps", type=int, default=3)
    parser.add_argument(
        "--fd-limit",
        type=float,
        default=60.0,
        help="seconds: slower FD baselines are estimated from one-CARE timings",
    )
    args = parser.parse_args()
    budget = 0.3 if args.quick else 2.0
    single: list[list[str]] = []
    batch: list[list[str]] = []

    for nn in args.sizes:
        row1, row2 = run_size(nn, budget, args.min_reps, args.fd_limit)
        single.append(row1)
        batch.append(row2)
        print(f"N = {nn} done", flush=True)

    head1 = [
        "N",
        "n",
        "ours η+∇η (ms)",
        "scipy CARE+FD (ms)",
        "ratio",
        "scipy CARE+adjoint (ms)",
        "ratio",
        "ours ∇²η (ms)",
        "scipy ∇²η analytic (ms)",
        "ratio",
    ]
    head2 = [
        "N",
        "K",
        "loop cost (ms)",
        "cost_many (ms)",
        "speed-up",
        "loop η+∇η (ms)",
        "value_and_gradient_many (ms)",
        "speed-up",
    ]
    blas = os.environ.get("OPENBLAS_NUM_THREADS")
    print(
        f"\ncores: {os.cpu_count()}; numpy {np.__version__}, OPENBLAS_NUM_THREADS={blas}; "
        "ratios = baseline / ours"
    )
    for head, rows in ((head1, single), (head2, batch)):
        if args.markdown:
            print("| " + " | ".join(head) + " |")
            print("|" + "---|" * len(head))
            for row in rows:
                print("| " + " | ".join(row) + " |")
        else:
            widths = [max(len(x) for x in col) for col in zip(head, *rows, strict=True)]
            for row in [head, *rows]:
                print("  ".join(x.rjust(w) for x, w in zip(row, widths, strict=True)))
        print()
    print("* estimated as (N + 1) × one scipy CARE (the full FD run would exceed --fd-limit)")


if __name__ == "__main__":
    main()
