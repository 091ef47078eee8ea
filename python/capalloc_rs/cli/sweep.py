"""``capalloc sweep SPEC --out DIR``: a sweep spec run in parallel (local processes, or a
dask.distributed cluster with ``--scheduler``) into a resumable Parquet dataset."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any, cast

from .._optional import require
from ..errors import SweepError
from ..sweep import SweepSpec, SweepStats, load_spec
from ..sweep.store import PART_GLOB
from .errors import EXIT_INTERRUPTED
from .output import print_json

__all__ = ["run_sweep"]


def _check_out(args: argparse.Namespace, out: Path) -> None:
    """Results already in ``--out`` need ``--resume`` or ``--overwrite``."""
    has_parts = out.is_dir() and any(out.glob(PART_GLOB))
    if has_parts and not (args.resume or args.overwrite):
        raise SweepError(
            f"{out} already holds sweep results; pass --resume to continue them or --overwrite "
            "to start afresh"
        )


def _connect(args: argparse.Namespace) -> Any:
    """The dask client of ``--scheduler`` (``None`` without it)."""
    if not args.scheduler:
        return None
    Client = require("distributed", "--scheduler").Client
    try:
        return cast(Any, Client)(args.scheduler, timeout=args.connect_timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SweepError(f"cannot connect to the dask scheduler {args.scheduler}: {exc}") from None


def _summary(
    args: argparse.Namespace, spec: SweepSpec, out: Path, stats: SweepStats, rows: int
) -> dict[str, Any]:
    return {
        "spec": args.spec,
        "out": str(out),
        "compute": spec.compute,
        "networks": spec.num_networks,
        "capacities": list(spec.capacities),
        "tasks": stats.tasks,
        "computed": stats.computed,
        "skipped": stats.skipped,
        "failed": stats.failed,
        "part_files_written": stats.chunks,
        "seconds": round(stats.seconds, 3),
        "rows": rows,
    }


def _print_summary(
    args: argparse.Namespace, spec: SweepSpec, out: Path, stats: SweepStats, table: Any
) -> None:
    rate = stats.computed / stats.seconds if stats.seconds > 0 else math.nan
    print(
        f"sweep {args.spec}: {stats.tasks} tasks ({spec.num_networks} networks × "
        f"{len(spec.capacities)} capacities, compute = {spec.compute})"
    )
    print(
        f"  computed {stats.computed}, skipped (already done) {stats.skipped}, "
        f"failed {stats.failed}; {stats.seconds:.2f} s ({rate:.1f} tasks/s)"
    )
    print(f"  results: {out}/ (Parquet dataset; pandas.read_parquet({str(out)!r}))")
    if stats.failed:
        errs = [e for e in table.column("error").to_pylist() if e is not None]
        print(f"  first error: {errs[0]}")


def run_sweep(args: argparse.Namespace) -> int:
    """``capalloc sweep SPEC --out DIR``."""
    spec = load_spec(args.spec)
    out = Path(args.out)
    _check_out(args, out)
    client = _connect(args)
    stats = SweepStats()
    try:
        table = spec.run(
            out=out,
            resume=not args.overwrite,
            executor=None if client is None else client.get_executor(),
            workers=args.workers,
            progress=not args.no_progress,
            stats=stats,
            **({"chunk_size": args.chunk_size} if args.chunk_size else {}),
        )
    except KeyboardInterrupt:
        print(
            f"capalloc: interrupted after {stats.computed} new tasks; finished chunks are saved "
            f"in {out} (continue with --resume)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    finally:
        if client is not None:
            client.close()
    if args.json:
        print_json(_summary(args, spec, out, stats, table.num_rows))
    else:
        _print_summary(args, spec, out, stats, table)
    return 0
