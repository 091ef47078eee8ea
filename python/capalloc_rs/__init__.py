"""capalloc-rs: optimal capacity allocation for sampled networked systems.

Implements and extends Chen, Belabbas and Başar, "Optimal Capacity Allocation for Sampled Networked
Systems": the heavy numerics (real Schur with reordering, Hamiltonian/Schur CARE, Bartels–Stewart
Lyapunov solvers, Van Loan discretisation) live in a Rust core; this package is the typed Python
layer on top.
"""

from __future__ import annotations

from . import errors, linalg
from ._core import __version__
from .errors import (
    CapallocError,
    ConvergenceError,
    InputError,
    InvalidInputError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NumericalError,
    ReorderError,
    ShapeError,
    SingularProblemError,
)

__all__ = [
    "__version__",
    "errors",
    "linalg",
    "CapallocError",
    "ConvergenceError",
    "InputError",
    "InvalidInputError",
    "NoStabilizingSolutionError",
    "NonFiniteError",
    "NumericalError",
    "ReorderError",
    "ShapeError",
    "SingularProblemError",
]
