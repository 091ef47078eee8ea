"""Child process of ``test_edges.py``: runs one group of public entry points on subnormal, tiny
and huge data and prints one JSON object ``{case: outcome}`` on its last line.

An outcome is ``"ok"`` (a result that passed its independent check), ``"error:<Class>: <msg>"``
(a package exception, which the contract allows), ``"foreign:<Class>: <msg>"`` (any other
exception — a contract violation) or ``"wrong: <detail>"`` (a result that failed its check). It
runs in a child so that the parent can kill it if a regression makes a call hang.

Every check uses an independent route: an exact scaling law (``H`` of Van Loan and the Lyapunov
and Sylvester solutions are linear in ``Q``; the network's ``η`` satisfies
``η(A, cG, ĉ/c) = c² η(A, G, ĉ)`` exactly, as do the sampled cost and the Monte Carlo MSE), a
closed form, or the residual of the equation solved.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

import capalloc_rs
from capalloc_rs import errors, linalg

SUBNORMAL_MIN = 5e-324
#: Scales of the data: subnormal, tiny, and huge.
SCALES = (5e-324, 1e-310, 1e-300, 1e300)

A = np.array([[-1.0, 0.3], [0.2, -2.0]])
B = np.array([[1.0], [0.5]])
Q0 = np.array([[1.0, 0.2], [0.2, 0.5]])
SENSORS = [np.array([1.0, 0.0]), np.array([0.0, 1.0])]


def close(x: Any, ref: Any, rel: float) -> bool:
    """``|x − ref| ≤ rel·|ref| + 4·(smallest subnormal)`` entrywise, all finite."""
    x, ref = np.asarray(x, dtype=float), np.asarray(ref, dtype=float)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(ref))):
        return False
    return bool(np.all(np.abs(x - ref) <= rel * np.max(np.abs(ref)) + 4 * SUBNORMAL_MIN))


def outcome(check: Callable[[], bool | str]) -> str:
    try:
        res = check()
    except errors.CapallocError as e:
        return f"error:{type(e).__name__}: {e}"
    except Exception as e:  # noqa: BLE001 - the point is to report any foreign exception
        return f"foreign:{type(e).__name__}: {e}"
    if res is True:
        return "ok"
    return f"wrong: {res}"


def group_linalg() -> dict[str, str]:
    out: dict[str, str] = {}
    _, h0 = linalg.van_loan(A, Q0, 0.7)
    x_lyap = linalg.solve_continuous_lyapunov(A, Q0)
    bs = np.array([[-3.0, 1.0], [0.0, -4.0]])
    x_sylv = linalg.solve_sylvester(A, bs, Q0)
    for q in SCALES:

        def van_loan(q: float = q) -> bool | str:
            e, h = linalg.van_loan(A, q * Q0, 0.7)
            e_ref = linalg.expm(0.7 * A)
            return (close(h, q * h0, 1e-12) and close(e, e_ref, 1e-14)) or f"H = {h.tolist()}"

        def van_loan_identity(q: float = q) -> bool | str:
            # The call: A = −I, closed form H = q (1 − e^{−1.4})/2 · I.
            _, h = linalg.van_loan(-np.eye(2), q * np.eye(2), 0.7)
            return close(h, q * -np.expm1(-1.4) / 2 * np.eye(2), 1e-14) or f"H = {h.tolist()}"

        def expm(q: float = q) -> bool | str:
            e = linalg.expm(q * A)
            if q < 1:
                # e^{qA} = I + qA + O(q²): I + qA rounded, here.
                return close(e, np.eye(2) + q * A, 1e-15) or f"e^qA = {e.tolist()}"
            # e^{−10³⁰⁰·(…)}: A is stable with real eigenvalues, so the exact answer underflows
            # to 0 (an overflow error would also be a correct refusal).
            return close(e, np.zeros((2, 2)), 0.0) or f"e^qA = {e.tolist()}"

        def lyapunov(q: float = q) -> bool | str:
            x = linalg.solve_continuous_lyapunov(A, q * Q0)
            return close(x, q * x_lyap, 1e-12) or f"X = {x.tolist()}"

        def sylvester(q: float = q) -> bool | str:
            x = linalg.solve_sylvester(A, bs, q * Q0)
            return close(x, q * x_sylv, 1e-12) or f"X = {x.tolist()}"

        def schur(q: float = q) -> bool | str:
            m = q * np.array([[1.0, 2.0, 0.5], [-3.0, 0.5, 1.0], [0.2, 0.1, -2.0]])
            t, z, sdim = linalg.schur(m, sort="lhp")
            ok = close(z.T @ z, np.eye(3), 1e-14)
            if q < 2.2250738585072014e-308:
                # Subnormal data carry a few bits only: Z T Zᵀ = M to the subnormal spacing.
                ok = ok and bool(np.max(np.abs(z @ t @ z.T - m)) <= 16 * SUBNORMAL_MIN)
                return ok or f"T = {t.tolist()}"
            # Z T Zᵀ = M, compared in units of q (the product may underflow for tiny q).
            ok = ok and close((z @ (t / q) @ z.T), m / q, 1e-12)
            ev = np.sort_complex(np.linalg.eigvals(t / q))
            ok = ok and close(ev.real, np.sort_complex(np.linalg.eigvals(m / q)).real, 1e-12)
            return (ok and sdim == 1) or f"T = {t.tolist()}, sdim = {sdim}"

        def care(q: float = q, scipy_form: bool = False) -> bool | str:
            if scipy_form:
                x = linalg.solve_continuous_are(A, B, q * Q0, np.eye(1))
            else:
                x = linalg.care(A, B, q * Q0).x
            g = B @ B.T
            r = A.T @ x + x @ A - x @ g @ x + q * Q0
            scale = q * np.linalg.norm(Q0) + 2 * np.linalg.norm(A) * np.linalg.norm(x)
            scale += np.linalg.norm(g) * np.linalg.norm(x) ** 2
            rel = np.linalg.norm(r) / scale
            stable = np.all(np.linalg.eigvals(A - g @ x).real < 0)
            psd = np.all(np.linalg.eigvalsh(x / max(np.max(np.abs(x)), 1e-300)) > -1e-12)
            return bool(rel <= 1e-12 and stable and psd) or f"X = {x.tolist()}, rel {rel:.1e}"

        for name, fn in [
            ("van_loan", van_loan),
            ("van_loan_identity", van_loan_identity),
            ("expm", expm),
            ("solve_continuous_lyapunov", lyapunov),
            ("solve_sylvester", sylvester),
            ("schur", schur),
            ("care", care),
            ("solve_continuous_are", lambda q=q: care(q, scipy_form=True)),
        ]:
            out[f"{name}@{q:g}"] = outcome(fn)
    return out


def scaled_network(c: float) -> capalloc_rs.Network:
    """``(A, c·G, ĉ_i/c)``: ``η`` scales by exactly ``c²`` (Σ → c²Σ solves the scaled CARE)."""
    g = np.linalg.cholesky(Q0)
    return capalloc_rs.Network(A, c * g, [s / c for s in SENSORS])


#: ``c`` with ``c²`` subnormal, tiny and huge (``Q = c² Q0``, ``W = W0/c²``).
C_SCALES = (1e-155, 1e-150, 1e150)


def group_network() -> dict[str, str]:
    out: dict[str, str] = {}
    base = scaled_network(1.0)
    r = np.array([2.0, 3.0])
    eta0, g0 = base.cost(r), base.gradient(r)
    alloc0 = capalloc_rs.optimal_allocation(base, 5.0)
    for c in C_SCALES:
        net = outcome(lambda c=c: bool(scaled_network(c)) or "")
        if net != "ok":
            for k in ("cost", "gradient", "optimal_allocation"):
                out[f"{k}@{c:g}"] = net
            continue
        n = scaled_network(c)
        out[f"cost@{c:g}"] = outcome(
            lambda n=n, c=c: close(n.cost(r), c * c * eta0, 1e-10) or f"η = {n.cost(r)}"
        )
        out[f"gradient@{c:g}"] = outcome(
            lambda n=n, c=c: close(n.gradient(r), c * c * g0, 1e-9) or f"∇η = {n.gradient(r)}"
        )

        def alloc(n: capalloc_rs.Network = n, c: float = c) -> bool | str:
            a = capalloc_rs.optimal_allocation(n, 5.0)
            ok = close(a.r, alloc0.r, 1e-7) and close(a.eta, c * c * alloc0.eta, 1e-9)
            return ok or f"rates {a.r}, η {a.eta}"

        out[f"optimal_allocation@{c:g}"] = outcome(alloc)
    # Tiny Q without compensating sensors (the model has G = 1e-160·I): for such Q the
    # W term is negligible and Σ is the Lyapunov solution of A Σ + Σ Aᵀ + Q = 0 to rounding.
    for gscale in (1e-150, 1e-160):
        net = capalloc_rs.Network(A, gscale * np.eye(2), SENSORS)
        sigma = linalg.solve_continuous_lyapunov(A, -np.eye(2)) * gscale * gscale
        out[f"cost_tiny_q@{gscale:g}"] = outcome(
            lambda net=net, s=sigma: close(net.cost(r), np.trace(s), 1e-6) or f"η = {net.cost(r)}"
        )
    return out


def group_sampled() -> dict[str, str]:
    out: dict[str, str] = {}
    base = scaled_network(1.0)
    sched = [0, 1, 0]
    v0 = capalloc_rs.sampled_cost(base, 0.5, sched)
    b0 = capalloc_rs.best_schedule(base, 0.5, 4)
    m0 = capalloc_rs.simulate(base, 0.5, sched, periods=20, seed=7, runs=8)
    for c in C_SCALES:
        n = outcome(lambda c=c: bool(scaled_network(c)) or "")
        if n != "ok":
            for k in ("sampled_cost", "best_schedule", "simulate"):
                out[f"{k}@{c:g}"] = n
            continue
        net = scaled_network(c)
        out[f"sampled_cost@{c:g}"] = outcome(
            lambda net=net, c=c: (
                close(capalloc_rs.sampled_cost(net, 0.5, sched), c * c * v0, 1e-9) or "value"
            )
        )

        def best(net: capalloc_rs.Network = net, c: float = c) -> bool | str:
            b = capalloc_rs.best_schedule(net, 0.5, 4)
            ok = b.schedule == b0.schedule and close(b.eta_bar, c * c * b0.eta_bar, 1e-9)
            return ok or f"{b.schedule} η̄ = {b.eta_bar}"

        def sim(net: capalloc_rs.Network = net, c: float = c) -> bool | str:
            m = capalloc_rs.simulate(net, 0.5, sched, periods=20, seed=7, runs=8)
            return close(m.mse, c * c * m0.mse, 1e-8) or f"mse {m.mse}"

        out[f"best_schedule@{c:g}"] = outcome(best)
        out[f"simulate@{c:g}"] = outcome(sim)
    # The model: G = 1e-160·I (Q = 1e-320·I, subnormal). η̄ is a subnormal number; the
    # contract is an answer in [0, ‖Q‖-scale] or a package error, fast.
    net = capalloc_rs.Network(A, 1e-160 * np.eye(2), SENSORS)
    tiny = 1e-318
    out["issue_sampled_cost"] = outcome(
        lambda: 0 <= capalloc_rs.sampled_cost(net, 0.5, [0, 1]) <= tiny or "value"
    )
    out["issue_best_schedule"] = outcome(
        lambda: 0 <= capalloc_rs.best_schedule(net, 0.5, 2).eta_bar <= tiny or "value"
    )
    out["issue_simulate"] = outcome(
        lambda: (
            0 <= capalloc_rs.simulate(net, 0.5, [0, 1], periods=5, seed=1).mse <= tiny or "value"
        )
    )
    return out


GROUPS = {"linalg": group_linalg, "network": group_network, "sampled": group_sampled}

if __name__ == "__main__":
    print(json.dumps(GROUPS[sys.argv[1]]()))
