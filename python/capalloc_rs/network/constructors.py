"""Assembling the paper's block networks: ``A = blockdiag(A_i) + ε·[A_ij]``, ``G = blockdiag(G_i)``
and the zero-padded sensors ``ĉ_i``, from blocks, from python-control state-space systems or at
random (observable by construction).

The functions here check their arguments (naming the subsystem and field) and return arrays; the
:class:`~capalloc_rs.Network` constructors call them.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from .._arrays import F64, MAX_SEED, as_count, as_float_array, as_real
from ..errors import InvalidInputError, ShapeError
from ..limits import check_limit
from .cost import BlockStructure, _frozen
from .stochastic import as_noise, noise_factor, whitened_sensor

__all__ = ["as_sensor", "block_network", "random_blocks", "square", "statespace_blocks"]


def as_sensor(name: str, x: Any) -> F64:
    """A 2-D float array; a 1-D vector becomes one column."""
    arr = as_float_array(name, x, (1, 2))
    if arr.ndim == 1:
        arr = arr.reshape(-1, 1)
    return as_float_array(name, arr, 2)


def _sequence(name: str, x: Any) -> Sequence[Any]:
    if isinstance(x, np.ndarray | str | bytes) or not isinstance(x, Sequence):
        if isinstance(x, np.ndarray) and x.ndim >= 1:
            return list(x)
        raise InvalidInputError(
            f"{name} must be a list (one entry per subsystem), got {type(x).__name__}"
        )
    return x


def square(name: str, x: Any) -> F64:
    arr = as_float_array(name, x, 2)
    if arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise ShapeError(f"{name} must be square and non-empty, got shape {arr.shape}")
    return arr


def general_network(a: Any, g: Any, sensors: Any) -> tuple[F64, F64, list[F64]]:
    """``(A, G, [ĉ_1 … ĉ_N])`` of the general form :class:`Network(a, g, sensors)
    <capalloc_rs.Network>` checked: shapes, finiteness, sizes within the limits."""
    a_arr = square("A", a)
    n = a_arr.shape[0]
    check_limit("the state dimension n", n, "MAX_STATE_DIMENSION")
    g_arr = as_noise("G", g, n)
    if isinstance(sensors, np.ndarray) or not isinstance(sensors, Sequence):
        raise InvalidInputError(
            "sensors must be a list of n×p_i arrays (one per sensor); for one column per "
            "sensor from a matrix C (n×N) pass list(C.T)"
        )
    if len(sensors) == 0:
        raise ShapeError("the network needs at least one sensor")
    check_limit("the number of sensors", len(sensors), "MAX_SENSORS")
    cs = []
    for i, c in enumerate(sensors):
        arr = as_sensor(f"sensors[{i}]", c)
        if arr.shape[0] != n or arr.shape[1] == 0:
            raise ShapeError(f"sensors[{i}] must be {n}×p_i with p_i ≥ 1, got {arr.shape}")
        cs.append(arr)
    return a_arr, g_arr, cs


def _pair(key: Any) -> tuple[Any, Any]:
    try:
        i, j = key
    except (TypeError, ValueError):
        raise InvalidInputError(f"couplings: keys must be pairs (i, j), got {key!r}") from None
    return i, j


def _offsets(sizes: Sequence[int]) -> F64:
    return np.concatenate([[0], np.cumsum(sizes)]).astype(int)


def _full_coupling(couplings: Any, sizes: Sequence[int]) -> F64:
    """An ``n × n`` coupling array, checked: zero diagonal blocks."""
    off = _offsets(sizes)
    n = int(off[-1])
    full = as_float_array("couplings", couplings, 2)
    if full.shape != (n, n):
        raise ShapeError(f"couplings as a matrix must be {n}×{n}, got {full.shape}")
    for i in range(len(sizes)):
        if np.any(full[off[i] : off[i + 1], off[i] : off[i + 1]] != 0):
            raise InvalidInputError(
                f"couplings: the diagonal block of subsystem {i} must be zero (put it in A_blocks)"
            )
    return full


def _coupling_items(couplings: Any) -> Iterable[Any]:
    """The ``(i, j, A_ij)`` items of a mapping or an iterable of triples."""
    if isinstance(couplings, Mapping):
        return ((*_pair(k), v) for k, v in couplings.items())
    if isinstance(couplings, Iterable) and not isinstance(couplings, str | bytes):
        return couplings
    raise InvalidInputError(
        "couplings must be a mapping {(i, j): A_ij}, an iterable of (i, j, A_ij) or an n×n "
        f"array, got {type(couplings).__name__}"
    )


def _pair_indices(item: Any, nn: int) -> tuple[int, int, Any]:
    """``(i, j, A_ij)`` of one coupling item, the indices checked (integers, in range, i ≠ j)."""
    try:
        i_raw, j_raw, block = item
    except (TypeError, ValueError):
        raise InvalidInputError(
            "couplings must be a mapping {(i, j): A_ij}, an iterable of (i, j, A_ij) or an "
            f"n×n array; got an item {item!r}"
        ) from None
    if isinstance(i_raw, bool | np.bool_) or isinstance(j_raw, bool | np.bool_):
        raise InvalidInputError(f"couplings: indices must be integers, got ({i_raw}, {j_raw})")
    try:
        i, j = int(i_raw), int(j_raw)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"couplings: indices must be integers, got ({i_raw!r}, {j_raw!r})"
        ) from None
    if i != i_raw or j != j_raw:
        raise InvalidInputError(f"couplings: indices must be integers, got ({i_raw}, {j_raw})")
    if not (0 <= i < nn and 0 <= j < nn):
        raise InvalidInputError(
            f"couplings: pair ({i}, {j}) is out of range for {nn} subsystems (indices from 0)"
        )
    if i == j:
        raise InvalidInputError(
            f"couplings: pair ({i}, {i}) couples a subsystem to itself (put it in A_blocks)"
        )
    return i, j, block


def _assemble_couplings(couplings: Any, sizes: Sequence[int]) -> F64:
    """The unscaled ``n × n`` coupling matrix from ``None``, ``{(i, j): A_ij}``, an iterable of
    ``(i, j, A_ij)`` or a full ``n × n`` array with zero diagonal blocks."""
    off = _offsets(sizes)
    n = int(off[-1])
    if couplings is None:
        return np.zeros((n, n))
    if isinstance(couplings, np.ndarray) and couplings.ndim == 2:
        return _full_coupling(couplings, sizes)
    out = np.zeros((n, n))
    seen: set[tuple[int, int]] = set()
    for item in _coupling_items(couplings):
        i, j, block = _pair_indices(item, len(sizes))
        if (i, j) in seen:
            raise InvalidInputError(f"couplings: pair ({i}, {j}) is given twice")
        seen.add((i, j))
        name = f"couplings[({i}, {j})]"
        b = as_float_array(name, block, 2)
        if b.shape != (sizes[i], sizes[j]):
            raise ShapeError(
                f"{name} must be {sizes[i]}×{sizes[j]} (n_{i} × n_{j}), got {b.shape[0]}×"
                f"{b.shape[1]}"
            )
        out[off[i] : off[i + 1], off[j] : off[j + 1]] = b
    return out


def _is_system(obj: Any) -> bool:
    """A single python-control system (state space or transfer function), not a list of them."""
    return (hasattr(obj, "A") and hasattr(obj, "C")) or (
        hasattr(obj, "num") and hasattr(obj, "den")
    )


def _check_statespace(name: str, s: Any) -> None:
    """A continuous-time state-space system (duck-typed ``.A``, ``.C``; python-control ``dt``)."""
    if hasattr(s, "num") and hasattr(s, "den") and not hasattr(s, "A"):
        raise InvalidInputError(
            f"{name} is a transfer function ({type(s).__name__}); Network.from_statespace needs "
            "a state-space model: convert it with control.ss(tf), or build the network from "
            "matrices with Network.from_blocks"
        )
    if not (hasattr(s, "A") and hasattr(s, "C")):
        raise InvalidInputError(
            f"{name} has no .A and .C (expected a python-control StateSpace), got "
            f"{type(s).__name__}"
        )
    dt = getattr(s, "dt", 0)
    if dt is not None and dt is not False and dt != 0:
        raise InvalidInputError(
            f"{name} is a discrete-time system (dt = {dt!r}); the network model is "
            "continuous-time (dx = A x dt + G dw) and capalloc samples it itself at the period τ "
            "(best_schedule, sampled_cost): give the continuous-time system (dt = 0)"
        )


def _subsystem(i: int, a: Any, g: Any, c: Any) -> tuple[F64, F64, F64]:
    """``(A_i, G_i, c_i)`` checked: square ``A_i``, ``G_i`` with ``n_i`` rows and at least one
    column (``Q_i = G_iG_iᵀ`` may be singular; a vector is one column), ``c_i`` with ``n_i`` rows
    (a vector is one column)."""
    ai = square(f"subsystem {i}: A_{i}", a)
    ni = ai.shape[0]
    gi = as_noise(f"subsystem {i}: G_{i}", g, ni)
    ci = as_sensor(f"subsystem {i}: c_{i}", c)
    if ci.shape[0] != ni or ci.shape[1] == 0:
        raise ShapeError(
            f"subsystem {i}: c_{i} must be {ni}×p_{i} with p_{i} ≥ 1 (or a vector of "
            f"length {ni}), got {ci.shape}"
        )
    return ai, gi, ci


def block_network(
    a_blocks: Any, g_blocks: Any, c_blocks: Any, couplings: Any, eps: Any
) -> tuple[F64, F64, list[F64], BlockStructure]:
    """``(A, G, [ĉ_1 … ĉ_N], structure)`` of the block network (arguments as in
    :meth:`Network.from_blocks <capalloc_rs.Network.from_blocks>`).

    Raises:
        ShapeError, NonFiniteError, InvalidInputError: malformed blocks (the message names the
            subsystem), bad couplings.
    """
    a_blocks = _sequence("a_blocks", a_blocks)
    g_blocks = _sequence("g_blocks", g_blocks)
    c_blocks = _sequence("c_blocks", c_blocks)
    nn = len(a_blocks)
    if nn == 0:
        raise ShapeError("the network needs at least one subsystem")
    if len(g_blocks) != nn or len(c_blocks) != nn:
        raise ShapeError(
            f"a_blocks, g_blocks and c_blocks must have the same length, got "
            f"{nn}, {len(g_blocks)}, {len(c_blocks)}"
        )
    blocks = [_subsystem(i, a_blocks[i], g_blocks[i], c_blocks[i]) for i in range(nn)]
    e = as_real("eps", eps)
    sizes = [ai.shape[0] for ai, _, _ in blocks]
    coupling = _assemble_couplings(couplings, sizes)
    off = _offsets(sizes)
    n = int(off[-1])
    a = e * coupling
    g_off = _offsets([gi.shape[1] for _, gi, _ in blocks])
    g = np.zeros((n, int(g_off[-1])))
    sensors = []
    for i, (ai, gi, ci) in enumerate(blocks):
        sl = slice(off[i], off[i + 1])
        a[sl, sl] = ai
        g[sl, int(g_off[i]) : int(g_off[i + 1])] = gi
        c = np.zeros((n, ci.shape[1]))
        c[sl] = ci
        sensors.append(c)
    structure = BlockStructure(
        tuple(_frozen(x) for x, _, _ in blocks),
        tuple(_frozen(x) for _, x, _ in blocks),
        tuple(_frozen(x) for _, _, x in blocks),
        _frozen(coupling),
        e,
    )
    return a, g, sensors, structure


def statespace_blocks(
    systems: Any, g_blocks: Any, w: Any = None, r: Any = None
) -> tuple[list[F64], Any, list[F64]]:
    """``(A_i)``, ``(G_i)`` and ``(c_i)`` from python-control state-space systems (see
    :meth:`Network.from_statespace <capalloc_rs.Network.from_statespace>`): ``G_i`` given, or
    ``B_i W_i^{1/2}`` from the intensity ``w``; ``c_i = C_iᵀ``, or ``C_iᵀ R_i^{-1/2}`` with ``r``.

    Raises:
        InvalidInputError: not a state-space system, a transfer function, or discrete-time; both
            or neither of ``g_blocks`` and ``w``; a bad ``w`` or ``r`` (named with its index).
    """
    if _is_system(systems):
        systems = [systems]
    if isinstance(systems, str | bytes) or not hasattr(systems, "__iter__"):
        raise InvalidInputError(
            f"systems must be a python-control StateSpace or a list of them, got "
            f"{type(systems).__name__}"
        )
    systems = list(systems)
    for i, s in enumerate(systems):
        _check_statespace(f"systems[{i}]", s)
    a_blocks = [np.asarray(s.A, dtype=np.float64) for s in systems]
    if (g_blocks is None) == (w is None):
        raise InvalidInputError(
            "give the process noise either as g_blocks (G_i) or as w (the intensity W_i of the "
            "noise entering through each system's B), not both or neither"
        )
    if w is not None:
        ws = _per_system("w", w, len(systems))
        g_blocks = [
            noise_factor(f"systems[{i}].B", f"w[{i}]", getattr(s, "B", None), wi, a.shape[0])
            for i, (s, wi, a) in enumerate(zip(systems, ws, a_blocks, strict=True))
        ]
    if r is None:  # unit sample noise: c_i = C_iᵀ exactly
        c_blocks = [np.asarray(s.C, dtype=np.float64).T for s in systems]
    else:
        rs = _per_system("r", r, len(systems))
        c_blocks = [
            whitened_sensor(f"systems[{i}].C", f"r[{i}]", s.C, ri, a.shape[0])
            for i, (s, ri, a) in enumerate(zip(systems, rs, a_blocks, strict=True))
        ]
    if isinstance(g_blocks, np.ndarray) and g_blocks.ndim == 2 and len(a_blocks) == 1:
        g_blocks = [g_blocks]
    return a_blocks, g_blocks, c_blocks


def _per_system(name: str, x: Any, count: int) -> list[Any]:
    """One value per system: a scalar for all, or a list of ``count`` (scalars or matrices)."""
    if isinstance(x, numbers.Number) or (isinstance(x, np.ndarray) and x.ndim == 0):
        return [x] * count
    if count == 1 and isinstance(x, np.ndarray) and x.ndim == 2:
        return [x]
    if isinstance(x, str | bytes) or not isinstance(x, Sequence) or len(x) != count:
        raise InvalidInputError(
            f"{name} must be a scalar or a list with one entry per system ({count})"
        )
    return list(x)


def _per(name: str, v: int | Sequence[int], nn: int) -> list[int]:
    """One positive count per subsystem from a count or a sequence of ``nn`` counts."""
    if isinstance(v, Sequence) and not isinstance(v, str | bytes):
        vals = [as_count(f"{name}[{k}]", x, minimum=1) for k, x in enumerate(v)]
    else:
        vals = [as_count(name, v, minimum=1)] * nn
    if len(vals) != nn:
        raise InvalidInputError(
            f"{name} must be a positive integer or {nn} positive integers, got {len(vals)}"
        )
    return vals


def _random_subsystem(rng: np.random.Generator, ni: int, pi: int) -> tuple[F64, F64, F64]:
    """``(A_i, G_i, c_i)``: ``A_i = U F Uᵀ``, ``c_i = U [e_1, ξ]`` with ``F`` the observer
    companion matrix of a random spectrum, ``G_i`` lower triangular."""
    eig: list[complex] = []
    while len(eig) < ni:
        if ni - len(eig) >= 2 and rng.random() < 0.5:
            re, im = rng.uniform(-1.5, 0.5), rng.uniform(0.2, 2.0)
            eig += [complex(re, im), complex(re, -im)]
        else:
            eig.append(complex(rng.uniform(-1.5, 0.5), 0.0))
    coeffs = np.real(np.poly(np.array(eig)))  # [1, a_1, …, a_n]
    f = np.zeros((ni, ni))
    f[:, 0] = -coeffs[1:]
    f[: ni - 1, 1:] = np.eye(ni - 1)
    u, _ = np.linalg.qr(rng.standard_normal((ni, ni)))
    c = np.zeros((ni, pi))
    c[0, 0] = 1.0
    c[:, 1:] = rng.standard_normal((ni, pi - 1))
    g = np.tril(0.3 * rng.standard_normal((ni, ni)), -1) + np.diag(rng.uniform(0.5, 1.5, ni))
    return u @ f @ u.T, g, u @ c


def random_blocks(
    num_subsystems: Any, n: Any, p: Any, eps: Any, seed: Any, r_min: Any
) -> tuple[list[F64], list[F64], list[F64], F64, float, float]:
    """``(A_i), (G_i), (c_i)``, the coupling matrix, ``ε`` and ``r_min`` of
    :meth:`Network.random <capalloc_rs.Network.random>` (arguments checked there)."""
    nn = as_count("num_subsystems", num_subsystems, minimum=1)
    check_limit("num_subsystems (one sensor each)", nn, "MAX_SENSORS")
    if isinstance(n, int | np.integer):
        # Checked before the per-subsystem lists and spectra are built.
        check_limit("the state dimension num_subsystems·n", nn * int(n), "MAX_STATE_DIMENSION")
    sizes, outs = _per("n", n, nn), _per("p", p, nn)
    check_limit("the state dimension n = Σ n_i", sum(sizes), "MAX_STATE_DIMENSION")
    e = as_real("eps", eps)
    rm = as_real("r_min", r_min, positive=True)
    if seed is not None:
        seed = as_count("seed", seed, maximum=MAX_SEED)
    rng = np.random.default_rng(seed)
    a_blocks, g_blocks, c_blocks = [], [], []
    for ni, pi in zip(sizes, outs, strict=True):
        a, g, c = _random_subsystem(rng, ni, pi)
        a_blocks.append(a)
        g_blocks.append(g)
        c_blocks.append(c)
    ntot = sum(sizes)
    coupling = rng.standard_normal((ntot, ntot)) / np.sqrt(ntot)
    off = _offsets(sizes)
    for i in range(nn):
        coupling[off[i] : off[i + 1], off[i] : off[i + 1]] = 0.0
    return a_blocks, g_blocks, c_blocks, coupling, e, rm
