"""High-throughput sweeps: many (network, capacity) tasks, in parallel, resumable.

:func:`sweep` runs one task per pair of the cross product ``networks × capacities`` and returns a
:class:`pyarrow.Table` with one row per task (``table.to_pandas()`` for pandas; both come with
``pip install 'capalloc-rs[sweep]'``). Without pyarrow an in-memory sweep still runs and returns a
:class:`~capalloc_rs._rowtable.RowTable` with the same rows and columns; Parquet output (``out=``)
needs pyarrow. What a task computes is chosen by ``compute``:

* ``"allocation"`` — :func:`capalloc_rs.allocation.optimal_allocation` at ``r_tot``
  (columns ``eta``, ``r``, ``gamma``, ``gradient``, ``mu``, ``active``, ``gap``, ``kkt_residual``,
  ``iterations``);
* ``"filtration"`` — :func:`capalloc_rs.filtration.filtration` up to ``σ_max = r_tot − N·r_min``
  (``breakpoints``, ``active_sets``, ``entry_order``, ``is_monotone``, ``is_filtration``, and
  ``eta``, ``r``, ``mu`` at ``σ_max``);
* ``"schedule"`` — the best schedule at period ``tau`` with ``r_tot`` slots (``schedule``,
  ``counts``, ``eta_bar``, ``eta_limit`` — the fast-sampling cost of the same counts —,
  ``relative_error``, ``converged``; ``eta`` is ``eta_bar``).

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
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import multiprocessing
import os
import signal
import struct
import sys
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeoutError
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from .. import limits
from .._arrays import MAX_SEED, as_count, as_real
from .dirlock import DirLock, is_dead_debris, tmp_name
from .mainguard import unguarded_call
from .._optional import require
from .rowtable import RowTable
from .tasks import COMPUTES, TaskSpec, run_chunk, sampled_api
from .._textdata import finite_float, read_data
from .._unchecked import warn_outside
from ..allocation import HESSIAN_MODES, METHODS, one_of
from ..errors import (
    InvalidInputError,
    MissingDependencyError,
    SweepError,
    UnguardedMainWarning,
)
from ..network import Network

if TYPE_CHECKING:
    import pyarrow as pa

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

MANIFEST = "_sweep.json"
#: The manifest key (and part-file metadata key) of a sweep's identity.
SWEEP_ID = "sweep_id"
_PART_GLOB = "part-*.parquet"
_TMP_PREFIX = ".tmp-part-"


def _pa() -> Any:
    pyarrow = require("pyarrow", "a sweep's Parquet output")
    require("pyarrow.parquet", "a sweep's Parquet output")
    return pyarrow


# -- schema -----------------------------------------------------------------------------------


def columns(compute: str) -> list[tuple[str, str]]:
    """The columns of a sweep's table for ``compute``: ``(name, Arrow type name)`` pairs (also
    the keys of the rows of an in-memory sweep without pyarrow)."""
    fl, i64 = "list<float64>", "list<int64>"
    common = [
        ("task_id", "string"),
        ("network_index", "int64"),
        ("r_tot", "int64" if compute == "schedule" else "float64"),  # slots, or a capacity
        ("network_digest", "string"),
        ("num_sensors", "int64"),
        ("error", "string"),
        ("eta", "float64"),
        ("r", fl),
        ("mu", "float64"),
    ]
    extra: dict[str, list[tuple[str, str]]] = {
        "allocation": [
            ("gamma", fl),
            ("gradient", fl),
            ("active", i64),
            ("gap", "float64"),
            ("kkt_residual", "float64"),
            ("iterations", "int64"),
        ],
        "filtration": [
            ("sigma_max", "float64"),
            ("breakpoints", fl),
            ("active_sets", "list<list<int64>>"),
            ("entry_order", i64),
            ("is_monotone", "bool"),
            ("is_filtration", "bool"),
        ],
        "schedule": [
            ("tau", "float64"),
            ("schedule", i64),
            ("counts", i64),
            ("eta_bar", "float64"),
            ("eta_limit", "float64"),
            ("relative_error", "float64"),
            ("converged", "bool"),
        ],
    }
    if compute not in extra:
        raise InvalidInputError(f"compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    fields = common + extra[compute]
    if compute == "schedule":  # schedules have no rates or multiplier
        fields = [f for f in fields if f[0] not in ("r", "mu")]
    return fields


def schema(compute: str) -> pa.Schema:
    """The Arrow schema of a sweep's table for ``compute`` (see :func:`columns`)."""
    pa = _pa()
    f64, i64 = pa.float64(), pa.int64()
    types = {
        "string": pa.string(),
        "int64": i64,
        "float64": f64,
        "bool": pa.bool_(),
        "list<float64>": pa.list_(f64),
        "list<int64>": pa.list_(i64),
        "list<list<int64>>": pa.list_(pa.list_(i64)),
    }
    return pa.schema([(name, types[t]) for name, t in columns(compute)])


def _have_pyarrow() -> bool:
    try:
        _pa()
    except MissingDependencyError:
        return False
    return True


