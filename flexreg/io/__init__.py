"""Scan and transform I/O: ``read_scan`` / ``read_scans`` / ``write_scan`` dispatch on the suffix.

Every reader returns whole, validated :class:`~flexreg.core.scan.Scan` objects or raises
:class:`~flexreg.errors.InputError` naming the file and the problem; nothing is half-read.

=============  ==========================================================================
suffix         reader
=============  ==========================================================================
``.ptx``       Leica PTX, every cloud, native grid, pose (``flexreg.io.ptx``)
``.e57``       ASTM E57 via pye57, every scan, row/column grid, pose (``flexreg.io.e57``)
``.ply``       PLY via open3d (``flexreg.io.pointcloud``)
``.pcd``       PCD via open3d; an organised PCD keeps its width x height grid
``.las/.laz``  LAS/LAZ via laspy (``flexreg.io.las``)
``.bin``       KITTI Velodyne float32 ``x y z reflectance`` (``flexreg.io.kitti``)
``.3d``        3DTK scan (cm, left-handed) with its ``.pose`` (``flexreg.io.threedtk``)
``.npy/.npz``  NumPy arrays; ``.npz`` in flexreg's own layout round-trips (``flexreg.io.npz``)
``.png``       16-bit depth/range image + camera (``flexreg.io.depth``)
=============  ==========================================================================
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import Any

from flexreg.core.scan import Scan
from flexreg.errors import InputError
from flexreg.io.transform_io import read_transform, write_transform_json, write_transform_txt

__all__ = [
    "FORMATS",
    "read_scan",
    "read_scans",
    "read_transform",
    "write_scan",
    "write_transform_json",
    "write_transform_txt",
]

# suffix -> (module, format name)
FORMATS: dict[str, tuple[str, str]] = {
    ".ptx": ("ptx", "ptx"),
    ".e57": ("e57", "e57"),
    ".ply": ("pointcloud", "ply"),
    ".pcd": ("pointcloud", "pcd"),
    ".las": ("las", "las"),
    ".laz": ("las", "laz"),
    ".bin": ("kitti", "kitti"),
    ".3d": ("threedtk", "3dtk"),
    ".npy": ("npz", "npy"),
    ".npz": ("npz", "npz"),
    ".png": ("depth", "depth"),
}
_BY_NAME = {name: mod for mod, name in FORMATS.values()}
_WRITERS = {".ply": "pointcloud", ".npz": "npz", ".ptx": "ptx", ".e57": "e57"}


def _module(name: str) -> Any:
    return importlib.import_module(f"{__name__}.{name}")


def detect_format(path: str | PathLike[str], format: str | None = None) -> tuple[str, str]:
    """Return ``(module, format name)`` for a path, by explicit ``format`` or by suffix."""
    p = Path(path)
    if format is not None:
        key = format.lower().lstrip(".")
        if key not in _BY_NAME:
            raise InputError(p, f"unknown format {format!r}; known: {', '.join(sorted(_BY_NAME))}")
        return _BY_NAME[key], key
    suffix = p.suffix.lower()
    if suffix not in FORMATS:
        raise InputError(
            p, f"unknown scan suffix {suffix or '(none)'!r}; known: {', '.join(sorted(FORMATS))}"
        )
    return FORMATS[suffix]


def _check_file(p: Path) -> None:
    if not p.exists():
        raise InputError(p, "no such file")
    if p.is_dir():
        raise InputError(p, "is a folder, not a scan file")
    if p.stat().st_size == 0:
        raise InputError(p, "file is empty")


def read_scans(
    path: str | PathLike[str], *, format: str | None = None, **options: Any
) -> list[Scan]:
    """Read every scan (cloud, station) in a file.

    Parameters
    ----------
    path : path-like
    format : str, optional
        Override the suffix: ``ptx``, ``e57``, ``ply``, ``pcd``, ``las``, ``laz``, ``kitti``,
        ``3dtk``, ``npy``, ``npz``, ``depth``.
    **options
        Reader options (``camera``, ``depth_scale``, ``depth_kind`` for depth images; ``pose``
        for 3DTK).

    Raises
    ------
    InputError
        Unknown suffix, missing/empty file, or any inconsistency in its content.
    """
    p = Path(path)
    mod, _ = detect_format(p, format)
    _check_file(p)
    scans: list[Scan] = _module(mod).read(p, **options)
    if not scans:
        raise InputError(p, "file holds no scan")
    if all(len(s) == 0 for s in scans):
        raise InputError(p, "file holds no valid point (every cell is a no-return)")
    return scans


def read_scan(
    path: str | PathLike[str], *, format: str | None = None, index: int = 0, **options: Any
) -> Scan:
    """Read one scan of a file (the first unless ``index`` says otherwise).

    See :func:`read_scans` for formats and options.
    """
    scans = read_scans(path, format=format, **options)
    if not -len(scans) <= index < len(scans):
        raise InputError(path, f"scan index {index} out of range: the file holds {len(scans)}")
    return scans[index]


def write_scan(path: str | PathLike[str], scan: Scan | list[Scan], **options: Any) -> Path:
    """Write a scan (or several, for PTX and E57) by suffix: ``.ply``, ``.npz``, ``.ptx``, ``.e57``.

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


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp)`` on a temporary sibling of ``path``, then rename it into place.

    An :class:`InputError` the writer raises about the temporary file is re-raised naming
    ``path``, the file the caller asked for.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        write(tmp)
        tmp.replace(path)
    except InputError as e:
        if e.source == str(tmp):
            raise InputError(path, e.problem) from None
        raise
    finally:
        tmp.unlink(missing_ok=True)
