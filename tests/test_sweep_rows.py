"""One serialisation: a sweep's row is its result's ``to_dict()`` (the CLI's ``--json``), flattened
by one documented rule; directories of the earlier output format are refused, not misread."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import capalloc_rs as ca
from capalloc_rs.cli import main

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from capalloc_rs.errors import SweepError  # noqa: E402
from capalloc_rs.sweep import read_results, sweep  # noqa: E402
from capalloc_rs.sweep.columns import NOT_COLUMNS, columns, flatten  # noqa: E402

MODEL = str(Path(__file__).resolve().parent.parent / "examples" / "three_subsystems.toml")
#: The columns that say which task a row is (and whether it failed), not what it computed.
IDENTITY = {"task_id", "network_index", "r_tot", "network_digest", "num_sensors", "error"}
#: The columns a filtration's row adds at its end point (an allocation's ``to_dict()`` has them).
AT_END = {"eta", "r", "mu", "shadow_price"}


def _flat_by_hand(d: dict[str, Any]) -> dict[str, Any]:
    """The rule written out for two levels (what pandas.json_normalize does with sep=".")."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update({f"{k}.{k2}": v2 for k2, v2 in v.items()})
        else:
            out[k] = v
    return out


def test_flatten_joins_nested_keys_with_dots() -> None:
    d = {"a": 1, "b": {"c": [1, 2], "d": {"e": None}}, "f": [{"g": 1}]}
    assert flatten(d) == {"a": 1, "b.c": [1, 2], "b.d.e": None, "f": [{"g": 1}]}
    pd = pytest.importorskip("pandas")
    # the same names as pandas gives them (pandas orders nested columns after the flat ones)
    assert sorted(pd.json_normalize(d, max_level=5).columns) == ["a", "b.c", "b.d.e", "f"]


def _row(compute: str, r_tot: float, **kw: Any) -> dict[str, Any]:
    net = ca.Network.load(MODEL)
    t = sweep([net], [r_tot], compute=compute, executor=ca.SerialExecutor(), progress=False, **kw)
    assert t.column_names == [name for name, _ in columns(compute)]
    (row,) = t.to_pylist()
    assert row["error"] is None
    return dict(row)


def _same(row: dict[str, Any], d: dict[str, Any], compute: str) -> None:
    """The row's columns are the flattened dict's keys (but NOT_COLUMNS), with the same values."""
    flat = {k: v for k, v in _flat_by_hand(d).items() if k not in NOT_COLUMNS[compute]}
    assert set(row) - IDENTITY - AT_END == set(flat) - IDENTITY - AT_END
    for k, v in flat.items():
        if k not in IDENTITY:
            assert row[k] == v, k


def test_allocation_row_is_the_allocations_to_dict() -> None:
    row = _row("allocation", 8.0)
    d = ca.optimal_allocation(ca.Network.load(MODEL), 8.0).to_dict()
    _same(row, d, "allocation")
    assert row["certificate.frank_wolfe_gap"] == d["certificate"]["frank_wolfe_gap"]
    assert row["r_tot"] == 8.0


def test_filtration_row_is_the_filtrations_to_dict_and_the_end_point() -> None:
    net = ca.Network.load(MODEL)
    row = _row("filtration", 8.0)
    sigma_max = 8.0 - 3 * net.r_min
    f = ca.filtration(net, sigma_max, tol=1e-10)
    _same(row, f.to_dict(), "filtration")
    # the end point by the continuous optimum at r_tot (another route than the path's nodes)
    a = ca.optimal_allocation(net, 8.0)
    np.testing.assert_allclose(row["r"], a.r, rtol=1e-7, atol=1e-9)
    assert row["eta"] == pytest.approx(a.eta, rel=1e-9)
    assert row["shadow_price"] == -row["mu"] == pytest.approx(a.shadow_price, rel=1e-7)
    assert row["events"] == f.to_dict()["events"] and row["events"]


def test_schedule_row_is_the_best_schedules_to_dict_without_wall_time() -> None:
    row = _row("schedule", 7, tau=0.5)
    d = ca.best_schedule(ca.Network.load(MODEL), 0.5, 7).to_dict()
    _same(row, d, "schedule")
    assert "elapsed" in d and "elapsed" not in row
    assert row["eta"] == row["eta_bar"] == d["eta_bar"]
    assert row["baselines.greedy"] == d["baselines"]["greedy"]
    assert row["r_tot"] == 7 and type(row["r_tot"]) is int


