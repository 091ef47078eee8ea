"""Every code example of the README and of ``docs/`` runs.

* The ```python blocks of each page run in order as one script, in a fresh interpreter, in a
  temporary directory holding a copy of ``examples/`` (the pages say "run from the repository
  root"), so nothing is written into the clone.
* The README's tutorial is saved as a file and run as ``python tutorial.py`` (it must run as a
  script, worker processes of ``sweep`` included) and stays within 20 lines.
* Every ``capalloc …`` line of a ```bash or ```console block is parsed by the real argument
  parser; the cheap ones are executed too (in the temporary directory), and a ```console block's
  displayed output must appear in the command's output.

A block is skipped only when the line before its fence is ``<!-- skip-exec: REASON -->``.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from capalloc_rs.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted(
    [ROOT / "README.md"]
    + [p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.relative_to(ROOT).parts]
)
FENCE = re.compile(r"^(`{3,})\s*([\w-]*)\s*$")
SKIP = re.compile(r"^<!--\s*skip-exec:\s*(\S.*?)\s*-->$")
#: Subcommands whose documented invocations are only parsed, never run here (long or writing).
PARSE_ONLY = {"sweep"}
TIMEOUT = 120


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    skip: str | None  # the reason, when marked <!-- skip-exec: … -->


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a Markdown page (fences of 3+ backticks, nested longer ones)."""
    lines = page.read_text(encoding="utf-8").splitlines()
    out: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, lang, start = m.group(1), m.group(2), i
        j = i + 1
        while j < len(lines) and lines[j].strip() != fence:
            j += 1
        prev = next((ln.strip() for ln in reversed(lines[:start]) if ln.strip()), "")
        sm = SKIP.match(prev)
        text = "\n".join(lines[start + 1 : j]) + "\n"
        out.append(Block(page, start + 1, lang, text, sm.group(1) if sm else None))
        i = j + 1
    return out


def _name(page: Path) -> str:
    return str(page.relative_to(ROOT))


def _workdir(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    return tmp_path


def _env() -> dict[str, str]:
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONDONTWRITEBYTECODE="1")
    env.pop("CAPALLOC_TRACEBACK", None)
    return env


def _run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        argv, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=TIMEOUT, check=False
    )


PY_PAGES = [p for p in PAGES if any(b.lang == "python" and not b.skip for b in blocks(p))]


def test_pages_found() -> None:
    names = {_name(p) for p in PAGES}
    assert "README.md" in names and "docs/index.md" in names and "docs/api.md" in names
    assert len(PY_PAGES) >= 5, [_name(p) for p in PY_PAGES]


def test_skip_markers_have_reasons() -> None:
    for page in PAGES:
        for line in page.read_text(encoding="utf-8").splitlines():
            if "skip-exec" in line:
                assert SKIP.match(line.strip()), f"{_name(page)}: malformed marker {line!r}"


@pytest.mark.parametrize("page", PY_PAGES, ids=_name)
def test_python_blocks_run(page: Path, tmp_path: Path) -> None:
    """All python blocks of a page, in order, as one script in a fresh interpreter."""
    parts = [
        f"# --- {_name(page)}:{b.line}\n{b.text}"
        for b in blocks(page)
        if b.lang == "python" and not b.skip
    ]
    cwd = _workdir(tmp_path)
    script = cwd / "page_examples.py"
    script.write_text("\n".join(parts), encoding="utf-8")
    proc = _run([sys.executable, str(script)], cwd)
    assert proc.returncode == 0, f"{_name(page)} failed:\n{proc.stdout}\n{proc.stderr}"


def _tutorial() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Tutorial", 1)[1].split("\n## ", 1)[0]
    first = [b for b in blocks(ROOT / "README.md") if b.lang == "python" and b.text in section]
    assert first, "the README has no python block under '## Tutorial'"
    return first[0].text


def test_readme_tutorial_runs_as_a_script(tmp_path: Path) -> None:
    code = _tutorial()
    assert len(code.strip().splitlines()) <= 20
    assert 'if __name__ == "__main__":' in code  # it calls sweep
    cwd = _workdir(tmp_path)
    (cwd / "tutorial.py").write_text(code, encoding="utf-8")
    proc = _run([sys.executable, "tutorial.py"], cwd)
    assert proc.returncode == 0, proc.stderr
    assert "Warning" not in proc.stderr, proc.stderr  # guarded: worker processes, no fallback
    # every print of the script appears once: the workers did not re-run the script's body
    out = proc.stdout.splitlines()
    assert len(out) == code.count("print("), proc.stdout
    assert sorted(p.name for p in cwd.iterdir()) == ["examples", "tutorial.py"]


