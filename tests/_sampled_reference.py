"""An independent reference for the sampled system with sample costs and an error weight: Van
Loan's discretisation by ``scipy.linalg.expm`` of the block matrix, the slot maps
``φ_i(S) = ((E_i S E_iᵀ + H_i)⁻¹ + c̄_i c̄_iᵀ)⁻¹`` in information form, the idle tail, and the
plain fixed-point iteration of the period map — none of the package's code."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla


def van_loan(a: np.ndarray, q: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``E = e^{At}``, ``H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`` from ``expm([[−A, Q], [0, Aᵀ]] t)``."""
    n = a.shape[0]
    f = sla.expm(np.block([[-a, q], [np.zeros((n, n)), a.T]]) * t)
    e = f[n:, n:].T
    h = e @ f[:n, n:]
    return e, (h + h.T) / 2


def slot_map(s: np.ndarray, e: np.ndarray, h: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``((E S Eᵀ + H)⁻¹ + c cᵀ)⁻¹``."""
    p = e @ s @ e.T + h
    out = np.linalg.inv(np.linalg.inv(p) + c @ c.T)
    return (out + out.T) / 2


def fixed_point(
    a: np.ndarray,
    q: np.ndarray,
    sensors: list[np.ndarray],
    costs: list[float],
    tau: float,
    slots: list[int],
    budget: float,
    weight: np.ndarray | None = None,
    periods: int = 20000,
) -> tuple[float, float]:
    """``(η̄_boundary, η̄_average)`` by iterating the period map from ``Σ = I`` until it settles
    (``tr(M ·)`` with a weight)."""
    n = a.shape[0]
    t0 = tau / budget
    steps = {b: van_loan(a, q, b * t0) for b in set(costs)}
    idle = budget - sum(costs[i] for i in slots)
    tail = van_loan(a, q, idle * t0) if idle > 1e-12 * budget else None
    m = np.eye(n) if weight is None else weight
    s = np.eye(n)
    posts: list[np.ndarray] = []
    for _ in range(periods):
        prev = s
        posts = []
        for i in slots:
            e, h = steps[costs[i]]
            s = slot_map(s, e, h, sensors[i] * np.sqrt(tau))
            posts.append(s)
        if tail is not None:
            s = tail[0] @ s @ tail[0].T + tail[1]
        if np.linalg.norm(s - prev) <= 1e-15 * np.linalg.norm(s):
            break
    boundary = float(np.sum(m * s))
    average = float(np.mean([np.sum(m * p) for p in posts]))
    return boundary, average
