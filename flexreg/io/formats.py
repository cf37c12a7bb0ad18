"""Scan file formats by suffix: which :mod:`flexreg.io` module reads each."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from flexreg.errors import InputError

__all__ = ["FORMATS", "detect_format"]

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
