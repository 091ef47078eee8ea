"""The networks of a sweep: reproducible random block networks, built lazily, and the resolution
of each item of ``networks`` (a :class:`~capalloc_rs.Network` or a model-file path) to a network,
its digest and its load error.

Network ``k`` of :func:`random_networks` is ``Network.random(num_subsystems, n, p, eps, seed=s_k,
r_min=r_min)`` with ``s_k`` drawn from ``numpy.random.SeedSequence([seed, k])``: the networks are
independent and each can be rebuilt on its own.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Sequence
from typing import Any, overload

import numpy as np

from .._arrays import MAX_SEED, as_count
from ..errors import InvalidInputError
from ..network import Network
from .task_ids import network_digest
from .tasks import TASK_ERRORS

__all__ = ["Chain", "RandomNetworks", "checked_networks", "random_networks", "resolve"]


class RandomNetworks(Sequence[Network]):
    """A lazy, sized sequence of reproducible random block networks (see :func:`random_networks`):
    network ``k`` is built when it is accessed, so iterating over a million of them holds one at a
    time, and ``len`` gives progress bars their total."""

    def __init__(
        self,
        count: int,
        num_subsystems: int,
        n: int = 2,
        p: int = 1,
        eps: float = 0.1,
        seed: int = 0,
        r_min: float = 1.0,
        *,
        costs: Any = None,
        r_max: Any = None,
    ) -> None:
        self.size = as_count("count", count)
        self.costs, self.r_max = costs, r_max
        self.num_subsystems = num_subsystems
        self.n, self.p, self.eps, self.r_min = n, p, eps, r_min
        self.seed = as_count("seed", seed, maximum=MAX_SEED)
        if self.size:
            self._build(0)  # validate the parameters now

    def seed_of(self, k: int) -> int:
        """The ``Network.random`` seed of network ``k``."""
        return int(np.random.SeedSequence([self.seed, k]).generate_state(1, np.uint64)[0])

    def _build(self, k: int) -> Network:
        net = Network.random(
            self.num_subsystems, self.n, self.p, self.eps, seed=self.seed_of(k), r_min=self.r_min
        )
        if self.costs is None and self.r_max is None:
            return net
        st = net.structure
        assert st is not None
        return Network.from_blocks(
            st.a_blocks,
            st.g_blocks,
            st.c_blocks,
            st.coupling,
            st.eps,
            self.r_min,
            costs=self.costs,
            r_max=self.r_max,
        )

    def __len__(self) -> int:
        return self.size

    @overload
    def __getitem__(self, k: int) -> Network: ...
    @overload
    def __getitem__(self, k: slice) -> list[Network]: ...
    def __getitem__(self, k: int | slice) -> Network | list[Network]:
        if isinstance(k, slice):
            return [self._build(i) for i in range(*k.indices(self.size))]
        i = int(k) + (self.size if int(k) < 0 else 0)
        if not 0 <= i < self.size:
            raise IndexError(f"network index {k} out of range for {self.size} networks")
        return self._build(i)

    def __repr__(self) -> str:
        return (
            f"RandomNetworks(size={self.size}, num_subsystems={self.num_subsystems}, "
            f"n={self.n}, p={self.p}, eps={self.eps}, seed={self.seed}, r_min={self.r_min}"
            + ("" if self.costs is None else f", costs={self.costs}")
            + ("" if self.r_max is None else f", r_max={self.r_max}")
            + ")"
        )


def random_networks(
    count: int,
    num_subsystems: int,
    n: int = 2,
    p: int = 1,
    eps: float = 0.1,
    seed: int = 0,
    r_min: float = 1.0,
    *,
    costs: Any = None,
    r_max: Any = None,
) -> RandomNetworks:
    """``count`` reproducible random block networks, as a lazy sequence: network ``k`` is
    ``Network.random(num_subsystems, n, p, eps, seed=s_k, r_min=r_min)`` with ``s_k`` drawn from
    ``numpy.random.SeedSequence([seed, k])``, so networks are independent and each can be rebuilt
    on its own; it is built only when accessed. ``costs`` and ``r_max`` (scalars or one value per
    sensor) give every network those sample costs and rate caps (see
    :meth:`Network.from_blocks <capalloc_rs.Network.from_blocks>`)."""
    return RandomNetworks(count, num_subsystems, n, p, eps, seed, r_min, costs=costs, r_max=r_max)


class Chain(Sequence[Any]):
    """Two sequences back to back, lazily."""

    def __init__(self, first: Sequence[Any], second: Sequence[Any]) -> None:
        self._a, self._b = first, second

    def __len__(self) -> int:
        return len(self._a) + len(self._b)

    @overload
    def __getitem__(self, k: int) -> Any: ...
    @overload
    def __getitem__(self, k: slice) -> list[Any]: ...
    def __getitem__(self, k: int | slice) -> Any:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        i = int(k) + (len(self) if int(k) < 0 else 0)
        if not 0 <= i < len(self):
            raise IndexError(k)
        return self._a[i] if i < len(self._a) else self._b[i - len(self._a)]


NetworkItem = Network | str | os.PathLike[str]


def checked_networks(networks: Any) -> Iterable[NetworkItem]:
    """``networks`` if it is an iterable (not a string).

    Raises:
        InvalidInputError: anything else.
    """
    if isinstance(networks, str | bytes) or not isinstance(networks, Iterable):
        raise InvalidInputError(
            f"networks must be an iterable of Network objects or model-file paths, got "
            f"{type(networks).__name__}"
        )
    return networks


def known_count(networks: Iterable[NetworkItem]) -> int | None:
    """How many networks there are, if ``networks`` is a sequence (a generator does not tell)."""
    if isinstance(networks, Sequence) and not isinstance(networks, str | bytes):
        return len(networks)
    return None


def resolve(item: Any) -> tuple[Network | None, str, str | None]:
    """``(network, digest, load error)`` for a Network or a model-file path.

    Raises:
        InvalidInputError: ``item`` is neither.
    """
    if isinstance(item, Network):
        return item, network_digest(item), None
    if isinstance(item, str | os.PathLike):
        try:
            net = Network.load(item)
        except TASK_ERRORS as exc:  # a bad file's failure becomes its tasks' error rows
            d = hashlib.sha256(f"unloadable:{os.fspath(item)}".encode()).hexdigest()[:16]
            return None, d, f"{type(exc).__name__}: {exc}"
        return net, network_digest(net), None
    raise InvalidInputError(
        f"networks must hold capalloc_rs.Network objects or model-file paths, got {type(item)!r}"
    )
