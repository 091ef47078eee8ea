"""Sweeps into an output directory: resume in process and after a real killed process or a crashed
worker, one sweep at a time (the directory lock), only its own temporary files, only its own
part-files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import capalloc_rs
from capalloc_rs import Network
from capalloc_rs.errors import SweepError

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from capalloc_rs.sweep import (  # noqa: E402
    SerialExecutor,
    SweepStats,
    random_networks,
    read_results,
    sweep,
)
from capalloc_rs.sweep.dirlock import tmp_name  # noqa: E402

PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.fixture(scope="module")
def nets() -> list[Network]:
    return list(random_networks(6, 3, 2, eps=0.1, seed=11))


def test_resume_in_process_recomputes_only_missing_chunks(
    nets: list[Network], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    caps = [4.0, 7.0]
    full = sweep(nets, caps, executor=SerialExecutor(), out=out, chunk_size=2, progress=False)
    assert full.equals(read_results(out))
    assert pq.read_table(out).num_rows == full.num_rows  # a plain Parquet dataset
    parts = sorted(out.glob("part-*.parquet"))
    assert len(parts) == 6
    for p in parts[::2]:
        p.unlink()
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    debris = tmp_name(".tmp-part-", "deadbeef", ".parquet").replace(
        f"-{os.getpid()}-", f"-{int(dead.stdout)}-"
    )
    (out / debris).write_bytes(b"half a file of a killed sweep")
    st = SweepStats()
    again = sweep(
        nets, caps, executor=SerialExecutor(), out=out, chunk_size=2, progress=False, stats=st
    )
    assert again.equals(full, check_metadata=True)
    assert (st.computed, st.skipped) == (6, 6)
    assert not list(out.glob(".tmp-*"))
    # nothing left to do
    st = SweepStats()
    sweep(nets, caps, executor=SerialExecutor(), out=out, progress=False, stats=st)
    assert (st.computed, st.skipped) == (0, 12)
    # a subset of the capacities is served from the saved results
    sub = sweep(nets, [7.0], executor=SerialExecutor(), out=out, progress=False)
    assert sub.equals(full.filter(pa.compute.equal(full.column("r_tot"), 7.0)))
    # resume=False starts afresh
    st = SweepStats()
    sweep(nets, caps, executor=SerialExecutor(), out=out, resume=False, progress=False, stats=st)
    assert st.computed == 12


def test_output_directory_of_another_sweep_is_refused(nets: list[Network], tmp_path: Path) -> None:
    out = tmp_path / "out"
    sweep(nets[:1], [5.0], executor=SerialExecutor(), out=out, progress=False)
    with pytest.raises(SweepError, match="different sweep"):
        sweep(
            nets[:1],
            [5.0],
            compute="filtration",
            executor=SerialExecutor(),
            out=out,
            progress=False,
        )
    manifest = json.loads((out / "_sweep.json").read_text())
    assert manifest["compute"] == "allocation"


def test_changed_network_gets_new_task_ids(nets: list[Network], tmp_path: Path) -> None:
    out = tmp_path / "out"
    sweep(nets[:2], [5.0], executor=SerialExecutor(), out=out, progress=False)
    st = SweepStats()
    t = sweep(
        [nets[0], nets[3]], [5.0], executor=SerialExecutor(), out=out, progress=False, stats=st
    )
    assert (st.skipped, st.computed) == (1, 1)
    assert t.num_rows == 2
    assert t.column("network_digest").to_pylist()[1] != t.column("network_digest").to_pylist()[0]


# -- a real process killed midway ---------------------------------------------------------------

_KILLED_SCRIPT = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from capalloc_rs.sweep import random_networks, sweep

    out, ready = Path(sys.argv[1]), Path(sys.argv[2])

    def held():
        # The driver consumes this generator lazily, collecting finished chunks between networks.
        # Once a part-file exists the generator announces it (the ready marker) and holds the
        # sweep until it is signalled: the signal always meets a running sweep with saved chunks.
        # (If every network is consumed first, the sweep finishes: the test allows for it.)
        for net in random_networks(30, 3, 2, seed=5):
            if any(out.glob("part-*.parquet")):
                ready.write_text("a part-file is saved")
                while True:
                    time.sleep(0.01)
            time.sleep(0.02)
            yield net

    if __name__ == "__main__":
        sweep(held(), [4.0, 7.0], workers=1, chunk_size=2, out=out, progress=False)
        print("finished")
    """
)


