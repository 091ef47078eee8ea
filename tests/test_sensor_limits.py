"""Per-sensor sample costs, rate minima and caps on the network: construction, validation,
identity, files, and the channel-units form (its cost at ``s = b∘r`` is the network's at ``r``)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs.errors import InvalidInputError, ShapeError

COSTS = [1.0, 2.5, 0.4]
R_MIN = [0.5, 1.0, 2.0]
R_MAX = [np.inf, 6.0, 9.0]


def _net(**kw: object) -> cr.Network:
    base = cr.Network.random(3, 2, eps=0.1, seed=7)
    st = base.structure
    assert st is not None
    return cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, st.eps, **kw)


def test_properties_and_budget() -> None:
    net = _net(costs=COSTS, r_min=R_MIN, r_max=R_MAX)
    np.testing.assert_array_equal(net.costs, COSTS)
    np.testing.assert_array_equal(net.rate_min, R_MIN)
    np.testing.assert_array_equal(net.rate_max, R_MAX)
    assert not net.is_paper_form
    np.testing.assert_array_equal(net.r_min, R_MIN)
    lo = 1.0 * 0.5 + 2.5 * 1.0 + 0.4 * 2.0
    assert net.budget_range == (lo, np.inf)
    assert net.budget_of([1.0, 2.0, 3.0]) == pytest.approx(1.0 + 5.0 + 1.2, rel=1e-15)
    np.testing.assert_array_equal(net.rates_from_gamma([0.0, 1.0, 2.0]), [0.5, 2.0, 4.0])
    capped = _net(r_max=[4.0, 5.0, 6.0], costs=2.0)
    assert capped.budget_range == (6.0, 30.0)
    with pytest.raises(ShapeError, match="rates must have length 3"):
        net.budget_of([1.0, 2.0])
    for arr in (net.costs, net.rate_min, net.rate_max):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 3.0
    assert "costs=[1, 2.5, 0.4]" in repr(net) and "r_max=[inf, 6, 9]" in repr(net)


def test_paper_form_is_unchanged() -> None:
    plain = cr.Network.random(3, 2, eps=0.1, seed=7)
    same = _net(costs=1.0, r_min=[1.0, 1.0, 1.0], r_max=np.inf)
    assert plain.is_paper_form and same.is_paper_form
    assert same == plain and hash(same) == hash(plain)
    assert plain.r_min == 1.0 and isinstance(plain.r_min, float)
    assert repr(plain) == repr(same) and "r_min=1)" in repr(plain)
    assert plain.in_channel_units() is plain
    assert plain.budget_range == (3.0, np.inf)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"costs": [1.0, -2.0, 1.0]}, InvalidInputError, r"costs\[1\] must be positive"),
        ({"costs": [1.0, np.inf, 1.0]}, cr.errors.NonFiniteError, r"costs\[1\]"),
        ({"costs": [1.0, 2.0]}, ShapeError, "costs must be a scalar or have one entry per sensor"),
        ({"r_min": [1.0, -1.0, 1.0]}, InvalidInputError, r"r_min\[1\] must be non-negative"),
        ({"r_max": [5.0, 0.5, 5.0]}, InvalidInputError, r"r_max\[1\] = 0.5 must exceed"),
        ({"r_max": [5.0, np.nan, 5.0]}, cr.errors.NonFiniteError, r"r_max\[1\]"),
        ({"r_max": "5"}, InvalidInputError, "r_max"),
    ],
)
def test_bad_limits_name_the_argument(kwargs: dict[str, object], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        _net(**kwargs)


def test_identity_pickle_and_constructors() -> None:
    net = _net(costs=COSTS, r_min=R_MIN, r_max=R_MAX)
    assert net != _net(costs=COSTS, r_min=R_MIN)
    assert net != _net(costs=[1.0, 2.5, 0.5], r_min=R_MIN, r_max=R_MAX)
    back = pickle.loads(pickle.dumps(net))
    assert back == net and hash(back) == hash(net)
    np.testing.assert_array_equal(back.rate_max, R_MAX)
    general = cr.Network(net.a, net.g, net.sensors, R_MIN, costs=COSTS, r_max=R_MAX)
    np.testing.assert_array_equal(general.costs, COSTS)
    assert general.cost([2.0, 3.0, 4.0]) == net.cost([2.0, 3.0, 4.0])
    a = net.a
    c = [s.T for s in net.sensors]
    model = cr.Network.from_model(a, net.g, 1.0, c, 1.0, costs=COSTS, r_min=R_MIN, r_max=R_MAX)
    np.testing.assert_array_equal(model.rate_min, R_MIN)
    assert model.cost([2.0, 3.0, 4.0]) == pytest.approx(net.cost([2.0, 3.0, 4.0]), rel=1e-13)


@pytest.mark.parametrize("fmt", ["toml", "json", "npz"])
@pytest.mark.parametrize("general", [False, True])
def test_files_round_trip(tmp_path, fmt: str, general: bool) -> None:
    net = _net(costs=COSTS, r_min=R_MIN, r_max=R_MAX)
    if general:
        net = cr.Network(net.a, net.g, net.sensors, R_MIN, costs=COSTS, r_max=R_MAX)
    path = tmp_path / f"net.{fmt}"
    net.save(path)
    back = cr.Network.load(path)
    assert back == net
    if fmt == "toml":
        text = path.read_text()
        assert "cost = 2.5" in text and "r_max = 6.0" in text


def test_file_per_sensor_fields_and_errors(tmp_path) -> None:
    text = """