def _rows_to_table(rows: Sequence[Mapping[str, Any]], sch: pa.Schema) -> pa.Table:
    pa = _pa()
    cols = {name: [row.get(name) for row in rows] for name in sch.names}
    return pa.Table.from_pydict(cols, schema=sch)


# -- task ids ---------------------------------------------------------------------------------


def _sortable(x: float) -> str:
    """16 hex digits whose string order is the numeric order of the float ``x``."""
    (bits,) = struct.unpack(">Q", struct.pack(">d", float(x)))
    bits = bits ^ 0xFFFFFFFFFFFFFFFF if bits >> 63 else bits | (1 << 63)
    return f"{bits:016x}"


def task_id(
    network_index: int, r_tot: float, compute: str, params: Mapping[str, Any], digest: str
) -> str:
    """The deterministic id of a task (see the module docstring)."""
    key = json.dumps(
        [int(network_index), repr(float(r_tot)), compute, dict(params), digest],
        sort_keys=True,
        separators=(",", ":"),
    )
    h = hashlib.sha256(key.encode()).hexdigest()[:12]
    return f"{int(network_index):08d}-{_sortable(r_tot)}-{h}"


def _digest(net: Network) -> str:
    return net._key()[:16]


# -- executors --------------------------------------------------------------------------------


