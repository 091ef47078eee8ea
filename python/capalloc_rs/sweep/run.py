"""Running a sweep: tasks fed in bounded chunks to an executor, rows collected as chunks finish.

The tasks are the cross product ``networks × capacities``, generated lazily (``networks`` may be a
generator) with their deterministic ids; tasks already saved in the output directory are skipped.
Chunks of ``chunk_size`` tasks are submitted while fewer than the window (``max_pending``) are in
flight; only ``submit`` and ``Future.done``/``Future.result`` are used (dask's futures do not work
with :func:`concurrent.futures.as_completed`). Each finished chunk is written as one part-file (or
kept in memory) at once, so an interruption loses at most the chunks in flight.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import Executor, Future
from concurrent.futures import TimeoutError as FutureTimeoutError
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import SweepError
from ..network import Network
from .columns import arrow, columns, rows_to_table, schema
from .dirlock import DirLock
from .executors import executor_width, own_executor, shut_down
from .networks import checked_networks, known_count, resolve
from .options import SweepOptions, check_task_count
from .rowtable import RowTable
from .store import finish, prepare_out, read_parts, write_part
from .task_ids import task_id
from .tasks import TaskSpec, run_chunk

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["SweepStats", "sweep"]


@dataclass
class SweepStats:
    """Counts of one :func:`sweep` call (also in the table's schema metadata ``capalloc.sweep``).

    Attributes:
        tasks: tasks in the sweep.
        computed: tasks computed by this call.
        skipped: tasks found finished in ``out`` and not recomputed.
        failed: tasks of the final table with an error.
        chunks: part-files (or in-memory chunks) written by this call.
        seconds: wall time of the call.
    """

    tasks: int = 0
    computed: int = 0
    skipped: int = 0
    failed: int = 0
    chunks: int = 0
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """The counts as plain JSON-ready values (``{"tasks", "computed", "skipped", "failed",
        "chunks", "seconds"}``)."""
        return {
            "tasks": int(self.tasks),
            "computed": int(self.computed),
            "skipped": int(self.skipped),
            "failed": int(self.failed),
            "chunks": int(self.chunks),
            "seconds": float(self.seconds),
        }


def _chunks(tasks: Iterator[TaskSpec], size: int) -> Iterator[list[TaskSpec]]:
    buf: list[TaskSpec] = []
    for t in tasks:
        buf.append(t)
        if len(buf) == size:
            yield buf
            buf = []
    if buf:
        yield buf


def _progress_bar(enabled: bool, total: int | None, initial: int) -> Any:
    if not enabled or not sys.stderr.isatty():
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, initial=initial, unit="task", dynamic_ncols=True, smoothing=0.1)


@dataclass
class _Run:
    """The state of one sweep while it runs: its options, counts, progress bar, the ids of the
    tasks it consists of, and the rows (or tables) collected in memory."""

    opts: SweepOptions
    stats: SweepStats
    started: float
    token: str = ""
    sweep_id: str = ""
    done: set[str] = field(default_factory=set)
    wanted: set[str] = field(default_factory=set)
    memory: list[Any] = field(default_factory=list)
    bar: Any = None
    window: int = 1

    def tasks(self, networks: Iterable[Any]) -> Iterator[TaskSpec]:
        """The tasks still to compute, lazily (each id once; saved ones counted as skipped)."""
        o = self.opts
        for idx, item in enumerate(networks):
            net, digest, err = resolve(item)
            for r in o.capacities:
                tid = task_id(idx, r, o.compute, o.params, digest)
                if tid in self.wanted:
                    continue
                self.wanted.add(tid)
                self.stats.tasks += 1
                check_task_count(self.stats.tasks)
                if tid in self.done:
                    self.stats.skipped += 1
                    self._advance(1)
                    continue
                yield TaskSpec(tid, idx, r, digest, net, err)

    def _advance(self, n: int) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def collect(self, fut: Future[Any]) -> None:
        """Saves the rows of a finished chunk (a part-file, or in memory)."""
        try:
            rows = fut.result()
        except Exception as exc:  # the chunk's failure, whatever it was, ends the sweep
            where = (
                f"; finished chunks are saved in {self.opts.out_dir}" if self.opts.out_dir else ""
            )
            raise SweepError(
                f"a sweep worker failed ({type(exc).__name__}: {exc}){where}; "
                "re-run with resume=True to continue"
            ) from exc
        if not self.opts.arrow:  # no pyarrow: plain rows
            self.memory.extend(rows)
        elif self.opts.out_dir is not None:
            sch = schema(self.opts.compute)
            write_part(self.opts.out_dir, rows_to_table(rows, sch), self.token, self.sweep_id)
        else:
            self.memory.append(rows_to_table(rows, schema(self.opts.compute)))
        self.stats.computed += len(rows)
        self.stats.chunks += 1
        self._advance(len(rows))

    def metadata(self) -> dict[bytes, bytes]:
        info = {
            "compute": self.opts.compute,
            "params": dict(self.opts.params),
            "tasks": self.stats.tasks,
            "failed": self.stats.failed,
        }
        return {b"capalloc.sweep": json.dumps(info).encode()}

    def result(self) -> pa.Table | RowTable:
        """The table of every task of the sweep, sorted by task id."""
        if not self.opts.arrow:
            return self._row_table()
        pa = arrow()
        sch = schema(self.opts.compute)
        out = self.opts.out_dir
        tables = read_parts(out, sch) if out is not None else self.memory
        table = finish(pa.concat_tables(tables) if tables else sch.empty_table(), self.wanted)
        self._count_failed(table.num_rows - table.column("error").null_count)
        return table.replace_schema_metadata(self.metadata())

    def _row_table(self) -> RowTable:
        rows = {r["task_id"]: r for r in reversed(self.memory) if r["task_id"] in self.wanted}
        names = [name for name, _ in columns(self.opts.compute)]
        plain = RowTable([rows[t] for t in sorted(rows)], names)
        self._count_failed(plain.num_rows - plain.column("error").null_count)
        plain.metadata = self.metadata()
        return plain

    def _count_failed(self, failed: int) -> None:
        self.stats.failed = failed
        self.stats.seconds = time.perf_counter() - self.started


def _fill(
    ex: Executor, run: _Run, chunks: Iterator[list[TaskSpec]], pending: list[Future[Any]]
) -> bool:
    """Submits chunks while fewer than the window are in flight; whether the chunks ran out."""
    while len(pending) < run.window:
        nxt = next(chunks, None)
        if nxt is None:
            return True
        pending.append(ex.submit(run_chunk, run.opts.compute, dict(run.opts.params), nxt))
    return False


def _drive(
    ex: Executor, run: _Run, chunks: Iterator[list[TaskSpec]], pending: list[Future[Any]]
) -> None:
    """Keeps the window full and collects every chunk as it finishes, until none is left."""
    exhausted = False
    while True:
        exhausted = exhausted or _fill(ex, run, chunks, pending)
        if not pending:
            return
        finished = [f for f in pending if f.done()]
        if not finished:
            # Block briefly on the oldest chunk (no as_completed: dask futures break it); its
            # outcome, exception included, is collected once it is done.
            with contextlib.suppress(FutureTimeoutError, Exception):
                pending[0].result(timeout=0.05)
            continue
        for f in finished:
            pending.remove(f)
            run.collect(f)


def _execute(run: _Run, networks: Iterable[Any]) -> None:
    """Runs the tasks on the caller's executor or the sweep's own (shut down at the end, its
    workers stopped first after an interruption or failure)."""
    o = run.opts
    ex = own_executor(o.workers) if o.executor is None else o.executor
    run.window = o.window(o.workers if o.executor is None else executor_width(ex))
    pending: list[Future[Any]] = []
    completed = False
    try:
        _drive(ex, run, _chunks(run.tasks(networks), o.chunk_size), pending)
        completed = True
    finally:
        for f in pending:
            f.cancel()
        if o.executor is None:
            shut_down(ex, completed=completed)


@contextlib.contextmanager
def _locked(out_dir: Path | None) -> Iterator[DirLock | None]:
    """``out_dir`` created and locked for this sweep (nothing for an in-memory sweep)."""
    if out_dir is None:
        yield None
        return
    if out_dir.exists() and not out_dir.is_dir():
        raise SweepError(f"out = {out_dir} exists and is not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    with DirLock(out_dir) as lock:
        yield lock


def _run(
    networks: Iterable[Any], opts: SweepOptions, lock: DirLock | None, run: _Run
) -> pa.Table | RowTable:
    """The sweep in its (locked) output directory."""
    if opts.out_dir is not None and lock is not None:
        run.token = lock.token
        run.done, run.sweep_id = prepare_out(
            opts.out_dir, opts.compute, dict(opts.params), opts.resume, run.token
        )
    count = known_count(networks)
    run.bar = _progress_bar(
        opts.progress, None if count is None else count * len(opts.capacities), 0
    )
    try:
        _execute(run, networks)
    finally:
        if run.bar is not None:
            run.bar.close()
    return run.result()


def sweep(
    networks: Iterable[Network | str | os.PathLike[str]],
    capacities: Iterable[float],
    *,
    compute: str = "allocation",
    tau: float | None = None,
    which: str = "boundary",
    method: str = "newton",
    tol: float | None = None,
    hessian: str = "auto",
    executor: Executor | None = None,
    workers: int | None = None,
    out: str | os.PathLike[str] | None = None,
    resume: bool = True,
    progress: bool = True,
    chunk_size: int = 16,
    max_pending: int | None = None,
    stats: SweepStats | None = None,
    robust: Mapping[str, Any] | None = None,
) -> pa.Table | RowTable:
    """Runs ``compute`` for every pair of ``networks × capacities`` (see :mod:`capalloc_rs.sweep`).

    Args:
        networks: a sequence or generator of :class:`~capalloc_rs.Network` (or model-file paths,
            loaded in this process; a file that fails to load gives error rows). Consumed lazily.
        capacities: the ``r_tot`` values (finite; duplicates are dropped; integers for
            ``compute="schedule"``).
        compute: ``"allocation"``, ``"filtration"``, ``"schedule"`` or ``"robust"`` (the robust
            allocation over the network with an uncertain coupling strength, see
            :mod:`capalloc_rs.sweep.tasks`; block networks only).
        tau: the period (required) for ``compute="schedule"``.
        which: the figure (``"boundary"``/``"average"``) for ``compute="schedule"``.
        method: the allocation method (default that of
            :func:`~capalloc_rs.allocation.optimal_allocation`).
        tol: the allocation or filtration tolerance (default each function's own).
        hessian: the Newton variant of the allocation (``"auto"``, ``"exact"``, ``"hvp"``; see
            :func:`~capalloc_rs.allocation.optimal_allocation`).
        executor: any :class:`concurrent.futures.Executor` (e.g. a dask ``Client.get_executor()``);
            default a process pool of ``workers`` processes, shut down at the end. An executor
            you pass is not shut down.
        workers: processes of the default executor (default ``os.cpu_count()``).
        out: directory of the Parquet dataset (one part-file per finished chunk); ``None`` keeps
            results in memory only.
        resume: skip tasks already saved in ``out`` (``False``: delete its part-files first).
        progress: show a tqdm progress bar (only on a terminal, and only if tqdm is installed).
        chunk_size: tasks per chunk (per submitted call and per part-file).
        max_pending: chunks in flight at once (default twice the number of workers).
        stats: if given, filled with the counts of this call.
        robust: for ``compute="robust"``: ``{"objective": "mean" | "worst", "num_models": K,
            "eps": [low, high], "seed": s}`` (defaults ``"mean"``, 8, ``[0, 0.3]``, 0): the
            task's models are the network with ε replaced by K values uniform in
            ``[low, high]`` drawn with ``seed`` (the same for every task).

    Returns:
        The table of all tasks (including those skipped on resume), sorted by ``task_id``: a
        :class:`pyarrow.Table`, or without pyarrow (in memory only) a
        :class:`~capalloc_rs.sweep.rowtable.RowTable` with the same rows and columns.

    Raises:
        InvalidInputError: bad arguments.
        SweepError: ``out`` holds a different sweep, or a worker died (finished chunks are saved;
            re-run with ``resume=True``).
        MissingDependencyError: ``out`` is given and pyarrow is not installed.
    """
    started = time.perf_counter()
    opts = SweepOptions.build(
        capacities,
        compute=compute,
        tau=tau,
        which=which,
        method=method,
        tol=tol,
        hessian=hessian,
        executor=executor,
        workers=workers,
        out=out,
        resume=resume,
        progress=progress,
        chunk_size=chunk_size,
        max_pending=max_pending,
        robust=robust,
    )
    nets = checked_networks(networks)
    count = known_count(nets)
    if count is not None:
        check_task_count(count * len(opts.capacities))
    run = _Run(opts, stats if stats is not None else SweepStats(), started)
    with _locked(opts.out_dir) as lock:
        return _run(nets, opts, lock, run)
