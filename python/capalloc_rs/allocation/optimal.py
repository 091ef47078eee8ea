"""Optimal capacity allocation on the simplex (the paper's Theorem 1) and its integer version.

Problem (fast-sampling limit). With rates ``r = r_min + γ`` the cost is ``η(r) = tr Σ(r)``; the
optimal allocation solves

    minimise η(r_min + γ)   subject to   γ ≥ 0,  Σ γ_i = σ = r_tot − N·r_min.

Theorem 1 (KKT): γ* is optimal iff there is ``μ ≤ 0`` with ``∂η/∂γ_i = μ`` where ``γ_i > 0`` and
``∂η/∂γ_j ≥ μ`` where ``γ_j = 0``. Because η is convex, the Frank–Wolfe gap

    gap(γ) = Σ_i γ_i (g_i − min_j g_j) = max_{γ' ∈ simplex} ∇η(γ)ᵀ(γ − γ')  ≥  η(γ) − η*

is a certificate that needs no threshold: every method here stops on it.

Costs and limits. For a network with sample costs ``b_i``, per-sensor minima or caps
(``not net.is_paper_form``) the second argument is the budget ``B = Σ b_i r_i`` in channel units
and the problem ``min η(r)`` over ``{r_min,i ≤ r_i ≤ r_max,i, Σ b_i r_i = B}`` is solved in
channel units ``s = b ∘ r`` on the weighted box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` (γ = s − b∘r_min,
c = b∘(r_max − r_min), σ = B − Σ b_i r_min,i) by :mod:`.budgeted`. KKT per channel unit:
``g_i = μ`` on the free set, ``g_i ≥ μ`` at a minimum, ``g_i ≤ μ`` at a cap (in rates
``∂η/∂r_i = μ b_i``); the certificate is the Frank–Wolfe gap on the box-simplex (its linear
minimiser a fractional knapsack, :mod:`.box_simplex`), again a proven bound on ``η(r) − η*``.
Networks in the paper's form take the code below unchanged.

Start. Newton starts by default (``start="auto"``) from the *decoupled* optimum when the network
is a block network with one subsystem per sensor (:mod:`.decoupled`: the optimum at ε = 0, a
separable problem solved in Rust with ``N`` small Riccati solves per step; ``O(ε)`` from the
coupled optimum, and the optimum itself at ε = 0), else — and with ``start="uniform"``, today's
algorithm before the decoupled start existed — from the uniform point ``γ = σ/N``. Every iterate,
the first included, is certified the same way. After the decoupled start Newton's steps are
short, and each evaluation point is warm-started from the previous one (Newton–Kleinman from its
``Σ``, :meth:`capalloc_rs.network.CostPoint.warm`, certified as a cold solve is) from state order
:data:`DECOUPLED_WARM_MIN_ORDER` on; ``warm=`` overrides it.

Methods (all reach the same optimum):

* ``"newton"`` — Newton's method on the simplex, in one of two variants (``hessian=``):

  - ``"exact"``: sequential quadratic programming with the exact Hessian (``N`` Lyapunov solves
    per step): each step solves the quadratic model ``gᵀd + ½ dᵀ∇²η d`` over the simplex exactly
    (primal active-set QP, finite), then an Armijo line search on η. Once the active set is
    identified this is Newton's method on the face: quadratic convergence.
  - ``"hvp"``: Newton–CG, which never forms the Hessian. At γ with gradient g and the multiplier
    estimate ``μ = γᵀg/σ``, the free set is ``F = {i : γ_i > 0} ∪ {j : γ_j = 0, g_j < μ}``. The
    face-restricted Newton system ``min gᵀd + ½ dᵀ∇²η d`` over ``{d_F ⊥ 1, d_j = 0 off F}`` is
    solved by projected preconditioned conjugate gradients: the residual is projected on the null
    space of ``1ᵀ`` in the preconditioner's metric, ``z = D⁻¹r − D⁻¹1·(1ᵀD⁻¹r)/(1ᵀD⁻¹1)``
    (``D = I`` gives ``P = I − 11ᵀ/k``), with ``D`` the diagonal of the decoupled (ε = 0)
    Hessian ``η_i''(r_i)`` for block networks (one small Riccati problem per subsystem; formed
    again only when a rate moved by more than 10 % since, so once per solve after the decoupled
    start) and ``I`` otherwise. Products ``∇²η p`` come from one cached :meth:`Network.at` point
    (two triangular Lyapunov solves each, in the Schur coordinates of the closed loop). CG is
    truncated when ``‖P r‖ ≤ η_k ‖P g_F‖`` with the forcing term
    ``η_k = min(0.1, gap_k/|η|)`` (Eisenstat–Walker: η_k = O(‖g_F − μ1‖) keeps the local
    convergence quadratic, as for the exact Newton step; the √-forcing of order 1.5 saved only 2
    products of 20–35 at N = 50–100, same step counts). If a CG step would make some
    ``γ_i + d_i`` negative, it stops at the boundary, fixes ``i`` at zero and CG restarts on the
    smaller face (projected search as in TRON); on a direction of non-positive curvature the
    first iteration steps to the boundary and later ones stop. At most ``|F|`` products per
    step. Then the same Armijo search and certificate as ``"exact"``.
  - ``"auto"`` (default): ``"exact"`` below :data:`HVP_MIN_SENSORS` sensors, ``"hvp"`` from
    there on (the crossover measured with ``benches/compare_allocation.py``).
* ``"projected-gradient"`` — spectral (Barzilai–Borwein) projected gradient with Armijo backtracking
  along the projection arc; gradient only.
* ``"double-bracket"`` — the paper's Appendix D flow ``Ḣ = −σ[H, [H, diag ∇η(σ diag H)]]`` on
  ``H = vvᵀ``, ``‖v‖ = 1``; on rank-one H it is ``v̇_i = −σ (g_i − Σ_j g_j v_j²) v_i``, i.e. the
  replicator equation ``γ̇_i = −2σ γ_i (g_i − γᵀg/σ)``. Integrated with an adaptive Dormand–Prince
  5(4) pair (error control on v, v renormalised after each step) until the certificate holds.
  Inactive entries only decay exponentially, so it is slow: it is here for fidelity to the paper.

The network is any object with ``r_min``, ``sensors`` (length N) and ``cost``, ``gradient``,
``hessian`` (and ``cost_many`` for the integer allocation) methods of rates ``r`` — in practice a
:class:`capalloc_rs.Network`. Newton–CG also needs ``at(r)`` returning an evaluation point with
``value``, ``gradient`` and ``hvp`` (:class:`capalloc_rs.network.CostPoint`); when it is there,
both Newton variants take the value, gradient and Hessian (or products) from one point per step
and the line search's first trial point becomes the next step's point.
"""

