"""Type stubs for the Rust extension module ``capalloc_rs._core``."""

import numpy as np
import numpy.typing as npt

__version__: str

_F64 = npt.NDArray[np.float64]

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
) -> tuple[_F64, float, float, float, int, float, float, float, float, bool]: ...
def solve_lyapunov(a: _F64, q: _F64) -> _F64: ...
def solve_sylvester(a: _F64, b: _F64, q: _F64) -> _F64: ...
def schur(a: _F64, sort: str | None = None) -> tuple[_F64, _F64, int]: ...
def schur_reorder(t: _F64, z: _F64, select: list[bool]) -> tuple[_F64, _F64, int]: ...
def expm(a: _F64) -> _F64: ...
def van_loan(a: _F64, q: _F64, t: float) -> tuple[_F64, _F64]: ...

class CostModel:
    def __init__(
        self,
        a: _F64,
        g: _F64,
        sensors: list[_F64],
        scale: bool = True,
        newton_steps: int = 8,
    ) -> None: ...
    @property
    def n(self) -> int: ...
    @property
    def num_sensors(self) -> int: ...
    def sensor_rows(self) -> list[tuple[int, int]]: ...
    def weight(self, r: _F64) -> _F64: ...
    def cost(self, r: _F64) -> float: ...
    def value_gradient(self, r: _F64) -> tuple[float, _F64]: ...
    def evaluate(
        self, r: _F64, order: int = 0, threads: int | None = None
    ) -> tuple[float, _F64, float, float, _F64 | None, _F64 | None]: ...
    def hvp(self, r: _F64, v: _F64) -> _F64: ...
    def at(self, r: _F64) -> CostPoint: ...
    def cost_many(
        self, rates: _F64, nan_on_error: bool = False, threads: int | None = None
    ) -> _F64: ...
    def value_gradient_many(
        self, rates: _F64, nan_on_error: bool = False, threads: int | None = None
    ) -> tuple[_F64, _F64]: ...

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
    def gradient(self) -> _F64: ...
    def hvp(self, v: _F64) -> _F64: ...
    def hessian(self, threads: int | None = None) -> _F64: ...

# -- sampled system (capalloc_rs.sampled) -------------------------------------------------------
_I64 = npt.NDArray[np.int64]
_F64_3 = npt.NDArray[np.float64]

def sampled_discretise(
    a: _F64, q: _F64, sensors: list[_F64], tau: float, r_tot: int
) -> tuple[_F64, _F64, list[_F64]]: ...
def sampled_period_triplet(
    a: _F64, q: _F64, sensors: list[_F64], tau: float, slots: _I64
) -> tuple[_F64, _F64, _F64]: ...
def sampled_steady_state(
    a: _F64,
    q: _F64,
    sensors: list[_F64],
    tau: float,
    slots: _I64,
    tol: float = 1e-12,
    max_steps: int = 64,
) -> tuple[_F64, _F64_3, _F64_3, int, float, float, float]: ...
def sampled_propagate(
    a: _F64, q: _F64, sensors: list[_F64], tau: float, slots: _I64, sigma0: _F64
) -> tuple[_F64_3, _F64_3]: ...
def sampled_fixed_point(
    a: _F64,
    q: _F64,
    sensors: list[_F64],
    tau: float,
    slots: _I64,
    sigma0: _F64,
    tol: float,
    max_periods: int,
) -> tuple[_F64, int, float]: ...
def sampled_cost(
    a: _F64,
    q: _F64,
    sensors: list[_F64],
    tau: float,
    slots: _I64,
    which: str = "boundary",
    tol: float = 1e-12,
    max_steps: int = 64,
) -> float: ...
def sampled_neighbourhood(
    a: _F64,
    q: _F64,
    sensors: list[_F64],
    tau: float,
    slots: _I64,
    which: str = "boundary",
    min_count: int = 1,
    tol: float = 1e-12,
    max_steps: int = 64,
    time_limit: float | None = None,
) -> tuple[float, _F64, _F64, _F64, bool, int]: ...
def sampled_greedy_pass(
    a: _F64,
    q: _F64,
    sensors: list[_F64],
    tau: float,
    r_tot: int,
    sigma0: _F64,
    min_count: int,
) -> tuple[_I64, _F64]: ...
def sampled_unobservable_dimension(a: _F64, c: _F64, rtol: float = 1e-10) -> int: ...
def sampled_aliasing_pair(
    a: _F64, tau: float, tol: float = 1e-8
) -> tuple[tuple[float, float], tuple[float, float]] | None: ...
