"""A set of K models of one sensor network and the evaluations the robust allocation needs.

The robust problems of :mod:`.robust` are posed over the weighted box-simplex of
:mod:`.box_simplex`, which depends only on the sensors' sample costs ``b``, minima ``r_min`` and
caps ``r_max`` and the budget ``B``: the K models must agree on those (and on ``N``); their
dynamics (``A``, ``G``, the sensor matrices, even the state dimension) may differ. Each model is
evaluated in channel units (``Network.in_channel_units()``, rates ``s = b ∘ r``).

Evaluations. At a point ``s`` every model's ``η_k(s)``, ``∇η_k(s)`` and (for Newton)
``∇²η_k(s)`` are needed; each is a Rust call that releases the GIL, so the K calls run
concurrently on a thread pool of at most as many threads as cores (each call single-threaded,
``threads=1``). The results do not depend on the number of threads.

Also here: :func:`coupling_models`, the models of an uncertain coupling strength — a block network
``A = blockdiag(A_i) + ε·coupling`` with ε replaced by each of several values.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .._arrays import as_count, as_float_array
from ..errors import InvalidInputError
from ..network import Network

__all__ = ["MAX_MODELS", "ModelSet", "coupling_models", "model_list", "model_weights"]

F64 = npt.NDArray[np.float64]

#: The largest number of models accepted (a list or ``num_models`` of a sampler).
MAX_MODELS = 100_000


def _cores() -> int:
    """The cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)
    if affinity is not None:
        return max(1, len(affinity(0)))
    return max(1, os.cpu_count() or 1)


def _one_model(k: int, m: Any) -> Network:
    """``models[k]``: a :class:`~capalloc_rs.Network` or a path to a model file."""
    if isinstance(m, str | os.PathLike):
        return Network.load(Path(m))
    if not isinstance(m, Network):
        raise InvalidInputError(
            f"models[{k}] must be a capalloc_rs.Network or a model file, got {type(m).__name__}"
        )
    return m


def _sampled(sampler: Callable[[Any], Any], num_models: Any, seed: Any) -> list[Network]:
    """``num_models`` networks ``sampler(rng)`` with ``rng = numpy.random.default_rng(seed)``."""
    if num_models is None:
        raise InvalidInputError("models given as a sampler need num_models (how many to draw)")
    count = as_count("num_models", num_models, minimum=1, maximum=MAX_MODELS)
    if seed is not None:
        seed = as_count("seed", seed)
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        net = sampler(rng)
        if not isinstance(net, Network):
            raise InvalidInputError(
                f"models: the sampler must return a capalloc_rs.Network, got "
                f"{type(net).__name__} at draw {k}"
            )
        out.append(net)
    return out


def _same_sensors(nets: Sequence[Network]) -> None:
    """Every model has the sensors of ``models[0]``: ``N``, costs, minima and caps."""
    first = nets[0]
    for k, net in enumerate(nets[1:], start=1):
        if net.num_sensors != first.num_sensors:
            raise InvalidInputError(
                f"models[{k}] has {net.num_sensors} sensors, models[0] has {first.num_sensors}: "
                "the models must describe the same sensors"
            )
        for name in ("costs", "rate_min", "rate_max"):
            if not np.array_equal(getattr(net, name), getattr(first, name)):
                raise InvalidInputError(
                    f"models[{k}] has other sensor {name} than models[0]: the models must share "
                    "the sensors' sample costs, minima and caps"
                )


def model_list(models: Any, num_models: Any = None, seed: Any = None) -> list[Network]:
    """The models as a checked list: a non-empty sequence of networks (or model files) with the
    same sensors, or ``num_models`` draws of a sampler ``models(rng)``.

    Raises:
        InvalidInputError: an empty or malformed list, models with different sensors (naming
            ``models``), a sampler without ``num_models``, or ``num_models``/``seed`` given with
            a list.
    """
    if callable(models) and not isinstance(models, Network):
        nets = _sampled(models, num_models, seed)
    else:
        if num_models is not None or seed is not None:
            raise InvalidInputError("num_models and seed apply only when models is a sampler")
        if isinstance(models, Network | str | os.PathLike) or not isinstance(
            models, Sequence | tuple
        ):
            raise InvalidInputError(
                "models must be a non-empty list of networks (or model files) or a sampler "
                f"sampler(rng) -> Network, got {type(models).__name__}"
            )
        if len(models) == 0:
            raise InvalidInputError("models must not be empty")
        if len(models) > MAX_MODELS:
            raise InvalidInputError(f"models: at most {MAX_MODELS} models, got {len(models)}")
        nets = [_one_model(k, m) for k, m in enumerate(models)]
    _same_sensors(nets)
    return nets


