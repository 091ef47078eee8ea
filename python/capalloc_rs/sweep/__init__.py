"""High-throughput sweeps: many (network, capacity) tasks, in parallel, resumable.

:func:`sweep` runs one task per pair of the cross product ``networks × capacities`` and returns a
:class:`pyarrow.Table` with one row per task (``table.to_pandas()`` for pandas; both come with
``pip install 'capalloc-rs[sweep]'``). Without pyarrow an in-memory sweep still runs and returns
a :class:`~capalloc_rs.sweep.rowtable.RowTable` with the same rows and columns; Parquet output
(``out=``) needs pyarrow. What a task computes is chosen by ``compute``, and its row holds the
result's ``to_dict()`` — the dict the CLI prints with ``--json`` — flattened into columns by
:func:`~capalloc_rs.sweep.columns.flatten` (a nested key is the path joined with ``"."``, as
:func:`pandas.json_normalize` names it: ``certificate.frank_wolfe_gap``):

* ``"allocation"`` — :func:`capalloc_rs.allocation.optimal_allocation` at ``r_tot``: every key of
  :meth:`~capalloc_rs.Allocation.to_dict` (``eta``, ``r``, ``gamma``, ``gradient``, ``mu``,
  ``active``, ``certificate.frank_wolfe_gap``, ``certificate.kkt_residual``, ``iterations``, …,
  ``budget``, ``costs``, ``at_minimum``, ``at_cap``, ``lower_multipliers``,
  ``upper_multipliers``; for a network with sample costs or rate limits ``r_tot`` is the budget
  B in channel units);
* ``"filtration"`` — :func:`capalloc_rs.allocation.filtration` up to ``σ_max = r_tot − N·r_min``
  (with sample costs or rate limits ``r_tot`` is the budget B and ``σ_max = B − Σ b_i r_min,i``):
  every key of :meth:`~capalloc_rs.Filtration.to_dict` (``breakpoints``, ``active_sets``,
  ``entry_order``, ``events``, ``is_monotone``, ``is_filtration``, ``capped_sets``, …) and
  ``eta``, ``r``, ``mu``, ``shadow_price`` (−μ) at ``σ_max``;
* ``"schedule"`` — :func:`capalloc_rs.sampled.best_schedule` at period ``tau`` with ``r_tot``
  slots: every key of :meth:`~capalloc_rs.BestSchedule.to_dict` (``schedule``, ``counts``,
  ``eta_bar``, ``eta_limit``, ``relative_error_vs_limit``, ``baselines.greedy``, …) but its wall
  time ``elapsed`` (rows are deterministic); ``eta`` is ``eta_bar``.

Every row also has ``task_id``, ``network_index``, ``r_tot``, ``network_digest`` (a hash of the
network's data), ``num_sensors`` and ``error`` (``None``, or ``"ExceptionClass: message"`` for a
task that failed — a failing task never stops the sweep).

**Task ids** are deterministic: ``"{network_index:08d}-{r_tot as 16 order-preserving hex digits}-
{12 hex digits of SHA-256(network_index, r_tot, compute, parameters, network digest)}"``, so sorting
by ``task_id`` sorts by network, then capacity; the returned table is always sorted by it,
whatever the completion order. A changed network or parameter gives a new id, never a stale row.

**Execution.** Tasks are grouped in chunks of ``chunk_size`` and submitted to an executor: by
default a process pool with ``workers`` processes (the heavy kernels are in Rust and release the
GIL, but the optimisation loops are Python) — or, when the sweep is called from a script's top level
without ``if __name__ == "__main__":`` (whose worker processes would re-run the script), a thread
pool of that size with one :class:`~capalloc_rs.errors.UnguardedMainWarning`; any
:class:`concurrent.futures.Executor` works unchanged — in particular
``dask.distributed.Client(address).get_executor()`` to go past one machine. Only ``submit`` and
``Future.done``/``Future.result`` are used (dask's futures do not work with
:func:`concurrent.futures.as_completed`). At most ``max_pending`` chunks are in flight, and
``networks`` may be a generator: it is consumed lazily, so memory stays bounded by the window (plus
the result table itself).

**Nothing lost.** With ``out=DIR`` each finished chunk is written as one Parquet part-file
``DIR/part-*.parquet``, atomically (a temporary file, flushed and fsynced, then renamed), as soon
as it completes. ``DIR/_sweep.json`` records what the sweep computes. Re-running the same sweep
with ``resume=True`` (the default) skips every task whose id is in a part-file — including tasks
that failed; use ``resume=False`` to start afresh — and returns the same table as an
uninterrupted run: an interrupted sweep (Ctrl-C, killed process, crashed worker) loses at most
the chunks in flight.

**Modules.** :mod:`~capalloc_rs.sweep.spec` (spec files), :mod:`~capalloc_rs.sweep.options`
(checked arguments), :mod:`~capalloc_rs.sweep.networks`, :mod:`~capalloc_rs.sweep.task_ids`,
:mod:`~capalloc_rs.sweep.tasks` (the worker side), :mod:`~capalloc_rs.sweep.columns`,
:mod:`~capalloc_rs.sweep.executors`, :mod:`~capalloc_rs.sweep.run` (the driving loop),
:mod:`~capalloc_rs.sweep.store` (the output directory) with :mod:`~capalloc_rs.sweep.dirlock`,
and :mod:`~capalloc_rs.sweep.rowtable` (the table without pyarrow).
"""

from __future__ import annotations

from .columns import columns, schema
from .executors import SerialExecutor
from .networks import RandomNetworks, random_networks
from .run import SweepStats, sweep
from .spec import SweepSpec, load_spec
from .store import read_results
from .task_ids import task_id
from .tasks import COMPUTES

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
