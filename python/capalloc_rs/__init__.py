"""capalloc-rs: optimal capacity allocation for sampled networked systems.

Implements and extends Chen, Belabbas and Başar, "Optimal Capacity Allocation for Sampled Networked
Systems": the heavy numerics (real Schur with reordering, Hamiltonian/Schur CARE, Bartels–Stewart
Lyapunov solvers, Van Loan discretisation) live in a Rust core; this package is the typed Python
layer on top.

The finite-τ layer is the package :mod:`capalloc_rs.sampled`. ``capalloc_rs.scheduling`` and
``capalloc_rs.montecarlo`` are kept as attributes of this package for the code that used the old
modules of those names: they are :mod:`capalloc_rs.sampled.search` and
:mod:`capalloc_rs.sampled.montecarlo` (``import capalloc_rs.scheduling`` no longer works; use
``from capalloc_rs import scheduling`` or the new names).
"""

from __future__ import annotations

from . import errors, limits, linalg, sampled
from ._core import __version__
from .allocation import (
    Allocation,
    Filtration,
    FiltrationEvent,
    IntegerAllocation,
    RobustAllocation,
    RobustIntegerAllocation,
    filtration,
    integer_allocation,
    optimal_allocation,
    robust_allocation,
    robust_integer_allocation,
)
from .errors import (
    AliasingError,
    CapallocError,
    ConvergenceError,
    FeatureUnavailableError,
    InaccurateSolutionWarning,
    InputError,
    InvalidInputError,
    MarginalSolutionWarning,
    MissingDependencyError,
    ModelFormatError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NotDetectableError,
    NotObservableError,
    NumericalError,
    ReorderError,
    ScheduleError,
    ShapeError,
    SingularProblemError,
    SweepError,
    UncheckedExistenceWarning,
    UnexcitedAxisModeError,
    UnguardedMainWarning,
    UnobservableError,
)
from .network import Network, NetworkReport
from .network import files as model_io
from .sampled import (
    BestSchedule,
    MonteCarloResult,
    SampledCovariance,
    Schedule,
    best_schedule,
    check_existence,
    greedy_schedule,
    montecarlo,
    round_robin_schedule,
    sampled_cost,
    sampled_covariance,
    simulate,
)
from .sampled import search as scheduling
from .sweep import SerialExecutor, SweepStats, random_networks, sweep

__all__ = [
    "__version__",
    "errors",
    "limits",
    "linalg",
    "model_io",
    "Network",
    "NetworkReport",
    "Allocation",
    "IntegerAllocation",
    "optimal_allocation",
    "integer_allocation",
    "RobustAllocation",
    "RobustIntegerAllocation",
    "robust_allocation",
    "robust_integer_allocation",
    "Filtration",
    "FiltrationEvent",
    "filtration",
    "CapallocError",
    "ConvergenceError",
    "InputError",
    "InvalidInputError",
    "MarginalSolutionWarning",
    "InaccurateSolutionWarning",
    "ModelFormatError",
    "NoStabilizingSolutionError",
    "NonFiniteError",
    "NotDetectableError",
    "UnexcitedAxisModeError",
    "NotObservableError",
    "NumericalError",
    "ReorderError",
    "ShapeError",
    "SingularProblemError",
    "montecarlo",
    "sampled",
    "scheduling",
    "AliasingError",
    "ScheduleError",
    "UnobservableError",
    "Schedule",
    "SampledCovariance",
    "check_existence",
    "sampled_cost",
    "sampled_covariance",
    "BestSchedule",
    "best_schedule",
    "greedy_schedule",
    "round_robin_schedule",
    "MonteCarloResult",
    "simulate",
    "FeatureUnavailableError",
    "MissingDependencyError",
    "UncheckedExistenceWarning",
    "UnguardedMainWarning",
    "SweepError",
    "sweep",
    "SweepStats",
    "SerialExecutor",
    "random_networks",
]