from __future__ import annotations

import sys
from typing import Any, Literal, get_args

import numpy as np

from .._arrays import as_count, as_float_array, as_real, numerical_errors
from ..errors import ConvergenceError, InvalidInputError
from ..network import accepts_path
from .budgeted import budgeted_allocation, is_paper_form
from .decoupled import decoupled_covariance, decoupled_start, has_decoupled_start
from .first_order import FLOW_TOL, double_bracket, projected_gradient
from .newton import CORE_NEWTON_MAX_SENSORS, core_model, newton, newton_in_core
from .oracle import CostOracle, num_sensors
from .result import Allocation, make_allocation
from .simplex import STAGNATION_GAP, _fix_sum

__all__ = [
    "DECOUPLED_WARM_MIN_ORDER",
    "ENGINES",
    "Engine",
    "HESSIAN_MODES",
    "HVP_MIN_SENSORS",
    "METHODS",
    "HessianMode",
    "Method",
    "STARTS",
    "Start",
    "one_of",
    "optimal_allocation",
]

Method = Literal["newton", "projected-gradient", "double-bracket"]
HessianMode = Literal["auto", "exact", "hvp"]
Start = Literal["auto", "decoupled", "uniform"]
Engine = Literal["auto", "core", "python"]
#: The values of ``method``, ``hessian`` and ``start`` (for validation elsewhere: sweeps, the CLI).
METHODS: tuple[str, ...] = get_args(Method)
HESSIAN_MODES: tuple[str, ...] = get_args(HessianMode)
STARTS: tuple[str, ...] = get_args(Start)
ENGINES: tuple[str, ...] = get_args(Engine)


