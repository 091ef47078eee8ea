"""The network model of Chen, Belabbas and Başar: the linear stochastic system
``dx = A x dt + G dw`` observed by ``N`` sensors, its fast-sampling cost ``η(r) = tr Σ(r)`` with
derivatives, its diagnostics (observability, detectability, regular triplets) and its model files.

Modules: :mod:`~capalloc_rs.network.model` (the :class:`Network` class),
:mod:`~capalloc_rs.network.constructors` (block assembly), :mod:`~capalloc_rs.network.cost` (the
cost evaluation façade), :mod:`~capalloc_rs.network.diagnostics` (PBH margins and reports),
:mod:`~capalloc_rs.network.io` and :mod:`~capalloc_rs.network.schema` (file formats) and
:mod:`~capalloc_rs.network.files` (the public file API, :mod:`capalloc_rs.model_io`).
"""

from __future__ import annotations

from . import files
from ._netarg import accepts_path, as_network
from .cost import MAX_THREADS, BlockStructure, CostEvaluation, CostPoint
from .diagnostics import PBH_RTOL, NetworkReport, SubsystemReport
from .model import Network
from .model import _restore as _restore  # networks pickled before the package split
from .sensor_limits import SensorLimits, require_paper_form

__all__ = [
    "BlockStructure",
    "CostEvaluation",
    "CostPoint",
    "Network",
    "NetworkReport",
    "SubsystemReport",
    "PBH_RTOL",
    "SensorLimits",
    "require_paper_form",
    "MAX_THREADS",
    "accepts_path",
    "as_network",
    "files",
]
