"""Transforms on disk: 4x4 text (CloudCompare style, row-major) and JSON with metadata."""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.transforms import as_transform
from flexreg.errors import InputError


def write_transform_txt(path: str | PathLike[str], T: ArrayLike) -> Path:
    """Write a 4x4 matrix as four whitespace-separated rows (what CloudCompare's
    "Edit > Apply transformation" and ``-APPLY_TRANS`` read). Full float64 precision."""
    from flexreg.io import atomic_write

    M = as_transform(T)
    p = Path(path)
    text = "\n".join(" ".join(f"{x:.17g}" for x in row) for row in M) + "\n"
    atomic_write(p, lambda tmp: tmp.write_text(text))
    return p


def write_transform_json(
    path: str | PathLike[str], T: ArrayLike, *, key: str = "T_target_source", **metadata: Any
) -> Path:
    """Write ``{key: [[4x4]], **metadata}`` as JSON (metadata must be JSON-serialisable)."""
    from flexreg.io import atomic_write

    M = as_transform(T)
    doc = {key: M.tolist(), **metadata}
    text = json.dumps(doc, indent=2, default=_json_default) + "\n"
    p = Path(path)
    atomic_write(p, lambda tmp: tmp.write_text(text))
    return p


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


def read_transform(
    path: str | PathLike[str], *, key: str = "T_target_source"
) -> NDArray[np.float64]:
    """Read a 4x4 transform from a text file (4 rows of 4 numbers, or 3 rows + implied
    ``0 0 0 1``) or from JSON (``key``, else the single 4x4 list it holds)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    text = p.read_text(errors="replace")
    if p.suffix.lower() == ".json":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None
        if isinstance(doc, dict):
            if key not in doc:
                raise InputError(p, f"no {key!r} entry")
            doc = doc[key]
        return as_transform(doc, name=str(p))
    try:
        rows = [[float(x) for x in line.split()] for line in text.splitlines() if line.strip()]
    except ValueError:
        raise InputError(p, "transform text must hold only numbers") from None
    if len(rows) == 3:
        rows.append([0.0, 0.0, 0.0, 1.0])
    if len(rows) != 4 or any(len(r) != 4 for r in rows):
        raise InputError(p, "expected 4 rows of 4 numbers")
    return as_transform(rows, name=str(p))
