"""A generated corpus of malformed model files through ``Network.load`` and every CLI subcommand
(issue 12 points 3–6): truncated, empty, binary garbage, forged ``.npy`` headers, huge declared
sizes, zip bombs, deep nesting, big integers, non-array members, pickles.

The contract: ``Network.load`` raises :class:`~capalloc_rs.errors.ModelFormatError` naming the
file (or another package error for a well-formed but invalid model); the CLI prints one line
``capalloc: error: …`` and exits with status 2 (``--json``: also a JSON error object on stdout),
never a traceback; a sweep over the corpus writes error rows and finishes.
"""

from __future__ import annotations

import io
import json
import os
import random
import struct
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import Network, limits
from capalloc_rs.cli import demo_network, main
from capalloc_rs.errors import CapallocError, InputError, ModelFormatError

PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)


# -- building malformed files --------------------------------------------------------------------


def npy(header: str, data: bytes, version: tuple[int, int] = (1, 0)) -> bytes:
    """``.npy`` bytes with a literal header dict (forged at will)."""
    h = header.encode("latin1")
    pad = 64 - (10 + len(h) + 1) % 64
    h = h + b" " * pad + b"\n"
    if version == (1, 0):
        return b"\x93NUMPY" + bytes(version) + struct.pack("<H", len(h)) + h + data
    return b"\x93NUMPY" + bytes(version) + struct.pack("<I", len(h)) + h + data


def zip_of(members: dict[str, bytes], compress: bool = True) -> bytes:
    buf = io.BytesIO()
    mode = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(buf, "w", mode) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def good_npz_members(tmp: Path) -> dict[str, bytes]:
    path = tmp / "good-model.npz"
    demo_network().save(str(path))
    with zipfile.ZipFile(path) as z:
        out = {n: z.read(n) for n in z.namelist()}
    path.unlink()
    return out