@pytest.mark.parametrize(
    ("compute", "argv"),
    [
        ("allocation", ["solve", MODEL, "--r-tot", "8"]),
        ("filtration", ["trace", MODEL, "--sigma-max", "5"]),
        ("schedule", ["schedule", MODEL, "--tau", "0.5", "--r-tot", "7", "--no-progress"]),
    ],
)
def test_cli_json_and_sweep_rows_share_one_set_of_keys(
    compute: str, argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*argv, "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    keys = set(_flat_by_hand(printed)) - NOT_COLUMNS[compute]
    cols = {name for name, _ in columns(compute)} - IDENTITY - AT_END
    assert cols == keys - IDENTITY - AT_END


@pytest.mark.parametrize("command", ["solve", "trace", "schedule"])
def test_cli_json_keeps_every_key_it_printed_before(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from cli_reference import allocation_dict, filtration_dict, schedule_dict

    from capalloc_rs._json import plain

    net = ca.Network.load(MODEL)
    argv, before = {
        "solve": (["--r-tot", "8"], lambda: allocation_dict(ca.optimal_allocation(net, 8.0))),
        "trace": (["--sigma-max", "5"], lambda: filtration_dict(ca.filtration(net, 5.0))),
        "schedule": (
            ["--tau", "0.5", "--r-tot", "7"],
            lambda: schedule_dict(ca.best_schedule(net, 0.5, 7)),
        ),
    }[command]
    quiet = [] if command == "solve" else ["--no-progress"]
    assert main([command, MODEL, *argv, "--json", *quiet]) == 0
    now = json.loads(capsys.readouterr().out)
    old = plain(before())
    _keeps(now, old)


def _keeps(now: Any, old: Any) -> None:
    """``now`` has everything ``old`` had, with the same values (dicts may have gained keys,
    also inside lists: the filtration's events gained ``mu`` and ``shadow_price``)."""
    if isinstance(old, dict):
        assert isinstance(now, dict) and set(old) <= set(now), set(old) - set(now)
        for k, v in old.items():
            _keeps(now[k], v)
    elif isinstance(old, list):
        assert isinstance(now, list) and len(now) == len(old)
        for a, b in zip(now, old, strict=True):
            _keeps(a, b)
    else:
        assert now == old


def _old_directory(out: Path) -> None:
    """A directory as the sweep of output format 1 wrote it: its manifest, and a part-file with
    the old column names (gap, kkt_residual)."""
    out.mkdir()
    params = {"method": "newton", "tol": 1e-12}
    manifest = {
        "format": "capalloc-sweep-output",
        "version": 1,
        "compute": "allocation",
        "params": params,
        "sweep_id": "0123456789abcdef",
    }
    (out / "_sweep.json").write_text(json.dumps(manifest))
    old = pa.table(
        {
            "task_id": ["00000000-c020000000000000-000000000000"],
            "network_index": [0],
            "r_tot": [8.0],
            "network_digest": ["f04e0b6838075093"],
            "num_sensors": [3],
            "error": pa.array([None], pa.string()),
            "eta": [1.0],
            "gap": [0.0],
            "kkt_residual": [0.0],
        }
    ).replace_schema_metadata({"sweep_id": "0123456789abcdef"})
    pq.write_table(old, out / "part-old.parquet")


def test_a_directory_of_the_old_column_names_is_refused_clearly(tmp_path: Path) -> None:
    out = tmp_path / "old"
    _old_directory(out)
    net = ca.Network.load(MODEL)
    with pytest.raises(SweepError, match=r"output format version 1.*to_dict\(\) keys"):
        sweep([net], [8.0], executor=ca.SerialExecutor(), out=out, progress=False)
    with pytest.raises(SweepError, match="output format version 1"):
        read_results(out)
    assert (out / "part-old.parquet").exists()  # nothing was touched
    assert json.loads((out / "_sweep.json").read_text())["version"] == 1
    # starting afresh is the way out, and writes the current format
    t = sweep([net], [8.0], executor=ca.SerialExecutor(), out=out, resume=False, progress=False)
    assert t.num_rows == 1 and "certificate.frank_wolfe_gap" in t.column_names
    assert json.loads((out / "_sweep.json").read_text())["version"] == 2
    assert read_results(out).equals(t)


def test_the_cli_refuses_an_old_directory_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "old"
    _old_directory(out)
    spec = tmp_path / "spec.toml"
    spec.write_text(f'capacities = [8.0]\n[networks]\nfiles = ["{MODEL}"]\n')
    assert main(["sweep", str(spec), "--out", str(out), "--resume", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "output format version 1" in err
