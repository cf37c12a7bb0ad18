"""Scan files by suffix: ``read_scan`` / ``read_scans`` / ``write_scan`` (see :mod:`flexreg.io`).

Each format lives in its own module (``ptx``, ``e57``, ``pointcloud``, ...), imported when a
file of that format is first read or written.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.range_image import RangeImage
from flexreg.core.scan import FLOAT32_MAX_M, Scan
from flexreg.errors import InputError
from flexreg.io.files import atomic_write, protect
from flexreg.io.formats import detect_format
from flexreg.io.selector import parse_scan_ref, pick, select_setup

__all__ = [
    "check_file",
    "read_scan",
    "read_scans",
    "read_working_scan",
    "read_working_scans",
    "single_precision",
    "write_scan",
]

_WRITERS = {
    ".ply": "pointcloud",
    ".pcd": "pointcloud",
    ".npz": "npz",
    ".ptx": "ptx",
    ".e57": "e57",
    ".las": "las",
    ".laz": "las",
}


def _module(name: str) -> Any:
    return importlib.import_module(f"flexreg.io.{name}")


def check_file(p: Path) -> None:
    """Raise :class:`InputError` for a missing path, a folder or an empty file (and mark the
    file as an input that no output may replace)."""
    protect(p)
    if not p.exists():
        raise InputError(p, "no such file")
    if p.is_dir():
        raise InputError(p, "is a folder, not a scan file")
    if p.stat().st_size == 0:
        raise InputError(p, "file is empty")


def read_scans(
    path: str | PathLike[str], *, format: str | None = None, **options: Any
) -> list[Scan]:
    """Read every scan (cloud, station, setup) in a file, or the one setup ``FILE#N`` /
    ``FILE#NAME`` names (see :mod:`flexreg.io.setups`).

    Parameters
    ----------
    path : path-like
        A file, or a file and a setup selector: ``project.e57#2``, ``project.e57#Station 7``.
    format : str, optional
        Override the suffix: ``ptx``, ``e57``, ``ply``, ``pcd``, ``las``, ``laz``, ``kitti``,
        ``3dtk``, ``npy``, ``npz``, ``depth``.
    **options
        Reader options (``camera``, ``depth_scale``, ``depth_kind`` for depth images; ``pose``
        for 3DTK), and ``precise``: keep float64 points. By default points that all lie
        within :data:`~flexreg.core.scan.FLOAT32_MAX_M` of the scan's origin are float32
        (:func:`single_precision`; half the memory, 0.5 mm or better); ``precise=True`` keeps
        the file's values exactly (to write them back unchanged). An npz file gives back the
        type it stores. ``intensity=False``: no intensities (for callers that never read
        them; the PTX reader then does not store them at all, 4 bytes per point less).

    Raises
    ------
    InputError
        Unknown suffix, missing/empty file, or any inconsistency in its content.
    """
    ref = parse_scan_ref(path)
    p = ref.path
    mod, _ = detect_format(p, format)
    check_file(p)
    precise = bool(options.pop("precise", False))
    intensity = bool(options.pop("intensity", True))
    if mod == "ptx":  # reads float32 itself, and stores intensities only when asked
        options["precise"] = precise
        options["intensity"] = intensity
    if ref.selector is not None and mod == "e57" and not options:
        one = _module(mod).read_one(p, ref)  # one setup of a large project file: only it
        one = one if precise else single_precision(one)
        if not intensity:
            one.intensity = None
        return [one]
    scans: list[Scan] = _module(mod).read(p, **options)
    if not scans:
        raise InputError(p, "file holds no scan")
    if all(len(s) == 0 for s in scans):
        raise InputError(p, "file holds no valid point (every cell is a no-return)")
    if not precise and mod not in ("ptx", "npz"):  # PTX chooses; npz keeps what it stores
        scans = [single_precision(s) for s in scans]
    if not intensity:
        for s in scans:  # scans of our own making: drop the array, no copy
            s.intensity = None
    return scans if ref.selector is None else [pick(scans, ref)]


def single_precision(scan: Scan) -> Scan:
    """The scan with float32 points when they all lie within
    :data:`~flexreg.core.scan.FLOAT32_MAX_M` of its origin (0.5 mm or better), else as it is
    (project or map coordinates keep float64). Half the memory for every later stage."""
    P = scan.points
    if P.dtype == np.float32 or not len(P):
        return scan
    if max(-float(P.min()), float(P.max())) > FLOAT32_MAX_M:
        return scan
    return replace(scan, points=P.astype(np.float32))


def read_scan(
    path: str | PathLike[str], *, format: str | None = None, index: int = 0, **options: Any
) -> Scan:
    """Read one scan of a file: the setup a ``FILE#N`` / ``FILE#NAME`` selector names, else the
    one at ``index`` (the first by default).

    See :func:`read_scans` for formats and options; :func:`flexreg.io.setups.list_setups`
    lists a file's setups.
    """
    scans = read_scans(path, format=format, **options)
    if parse_scan_ref(path).selector is not None:
        return scans[0]
    if not -len(scans) <= index < len(scans):
        raise InputError(path, f"scan index {index} out of range: the file holds {len(scans)}")
    return scans[index]


def read_working_scans(
    path: str | PathLike[str], *, max_pixels: int
) -> list[tuple[Scan, RangeImage | None]]:
    """The scans of a file as :func:`read_scans` selects them (every setup, or the one a
    ``FILE#N`` / ``FILE#NAME`` selector names), read for a caller that needs their points and
    working images only (a survey worker preparing a station, ``flexreg register``).

    PTX and E57 files are read straight into both: no grid index, intensity or colour is
    stored, 12 bytes per float32 point, and the working image of at most ``max_pixels``
    pixels is built while the lines or blocks stream past (:func:`flexreg.io.ptx.read_working`,
    :func:`flexreg.io.e57.read_working`: an E57 scan without row and column indices
    comes with None for its image). A LAS/LAZ file is decoded chunk by chunk into its
    points only (:func:`flexreg.io.las.read_working`), with None for its image. Other
    formats: :func:`read_scans` without intensities, and None for each image (the caller
    builds the working images).
    """
    ref = parse_scan_ref(path)
    p = ref.path
    mod, _ = detect_format(p)
    if mod not in ("ptx", "e57", "las"):
        return [(scan, None) for scan in read_scans(path, intensity=False)]
    check_file(p)
    if mod == "e57":  # only the selected setup's points are read
        return list(
            _module(mod).read_working(
                p, max_pixels=int(max_pixels), ref=ref if ref.selector else None
            )
        )
    pairs: list[tuple[Scan, RangeImage | None]] = list(
        _module(mod).read_working(p, max_pixels=int(max_pixels))
    )
    if not pairs:
        raise InputError(p, "file holds no scan")
    if all(len(s) == 0 for s, _ in pairs):
        raise InputError(p, "file holds no valid point (every cell is a no-return)")
    if ref.selector is None:
        return pairs
    return [pairs[select_setup([s.name for s, _ in pairs], ref)]]


def read_working_scan(
    path: str | PathLike[str], *, max_pixels: int
) -> tuple[Scan, RangeImage | None]:
    """The first of :func:`read_working_scans` (the setup a selector names, else the file's
    first), as :func:`read_scan` selects it."""
    return read_working_scans(path, max_pixels=max_pixels)[0]


def write_scan(path: str | PathLike[str], scan: Scan | list[Scan], **options: Any) -> Path:
    """Write a scan (or several, for PTX and E57) by suffix: ``.ply``, ``.pcd``, ``.npz``,
    ``.ptx``, ``.e57``, ``.las``, ``.laz``.

    The file is written to a temporary name first and renamed at the end, so a failure never
    leaves a partial file behind.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _WRITERS:
        raise InputError(
            p, f"cannot write {suffix or '(none)'!r}; writable: {', '.join(sorted(_WRITERS))}"
        )
    scans = scan if isinstance(scan, list) else [scan]
    writer: Callable[..., None] = _module(_WRITERS[suffix]).write
    atomic_write(p, lambda tmp: writer(tmp, scans, **options))
    return p