r_min = 2.0
[[subsystems]]
A = [[-1.0]]
G = [[1.0]]
c = [1.0]
cost = 3.0
[[subsystems]]
A = [[0.5]]
G = [[1.0]]
C = [2.0]
R = [[4.0]]
r_max = 7.0
"""
    path = tmp_path / "m.toml"
    path.write_text(text)
    net = cr.Network.load(path)
    np.testing.assert_array_equal(net.costs, [3.0, 1.0])
    np.testing.assert_array_equal(net.rate_min, [2.0, 2.0])
    np.testing.assert_array_equal(net.rate_max, [np.inf, 7.0])
    path.write_text(text.replace("cost = 3.0", "cost = -3.0"))
    with pytest.raises(cr.errors.ModelFormatError, match=r"subsystems\[0\]\.cost"):
        cr.Network.load(path)
    path.write_text(text.replace("r_max = 7.0", "r_max = 1.0"))
    with pytest.raises(cr.errors.CapallocError, match="r_max"):
        cr.Network.load(path)


def test_channel_units_cost_gradient_hessian() -> None:
    """``η_s(s) = η(s/b)``, ``∂η/∂r_i = b_i ∂η_s/∂s_i``, ``∇²_r η = diag(b) ∇²_s η diag(b)``."""
    net = _net(costs=COSTS, r_min=R_MIN, r_max=R_MAX)
    ch = net.in_channel_units()
    b = np.array(COSTS)
    assert ch.is_paper_form is False  # the minima b∘r_min differ
    np.testing.assert_array_equal(ch.costs, 1.0)
    np.testing.assert_allclose(ch.rate_min, b * R_MIN, rtol=1e-15)
    np.testing.assert_allclose(ch.rate_max, b * R_MAX, rtol=1e-15)
    assert ch.budget_range == pytest.approx(net.budget_range, rel=1e-15)
    r = np.array([1.3, 2.2, 4.1])
    s = b * r
    assert ch.cost(s) == pytest.approx(net.cost(r), rel=1e-13)
    np.testing.assert_allclose(b * ch.gradient(s), net.gradient(r), rtol=1e-11)
    np.testing.assert_allclose(
        np.diag(b) @ ch.hessian(s) @ np.diag(b), net.hessian(r), rtol=1e-10, atol=1e-14
    )
    assert ch.structure is not None
    np.testing.assert_allclose(ch.structure.c_blocks[1], net.structure.c_blocks[1] / np.sqrt(2.5))


def test_check_reports_the_feasible_budgets(tmp_path) -> None:
    net = _net(costs=2.0, r_max=[4.0, 5.0, 6.0])
    rep = net.check()
    assert rep.budget_range == (6.0, 30.0)
    assert rep.to_dict()["budget_range"] == [6.0, 30.0]
    assert "feasible budgets 6 ≤ B ≤ 30" in str(rep)
    assert cr.Network.random(3, 2, seed=7).check().to_dict()["budget_range"] is None
    open_top = _net(costs=2.0).check().to_dict()["budget_range"]
    assert open_top == [6.0, None]
