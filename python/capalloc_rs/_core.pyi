"""Type stubs for the Rust extension module ``capalloc_rs._core``.

Checked against the built extension by ``python -m mypy.stubtest capalloc_rs._core`` (CI). Every
binding that returns several values returns one of the frozen record classes below (declared in
``rust/python/results.rs``): read-only attributes, no constructor. ``CostModel`` and
``SampledModel`` hold a model validated once; the sampled functions and the schedule search go
through ``SampledModel`` (``capalloc_rs.sampled.SampledSystem.core``).
"""

from collections.abc import Sequence
from typing import final

import numpy as np
import numpy.typing as npt

__version__: str
__all__ = [
    "__version__",
    "_core_error_mapping",
    "_raise_core_error",
    "CareSolution",
    "SchurForm",
    "VanLoan",
    "ValueGradient",
    "ValueGradientBatch",
    "CostEvaluation",
    "SlotDiscretisation",
    "PeriodTriplet",
    "SteadyState",
    "Propagation",
    "FixedPoint",
    "Neighbourhood",
    "Screen",
    "CandidateCosts",
    "GreedyPass",
    "AliasingPair",
    "SeparableAllocation",
    "NewtonAllocation",
    "separable_allocation",
    "care",
    "solve_lyapunov",
    "solve_sylvester",
    "schur",
    "schur_reorder",
    "expm",
    "van_loan",
    "CostModel",
    "CostPoint",
    "SampledModel",
    "sampled_unobservable_dimension",
    "sampled_aliasing_pair",
    "ExactSchedule",
    "sampled_exact_schedule",
]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_F64_3 = npt.NDArray[np.float64]

# -- the error seam (rust/python/errors.rs): test hooks -----------------------------------------

def _core_error_mapping() -> list[tuple[str, str]]: ...
def _raise_core_error(variant: str, message: str) -> None: ...

# -- result records (rust/python/results.rs) ----------------------------------------------------

@final
class SeparableAllocation:
    @property
    def gamma(self) -> _F64: ...
    @property
    def value(self) -> float: ...
    @property
    def gap(self) -> float: ...
    @property
    def iterations(self) -> int: ...

@final
class NewtonAllocation:
    @property
    def gamma(self) -> _F64: ...
    @property
    def iterations(self) -> int: ...
    @property
    def value(self) -> float: ...
    @property
    def gradient(self) -> _F64: ...
    @property
    def value_error(self) -> float: ...

@final
class CareSolution:
    @property
    def x(self) -> _F64: ...
    @property
    def residual(self) -> float: ...
    @property
    def rcond(self) -> float: ...
    @property
    def closed_loop_abscissa(self) -> float: ...
    @property
    def newton_steps(self) -> int: ...
    @property
    def scaling(self) -> float: ...
    @property
    def forward_error(self) -> float: ...
    @property
    def trace_error(self) -> float: ...
    @property
    def axis_margin(self) -> float: ...
    @property
    def marginal(self) -> bool: ...

@final
class SchurForm:
    @property
    def t(self) -> _F64: ...
    @property
    def z(self) -> _F64: ...
    @property
    def sdim(self) -> int: ...

@final
class VanLoan:
    @property
    def e(self) -> _F64: ...
    @property
    def h(self) -> _F64: ...

@final
class ValueGradient:
    @property
    def value(self) -> float: ...
    @property
    def gradient(self) -> _F64: ...

@final
class ValueGradientBatch:
    @property
    def values(self) -> _F64: ...
    @property
    def gradients(self) -> _F64: ...

@final
class CostEvaluation:
    @property
    def value(self) -> float: ...
    @property
    def sigma(self) -> _F64: ...
    @property
    def care_residual(self) -> float: ...
    @property
    def closed_loop_abscissa(self) -> float: ...
    @property
    def gradient(self) -> _F64 | None: ...
    @property
    def hessian(self) -> _F64 | None: ...

@final
class SlotDiscretisation:
    @property
    def e(self) -> _F64: ...
    @property
    def h(self) -> _F64: ...
    @property
    def cbar(self) -> list[_F64]: ...
    @property
    def es(self) -> list[_F64]: ...
    @property
    def hs(self) -> list[_F64]: ...
    @property
    def tau0(self) -> float: ...

@final
class PeriodTriplet:
    @property
    def a(self) -> _F64: ...
    @property
    def g(self) -> _F64: ...
    @property
    def h(self) -> _F64: ...

