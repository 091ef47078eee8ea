"""The network model: construction forms, validation, the check() report, files, pickling."""

from __future__ import annotations

import json
import pickle
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs import model_io
from capalloc_rs.errors import (
    InputError,
    InvalidInputError,
    ModelFormatError,
    NonFiniteError,
    NotDetectableError,
    NotObservableError,
    ShapeError,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def example1_blocks() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = np.diag([-1.0, -2.0])
    g = np.linalg.cholesky(np.array([[5.0, -3.0], [-3.0, 4.0]]))
    c = np.array([1.0, 1.0])
    return a, g, c


def small_block_network(eps: float = 0.3) -> cr.Network:
    """Heterogeneous: sizes 2, 3, 1; outputs 1, 2, 1; couplings given per pair."""
    rng = np.random.default_rng(7)
    a = [rng.standard_normal((k, k)) for k in (2, 3, 1)]
    g = [np.eye(k) + 0.2 * np.tril(rng.standard_normal((k, k)), -1) for k in (2, 3, 1)]
    c = [rng.standard_normal(2), rng.standard_normal((3, 2)), np.array([[1.5]])]
    couplings = {(0, 1): rng.standard_normal((2, 3)), (2, 0): rng.standard_normal((1, 2))}
    return cr.Network.from_blocks(a, g, c, couplings, eps=eps, r_min=0.5)


# -- construction --------------------------------------------------------------------------------


def test_general_form_copies_and_freezes() -> None:
    a, g, c = example1_blocks()
    c2 = c.copy()
    net = cr.Network(a, g, [c2])
    c2[0] = 100.0
    assert net.sensors[0][0, 0] == 1.0
    assert net.n == 2 and net.num_sensors == 1 and net.outputs == (1,)
    assert net.structure is None and net.eps is None
    for arr in (net.a, net.g, net.sensors[0]):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[0, 0] = 1.0
    with pytest.raises(AttributeError):
        net.r_min = 2.0  # type: ignore[misc]
    with pytest.raises(AttributeError):
        net._a = a  # type: ignore[misc]
    np.testing.assert_allclose(net.q, np.array([[5.0, -3.0], [-3.0, 4.0]]), atol=1e-14)


def test_from_blocks_assembles_the_paper_matrices() -> None:
    net = small_block_network(eps=0.3)
    st = net.structure
    assert st is not None
    assert st.sizes == (2, 3, 1) and st.offsets == (0, 2, 5, 6)
    assert net.outputs == (1, 2, 1)
    assert net.n == 6 and net.r_min == 0.5 and net.eps == 0.3
    np.testing.assert_array_equal(net.a[0:2, 0:2], st.a_blocks[0])
    np.testing.assert_array_equal(net.a[0:2, 2:5], 0.3 * st.block(0, 1))
    np.testing.assert_array_equal(net.a[5:6, 0:2], 0.3 * st.block(2, 0))
    np.testing.assert_array_equal(net.a[2:5, 0:2], 0.0)
    np.testing.assert_array_equal(net.g[2:5, 2:5], st.g_blocks[1])
    np.testing.assert_array_equal(net.g[0:2, 2:6], 0.0)
    np.testing.assert_array_equal(net.sensors[1][2:5], st.c_blocks[1])
    np.testing.assert_array_equal(net.sensors[1][[0, 1, 5]], 0.0)
    assert set(st.couplings) == {(0, 1), (2, 0)}
    # the three ways of passing couplings agree
    items = [(i, j, b) for (i, j), b in st.couplings.items()]
    same = cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, items, 0.3, 0.5)
    full = cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, 0.3, 0.5)
    assert same == net and full == net and hash(same) == hash(net)


def test_from_statespace_duck_typing() -> None:
    a, g, c = example1_blocks()
    sys1 = SimpleNamespace(A=a, B=np.zeros((2, 1)), C=c.reshape(1, 2), D=np.zeros((1, 1)))
    sys2 = SimpleNamespace(A=np.array([[0.5]]), C=np.array([[2.0], [1.0]]))  # p = 2
    net = cr.Network.from_statespace([sys1, sys2], [g, np.eye(1)], {(0, 1): [[1.0], [0.0]]}, 0.1)
    assert net.outputs == (1, 2)
    np.testing.assert_array_equal(net.sensors[1][2], [2.0, 1.0])
    single = cr.Network.from_statespace(sys1, g)
    assert single.num_sensors == 1
    with pytest.raises(InvalidInputError, match=r"systems\[1\]"):
        cr.Network.from_statespace([sys1, object()], [g, g])


