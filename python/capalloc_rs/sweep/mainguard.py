"""Is a sweep started from a script's top level without ``if __name__ == "__main__":``?

Worker processes started by ``spawn`` or ``forkserver`` (the sweep's default: never ``fork`` a
process that may hold Rust threads) re-run the main script to rebuild its module; a script whose
sweep call is not guarded by ``if __name__ == "__main__":`` would start the sweep again in every
worker, which multiprocessing refuses with a bootstrapping ``RuntimeError``. :func:`unguarded_call`
finds that case beforehand, statically: the statement of the main script that is running now is
located in the script's syntax tree, and it is guarded if it sits in a top-level
``if __name__ == "__main__":`` block.
"""

from __future__ import annotations

import ast
import sys

__all__ = ["unguarded_call"]


def _is_main_guard(stmt: ast.stmt) -> bool:
    """``if __name__ == "__main__":`` (either operand order)."""
    if not isinstance(stmt, ast.If) or not isinstance(stmt.test, ast.Compare):
        return False
    t = stmt.test
    if len(t.ops) != 1 or not isinstance(t.ops[0], ast.Eq):
        return False
    sides = [t.left, t.comparators[0]]
    names = [s.id for s in sides if isinstance(s, ast.Name)]
    consts = [s.value for s in sides if isinstance(s, ast.Constant)]
    return names == ["__name__"] and consts == ["__main__"]


def unguarded_call() -> str | None:
    """``"path:line"`` of the main script's top-level statement that is running now if it is
    not inside ``if __name__ == "__main__":``; ``None`` if it is guarded, or if worker processes
    would not re-run any script (interactive sessions, ``python -c``, notebooks, or a call made
    after the script's top level has finished)."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or not isinstance(path, str):
        return None
    spec_name = getattr(getattr(main, "__spec__", None), "name", None) or ""
    if spec_name == "__main__" or spec_name.endswith(".__main__"):
        return None  # python -m pkg: workers do not re-run a package's __main__
    frame = sys._getframe(1)
    while frame is not None and not (
        frame.f_code.co_name == "<module>" and frame.f_globals is vars(main)
    ):
        frame = frame.f_back  # type: ignore[assignment]
    if frame is None:
        return None
    line = frame.f_lineno
    try:
        with open(path, "rb") as fh:
            tree = ast.parse(fh.read(), filename=path)
    except (OSError, SyntaxError, ValueError):
        return None  # cannot tell: keep the process pool
    for stmt in tree.body:
        end = stmt.end_lineno if stmt.end_lineno is not None else stmt.lineno
        if stmt.lineno <= line <= end:
            return None if _is_main_guard(stmt) else f"{path}:{line}"
    return None
