"""Sweep spec files: parsing, the checks of every field, the limits, and running a spec."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from capalloc_rs import errors as cr_errors
from capalloc_rs.errors import SweepError

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

from capalloc_rs.sweep import (  # noqa: E402
    SerialExecutor,
    load_spec,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


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


def test_spec_random_networks_with_costs_and_caps(tmp_path: Path) -> None:
    """``[networks.random]`` takes ``costs`` and ``r_max`` (a number or one per sensor): every
    network carries them, and the capacities are budgets B."""
    p = tmp_path / "spec.toml"
    p.write_text(
        "capacities = [12.0]\n[networks.random]\ncount = 2\nN = 3\n"
        "costs = [1.0, 2.0, 3.0]\nr_max = [inf, 2.0, inf]\n"
    )
    spec = load_spec(p)
    nets = spec.networks()
    assert [list(n.costs) for n in nets] == [[1.0, 2.0, 3.0]] * 2
    assert [n.rate_max[1] for n in nets] == [2.0, 2.0]
    t = spec.run(executor=SerialExecutor(), progress=False)
    rows = t.to_pylist()
    assert len(rows) == 2 and all(r["error"] is None for r in rows)
    for r in rows:
        assert r["budget"] == pytest.approx(12.0)
        assert sum(b * x for b, x in zip([1.0, 2.0, 3.0], r["r"], strict=True)) == pytest.approx(
            12.0
        )
        assert r["r"][1] <= 2.0
    p.write_text("capacities = [12.0]\n[networks.random]\ncount = 1\nN = 3\ncosts = 'x'\n")
    with pytest.raises(SweepError, match="networks.random.costs"):
        load_spec(p)
    p.write_text(
        "capacities = [12.0]\n[networks.random]\ncount = 1\nN = 3\ncosts = [1.0, -2.0, 1.0]\n"
    )
    with pytest.raises(cr_errors.InvalidInputError, match=r"costs\[1\] must be positive"):
        load_spec(p).networks()
