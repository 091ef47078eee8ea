"""Decisions with proofs, side by side with the alternatives: exact integer counts by
branch-and-bound against brute force and the greedy (``certified_integer``), robust against nominal
allocations on held-out perturbed models (``certified_robust``), and best schedules with their
certified gap (``certified_schedule``). Each part is its own script in ``benches/`` (run it alone
for its options); this one runs them all with their defaults.

Usage: ``python benches/compare_certified.py [--only integer robust schedule]``; run with
``OPENBLAS_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

PARTS = {
    "integer": "certified_integer",
    "robust": "certified_robust",
    "schedule": "certified_schedule",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", choices=sorted(PARTS), default=list(PARTS))
    args = ap.parse_args()
    for part in args.only:
        module = importlib.import_module(PARTS[part])
        print(f"\n## {part}\n", flush=True)
        sys.argv = [f"{PARTS[part]}.py"]  # each part with its own default options
        module.main()


if __name__ == "__main__":
    main()
