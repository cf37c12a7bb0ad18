"""Transforms on disk: 4x4 text (CloudCompare style, row-major) and JSON with metadata."""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.jsonable import to_jsonable
from flexreg.core.transforms import as_transform, invert, nearest_rotation
from flexreg.errors import InputError
from flexreg.io.files import atomic_write, protect


def write_transform_txt(path: str | PathLike[str], T: ArrayLike) -> Path:
    """Write a 4x4 matrix as four whitespace-separated rows (what CloudCompare's
    "Edit > Apply transformation" and ``-APPLY_TRANS`` read). Full float64 precision."""
    M = as_transform(T)
    p = Path(path)
    text = "\n".join(" ".join(f"{x:.17g}" for x in row) for row in M) + "\n"
    atomic_write(p, lambda tmp: tmp.write_text(text))
    return p


def write_transform_json(
    path: str | PathLike[str], T: ArrayLike, *, key: str = "T_target_source", **metadata: Any
) -> Path:
    """Write ``{key: [[4x4]], **metadata}`` as JSON (numpy values and paths in the metadata are
    converted by :func:`~flexreg.core.jsonable.to_jsonable`)."""
    M = as_transform(T)
    doc = {key: M.tolist(), **metadata}
    text = json.dumps(to_jsonable(doc), indent=2) + "\n"
    p = Path(path)
    atomic_write(p, lambda tmp: tmp.write_text(text))
    return p


def read_transform(
    path: str | PathLike[str], *, key: str = "T_target_source"
) -> NDArray[np.float64]:
    """Read a 4x4 transform from a text file (4 rows of 4 numbers, or 3 rows + implied
    ``0 0 0 1``) or from JSON (``key``, else the single 4x4 list it holds)."""
    p = Path(path)
    protect(p)
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


def read_pair_transform(path: str | PathLike[str], target: str, source: str) -> NDArray[np.float64]:
    """A given ``T_target_source`` of the pair ``target``, ``source`` (station stems): what
    ``flexreg register --init`` / ``--truth`` and ``flexreg survey --link`` read.

    Accepted: a 4x4 text matrix (:func:`read_transform`: 4 rows of 4 numbers, or 3 rows), a
    JSON ``{"T_target_source": [[4x4]], ...}`` (what ``flexreg register`` writes), or a
    ``flexreg synth`` ``gt.json`` (its ``pairs`` entry for ``target`` / ``source``, inverted
    when listed the other way round).

    Parameters
    ----------
    path : path-like
    target, source : str
        Stems of the two scans, to pick a pair of a ``gt.json``.

    Returns
    -------
    (4, 4) float64
        A rigid transform.

    Raises
    ------
    InputError
        Naming ``path``: missing or unreadable file, invalid JSON, no matching entry, or a
        matrix that is not a 4x4 rigid transform (non-orthonormal rotation block, reflection,
        bad last row, NaN).
    """
    p = Path(path)
    protect(p)
    try:
        if p.suffix.lower() == ".json" and p.is_file():
            T = _pair_entry(p, target, source)
            if T is not None:
                return T
        return np.asarray(read_transform(p), dtype=np.float64)
    except OSError as e:
        raise InputError(p, f"cannot read: {e.strerror or e}") from None


def _pair_entry(p: Path, target: str, source: str) -> NDArray[np.float64] | None:
    """The ``pairs`` entry of a ``gt.json`` for ``target``/``source`` (inverted when listed
    the other way round); None when the file is not such a list (a transform JSON)."""
    try:
        doc = json.loads(p.read_text(errors="replace"))
    except json.JSONDecodeError as e:
        raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None
    except (OSError, UnicodeError) as e:
        raise InputError(p, f"cannot read: {e}") from None
    if not (isinstance(doc, dict) and "pairs" in doc and "T_target_source" not in doc):
        return None
    pairs = doc["pairs"]
    if not isinstance(pairs, list) or not all(isinstance(q, dict) for q in pairs):
        raise InputError(p, "'pairs' must be a list of objects")
    for pair in pairs:
        names = (pair.get("target"), pair.get("source"))
        if names in ((target, source), (source, target)):
            if "T_target_source" not in pair:
                raise InputError(p, f"pair {names[0]} / {names[1]} has no T_target_source")
            T = _json_matrix(pair["T_target_source"], p)
            return T if names == (target, source) else invert(T)
    raise InputError(p, f"no pair {target} / {source} in its 'pairs'")


