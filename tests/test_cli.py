"""The ``capalloc`` command line, through a real subprocess: every subcommand, ``--json``, bad
model files and bad arguments (one line on stderr, exit status 2, never a traceback). (``capalloc
sweep``: test_cli_sweep.py; budgets and progress: test_cli_budgets.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import EXAMPLES, MODEL, PKG_ROOT, assert_user_error, has, ok_json, run

import capalloc_rs
from capalloc_rs import Network
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.cli import demo_network


def assert_mc_interval(d: dict[str, Any], mc: Any) -> None:
    """The CLI's Monte Carlo numbers are the API's, and the interval is the documented
    two-sided Student-t interval mse ± t_{(1+level)/2, runs−1}·stderr (t from scipy; the package's
    Cornish–Fisher quantile is within 1e-3 of it for df ≥ 5)."""
    from scipy import stats

    assert d["mse"] == mc.mse and d["ci"] == [mc.ci_low, mc.ci_high]
    assert d["runs"] == mc.runs and d["level"] == mc.level == 0.95
    t = stats.t.ppf(0.5 + mc.level / 2, mc.runs - 1)
    assert d["ci"][1] - d["ci"][0] == pytest.approx(2 * t * mc.stderr, rel=1e-3)
    assert mc.mse - d["ci"][0] == pytest.approx(d["ci"][1] - mc.mse, rel=1e-9)


def test_demo_text(tmp_path: Path) -> None:
    p = run("demo", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = p.stdout
    for s in ("Optimal allocation", "certificate", "Filtration", "active set", "schedule"):
        assert s in out
    # issue 13: nothing is written into the working directory unless asked (--plot FILE)
    assert not list(tmp_path.iterdir())
    assert "plot" not in out
    if has("matplotlib"):
        p = run("demo", "--plot", "f.png", cwd=tmp_path)
        assert p.returncode == 0, p.stderr
        assert (tmp_path / "f.png").stat().st_size > 1000
        assert "plot saved to f.png" in p.stdout
    assert "Monte Carlo" in out and "η̄(τ, R)" in out


def test_demo_json_matches_the_api(tmp_path: Path) -> None:
    d = ok_json("demo", "--no-plot", cwd=tmp_path)
    assert not list(tmp_path.iterdir())
    net = demo_network()
    assert net == Network.load(MODEL)
    a = optimal_allocation(net, 8.0)
    assert d["allocation"]["eta"] == a.eta
    assert d["allocation"]["r"] == a.r.tolist()
    assert d["allocation"]["certificate"]["frank_wolfe_gap"] <= 1e-10
    f = filtration(net, 12.0)
    assert d["filtration"]["breakpoints"] == f.breakpoints.tolist()
    assert d["filtration"]["entry_order"] == list(f.entry_order)
    s = d["schedule"]
    assert s["r_tot"] == 8 and sum(s["counts"]) == 8 and len(s["schedule"]) == 8
    best = capalloc_rs.best_schedule(net, 0.5, 8)
    assert s["eta_bar"] == best.eta_bar and s["counts"] == list(best.counts)
    assert s["eta_limit"] == net.cost(np.asarray(best.counts, dtype=float))
    mc = capalloc_rs.simulate(net, 0.5, best.schedule, 400, 0, runs=64)
    assert_mc_interval(s["monte_carlo"], mc)


def test_check() -> None:
    p = run("check", MODEL)
    assert p.returncode == 0 and "detectable: True" in p.stdout
    d = ok_json("check", str(EXAMPLES / "example1.toml"))
    assert d["regular"] is False  # the paper's Example 1 is not a regular triplet


def test_solve() -> None:
    net = Network.load(MODEL)
    a = optimal_allocation(net, 7.5)
    d = ok_json("solve", MODEL, "--r-tot", "7.5")
    assert d["eta"] == a.eta and d["r"] == a.r.tolist() and d["mu"] == a.mu
    p = run("solve", str(EXAMPLES / "three_subsystems.json"), "--r-tot", "7.5")
    assert p.returncode == 0 and "certificate" in p.stdout and f"{a.eta:.10g}" in p.stdout
    d = ok_json("solve", MODEL, "--r-tot", "9", "--integer")
    assert sum(d["counts"]) == 9
    d = ok_json("solve", MODEL, "--r-tot", "7.5", "--method", "projected-gradient")
    assert d["eta"] == pytest.approx(a.eta, rel=1e-9)
    assert d["hessian"] is None
    d = ok_json("solve", MODEL, "--r-tot", "7.5", "--hessian", "hvp")
    assert d["eta"] == pytest.approx(a.eta, rel=1e-12) and d["hessian"] == "hvp"
    assert d["hessian_vector_products"] == optimal_allocation(net, 7.5, hessian="hvp").hvp_count > 0
    p = run("solve", MODEL, "--r-tot", "7.5", "--hessian", "hvp")
    assert p.returncode == 0 and "Newton–CG" in p.stdout
    p = run("solve", MODEL, "--r-tot", "7.5", "--hessian", "cg")
    assert p.returncode == 2 and "invalid choice" in p.stderr


def test_trace(tmp_path: Path) -> None:
    net = Network.load(MODEL)
    f = filtration(net, 6.0)
    d = ok_json("trace", MODEL, "--sigma-max", "6")
    assert d["breakpoints"] == f.breakpoints.tolist()
    assert d["active_sets"] == [list(s) for s in f.active_sets]
    plot = tmp_path / "f.png"
    p = run("trace", MODEL, "--sigma-max", "6", "--plot", str(plot))
    assert p.returncode == 0, p.stderr
    assert "active set" in p.stdout
    if has("matplotlib"):
        assert plot.stat().st_size > 1000
    else:
        assert "plot skipped" in p.stdout


def test_schedule() -> None:
    best = capalloc_rs.best_schedule(Network.load(MODEL), 0.5, 7)
    d = ok_json("schedule", MODEL, "--tau", "0.5", "--r-tot", "7")
    assert d["eta_bar"] == best.eta_bar and d["counts"] == list(best.counts)
    p = run("schedule", MODEL, "--tau", "0.5", "--r-tot", "7")
    assert p.returncode == 0 and "fast-sampling" in p.stdout
    assert_user_error(run("schedule", MODEL, "--tau", "0.5", "--r-tot", "7.5"), "integer")


def test_simulate() -> None:
    seeded = ("simulate", MODEL, "--tau", "0.5", "--schedule", "0,1,2,1,2")
    seeded += ("--periods", "50", "--runs", "8", "--seed", "3")
    d = ok_json(*seeded)
    assert d["schedule"] == [0, 1, 2, 1, 2]
    sched = capalloc_rs.Schedule([0, 1, 2, 1, 2], 3)
    assert_mc_interval(d, capalloc_rs.simulate(Network.load(MODEL), 0.5, sched, 50, 3, runs=8))
    again = ok_json(*seeded)
    assert again == d  # seeded: reproducible
    d = ok_json("simulate", MODEL, "--tau", "0.5", "--r-tot", "6", "--periods", "50", "--runs", "8")
    assert d["source"] == "best" and len(d["schedule"]) == 6
    assert_user_error(
        run("simulate", MODEL, "--tau", "0.5", "--schedule", "0,x", "--periods", "5"),
        "--schedule",
    )


def _bad_models(tmp_path: Path) -> list[tuple[str, tuple[str, ...]]]:
    files = {
        "syntax.toml": ("r_min = [1.0\n", ("syntax.toml",)),
        "typo.toml": (
            "[[subsystems]]\nA = [[-1.0]]\nG = [[1.0]]\nc = [1.0]\nr_mn = 2\n",
            ("r_mn",),
        ),
        "singular.toml": ("[[subsystems]]\nA = [[0.0]]\nG = [[0.0]]\nc = [1.0]\n", ("axis", "G")),
        "shape.json": (
            json.dumps({"subsystems": [{"A": [[1.0, 0.0]], "G": [[1.0]], "c": [1.0]}]}),
            ("A",),
        ),
        "unobservable.toml": (
            "[[subsystems]]\nA = [[-1.0, 0.0], [0.0, 1.0]]\nG = [[1.0, 0.0], [0.0, 1.0]]\n"
            "c = [1.0, 0.0]\n",
            ("observable",),
        ),
        "model.txt": ("hello", ("txt",)),
    }
    out = []
    for name, (text, words) in files.items():
        (tmp_path / name).write_text(text)
        out.append((str(tmp_path / name), words))
    out.append((str(tmp_path / "missing.toml"), ("missing.toml",)))
    return out


def test_bad_model_files(tmp_path: Path) -> None:
    for path, words in _bad_models(tmp_path):
        for cmd in (
            ["solve", path, "--r-tot", "5"],
            ["trace", path, "--sigma-max", "2"],
            ["check", path],
        ):
            assert_user_error(run(*cmd), *words)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--json"], ("required", "COMMAND")),  # no arguments at all: the help (test_newcomer)
        (["frobnicate"], ("invalid choice",)),
        (["solve", MODEL], ("--r-tot",)),
        (["solve", MODEL, "--r-tot", "-3"], ("positive",)),
        (["solve", MODEL, "--r-tot", "abc"], ("number",)),
        (["solve", MODEL, "--r-tot", "2"], ("infeasible",)),
        (["solve", MODEL, "--r-tot", "5", "--method", "magic"], ("invalid choice",)),
        (["solve", MODEL, "--r-tot", "5.5", "--integer"], ("integer",)),
        (["trace", MODEL], ("--sigma-max",)),
        (["trace", MODEL, "--sigma-max", "inf"], ("positive",)),
        (["trace", MODEL, "--sigma-max", "nan"], ("positive",)),
        (["solve", MODEL, "--r-tot", "nan"], ("positive",)),
        (["schedule", MODEL, "--r-tot", "5"], ("--tau",)),
        (["simulate", MODEL, "--tau", "0.5"], ("--r-tot", "--schedule")),
        (["sweep", "spec.toml"], ("--out",)),
        (["demo", "--tau", "0"], ("positive",)),
    ],
)
def test_bad_arguments(args: list[str], words: tuple[str, ...]) -> None:
    assert_user_error(run(*args), *words)


def test_help_and_version() -> None:
    p = run("--help")
    assert p.returncode == 0
    for cmd in ("demo", "solve", "trace", "schedule", "simulate", "sweep"):
        assert cmd in p.stdout
    p = run("--version")
    assert p.returncode == 0 and capalloc_rs.__version__ in p.stdout


def test_console_script_entry_point() -> None:
    """``capalloc`` is declared as a console script running :func:`capalloc_rs.cli.main`."""
    tomllib = pytest.importorskip("tomllib")
    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    scripts = tomllib.loads(pyproject.read_text())["project"]["scripts"]
    assert scripts["capalloc"] == "capalloc_rs.cli:main"
    from capalloc_rs.cli import main

    assert main(["solve", MODEL, "--r-tot", "0.5"]) == 2
    assert np.isfinite(0.0)


_BLOCKER = """
import sys
BLOCKED = ("pyarrow", "tqdm", "dask", "distributed", "matplotlib", "pandas", "scipy")
class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"No module named {name!r} (blocked by the test)")
        return None
sys.meta_path.insert(0, Blocker())
from capalloc_rs.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_demo_needs_only_numpy(tmp_path: Path) -> None:
    """``pip install . && capalloc demo`` on a fresh machine: no pyarrow, tqdm, dask, matplotlib
    or scipy."""
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    p = subprocess.run(
        [sys.executable, "-c", _BLOCKER, "demo"],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    assert "plot" not in p.stdout  # no plot unless asked, so matplotlib is not needed
    assert "certificate" in p.stdout and "active set" in p.stdout
    assert not list(tmp_path.iterdir())
    # sweeps say what to install, in one line
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps({"capacities": [4], "networks": {"random": {"count": 1, "N": 2}}}))
    p = subprocess.run(
        [sys.executable, "-c", _BLOCKER, "sweep", str(spec), "--out", str(tmp_path / "o")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert_user_error(p, "pyarrow", "pip install 'capalloc-rs[sweep]'")
