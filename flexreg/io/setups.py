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
from flexreg.io.scans import check_file, read_scans
from flexreg.io.selector import ScanRef, parse_scan_ref, pick, select_setup, setup_choices

__all__ = [
    "ScanRef",
    "SetupInfo",
    "list_setups",
    "parse_scan_ref",
    "pick",
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
        In file order. E57 setups are listed from the file's headers without reading any point;
        other formats are read whole (a single-setup format lists one setup).

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
    scans = read_scans(p, **options)
    return [SetupInfo(p, i, s.name, len(s), s.T_world_scanner.copy()) for i, s in enumerate(scans)]


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
