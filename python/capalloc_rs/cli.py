"""The ``capalloc`` command line.

``capalloc demo`` solves a built-in example and prints the solution with its diagnostics.
User mistakes end with one clear line on stderr and a non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import numpy as np

from .errors import CapallocError
from .linalg import care

#: Built-in example: a lightly damped two-mass chain (n = 4) with one actuator.
DEMO_A = np.array(
    [
        [0.0, 1.0, 0.0, 0.0],
        [-2.0, -0.1, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [1.0, 0.0, -1.0, -0.1],
    ]
)
DEMO_B = np.array([[0.0], [1.0], [0.0], [0.0]])
DEMO_Q = np.eye(4)
DEMO_R = np.array([[1.0]])


def _demo(args: argparse.Namespace) -> int:
    res = care(DEMO_A, DEMO_B, DEMO_Q, DEMO_R)
    if args.json:
        out = {
            "equation": "A'X + XA - X B R^-1 B' X + Q = 0",
            "x": res.x.tolist(),
            "residual": res.residual,
            "rcond": res.rcond,
            "closed_loop_abscissa": res.closed_loop_abscissa,
            "newton_steps": res.newton_steps,
            "scaling": res.scaling,
        }
        print(json.dumps(out, indent=2))
        return 0
    np.set_printoptions(precision=6, suppress=True, linewidth=100)
    print("capalloc demo: CARE  A'X + XA - X B R^-1 B' X + Q = 0  (two-mass chain, n = 4)")
    print("X =")
    print(res.x)
    print(f"relative residual      {res.residual:.3e}")
    print(f"rcond(U11)             {res.rcond:.3e}")
    print(f"closed-loop abscissa   {res.closed_loop_abscissa:.6f}")
    print(f"scaling factor         {res.scaling:.6g}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="capalloc", description="Optimal capacity allocation for sampled networked systems."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="solve a built-in example and print it with diagnostics")
    demo.add_argument("--json", action="store_true", help="machine-readable output")
    demo.set_defaults(func=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.func(args)
    except CapallocError as exc:
        print(f"capalloc: error: {exc}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