def corpus(tmp: Path) -> list[Path]:
    """The malformed files, written into ``tmp``."""
    rng = random.Random(12)
    net = demo_network()
    files: dict[str, bytes] = {}
    good_toml = capalloc_rs.model_io.dumps_toml(capalloc_rs.model_io.to_dict(net)).encode()
    good_json = capalloc_rs.model_io.dumps_json(capalloc_rs.model_io.to_dict(net)).encode()
    members = good_npz_members(tmp)
    good_npz = zip_of(members)
    for ext, good in (("toml", good_toml), ("json", good_json), ("npz", good_npz)):
        files[f"empty.{ext}"] = b""
        files[f"garbage.{ext}"] = bytes(rng.randrange(256) for _ in range(3000))
        for frac in (0.1, 0.5, 0.9):
            files[f"truncated{int(frac * 100)}.{ext}"] = good[: int(len(good) * frac)]
    files["minus1.npz"] = good_npz[:-1]
    # text formats
    files["not_utf8.toml"] = b"r_min = 1.0\n# \xff\xfe\n"
    files["deep.json"] = b"[" * 100_000 + b"]" * 100_000
    files["many_arrays.json"] = b"[" + b"[]," * 600_000 + b"[]]"
    files["deep_object.json"] = b'{"a":' * 50_000 + b"1" + b"}" * 50_000
    files["deep.toml"] = b"A = " + b"[" * 100_000 + b"]" * 100_000 + b"\n"
    files["deep_inline.toml"] = b"x = " + b"{a = " * 5_000 + b"1" + b"}" * 5_000 + b"\n"
    big = str(10**400).encode()
    files["bigint_rmin.json"] = b'{"r_min": ' + big + b', "A": [[1]], "G": [[1]], "sensors": []}'
    files["bigint_matrix.json"] = good_json.replace(b"-0.4", big, 1)
    files["bigint_matrix.toml"] = good_toml.replace(b"-0.4", big, 1)
    files["bigint_5000_digits.toml"] = b"r_min = " + b"9" * 5000 + b"\n"
    files["inf_literal.json"] = good_json.replace(b"-0.4", b"1e999", 1)
    files["nan_literal.json"] = good_json.replace(b"-0.4", b"NaN", 1)
    files["long_float.json"] = good_json.replace(b"-0.4", b"0." + b"1" * 5000, 1)
    files["huge_matrix.json"] = json.dumps(
        {"A": [[0.0]] * (limits.MAX_MODEL_STATES + 1), "G": [[1.0]], "sensors": [{"c": [1.0]}]}
    ).encode()
    files["wrong_types.json"] = b'{"A": "x", "G": [[1]], "sensors": [{"c": [1]}]}'
    files["list_top.json"] = b"[1, 2, 3]"
    files["bool_matrix.json"] = b'{"A": [[true]], "G": [[1]], "sensors": [{"c": [1]}]}'
    files["unknown_keys.toml"] = b"bogus = 1\n" + good_toml
    # npz archives
    files["not_a_zip.npz"] = b"PK\x03\x04" + b"\x00" * 100
    files["zip_text_member.npz"] = zip_of({**members, "notes.txt": b"hello"})
    files["zip_not_npy.npz"] = zip_of({**members, "A_0.npy": b"this is not an array"})
    files["forged_shape.npz"] = zip_of(
        {
            **members,
            "A_0.npy": npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000,), }", b"\0" * 16
            ),
        }
    )
    files["forged_2d.npz"] = zip_of(
        {
            **members,
            "A_0.npy": npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 2), }", b"\0" * 8
            ),
        }
    )
    files["forged_bad_dict.npz"] = zip_of(
        {**members, "A_0.npy": npy("{'descr': '<f8', 'shape': ", b"")}
    )
    files["forged_v2_header.npz"] = zip_of(
        {
            **members,
            "A_0.npy": npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (9999999, 9999999), }",
                b"",
                (2, 0),
            ),
        }
    )
    files["npy_v9.npz"] = zip_of({**members, "A_0.npy": npy("{}", b"", (9, 0))})
    # a zip bomb: a 6000-state A_0 of zeros, a few hundred kB compressed
    files["bomb_6000_states.npz"] = zip_of(
        {
            **members,
            "A_0.npy": npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (6000, 6000), }",
                bytes(6000 * 6000 * 8),
            ),
        }
    )
    files["pickle.npz"] = _pickled_npz()
    files["complex.npz"] = zip_of({**members, "A_0.npy": _npy_of(np.ones((2, 2), complex))})
    files["bool.npz"] = zip_of({**members, "A_0.npy": _npy_of(np.ones((2, 2), bool))})
    files["strings.npz"] = zip_of({**members, "A_0.npy": _npy_of(np.array([["a", "b"]]))})
    files["structured.npz"] = zip_of(
        {**members, "A_0.npy": _npy_of(np.zeros(2, dtype=[("x", "<f8"), ("y", "<i4")]))}
    )
    files["three_d.npz"] = zip_of({**members, "A_0.npy": _npy_of(np.zeros((2, 2, 2)))})
    files["nan.npz"] = zip_of({**members, "A_0.npy": _npy_of(np.full((2, 2), np.nan))})
    files["empty_zip.npz"] = zip_of({})
    files["many_members.npz"] = zip_of(
        {f"x{i}.npy": b"" for i in range(limits.MAX_NPZ_MEMBERS + 1)}, compress=False
    )
    files["unknown_arrays.npz"] = zip_of(
        {**members, **{f"junk_{i}.npy": _npy_of(np.zeros(1)) for i in range(50)}}
    )
    out = []
    for name, data in files.items():
        p = tmp / name
        p.write_bytes(data)
        out.append(p)
    return out


def _npy_of(arr: np.ndarray[Any, Any]) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=True)
    return buf.getvalue()


def _pickled_npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, A=np.array([{"evil": 1}], dtype=object), G=np.eye(1), sensor_0=np.ones((1, 1)))
    return buf.getvalue()


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return corpus(tmp_path_factory.mktemp("corpus"))


# -- Network.load --------------------------------------------------------------------


def test_load_raises_only_package_errors_naming_the_file(bad_files: list[Path]) -> None:
    assert len(bad_files) > 50
    for p in bad_files:
        with pytest.raises(CapallocError) as info:
            Network.load(p)
        assert isinstance(info.value, InputError), (p.name, repr(info.value))
        assert str(p) in str(info.value), (p.name, str(info.value))
        assert len(str(info.value)) < 2000, p.name  # one readable line, not a dump


def test_damaged_files_are_model_format_errors(bad_files: list[Path]) -> None:
    for p in bad_files:
        if p.stem in ("nan", "bool_matrix"):
            continue  # well-formed numbers, invalid network: NonFiniteError etc. are fine
        with pytest.raises(ModelFormatError):
            Network.load(p)