@dataclass(frozen=True)
class Command:
    block: Block
    args: list[str]  # after "capalloc"
    expected: list[str]  # displayed output (console blocks)


def _commands(block: Block) -> list[Command]:
    """The ``capalloc …`` lines of a bash/console block (with the console output after each)."""
    out: list[Command] = []
    lines = block.text.replace("\\\n", " ").splitlines()  # join continued lines
    for k, raw in enumerate(lines):
        line = raw.strip()
        if block.lang == "console":
            if not line.startswith("$ "):
                continue
            line = line[2:]
        if line.split()[:1] != ["capalloc"]:
            continue
        words = shlex.split(line, comments=True)
        expected: list[str] = []
        if block.lang == "console":
            for follow in lines[k + 1 :]:
                if follow.startswith("$ "):
                    break
                if follow.strip():
                    expected.append(" ".join(follow.split()))
        out.append(Command(block, words[1:], expected))
    return out


COMMANDS = [
    c
    for p in PAGES
    for b in blocks(p)
    if b.lang in ("bash", "console", "sh", "shell") and not b.skip
    for c in _commands(b)
]


def _cmd_id(c: Command) -> str:
    return f"{_name(c.block.page)}:{c.block.line}:{' '.join(c.args)[:40]}"


def test_commands_found() -> None:
    used = {c.args[0] for c in COMMANDS if c.args}
    assert {"demo", "solve", "trace", "schedule", "simulate", "sweep", "check"} <= used, used


@pytest.mark.parametrize("cmd", COMMANDS, ids=_cmd_id)
def test_cli_examples(cmd: Command, tmp_path: Path) -> None:
    if cmd.args:
        build_parser().parse_args(cmd.args)  # exits (SystemExit) on an unknown option
    if cmd.args and cmd.args[0] in PARSE_ONLY:
        return
    cwd = _workdir(tmp_path)
    code = "import sys; from capalloc_rs.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = _run([sys.executable, "-c", code, *cmd.args], cwd)
    shown = proc.stdout + proc.stderr
    if cmd.expected:
        got = [" ".join(line.split()) for line in shown.splitlines()]
        for line in cmd.expected:
            assert line in got, f"{_cmd_id(cmd)}: {line!r} not in output:\n{shown}"
    else:
        assert proc.returncode == 0, f"{_cmd_id(cmd)}:\n{shown}"


def test_api_page_documents_every_public_name() -> None:
    """docs/api.md names each public class and function by its top-level name (errors through
    the documented ``capalloc_rs.errors`` module)."""
    import types

    import capalloc_rs
    from capalloc_rs import errors

    api = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    for name in capalloc_rs.__all__:
        obj = getattr(capalloc_rs, name)
        if isinstance(obj, types.ModuleType) or name == "__version__":
            continue
        if name in errors.__all__:
            assert "automodule:: capalloc_rs.errors" in api
        else:
            assert re.search(rf"auto\w+:: capalloc_rs\.{name}\n", api), name


def test_readme_starts_with_the_two_commands() -> None:
    first = blocks(ROOT / "README.md")[0]
    assert first.lang == "bash"
    assert "pip install . && capalloc demo" in first.text
    assert 'pip install ".[test]" && cargo test && python3 -m pytest' in first.text


TOML_MODELS = [
    b
    for p in PAGES
    for b in blocks(p)
    if b.lang == "toml" and ("[[subsystems]]" in b.text or "[[sensors]]" in b.text)
]


@pytest.mark.parametrize("block", TOML_MODELS, ids=lambda b: f"{_name(b.page)}:{b.line}")
def test_toml_model_blocks_load(block: Block, tmp_path: Path) -> None:
    """A model file shown in the docs is a valid model file."""
    import capalloc_rs as ca

    path = tmp_path / "model.toml"
    path.write_text(block.text, encoding="utf-8")
    net = ca.Network.load(path)
    assert net.num_sensors >= 1
