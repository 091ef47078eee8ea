"""Sphinx configuration of the capalloc-rs documentation.

Build (warnings are errors, as in CI)::

    python3 -m sphinx -W --keep-going -b html docs docs/_build/html

The package must be importable (``pip install .`` or the development environment): the API
reference is generated from its docstrings by autodoc + napoleon (Google style).
"""

from __future__ import annotations

import os
import sys

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
