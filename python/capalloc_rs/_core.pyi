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
    scale: bool = True,
    newton_steps: int = 0,
) -> tuple[_F64, float, float, float, int, float]: ...
def solve_lyapunov(a: _F64, q: _F64) -> _F64: ...
def solve_sylvester(a: _F64, b: _F64, q: _F64) -> _F64: ...
def schur(a: _F64, sort: str | None = None) -> tuple[_F64, _F64, int]: ...
def expm(a: _F64) -> _F64: ...
def van_loan(a: _F64, q: _F64, t: float) -> tuple[_F64, _F64]: ...
