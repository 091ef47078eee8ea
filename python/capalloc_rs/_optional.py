"""Optional dependencies: one import helper, one error class, one pip command per extra.

Every optional import of the package goes through :func:`require`, so a missing package always
raises :class:`~capalloc_rs.errors.MissingDependencyError` (an :class:`ImportError`) whose
message names the feature, the missing module and the exact command that installs it, e.g.
``pip install 'capalloc-rs[plot]'``. The extras are those of ``pyproject.toml``.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingDependencyError

__all__ = ["EXTRAS", "pip_command", "require"]

#: The extra of ``pyproject.toml`` that installs each optional top-level module.
EXTRAS = {
    "matplotlib": "plot",
    "pyarrow": "sweep",
    "pandas": "sweep",
    "tqdm": "sweep",
    "distributed": "distributed",
    "dask": "distributed",
}


def pip_command(module: str) -> str:
    """The command that installs ``module`` as the package's extra (``pip install
    'capalloc-rs[plot]'`` for matplotlib)."""
    top = module.split(".", 1)[0]
    extra = EXTRAS.get(top)
    return f"pip install 'capalloc-rs[{extra}]'" if extra else f"pip install {top}"


def require(module: str, feature: str) -> ModuleType:
    """Imports ``module`` (e.g. ``"matplotlib.pyplot"``) for ``feature`` (e.g. ``"the plot"``), else
    raises :class:`MissingDependencyError` with the pip command."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        top = module.split(".", 1)[0]
        raise MissingDependencyError(
            f"{top} is not installed and {feature} needs it: {pip_command(module)}"
        ) from exc
