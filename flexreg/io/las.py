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

__all__ = ["read", "write"]


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


def write(path: Path, scans: list[Scan], *, resolution_m: float = 1e-4, **options: Any) -> None:
    """Write one scan as LAS 1.4 (LAZ when the suffix is ``.laz``), coordinates in the file's
    frame at ``resolution_m``.

    The LAS offset is the floor of the points' minimum (whole metres), so georeferenced
    coordinates (UTM eastings of 10^5-10^6 m) keep ``resolution_m`` precision in LAS's 32-bit
    integers: the scan may span up to ``2^31 * resolution_m`` (214 km at 0.1 mm) per axis.
    Intensity is rounded and clipped to LAS's 16 bits; colours (0..255) are stored as 16-bit
    values ``c * 257``. LAS has no scanner pose: ``T_world_scanner`` is not written.

    Raises
    ------
    InputError
        More than one scan, an unknown option, or a scan too large for the resolution.
    """
    if options:
        raise InputError(path, f"unknown LAS option(s): {', '.join(sorted(options))}")
    if len(scans) != 1:
        raise InputError(path, f"LAS holds one scan, got {len(scans)}: write one file each")
    import laspy

    (scan,) = scans
    pts = scan.points
    offset = np.floor(pts.min(axis=0)) if len(pts) else np.zeros(3)
    if len(pts) and float((pts.max(axis=0) - offset).max()) / resolution_m >= 2**31 - 1:
        raise InputError(path, f"the scan spans too far for {resolution_m} m LAS resolution")
    header = laspy.LasHeader(point_format=2 if scan.colors is not None else 0, version="1.4")
    header.offsets = offset
    header.scales = np.full(3, resolution_m)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    if scan.intensity is not None:
        las.intensity = np.clip(np.rint(scan.intensity), 0, 65535).astype(np.uint16)
    if scan.colors is not None:
        for k, c in enumerate(("red", "green", "blue")):
            las[c] = scan.colors[:, k].astype(np.uint16) * 257
    las.write(str(path), do_compress=path.suffix.lower() == ".laz")


def _to_8bit(channel: NDArray[Any]) -> NDArray[np.uint8]:
    """One LAS colour channel (uint16) to uint8: 16-bit values >> 8, 8-bit values as they are."""
    c = channel.astype(np.uint16)
    if c.size and int(c.max()) > 255:
        return (c // 256).astype(np.uint8)
    return c.astype(np.uint8)
