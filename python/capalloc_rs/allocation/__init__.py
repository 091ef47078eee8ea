"""Optimal capacity allocation (the paper's Theorem 1), integer slot counts and the optimal
allocation map with its filtration (Theorem 2).

Modules: :mod:`~capalloc_rs.allocation.optimal` (:func:`optimal_allocation`: validation and
dispatch, with the description of the methods), :mod:`~capalloc_rs.allocation.newton` (Newton with
the exact Hessian and Newton–CG, Armijo line search), :mod:`~capalloc_rs.allocation.decoupled`
(Newton's start: the optimum of the decoupled network), :mod:`~capalloc_rs.allocation.first_order`
(projected gradient, the double-bracket flow), :mod:`~capalloc_rs.allocation.simplex` (projection,
the simplex QP, the certificate), :mod:`~capalloc_rs.allocation.budgeted` (networks with sample
costs, per-sensor minima or caps: the weighted box-simplex in channel units, with
:mod:`~capalloc_rs.allocation.box_simplex` its geometry and certificate and
:mod:`~capalloc_rs.allocation.box_newton` its Newton and projected-gradient solvers),
:mod:`~capalloc_rs.allocation.integer_budget` and :mod:`~capalloc_rs.allocation.knapsack`
(integer counts under a budget), :mod:`~capalloc_rs.allocation.oracle` (what the methods need from
a network), :mod:`~capalloc_rs.allocation.result` (:class:`Allocation`,
:class:`IntegerAllocation`), :mod:`~capalloc_rs.allocation.integer` (:func:`integer_allocation`),
:mod:`~capalloc_rs.allocation.integer_relaxation` (a box's convex relaxation, its certified lower
bound and rounding) and :mod:`~capalloc_rs.allocation.branch_and_bound` (the exact integer
counts), for a set of models :mod:`~capalloc_rs.allocation.robust` (:func:`robust_allocation`:
the mean or worst-case optimum with a certificate; its solvers
:mod:`~capalloc_rs.allocation.robust_solvers` and :mod:`~capalloc_rs.allocation.minimax_qp`,
the models :mod:`~capalloc_rs.allocation.model_set`, integer counts
:mod:`~capalloc_rs.allocation.robust_integer`, results
:mod:`~capalloc_rs.allocation.robust_result`),
and for the path :mod:`~capalloc_rs.allocation.filtration` (:func:`filtration`: validation and
the choice of tracer), :mod:`~capalloc_rs.allocation.continuation` (the default path following:
Hermite predictors, events by Newton), :mod:`~capalloc_rs.allocation.kkt_newton` (Newton on the KKT
system closed by σ or by an event), :mod:`~capalloc_rs.allocation.face_hessian` (``η''_JJ`` exact
or through Hessian-vector products), :mod:`~capalloc_rs.allocation.corrector` (the reference
tracer's predictor–corrector), :mod:`~capalloc_rs.allocation.filtration_path` (the record of a
path), :mod:`~capalloc_rs.allocation.filtration_result` (:class:`Filtration`) and
:mod:`~capalloc_rs.allocation.filtration_plot` (drawing).
"""

from __future__ import annotations

from .decoupled import decoupled_start
from .filtration import filtration
from .filtration_result import Filtration, FiltrationEvent
from .first_order import FLOW_TOL
from .integer import integer_allocation
from .model_set import coupling_models
from .newton import NOISE_DECREASE
from .optimal import (
    ENGINES,
    HESSIAN_MODES,
    HVP_MIN_SENSORS,
    METHODS,
    STARTS,
    Engine,
    HessianMode,
    Method,
    Start,
    one_of,
    optimal_allocation,
)
from .oracle import CostOracle, CostPointOracle, value_gradient, value_gradient_hessian
from .result import Allocation, IntegerAllocation
from .robust import OBJECTIVES, Objective, robust_allocation
from .robust_integer import robust_integer_allocation
from .robust_result import RobustAllocation, RobustIntegerAllocation
from .simplex import STAGNATION_GAP, face_kkt_solve, frank_wolfe_gap, project_simplex

__all__ = [
    "Allocation",
    "IntegerAllocation",
    "optimal_allocation",
    "decoupled_start",
    "integer_allocation",
    "RobustAllocation",
    "RobustIntegerAllocation",
    "robust_allocation",
    "robust_integer_allocation",
    "OBJECTIVES",
    "coupling_models",
    "Objective",
    "project_simplex",
    "frank_wolfe_gap",
    "face_kkt_solve",
    "value_gradient",
    "value_gradient_hessian",
    "CostOracle",
    "CostPointOracle",
    "Filtration",
    "FiltrationEvent",
    "filtration",
    "METHODS",
    "HESSIAN_MODES",
    "STARTS",
    "ENGINES",
    "HVP_MIN_SENSORS",
    "FLOW_TOL",
    "NOISE_DECREASE",
    "STAGNATION_GAP",
    "Method",
    "HessianMode",
    "Start",
    "Engine",
    "one_of",
]