@final
class SteadyState:
    @property
    def boundary(self) -> _F64: ...
    @property
    def posteriors(self) -> _F64_3: ...
    @property
    def priors(self) -> _F64_3: ...
    @property
    def steps(self) -> int: ...
    @property
    def rel_change(self) -> float: ...
    @property
    def spectral_radius(self) -> float: ...
    @property
    def residual(self) -> float: ...
    @property
    def idle(self) -> float: ...
    @property
    def tail_e(self) -> _F64: ...
    @property
    def tail_h(self) -> _F64: ...

@final
class Propagation:
    @property
    def priors(self) -> _F64_3: ...
    @property
    def posteriors(self) -> _F64_3: ...

@final
class FixedPoint:
    @property
    def sigma(self) -> _F64: ...
    @property
    def periods(self) -> int: ...
    @property
    def rel_change(self) -> float: ...

@final
class Neighbourhood:
    @property
    def current(self) -> float: ...
    @property
    def reassign(self) -> _F64: ...
    @property
    def swap(self) -> _F64: ...
    @property
    def rotate(self) -> _F64: ...
    @property
    def complete(self) -> bool: ...
    @property
    def evaluated(self) -> int: ...

@final
class Screen:
    @property
    def current(self) -> float: ...
    @property
    def spectral_radius(self) -> float: ...
    @property
    def reassign(self) -> _F64: ...
    @property
    def swap(self) -> _F64: ...
    @property
    def rotate(self) -> _F64: ...
    @property
    def stein_steps(self) -> int: ...

@final
class CandidateCosts:
    @property
    def costs(self) -> _F64: ...
    @property
    def complete(self) -> bool: ...
    @property
    def evaluated(self) -> int: ...

@final
class GreedyPass:
    @property
    def slots(self) -> _I64: ...
    @property
    def sigma(self) -> _F64: ...

@final
class AliasingPair:
    @property
    def first(self) -> complex: ...
    @property
    def second(self) -> complex: ...

# -- linear algebra (capalloc_rs.linalg) --------------------------------------------------------

def care(
    a: _F64,
    b: _F64,
    q: _F64,
    r: _F64 | None = None,
    e: _F64 | None = None,
    s: _F64 | None = None,
    scale: bool = True,
    newton_steps: int = 8,
    balance: bool = True,
    accept_marginal: bool = False,
) -> CareSolution: ...
def solve_lyapunov(a: _F64, q: _F64) -> _F64: ...
def separable_allocation(
    a_blocks: Sequence[_F64],
    g_blocks: Sequence[_F64],
    c_blocks: Sequence[_F64],
    r_min: float,
    sigma: float,
    tol: float,
    max_iter: int,
    weight_blocks: Sequence[_F64] | None = None,
) -> SeparableAllocation: ...
def solve_sylvester(a: _F64, b: _F64, q: _F64) -> _F64: ...
def schur(a: _F64, sort: str | None = None) -> SchurForm: ...
def schur_reorder(t: _F64, z: _F64, select: list[bool]) -> SchurForm: ...
def expm(a: _F64) -> _F64: ...
def van_loan(a: _F64, q: _F64, t: float) -> VanLoan: ...

# -- the cost η(r) (capalloc_rs.network) --------------------------------------------------------

@final
class CostModel:
    def __new__(
        cls,
        a: _F64,
        g: _F64,
        sensors: list[_F64],
        scale: bool = True,
        newton_steps: int = 8,
        error_weight: _F64 | None = None,
    ) -> CostModel: ...
    @property
    def n(self) -> int: ...
    @property
    def num_sensors(self) -> int: ...
    def weight(self, r: _F64) -> _F64: ...
    def cost(self, r: _F64) -> float: ...
    def value_gradient(self, r: _F64) -> ValueGradient: ...
    def evaluate(self, r: _F64, order: int = 0, threads: int | None = None) -> CostEvaluation: ...
    def hvp(self, r: _F64, v: _F64) -> _F64: ...
    def at(self, r: _F64) -> CostPoint: ...
    def warm_at(self, r: _F64, sigma0: _F64) -> CostPoint: ...
    def newton_exact(
        self, r_min: float, sigma: float, gamma0: _F64, tol: float, max_iter: int, warm: bool
    ) -> NewtonAllocation: ...
    def cost_many(
        self, rates: _F64, nan_on_error: bool = False, threads: int | None = None
    ) -> _F64: ...
    def value_gradient_many(
        self, rates: _F64, nan_on_error: bool = False, threads: int | None = None
    ) -> ValueGradientBatch: ...

