"""Sweeps: equality with the one-at-a-time API, determinism, failures recorded, bounded streaming,
resume after a real killed process, dask.distributed."""

from __future__ import annotations

import json
import os
import pickle
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import Network
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.errors import FeatureUnavailableError, InvalidInputError, SweepError

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from capalloc_rs._dirlock import tmp_name  # noqa: E402
from capalloc_rs._tasks import sampled_api  # noqa: E402
from capalloc_rs.sweep import (  # noqa: E402
    SerialExecutor,
    SweepStats,
    load_spec,
    random_networks,
    read_results,
    sweep,
    task_id,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _has_sampled() -> bool:
    try:
        sampled_api()
    except FeatureUnavailableError:  # the one documented reason; anything else is a failure
        return False
    return True


@pytest.fixture(scope="module")
def nets() -> list[Network]:
    return list(random_networks(6, 3, 2, eps=0.1, seed=11))


def test_allocation_sweep_equals_single_api(nets: list[Network]) -> None:
    caps = [4.0, 6.5, 9.0]
    stats = SweepStats()
    t = sweep(nets, caps, executor=SerialExecutor(), chunk_size=4, progress=False, stats=stats)
    assert t.num_rows == len(nets) * len(caps)
    assert stats.computed == t.num_rows and stats.skipped == 0 and stats.failed == 0
    ids = t.column("task_id").to_pylist()
    assert ids == sorted(ids) and len(set(ids)) == len(ids)
    for row in t.to_pylist():
        net = nets[row["network_index"]]
        a = optimal_allocation(net, row["r_tot"])
        assert row["error"] is None
        assert row["eta"] == a.eta
        np.testing.assert_array_equal(row["r"], a.r)
        np.testing.assert_array_equal(row["gamma"], a.gamma)
        assert row["mu"] == a.mu
        assert row["active"] == [int(i) for i in a.active]
        assert row["task_id"] == task_id(
            row["network_index"],
            row["r_tot"],
            "allocation",
            {"method": "newton", "tol": 1e-12},
            row["network_digest"],
        )
    # sorted by task id = sorted by (network, capacity)
    keys = [(r["network_index"], r["r_tot"]) for r in t.to_pylist()]
    assert keys == sorted(keys)


def test_process_pool_and_threads_give_identical_tables(nets: list[Network]) -> None:
    caps = [5.0, 8.0]
    serial = sweep(nets, caps, executor=SerialExecutor(), progress=False)
    procs = sweep(nets, caps, workers=2, chunk_size=3, progress=False)
    with ThreadPoolExecutor(2) as ex:
        threads = sweep(iter(nets), caps, executor=ex, chunk_size=1, progress=False)
    assert procs.equals(serial, check_metadata=True)
    assert threads.equals(serial, check_metadata=True)


def test_allocation_sweep_passes_the_newton_variant(nets: list[Network]) -> None:
    kw = {"executor": SerialExecutor(), "progress": False}
    for hessian in ("exact", "hvp"):
        t = sweep(nets[:2], [5.0, 7.0], hessian=hessian, **kw)  # type: ignore[arg-type]
        for row in t.to_pylist():
            a = optimal_allocation(nets[row["network_index"]], row["r_tot"], hessian=hessian)
            assert row["error"] is None and row["eta"] == a.eta
            np.testing.assert_array_equal(row["r"], a.r)
            # The variant is part of the task (a different computation), "auto" is not recorded.
            assert row["task_id"] == task_id(
                row["network_index"],
                row["r_tot"],
                "allocation",
                {"method": "newton", "tol": 1e-12, "hessian": hessian},
                row["network_digest"],
            )
    with pytest.raises(InvalidInputError, match="hessian"):
        sweep(nets, [5.0], hessian="cg", **kw)  # type: ignore[arg-type]


def test_filtration_sweep_equals_single_api(nets: list[Network]) -> None:
    t = sweep(nets[:3], [5.0, 7.0], compute="filtration", executor=SerialExecutor(), progress=False)
    for row in t.to_pylist():
        net = nets[row["network_index"]]
        sigma_max = row["r_tot"] - net.num_sensors * net.r_min
        f = filtration(net, sigma_max)
        assert row["error"] is None
        assert row["sigma_max"] == sigma_max
        np.testing.assert_array_equal(row["breakpoints"], f.breakpoints)
        assert row["active_sets"] == [list(s) for s in f.active_sets]
        assert row["entry_order"] == list(f.entry_order)
        assert row["is_filtration"] == f.is_filtration
        np.testing.assert_allclose(row["r"], f.allocation(sigma_max) + net.r_min, atol=1e-9)
        # the filtration's end point is the optimal allocation there
        a = optimal_allocation(net, row["r_tot"])
        np.testing.assert_allclose(row["r"], a.r, atol=1e-7)
        assert row["eta"] == pytest.approx(a.eta, rel=1e-10)


@pytest.mark.skipif(not _has_sampled(), reason="the finite-τ layer (issue 6) is not in this build")
def test_schedule_sweep_equals_single_api(nets: list[Network]) -> None:
    best_schedule = sampled_api()["best_schedule"]
    t = sweep(
        nets[:2], [4, 6], compute="schedule", tau=0.4, executor=SerialExecutor(), progress=False
    )
    for row in t.to_pylist():
        b = best_schedule(nets[row["network_index"]], 0.4, int(row["r_tot"]))
        assert row["error"] is None
        assert row["eta_bar"] == b.eta_bar and row["eta"] == b.eta_bar
        assert row["eta_limit"] == b.eta_limit
        assert row["schedule"] == [int(i) for i in b.schedule.as_array()]
        assert row["counts"] == list(b.counts)


def test_failures_are_recorded_and_do_not_stop_the_sweep(
    nets: list[Network], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[[subsystems]]\nA = [[1.0]]\nG = [[0.0]]\nc = [1.0]\n")  # singular G
    items = [nets[0], bad, str(tmp_path / "missing.toml"), EXAMPLES / "three_subsystems.toml"]
    t = sweep(items, [2.0, 6.0], executor=SerialExecutor(), progress=False)
    rows = {(r["network_index"], r["r_tot"]): r for r in t.to_pylist()}
    assert len(rows) == 8
    assert "infeasible" in rows[(0, 2.0)]["error"]  # r_tot < N·r_min
    assert rows[(0, 6.0)]["error"] is None
    assert (
        rows[(1, 6.0)]["error"].startswith("InvalidInputError") and "G" in rows[(1, 6.0)]["error"]
    )
    assert rows[(2, 2.0)]["error"].startswith("FileNotFoundError")
    assert rows[(3, 6.0)]["error"] is None
    ref = optimal_allocation(Network.load(EXAMPLES / "three_subsystems.toml"), 6.0)
    assert rows[(3, 6.0)]["eta"] == ref.eta


def test_generator_is_streamed_with_a_bounded_window() -> None:
    produced: list[int] = []

    class Watching(SerialExecutor):
        def __init__(self) -> None:
            self.seen_at_submit: list[int] = []

        def submit(self, fn, /, *args, **kwargs):  # type: ignore[no-untyped-def]
            self.seen_at_submit.append(len(produced))
            return super().submit(fn, *args, **kwargs)

    def gen() -> Iterator[Network]:
        for k, net in enumerate(random_networks(12, 2, 1, seed=3)):
            produced.append(k)
            yield net

    ex = Watching()
    t = sweep(gen(), [3.0], executor=ex, chunk_size=2, max_pending=1, progress=False)
    assert t.num_rows == 12
    # each chunk is submitted when only its own networks (plus at most one look-ahead) exist
    assert ex.seen_at_submit == [2, 4, 6, 8, 10, 12]


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


def test_bad_arguments(nets: list[Network]) -> None:
    kw = {"executor": SerialExecutor(), "progress": False}
    with pytest.raises(InvalidInputError, match="compute"):
        sweep(nets, [5.0], compute="nope", **kw)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="finite"):
        sweep(nets, [float("nan")], **kw)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="empty"):
        sweep(nets, [], **kw)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="chunk_size"):
        sweep(nets, [5.0], chunk_size=0, **kw)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="networks must hold"):
        sweep([42], [5.0], **kw)  # type: ignore[arg-type, list-item]
    if _has_sampled():
        with pytest.raises(InvalidInputError, match="tau"):
            sweep(nets, [5.0], compute="schedule", **kw)  # type: ignore[arg-type]
        with pytest.raises(InvalidInputError, match="integers"):
            sweep(nets, [5.5], compute="schedule", tau=0.3, **kw)  # type: ignore[arg-type]
    # duplicates are dropped
    t = sweep(nets[:1], [5.0, 5, 5.0], **kw)  # type: ignore[arg-type]
    assert t.num_rows == 1


