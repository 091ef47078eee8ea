"""``capalloc solve`` and ``capalloc sweep`` on a model file with per-sensor ``cost``, ``r_min`` and
``r_max`` (issue 15, points 3 and 5): the budget B through ``--r-tot`` and the capacities, the new
result fields in the JSON, the text and the sweep's columns, and one error line (no traceback) for
bad values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import assert_user_error, has, ok_json, run

import capalloc_rs as cr

MODEL = """
[[subsystems]]
A = [[-1.0, 0.3], [0.0, -0.5]]
G = [[1.0, 0.0], [0.2, 0.8]]
c = [1.0, 0.0]
cost = 2.0
r_min = 1.0
[[subsystems]]
A = [[0.4]]
G = [[1.0]]
c = [1.5]
cost = 0.5
r_min = 2.0
r_max = 3.0
[[subsystems]]
A = [[-0.2]]
G = [[1.2]]
c = [0.7]
r_min = 0.5
"""


@pytest.fixture
def model(tmp_path: Path) -> Path:
    path = tmp_path / "costed.toml"
    path.write_text(MODEL)
    return path


def test_solve_json_is_the_apis_allocation(model: Path) -> None:
    net = cr.Network.load(model)
    assert not net.is_paper_form
    d = ok_json("solve", str(model), "--r-tot", "9")
    a = cr.optimal_allocation(net, 9.0)
    assert d == a.to_dict()
    assert d["budget"] == 9.0 and d["costs"] == [2.0, 0.5, 1.0]
    assert d["at_cap"] == [1] and d["upper_multipliers"][1] > 0
    assert float(np.dot(d["costs"], d["r"])) == pytest.approx(9.0, rel=1e-14)


def test_solve_text_shows_the_budget_and_the_caps(model: Path) -> None:
    p = run("solve", str(model), "--r-tot", "9")
    assert p.returncode == 0, p.stderr
    assert "budget B = 9 channel units" in p.stdout
    assert "at their cap  = [1]" in p.stdout and "shadow price" in p.stdout


def test_solve_integer_with_a_real_budget(model: Path) -> None:
    d = ok_json("solve", str(model), "--r-tot", "9.5", "--integer")
    ia = cr.integer_allocation(cr.Network.load(model), 9.5)
    assert d["counts"] == [int(k) for k in ia.counts] and d["spent"] <= 9.5
    assert d["proven_optimal"] is True
    p = run("solve", str(model), "--r-tot", "9.5", "--integer")
    assert p.returncode == 0 and "proven optimal" in p.stdout


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--r-tot", "2"], ["r_tot", "budget range"]),
        (["--r-tot", "3"], ["r_tot", "budget range"]),
        (["--r-tot", "9", "--method", "double-bracket"], ["double-bracket"]),
        (["--r-tot", "2", "--integer"], ["infeasible budget"]),
    ],
)
def test_bad_budgets_are_one_error_line(model: Path, args: list[str], words: list[str]) -> None:
    assert_user_error(run("solve", str(model), *args), *words)


def test_bad_limits_in_the_file_are_one_error_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(MODEL.replace("r_max = 3.0", "r_max = 1.0"))
    assert_user_error(run("solve", str(path), "--r-tot", "9"), "r_max")
    path.write_text(MODEL.replace("cost = 0.5", "cost = 0.0"))
    assert_user_error(run("solve", str(path), "--r-tot", "9"), "cost")


@pytest.mark.skipif(not has("pyarrow"), reason="sweeps write Parquet")
def test_sweep_of_a_costed_model(model: Path, tmp_path: Path) -> None:
    spec = tmp_path / "sweep.toml"
    spec.write_text(
        'compute = "allocation"\ncapacities = [8.0, 9.0, 3.0]\n'
        f'[networks]\nfiles = ["{model.name}"]\n'
    )
    out = tmp_path / "out"
    p = run("sweep", str(spec), "--out", str(out), "--no-progress")
    assert p.returncode == 0, p.stderr
    import pyarrow.parquet as pq

    rows = pq.read_table(out).to_pylist()
    by_budget = {row["r_tot"]: row for row in rows}
    net = cr.Network.load(model)
    for budget in (8.0, 9.0):
        row, a = by_budget[budget], cr.optimal_allocation(net, budget)
        assert row["error"] is None and row["eta"] == a.eta
        assert row["budget"] == budget and row["at_cap"] == list(a.at_cap)
        assert row["upper_multipliers"] == list(a.upper_multipliers)
    assert "budget range" in by_budget[3.0]["error"]