def test_from_statespace_python_control() -> None:
    control = pytest.importorskip("control")
    a, g, c = example1_blocks()
    sys = control.ss(a, np.ones((2, 1)), c.reshape(1, 2), 0)
    net = cr.Network.from_statespace([sys], [g])
    np.testing.assert_allclose(net.covariance([1.0]), [[2.0, -1.0], [-1.0, 1.0]], atol=1e-12)


def test_random_is_reproducible_and_observable() -> None:
    a = cr.Network.random(6, 3, p=2, eps=0.2, seed=11)
    b = cr.Network.random(6, 3, p=2, eps=0.2, seed=11)
    c = cr.Network.random(6, 3, p=2, eps=0.2, seed=12)
    assert a == b and a != c
    np.testing.assert_array_equal(a.a, b.a)
    het = cr.Network.random(4, n=[1, 2, 3, 4], p=[1, 1, 2, 3], seed=3)
    assert het.n == 10 and het.outputs == (1, 1, 2, 3)
    for seed in range(5):
        rep = cr.Network.random(8, 3, eps=0.5, seed=seed).check()
        assert rep.detectable and rep.observable
        assert all(s.observable for s in rep.subsystems)
    with pytest.raises(InvalidInputError):
        cr.Network.random(0)
    with pytest.raises(InvalidInputError):
        cr.Network.random(3, n=[1, 2])


def test_equality_hash_repr() -> None:
    a, g, c = example1_blocks()
    n1 = cr.Network(a, g, [c])
    n2 = cr.Network(a.copy(), g.copy(), [c.copy()])
    n3 = cr.Network(a, g, [c], r_min=2.0)
    nb = cr.Network.from_blocks([a], [g], [c])
    assert n1 == n2 and hash(n1) == hash(n2)
    assert n1 != n3
    assert n1 != nb  # same matrices, but one carries a block description
    assert len({n1, n2, n3}) == 2
    assert "general" in repr(n1) and "block" in repr(nb)


def test_pickle_round_trip() -> None:
    net = small_block_network()
    back = pickle.loads(pickle.dumps(net))
    assert back == net
    assert back.structure is not None and not back.structure.a_blocks[0].flags.writeable
    assert not back.a.flags.writeable
    r = np.array([1.0, 2.0, 0.7])
    assert back.cost(r) == net.cost(r)


# -- validation ----------------------------------------------------------------------------------


def test_general_form_validation() -> None:
    a, g, c = example1_blocks()
    with pytest.raises(ShapeError, match="A must be square"):
        cr.Network(np.ones((2, 3)), g, [c])
    with pytest.raises(ShapeError, match="G must be 2×m"):
        cr.Network(a, np.eye(3), [c])
    with pytest.raises(ShapeError, match=r"sensors\[1\]"):
        cr.Network(a, g, [c, np.ones(3)])
    with pytest.raises(NonFiniteError, match=r"sensors\[0\]"):
        cr.Network(a, g, [np.array([1.0, np.nan])])
    with pytest.raises(NonFiniteError, match="A"):
        cr.Network(np.array([[np.inf, 0], [0, 1.0]]), g, [c])
    with pytest.raises(NonFiniteError, match="A"):
        cr.Network(np.array([[np.nan, 0], [0, 1.0]]), g, [c])
    with pytest.raises(ShapeError, match="G must be 2×m"):
        cr.Network(a, np.zeros((2, 0)), [c])
    with pytest.raises(ShapeError, match="at least one sensor"):
        cr.Network(a, g, [])
    with pytest.raises(InvalidInputError, match="list"):
        cr.Network(a, g, np.ones((2, 1)))  # ambiguous: a matrix is not a list of sensors
    for bad in (-1.0, -5e-324, np.nan):
        with pytest.raises(InvalidInputError, match="r_min"):
            cr.Network(a, g, [c], r_min=bad)
    with pytest.raises(InvalidInputError, match="at least one sensor needs a positive minimum"):
        cr.Network(a, g, [c], r_min=0.0)  # every sensor may be off: no measurement at all
    with pytest.raises(InvalidInputError, match="complex"):
        cr.Network(a, g, [np.array([1j, 1.0])])


