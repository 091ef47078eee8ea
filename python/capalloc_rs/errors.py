"""The package's exception classes.

Input problems are :class:`ValueError` subclasses; numerical failures are subclasses of
:class:`numpy.linalg.LinAlgError`. The Rust core raises these same classes (its one conversion,
with the table of which core error becomes which class, is ``rust/python/errors.rs``), so
``except capalloc_rs.errors.CapallocError`` catches everything the library raises on purpose.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "CapallocError",
    "InputError",
    "ShapeError",
    "NonFiniteError",
    "InvalidInputError",
    "NonFiniteValueError",
    "NumericalError",
    "NoStabilizingSolutionError",
    "SingularProblemError",
    "ReorderError",
    "ConvergenceError",
    "PathStallError",
    "NotObservableError",
    "NotDetectableError",
    "UnexcitedAxisModeError",
    "ModelFormatError",
    "ScheduleError",
    "AliasingError",
    "UnobservableError",
    "SweepError",
    "MissingDependencyError",
    "FeatureUnavailableError",
    "MarginalSolutionWarning",
    "InaccurateSolutionWarning",
    "UncheckedExistenceWarning",
    "UnguardedMainWarning",
]


class CapallocError(Exception):
    """Base class of every error raised on purpose by capalloc_rs."""


class InputError(CapallocError, ValueError):
    """The input is invalid (shape, values, or a property the method requires)."""


class ShapeError(InputError):
    """An array has the wrong shape (non-square, mismatched, empty, wrong number of dimensions)."""


class NonFiniteError(InputError):
    """An array contains NaN or infinite entries."""


class InvalidInputError(InputError):
    """Any other invalid input (e.g. a weight that is not positive definite, an asymmetric Q)."""


class NonFiniteValueError(NonFiniteError, InvalidInputError):
    """A scalar argument (a capacity, period, tolerance…) is NaN or infinite: both a
    :class:`NonFiniteError` and an :class:`InvalidInputError`."""


class NumericalError(CapallocError, np.linalg.LinAlgError):
    """A numerical method could not deliver an accurate answer for valid input."""


class NoStabilizingSolutionError(NumericalError):
    """The Riccati equation has no stabilising solution (e.g. Hamiltonian eigenvalues on or too
    near the imaginary axis, or unstabilisable/undetectable data)."""


class SingularProblemError(NumericalError):
    """A linear system or matrix equation is singular or too ill-conditioned to solve accurately."""


class ReorderError(NumericalError):
    """A Schur reordering swap was rejected because it would have lost accuracy."""


class ConvergenceError(NumericalError):
    """An iteration did not converge within its bound."""


class PathStallError(ConvergenceError):
    """Path following (:func:`capalloc_rs.filtration`) cannot get past ``sigma``: the corrector
    failed on ``failures`` consecutive steps, the last and smallest of length ``step``, and the
    next would be below ``min_step`` (the message says where, why and what to do)."""

    def __init__(
        self,
        message: str,
        sigma: float = float("nan"),
        step: float = float("nan"),
        min_step: float = float("nan"),
        failures: int = 0,
    ) -> None:
        super().__init__(message)
        self.sigma = sigma
        self.step = step
        self.min_step = min_step
        self.failures = failures

    def __reduce__(self) -> tuple[object, ...]:  # keeps the fields through pickle (dask workers)
        return (type(self), (str(self), self.sigma, self.step, self.min_step, self.failures))


class NotObservableError(InputError):
    """A subsystem's pair ``(A_i, c_i)`` is not observable (the paper's Assumption 1)."""


class NotDetectableError(InputError):
    """The network's pair ``(A, [ĉ_1 … ĉ_N])`` is not detectable: an unstable or marginally stable
    mode is seen by no sensor, so no steady-state error covariance exists."""


class UnexcitedAxisModeError(InputError):
    """A mode of ``A`` on the imaginary axis receives no process noise: ``(A, Q^{1/2})`` has an
    uncontrollable mode there, so the Riccati equation has no stabilising solution (possible only
    when ``Q = G Gᵀ`` is singular)."""


class ModelFormatError(InputError):
    """A model file (TOML, JSON or ``.npz``) is malformed; the message names the field."""


class ScheduleError(InputError):
    """A schedule is invalid for the network: a slot names an unknown sensor, or a sensor gets fewer
    than ``r_min`` slots per period (starved)."""


class AliasingError(InputError):
    """The period τ aliases two distinct eigenvalues of A (``e^{λ_iτ} = e^{λ_jτ}``): τ ∉ 𝒯, so
    Proposition 1 of the paper does not guarantee a periodic steady state."""


class UnobservableError(NotObservableError):
    """``(A, [c̄_1 … c̄_N])`` restricted to the sensors a schedule uses is not observable, so
    Proposition 1 of the paper does not guarantee a periodic steady state (a
    :class:`NotObservableError` about the whole network rather than one subsystem)."""


class SweepError(InputError):
    """A sweep cannot run or resume as asked (e.g. its output directory holds a different sweep,
    a bad sweep spec file, or a worker process died); finished chunks stay saved."""


class MissingDependencyError(CapallocError, ImportError):
    """An optional dependency is not installed (the message says what to ``pip install``)."""


class FeatureUnavailableError(CapallocError, NotImplementedError):
    """A feature is not part of this build of capalloc_rs."""


class MarginalSolutionWarning(RuntimeWarning):
    """A Riccati solution was returned for a marginal problem: Hamiltonian eigenvalues lie on the
    imaginary axis to within their own perturbation bounds, so the solution is at best
    semi-stabilising and its accuracy is poor (the message gives the margin and the error bound).
    Raised as a warning by the scipy-compatible :func:`capalloc_rs.linalg.solve_continuous_are`;
    :func:`capalloc_rs.linalg.care` raises :class:`NoStabilizingSolutionError` instead unless
    ``accept_marginal=True``."""


class InaccurateSolutionWarning(RuntimeWarning):
    """A Riccati solution was returned whose proven error bound ``forward_error`` is above
    :data:`capalloc_rs.linalg.INACCURATE_BOUND` (1e-3, relative): fewer than three correct
    digits are guaranteed, and with a bound of 1 or more none are (the message gives the bound).
    Warned by :func:`capalloc_rs.linalg.care` and so by the scipy-compatible
    :func:`capalloc_rs.linalg.solve_continuous_are`, which returns ``X`` alone. Known case: a tiny
    ``R`` with a single input (``R = 1e-12``), see docs/guide/linalg.md."""


class UncheckedExistenceWarning(UserWarning):
    """``check=False`` (the CLI's ``--no-check``): the hypotheses of Proposition 1 (observability
    of the sensors a schedule uses, τ ∈ 𝒯) were not checked, so the periodic steady state the
    result describes is not guaranteed to exist."""


class UnguardedMainWarning(RuntimeWarning):
    """:func:`capalloc_rs.sweep` was called from a script's top level without
    ``if __name__ == "__main__":``; worker processes would re-run the script, so the sweep runs
    in threads of this process instead (same results; guard the script for worker processes)."""
