"""High-throughput sweeps (package; see :mod:`capalloc_rs.sweep.run`)."""

from __future__ import annotations

from .run import (
    COMPUTES,
    RandomNetworks,
    SerialExecutor,
    SweepSpec,
    SweepStats,
    columns,
    load_spec,
    random_networks,
    read_results,
    schema,
    sweep,
    task_id,
)

__all__ = [
    "COMPUTES",
    "RandomNetworks",
    "SerialExecutor",
    "SweepSpec",
    "SweepStats",
    "load_spec",
    "columns",
    "random_networks",
    "read_results",
    "schema",
    "sweep",
    "task_id",
]
