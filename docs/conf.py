"""Sphinx configuration of the capalloc-rs documentation.

Build (warnings are errors, as in CI)::

    python3 -m sphinx -W --keep-going -b html docs docs/_build/html

The package must be importable (``pip install .`` or the development environment): the API
reference is generated from its docstrings by autodoc + napoleon (Google style).
"""

from __future__ import annotations

import os
import sys
from typing import Any

# Use the installed package; fall back to the source tree (with a compiled extension in it).
try:
    import capalloc_rs
except ImportError:  # pragma: no cover - only when building from a bare source checkout
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "python"))
    import capalloc_rs

project = "capalloc-rs"
author = "capalloc-rs authors"
copyright = "capalloc-rs authors"
release = capalloc_rs.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

html_theme = "alabaster"
html_title = "capalloc-rs"

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "show-inheritance": True}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

# Attributes sections become field lists of their class (no separate object descriptions), so a
# dataclass field that is also a documented property is not described twice.
napoleon_use_ivar = True

# --- TEMPORARY: docstrings with reST errors in modules being moved (see the lead's list of
# docstring fixes). Each object named here is shown as a literal block instead of being parsed.
# Remove an entry once its docstring is fixed; remove the whole block when the set is empty.
TEMPORARY_LITERAL_DOCSTRINGS: frozenset[str] = frozenset(
    {
        "capalloc_rs.SerialExecutor.submit",  # inherits Executor.submit's "fn(*args, **kwargs)"
    }
)


def _literal_docstring(
    app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    if name in TEMPORARY_LITERAL_DOCSTRINGS and lines:
        body = ["    " + line if line else "" for line in lines]
        lines[:] = ["::", "", *body, ""]


def setup(app: Any) -> None:
    app.connect("autodoc-process-docstring", _literal_docstring)


# --- end TEMPORARY