def one_of(choices: tuple[str, ...]) -> str:
    """``'a', 'b' or 'c'``: the choices of an argument, for error messages."""
    quoted = [repr(c) for c in choices]
    return ", ".join(quoted[:-1]) + " or " + quoted[-1]


#: ``hessian="auto"`` runs Newton–CG (``"hvp"``) from this many sensors on and the exact Hessian
#: below. Measured with ``benches/compare_allocation.py --cg`` (``Network.random(N, 2, eps=0.05)``,
#: r_tot = 3N, one BLAS thread, 2 cores), exact time / Newton–CG time over six networks per size:
#: 1.02–1.14× at N = 10–15 and 0.99–1.23× at N = 20 (a few ms either way; the exact QP is the more
#: robust there), 1.18–1.51× at N = 25, 1.37× at 30, 1.6–1.7× at 50, 2.3× at 100, 2.2–3.6× at 200.
HVP_MIN_SENSORS = 25


def _validate(net: CostOracle, r_tot: float) -> tuple[int, float, float]:
    n_sens = num_sensors(net)
    r_min = float(net.r_min)
    r_tot = as_real("r_tot", r_tot)
    sigma = float(r_tot) - n_sens * r_min
    if sigma < -1e-12 * max(1.0, abs(float(r_tot))):
        raise InvalidInputError(
            f"infeasible capacity: r_tot = {r_tot} < N·r_min = {n_sens}·{r_min} = {n_sens * r_min}"
        )
    return n_sens, r_min, max(sigma, 0.0)


def _check_choices(method: Any, hessian: Any) -> None:
    """``method`` and ``hessian`` are among the documented strings (InvalidInputError)."""
    if not isinstance(method, str) or not isinstance(hessian, str):
        raise InvalidInputError(f"method and hessian must be strings, got {method!r}, {hessian!r}")
    if method not in METHODS:
        raise InvalidInputError(f"method must be {one_of(METHODS)}, got {method!r}")
    if hessian not in HESSIAN_MODES:
        raise InvalidInputError(f"hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")


def _newton_mode(net: CostOracle, method: str, hessian: str, n_sens: int) -> str | None:
    """The Newton variant that runs (``"auto"`` resolved), ``None`` for the other methods."""
    if method != "newton":
        return None
    has_points = callable(getattr(net, "at", None))
    if hessian == "hvp" and not has_points:
        raise InvalidInputError(
            "hessian='hvp' needs a network with an at(r) evaluation point (capalloc_rs.Network)"
        )
    if hessian == "auto":
        return "hvp" if has_points and n_sens >= HVP_MIN_SENSORS else "exact"
    return hessian


#: With the decoupled start, Newton's evaluation points are warm-started from the previous point
#: (:meth:`capalloc_rs.network.CostPoint.warm`) from this state order on: its steps are short,
#: and the warm start paid at every size measured (``benches/compare_allocation.py --start``,
#: ``Network.random(N, 2, eps=0.05)``, r_tot = 3N: 1.05× at n = 6, 1.2× at n = 20, 1.4× at
#: n = 40, 1.6× at n = 100). From the uniform start the threshold stays
#: :data:`~.oracle.WARM_START_MIN_ORDER` (its long first steps make warm starts fall back).
DECOUPLED_WARM_MIN_ORDER = 4


def _warm_min_order(warm: Any, decoupled: bool) -> int | None:
    """The state order from which Newton's points are warm-started (``None``: the default of
    :class:`~.oracle.PointCache`)."""
    if warm is None:
        return DECOUPLED_WARM_MIN_ORDER if decoupled else None
    if not isinstance(warm, bool):
        raise InvalidInputError(f"warm must be True, False or None, got {warm!r}")
    return 0 if warm else sys.maxsize


