"""capalloc-rs: optimal capacity allocation for sampled networked systems.

Implements and extends Chen, Belabbas and Başar, "Optimal Capacity Allocation for Sampled Networked
Systems": the heavy numerics (real Schur with reordering, Hamiltonian/Schur CARE, Bartels–Stewart
Lyapunov solvers, Van Loan discretisation) live in a Rust core; this package is the typed Python
layer on top.
"""

from __future__ import annotations

from . import errors, linalg, model_io
from ._core import __version__
from .errors import (
    CapallocError,
    ConvergenceError,
    InputError,
    InvalidInputError,
    ModelFormatError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NotDetectableError,
    NotObservableError,
    NumericalError,
    ReorderError,
    ShapeError,
    SingularProblemError,
)
from .network import Network, NetworkReport

__all__ = [
    "__version__",
    "errors",
    "linalg",
    "model_io",
    "Network",
    "NetworkReport",
    "CapallocError",
    "ConvergenceError",
    "InputError",
    "InvalidInputError",
    "ModelFormatError",
    "NoStabilizingSolutionError",
    "NonFiniteError",
    "NotDetectableError",
    "NotObservableError",
    "NumericalError",
    "ReorderError",
    "ShapeError",
    "SingularProblemError",
]
