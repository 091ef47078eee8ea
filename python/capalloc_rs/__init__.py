"""capalloc-rs: optimal capacity allocation for sampled networked systems.

Implements and extends Chen, Belabbas and Başar, "Optimal Capacity Allocation for Sampled Networked
Systems": the heavy numerics (real Schur with reordering, Hamiltonian/Schur CARE, Bartels–Stewart
Lyapunov solvers, Van Loan discretisation) live in a Rust core; this package is the typed Python
layer on top.
"""

from __future__ import annotations

from . import errors, linalg, model_io
from ._core import __version__
from .allocation import Allocation, IntegerAllocation, integer_allocation, optimal_allocation
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
from .filtration import Filtration, FiltrationEvent, filtration
from .network import Network, NetworkReport

__all__ = [
    "__version__",
    "errors",
    "linalg",
    "model_io",
    "Network",
    "NetworkReport",
    "Allocation",
    "IntegerAllocation",
    "optimal_allocation",
    "integer_allocation",
    "Filtration",
    "FiltrationEvent",
    "filtration",
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
