"""Fails when a source module is over the size limit without saying why.

Every ``.py`` and ``.rs`` file under ``python/``, ``rust/``, ``tests/``, ``benches/`` and
``scripts/`` must have at most ``LIMIT`` lines, or state the reason in its first ``HEADER`` lines
with a line containing ``Why this module is long:``. Run ``python3 scripts/check_module_size.py``
(exit status 1 and one line per offending file when the rule is broken); the test suite runs it.
"""

from __future__ import annotations

import sys
from pathlib import Path

LIMIT = 500
HEADER = 40
MARKER = "Why this module is long:"
ROOTS = ("python", "rust", "tests", "benches", "scripts")


def violations(repo: Path) -> list[str]:
    """One message per file over ``LIMIT`` lines whose header does not give a reason."""
    out = []
    for root in ROOTS:
        for path in sorted((repo / root).rglob("*")):
            if path.suffix not in (".py", ".rs") or not path.is_file():
                continue
            lines = path.read_text(encoding="utf-8").splitlines()
            if len(lines) > LIMIT and not any(MARKER in line for line in lines[:HEADER]):
                rel = path.relative_to(repo)
                out.append(f"{rel}: {len(lines)} lines > {LIMIT} and no '{MARKER}' line at its top")
    return out


def main() -> int:
    found = violations(Path(__file__).resolve().parent.parent)
    for message in found:
        print(message)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
