"""Issue 13, point 4: what a newcomer trips over, each fixed and kept fixed.

Each test names the stumble it covers. Checks go by an independent route where there is a number
(the same computation through the other entry point, or the JSON parsed back and typed).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import ALIASING_TAU, MODEL, ROOT, assert_user_error, child_env, run

import capalloc_rs as ca
from capalloc_rs import errors
from capalloc_rs.cli import build_parser, main

#: Runs the CLI (or a snippet) with some modules made unimportable by an import hook.
_BLOCKED_RUN = """
import sys
BLOCKED = tuple(sys.argv[1].split(","))
class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"No module named {name!r} (blocked by the test)")
        return None
sys.meta_path.insert(0, Blocker())
if sys.argv[2] == "-c":
    exec(sys.argv[3])
else:
    from capalloc_rs.cli import main
    sys.exit(main(sys.argv[2:]))
"""


def blocked(modules: str, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", _BLOCKED_RUN, modules, *args],
        env=child_env(),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


# -- 1. help --------------------------------------------------------------------------------------


def test_no_arguments_prints_the_help_and_succeeds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    out = capsys.readouterr()
    assert out.out.startswith("usage: capalloc")
    for command in ("demo", "check", "solve", "trace", "schedule", "simulate", "sweep"):
        assert command in out.out
    assert out.err == ""
    p = run()
    assert p.returncode == 0 and p.stdout.startswith("usage: capalloc"), p.stderr


def _actions(parser: argparse.ArgumentParser, where: str) -> list[tuple[str, argparse.Action]]:
    found = []
    for action in parser._actions:
        found.append((where, action))
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _actions(sub, f"{where} {name}")
    return found


def test_every_option_of_every_subcommand_has_help() -> None:
    actions = _actions(build_parser(), "capalloc")
    assert len(actions) > 50
    missing = [
        f"{where}: {'/'.join(a.option_strings) or a.dest}"
        for where, a in actions
        if not (isinstance(a.help, str) and a.help.strip() and a.help != argparse.SUPPRESS)
    ]
    assert missing == []


# -- 2. optional dependencies ---------------------------------------------------------------------


def _pyproject() -> dict[str, Any]:
    tomllib = pytest.importorskip("tomllib")
    return dict(tomllib.loads((ROOT / "pyproject.toml").read_text()))


def test_extras_named_in_messages_exist_and_sweep_has_pandas() -> None:
    from capalloc_rs._optional import EXTRAS, pip_command

    extras = _pyproject()["project"]["optional-dependencies"]
    for module, extra in EXTRAS.items():
        assert extra in extras, (module, extra)
        assert pip_command(module) == f"pip install 'capalloc-rs[{extra}]'"
    sweep = " ".join(extras["sweep"])
    assert "pandas" in sweep and "pyarrow" in sweep  # table.to_pandas() is advertised
    assert "pandas" in " ".join(extras["all"])


def test_plot_without_matplotlib_is_a_missing_dependency_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    f = ca.filtration(ca.Network.load(MODEL), 2.0)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib → ImportError
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(errors.MissingDependencyError, match=r"pip install 'capalloc-rs\[plot\]'"):
        f.plot()
    with pytest.raises(ImportError):  # still an ImportError for code that catches that
        f.plot()


def test_explicit_plot_without_matplotlib_exits_2(tmp_path: Path) -> None:
    for args in (
        ("trace", MODEL, "--sigma-max", "2", "--plot", "f.png"),
        ("demo", "--plot", "f.png", "--periods", "5", "--runs", "2"),
    ):
        p = blocked("matplotlib", *args, cwd=tmp_path)
        assert_user_error(p, "matplotlib", "pip install 'capalloc-rs[plot]'")
        assert not (tmp_path / "f.png").exists()
    # without --plot, nothing needs matplotlib
    p = blocked("matplotlib", "trace", MODEL, "--sigma-max", "2", cwd=tmp_path)
    assert p.returncode == 0, p.stderr


# -- 3. plain ints in all output ------------------------------------------------------------------

#: Keys whose values are counts, slots, seeds or sensor indices (scalars or nested lists of them).
INT_KEYS = {
    "counts", "schedule", "seed", "runs", "periods", "periods_completed", "moves",
    "evaluations", "iterations", "exchanges", "sensor", "active", "entry_order", "active_sets",
    "index", "n", "p", "N", "num_sensors", "outputs", "hessian_vector_products",
}  # fmt: skip


def _assert_ints(obj: Any, path: str = "") -> int:
    """Checks every INT_KEYS value in parsed JSON; returns how many leaves it checked."""
    checked = 0
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k in INT_KEYS:
                checked += _leaves_are_ints(v, f"{path}.{k}")
            else:
                checked += _assert_ints(v, f"{path}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            checked += _assert_ints(v, f"{path}[{i}]")
    return checked


def _leaves_are_ints(v: Any, path: str) -> int:
    if isinstance(v, list):
        return sum(_leaves_are_ints(x, f"{path}[]") for x in v)
    if v is None:
        return 0
    if isinstance(v, dict):  # e.g. the demo's "schedule" section
        return _assert_ints(v, path)
    assert type(v) is int, f"{path} = {v!r} ({type(v).__name__})"
    return 1


def _json(*args: str) -> Any:
    p = run(*args, "--json")
    assert p.returncode == 0, p.stderr
    assert "np.int" not in p.stdout and "np.float" not in p.stdout
    return json.loads(p.stdout)


def test_json_output_has_plain_ints() -> None:
    d = _json("solve", MODEL, "--r-tot", "8", "--integer")
    assert type(d["r_tot"]) is int and d["r_tot"] == 8 == sum(d["counts"])
    assert _assert_ints(d) == 3 + 2  # counts, exchanges, evaluations
    assert _assert_ints(_json("solve", MODEL, "--r-tot", "8")) >= 2
    assert _assert_ints(_json("trace", MODEL, "--sigma-max", "3")) >= 6
    s = _json("schedule", MODEL, "--tau", "0.5", "--r-tot", "8.0")
    assert type(s["r_tot"]) is int and _assert_ints(s) >= 8 + 3
    m = _json("simulate", MODEL, "--tau", "0.5", "--schedule", "0,1,2,1", "--periods", "5",
              "--runs", "3", "--seed", "7")  # fmt: skip
    assert m["seed"] == 7 and _assert_ints(m) >= 4 + 4
    demo = _json("demo", "--periods", "5", "--runs", "2")
    assert _assert_ints(demo) > 20


def test_text_output_has_plain_ints() -> None:
    p = run("solve", MODEL, "--r-tot", "8", "--integer")
    assert p.returncode == 0, p.stderr
    assert "np.int" not in p.stdout and "counts [" in p.stdout
    counts = json.loads(p.stdout.split("counts ", 1)[1].split("]", 1)[0] + "]")
    assert counts == list(ca.integer_allocation(ca.Network.load(MODEL), 8).counts)


def test_sweep_rows_have_plain_ints() -> None:
    pytest.importorskip("pyarrow")
    net = ca.Network.load(MODEL)
    t = ca.sweep([net], [6, 8], compute="schedule", tau=0.5, executor=ca.SerialExecutor(),
                 progress=False)  # fmt: skip
    rows = t.to_pylist()
    assert len(rows) == 2
    for row in rows:
        assert row["error"] is None
        # counts, slots, num_sensors, and the search's moves and evaluations
        assert _assert_ints(row) == 3 + row["r_tot"] + 1 + 2
        assert type(row["network_index"]) is int and type(row["r_tot"]) is int


# -- 4. integral floats as slot counts; one rule for r_min ----------------------------------------


def test_integral_floats_are_slot_counts_everywhere() -> None:
    net = ca.Network.load(MODEL)
    b_int = ca.best_schedule(net, 0.5, 8)
    b_float = ca.best_schedule(net, 0.5, 8.0)
    assert b_float.schedule == b_int.schedule and b_float.eta_bar == b_int.eta_bar
    assert ca.best_schedule(net, 0.5, np.float64(8.0)).schedule == b_int.schedule
    counts = ca.integer_allocation(net, 8).counts
    assert list(ca.integer_allocation(net, 8.0).counts) == list(counts)
    assert ca.round_robin_schedule(net, 6.0) == ca.round_robin_schedule(net, 6)
    for bad in (8.5, math.nan, "8"):
        for fn in (
            lambda r: ca.best_schedule(net, 0.5, r),
            lambda r: ca.integer_allocation(net, r),
            lambda r: ca.round_robin_schedule(net, r),
        ):
            with pytest.raises(errors.InvalidInputError, match="r_tot"):
                fn(bad)
    assert_user_error(
        run("schedule", MODEL, "--tau", "0.5", "--r-tot", "8.5"), "--r-tot", "integer"
    )
    assert_user_error(run("solve", MODEL, "--r-tot", "8.5", "--integer"), "--r-tot", "integer")
    # counts on the CLI too: "5.0" periods is 5 periods, "5.5" is refused naming the option
    args = ("simulate", MODEL, "--tau", "0.5", "--schedule", "0,1,2", "--seed", "3")
    a = _json(*args, "--periods", "5.0", "--runs", "2.0")
    b = _json(*args, "--periods", "5", "--runs", "2")
    assert a == b and a["periods"] == 5 and a["runs"] == 2
    assert_user_error(run(*args, "--periods", "5.5"), "--periods", "integer")


def test_best_schedule_never_starves_a_sensor() -> None:
    # `capalloc schedule examples/three_subsystems.toml --tau 31.4 --r-tot 8` ended with "rates
    # must be positive, got r[2] = 0": a batch of moves took sensor 2's only slot.
    net = ca.Network.load(MODEL)
    for tau in (10.0, 31.4, 50.0):
        b = ca.best_schedule(net, tau, 8)
        assert sum(b.counts) == 8 and min(b.counts) >= 1  # r_min = 1
        assert b.eta_limit == net.cost(np.asarray(b.counts, dtype=float))  # by the other route
        assert b.eta_bar == pytest.approx(ca.sampled_cost(net, tau, b.schedule), rel=1e-12)


def test_one_rule_for_non_integer_r_min() -> None:
    # r_min = 1.5: every sensor needs ⌈1.5⌉ = 2 slots, in integer allocations and in schedules
    net = ca.Network.from_blocks(
        [[[-1.0]], [[-2.0]], [[0.5]]], [[[1.0]], [[1.0]], [[1.0]]], [[1.0], [1.0], [1.0]],
        r_min=1.5,
    )  # fmt: skip
    counts = list(ca.integer_allocation(net, 7).counts)
    assert sum(counts) == 7 and min(counts) == 2
    best = ca.best_schedule(net, 0.5, 7)
    assert sum(best.counts) == 7 and min(best.counts) >= 2
    for fn in (lambda: ca.integer_allocation(net, 5), lambda: ca.best_schedule(net, 0.5, 5)):
        with pytest.raises(errors.InputError, match="6"):  # N·⌈r_min⌉ = 6 slots at least
            fn()


# -- 5. from_statespace ---------------------------------------------------------------------------


def test_from_statespace_refuses_discrete_time_and_transfer_functions() -> None:
    control = pytest.importorskip("control")
    cont = control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    net = ca.Network.from_statespace(cont, [np.eye(1)])
    assert net.n == 1
    for dt in (0.1, True):
        disc = control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt)
        with pytest.raises(errors.InvalidInputError, match=r"discrete-time.*dt = 0"):
            ca.Network.from_statespace(disc, [np.eye(1)])
        with pytest.raises(errors.InvalidInputError, match=r"systems\[1\] is a discrete"):
            ca.Network.from_statespace([cont, disc], [np.eye(1), np.eye(1)])
    tf = control.tf([1.0], [1.0, 1.0])
    for systems in (tf, [cont, tf]):
        with pytest.raises(errors.InvalidInputError, match=r"transfer function.*control\.ss"):
            ca.Network.from_statespace(systems, [np.eye(1)] * (1 + isinstance(systems, list)))
    # the conversion the message names works
    assert ca.Network.from_statespace(control.ss(tf), [np.eye(1)]).n == 1


# -- 7. --no-check, and paths wherever a Network is -----------------------------------------------


def test_no_check_on_the_cli_with_the_api_warning() -> None:
    p = run("schedule", MODEL, "--tau", str(ALIASING_TAU), "--r-tot", "8")
    line = assert_user_error(p, "not in 𝒯", "--no-check")
    assert "check=False" not in line
    for cmd in (
        ("schedule", MODEL, "--tau", str(ALIASING_TAU), "--r-tot", "8", "--no-check"),
        ("simulate", MODEL, "--tau", str(ALIASING_TAU), "--r-tot", "8", "--no-check",
         "--periods", "5", "--runs", "2"),
    ):  # fmt: skip
        p = run(*cmd)
        assert p.returncode == 0, p.stderr
        warns = [ln for ln in p.stderr.splitlines() if ln.startswith("capalloc: warning: ")]
        assert len(warns) == 1, p.stderr  # once, however many API calls warned
        assert "--no-check" in warns[0] and "not checked" in warns[0]
    # the API's warning, and the same numbers as the CLI by the other route
    net = ca.Network.load(MODEL)
    with pytest.warns(errors.UncheckedExistenceWarning, match="not checked") as rec:
        b = ca.best_schedule(net, ALIASING_TAU, 8, check=False)
    assert rec[0].filename == __file__  # attributed to the caller, not the package
    with pytest.warns(errors.UncheckedExistenceWarning):
        ca.sampled_cost(net, ALIASING_TAU, b.schedule, check=False)
    d = _json("schedule", MODEL, "--tau", str(ALIASING_TAU), "--r-tot", "8", "--no-check")
    assert d["schedule"] == list(b.schedule) and d["eta_bar"] == b.eta_bar
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # check=True (the default) warns about nothing
        ca.best_schedule(net, 0.5, 8)


def test_paths_accepted_wherever_a_network_is(tmp_path: Path) -> None:
    net = ca.Network.load(MODEL)
    for path in (MODEL, Path(MODEL)):
        assert np.array_equal(ca.optimal_allocation(path, 8).r, ca.optimal_allocation(net, 8).r)
        assert list(ca.integer_allocation(path, 8).counts) == list(
            ca.integer_allocation(net, 8).counts
        )
        assert np.array_equal(ca.filtration(path, 2.0).breakpoints,
                              ca.filtration(net, 2.0).breakpoints)  # fmt: skip
        assert ca.best_schedule(path, 0.5, 6).schedule == ca.best_schedule(net, 0.5, 6).schedule
        assert ca.round_robin_schedule(path, 6) == ca.round_robin_schedule(net, 6)
        assert ca.sampled_cost(path, 0.5, [0, 1, 2]) == ca.sampled_cost(net, 0.5, [0, 1, 2])
        assert (
            ca.simulate(path, 0.5, [0, 1, 2], 5, 1, runs=2).mse
            == ca.simulate(net, 0.5, [0, 1, 2], 5, 1, runs=2).mse
        )
        ca.check_existence(path, 0.5)
        d_path, d_net = ca.sampled.discretise(path, 0.5, 4), ca.sampled.discretise(net, 0.5, 4)
        assert np.array_equal(d_path.E, d_net.E)
        assert ca.scheduling.initial_counts(path, 8) == ca.scheduling.initial_counts(net, 8)
    assert ca.optimal_allocation(net=MODEL, r_tot=8).eta == ca.optimal_allocation(net, 8).eta
    with pytest.raises(errors.InputError):
        ca.optimal_allocation(tmp_path, 8)  # a directory
    for missing in (str(tmp_path / "missing.toml"), tmp_path / "missing.json", "missing.npz"):
        with pytest.raises(errors.InvalidInputError, match="net = .* not a readable model file"):
            ca.optimal_allocation(missing, 8)
    bad = tmp_path / "bad.toml"
    bad.write_text("this is not = [a model")
    with pytest.raises(errors.ModelFormatError):
        ca.optimal_allocation(bad, 8)


# -- the filtration plot at 20 sensors (issue 13 point 4) ----------------------------------------


def test_filtration_plot_is_readable_at_20_sensors(tmp_path: Path) -> None:
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    net = ca.Network.random(20, 2, 1, eps=0.05, seed=3)
    f = ca.filtration(net, 10.0)
    ax = f.plot()
    ax.figure.canvas.draw()
    renderer = ax.figure.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in ax.texts]
    assert len(boxes) >= 8  # breakpoints close together (σ = 0.140, 0.144, 0.162 here)
    for i in range(len(boxes)):
        for j in range(i):
            assert not boxes[i].overlaps(boxes[j]), (ax.texts[i].get_text(), ax.texts[j].get_text())
    lines = ax.get_lines()[:20]
    styles = {(matplotlib.colors.to_hex(ln.get_color()), ln.get_linestyle()) for ln in lines}
    assert len(styles) == 20  # no two sensors drawn alike
    # the curves are the path, by the other route (Filtration.allocation), also as rates
    assert f.plot(log=True).get_yscale() == "symlog"  # shares start at zero
    ax2 = f.plot(rates=True, log=True)
    assert ax2.get_yscale() == "log"  # rates are positive
    x, y = ax2.get_lines()[7].get_data()
    k = len(x) // 2
    assert y[k] == pytest.approx(f.allocation(x[k])[7] + net.r_min, rel=1e-9, abs=1e-12)
    plt.close("all")


def test_print_filtration_is_short() -> None:
    net = ca.Network.random(20, 2, 1, eps=0.05, seed=3)
    f = ca.filtration(net, 10.0)
    text = repr(f)
    assert str(f) == text and "\n" not in text and len(text) < 300  # was ~15,000 characters
    assert f"{f.breakpoints[1]:.4g}" in text and f"({len(f.breakpoints) - 2} in all)" in text
    assert text.startswith("Filtration(σ ∈ [0, 10]") and "is_filtration=" in text


def test_breakpoint_labels_share_one_sigma() -> None:
    from capalloc_rs.allocation import FiltrationEvent
    from capalloc_rs.allocation.filtration_plot import _breakpoint_labels, _label_rows

    events = [
        FiltrationEvent(0.0, "enter", 1),
        FiltrationEvent(0.5, "enter", 5),
        FiltrationEvent(0.5 + 1e-12, "enter", 4),
        FiltrationEvent(0.7, "leave", 2),
        FiltrationEvent(0.7, "stall", 3),
    ]
    assert _breakpoint_labels(events, 10.0) == [(0.5, "+5,+4"), (0.7, "−2")]
    assert _label_rows([(0, 2), (1, 3), (2.5, 4), (5, 6)]) == [0, 1, 0, 0]


def test_trace_plot_options(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    p = run("trace", MODEL, "--sigma-max", "3", "--plot", "r.png", "--rates", "--log", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "r.png").stat().st_size > 1000


# -- 8. demo outputs ------------------------------------------------------------------------------


def test_demo_writes_nothing_into_the_working_directory(tmp_path: Path) -> None:
    p = run("demo", "--periods", "5", "--runs", "2", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = run("demo", "--periods", "5", "--runs", "2", "--no-plot", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert list(tmp_path.iterdir()) == []


def test_readme_and_example_outputs_are_ignored_by_git() -> None:
    ignore = (ROOT / ".gitignore").read_text().split()
    for pattern in ("/results/", "/filtration.png", "capalloc-demo-filtration.png"):
        assert pattern in ignore
