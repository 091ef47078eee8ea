"""Allocation with sample costs and rate limits: ours against the routes a user would otherwise
take — side by side in one process.

Problem: minimise ``η(r) = tr Σ(r)`` over ``{Σ b_i r_i = B, r_min,i ≤ r_i ≤ r_max,i}`` on
``Network.random(N, 2, eps=0.05, seed)`` with sample costs ``b_i ∈ [0.5, 3]``, minima
``r_min,i ∈ [0.5, 2]`` and caps on every third sensor (``r_min,i + 0.3``, so they bind), budget
``B = Σ b_i r_min,i + N``.

Routes:

* ours — ``optimal_allocation(net, B)`` (Newton on the box-simplex with a certificate);
* SDP — the convex SDP ``min tr T`` s.t. ``[[T, I], [I, Y]] ⪰ 0`` and the Riccati LMI
  ``[[YA + AᵀY − Σ r_i ĉ_i ĉ_iᵀ, YG], [GᵀY, −I]] ⪯ 0`` in ``Y = Σ⁻¹`` with the box and the budget,
  solved by cvxpy + Clarabel (tolerances 1e-10; skipped when cvxpy is missing or for ``N`` above
  ``--sdp-max``);
* SLSQP — ``scipy.optimize.minimize(method="SLSQP")`` with the bounds and the budget as a linear
  equality, η from ``scipy.linalg.solve_continuous_are`` and finite-difference gradients.

Printed per N: each route's time (best of ``--repeat``), the ratio to ours, and ``(η_route −
η_ours)/η_ours`` (positive: the route's point is worse), plus our certificate gap. Run with
``OPENBLAS_NUM_THREADS=1``.

Usage: ``python benches/compare_constrained.py [--sizes 3 5 10 20] [--sdp-max 10] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import importlib.util
from typing import Any

import numpy as np
import scipy.linalg as sla
from _timing import best_of
from scipy.optimize import minimize

from capalloc_rs import Network
from capalloc_rs.allocation import optimal_allocation


def constrained_network(n_sens: int, seed: int) -> tuple[Network, float]:
    """The benchmark network of ``n_sens`` sensors and its budget ``B``."""
    base = Network.random(n_sens, 2, eps=0.05, seed=seed)
    rng = np.random.default_rng(seed)
    costs = rng.uniform(0.5, 3.0, n_sens)
    lo = rng.uniform(0.5, 2.0, n_sens)
    hi = np.where(np.arange(n_sens) % 3 == 2, lo + 0.3, np.inf)
    st = base.structure
    assert st is not None
    net = Network.from_blocks(
        st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, st.eps, lo, costs=costs, r_max=hi
    )
    return net, float(costs @ lo + n_sens)


def scipy_cost(net: Network, r: np.ndarray) -> float:
    c = np.hstack(net.sensors)
    w = np.concatenate([np.full(s.shape[1], ri) for s, ri in zip(net.sensors, r, strict=True)])
    return float(np.trace(sla.solve_continuous_are(net.a.T, c, net.q, np.diag(1.0 / w))))


def slsqp(net: Network, budget: float) -> np.ndarray:
    b, lo, hi = net.costs, net.rate_min, net.rate_max
    x0 = lo + (budget - b @ lo) / b.sum()
    res = minimize(
        lambda r: scipy_cost(net, r),
        np.minimum(x0, np.where(np.isinf(hi), x0, hi)),
        method="SLSQP",
        bounds=[(float(a), None if np.isinf(c) else float(c)) for a, c in zip(lo, hi, strict=True)],
        constraints=[{"type": "eq", "fun": lambda r: b @ r - budget}],
        options={"ftol": 1e-12, "maxiter": 500},
    )
    return np.asarray(res.x)


def sdp(net: Network, budget: float) -> np.ndarray:
    import cvxpy as cp

    n, nn = net.n, net.num_sensors
    y = cp.Variable((n, n), symmetric=True)
    t = cp.Variable((n, n), symmetric=True)
    r = cp.Variable(nn)
    info = sum(r[i] * (net.sensors[i] @ net.sensors[i].T) for i in range(nn))
    ric = cp.bmat([[y @ net.a + net.a.T @ y - info, y @ net.g], [net.g.T @ y, -np.eye(n)]])
    cons = [
        cp.bmat([[t, np.eye(n)], [np.eye(n), y]]) >> 0,
        (ric + ric.T) / 2 << 0,
        net.costs @ r == budget,
        r >= net.rate_min,
    ]
    capped = np.isfinite(net.rate_max)
    if capped.any():
        cons.append(r[np.flatnonzero(capped)] <= net.rate_max[capped])
    prob = cp.Problem(cp.Minimize(cp.trace(t)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    return np.asarray(r.value)


def row(n_sens: int, args: Any) -> str:
    net, budget = constrained_network(n_sens, seed=n_sens)
    t_ours, res = best_of(lambda: optimal_allocation(net, budget), args.repeat)
    cells = [f"{n_sens}", f"{t_ours * 1e3:.1f} ms", f"{res.gap:.1e}"]
    routes = [("SLSQP", slsqp)]
    if importlib.util.find_spec("cvxpy") is not None and n_sens <= args.sdp_max:
        routes.append(("SDP", sdp))
    for _, fn in routes:
        t, r = best_of(lambda fn=fn: fn(net, budget), 1 if n_sens > 5 else args.repeat)
        eta = net.cost(np.clip(r, net.rate_min, net.rate_max))  # solvers may overstep by 1e-10
        cells += [f"{t * 1e3:.0f} ms", f"{t / t_ours:.0f}×", f"{(eta - res.eta) / res.eta:+.1e}"]
    if len(routes) == 1:
        cells += ["–", "–", "–"]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="*", default=[3, 5, 10, 20])
    p.add_argument("--sdp-max", type=int, default=10)
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    print("| N | ours | our certified gap | SLSQP | ratio | Δη/η | SDP (Clarabel) | ratio | Δη/η |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_sens in args.sizes:
        print(row(n_sens, args), flush=True)


if __name__ == "__main__":
    main()
