"""Setups (stations) of a scan file, and the one parser of the ``FILE#N`` / ``FILE#NAME`` selector.

A PTX file may hold several clouds and an E57 file several ``data3D`` scans: each is one setup
of the scanner, with its own points and its own stored pose. Everywhere a scan is read, a
setup is named by the file and a selector after ``#``:

- ``project.e57#2``: the third setup (indices start at 0, as ``flexreg info`` lists them);
- ``project.e57#Station 7``: the setup named so (E57 stores a name per scan).

A file that exists under the full name (``#`` being part of its file name) is read as a file,
without selector. A selector made of digits only is always an index. :func:`list_setups` tells
what a file holds without keeping the points (for E57, without reading them at all).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import invert, is_rigid
from flexreg.errors import InputError
from flexreg.io.e57 import headers
from flexreg.io.formats import detect_format
from flexreg.io.ptx import header_pose
from flexreg.io.scans import check_file, read_scans
from flexreg.io.selector import ScanRef, parse_scan_ref, pick, select_setup, setup_choices

__all__ = [
    "ScanRef",
    "SetupInfo",
    "list_setups",
    "parse_scan_ref",
    "pick",
    "ptx_headers",
    "select_setup",
    "setup_choices",
    "stored_T_target_source",
]


@dataclass(frozen=True)
class SetupInfo:
    """One setup of a file, without its points.

    Attributes
    ----------
    path : Path
        The file.
    index : int
        Position in the file (0 first); ``f"{path}#{index}"`` reads it.
    name : str
        The name the file gives it (E57 ``name``; ``"stem#k"`` for PTX cloud ``k``).
    points : int
        Points stored (E57: as the file counts them, no-returns included; other formats: valid
        points).
    T_world_scanner : (4, 4) float64
        The stored pose: maps this setup's scanner-frame points into the file's common frame
        (E57 ``pose`` quaternion + translation; PTX header transform). Identity when the file
        stores none.
    """

    path: Path
    index: int
    name: str
    points: int
    T_world_scanner: NDArray[np.float64] = field(repr=False)

    @property
    def ref(self) -> str:
        """``FILE#index``: how to name this setup on the command line."""
        return f"{self.path}#{self.index}"

    @property
    def has_pose(self) -> bool:
        """Whether the stored pose is anything but the identity."""
        return not np.allclose(self.T_world_scanner, np.eye(4), rtol=0.0, atol=1e-12)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: path, index, name, points, T_world_scanner (nested lists)."""
        return {
            "path": str(self.path),
            "index": self.index,
            "name": self.name,
            "points": self.points,
            "T_world_scanner": np.asarray(self.T_world_scanner).tolist(),
        }


def list_setups(path: str | PathLike[str], **options: Any) -> list[SetupInfo]:
    """Every setup of a scan file: index, name, point count and stored pose.

    A survey over a project export takes every setup of every file this way:

    >>> for s in list_setups("project.e57"):                      # doctest: +SKIP
    ...     scan = read_scan(s.ref)                               # one setup at a time

    Parameters
    ----------
    path : path-like
        A scan file (any readable format; a ``#`` selector is not allowed here).
    **options
        Reader options, as for :func:`flexreg.io.read_scans`.

    Returns
    -------
    list of SetupInfo
        In file order. E57 setups are listed from the file's headers without reading any point,
        PTX clouds from their headers while the point lines are only counted (``points`` is
        then the grid size, no-returns included); other formats are read whole (a
        single-setup format lists one setup).

    Raises
    ------
    InputError
        A missing, unreadable or corrupt file, or a selector in ``path``.
    """
    ref = parse_scan_ref(path)
    if ref.selector is not None:
        raise InputError(path, "list_setups takes a file, not a setup (drop the '#...')")
    p = ref.path
    mod, _ = detect_format(p, options.pop("format", None))
    check_file(p)
    if mod == "e57" and not options:
        return [SetupInfo(p, i, n, c, T) for i, (n, c, T) in enumerate(headers(p))]
    if mod == "ptx" and not options:
        return [SetupInfo(p, i, n, c, T) for i, (n, c, T) in enumerate(ptx_headers(p))]
    scans = read_scans(p, **options)
    return [SetupInfo(p, i, s.name, len(s), s.T_world_scanner.copy()) for i, s in enumerate(scans)]


#: bytes read at a time while counting a PTX cloud's point lines
_BLOCK = 1 << 24


def _skip_lines(f: Any, n: int) -> bool:
    """Move ``f`` (binary, buffered) past ``n`` newline characters; False at end of file."""
    while n > 0:
        start = f.tell()
        block = f.read(_BLOCK)
        if not block:
            return False
        k = block.count(b"\n")
        if k < n:
            n -= k
            continue
        ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10)
        f.seek(start + int(ends[n - 1]) + 1)
        return True
    return True


def _ptx_header(f: Any, path: Path, cloud: int) -> list[list[float]] | None:
    """The next cloud's 10 header lines as numbers (None at end of file)."""
    lines: list[bytes] = []
    while len(lines) < 10:
        raw = f.readline()
        if not raw:
            if not lines:
                return None
            raise InputError(path, f"cloud {cloud}: truncated header")
        if raw.strip() or lines:
            lines.append(raw)
    try:
        rows = [[float(v) for v in ln.split()] for ln in lines]
    except ValueError:
        rows = []
    if [len(r) for r in rows] != [1, 1, 3, 3, 3, 3, 4, 4, 4, 4]:
        raise InputError(
            path,
            f"cloud {cloud}: malformed header (expected COLS, ROWS, position, 3 axes, "
            "transposed 4x4 transform)",
        )
    return rows


def ptx_headers(path: Path) -> list[tuple[str, int, NDArray[np.float64]]]:
    """``(name, grid cells, T_world_scanner)`` of every cloud of a PTX file, from the headers:
    the point lines are counted, not parsed (the file is read once at disk speed, with one
    block in memory), so listing the setups of a large project export costs no parsing.

    Raises
    ------
    InputError
        A malformed or truncated header, or fewer point lines than a header announces.
    """
    out: list[tuple[str, int, NDArray[np.float64]]] = []
    with open(path, "rb") as f:
        while (rows := _ptx_header(f, path, len(out))) is not None:
            cols, n_rows = rows[0][0], rows[1][0]
            if cols != int(cols) or n_rows != int(n_rows) or cols <= 0 or n_rows <= 0:
                raise InputError(path, f"cloud {len(out)}: grid size {cols:g} x {n_rows:g}")
            n = int(cols) * int(n_rows)
            pose = np.zeros((8, 4))
            for i, r in enumerate(rows[2:]):
                pose[i, : len(r)] = r
            name = path.stem if not out else f"{path.stem}#{len(out)}"
            out.append((name, n, header_pose(pose)))
            if not _skip_lines(f, n):
                raise InputError(
                    path, f"cloud {len(out) - 1}: header announces {n} points; the file ends early"
                )
    if not out:
        raise InputError(path, "no cloud in file")
    return out


def stored_T_target_source(target: Scan, source: Scan) -> NDArray[np.float64] | None:
    """The relative pose the files store: ``inv(T_world_target) @ T_world_source``.

    Parameters
    ----------
    target, source : Scan
        Setups whose ``T_world_scanner`` came from their files (E57 ``pose``, PTX header).

    Returns
    -------
    (4, 4) float64 or None
        ``T_target_source`` in the scanners' own frames, or None when neither setup stores a
        pose (both identity: a file without poses says nothing about where its scanner stood)
        or a pose is not rigid.
    """
    Tt, Ts = target.T_world_scanner, source.T_world_scanner
    eye = np.eye(4)
    if np.allclose(Tt, eye, rtol=0.0, atol=1e-12) and np.allclose(Ts, eye, rtol=0.0, atol=1e-12):
        return None
    if not (is_rigid(Tt) and is_rigid(Ts)):
        return None
    return invert(Tt) @ Ts
