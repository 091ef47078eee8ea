"""``capalloc demo``: the main job on a built-in network — the optimal allocation with its KKT
certificate, the filtration as the capacity grows, and the best schedule at a finite period with
a Monte Carlo check of its predicted error."""

from __future__ import annotations

import argparse
from typing import Any

from ..allocation import Allocation, filtration, optimal_allocation
from ..network import Network
from ..sampled import best_schedule, simulate
from .output import (
    print_allocation,
    print_filtration,
    print_json,
    print_mc,
    print_schedule,
    save_plot,
)

__all__ = ["demo_network", "run_demo"]


def demo_network() -> Network:
    """The demo's network: ``examples/three_subsystems.toml`` (three weakly coupled subsystems of
    sizes 2, 3, 1, ε = 0.1; subsystem 1's sensor has two outputs), embedded so that ``capalloc
    demo`` needs no file."""
    return Network.from_blocks(
        a_blocks=[
            [[0.0, 1.0], [-4.0, -0.4]],
            [[0.2, 1.0, 0.0], [0.0, -0.5, 1.0], [0.0, 0.0, -1.0]],
            [[-0.3]],
        ],
        g_blocks=[
            [[0.5, 0.0], [0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.3, 1.0, 0.0], [0.0, 0.3, 1.0]],
            [[2.0]],
        ],
        c_blocks=[[1.0, 0.0], [[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]], [0.5]],
        couplings={
            (0, 1): [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
            (1, 2): [[0.0], [0.0], [1.0]],
            (2, 0): [[1.0, -1.0]],
        },
        eps=0.1,
        r_min=1.0,
    )


def _network_dict(net: Network) -> dict[str, Any]:
    return {
        "n": net.n,
        "N": net.num_sensors,
        "eps": net.eps,
        "r_min": net.r_min,
        "outputs": list(net.outputs),
    }


def _print_header(net: Network) -> None:
    print(
        "capalloc demo: three weakly coupled subsystems (n = 2, 3, 1; ε = 0.1; "
        "examples/three_subsystems.toml)"
    )
    rep = net.check()
    print(
        f"  detectable: {rep.detectable}; every subsystem observable: "
        f"{all(s.observable for s in rep.subsystems)}; regular triplets: {rep.regular}"
    )
    print("\n1. Optimal allocation (fast-sampling limit) with its KKT certificate")


def _filtration_step(args: argparse.Namespace, net: Network, text: bool) -> dict[str, Any]:
    """Step 2: the filtration (and its plot, only when asked: the demo writes no file by
    default)."""
    filt = filtration(net, float(args.sigma_max))
    d = filt.to_dict()
    if text:
        print_filtration(filt)
    if args.plot:
        save_plot(filt, args.plot)
        d["plot"] = args.plot
        if text:
            print(f"  plot saved to {args.plot}")
    return d


def _schedule_step(
    args: argparse.Namespace, net: Network, alloc: Allocation, text: bool
) -> dict[str, Any]:
    """Step 3: the best schedule at period ``--tau`` and its Monte Carlo check."""
    r_tot = float(args.r_tot)
    slots = int(round(r_tot))
    best = best_schedule(net, float(args.tau), slots)
    eta_star = alloc.eta if float(slots) == r_tot else None
    d = best.to_dict()
    if eta_star is not None:  # the demo's addition: the continuous optimum at this capacity
        d["eta_star_continuous"] = eta_star
    mc = simulate(
        net, float(args.tau), best.schedule, int(args.periods), int(args.seed), runs=int(args.runs)
    )
    d["monte_carlo"] = mc.to_dict()
    if text:
        print_schedule(best, eta_star)
        print_mc(mc)
    return d


def run_demo(args: argparse.Namespace) -> int:
    """``capalloc demo``: returns the exit status."""
    net = demo_network()
    text = not args.json
    out: dict[str, Any] = {"network": _network_dict(net)}
    if text:
        _print_header(net)
    alloc = optimal_allocation(net, float(args.r_tot))
    out["allocation"] = alloc.to_dict()
    if text:
        print_allocation(alloc)
        print("\n2. Filtration: the optimal allocation as the capacity grows")
    out["filtration"] = _filtration_step(args, net, text)
    if text:
        print(f"\n3. Best schedule at finite period τ = {args.tau:g} vs the fast-sampling limit")
    out["schedule"] = _schedule_step(args, net, alloc, text)
    if not text:
        print_json(out)
    return 0