def test_undetectable_general_network() -> None:
    # the unstable mode x_1 is seen by no sensor
    with pytest.raises(NotDetectableError, match="λ = 1"):
        cr.Network(np.diag([1.0, -1.0]), np.eye(2), [np.array([0.0, 1.0])])
    # an unobservable but stable mode is fine (detectable)
    cr.Network(np.diag([-1.0, 2.0]), np.eye(2), [np.array([0.0, 1.0])])


def test_block_validation_names_the_subsystem() -> None:
    a, g, c = example1_blocks()
    with pytest.raises(ShapeError, match="subsystem 1: A_1 must be square"):
        cr.Network.from_blocks([a, np.ones((2, 3))], [g, g], [c, c])
    with pytest.raises(ShapeError, match="subsystem 1: G_1"):
        cr.Network.from_blocks([a, a], [g, np.eye(3)], [c, c])
    with pytest.raises(ShapeError, match="subsystem 2: G_2 must be 2×m"):
        cr.Network.from_blocks([a, a, a], [g, g, np.ones((3, 1))], [c, c, c])
    with pytest.raises(ShapeError, match="subsystem 0: c_0"):
        cr.Network.from_blocks([a], [g], [np.ones(3)])
    with pytest.raises(NonFiniteError, match="subsystem 1: c_1"):
        cr.Network.from_blocks([a, a], [g, g], [c, [np.nan, 1.0]])
    with pytest.raises(ShapeError, match="same length"):
        cr.Network.from_blocks([a, a], [g], [c, c])
    # subsystem 1 has a mode (λ = −2, eigenvector e_2) that its sensor cannot see
    with pytest.raises(NotObservableError, match=r"subsystem 1: \(A_1, c_1\) is not observable"):
        cr.Network.from_blocks([a, a], [g, g], [c, np.array([1.0, 0.0])])
    # repeated eigenvalue with a one-dimensional sensor: never observable
    with pytest.raises(NotObservableError, match="subsystem 0"):
        cr.Network.from_blocks([-np.eye(2)], [np.eye(2)], [np.array([1.0, 1.0])])
    # a Jordan block observed at the right end is observable
    cr.Network.from_blocks([np.array([[0.0, 1.0], [0.0, 0.0]])], [np.eye(2)], [[1.0, 0.0]])


def test_coupling_validation() -> None:
    a, g, c = example1_blocks()
    args = ([a, a], [g, g], [c, c])
    with pytest.raises(InvalidInputError, match=r"\(1, 1\)"):
        cr.Network.from_blocks(*args, {(1, 1): np.eye(2)})
    with pytest.raises(InvalidInputError, match="out of range"):
        cr.Network.from_blocks(*args, {(0, 2): np.eye(2)})
    with pytest.raises(ShapeError, match=r"couplings\[\(0, 1\)\] must be 2×2"):
        cr.Network.from_blocks(*args, {(0, 1): np.eye(3)})
    with pytest.raises(InvalidInputError, match="twice"):
        cr.Network.from_blocks(*args, [(0, 1, np.eye(2)), (0, 1, np.eye(2))])
    with pytest.raises(InvalidInputError, match="diagonal block of subsystem 0"):
        cr.Network.from_blocks(*args, np.ones((4, 4)))
    with pytest.raises(InvalidInputError, match="eps"):
        cr.Network.from_blocks(*args, eps=np.inf)
    with pytest.raises(InvalidInputError, match="eps"):
        cr.Network.from_blocks(*args, eps=np.nan)


def test_coupling_can_destroy_detectability() -> None:
    # Each (A_i, c_i) is observable, but the coupling creates an unstable eigenvector
    # v = (0, 1, 0, 1), λ = 1, on which both sensors read zero.
    a_i = np.array([[-1.0, 1.0], [0.0, -2.0]])
    c_i = np.array([1.0, 0.0])
    v_i = np.array([0.0, 1.0])
    w = 1.0 * v_i - a_i @ v_i  # ε A_12 v_2 must supply λ v_1 − A_1 v_1
    eps = 0.5
    block = np.outer(w, v_i) / eps
    args = ([a_i, a_i], [np.eye(2), np.eye(2)], [c_i, c_i])
    with pytest.raises(NotDetectableError, match="λ = 1"):
        cr.Network.from_blocks(*args, {(0, 1): block, (1, 0): block}, eps=eps)
    cr.Network.from_blocks(*args, {(0, 1): block, (1, 0): block}, eps=0.0)


