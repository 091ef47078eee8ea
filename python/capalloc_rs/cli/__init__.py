"""The ``capalloc`` command line (package; see :mod:`capalloc_rs.cli.main`)."""

from __future__ import annotations

from .main import build_parser, demo_network, main

__all__ = ["main", "build_parser", "demo_network"]
