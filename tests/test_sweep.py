"""Sweeps: equality with the one-at-a-time API, determinism, failures recorded, bounded streaming,
lazy random networks, dask.distributed. (Resuming and the output directory:
test_sweep_resume.py; spec files: test_sweep_spec.py.)"""

from __future__ import annotations

import json
import pickle
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import Network
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.errors import InvalidInputError

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from capalloc_rs.sweep import (  # noqa: E402
    SerialExecutor,
    SweepStats,
    random_networks,
    sweep,
    task_id,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


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


def test_schedule_sweep_equals_single_api(nets: list[Network]) -> None:
    best_schedule = capalloc_rs.best_schedule
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
    bad.write_text("[[subsystems]]\nA = [[0.0]]\nG = [[0.0]]\nc = [1.0]\n")  # unexcited λ = 0
    items = [nets[0], bad, str(tmp_path / "missing.toml"), EXAMPLES / "three_subsystems.toml"]
    t = sweep(items, [2.0, 6.0], executor=SerialExecutor(), progress=False)
    rows = {(r["network_index"], r["r_tot"]): r for r in t.to_pylist()}
    assert len(rows) == 8
    assert "infeasible" in rows[(0, 2.0)]["error"]  # r_tot < N·r_min
    assert rows[(0, 6.0)]["error"] is None
    assert (
        rows[(1, 6.0)]["error"].startswith("UnexcitedAxisModeError")
        and "G" in rows[(1, 6.0)]["error"]
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
    with pytest.raises(InvalidInputError, match="tau"):
        sweep(nets, [5.0], compute="schedule", **kw)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="integers"):
        sweep(nets, [5.5], compute="schedule", tau=0.3, **kw)  # type: ignore[arg-type]
    # duplicates are dropped
    t = sweep(nets[:1], [5.0, 5, 5.0], **kw)  # type: ignore[arg-type]
    assert t.num_rows == 1


def test_networks_and_rows_pickle(nets: list[Network]) -> None:
    from capalloc_rs.sweep.tasks import TaskSpec, run_chunk

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


def test_progress_bar_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from capalloc_rs.sweep.run import _progress_bar

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


def test_stats_to_dict_and_short_reprs(nets: list[Network]) -> None:
    from capalloc_rs.sweep.rowtable import RowTable

    st = SweepStats()
    t = sweep(nets[:2], [5.0, 6.0], executor=SerialExecutor(), progress=False, stats=st)
    d = st.to_dict()
    assert json.loads(json.dumps(d, allow_nan=False)) == d
    assert {k: d[k] for k in ("tasks", "computed", "skipped", "failed", "chunks")} == {
        "tasks": 4,
        "computed": 4,
        "skipped": 0,
        "failed": 0,
        "chunks": st.chunks,
    }
    assert d["seconds"] == st.seconds >= 0 and type(d["tasks"]) is int
    plain = RowTable(t.to_pylist(), t.column_names)
    text = repr(plain)
    assert "\n" not in text and len(text) < 200 and text.startswith("RowTable(4 rows × ")
    assert "\n" not in repr(random_networks(3, 2)) and len(repr(random_networks(3, 2))) < 200
