"""Optimal allocation with sample costs, per-sensor minima and caps (the weighted box-simplex),
side by side in one process.

First table — costs alone, ``r_min,i = 1/b_i`` (a common minimum 1 in channel units, no caps):
the box-simplex path on the costed network against the paper's path (``engine="python"``) on the
whitened network with sensors ``c_i/√b_i``, which is the same problem; both must give ``r = s/b``
(``|Δr|/r`` printed) and the time ratio shows what the box path costs over the paper's.

Second table — unequal minima, 30 % of the sensors capped at 80 % of their uncapped optimum: the
exact-Hessian Newton, Newton–CG and (``--pg``) projected gradient, each from ``start="auto"`` (the
projected decoupled optimum) and Newton–CG also from ``start="uniform"``; their rates must agree
to 1e-8 relative.

Networks ``Network.random(N, 2, eps=0.05, seed=1)``, costs uniform in [0.5, 3], budget
``B = Σ b_i r_min,i + 3N``. Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/compare_box.py [--sizes 10 50 100] [--repeat 3] [--pg]``.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network
from capalloc_rs.allocation import optimal_allocation


def _networks(n: int) -> tuple[Any, Any, Any, Any]:
    st = Network.random(n, 2, eps=0.05, seed=1).structure
    rng = np.random.default_rng(n)
    costs = rng.uniform(0.5, 3.0, n)
    blocks = (st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, st.eps)
    costed = Network.from_blocks(*blocks, costs=costs, r_min=1.0 / costs)
    whitened = Network.from_blocks(
        st.a_blocks,
        st.g_blocks,
        [c / np.sqrt(b) for c, b in zip(st.c_blocks, costs, strict=True)],
        st.coupling,
        st.eps,
        r_min=1.0,
    )
    r_min = rng.uniform(0.5, 1.5, n)
    budget = float(costs @ r_min) + 3.0 * n
    free = optimal_allocation(Network.from_blocks(*blocks, costs=costs, r_min=r_min), budget)
    pick = (rng.random(n) < 0.3) & (free.r > r_min + 0.1)
    r_max = np.where(pick, r_min + 0.8 * (free.r - r_min), np.inf)
    capped = Network.from_blocks(*blocks, costs=costs, r_min=r_min, r_max=r_max)
    return costed, whitened, capped, budget


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[10, 50, 100])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pg", action="store_true", help="also projected gradient (slow)")
    args = ap.parse_args()
    print("| N | Hessian | paper path (s) | box path (s) | box/paper | steps | max |Δr|/r |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for n in args.sizes:
        costed, whitened, capped, budget = _networks(n)
        b = np.asarray(costed.costs)
        total = 3.0 * n + n  # Σ b_i r_min,i = N
        for h in ("exact", "hvp"):
            tp, ap_ = best_of(
                lambda h=h, w=whitened, t=total: optimal_allocation(
                    w, t, hessian=h, engine="python"
                ),
                args.repeat,
            )
            tb, ab = best_of(
                lambda h=h, c=costed, t=total: optimal_allocation(c, t, hessian=h), args.repeat
            )
            diff = float(np.max(np.abs(ab.r - ap_.r / b) / ab.r))
            print(
                f"| {n} | {h} | {tp:.3f} | {tb:.3f} | {tb / tp:.2f} | "
                f"{ap_.iterations} / {ab.iterations} | {diff:.1e} |"
            )
        rows.append((n, capped, budget))
    print()
    print("| N | at cap / at minimum | variant | time (s) | steps | products | gap/η |")
    print("|---|---|---|---|---|---|---|")
    for n, capped, budget in rows:
        variants: list[tuple[str, dict[str, Any]]] = [
            ("exact", {"hessian": "exact"}),
            ("hvp", {"hessian": "hvp"}),
            ("hvp, uniform start", {"hessian": "hvp", "start": "uniform"}),
        ]
        if args.pg:
            variants.append(("projected gradient", {"method": "projected-gradient"}))
        ref = None
        for name, kw in variants:
            t, a = best_of(
                lambda kw=kw, c=capped, bb=budget: optimal_allocation(c, bb, **kw), args.repeat
            )
            ref = a if ref is None else ref
            assert np.allclose(a.r, ref.r, rtol=1e-8), name
            print(
                f"| {n} | {len(a.at_cap)} / {len(a.at_minimum)} | {name} | {t:.3f} | "
                f"{a.iterations} | {a.hvp_count} | {a.gap / a.eta:.1e} |"
            )


if __name__ == "__main__":
    main()