def _in_core(net: CostOracle, mode: str | None, engine: Any, n_sens: int) -> bool:
    """Whether the Newton loop runs in the Rust core (``engine`` checked)."""
    if not isinstance(engine, str) or engine not in ENGINES:
        raise InvalidInputError(f"engine must be {one_of(ENGINES)}, got {engine!r}")
    available = mode == "exact" and core_model(net) is not None
    if engine == "core" and not available and mode is not None:
        raise InvalidInputError(
            "engine='core' runs Newton with the exact Hessian on a capalloc_rs.Network: "
            "use hessian='exact' (or engine='auto')"
        )
    if engine == "auto":
        return available and n_sens <= CORE_NEWTON_MAX_SENSORS
    return engine == "core" and available


def _check_start(net: CostOracle, start: Any) -> str:
    """``start`` is a documented string, and ``"decoupled"`` is possible for ``net``."""
    if not isinstance(start, str) or start not in STARTS:
        raise InvalidInputError(f"start must be {one_of(STARTS)}, got {start!r}")
    if start == "decoupled" and not has_decoupled_start(net):
        raise InvalidInputError(
            "start='decoupled' needs a block network with one subsystem per sensor "
            "(Network.structure); use start='uniform' or 'auto'"
        )
    return start


def _start(
    net: CostOracle, gamma0: Any, start: str, method: str, sigma: float, tol: float
) -> tuple[Any, bool]:
    """The starting point on the simplex and whether it is the decoupled optimum: ``gamma0``
    checked; else the decoupled optimum (``start="decoupled"``, or ``"auto"`` for Newton on a
    block network) when it exists; else uniform."""
    n_sens = num_sensors(net)
    if gamma0 is None:
        if start == "decoupled" or (start == "auto" and method == "newton"):
            g0 = decoupled_start(net, sigma, tol)
            if g0 is not None:
                return g0, True
        return np.full(n_sens, sigma / n_sens), False
    g0 = as_float_array("gamma0", gamma0, 1)
    if g0.shape != (n_sens,) or not np.all(np.isfinite(g0)) or np.any(g0 < 0):
        raise InvalidInputError(f"gamma0 must be {n_sens} finite non-negative numbers")
    if abs(float(g0.sum()) - sigma) > 1e-9 * max(sigma, 1.0):
        raise InvalidInputError(f"gamma0 must sum to sigma = {sigma}, got {g0.sum()}")
    return _fix_sum(g0.copy(), sigma), False


def _check_stagnation(res: Allocation, method: str, tol: float) -> Allocation:
    """``res``, unless its gap is above both the tolerance (at least :data:`STAGNATION_GAP`) and
    ten times the accuracy of η: a gap below the accuracy of η is not a failure to converge (the
    result says so, ``certified``)."""
    if res.gap > max(max(tol, STAGNATION_GAP) * max(abs(res.eta), 1e-300), 10.0 * res.eta_error):
        raise ConvergenceError(
            f"{method} stagnated with Frank–Wolfe gap {res.gap:.3e} (η = {res.eta:.6e}); "
            "the cost is too flat or too noisy to certify the optimum"
        )
    return res


def _budgeted(
    net: CostOracle,
    budget: float,
    method: Any,
    tol: Any,
    max_iter: Any,
    gamma0: Any,
    hessian: Any,
    start: Any,
    warm: Any,
    engine: Any,
) -> Allocation:
    """:func:`optimal_allocation` for a network with costs or limits (:mod:`.budgeted`): the same
    validation of the keywords, then the box-simplex solvers."""
    tol = as_real("tol", tol, positive=True)
    if max_iter is not None:
        max_iter = as_count("max_iter", max_iter, minimum=1)
    _check_choices(method, hessian)
    if not isinstance(start, str) or start not in STARTS:
        raise InvalidInputError(f"start must be {one_of(STARTS)}, got {start!r}")
    if not isinstance(engine, str) or engine not in ENGINES:
        raise InvalidInputError(f"engine must be {one_of(ENGINES)}, got {engine!r}")
    warm_order = _warm_min_order(warm, False)
    mode = _newton_mode(net, method, hessian, num_sensors(net))
    res = budgeted_allocation(
        net,
        budget,
        method=method,
        tol=tol,
        max_iter=max_iter,
        gamma0=gamma0,
        mode=mode,
        start=start,
        warm_order=warm_order,
        engine=engine,
    )
    return _check_stagnation(res, method, tol)


