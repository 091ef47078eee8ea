"""Plain, JSON-ready Python values from numpy results: the one conversion behind every
``to_dict()``, the CLI's ``--json`` and the sweep rows.

numpy arrays become (nested) lists, numpy scalars Python ``int``/``float``/``bool``, complex numbers
``[re, im]`` pairs, and NaN/±inf ``None`` (strict JSON has no non-finite numbers).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def plain(x: Any) -> Any:
    """``x`` with every numpy value replaced by plain Python (recursively through dicts, lists
    and tuples; tuples become lists); non-finite floats become ``None``."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, np.generic):
        return plain(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, complex):
        return [plain(x.real), plain(x.imag)]
    return x


def ints(x: Any) -> list[int]:
    """Plain Python ints from an integer array or sequence (``[2, 3]``, never ``np.int64(2)``)."""
    return [int(v) for v in np.asarray(x).ravel()]