def _json_matrix(value: Any, path: Path) -> NDArray[np.float64]:
    """A 4x4 rigid transform from a JSON value, or one error line naming ``path``."""
    try:
        return as_transform(np.asarray(value, dtype=np.float64), name=str(path))
    except (ValueError, TypeError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(path, f"T_target_source is not a 4x4 matrix of numbers ({e})") from None


def read_ground_truth(
    path: str | PathLike[str],
    *,
    target: str | None = None,
    source: str | None = None,
    reorthonormalize: float = 0.0,
) -> NDArray[np.float64]:
    """A known ``T_target_source`` from a file.

    Accepted: JSON ``{"T_target_source": [[4x4]], ...}`` (what ``flexreg register`` writes),
    a ``flexreg synth`` ``gt.json`` (its ``pairs`` entry for the stems ``target`` and
    ``source``, inverted if listed the other way round), a ``.npy`` 4x4 array, or a 4x4 text
    matrix (:func:`read_transform`).

    Parameters
    ----------
    path : path-like
    target, source : str, optional
        Stems of the scans, to pick a pair of a ``gt.json``.
    reorthonormalize : float
        A rotation block this close to a rotation (largest element difference) is replaced by
        the nearest rotation (SVD), for references stored with few digits (3DMatch's
        ``gt.npy`` is orthonormal to 7e-5 only); anything further is refused. 0: never.

    Raises
    ------
    InputError
        Missing or unreadable file, no matching entry, or a matrix that is not a rigid
        transform (non-orthonormal rotation block, reflection, bad last row, NaN).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    suffix = p.suffix.lower()
    if suffix == ".json":
        T, inverted = _ground_truth_entry(p, target, source)
        M = _rigid(T, p, reorthonormalize)
        return invert(M) if inverted else M
    if suffix == ".npy":
        try:
            T = np.load(p)
        except (OSError, ValueError) as e:
            raise InputError(p, f"cannot read the transform ({e})") from None
        return _rigid(T, p, reorthonormalize)
    return _rigid(read_transform(p), p, reorthonormalize)


def _ground_truth_entry(p: Path, target: str | None, source: str | None) -> tuple[Any, bool]:
    """The matrix of a ground-truth JSON file, and whether it maps the other way round."""
    try:
        doc = json.loads(p.read_text(errors="replace"))
    except json.JSONDecodeError as e:
        raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None
    if isinstance(doc, dict) and "T_target_source" not in doc and "pairs" in doc:
        pairs = doc["pairs"]
        if not isinstance(pairs, list) or not all(isinstance(q, dict) for q in pairs):
            raise InputError(
                p, "'pairs' must be a list of objects with 'target', 'source' and 'T_target_source'"
            )
        for pair in pairs:
            names = (pair.get("target"), pair.get("source"))
            if names == (target, source):
                return pair.get("T_target_source"), False
            if names == (source, target):
                return pair.get("T_target_source"), True
        raise InputError(p, f"no pair {target} / {source} in its 'pairs'")
    if isinstance(doc, dict) and "T_target_source" not in doc:
        raise InputError(p, "no 'T_target_source' entry")
    return (doc["T_target_source"] if isinstance(doc, dict) else doc), False


def _rigid(T: Any, path: Path, reorthonormalize: float = 0.0) -> NDArray[np.float64]:
    try:
        M = np.array(T, dtype=float)
        if reorthonormalize > 0 and M.shape == (4, 4) and np.isfinite(M).all():
            R = nearest_rotation(M[:3, :3])  # a reflection stays one: as_transform refuses it
            if np.abs(R - M[:3, :3]).max() < reorthonormalize:
                M[:3, :3] = R
        return as_transform(M, name=str(path), rigid=True)
    except (TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(path, f"not a 4x4 matrix of numbers ({e})") from None