@accepts_path
@numerical_errors
def optimal_allocation(
    net: CostOracle,
    r_tot: float,
    *,
    method: Method = "newton",
    tol: float = 1e-12,
    max_iter: int | None = None,
    gamma0: Any = None,
    hessian: HessianMode = "auto",
    start: Start = "auto",
    warm: bool | None = None,
    engine: Engine = "auto",
) -> Allocation:
    """The optimal allocation ``argmin η(r_min + γ)`` over the simplex of height
    ``σ = r_tot − N·r_min``, with its KKT certificate (Theorem 1).

    For a network with sample costs, per-sensor minima or caps (``not net.is_paper_form``) the
    problem is ``min η(r)`` over ``{r_min,i ≤ r_i ≤ r_max,i, Σ b_i r_i = B}``, solved in channel
    units on the weighted box-simplex (:mod:`capalloc_rs.allocation.budgeted`); the result's
    μ, multipliers and certificate are then per channel unit.

    Args:
        net: the network (see :class:`~capalloc_rs.allocation.CostOracle`).
        r_tot: total capacity (slots per unit time in the fast-sampling limit). For a network
            with costs or limits: the budget ``B`` in channel units (``Σ b_i r_i``; the total
            capacity r_tot when every sample costs 1), within ``net.budget_range``.
        method: ``"newton"`` (default), ``"projected-gradient"`` or ``"double-bracket"``.
        tol: stop when the Frank–Wolfe gap ≤ ``tol·η`` (for the flow at least 1e-9·η). A method
            that stalls in floating point first returns its point if the gap is ≤ 1e-8·η (the
            result's ``gap`` says exactly how close it is) and raises otherwise.
        max_iter: iteration bound (defaults: 200 Newton steps, 50 000 gradient steps, 200 000 ODE
            steps); exceeding it raises :class:`~capalloc_rs.errors.ConvergenceError`.
        gamma0: optional starting point on the simplex (warm start); when given, ``start`` is
            not used. With costs or limits: channel units above the minima,
            ``0 ≤ γ_i ≤ b_i (r_max,i − r_min,i)`` summing to ``B − Σ b_i r_min,i``.
        start: where to start without ``gamma0``: ``"decoupled"`` (the optimum of the network
            at ε = 0, see :mod:`capalloc_rs.allocation.decoupled`; needs a block network with
            one subsystem per sensor), ``"uniform"`` (``γ = σ/N``; the only start before the
            decoupled one existed) or ``"auto"`` (default: ``"decoupled"`` for
            ``method="newton"`` on such a network, else ``"uniform"``; also uniform when a
            subsystem alone has no stabilising Riccati solution). With costs or limits the
            decoupled start needs, in channel units, one common minimum and no caps (else
            ``"decoupled"`` is refused and ``"auto"`` projects the decoupled optimum with the
            smallest minimum onto the box-simplex), and the uniform start is the Euclidean
            projection of ``γ = σ/N`` onto the box-simplex (:mod:`.budgeted`).
        warm: whether Newton's evaluation points are warm-started from the previous point
            (Newton–Kleinman, :meth:`capalloc_rs.network.CostPoint.warm`; the same numbers to
            rounding, with the cold solve as the fallback): ``True`` always, ``False`` never,
            ``None`` (default) from state order :data:`DECOUPLED_WARM_MIN_ORDER` on after the
            decoupled start and from :data:`~capalloc_rs.allocation.oracle.WARM_START_MIN_ORDER`
            on otherwise. ``start="uniform", warm=None`` is the algorithm before the decoupled
            start existed. Ignored by the other methods.
        engine: where the exact-Hessian Newton loop runs: ``"core"`` (in Rust, one call for
            the whole loop: the same steps, QP, line search and stopping rules as the Python
            loop, to rounding), ``"python"`` (one Rust call per evaluation; the loop before the
            core one existed) or ``"auto"`` (default: the core up to
            :data:`~capalloc_rs.allocation.newton.CORE_NEWTON_MAX_SENSORS` sensors on a
            :class:`~capalloc_rs.Network`). Newton–CG and the other methods run in Python.
            ``start="uniform", engine="python"`` is the algorithm before this release. With
            costs or limits the loop runs in Python (``"core"`` raises
            :class:`~capalloc_rs.errors.FeatureUnavailableError`).
        hessian: the Newton variant: ``"exact"`` (SQP with the ``N × N`` Hessian), ``"hvp"``
            (Newton–CG with Hessian-vector products, needs ``net.at``) or ``"auto"`` (``"hvp"``
            from :data:`HVP_MIN_SENSORS` sensors on when ``net.at`` exists, else ``"exact"``).
            Ignored by the other methods. The result's ``hessian`` field says which ran.

    Raises:
        InvalidInputError: infeasible capacity (``r_tot < N·r_min``; with costs or limits a
            budget outside ``net.budget_range``), bad method, ``start``, ``warm``, ``engine`` or
            ``gamma0``.
        FeatureUnavailableError: ``method="double-bracket"`` or ``engine="core"`` on a network
            with costs or limits.
        ConvergenceError: the certificate was not reached within the bound.
    """
    if not is_paper_form(net):
        return _budgeted(net, r_tot, method, tol, max_iter, gamma0, hessian, start, warm, engine)
    n_sens, r_min, sigma = _validate(net, r_tot)
    r_tot = as_real("r_tot", r_tot)
    tol = as_real("tol", tol, positive=True)
    if max_iter is not None:
        max_iter = as_count("max_iter", max_iter, minimum=1)
    _check_choices(method, hessian)
    start_at = _check_start(net, start)
    _warm_min_order(warm, False)  # validates ``warm`` whatever path follows
    mode = _newton_mode(net, method, hessian, n_sens)
    in_core = _in_core(net, mode, engine, n_sens)
    active_tol = 1e-9 * sigma if method == "double-bracket" else 0.0
    if sigma == 0.0 or n_sens == 1:
        gamma = np.full(n_sens, sigma / n_sens) if n_sens == 1 else np.zeros(n_sens)
        return make_allocation(net, gamma, sigma, r_tot, 0, method, active_tol, hessian=mode)
    g0, decoupled = _start(net, gamma0, start_at, method, sigma, tol)
    warm_order = _warm_min_order(warm, decoupled)
    hvps, value_grad, eta_error = 0, None, None
    if in_core:
        gamma, its, value_grad, eta_error = newton_in_core(
            net, r_min, sigma, tol, max_iter or 200, g0, warm_order
        )
    elif mode is not None:
        # After the decoupled start, the first point of a Network is reached from the decoupled
        # Σ too (``Network.at(r, start=...)``; other oracles' ``at`` takes only the rates).
        seeded = decoupled and warm is not False and core_model(net) is not None
        s0 = decoupled_covariance(net, g0 + r_min) if seeded else None
        gamma, its, pts = newton(
            net, n_sens, r_min, sigma, tol, max_iter or 200, g0, mode, warm_order, s0
        )
        # The last point is usually cached already: no further Riccati solve for the result.
        hvps, value_grad = pts.hvps, pts.value_gradient(gamma + r_min)
        eta_error = pts.value_error(gamma + r_min)
    elif method == "projected-gradient":
        gamma, its = projected_gradient(net, r_min, sigma, tol, max_iter or 50_000, g0)
    else:
        gamma, its = double_bracket(
            net, n_sens, r_min, sigma, max(tol, FLOW_TOL), max_iter or 200_000, g0
        )
    res = make_allocation(
        net,
        gamma,
        sigma,
        r_tot,
        its,
        method,
        active_tol,
        hessian=mode,
        hvp_count=hvps,
        value_grad=value_grad,
        eta_error=eta_error,
    )
    return _check_stagnation(res, method, tol)
