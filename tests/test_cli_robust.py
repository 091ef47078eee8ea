"""``capalloc solve --robust {mean,worst} MODEL1 MODEL2 …`` (issue 16, point 2): the JSON is the
API's result, the text shows the certificate, and misuse ends with one error line (no
traceback)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import EXAMPLES, MODEL, assert_user_error, ok_json, run

import capalloc_rs as cr


@pytest.fixture
def models(tmp_path: Path) -> list[str]:
    st = cr.Network.random(3, 2, eps=0.0, seed=1).structure
    paths = []
    for k, eps in enumerate((0.0, 0.15, 0.3)):
        net = cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, eps)
        path = tmp_path / f"m{k}.toml"
        net.save(path)
        paths.append(str(path))
    return paths


@pytest.mark.parametrize("objective", ["mean", "worst"])
def test_json_is_the_apis_result(models: list[str], objective: str) -> None:
    d = ok_json("solve", "--robust", objective, *models, "--r-tot", "9")
    want = cr.robust_allocation(models, 9.0, objective=objective)
    assert d == want.to_dict()
    assert d["gap"] >= 0 and d["lower_bound"] <= d["value"]


def test_weights_and_integer_counts(models: list[str]) -> None:
    d = ok_json("solve", "--robust", "mean", *models, "--r-tot", "9", "--weights", "1,2,1")
    want = cr.robust_allocation(models, 9.0, weights=[1, 2, 1])
    np.testing.assert_allclose(d["r"], want.r, rtol=1e-14)
    assert d["weights"] == pytest.approx([0.25, 0.5, 0.25])
    d = ok_json("solve", "--robust", "worst", *models, "--r-tot", "9", "--integer")
    assert sum(d["counts"]) == 9 and d["proven_optimal"] is False


def test_text_shows_the_certificate(models: list[str]) -> None:
    p = run("solve", "--robust", "worst", *models, "--r-tot", "9")
    assert p.returncode == 0, p.stderr
    assert "worst case" in p.stdout and "lower bound" in p.stdout and "gap" in p.stdout


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ((), ["--robust"]),
        (("--robust", "worst", "--weights", "1,2,3"), ["--weights"]),
        (("--robust", "mean", "--weights", "1,x,2"), ["--weights"]),
        (("--robust", "mean", "--weights", "1,2"), ["weights"]),
        (("--robust", "mean", "--method", "projected-gradient"), ["--method"]),
    ],
)
def test_misuse_is_one_error_line(models: list[str], extra: tuple[str, ...], words) -> None:
    assert_user_error(run("solve", *models, "--r-tot", "9", *extra), *words)


def test_models_of_other_sensors_are_refused(models: list[str]) -> None:
    p = run("solve", "--robust", "mean", models[0], str(EXAMPLES / "example1.toml"), "--r-tot", "9")
    assert_user_error(p, "models[1]")
    p = run("solve", "--robust", "median", *models, "--r-tot", "9")
    assert_user_error(p, "--robust")


def test_single_model_solve_unchanged() -> None:
    d = ok_json("solve", MODEL, "--r-tot", "8")
    assert d == cr.optimal_allocation(cr.Network.load(MODEL), 8.0).to_dict()
    assert_user_error(run("solve", MODEL, "--r-tot", "8", "--weights", "1"), "--weights")