def test_networks_and_rows_pickle(nets: list[Network]) -> None:
    from capalloc_rs._tasks import TaskSpec, run_chunk

    net2 = pickle.loads(pickle.dumps(nets[0]))
    assert net2 is not nets[0] and net2 == nets[0]
    r = np.array([1.5, 2.0, 1.5])
    assert net2.cost(r) == nets[0].cost(r)  # the copy computes, bit for bit
    np.testing.assert_array_equal(net2.a, nets[0].a)
    spec = TaskSpec("id", 0, 5.0, "d", nets[0])
    spec2 = pickle.loads(pickle.dumps(spec))
    fields = (spec2.task_id, spec2.network_index, spec2.r_tot, spec2.network_digest)
    assert fields == ("id", 0, 5.0, "d")
    # A chunk run on the unpickled spec gives the rows of the one-at-a-time API.
    rows = run_chunk("allocation", {"method": "newton", "tol": 1e-12}, [spec2])
    a = optimal_allocation(nets[0], 5.0)
    assert rows[0]["task_id"] == "id" and rows[0]["eta"] == a.eta and rows[0]["r"] == a.r.tolist()
    assert pickle.loads(pickle.dumps(rows)) == rows


def test_spec_files(tmp_path: Path) -> None:
    spec = load_spec(EXAMPLES / "sweep.toml")
    assert spec.compute == "allocation" and spec.num_networks == 102
    assert spec.files[0] == EXAMPLES / "three_subsystems.toml"
    small = tmp_path / "s.json"
    small.write_text(
        json.dumps(
            {
                "compute": "filtration",
                "capacities": {"start": 4, "stop": 6, "num": 3},
                "networks": {"random": {"count": 2, "N": 2}},
            }
        )
    )
    s = load_spec(small)
    assert s.capacities == (4.0, 5.0, 6.0) and s.hessian == "auto"
    hvp_spec = tmp_path / "h.json"
    hvp_spec.write_text(
        json.dumps(
            {"capacities": [5], "hessian": "hvp", "networks": {"random": {"count": 1, "N": 2}}}
        )
    )
    assert load_spec(hvp_spec).hessian == "hvp"
    t = s.run(executor=SerialExecutor(), progress=False)
    assert t.num_rows == 6 and t.column("error").null_count == 6
    for bad, msg in [
        ({"capacities": [1], "networks": {"files": []}, "typo": 1}, "unknown key"),
        ({"capacities": [], "networks": {"files": ["a.toml"]}}, "capacities"),
        ({"capacities": [5], "networks": {"random": {"N": 2}}}, "count"),
        ({"capacities": [5], "networks": {"random": {"count": 1, "N": 0}}}, "positive"),
        ({"capacities": [5], "compute": "x", "networks": {"files": ["a"]}}, "compute"),
        ({"capacities": [5], "compute": "schedule", "networks": {"files": ["a"]}}, "tau"),
        ({"capacities": ["a"], "networks": {"files": ["a"]}}, "capacities"),
        ({"capacities": [5], "hessian": "cg", "networks": {"files": ["a"]}}, "hessian"),
    ]:
        small.write_text(json.dumps(bad))
        with pytest.raises(SweepError, match=msg):
            load_spec(small)
    small.write_text("{not json")
    with pytest.raises(SweepError, match="invalid JSON"):
        load_spec(small)


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