def coupling_models(net: Network, eps: Any) -> list[Network]:
    """The block network ``net`` with its coupling strength ε replaced by each value of ``eps``
    (same subsystems, coupling matrix, sensors, costs, limits and error weight).

    Raises:
        InvalidInputError: ``net`` is not a block network (no ``structure``), or ``eps`` is not
            a non-empty list of finite numbers.
    """
    st = net.structure
    if st is None:
        raise InvalidInputError(
            "an uncertain coupling needs a block network (Network.from_blocks, Network.random or "
            "a model file with subsystems)"
        )
    values = as_float_array("eps", eps, 1)
    if values.size == 0 or values.size > MAX_MODELS:
        raise InvalidInputError(f"eps must hold 1 to {MAX_MODELS} values, got {values.size}")
    return [
        Network.from_blocks(
            st.a_blocks,
            st.g_blocks,
            st.c_blocks,
            st.coupling,
            float(e),
            net.rate_min,
            weight=net.error_weight,
            costs=net.costs,
            r_max=net.rate_max,
        )
        for e in values
    ]


def model_weights(weights: Any, count: int) -> F64:
    """The weights ``w_k ≥ 0`` normalised to sum 1 (equal when ``None``).

    Raises:
        InvalidInputError: not ``count`` finite non-negative numbers with a positive sum.
    """
    if weights is None:
        return np.full(count, 1.0 / count)
    w = as_float_array("weights", weights, 1)
    if w.shape != (count,):
        raise InvalidInputError(f"weights must have one entry per model ({count}), got {w.size}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InvalidInputError("weights must be finite and non-negative")
    total = float(np.sum(w))
    if not total > 0:
        raise InvalidInputError("weights must not all be zero")
    return w / total


class ModelSet:
    """K models in channel units, evaluated concurrently at one point ``s`` (channel units).

    Use as a context manager (the thread pool is shut down on exit)."""

    def __init__(self, nets: Sequence[Network]) -> None:
        self.nets = tuple(nets)
        self.units = tuple(n.in_channel_units() for n in self.nets)
        self.threads = min(len(self.nets), _cores())
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self.evaluations = 0

    def __enter__(self) -> ModelSet:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown()

    def _map(self, fn: Callable[[Network], Any]) -> list[Any]:
        self.evaluations += len(self.units)
        if self._pool is None:
            return [fn(m) for m in self.units]
        return list(self._pool.map(fn, self.units))

    def values(self, s: F64) -> F64:
        """``(η_k(s))_k``."""
        return np.array(self._map(lambda m: m.cost(s)), dtype=np.float64)

    def values_gradients(self, s: F64) -> tuple[F64, F64]:
        """``(η_k(s))_k`` and the ``K × N`` gradients."""
        out = self._map(lambda m: m.value_and_gradient(s))
        return np.array([v for v, _ in out]), np.array([g for _, g in out])

    def values_gradients_hessians(self, s: F64) -> tuple[F64, F64, F64]:
        """``(η_k(s))_k``, the ``K × N`` gradients and the ``K × N × N`` Hessians."""
        out = self._map(lambda m: m.value_gradient_hessian(s, threads=1))
        return (
            np.array([v for v, _, _ in out]),
            np.array([g for _, g, _ in out]),
            np.array([h for _, _, h in out]),
        )

    def value_errors(self, s: F64) -> F64:
        """The Riccati solver's bounds on ``|η_k(s) − η_k,exact|``."""
        return np.array(self._map(lambda m: m.at(s).value_error), dtype=np.float64)

    def costs_many(self, rows: F64) -> F64:
        """``K × M``: ``η_k`` at each row of ``rows`` (rates, not channel units), each model's
        rows in parallel in Rust."""
        self.evaluations += len(self.nets) * rows.shape[0]
        return np.array([m.cost_many(rows) for m in self.nets])
