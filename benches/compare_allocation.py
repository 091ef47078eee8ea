"""Optimal allocation: our Newton method against the route a user would otherwise write, and our
three methods against each other — side by side in one process.

The user's route: ``scipy.optimize.minimize(method="SLSQP")`` on η(r) computed with
``scipy.linalg.solve_continuous_are`` and finite-difference gradients (SLSQP's default). Both
must reach the same optimum (relative η difference printed). Networks:
``Network.random(N, 2, eps=0.05)``, r_tot = 3N. Prints a Markdown table.

A second table compares the two Newton variants, the exact Hessian (``hessian="exact"``: SQP,
``N`` Lyapunov solves per step spread over every core) and Newton–CG (``hessian="hvp"``:
Hessian-vector products on one cached ``Network.at`` point, sequential), for the ``--cg`` sizes:
both must reach the same optimum (η to 1e-10 relative, the same active set); reported are the
times (best of ``--cg-repeat`` runs, fewer for N ≥ 100), Newton steps and total products.
Run with ``OPENBLAS_NUM_THREADS=1``.

A third table (``--start``) times the current default against the previous algorithm
(``start="uniform", engine="python"``: Newton from the uniform point, one Rust call per
evaluation) side by side: time old / new, their ratio, the new time in cold-cost equivalents
(one cold ``Network.cost(r)`` and one cold ``value_and_gradient(r)`` at ``r = r_tot/N``),
Newton steps and products, and ``|Δη|/η`` (required ≤ 1e-12, the same active set).

Usage: ``python benches/compare_allocation.py [--sizes 5 20 50] [--big 200] [--cg 50 100 200]
[--start 5 10 20 50 200]`` (``--sizes`` / ``--big`` / ``--cg`` / ``--start`` with no value skip
that part).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import scipy.linalg as sla
from _timing import best_of
from scipy.optimize import minimize

from capalloc_rs import Network
from capalloc_rs.allocation import optimal_allocation


def scipy_cost(net: Network, r: np.ndarray) -> float:
    c = np.hstack(net.sensors)
    w = np.concatenate([np.full(s.shape[1], ri) for s, ri in zip(net.sensors, r, strict=True)])
    return float(np.trace(sla.solve_continuous_are(net.a.T, c, net.q, np.diag(1.0 / w))))


def slsqp(net: Network, r_tot: float) -> tuple[np.ndarray, float]:
    n = len(net.sensors)
    res = minimize(
        lambda r: scipy_cost(net, r),
        np.full(n, r_tot / n),
        method="SLSQP",
        bounds=[(net.r_min, None)] * n,
        constraints=[{"type": "eq", "fun": lambda r: r.sum() - r_tot}],
        options={"ftol": 1e-12, "maxiter": 1000},
    )
    return res.x, float(res.fun)


def fmt_time(t: float) -> str:
    return f"{t * 1e3:.1f} ms" if t < 1.0 else f"{t:.2f} s"


def newton_variants(sizes: list[int], repeat: int) -> None:
    """Newton with the exact Hessian against Newton–CG: same optimum, time, steps, products."""
    print(
        "| N | n | exact Hessian | steps | Newton–CG (HVP) | steps | HVPs (per step) "
        "| exact / CG | Δη/η | max Δr | gap/η exact, CG |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_sub in sizes:
        net = Network.random(n_sub, 2, eps=0.05, seed=n_sub)
        r_tot = 3.0 * n_sub
        rep = repeat if n_sub < 100 else 1
        t_ex, ex = best_of(lambda: optimal_allocation(net, r_tot, hessian="exact"), rep)  # noqa: B023
        t_cg, cg = best_of(lambda: optimal_allocation(net, r_tot, hessian="hvp"), rep)  # noqa: B023
        d_eta = abs(cg.eta / ex.eta - 1)
        same = d_eta <= 1e-10 and np.array_equal(cg.active, ex.active)
        if not same:
            raise SystemExit(f"N = {n_sub}: the variants disagree (Δη/η = {d_eta:.1e})")
        cells = [
            str(n_sub),
            str(net.n),
            fmt_time(t_ex),
            str(ex.iterations),
            fmt_time(t_cg),
            str(cg.iterations),
            f"{cg.hvp_count} ({cg.hvp_count / max(cg.iterations, 1):.1f})",
            f"{t_ex / t_cg:.2f}×",
            f"{d_eta:.0e}",
            f"{float(np.max(np.abs(cg.r - ex.r))):.0e}",
            f"{ex.gap / ex.eta:.0e}, {cg.gap / cg.eta:.0e}",
        ]
        print("| " + " | ".join(cells) + " |", flush=True)


def start_table(sizes: list[int], repeat: int) -> None:
    """The default (decoupled start, warm points, the core loop) against the previous algorithm."""
    print(
        "| N | previous | new | previous / new | new in cold costs (cost, value+gradient) "
        "| steps (prev, new) | HVPs (prev, new) | Δη/η |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_sub in sizes:
        net = Network.random(n_sub, 2, eps=0.05, seed=3)
        r_tot = 3.0 * n_sub
        r = np.full(n_sub, r_tot / n_sub)
        rep = repeat if n_sub < 100 else 1
        t_cost, _ = best_of(lambda: net.cost(r), max(rep, 3))  # noqa: B023
        t_vg, _ = best_of(lambda: net.value_and_gradient(r), max(rep, 3))  # noqa: B023
        old_kw: dict[str, Any] = {"start": "uniform", "engine": "python"}
        t_old, old = best_of(lambda: optimal_allocation(net, r_tot, **old_kw), rep)  # noqa: B023
        t_new, new = best_of(lambda: optimal_allocation(net, r_tot), rep)  # noqa: B023
        d_eta = abs(new.eta / old.eta - 1)
        if d_eta > 1e-12 or not np.array_equal(new.active, old.active):
            raise SystemExit(f"N = {n_sub}: old and new disagree (Δη/η = {d_eta:.1e})")
        cells = [
            str(n_sub),
            fmt_time(t_old),
            fmt_time(t_new),
            f"{t_old / t_new:.2f}×",
            f"{t_new / t_cost:.1f}, {t_new / t_vg:.1f}",
            f"{old.iterations}, {new.iterations}",
            f"{old.hvp_count}, {new.hvp_count}",
            f"{d_eta:.0e}",
        ]
        print("| " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="*", default=[5, 20, 50])
    parser.add_argument("--big", type=int, nargs="*", default=[200])
    parser.add_argument("--cg", type=int, nargs="*", default=[50, 100, 200])
    parser.add_argument("--cg-repeat", type=int, default=3)
    parser.add_argument("--start", type=int, nargs="*", default=[5, 10, 20, 50, 200])
    parser.add_argument("--start-repeat", type=int, default=10)
    args = parser.parse_args()
    if args.start:
        start_table(args.start, args.start_repeat)
        print()
    if args.cg:
        newton_variants(args.cg, args.cg_repeat)
        print()
    if not args.sizes and not args.big:
        return
    rows = []
    for n_sub in args.sizes:
        net = Network.random(n_sub, 2, eps=0.05, seed=n_sub)
        r_tot = 3.0 * n_sub
        rep = 3 if n_sub <= 20 else 1
        t_newton, ours = best_of(lambda: optimal_allocation(net, r_tot), 5)  # noqa: B023
        t_pg, pg = best_of(lambda: optimal_allocation(net, r_tot, method="projected-gradient"), 3)  # noqa: B023
        t_flow, flow = best_of(
            lambda: optimal_allocation(net, r_tot, method="double-bracket"),  # noqa: B023
            1,
        )
        t_slsqp, (_, f_slsqp) = best_of(lambda: slsqp(net, r_tot), rep)  # noqa: B023
        rows.append((n_sub, t_newton, ours, t_pg, pg.eta, t_flow, flow.eta, t_slsqp, f_slsqp))
    for n_sub in args.big:
        net = Network.random(n_sub, 2, eps=0.05, seed=n_sub)
        t_newton, ours = best_of(lambda: optimal_allocation(net, 3.0 * n_sub), 1)  # noqa: B023
        rows.append((n_sub, t_newton, ours, None, None, None, None, None, None))

    head = (
        "| N | newton | its | gap/η | projected-gradient | double-bracket "
        "| SLSQP + scipy CARE + FD | SLSQP / newton | η(SLSQP)/η* − 1 |"
    )
    print(head)
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_sub, t_n, ours, t_pg, eta_pg, t_f, eta_f, t_s, f_s in rows:
        cells = [
            str(n_sub),
            f"{t_n * 1e3:.2f} ms",
            f"{ours.iterations} ({ours.hessian})",
            f"{ours.gap / ours.eta:.1e}",
        ]
        if t_pg is None:
            cells += ["–", "–", "–", "–", "–"]
        else:
            cells += [
                f"{t_pg * 1e3:.2f} ms (Δη {abs(eta_pg / ours.eta - 1):.0e})",
                f"{t_f * 1e3:.0f} ms (Δη {abs(eta_f / ours.eta - 1):.0e})",
                f"{t_s * 1e3:.0f} ms",
                f"{t_s / t_n:.0f}×",
                f"{f_s / ours.eta - 1:.1e}",
            ]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
