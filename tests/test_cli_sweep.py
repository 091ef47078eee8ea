"""``capalloc sweep``: a spec run into a Parquet dataset, its summary, bad specs and schedulers,
Ctrl-C then --resume (through a real subprocess)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cli_helpers import MODEL, PKG_ROOT, assert_user_error, has, ok_json, run

from capalloc_rs import Network
from capalloc_rs.allocation import optimal_allocation


@pytest.mark.skipif(not has("pyarrow"), reason="sweeps need pyarrow")
def test_sweep(tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    spec = tmp_path / "spec.toml"
    spec.write_text(
        f'compute = "allocation"\ncapacities = [4.0, 6.0]\nchunk_size = 3\n'
        f'[networks]\nfiles = [{json.dumps(MODEL)}, "missing.toml"]\n'
        f"[networks.random]\ncount = 4\nN = 3\nn = 2\nseed = 1\n"
    )
    out = tmp_path / "out"
    d = ok_json("sweep", str(spec), "--out", str(out), "--workers", "2")
    assert (d["tasks"], d["computed"], d["skipped"]) == (12, 12, 0)
    assert d["failed"] == 2  # the missing file, at both capacities
    t = pq.read_table(out)
    assert t.num_rows == 12
    a = optimal_allocation(Network.load(MODEL), 6.0)
    rows = {(r["network_index"], r["r_tot"]): r for r in t.to_pylist()}
    assert rows[(0, 6.0)]["eta"] == a.eta
    assert "missing.toml" in rows[(1, 4.0)]["error"]
    # results exist: refuse to mix silently, resume skips everything, overwrite recomputes
    assert_user_error(run("sweep", str(spec), "--out", str(out)), "--resume")
    d = ok_json("sweep", str(spec), "--out", str(out), "--resume", "--no-progress")
    assert (d["computed"], d["skipped"]) == (0, 12)
    p = run("sweep", str(spec), "--out", str(out), "--overwrite", "--workers", "1")
    assert p.returncode == 0 and "computed 12" in p.stdout and "first error" in p.stdout
    # the example spec parses and names its networks
    p = run(
        "sweep",
        str(spec),
        "--out",
        str(out),
        "--resume",
        "--scheduler",
        "tcp://x",
        "--workers",
        "2",
    )
    assert_user_error(p, "not allowed with")


@pytest.mark.skipif(not has("pyarrow"), reason="sweeps need pyarrow")
def test_sweep_bad_spec_and_scheduler(tmp_path: Path) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text('capacities = [4.0]\n[networks]\nfile = ["a.toml"]\n')
    assert_user_error(run("sweep", str(spec), "--out", str(tmp_path / "o")), "unknown key", "file")
    spec.write_text("capacities = [4.0\n")
    assert_user_error(run("sweep", str(spec), "--out", str(tmp_path / "o")), "invalid TOML")
    assert_user_error(
        run("sweep", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")), "nope.toml"
    )
    spec.write_text("capacities = [4.0]\n[networks.random]\ncount = 1\nN = 2\n")
    p = run(
        "sweep",
        str(spec),
        "--out",
        str(tmp_path / "o"),
        "--scheduler",
        "tcp://127.0.0.1:1",
        "--connect-timeout",
        "1",
    )
    assert_user_error(p, "scheduler")


@pytest.mark.skipif(not has("pyarrow"), reason="sweeps need pyarrow")
def test_sweep_ctrl_c_then_resume(tmp_path: Path) -> None:
    import signal
    import time

    import pyarrow.parquet as pq

    spec = tmp_path / "spec.toml"
    spec.write_text(
        "capacities = [4.0, 5.0]\nchunk_size = 4\n"
        "[networks.random]\ncount = 1500\nN = 3\nn = 2\nseed = 2\n"
    )
    out = tmp_path / "out"
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, "-m", "capalloc_rs.cli", "sweep", str(spec), "--out", str(out)]
    proc = subprocess.Popen(
        [*cmd, "--workers", "1"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        # The ready marker: the first part-file (work has started and a chunk is saved). The
        # deadline only guards against a hung child; nothing waits for time.
        deadline = time.monotonic() + 600
        while proc.poll() is None and not any(out.glob("part-*.parquet")):
            assert time.monotonic() < deadline, "no part-file appeared"
            time.sleep(0.02)
        interrupted = proc.poll() is None
        if interrupted:
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole foreground group
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
    assert "Traceback" not in err, err
    done = pq.read_table(out).num_rows
    if interrupted and proc.returncode == 130:
        assert err.strip().count("\n") == 0 and err.startswith("capalloc: interrupted"), err
        assert 0 < done < 3000 and "--resume" in err or done == 3000, err
    else:  # the sweep won the race (finished before the signal): resuming finds everything done
        assert proc.returncode == 0, err
        assert done == 3000
    d = ok_json("sweep", str(spec), "--out", str(out), "--resume", "--workers", "2")
    assert d["skipped"] == done and d["computed"] == 3000 - done
    ids = pq.read_table(out).column("task_id").to_pylist()
    assert len(ids) == len(set(ids)) == 3000