def _wait_for(marker: Path, proc: subprocess.Popen[str], timeout: float) -> bool:
    """Polls until ``marker`` exists (True) or the process ends (False); ``timeout`` only guards
    against a hung child."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if marker.exists():
            return True
        if proc.poll() is not None:
            return marker.exists()
        time.sleep(0.02)
    raise AssertionError(f"no ready marker within {timeout} s")


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_killed_sweep_resumes_to_the_uninterrupted_table(tmp_path: Path, sig: int) -> None:
    out = tmp_path / "out"
    ready = tmp_path / "ready"
    script = tmp_path / "run_sweep.py"
    script.write_text(_KILLED_SCRIPT)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(out), str(ready)],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the kill reaches the pool's workers
    )
    try:
        interrupted = _wait_for(ready, proc, timeout=600)
        if interrupted:
            if sig == signal.SIGKILL:
                os.killpg(proc.pid, signal.SIGKILL)
            else:
                os.kill(proc.pid, signal.SIGINT)  # Ctrl-C in the driver
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
    try:  # leftovers of the interrupted sweep (its pool's workers) must not write any more
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    if interrupted:
        assert proc.returncode != 0
        if sig == signal.SIGINT:  # Ctrl-C: a KeyboardInterrupt, no other traceback
            assert "KeyboardInterrupt" in err and "Bad file descriptor" not in err, err
            assert err.count("Traceback") == 1, err
    else:  # the sweep won the race: it finished, and resuming must find everything done
        assert proc.returncode == 0, err

    before = {p.name: p.stat().st_mtime_ns for p in out.glob("part-*.parquet")}
    done_before = set(read_results(out).column("task_id").to_pylist())
    assert 0 < len(done_before) <= 60
    assert not interrupted or len(done_before) < 60

    nets = list(random_networks(30, 3, 2, seed=5))
    st = SweepStats()
    resumed = sweep(nets, [4.0, 7.0], workers=1, chunk_size=2, out=out, progress=False, stats=st)
    assert st.skipped == len(done_before)
    assert st.computed == 60 - len(done_before)
    # finished part-files untouched, and no finished task computed again
    for name, mtime in before.items():
        assert (out / name).stat().st_mtime_ns == mtime
    new_ids: list[str] = []
    for p in out.glob("part-*.parquet"):
        if p.name not in before:
            new_ids += pq.read_table(p, columns=["task_id"]).column("task_id").to_pylist()
    assert not set(new_ids) & done_before
    assert len(new_ids) == len(set(new_ids)) == 60 - len(done_before)

    uninterrupted = sweep(nets, [4.0, 7.0], executor=SerialExecutor(), progress=False)
    assert resumed.equals(uninterrupted, check_metadata=True)


class _CrashingNetwork(Network):
    """Unpickling it kills the worker process (a crashed worker)."""

    __slots__ = ()

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os._exit, (3,))


def test_crashed_worker_keeps_finished_chunks_and_resumes(tmp_path: Path) -> None:
    good = list(random_networks(4, 2, 1, seed=21))
    crasher = _CrashingNetwork.random(2, 1, seed=99)
    out = tmp_path / "out"
    with pytest.raises(SweepError, match="worker failed"):
        sweep(
            [*good[:3], crasher, good[3]],
            [3.0],
            workers=1,
            chunk_size=1,
            max_pending=1,
            out=out,
            progress=False,
        )
    saved = read_results(out)
    assert saved.column("network_index").to_pylist() == [0, 1, 2]
    fixed = [*good[:3], Network.random(2, 1, seed=99), good[3]]
    st = SweepStats()
    t = sweep(fixed, [3.0], workers=1, out=out, progress=False, stats=st)
    assert (st.skipped, st.computed) == (3, 2)
    assert t.equals(sweep(fixed, [3.0], executor=SerialExecutor(), progress=False))


# -- the output directory: one sweep at a time, only its own files, only its own part-files ------

_HOLDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from capalloc_rs.sweep.dirlock import DirLock

    lock = DirLock(Path(sys.argv[1]))
    lock.acquire()
    Path(sys.argv[2]).write_text("locked")
    while True:
        time.sleep(0.05)
    """
)