# -- check() -------------------------------------------------------------------------------------


def test_example_1_is_not_a_regular_triplet() -> None:
    a, g, c = example1_blocks()
    for net in (cr.Network(a, g, [c]), cr.Network.from_blocks([a], [g], [c])):
        rep = net.check()
        assert rep.detectable and rep.observable
        (sub,) = rep.subsystems
        assert sub.observable
        assert sub.regular is False
        assert sub.regularity_margin is not None and sub.regularity_margin < 1e-12
        assert sub.least_controllable_mode is not None
        assert abs(sub.least_controllable_mode - (-2.0)) < 1e-12
        assert rep.regular is False and not rep.ok
        assert "False" in str(rep)


def test_check_report_on_a_random_network() -> None:
    net = cr.Network.random(5, n=[2, 3, 1, 2, 2], p=[1, 2, 1, 1, 1], eps=0.2, seed=4)
    rep = net.check()
    assert rep.n == 10 and rep.num_sensors == 5 and rep.eps == 0.2
    assert len(rep.subsystems) == 5
    assert [s.n for s in rep.subsystems] == [2, 3, 1, 2, 2]
    assert [s.p for s in rep.subsystems] == [1, 2, 1, 1, 1]
    assert rep.ok and rep.regular is True
    assert all(0 < s.g_rcond <= 1 for s in rep.subsystems)
    text = str(rep)
    assert "eps = 0.2" in text and text.count("\n") >= 5 + 5
    # general networks with several sensors have no subsystem breakdown
    gen = cr.Network(net.a, net.g, list(net.sensors))
    assert gen.check().subsystems == () and gen.check().regular is None


# -- files ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["toml", "json", "npz"])
def test_round_trip(tmp_path: Path, fmt: str) -> None:
    nets = [
        small_block_network(),
        cr.Network.random(4, 2, p=2, seed=1),
        cr.Network(*example1_blocks()[:2], [example1_blocks()[2]], r_min=0.25),
    ]
    for k, net in enumerate(nets):
        path = tmp_path / f"m{k}.{fmt}"
        net.save(path)
        back = cr.Network.load(path)
        assert back == net, fmt
    # explicit format overrides the extension
    path = tmp_path / "model.txt"
    nets[0].save(path, format="json")
    assert cr.Network.load(path, format="json") == nets[0]
    with pytest.raises(InputError, match="unknown model format"):
        nets[0].save(tmp_path / "model.yaml")


def test_example_files_load() -> None:
    ex1 = cr.Network.load(EXAMPLES / "example1.toml")
    np.testing.assert_allclose(ex1.covariance([1.0]), [[2.0, -1.0], [-1.0, 1.0]], atol=1e-12)
    assert ex1.check().regular is False
    net = cr.Network.load(EXAMPLES / "three_subsystems.toml")
    assert net.structure is not None and net.structure.sizes == (2, 3, 1)
    assert net == cr.Network.load(EXAMPLES / "three_subsystems.json")


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