class SerialExecutor(Executor):
    """Runs each submitted call immediately in the calling thread (debugging, baselines)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        fut: Future[Any] = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # delivered through the future like a real executor
            fut.set_exception(exc)
        return fut


def _executor_width(ex: Any) -> int:
    """How many calls ``ex`` runs at once, as far as it tells (dask: its cluster's threads)."""
    client = getattr(ex, "_client", None)
    if client is not None:
        with contextlib.suppress(Exception):
            return max(1, int(sum(client.nthreads().values())))
    return int(getattr(ex, "_max_workers", 0) or os.cpu_count() or 1)


def _stop_workers(ex: Executor) -> None:
    """Terminates the worker processes of our own process pool (their chunks are lost; finished
    chunks are saved)."""
    procs = getattr(ex, "_processes", None) or {}
    for proc in list(procs.values()):
        with contextlib.suppress(Exception):
            proc.terminate()


def _worker_init() -> None:
    """Pool workers leave Ctrl-C to the driver, which cancels the sweep cleanly (a terminal sends
    SIGINT to the whole process group)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _own_executor(n_workers: int) -> Executor:
    """The default executor: a process pool, or threads when the sweep was started from a
    script's top level without ``if __name__ == "__main__":`` (its worker processes would re-run
    the script; see :mod:`capalloc_rs._mainguard`), with one warning saying so."""
    where = unguarded_call()
    if where is None:
        return ProcessPoolExecutor(
            max_workers=n_workers, mp_context=_default_context(), initializer=_worker_init
        )
    warn_outside(
        f"sweep called at {where} outside 'if __name__ == \"__main__\":', where worker "
        f"processes would re-run the script: running in {n_workers} threads of this process "
        "instead (same results; put the script's code under that guard for worker processes)",
        UnguardedMainWarning,
    )
    return ThreadPoolExecutor(max_workers=n_workers)


def _default_context() -> Any:
    # Never fork a process that may hold Rust (rayon) threads: forkserver where available.
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


# -- networks ---------------------------------------------------------------------------------


class RandomNetworks(Sequence[Network]):
    """A lazy, sized sequence of reproducible random block networks (see :func:`random_networks`):
    network ``k`` is built when it is accessed, so iterating over a million of them holds one at a
    time, and ``len`` gives progress bars their total."""

    def __init__(
        self,
        count: int,
        num_subsystems: int,
        n: int = 2,
        p: int = 1,
        eps: float = 0.1,
        seed: int = 0,
        r_min: float = 1.0,
    ) -> None:
        self.size = as_count("count", count)
        self.num_subsystems = num_subsystems
        self.n, self.p, self.eps, self.r_min = n, p, eps, r_min
        self.seed = as_count("seed", seed, maximum=MAX_SEED)
        if self.size:
            self._build(0)  # validate the parameters now

    def seed_of(self, k: int) -> int:
        """The ``Network.random`` seed of network ``k``."""
        return int(np.random.SeedSequence([self.seed, k]).generate_state(1, np.uint64)[0])

    def _build(self, k: int) -> Network:
        return Network.random(
            self.num_subsystems, self.n, self.p, self.eps, seed=self.seed_of(k), r_min=self.r_min
        )

    def __len__(self) -> int:
        return self.size

    @overload
    def __getitem__(self, k: int) -> Network: ...
    @overload
    def __getitem__(self, k: slice) -> list[Network]: ...
    def __getitem__(self, k: int | slice) -> Network | list[Network]:
        if isinstance(k, slice):
            return [self._build(i) for i in range(*k.indices(self.size))]
        i = int(k) + (self.size if int(k) < 0 else 0)
        if not 0 <= i < self.size:
            raise IndexError(f"network index {k} out of range for {self.size} networks")
        return self._build(i)

    def __repr__(self) -> str:
        return (
            f"RandomNetworks(size={self.size}, num_subsystems={self.num_subsystems}, "
            f"n={self.n}, p={self.p}, eps={self.eps}, seed={self.seed}, r_min={self.r_min})"
        )


def random_networks(
    count: int,
    num_subsystems: int,
    n: int = 2,
    p: int = 1,
    eps: float = 0.1,
    seed: int = 0,
    r_min: float = 1.0,
) -> RandomNetworks:
    """``count`` reproducible random block networks, as a lazy sequence: network ``k`` is
    ``Network.random(num_subsystems, n, p, eps, seed=s_k, r_min=r_min)`` with ``s_k`` drawn from
    ``numpy.random.SeedSequence([seed, k])``, so networks are independent and each can be rebuilt
    on its own; it is built only when accessed."""
    return RandomNetworks(count, num_subsystems, n, p, eps, seed, r_min)


class _Chain(Sequence[Any]):
    """Two sequences back to back, lazily."""

    def __init__(self, first: Sequence[Any], second: Sequence[Any]) -> None:
        self._a, self._b = first, second

    def __len__(self) -> int:
        return len(self._a) + len(self._b)

    @overload
    def __getitem__(self, k: int) -> Any: ...
    @overload
    def __getitem__(self, k: slice) -> list[Any]: ...
    def __getitem__(self, k: int | slice) -> Any:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        i = int(k) + (len(self) if int(k) < 0 else 0)
        if not 0 <= i < len(self):
            raise IndexError(k)
        return self._a[i] if i < len(self._a) else self._b[i - len(self._a)]


def _resolve(item: Any) -> tuple[Network | None, str, str | None]:
    """``(network, digest, load error)`` for a Network or a model-file path."""
    if isinstance(item, Network):
        return item, _digest(item), None
    if isinstance(item, str | os.PathLike):
        try:
            net = Network.load(item)
        except Exception as exc:  # whatever a bad file provokes becomes its tasks' error rows
            d = hashlib.sha256(f"unloadable:{os.fspath(item)}".encode()).hexdigest()[:16]
            return None, d, f"{type(exc).__name__}: {exc}"
        return net, _digest(net), None
    raise InvalidInputError(
        f"networks must hold capalloc_rs.Network objects or model-file paths, got {type(item)!r}"
    )


# -- parameters -------------------------------------------------------------------------------


def _params(
    compute: str,
    tau: float | None,
    which: str,
    method: str,
    tol: float | None,
    hessian: str = "auto",
) -> dict[str, Any]:
    if compute not in COMPUTES:
        raise InvalidInputError(f"compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    if compute == "allocation":
        if method not in METHODS:
            raise InvalidInputError(f"method must be {one_of(METHODS)}, got {method!r}")
        if hessian not in HESSIAN_MODES:
            raise InvalidInputError(f"hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")
        params: dict[str, Any] = {
            "method": method,
            "tol": 1e-12 if tol is None else as_real("tol", tol, positive=True),
        }
        if hessian != "auto":  # absent for "auto": task ids of earlier sweeps stay valid
            params["hessian"] = hessian
        return params
    if compute == "filtration":
        return {"tol": 1e-10 if tol is None else as_real("tol", tol, positive=True)}
    if tau is None or as_real("tau", tau) <= 0:
        raise InvalidInputError(f"compute='schedule' needs a period tau > 0, got {tau!r}")
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    sampled_api()  # fail now, not in every task, if the finite-τ layer is missing
    return {"tau": float(tau), "which": which}


def _capacities(capacities: Iterable[float], compute: str) -> list[float]:
    out: list[float] = []
    seen: set[float] = set()
    if isinstance(capacities, str | bytes) or not isinstance(capacities, Iterable):
        raise InvalidInputError(f"capacities must be a list of numbers, got {capacities!r}")
    for c in capacities:
        if isinstance(c, bool):
            raise InvalidInputError(f"capacities must be numbers, got {c!r}")
        try:
            v = float(c)
        except (TypeError, ValueError):
            raise InvalidInputError(f"capacities must be numbers, got {c!r}") from None
        if not math.isfinite(v):
            raise InvalidInputError(f"capacities must be finite, got {c!r}")
        if compute == "schedule" and v != math.floor(v):
            raise InvalidInputError(f"schedule capacities must be integers (slots), got {c!r}")
        if v not in seen:
            seen.add(v)
            out.append(v)
    if not out:
        raise InvalidInputError("capacities is empty")
    return out


# -- output directory -------------------------------------------------------------------------


def _manifest(compute: str, params: Mapping[str, Any]) -> dict[str, Any]:
    return {"format": "capalloc-sweep-output", "version": 1, "compute": compute, "params": params}


def _same_type(a: Any, b: Any) -> bool:
    """Arrow types equal up to the names of list items (Parquet writes ``element``)."""
    pa = _pa()
    if pa.types.is_list(a) and pa.types.is_list(b):
        return _same_type(a.value_type, b.value_type)
    return bool(a.equals(b))


def _check_part(path: Path, sch: pa.Schema, manifest: Mapping[str, Any]) -> pa.Table:
    """The id columns of the part-file ``path`` after checking that it belongs to the sweep of
    ``manifest``: it carries the sweep's identity, its schema is the sweep's, and every task id
    is the one its row's network index, capacity and digest give under the manifest's compute and
    parameters; else a :class:`SweepError`."""
    pa = _pa()
    compute, params = str(manifest["compute"]), manifest["params"]
    try:
        have = pa.parquet.read_schema(path)
    except (OSError, pa.ArrowException) as exc:
        raise SweepError(
            f"the part-file {path} is damaged or not Parquet ({exc}); delete it to recompute "
            "its tasks"
        ) from None
    if have.names != sch.names or not all(
        _same_type(have.field(k).type, sch.field(k).type) for k in sch.names
    ):
        diff = (
            sorted(set(have.names) ^ set(sch.names))[:4]
            or [k for k in sch.names if not _same_type(have.field(k).type, sch.field(k).type)][:4]
        )
        raise SweepError(
            f"the part-file {path} has another schema than this {compute} sweep (differing "
            f"columns {diff}); it is not from this sweep: move it away"
        )
    want_id = manifest.get(SWEEP_ID)
    if want_id:
        got_id = (have.metadata or {}).get(SWEEP_ID.encode(), b"").decode("utf-8", "replace")
        if got_id != want_id:
            raise SweepError(
                f"the part-file {path} belongs to another sweep (id {got_id or 'none'!r}, this "
                f"sweep's is {want_id!r}): it is not a task of this sweep; move it away"
            )
    cols = ["task_id", "network_index", "r_tot", "network_digest"]
    try:
        t = pa.parquet.read_table(path, columns=cols)
    except (OSError, pa.ArrowException) as exc:
        raise SweepError(f"the part-file {path} is damaged ({exc}); delete it") from None
    for tid, idx, r, dig in zip(*(t.column(c).to_pylist() for c in cols), strict=True):
        if None in (tid, idx, r, dig) or tid != task_id(idx, r, compute, params, dig):
            raise SweepError(
                f"the part-file {path} holds the task id {tid!r}, which is not a task of this "
                f"sweep (compute={compute!r}, params={dict(params)!r}): it is not from this "
                "sweep: move it away"
            )
    return t


def _clean_debris(out: Path, token: str) -> None:
    """Removes the temporary files of interrupted writes: this process's own, or those of a
    process of this host that no longer runs (never a running sweep's)."""
    for tmp in out.glob(_TMP_PREFIX + "*"):
        if is_dead_debris(tmp.name, _TMP_PREFIX, token):
            with contextlib.suppress(OSError):
                tmp.unlink()


def _prepare_out(
    out: Path, compute: str, params: dict[str, Any], resume: bool, token: str
) -> tuple[set[str], str]:
    """Checks ``out`` (created and locked by the caller); returns the ids of the tasks already
    finished there and the sweep's identity (kept on resume, new otherwise; every part-file
    carries it in its metadata)."""
    _clean_debris(out, token)
    man = out / MANIFEST
    want = _manifest(compute, params)
    parts = sorted(out.glob(_PART_GLOB))
    if not resume:
        for p in parts:
            p.unlink()
        parts = []
    elif man.exists():
        try:
            have = json.loads(man.read_text())
        except (OSError, ValueError) as exc:
            raise SweepError(
                f"{man} is unreadable ({exc}); remove it or use resume=False"
            ) from None
        if not isinstance(have, dict):
            raise SweepError(f"{man} is not a sweep manifest; remove it or use resume=False")
        same = {k: v for k, v in have.items() if k != SWEEP_ID}
        if same != json.loads(json.dumps(want)):
            raise SweepError(
                f"{out} holds a different sweep (compute={have.get('compute')!r}, "
                f"params={have.get('params')!r}); use another directory or resume=False"
            )
        want[SWEEP_ID] = have.get(SWEEP_ID)  # None: a directory of an earlier version
    elif parts:
        raise SweepError(f"{out} has part-files but no {MANIFEST}; use resume=False to overwrite")
    if not want.get(SWEEP_ID) and not parts:
        want[SWEEP_ID] = uuid.uuid4().hex
    _atomic_write_text(man, json.dumps(want, indent=2, sort_keys=True) + "\n", token)
    done: set[str] = set()
    sch = schema(compute)
    for p in parts:
        done.update(_check_part(p, sch, want).column("task_id").to_pylist())
    return done, str(want.get(SWEEP_ID) or "")


def _fsync_dir(d: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _atomic_write_text(path: Path, text: str, token: str) -> None:
    tmp = path.with_name(tmp_name(_TMP_PREFIX, f"{token}{uuid.uuid4().hex[:8]}", ".json"))
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def _write_part(out: Path, table: pa.Table, token: str, sweep_id: str) -> Path:
    pq = _pa().parquet
    if sweep_id:
        table = table.replace_schema_metadata({SWEEP_ID: sweep_id})
    first = table.column("task_id")[0].as_py()
    name = f"part-{first}-{uuid.uuid4().hex[:8]}.parquet"
    tmp = out / tmp_name(_TMP_PREFIX, f"{token}{uuid.uuid4().hex[:8]}", f"-{name}")
    with open(tmp, "wb") as fh:
        pq.write_table(table, fh)
        fh.flush()
        os.fsync(fh.fileno())
    final = out / name
    os.replace(tmp, final)
    _fsync_dir(out)
    return final


def read_results(out: str | os.PathLike[str]) -> pa.Table:
    """Every row saved in a sweep's output directory, one per task id, sorted by task id.

    Raises:
        SweepError: ``out`` is not a sweep's directory (no readable manifest), or a part-file is
            damaged, has another schema or holds tasks of another sweep (refused, not merged).
    """
    pa = _pa()
    d = Path(out)
    parts = sorted(d.glob(_PART_GLOB))
    man = d / MANIFEST
    if not man.exists():
        raise SweepError(f"{d} is not a sweep output directory (no {MANIFEST})")
    try:
        have = json.loads(man.read_text())
        compute, params = have["compute"], have["params"]
        sch = schema(str(compute))
        if not isinstance(params, dict):
            raise TypeError("params is not a table")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SweepError(f"{man} is not a valid sweep manifest ({exc})") from None
    tables = []
    for p in parts:
        _check_part(p, sch, have)
        try:
            tables.append(pa.parquet.read_table(p, schema=sch))
        except (OSError, pa.ArrowException) as exc:
            raise SweepError(f"the part-file {p} is damaged ({exc}); delete it") from None
    return _finish(pa.concat_tables(tables) if tables else sch.empty_table(), None)


def _finish(table: pa.Table, keep: set[str] | None) -> pa.Table:
    """Keeps the rows of ``keep`` (all if ``None``), one per task id, sorted by task id."""
    pa = _pa()
    ids = table.column("task_id").to_pylist()
    seen: set[str] = set()
    idx = []
    for k, t in enumerate(ids):
        if (keep is None or t in keep) and t not in seen:
            seen.add(t)
            idx.append(k)
    table = table.take(pa.array(idx, type=pa.int64()))
    return table.sort_by("task_id").combine_chunks()


# -- the sweep --------------------------------------------------------------------------------


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
) -> pa.Table | RowTable:
    """Runs ``compute`` for every pair of ``networks × capacities`` (see the module docstring).

    Args:
        networks: a sequence or generator of :class:`~capalloc_rs.Network` (or model-file paths,
            loaded in this process; a file that fails to load gives error rows). Consumed lazily.
        capacities: the ``r_tot`` values (finite; duplicates are dropped; integers for
            ``compute="schedule"``).
        compute: ``"allocation"``, ``"filtration"`` or ``"schedule"``.
        tau, which: the period (required) and the figure (``"boundary"``/``"average"``) for
            ``compute="schedule"``.
        method, tol: the allocation method and tolerance (``tol`` also for filtrations; default
            each function's own).
        hessian: the Newton variant of the allocation (``"auto"``, ``"exact"``, ``"hvp"``; see
            :func:`~capalloc_rs.allocation.optimal_allocation`).
        executor: any :class:`concurrent.futures.Executor` (e.g. a dask ``Client.get_executor()``);
            default a process pool of ``workers`` processes (default ``os.cpu_count()``), shut
            down at the end. An executor you pass is not shut down.
        out: directory of the Parquet dataset (one part-file per finished chunk); ``None`` keeps
            results in memory only.
        resume: skip tasks already saved in ``out`` (``False``: delete its part-files first).
        progress: show a tqdm progress bar (only on a terminal, and only if tqdm is installed).
        chunk_size: tasks per chunk (per submitted call and per part-file).
        max_pending: chunks in flight at once (default twice the number of workers).
        stats: if given, filled with the counts of this call.

    Returns:
        The table of all tasks (including those skipped on resume), sorted by ``task_id``: a
        :class:`pyarrow.Table`, or without pyarrow (in memory only) a
        :class:`~capalloc_rs._rowtable.RowTable` with the same rows and columns.

    Raises:
        InvalidInputError: bad arguments. SweepError: ``out`` holds a different sweep, or a
        worker died (finished chunks are saved; re-run with ``resume=True``).
        MissingDependencyError: ``out`` is given and pyarrow is not installed.
        FeatureUnavailableError: ``compute="schedule"`` without the finite-τ layer.
    """
    t0 = time.perf_counter()
    if out is not None:
        _pa()  # fail now if pyarrow is missing: Parquet output needs it
    st = stats if stats is not None else SweepStats()
    params = _params(compute, tau, which, method, tol, hessian)
    caps = _capacities(capacities, compute)
    chunk_size = as_count("chunk_size", chunk_size, minimum=1)
    if workers is not None:
        workers = as_count("workers", workers, minimum=1, maximum=limits.MAX_SWEEP_WORKERS)
    if max_pending is not None:
        max_pending = as_count("max_pending", max_pending, minimum=1)
    if executor is not None and not hasattr(executor, "submit"):
        raise InvalidInputError(f"executor must be a concurrent.futures.Executor, got {executor!r}")
    if isinstance(networks, str | bytes) or not isinstance(networks, Iterable):
        raise InvalidInputError(
            f"networks must be an iterable of Network objects or model-file paths, got "
            f"{type(networks).__name__}"
        )
    if isinstance(networks, Sequence) and not isinstance(networks, str | bytes):
        _check_task_count(len(networks) * len(caps))
    # Without pyarrow, an in-memory sweep returns a RowTable (same rows and columns).
    sch = schema(compute) if out is not None or _have_pyarrow() else None
    if sch is None:
        columns(compute)  # an unknown compute is refused here too
    out_dir = None if out is None else Path(out)
    lock: DirLock | None = None
    if out_dir is not None:
        if out_dir.exists() and not out_dir.is_dir():
            raise SweepError(f"out = {out_dir} exists and is not a directory")
        out_dir.mkdir(parents=True, exist_ok=True)
        lock = DirLock(out_dir)
        lock.acquire()
    try:
        return _sweep_locked(
            networks,
            caps,
            compute,
            params,
            sch,
            out_dir,
            lock,
            resume,
            executor,
            workers,
            progress,
            int(chunk_size),
            max_pending,
            st,
            t0,
        )
    finally:
        if lock is not None:
            lock.release()


def _check_task_count(count: int) -> None:
    if count > limits.MAX_SWEEP_TASKS:
        raise InvalidInputError(
            f"the sweep has {count} tasks (networks × capacities), more than "
            f"capalloc_rs.limits.MAX_SWEEP_TASKS = {limits.MAX_SWEEP_TASKS}; split it"
        )


def _sweep_locked(
    networks: Iterable[Network | str | os.PathLike[str]],
    caps: list[float],
    compute: str,
    params: dict[str, Any],
    sch: pa.Schema,
    out_dir: Path | None,
    lock: DirLock | None,
    resume: bool,
    executor: Executor | None,
    workers: int | None,
    progress: bool,
    chunk_size: int,
    max_pending: int | None,
    st: SweepStats,
    t0: float,
) -> pa.Table:
    pa = _pa() if sch is not None else None
    token = lock.token if lock is not None else ""
    done, sweep_id = (
        _prepare_out(out_dir, compute, params, resume, token)
        if out_dir is not None
        else (set(), "")
    )

    total: int | None = None
    if isinstance(networks, Sequence) and not isinstance(networks, str | bytes):
        total = len(networks) * len(caps)
    wanted: set[str] = set()

    def tasks() -> Iterator[TaskSpec]:
        for idx, item in enumerate(networks):
            net, digest, err = _resolve(item)
            for r in caps:
                tid = task_id(idx, r, compute, params, digest)
                if tid in wanted:
                    continue
                wanted.add(tid)
                st.tasks += 1
                _check_task_count(st.tasks)
                if tid in done:
                    st.skipped += 1
                    if bar is not None:
                        bar.update(1)
                    continue
                yield TaskSpec(tid, idx, r, digest, net, err)

    own = executor is None
    n_workers = int(workers) if workers is not None else (os.cpu_count() or 1)
    ex: Executor = _own_executor(n_workers) if executor is None else executor
    if max_pending is None:
        guess = n_workers if own else _executor_width(ex)
        window = 2 * max(guess, 1)
    else:
        window = max(int(max_pending), 1)

    bar = _progress_bar(progress, total, 0)
    memory: list[Any] = []
    pending: list[Future[Any]] = []
    ok = False
    try:
        chunk_iter = _chunks(tasks(), int(chunk_size))
        exhausted = False
        while True:
            while not exhausted and len(pending) < window:
                nxt = next(chunk_iter, None)
                if nxt is None:
                    exhausted = True
                    break
                pending.append(ex.submit(run_chunk, compute, params, nxt))
            if not pending:
                break
            finished = [f for f in pending if f.done()]
            if not finished:
                # Block briefly on the oldest chunk (no as_completed: dask futures break it);
                # its outcome, exception included, is collected once it is done.
                with contextlib.suppress(FutureTimeoutError, Exception):
                    pending[0].result(timeout=0.05)
                continue
            for f in finished:
                pending.remove(f)
                try:
                    rows = f.result()
                except Exception as exc:
                    where = f"; finished chunks are saved in {out_dir}" if out_dir else ""
                    raise SweepError(
                        f"a sweep worker failed ({type(exc).__name__}: {exc}){where}; "
                        "re-run with resume=True to continue"
                    ) from exc
                if sch is None:  # no pyarrow: plain rows
                    memory.extend(rows)
                elif out_dir is not None:
                    _write_part(out_dir, _rows_to_table(rows, sch), token, sweep_id)
                else:
                    memory.append(_rows_to_table(rows, sch))
                st.computed += len(rows)
                st.chunks += 1
                if bar is not None:
                    bar.update(len(rows))
        ok = True
    finally:
        for f in pending:
            f.cancel()
        if own:
            if not ok:  # interrupted or failed: stop the chunks in flight now
                _stop_workers(ex)
            # Always wait: shutdown(wait=False) leaves the pool's manager thread racing the
            # interpreter's exit ("Bad file descriptor" tracebacks after Ctrl-C); with the
            # workers stopped the wait is short.
            ex.shutdown(wait=True, cancel_futures=True)
        if bar is not None:
            bar.close()

    def meta() -> dict[bytes, bytes]:
        info = {"compute": compute, "params": params, "tasks": st.tasks, "failed": st.failed}
        return {b"capalloc.sweep": json.dumps(info).encode()}

    if pa is None:
        rows = {r["task_id"]: r for r in reversed(memory) if r["task_id"] in wanted}
        plain = RowTable([rows[t] for t in sorted(rows)], [name for name, _ in columns(compute)])
        st.failed = plain.num_rows - plain.column("error").null_count
        st.seconds = time.perf_counter() - t0
        plain.metadata = meta()
        return plain
    if out_dir is not None:
        parts = sorted(out_dir.glob(_PART_GLOB))
        tables = [pa.parquet.read_table(p, schema=sch) for p in parts]
    else:
        tables = memory
    result = _finish(pa.concat_tables(tables) if tables else sch.empty_table(), wanted)
    st.failed = result.num_rows - result.column("error").null_count
    st.seconds = time.perf_counter() - t0
    return result.replace_schema_metadata(meta())


# -- sweep spec files -------------------------------------------------------------------------

SPEC_FORMAT = "capalloc-sweep"

_SPEC_KEYS = {
    "format",
    "version",
    "compute",
    "capacities",
    "networks",
    "tau",
    "which",
    "method",
    "tol",
    "hessian",
    "chunk_size",
}
_RANDOM_KEYS = {"count", "N", "n", "p", "eps", "seed", "r_min"}


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep spec file (see :func:`load_spec`).

    Attributes:
        files: model files (resolved against the spec's directory).
        random: keyword arguments of :func:`random_networks`, or ``None``.
        capacities: the ``r_tot`` values.
        compute, tau, which, method, tol, hessian, chunk_size: as in :func:`sweep`.
    """

    files: tuple[Path, ...]
    random: Mapping[str, Any] | None
    capacities: tuple[float, ...]
    compute: str
    tau: float | None
    which: str
    method: str
    tol: float | None
    chunk_size: int
    hessian: str = "auto"

    def networks(self) -> Sequence[Network | Path]:
        """The spec's networks as a lazy sequence: the model files (as paths, loaded by
        :func:`sweep`, so a bad file gives error rows), then the random networks."""
        rnd: Sequence[Network] = []
        if self.random is not None:
            r = dict(self.random)
            rnd = random_networks(
                r["count"], r["N"], r["n"], r["p"], r["eps"], r["seed"], r["r_min"]
            )
        return _Chain(list(self.files), rnd)

    @property
    def num_networks(self) -> int:
        """How many networks the spec describes."""
        return len(self.files) + (0 if self.random is None else int(self.random["count"]))

    def run(self, **kwargs: Any) -> pa.Table | RowTable:
        """:func:`sweep` over this spec (keyword arguments: ``executor``, ``out``, …)."""
        kwargs.setdefault("chunk_size", self.chunk_size)
        return sweep(
            self.networks(),
            self.capacities,
            compute=self.compute,
            tau=self.tau,
            which=self.which,
            method=self.method,
            tol=self.tol,
            hessian=self.hessian,
            **kwargs,
        )


def _spec_number(name: str, v: Any, *, integer: bool = False) -> Any:
    f = finite_float(v)
    ok = f is not None
    if ok and integer:
        ok = isinstance(v, int) or float(v).is_integer()
    if not ok:
        kind = "an integer" if integer else "a number"
        raise SweepError(f"spec: {name} must be {kind}, got {v!r}")
    return int(v) if integer else float(v)


def load_spec(path: str | os.PathLike[str]) -> SweepSpec:
    """Reads a sweep spec (TOML or JSON, by extension; schema in ``examples/sweep.toml``).

    Raises:
        SweepError: a malformed spec (the message names the field). OSError: unreadable file.
    """
    p = Path(path)
    fmt = "json" if p.suffix.lower() == ".json" else "toml"
    d = read_data(p, fmt, lambda msg: SweepError(f"{p}: {msg}"))
    if not isinstance(d, dict):
        raise SweepError(f"{p}: the spec must be a table/object at the top level")
    unknown = sorted(set(d) - _SPEC_KEYS)
    if unknown:
        raise SweepError(f"{p}: unknown key(s) {', '.join(unknown)}")
    if d.get("format", SPEC_FORMAT) != SPEC_FORMAT:
        raise SweepError(f"{p}: format must be {SPEC_FORMAT!r}, got {d['format']!r}")
    if d.get("version", 1) != 1:
        raise SweepError(f"{p}: unsupported version {d['version']!r} (this build reads 1)")
    compute = d.get("compute", "allocation")
    if compute not in COMPUTES:
        raise SweepError(f"{p}: compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    caps_raw = d.get("capacities")
    if caps_raw is None:
        raise SweepError(f"{p}: capacities is missing")
    if isinstance(caps_raw, dict):
        extra = sorted(set(caps_raw) - {"start", "stop", "num"})
        if extra or not {"start", "stop", "num"} <= set(caps_raw):
            raise SweepError(f"{p}: capacities as a table needs exactly start, stop, num")
        num = _spec_number("capacities.num", caps_raw["num"], integer=True)
        if num < 1:
            raise SweepError(f"{p}: capacities.num must be at least 1")
        if num > limits.MAX_SWEEP_TASKS:
            raise SweepError(
                f"{p}: capacities.num = {num} is more than capalloc_rs.limits.MAX_SWEEP_TASKS = "
                f"{limits.MAX_SWEEP_TASKS}"
            )
        caps = tuple(
            float(x)
            for x in np.linspace(
                _spec_number("capacities.start", caps_raw["start"]),
                _spec_number("capacities.stop", caps_raw["stop"]),
                num,
            )
        )
    elif isinstance(caps_raw, list) and caps_raw:
        caps = tuple(_spec_number(f"capacities[{k}]", v) for k, v in enumerate(caps_raw))
    else:
        raise SweepError(f"{p}: capacities must be a non-empty list or {{start, stop, num}}")
    nets = d.get("networks")
    if not isinstance(nets, dict) or not nets:
        raise SweepError(f"{p}: [networks] with files = [...] and/or [networks.random] is missing")
    unknown = sorted(set(nets) - {"files", "random"})
    if unknown:
        raise SweepError(f"{p}: unknown key(s) in networks: {', '.join(unknown)}")
    files_raw = nets.get("files", [])
    if not isinstance(files_raw, list) or not all(isinstance(f, str) for f in files_raw):
        raise SweepError(f"{p}: networks.files must be a list of paths")
    files = tuple(p.parent / f for f in files_raw)
    rnd: dict[str, Any] | None = None
    if "random" in nets:
        r = nets["random"]
        if not isinstance(r, dict):
            raise SweepError(f"{p}: networks.random must be a table")
        bad = sorted(set(r) - _RANDOM_KEYS)
        if bad:
            raise SweepError(f"{p}: unknown key(s) in networks.random: {', '.join(bad)}")
        for req in ("count", "N"):
            if req not in r:
                raise SweepError(f"{p}: networks.random.{req} is missing")
        rnd = {
            "count": _spec_number("networks.random.count", r["count"], integer=True),
            "N": _spec_number("networks.random.N", r["N"], integer=True),
            "n": _spec_number("networks.random.n", r.get("n", 2), integer=True),
            "p": _spec_number("networks.random.p", r.get("p", 1), integer=True),
            "eps": _spec_number("networks.random.eps", r.get("eps", 0.1)),
            "seed": _spec_number("networks.random.seed", r.get("seed", 0), integer=True),
            "r_min": _spec_number("networks.random.r_min", r.get("r_min", 1.0)),
        }
        for k in ("count", "N", "n", "p"):
            if rnd[k] < (0 if k == "count" else 1):
                raise SweepError(f"{p}: networks.random.{k} must be positive, got {rnd[k]}")
        states = rnd["N"] * rnd["n"]
        if states > limits.MAX_MODEL_STATES or rnd["p"] > limits.MAX_MODEL_STATES:
            raise SweepError(
                f"{p}: networks.random needs N·n ≤ capalloc_rs.limits.MAX_MODEL_STATES = "
                f"{limits.MAX_MODEL_STATES} (and p as well), got N = {rnd['N']}, n = {rnd['n']}, "
                f"p = {rnd['p']}"
            )
        if rnd["seed"] < 0:
            raise SweepError(f"{p}: networks.random.seed must be non-negative, got {rnd['seed']}")
    if not files and rnd is None:
        raise SweepError(f"{p}: networks has no files and no random table")
    tasks = (len(files) + (rnd["count"] if rnd else 0)) * len(caps)
    if tasks > limits.MAX_SWEEP_TASKS:
        raise SweepError(
            f"{p}: {tasks} tasks (networks × capacities), more than "
            f"capalloc_rs.limits.MAX_SWEEP_TASKS = {limits.MAX_SWEEP_TASKS}; split the sweep"
        )
    tau = d.get("tau")
    if compute == "schedule" and tau is None:
        raise SweepError(f"{p}: compute = 'schedule' needs tau")
    which = d.get("which", "boundary")
    method = d.get("method", "newton")
    hessian = d.get("hessian", "auto")
    if not all(isinstance(v, str) for v in (which, method, hessian)):
        raise SweepError(f"{p}: which, method and hessian must be strings")
    if hessian not in HESSIAN_MODES:
        raise SweepError(f"{p}: hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")
    return SweepSpec(
        files=files,
        random=rnd,
        capacities=caps,
        compute=compute,
        tau=None if tau is None else _spec_number("tau", tau),
        which=which,
        method=method,
        tol=None if d.get("tol") is None else _spec_number("tol", d["tol"]),
        chunk_size=_spec_number("chunk_size", d.get("chunk_size", 16), integer=True),
        hessian=hessian,
    )