def test_second_sweep_is_refused_and_a_dead_owner_lock_is_taken_over(
    nets: list[Network], tmp_path: Path
) -> None:
    out, ready = tmp_path / "out", tmp_path / "ready"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(out), str(ready)], env=_env(), text=True
    )
    try:
        deadline = time.monotonic() + 300  # guards against a hung child only
        while not ready.exists():
            assert holder.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        with pytest.raises(SweepError, match=rf"in use by another sweep \(pid {holder.pid} on "):
            sweep(nets[:1], [5.0], executor=SerialExecutor(), out=out, progress=False)
        assert not list(out.glob("part-*"))  # the refused sweep computed nothing
    finally:
        holder.kill()  # SIGKILL: no clean-up, the lock file stays behind
        holder.wait(timeout=60)
    lock = json.loads((out / "_sweep.lock").read_text())
    assert lock["pid"] == holder.pid and "started" in lock and "host" in lock
    t = sweep(nets[:1], [5.0], executor=SerialExecutor(), out=out, progress=False)
    assert t.num_rows == 1 and t.column("error").null_count == 1
    assert not (out / "_sweep.lock").exists()  # released


def test_temporary_files_of_a_live_process_are_left_alone(
    nets: list[Network], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    sweep(nets[:1], [5.0], executor=SerialExecutor(), out=out, progress=False)
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        mine = tmp_name(".tmp-part-", "cafe", ".parquet")
        theirs = out / mine.replace(f"-{os.getpid()}-", f"-{live.pid}-")
        theirs.write_bytes(b"being written by another process")
        sweep(nets[:1], [5.0, 6.0], executor=SerialExecutor(), out=out, progress=False)
        assert theirs.exists()
    finally:
        live.kill()
        live.wait(timeout=60)
    sweep(nets[:1], [5.0, 6.0], executor=SerialExecutor(), out=out, progress=False)
    assert not theirs.exists()  # its owner is dead now


def test_foreign_or_damaged_part_files_are_refused(nets: list[Network], tmp_path: Path) -> None:
    out, other = tmp_path / "out", tmp_path / "other"
    sweep(nets[:2], [5.0], executor=SerialExecutor(), out=out, progress=False)
    assert read_results(out).num_rows == 2
    # a part-file of the same kind of sweep over other networks: foreign task ids
    sweep(nets[2:4], [5.0], executor=SerialExecutor(), out=other, progress=False)
    foreign = sorted(other.glob("part-*.parquet"))[0]
    planted = out / f"part-zzz-{foreign.name}"
    planted.write_bytes(foreign.read_bytes())
    with pytest.raises(SweepError, match="not a task of this sweep"):
        read_results(out)
    with pytest.raises(SweepError, match="not a task of this sweep"):
        sweep(nets[:2], [5.0], executor=SerialExecutor(), out=out, progress=False)
    # another schema (a filtration sweep's part-file)
    filt = tmp_path / "filt"
    sweep(
        nets[:1], [5.0], compute="filtration", executor=SerialExecutor(), out=filt, progress=False
    )
    planted.write_bytes(sorted(filt.glob("part-*.parquet"))[0].read_bytes())
    with pytest.raises(SweepError, match="another schema"):
        read_results(out)
    # a damaged file
    planted.write_bytes(b"PAR1 not really")
    with pytest.raises(SweepError, match="damaged"):
        read_results(out)
    with pytest.raises(SweepError, match="damaged"):
        sweep(nets[:2], [5.0], executor=SerialExecutor(), out=out, progress=False)
    planted.unlink()
    assert read_results(out).num_rows == 2


def test_lock_without_flock_uses_the_owner_pid(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where ``flock`` is unavailable the lock file is created exclusively: a live owner's lock is
    refused, a dead owner's (its pid no longer runs) is taken over."""
    import errno
    import socket

    from capalloc_rs.sweep import dirlock as _dirlock

    def no_flock(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, "no locks available")

    monkeypatch.setattr(_dirlock.fcntl, "flock", no_flock)
    first = _dirlock.DirLock(tmp_path)
    first.acquire()
    with pytest.raises(SweepError, match=f"pid {os.getpid()} on "):
        _dirlock.DirLock(tmp_path).acquire()
    first.release()
    assert not (tmp_path / _dirlock.LOCK_NAME).exists()
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    stale = {"pid": int(dead.stdout), "host": socket.gethostname(), "started": "earlier"}
    (tmp_path / _dirlock.LOCK_NAME).write_text(json.dumps(stale))
    again = _dirlock.DirLock(tmp_path)
    again.acquire()
    assert again.took_over == stale
    again.release()