def test_npz_limits_are_checked_before_reading(
    bad_files: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The 6000-state zip bomb and the forged headers are refused from the zip directory and the
    ``.npy`` headers: fewer than 1 MB of member data is ever decompressed (the bomb expands to
    288 MB)."""
    read = {"bytes": 0}
    original = zipfile.ZipExtFile.read

    def counting(self: zipfile.ZipExtFile, n: int = -1) -> bytes:
        data = original(self, n)
        read["bytes"] += len(data)
        return data

    monkeypatch.setattr(zipfile.ZipExtFile, "read", counting)
    by_name = {p.name: p for p in bad_files}
    for name, words in [
        ("bomb_6000_states.npz", "MAX_MODEL"),
        ("forged_shape.npz", "MAX_MODEL_STATES"),
        ("forged_v2_header.npz", "MAX_MODEL_STATES"),
        ("forged_2d.npz", "holds"),
        ("many_members.npz", "MAX_NPZ_MEMBERS"),
        ("pickle.npz", "pickle"),
    ]:
        read["bytes"] = 0
        with pytest.raises(ModelFormatError, match=words):
            Network.load(by_name[name])
        assert read["bytes"] < 2**20, (name, read["bytes"])


def test_limits_are_overridable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "m.npz"
    demo_network().save(str(path))
    assert Network.load(path) == demo_network()
    monkeypatch.setattr(limits, "MAX_MODEL_STATES", 2)
    with pytest.raises(ModelFormatError, match="MAX_MODEL_STATES = 2"):
        Network.load(path)
    monkeypatch.setattr(limits, "MAX_MODEL_STATES", 2000)
    monkeypatch.setattr(limits, "MAX_MODEL_ELEMENTS", 10)
    with pytest.raises(ModelFormatError, match="MAX_MODEL_ELEMENTS"):
        Network.load(path)
    js = tmp_path / "m.json"
    demo_network().save(str(js))
    monkeypatch.setattr(limits, "MAX_NESTING", 3)
    with pytest.raises(ModelFormatError, match="MAX_NESTING = 3"):
        Network.load(js)
    monkeypatch.setattr(limits, "MAX_ARRAYS", 5)
    with pytest.raises(ModelFormatError, match="MAX_ARRAYS = 5"):
        Network.load(js)


def test_good_files_still_load(tmp_path: Path) -> None:
    net = demo_network()
    for ext in ("toml", "json", "npz"):
        p = tmp_path / f"m.{ext}"
        net.save(str(p))
        assert Network.load(p) == net


# -- the CLI, in process --------------------------------------------------------------------

_SUBCOMMANDS = [
    ["check", "{}"],
    ["solve", "{}", "--r-tot", "5"],
    ["solve", "{}", "--r-tot", "5", "--integer"],
    ["trace", "{}", "--sigma-max", "2"],
    ["schedule", "{}", "--tau", "0.5", "--r-tot", "4"],
    ["simulate", "{}", "--tau", "0.5", "--r-tot", "4", "--runs", "2", "--periods", "2"],
]


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("capalloc: error: "), err
    assert "Traceback" not in err
    return lines[0]


def test_every_subcommand_on_every_bad_file(
    bad_files: list[Path], capsys: pytest.CaptureFixture[str]
) -> None:
    for p in bad_files:
        for cmd in _SUBCOMMANDS:
            args = [a.format(p) for a in cmd]
            assert main(args) == 2, args
            out, err = capsys.readouterr()
            assert str(p) in _one_error_line(err), (args, err)
            assert out == ""
        # --json: the same line on stderr and a JSON error object on stdout
        assert main(["check", str(p), "--json"]) == 2
        out, err = capsys.readouterr()
        _one_error_line(err)
        e = json.loads(out)["error"]
        assert str(p) in e["message"] and e["type"]


def test_sweep_survives_every_bad_file(
    bad_files: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sweep over the corpus (plus one good file) writes error rows for the bad files' tasks and
    the good file's results: it does not die on the first bad file."""
    pytest.importorskip("pyarrow")
    from capalloc_rs.sweep import read_results

    good = tmp_path / "good.toml"
    demo_network().save(str(good))
    spec = tmp_path / "spec.json"
    files = [str(p) for p in bad_files] + [str(good)]
    spec.write_text(json.dumps({"capacities": [5.0], "networks": {"files": files}}))
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["tasks"] == len(files) and summary["failed"] == len(bad_files)
    rows = read_results(out).to_pylist()
    assert [r["error"] is None for r in rows] == [False] * len(bad_files) + [True]


# -- the CLI, real processes --------------------------------------------------------------------


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("CAPALLOC_TRACEBACK", None)
    return env


def test_real_processes_on_bad_files(bad_files: list[Path]) -> None:
    by_name = {p.name: p for p in bad_files}
    for name in ("truncated50.npz", "deep.json", "bigint_matrix.toml", "zip_text_member.npz"):
        p = subprocess.run(
            [sys.executable, "-m", "capalloc_rs.cli", "solve", str(by_name[name]), "--r-tot", "5"],
            env=_env(),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert p.returncode == 2, (name, p.stderr)
        assert name in _one_error_line(p.stderr)
