"""Checks the minimum supported Rust version (MSRV) without installing that toolchain.

The crate declares ``rust-version`` in ``Cargo.toml``. Two things keep that claim true:

* clippy's ``incompatible_msrv`` lint (on by default, an error under ``-D warnings`` in CI) rejects
  uses of standard-library items stabilised after the declared version;
* this script rejects a dependency that needs a newer compiler: every package reachable from the
  crate through normal (non-dev) dependencies, with all features (the Python bindings included),
  must declare a ``rust-version`` no newer than ours (packages that declare none are reported as
  unknown, not as failures).

Run ``python3 scripts/check_msrv.py`` from the repository; exit status 1 lists the offenders.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def version(v: str) -> tuple[int, ...]:
    """``"1.84.0"`` → ``(1, 84, 0)`` (missing parts are 0)."""
    parts = [int(p) for p in v.split(".")]
    return tuple(parts + [0] * (3 - len(parts)))


def main() -> int:
    repo = Path(__file__).resolve().parent.parent
    out = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--all-features", "--offline"],
        cwd=repo,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    meta = json.loads(out)
    packages = {p["id"]: p for p in meta["packages"]}
    root = meta["resolve"]["root"]
    ours = packages[root].get("rust_version")
    if not ours:
        print("Cargo.toml declares no rust-version")
        return 1
    nodes = {n["id"]: n for n in meta["resolve"]["nodes"]}
    seen, stack = set(), [root]
    while stack:
        node = nodes[stack.pop()]
        for dep in node["deps"]:
            normal = any(k["kind"] is None for k in dep["dep_kinds"])
            if normal and dep["pkg"] not in seen:
                seen.add(dep["pkg"])
                stack.append(dep["pkg"])
    bad, unknown = [], []
    for pid in sorted(seen, key=lambda p: packages[p]["name"]):
        p = packages[pid]
        need = p.get("rust_version")
        if need is None:
            unknown.append(p["name"])
        elif version(need) > version(ours):
            bad.append(f"{p['name']} {p['version']} needs Rust {need} > our rust-version {ours}")
    print(f"rust-version {ours}: {len(seen)} dependencies checked, {len(unknown)} declare none")
    for line in bad:
        print(line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
