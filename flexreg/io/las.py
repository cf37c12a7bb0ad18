"""ASPRS LAS / LAZ point clouds via laspy (LAZ through its lazrs backend).

LAS stores integer coordinates with a per-file scale and offset; laspy applies them, so the
points come out as float64 in the file's units (metres for almost every CRS in use). LAS has
no scanner grid and no sensor pose: points are usually already in a projected/world frame, so
``T_world_scanner`` is the identity.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import Scan
from flexreg.errors import InputError

__all__ = ["read"]


def read(path: Path, **options: Any) -> list[Scan]:
    """Read a LAS or LAZ file as one scan.

    Parameters
    ----------
    path : Path
    **options
        None are accepted; an unknown option raises :class:`InputError`.

    Returns
    -------
    list of Scan
        One scan: ``points`` (N, 3) float64 (scaled and offset ``X Y Z``), ``intensity`` (N,)
        float32 (LAS's 16-bit value, unchanged), ``colors`` (N, 3) uint8 for point formats
        with RGB. LAS colours are 16-bit by the specification, but many writers store 8-bit
        values in them: channels whose maximum is at most 255 are taken as they are, others
        are shifted down by 8 bits.

    Raises
    ------
    InputError
        Not a LAS/LAZ file, corrupt or truncated data (fewer points than the header
        declares), no points, or LAZ without a decompression backend.
    """
    if options:
        raise InputError(path, f"unknown LAS option(s): {', '.join(sorted(options))}")
    import laspy

    try:
        with laspy.open(path) as reader:
            declared = int(reader.header.point_count)
            las = reader.read()
    except (laspy.errors.LaspyException, ValueError, RuntimeError, OSError, EOFError) as exc:
        raise InputError(path, f"not a readable LAS/LAZ file: {exc}") from None
    n = len(las.points)
    if declared == 0:
        raise InputError(path, "LAS file holds no points (header point count 0)")
    if n != declared:
        raise InputError(path, f"truncated: the header declares {declared} points, {n} were read")
    xyz = np.stack(
        [np.asarray(las.x, dtype=np.float64), np.asarray(las.y, dtype=np.float64),
         np.asarray(las.z, dtype=np.float64)],
        axis=1,
    )  # fmt: skip
    names = set(las.point_format.dimension_names)
    intensity = np.asarray(las.intensity, dtype=np.float32) if "intensity" in names else None
    colors = None
    if {"red", "green", "blue"} <= names:
        colors = np.stack([_to_8bit(np.asarray(las[c])) for c in ("red", "green", "blue")], axis=1)
    return [Scan(points=xyz, intensity=intensity, colors=colors, path=path, name=path.stem)]


def _to_8bit(channel: NDArray[Any]) -> NDArray[np.uint8]:
    """One LAS colour channel (uint16) to uint8: 16-bit values >> 8, 8-bit values as they are."""
    c = channel.astype(np.uint16)
    if c.size and int(c.max()) > 255:
        return (c // 256).astype(np.uint8)
    return c.astype(np.uint8)
