"""The ``"robust"`` sweep task (issue 16, point 2): each task is the robust allocation over the
task's network with an uncertain coupling strength; its row is the API's result, the spec's
``[robust]`` table is checked field by field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs.allocation import coupling_models
from capalloc_rs.errors import InvalidInputError, SweepError
from capalloc_rs.sweep import SerialExecutor, load_spec, random_networks, sweep
from capalloc_rs.sweep.tasks import robust_eps


def test_rows_are_the_apis_robust_allocation() -> None:
    nets = list(random_networks(2, 3, seed=4))
    robust = {"objective": "worst", "num_models": 3, "eps": [0.0, 0.3], "seed": 5}
    t = sweep(
        nets, [9.0], compute="robust", robust=robust, executor=SerialExecutor(), progress=False
    )
    rows = t.to_pylist()
    assert len(rows) == 2 and all(r["error"] is None for r in rows)
    eps = np.random.default_rng(5).uniform(0.0, 0.3, size=3)
    for row in rows:
        net = nets[row["network_index"]]
        models = coupling_models(net, eps)
        want = cr.robust_allocation(models, 9.0, objective="worst")
        np.testing.assert_array_equal(row["r"], want.r)
        assert row["value"] == row["eta"] == want.value and row["gap"] == want.gap
        nominal = cr.optimal_allocation(net, 9.0).r
        assert row["nominal_value"] == max(m.cost(nominal) for m in models)
        assert row["value"] <= row["nominal_value"] * (1 + 1e-12)
    params = {"seed": 5, "eps_low": 0.0, "eps_high": 0.3, "num_models": 3}
    np.testing.assert_array_equal(robust_eps(params), eps)


def test_a_network_without_blocks_is_an_error_row() -> None:
    base = cr.Network.random(2, 1, seed=0)
    flat = cr.Network(base.a, base.g, list(base.sensors))
    t = sweep([flat], [5.0], compute="robust", executor=SerialExecutor(), progress=False)
    assert "block network" in t.column("error").to_pylist()[0]


@pytest.mark.parametrize(
    ("robust", "match"),
    [
        ({"objective": "median"}, "objective"),
        ({"eps": [0.3, 0.0]}, "eps"),
        ({"eps": 0.3}, "eps"),
        ({"num_models": 0}, "num_models"),
        ({"seed": -1}, "seed"),
        ({"typo": 1}, "unknown"),
    ],
)
def test_bad_robust_options(robust, match, tmp_path: Path) -> None:
    nets = list(random_networks(1, 2))
    with pytest.raises(InvalidInputError, match=match):
        sweep(nets, [5.0], compute="robust", robust=robust, progress=False)
    spec = tmp_path / "s.json"
    body = {"compute": "robust", "capacities": [5], "networks": {"random": {"count": 1, "N": 2}}}
    spec.write_text(json.dumps({**body, "robust": robust}))
    with pytest.raises(SweepError, match=match):
        load_spec(spec)


def test_spec_with_a_robust_table(tmp_path: Path) -> None:
    spec = tmp_path / "s.toml"
    spec.write_text(
        'compute = "robust"\ncapacities = [6.0]\n[robust]\nobjective = "mean"\nnum_models = 2\n'
        "[networks.random]\ncount = 1\nN = 2\n"
    )
    s = load_spec(spec)
    assert s.compute == "robust" and s.robust == {"objective": "mean", "num_models": 2}
    t = s.run(executor=SerialExecutor(), progress=False)
    row = t.to_pylist()[0]
    assert row["error"] is None and row["num_models"] == 2 and row["objective"] == "mean"
    other = tmp_path / "o.json"
    other.write_text(
        json.dumps({"capacities": [5], "robust": {}, "networks": {"random": {"count": 1, "N": 2}}})
    )
    with pytest.raises(SweepError, match="robust"):
        load_spec(other)
    with pytest.raises(InvalidInputError, match="robust"):
        sweep(list(random_networks(1, 2)), [5.0], robust={}, progress=False)
