"""capalloc-rs: optimal capacity allocation for sampled networked systems.

Implements and extends Chen, Belabbas and Başar, "Optimal Capacity Allocation for Sampled Networked
Systems": the heavy numerics (real Schur with reordering, Hamiltonian/Schur CARE, Bartels–Stewart
Lyapunov solvers, Van Loan discretisation) live in a Rust core; this package is the typed Python
layer on top.
"""

from __future__ import annotations

from . import errors, limits, linalg, montecarlo, sampled, scheduling
from ._core import __version__
from .allocation import (
    Allocation,
    Filtration,
    FiltrationEvent,
    IntegerAllocation,
    filtration,
    integer_allocation,
    optimal_allocation,
)
from .errors import (
    AliasingError,
    CapallocError,
    ConvergenceError,
    FeatureUnavailableError,
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
    UnguardedMainWarning,
    UnobservableError,
)
from .montecarlo import MonteCarloResult, simulate
from .network import Network, NetworkReport
from .network import files as model_io
from .sampled import SampledCovariance, check_existence, sampled_cost, sampled_covariance
from .schedule import Schedule
from .scheduling import BestSchedule, best_schedule, greedy_schedule, round_robin_schedule
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
    "Filtration",
    "FiltrationEvent",
    "filtration",
    "CapallocError",
    "ConvergenceError",
    "InputError",
    "InvalidInputError",
    "MarginalSolutionWarning",
    "ModelFormatError",
    "NoStabilizingSolutionError",
    "NonFiniteError",
    "NotDetectableError",
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
