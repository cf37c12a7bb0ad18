"""Plain-JSON conversion of results: numpy arrays and scalars, paths, non-finite floats."""

from __future__ import annotations

import math
from pathlib import PurePath
from typing import Any

import numpy as np

__all__ = ["to_jsonable"]


def to_jsonable(x: Any) -> Any:
    """``x`` with every numpy array/scalar, tuple and path turned into JSON types.

    Non-finite floats become None (JSON has no NaN/Inf); dict keys become strings.

    >>> to_jsonable({"T": np.eye(2), 1: (np.float32(0.5), float("nan"))})
    {'T': [[1.0, 0.0], [0.0, 1.0]], '1': [0.5, None]}
    """
    if isinstance(x, dict):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [to_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return to_jsonable(x.tolist())
    if isinstance(x, np.generic):
        return to_jsonable(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, PurePath):
        return str(x)
    return x