GOOD = """
r_min = 1.0
eps = 0.1
[[subsystems]]
A = [[-1.0, 0.0], [0.0, -2.0]]
G = [[1.0, 0.0], [0.0, 1.0]]
c = [1.0, 1.0]
[[subsystems]]
A = [[0.5]]
G = [[1.0]]
c = [[1.0, 2.0]]
[[couplings]]
i = 0
j = 1
A = [[1.0], [0.0]]
"""


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("A = [[0.5]]", "A = [[0.5, 1.0]]", r"subsystems\[1\]\.A: must be square"),
        ("G = [[1.0]]", "G = [[1.0], [0.0]]", r"subsystems\[1\]\.G: must have 1 rows"),
        ("c = [1.0, 1.0]", 'c = [1.0, "x"]', r"subsystems\[0\]\.c\[1\]: expected a number"),
        ("c = [1.0, 1.0]", "c = [1.0, 1.0, 1.0]", r"subsystems\[0\]\.c: must have 2 rows"),
        ("A = [[1.0], [0.0]]", "A = [[1.0, 0.0]]", r"couplings\[0\]\.A: must have 2 rows"),
        ("j = 1", "j = 5", r"couplings\[0\]\.j: 5 is out of range"),
        ("j = 1", "j = 0", r"couplings\[0\]: i = j = 0"),
        ("eps = 0.1", 'eps = "small"', r"eps: expected a number"),
        ("r_min = 1.0", "r_min = -1.0", r"r_min: must be non-negative"),
        ("r_min = 1.0", "r_min = 1.0\nrmin = 2.0", r"unknown key\(s\) \['rmin'\]"),
        ("G = [[1.0, 0.0], [0.0, 1.0]]", "Gx = [[1.0]]", r"subsystems\[0\]: unknown key"),
        ("A = [[-1.0, 0.0], [0.0, -2.0]]", "A = [[-1.0, 0.0], [0.0]]", r"rows have different"),
        ("r_min = 1.0", 'format = "other"', r"format: must be"),
        ("r_min = 1.0", "version = 7", r"version: unsupported"),
    ],
)
def test_malformed_toml_names_the_field(tmp_path: Path, old: str, new: str, field: str) -> None:
    assert old in GOOD
    cr.Network.load(write(tmp_path, "ok.toml", GOOD))
    path = write(tmp_path, "bad.toml", GOOD.replace(old, new, 1))
    with pytest.raises(ModelFormatError, match=field):
        cr.Network.load(path)


def test_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(ModelFormatError, match="invalid TOML"):
        cr.Network.load(write(tmp_path, "x.toml", "A = [[1.0, 2.0]\n"))
    with pytest.raises(ModelFormatError, match="invalid JSON"):
        cr.Network.load(write(tmp_path, "x.json", "{"))
    with pytest.raises(ModelFormatError, match="needs either"):
        cr.Network.load(write(tmp_path, "e.json", "{}"))
    with pytest.raises(ModelFormatError, match="missing key"):
        cr.Network.load(write(tmp_path, "g.json", json.dumps({"A": [[1.0]], "G": [[1.0]]})))
    with pytest.raises(ModelFormatError, match=r"sensors\[0\]\.c: must have 1 rows"):
        d = {"A": [[-1.0]], "G": [[1.0]], "sensors": [{"c": [1.0, 2.0]}]}
        cr.Network.load(write(tmp_path, "s.json", json.dumps(d)))
    # a well-formed file describing an invalid model raises the model's error, with the path
    bad_model = GOOD.replace("c = [1.0, 1.0]", "c = [1.0, 0.0]")
    path = write(tmp_path, "unobs.toml", bad_model)
    with pytest.raises(NotObservableError, match=re.escape(str(path)) + ": subsystem 0"):
        cr.Network.load(path)


def test_malformed_npz(tmp_path: Path) -> None:
    net = small_block_network()
    path = tmp_path / "m.npz"
    net.save(path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    broken = dict(arrays)
    del broken["G_1"]
    np.savez(tmp_path / "nog.npz", **broken)
    with pytest.raises(ModelFormatError, match="G_1: missing array"):
        cr.Network.load(tmp_path / "nog.npz")
    extra = dict(arrays, junk=np.ones(2))
    np.savez(tmp_path / "junk.npz", **extra)
    with pytest.raises(ModelFormatError, match="junk"):
        cr.Network.load(tmp_path / "junk.npz")
    wrong = dict(arrays, A_0=np.ones((2, 3)))
    np.savez(tmp_path / "wrong.npz", **wrong)
    with pytest.raises(ShapeError, match="subsystem 0: A_0 must be square"):
        cr.Network.load(tmp_path / "wrong.npz")
    (tmp_path / "garbage.npz").write_bytes(b"not a zip")
    with pytest.raises(ModelFormatError, match="not a readable"):
        cr.Network.load(tmp_path / "garbage.npz")


def test_toml_text_is_readable() -> None:
    text = model_io.dumps_toml(model_io.to_dict(small_block_network()))
    assert text.count("[[subsystems]]") == 3 and text.count("[[couplings]]") == 2
    assert "eps = 0.3" in text
