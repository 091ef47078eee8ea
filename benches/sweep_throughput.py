"""Sweep throughput: optimal allocations per second for many random networks.

    python benches/sweep_throughput.py [--count 1000] [--N 5] [--n 2] [--r-tot 10] [--repeat 1]

Compares, on the same ``count`` random block networks (``random_networks(count, N, n, seed=0)``)
at one capacity:

* a plain Python loop over :func:`capalloc_rs.optimal_allocation` (the single-task API), and the
  same loop with the previous algorithm (``start="uniform", engine="python"``: Newton from the
  uniform point, one Rust call per evaluation) — old and new side by side in one process;
* :func:`capalloc_rs.sweep` in-process (:class:`~capalloc_rs.SerialExecutor`: the sweep's own
  overhead — task ids, chunking, Arrow conversion);
* :func:`capalloc_rs.sweep` with a process pool of 1 and of 2 workers (end to end, worker start-up
  included), and with 2 workers writing the Parquet dataset (``out=``).

Every variant must give the same η as the loop (checked: bitwise for the sweeps, to 1e-12
relative for the previous algorithm). Prints a Markdown table (``--json`` for
machine-readable output). Timings are wall clock: on a shared machine, look at the load average
printed with them. Needs pyarrow.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from capalloc_rs import SerialExecutor, optimal_allocation, random_networks, sweep


def _time(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--N", type=int, default=5)
    ap.add_argument("--n", type=int, default=2)
    ap.add_argument("--r-tot", type=float, default=10.0)
    ap.add_argument("--chunk-size", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    nets = list(random_networks(args.count, args.N, args.n, seed=0))
    caps = [args.r_tot]
    kw: dict[str, Any] = {"progress": False, "chunk_size": args.chunk_size}

    def loop() -> np.ndarray:
        return np.array([optimal_allocation(net, args.r_tot).eta for net in nets])

    def loop_previous() -> np.ndarray:
        return np.array(
            [
                optimal_allocation(net, args.r_tot, start="uniform", engine="python").eta
                for net in nets
            ]
        )

    def run_sweep(**extra: Any) -> Callable[[], np.ndarray]:
        def go() -> np.ndarray:
            t = sweep(nets, caps, **kw, **extra)
            assert t.column("error").null_count == t.num_rows, "a task failed"
            return np.asarray(t.column("eta").to_pylist())

        return go

    tmp = tempfile.TemporaryDirectory()
    variants: list[tuple[str, Callable[[], np.ndarray]]] = [
        ("plain Python loop, optimal_allocation", loop),
        ("plain Python loop, previous algorithm", loop_previous),
        ("sweep, in-process (SerialExecutor)", run_sweep(executor=SerialExecutor())),
        ("sweep, 1 worker process", run_sweep(workers=1)),
        ("sweep, 2 worker processes", run_sweep(workers=2)),
        (
            "sweep, 2 workers, Parquet out=",
            run_sweep(workers=2, out=os.path.join(tmp.name, "out"), resume=False),
        ),
    ]
    rows = []
    ref: np.ndarray | None = None
    for name, fn in variants:
        secs, etas = _time(fn, args.repeat)
        if ref is None:
            ref = etas
        elif fn is loop_previous:
            np.testing.assert_allclose(etas, ref, rtol=1e-12, atol=0, err_msg=name)
        else:
            assert np.array_equal(etas, ref), f"{name}: results differ from the loop"
        rows.append({"variant": name, "seconds": secs, "per_second": args.count / secs})
    tmp.cleanup()
    base = rows[0]["per_second"]
    one = rows[3]["per_second"]
    for r in rows:
        r["vs_loop"] = r["per_second"] / base
    info = {
        "count": args.count,
        "N": args.N,
        "n": args.n,
        "r_tot": args.r_tot,
        "chunk_size": args.chunk_size,
        "cpus": os.cpu_count(),
        "loadavg_1min": os.getloadavg()[0],
        "python": platform.python_version(),
        "scaling_2_vs_1_workers": rows[4]["per_second"] / one,
        "loop_new_vs_previous": base / rows[1]["per_second"],
        "rows": rows,
    }
    if args.json:
        print(json.dumps(info, indent=2))
        return
    print(
        f"{args.count} random networks (N = {args.N}, n = {args.n}), r_tot = {args.r_tot:g}; "
        f"{os.cpu_count()} CPUs, load average {info['loadavg_1min']:.2f}"
    )
    print()
    print("| variant | time (s) | allocations/s | vs. loop |")
    print("|---|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['variant']} | {r['seconds']:.2f} | {r['per_second']:.0f} | {r['vs_loop']:.2f}× |"
        )
    print()
    print(f"scaling, 2 workers vs 1: {info['scaling_2_vs_1_workers']:.2f}×")
    print(f"loop, new vs previous algorithm: {info['loop_new_vs_previous']:.2f}×")


if __name__ == "__main__":
    main()