@final
class CostPoint:
    @property
    def num_sensors(self) -> int: ...
    @property
    def rates(self) -> _F64: ...
    @property
    def value(self) -> float: ...
    @property
    def sigma(self) -> _F64: ...
    @property
    def care_residual(self) -> float: ...
    @property
    def value_error(self) -> float: ...
    @property
    def closed_loop_abscissa(self) -> float: ...
    @property
    def forward_error(self) -> float: ...
    @property
    def warm_started(self) -> bool: ...
    @property
    def warm_fallback(self) -> str | None: ...
    @property
    def warm_factorizations(self) -> int: ...
    @property
    def warm_chord_steps(self) -> int: ...
    @property
    def gradient(self) -> _F64: ...
    def hvp(self, v: _F64) -> _F64: ...
    def hessian(self, threads: int | None = None) -> _F64: ...
    def hessian_block(self, idx: list[int], threads: int | None = None) -> _F64: ...
    def warm(self, r: _F64, chord_steps: int = 0, compensated: bool = True) -> CostPoint: ...

# -- sampled system (capalloc_rs.sampled) -------------------------------------------------------

@final
class SampledModel:
    def __new__(
        cls,
        a: _F64,
        q: _F64,
        sensors: list[_F64],
        costs: list[float] | None = None,
        weight: _F64 | None = None,
    ) -> SampledModel: ...
    @property
    def n(self) -> int: ...
    @property
    def num_sensors(self) -> int: ...
    @property
    def costs(self) -> _F64: ...
    def discretise(self, tau: float, budget: float) -> SlotDiscretisation: ...
    def period_triplet(
        self, tau: float, slots: _I64, budget: float | None = None
    ) -> PeriodTriplet: ...
    def steady_state(
        self,
        tau: float,
        slots: _I64,
        tol: float = 1e-12,
        max_steps: int = 64,
        budget: float | None = None,
    ) -> SteadyState: ...
    def propagate(
        self, tau: float, slots: _I64, sigma0: _F64, budget: float | None = None
    ) -> Propagation: ...
    def fixed_point(
        self,
        tau: float,
        slots: _I64,
        sigma0: _F64,
        tol: float,
        max_periods: int,
        budget: float | None = None,
    ) -> FixedPoint: ...
    def cost(
        self,
        tau: float,
        slots: _I64,
        which: str = "boundary",
        tol: float = 1e-12,
        max_steps: int = 64,
        budget: float | None = None,
    ) -> float: ...
    def neighbourhood(
        self,
        tau: float,
        slots: _I64,
        which: str = "boundary",
        min_count: int = 1,
        tol: float = 1e-12,
        max_steps: int = 64,
        time_limit: float | None = None,
        budget: float | None = None,
        min_counts: list[int] | None = None,
        max_counts: list[int] | None = None,
    ) -> Neighbourhood: ...
    def screen(
        self,
        tau: float,
        slots: _I64,
        which: str = "boundary",
        min_count: int = 1,
        tol: float = 1e-12,
        max_steps: int = 64,
        budget: float | None = None,
        min_counts: list[int] | None = None,
        max_counts: list[int] | None = None,
        time_limit: float | None = None,
    ) -> Screen | None: ...
    def candidate_costs(
        self,
        tau: float,
        candidates: list[_I64],
        which: str = "boundary",
        tol: float = 1e-12,
        max_steps: int = 64,
        time_limit: float | None = None,
        budget: float | None = None,
        incumbent: float | None = None,
    ) -> CandidateCosts: ...
    def greedy_pass(
        self,
        tau: float,
        budget: float,
        sigma0: _F64,
        min_count: int,
        min_counts: list[int] | None = None,
        max_counts: list[int] | None = None,
    ) -> GreedyPass: ...

def sampled_unobservable_dimension(a: _F64, c: _F64, rtol: float = 1e-10) -> int: ...
def sampled_aliasing_pair(a: _F64, tau: float, tol: float = 1e-8) -> AliasingPair | None: ...

@final
class ExactSchedule:
    @property
    def slots(self) -> list[int] | None: ...
    @property
    def eta_bar(self) -> float: ...
    @property
    def lower_bound(self) -> float: ...
    @property
    def nodes(self) -> int: ...
    @property
    def complete(self) -> bool: ...

def sampled_exact_schedule(
    model: SampledModel,
    tau: float,
    length: int,
    which: str,
    relaxed: list[_F64],
    min_counts: list[int],
    max_counts: list[int],
    incumbent: float,
    symmetric: bool,
    node_limit: int,
    time_limit: float | None = None,
    budget: float | None = None,
) -> ExactSchedule: ...
