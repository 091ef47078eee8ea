"""Where a sweep's chunks run: any :class:`concurrent.futures.Executor`, or the sweep's own.

The sweep's own executor is a process pool (the heavy kernels are in Rust and release the GIL, but
the optimisation loops are Python) started by ``forkserver`` where available (never ``fork`` a
process that may hold Rust threads), else ``spawn``; or, when the sweep is called from a script's
top level without ``if __name__ == "__main__":`` (see :mod:`capalloc_rs.sweep.mainguard`), a
thread pool of the same size with one :class:`~capalloc_rs.errors.UnguardedMainWarning`.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from typing import Any

from .._unchecked import warn_outside
from ..errors import UnguardedMainWarning
from .mainguard import unguarded_call

__all__ = ["SerialExecutor", "executor_width", "own_executor", "shut_down"]


class SerialExecutor(Executor):
    """Runs each submitted call immediately in the calling thread (debugging, baselines)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        """Runs ``fn(*args, **kwargs)`` now, in the calling thread.

        Returns:
            A finished :class:`concurrent.futures.Future` holding the result, or the exception
            ``fn`` raised (delivered through the future, as a real executor would).
        """
        fut: Future[Any] = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # delivered through the future like a real executor
            fut.set_exception(exc)
        return fut


def executor_width(ex: Any) -> int:
    """How many calls ``ex`` runs at once, as far as it tells (dask: its cluster's threads)."""
    client = getattr(ex, "_client", None)
    if client is not None:
        # a cluster that cannot tell (closed connection, odd answer) gets the fallback below
        with contextlib.suppress(OSError, ValueError, TypeError, AttributeError):
            return max(1, int(sum(client.nthreads().values())))
    return int(getattr(ex, "_max_workers", 0) or os.cpu_count() or 1)


def _stop_workers(ex: Executor) -> None:
    """Terminates the worker processes of our own process pool (their chunks are lost; finished
    chunks are saved)."""
    procs = getattr(ex, "_processes", None) or {}
    for proc in list(procs.values()):
        with contextlib.suppress(OSError, ValueError):  # already gone, or closed
            proc.terminate()


def shut_down(ex: Executor, *, completed: bool) -> None:
    """Shuts our own executor down; after an interruption or failure (not ``completed``) its
    chunks in flight are stopped first."""
    if not completed:
        _stop_workers(ex)
    # Always wait: shutdown(wait=False) leaves the pool's manager thread racing the interpreter's
    # exit ("Bad file descriptor" tracebacks after Ctrl-C); with the workers stopped the wait is
    # short.
    ex.shutdown(wait=True, cancel_futures=True)


def _worker_init() -> None:
    """Pool workers leave Ctrl-C to the driver, which cancels the sweep cleanly (a terminal sends
    SIGINT to the whole process group)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _default_context() -> Any:
    # Never fork a process that may hold Rust (rayon) threads: forkserver where available.
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def own_executor(n_workers: int) -> Executor:
    """The default executor: a process pool, or threads when the sweep was started from a
    script's top level without ``if __name__ == "__main__":`` (its worker processes would re-run
    the script), with one warning saying so."""
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
