"""Robust vs nominal allocation under an uncertain coupling (issue 16, point 4), in one process.

The subsystems of ``Network.random(N, 2, seed=seed)`` are known; the coupling is not: model ``k``
is ``A = blockdiag(A_i) + ε_k (C + ½ Δ_k)`` with ``ε_k`` uniform in ``[0, 0.3]``, ``C`` the
coupling of ``Network.random`` and ``Δ_k`` an independent Gaussian matrix of the same pattern and
scale (the uncertain direction of the coupling). Three allocations at ``r_tot = 3N``:

* nominal — :func:`optimal_allocation` for the nominal model ``ε = 0.15``, ``Δ = 0``;
* robust mean — :func:`robust_allocation` with ``objective="mean"`` over 8 training models;
* robust worst — ``objective="worst"`` over the same 8 training models;

each evaluated on 100 held-out models drawn the same way (worst-case and mean η over them), with
its solve time (best of ``--repeat``) and the certified gap of the robust ones (on the training
set). Run with ``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/certified_robust.py [--sizes 5 10 20] [--train 8] [--held-out 100]
[--repeat 3] [--seed 0]``; ``section(args)`` prints the Markdown table
(``benches/compare_certified.py`` calls it; it reads ``args.robust_sizes``, ``train``,
``held_out``, ``repeat`` and ``seed`` when present, else the defaults above).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from _timing import best_of

from capalloc_rs import Network
from capalloc_rs.allocation import optimal_allocation, robust_allocation

EPS_RANGE = (0.0, 0.3)


def models(n: int, count: int, rng: np.random.Generator, seed: int) -> list[Network]:
    """``count`` models of the uncertain coupling (see the module docstring)."""
    st = Network.random(n, 2, eps=0.0, seed=seed).structure
    assert st is not None
    pattern = st.coupling != 0
    scale = float(np.sqrt(st.coupling.shape[0]))
    out = []
    for _ in range(count):
        delta = rng.standard_normal(st.coupling.shape) * pattern / scale
        eps = rng.uniform(*EPS_RANGE)
        c = st.coupling + 0.5 * delta
        out.append(Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, c, eps))
    return out


def nominal(n: int, seed: int) -> Network:
    """The nominal model: ``ε = 0.15``, the coupling ``C`` of ``Network.random``."""
    st = Network.random(n, 2, eps=0.0, seed=seed).structure
    assert st is not None
    return Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, 0.15)


def _held_out(r: Any, tests: list[Network]) -> tuple[float, float]:
    etas = np.array([m.cost(r) for m in tests])
    return float(np.max(etas)), float(np.mean(etas))


def rows(n: int, args: argparse.Namespace) -> list[tuple[Any, ...]]:
    """The table rows of one size: ``(N, name, worst, mean, time, gap)``."""
    seed = int(getattr(args, "seed", 0))
    rng = np.random.default_rng([seed, n])
    train = models(n, int(getattr(args, "train", 8)), rng, seed)
    tests = models(n, int(getattr(args, "held_out", 100)), rng, seed)
    repeat = int(getattr(args, "repeat", 3))
    budget = 3.0 * n
    nom = nominal(n, seed)
    t_nom, a_nom = best_of(lambda: optimal_allocation(nom, budget), repeat)
    t_mean, a_mean = best_of(lambda: robust_allocation(train, budget, objective="mean"), repeat)
    t_worst, a_worst = best_of(lambda: robust_allocation(train, budget, objective="worst"), repeat)
    out = []
    for name, r, t, gap in (
        ("nominal (ε = 0.15)", a_nom.r, t_nom, a_nom.gap / a_nom.eta),
        ("robust mean", a_mean.r, t_mean, a_mean.gap / a_mean.value),
        ("robust worst", a_worst.r, t_worst, a_worst.gap / a_worst.value),
    ):
        worst, mean = _held_out(r, tests)
        out.append((n, name, worst, mean, t, t / t_nom, gap))
    return out


def section(args: argparse.Namespace) -> None:
    """Prints the Markdown table of robust vs nominal allocation (see the module docstring)."""
    sizes = list(getattr(args, "robust_sizes", None) or [5, 10, 20])
    train = int(getattr(args, "train", 8))
    held = int(getattr(args, "held_out", 100))
    print(
        f"### Robust vs nominal allocation: uncertain coupling ε ∈ [0, 0.3] "
        f"({train} training models, {held} held-out)\n"
    )
    print(
        "| N | allocation | worst η (held-out) | mean η (held-out) | time [s] | "
        "time / nominal | certified gap / value |"
    )
    print("|---|---|---|---|---|---|---|")
    for n in sizes:
        for n_, name, worst, mean, t, ratio, gap in rows(n, args):
            print(
                f"| {n_} | {name} | {worst:.6f} | {mean:.6f} | {t:.4f} | {ratio:.1f}× | {gap:.1e} |"
            )
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", dest="robust_sizes", type=int, nargs="*", default=[5, 10, 20])
    ap.add_argument("--train", type=int, default=8)
    ap.add_argument("--held-out", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    section(ap.parse_args())


if __name__ == "__main__":
    main()