# -- dask.distributed -----------------------------------------------------------------------------


def test_dask_local_cluster(nets: list[Network], tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    caps = [4.0, 8.0]
    ref = sweep(nets, caps, executor=SerialExecutor(), progress=False)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        ex = client.get_executor()
        out = tmp_path / "dask"
        t = sweep(iter(nets), caps, executor=ex, out=out, chunk_size=3, progress=False)
        assert t.equals(ref, check_metadata=True)
        st = SweepStats()
        again = sweep(nets, caps, executor=ex, out=out, progress=False, stats=st)
        assert st.skipped == t.num_rows and again.equals(ref, check_metadata=True)


def test_random_networks_is_a_lazy_reproducible_sequence() -> None:
    rn = random_networks(5, 3, 2, eps=0.2, seed=9)
    assert len(rn) == 5
    items = list(rn)
    assert items[2] == rn[2] == rn[-3] == random_networks(5, 3, 2, eps=0.2, seed=9)[2]
    assert rn[1:3] == items[1:3]
    assert items[0] != items[1]
    assert items[0] == Network.random(3, 2, 1, 0.2, seed=rn.seed_of(0))
    with pytest.raises(IndexError):
        rn[5]
    with pytest.raises(InvalidInputError):
        random_networks(-1, 3)
    with pytest.raises(InvalidInputError):
        random_networks(2, 0)
    a = sweep(rn, [4.0], executor=SerialExecutor(), progress=False)
    b = sweep(items, [4.0], executor=SerialExecutor(), progress=False)
    assert a.equals(b)


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


def test_progress_bar_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from capalloc_rs.sweep import _progress_bar

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert _progress_bar(True, 10, 0) is None  # not a terminal
    tty = Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    assert _progress_bar(False, 10, 0) is None  # progress=False
    if pytest.importorskip("tqdm"):
        bar = _progress_bar(True, 10, 0)
        assert bar is not None
        bar.update(5)
        bar.close()
        assert "5/10" in tty.getvalue() and "task/s" in tty.getvalue()


# -- the output directory: one sweep at a time, only its own files, only its own part-files ------

_HOLDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from capalloc_rs._dirlock import DirLock

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


def test_bad_model_files_become_error_rows(nets: list[Network], tmp_path: Path) -> None:
    """Regression: a truncated .npz, deeply nested JSON and a big integer in JSON each killed the
    whole sweep with a traceback."""
    good = tmp_path / "good.npz"
    nets[0].save(str(good))
    bad = {
        "truncated.npz": good.read_bytes()[:200],
        "deep.json": b"[" * 100_000 + b"]" * 100_000,
        "bigint.json": b'{"r_min": 1' + b"0" * 400 + b"}",
    }
    paths: list[Any] = [good]
    for name, data in bad.items():
        (tmp_path / name).write_bytes(data)
        paths.append(tmp_path / name)
    t = sweep(paths, [5.0, 6.0], executor=SerialExecutor(), progress=False)
    errors = t.column("error").to_pylist()
    assert errors[:2] == [None, None]
    assert all(e and e.startswith("ModelFormatError") for e in errors[2:]), errors


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ({"networks": {"random": {"count": 1, "N": 1_000_000_000}}}, "MAX_MODEL_STATES"),
        ({"networks": {"random": {"count": 10**12, "N": 2}}}, "MAX_SWEEP_TASKS"),
        ({"networks": {"random": {"count": 1, "N": 10**400}}}, "number"),
        ({"networks": {"random": {"count": 1, "N": 2, "seed": -1}}}, "seed"),
        ({"capacities": {"start": 1, "stop": 2, "num": 10**12}}, "MAX_SWEEP_TASKS"),
        ({"capacities": [1e400]}, "capacities"),
    ],
)
def test_spec_limits(tmp_path: Path, spec: dict[str, Any], words: str) -> None:
    """Regression: ``N = 1000000000`` spun; now every spec is checked against the limits before
    anything runs."""
    full = {"capacities": [5.0], "networks": {"random": {"count": 1, "N": 2}}, **spec}
    p = tmp_path / "spec.json"
    p.write_text(json.dumps(full).replace("Infinity", "1e400"))
    with pytest.raises(SweepError, match=words):
        load_spec(p)


def test_spec_files_nested_or_with_big_numbers(tmp_path: Path) -> None:
    p = tmp_path / "spec.json"
    p.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(SweepError, match="MAX_NESTING"):
        load_spec(p)
    p = tmp_path / "spec.toml"
    p.write_text("capacities = [" + "9" * 5000 + "]\n")
    with pytest.raises(SweepError, match="invalid TOML"):
        load_spec(p)


def test_lock_without_flock_uses_the_owner_pid(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where ``flock`` is unavailable the lock file is created exclusively: a live owner's lock is
    refused, a dead owner's (its pid no longer runs) is taken over."""
    import errno
    import socket

    from capalloc_rs import _dirlock

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
