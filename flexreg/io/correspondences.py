"""Correspondence files: CSV tables of camera pixels paired with lidar coordinates.

The first non-comment line is a header naming the columns (case-insensitive, any order, extra
columns ignored): ``u,v`` (camera pixel) and either ``X,Y,Z`` (lidar frame, metres) or
``row,col`` (pixel of the scan's range image). Blank lines and lines starting with ``#`` are
skipped; ``,`` is the delimiter (``;`` or a tab when the header has no comma).
:func:`read_pairs` reads such a file, :func:`write_pairs` writes one it reads back exactly.
Lifting ``row,col`` to lidar points is calibration's part
(:func:`flexreg.calibration.read_correspondences`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.errors import InputError
from flexreg.io import atomic_write
from flexreg.io.files import protect

__all__ = ["PairTable", "read_pairs", "write_pairs"]


@dataclass(frozen=True, eq=False)
class PairTable:
    """The rows of a correspondence file.

    Attributes
    ----------
    pixels : (N, 2) float64, pixels
        ``(u, v)`` in the camera image.
    xyz : (N, 3) float64 or None, metres
        ``X,Y,Z`` in the lidar frame (files with those columns).
    rowcol : (N, 2) float64 or None, pixels
        ``(row, col)`` in the scan's range image (files with those columns).
    lines : (N,) int64
        Line of each pair in the file (1-based).
    path : Path
    """

    pixels: NDArray[np.float64]
    xyz: NDArray[np.float64] | None
    rowcol: NDArray[np.float64] | None
    lines: NDArray[np.int64]
    path: Path

    def __len__(self) -> int:
        return len(self.pixels)


def _parse_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header (lower-case names) and ``(line number, fields)`` of a CSV file."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as e:
        raise InputError(path, f"cannot read: {e.strerror or e}") from None
    lines = text.splitlines()
    header: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    delimiter = ","
    for lineno, line in enumerate(lines, start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if header is None:
            if "," not in s:
                delimiter = ";" if ";" in s else ("\t" if "\t" in s else ",")
            header = [h.strip().lower() for h in next(csv.reader([s], delimiter=delimiter))]
            continue
        rows.append((lineno, [f.strip() for f in next(csv.reader([s], delimiter=delimiter))]))
    if header is None:
        raise InputError(
            path, "empty correspondence file: expected a header u,v,X,Y,Z or u,v,row,col"
        )
    return header, rows


def _columns(path: Path, header: list[str]) -> tuple[str, list[int]]:
    """``("xyz" | "grid", column indices)`` from a header."""
    pos = {name: i for i, name in enumerate(header)}
    if len(pos) != len(header):
        raise InputError(path, f"line 1: duplicate column names in header {','.join(header)}")
    if "u" not in pos or "v" not in pos:
        raise InputError(path, f"header must name columns u,v; got {','.join(header)}")
    has_xyz = all(c in pos for c in ("x", "y", "z"))
    has_grid = all(c in pos for c in ("row", "col"))
    if has_xyz and has_grid:
        raise InputError(path, "give either X,Y,Z or row,col columns, not both")
    if has_xyz:
        return "xyz", [pos[c] for c in ("u", "v", "x", "y", "z")]
    if has_grid:
        return "grid", [pos[c] for c in ("u", "v", "row", "col")]
    raise InputError(
        path, f"header must be u,v,X,Y,Z or u,v,row,col (any order); got {','.join(header)}"
    )


def read_pairs(path: str | PathLike[str]) -> PairTable:
    """Read a correspondence CSV file (format: see the module docstring).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    PairTable
        ``xyz`` or ``rowcol`` set, as the header says.

    Raises
    ------
    InputError
        Missing file, bad header, or a malformed line (named by its line number): wrong
        number of fields or a value that is not a finite number.
    """
    p = Path(path)
    protect(p)
    if not p.is_file():
        raise InputError(p, "no such file")
    header, rows = _parse_rows(p)
    kind, cols = _columns(p, header)
    names = ["u", "v", "X", "Y", "Z"] if kind == "xyz" else ["u", "v", "row", "col"]
    values = np.empty((len(rows), len(cols)), dtype=np.float64)
    lines = np.empty(len(rows), dtype=np.int64)
    for k, (lineno, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise InputError(
                p,
                f"line {lineno}: expected {len(header)} values ({','.join(header)}), "
                f"got {len(fields)}",
            )
        for j, (c, name) in enumerate(zip(cols, names, strict=True)):
            try:
                x = float(fields[c])
            except ValueError:
                raise InputError(
                    p, f"line {lineno}: {name} is not a number: {fields[c]!r}"
                ) from None
            if not math.isfinite(x):
                raise InputError(p, f"line {lineno}: {name} is not finite: {fields[c]!r}")
            values[k, j] = x
        lines[k] = lineno
    if kind == "xyz":
        return PairTable(values[:, :2], values[:, 2:5], None, lines, p)
    return PairTable(values[:, :2], None, values[:, 2:4], lines, p)


def _number(x: float) -> str:
    """Shortest text that reads back as exactly ``x`` (whole numbers without ``.0``)."""
    return str(int(x)) if x.is_integer() and abs(x) < 2**53 else repr(x)


def write_pairs(
    path: str | PathLike[str],
    pixels: ArrayLike,
    *,
    xyz: ArrayLike | None = None,
    rowcol: ArrayLike | None = None,
    comments: Iterable[str] = (),
) -> Path:
    """Write correspondences as a CSV file :func:`read_pairs` reads back exactly.

    Parameters
    ----------
    path : path-like
    pixels : (N, 2) float, pixels
        ``(u, v)`` in the camera image.
    xyz : (N, 3) float, metres, optional
        Lidar-frame points (header ``u,v,X,Y,Z``).
    rowcol : (N, 2) float, optional
        Range-image pixels (header ``u,v,row,col``); give exactly one of ``xyz`` and ``rowcol``.
    comments : iterable of str
        Written first, each line prefixed with ``# ``.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    InputError
        Neither or both of ``xyz`` and ``rowcol``, mismatched lengths or non-finite values.

    Examples
    --------
    >>> import tempfile
    >>> f = Path(tempfile.mkdtemp()) / "pairs.csv"
    >>> _ = write_pairs(f, [[10.5, 20.0]], rowcol=[[3, 4.25]])
    >>> f.read_text()
    'u,v,row,col\\n10.5,20,3,4.25\\n'
    >>> read_pairs(f).rowcol.tolist()
    [[3.0, 4.25]]
    """
    p = Path(path)
    if (xyz is None) == (rowcol is None):
        raise InputError(p, "give either X,Y,Z points or row,col pixels, not both or neither")
    uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    if xyz is not None:
        header, other = "u,v,X,Y,Z", np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    else:
        header, other = "u,v,row,col", np.asarray(rowcol, dtype=np.float64).reshape(-1, 2)
    if len(other) != len(uv):
        raise InputError(p, f"{len(uv)} pixels but {len(other)} lidar coordinates")
    table = np.hstack([uv, other])
    if not np.isfinite(table).all():
        raise InputError(p, "NaN or Inf in the correspondences")
    out = [f"# {line}" for c in comments for line in (c.splitlines() or [""])] + [header]
    out += [",".join(_number(float(x)) for x in row) for row in table]
    text = "\n".join(out) + "\n"
    atomic_write(p, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return p
