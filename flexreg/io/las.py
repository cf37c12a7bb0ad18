"""ASPRS LAS / LAZ point clouds via laspy (LAZ through its lazrs backend).

LAS stores integer coordinates with a per-file scale and offset; laspy applies them, so the
points come out as float64 in the file's units (metres for almost every CRS in use). LAS has
no scanner grid and no sensor pose: points are usually already in a projected/world frame, so
``T_world_scanner`` is the identity.

A survey worker needs a station's points only: :func:`read_working` decodes the file in chunks
of :data:`WORKING_CHUNK_POINTS` points straight into float32 coordinates (12 bytes a point;
float64 when a coordinate lies beyond :data:`~flexreg.core.scan.FLOAT32_MAX_M`), where
:func:`read` holds every point record and its float64 coordinates at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory, format_bytes
from flexreg.core.scan import FLOAT32_MAX_M, POINT_BYTES, Scan
from flexreg.errors import InputError

__all__ = ["WORKING_CHUNK_POINTS", "check_declared_points", "read", "read_working", "write"]

#: points decoded per chunk by :func:`read_working`
WORKING_CHUNK_POINTS = 1 << 20

#: largest believable ratio of a LAZ file's points uncompressed to its size (LASzip reaches
#: 5-15 on real data; even constant points stay far below this)
MAX_LAZ_RATIO = 200


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
    with _opened(path) as (reader, declared):
        las = reader.read()
    n = len(las.points)
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


def read_working(path: Path, *, max_pixels: int) -> list[tuple[Scan, None]]:
    """A LAS or LAZ file as :func:`read` reads it, its points only, chunk by chunk.

    Parameters
    ----------
    path : Path
    max_pixels : int
        Unused (LAS has no grid: the caller projects the points); taken as every format's
        working reader takes it.

    Returns
    -------
    list of (Scan, None)
        One scan of the points (N, 3), float32 when every coordinate lies within
        :data:`~flexreg.core.scan.FLOAT32_MAX_M` (as :func:`flexreg.io.read_scan` makes them),
        else float64; no intensity or colour; no image.

    Raises
    ------
    InputError
        As :func:`read`.
    """
    del max_pixels
    try:
        return [(_read_points(path, None), None)]
    except _Wide:  # the header's bounds said float32 would do, and a point says otherwise
        return [(_read_points(path, np.float64), None)]


class _Wide(Exception):
    """Coordinates beyond :data:`FLOAT32_MAX_M` in a file read as float32."""


@contextmanager
def _opened(path: Path) -> Iterator[tuple[Any, int]]:
    """The file open in laspy and its declared point count (checked:
    :func:`check_declared_points`); laspy's and lazrs's errors in the block become an
    :class:`InputError` naming the file."""
    import laspy

    _check_signature(path)
    try:
        with laspy.open(path) as reader:
            declared = int(reader.header.point_count)
            if declared == 0:
                raise InputError(path, "LAS file holds no points (header point count 0)")
            check_declared_points(path, reader.header)
            yield reader, declared
    except (InputError, _Wide):
        raise
    except MemoryError:
        raise InputError(path, "out of memory while decoding the points") from None
    except Exception as exc:  # laspy and lazrs raise many kinds on broken headers and data
        raise InputError(path, f"not a readable LAS/LAZ file: {exc}") from None


def _read_points(path: Path, dtype: type | None) -> Scan:
    """The file's points as ``dtype``; None: float64 when the header's bounds reach beyond
    :data:`FLOAT32_MAX_M` (a georeferenced file, read once), else float32 (:class:`_Wide`
    when a point does after all)."""
    with _opened(path) as (reader, declared):
        if dtype is None:
            h = reader.header
            far = float(np.abs(np.concatenate([h.mins, h.maxs])).max())
            dtype = np.float64 if far > FLOAT32_MAX_M else np.float32
        points: NDArray[np.floating] = np.empty((declared, 3), dtype=dtype)
        n = 0
        for chunk in reader.chunk_iterator(WORKING_CHUNK_POINTS):
            m = min(len(chunk), declared - n)
            for k, axis in enumerate("xyz"):
                v = np.asarray(chunk[axis], dtype=np.float64)[:m]
                if dtype == np.float32 and m and np.abs(v).max() > FLOAT32_MAX_M:
                    raise _Wide()
                points[n : n + m, k] = v
            n += m
    if n != declared:
        raise InputError(path, f"truncated: the header declares {declared} points, {n} were read")
    if points.dtype == np.float64 and np.abs(points).max() <= FLOAT32_MAX_M:
        points = points.astype(np.float32)  # bounds wider than the points: float32 after all
    return Scan(points=points, path=path, name=path.stem)


def _check_signature(path: Path) -> None:
    """The ``LASF`` signature and a version 1.0-1.4, before laspy parses anything."""
    with open(path, "rb") as f:
        head = f.read(26)
    if len(head) < 26 or head[:4] != b"LASF":
        raise InputError(path, "not a LAS/LAZ file (no LASF signature)")
    major, minor = head[24], head[25]
    if major != 1 or minor > 4:
        raise InputError(path, f"LAS version {major}.{minor} is not supported (1.0 to 1.4)")


def check_declared_points(path: Path, header: Any) -> None:
    """Refuse a header whose point count the file cannot hold or the memory budget cannot take.

    An uncompressed LAS needs ``count x record length`` bytes after the header; a LAZ file
    cannot be smaller than :data:`MAX_LAZ_RATIO` times less than its points uncompressed.
    Raises
    ------
    InputError
        Naming the declared count, what it needs and what the file holds.
    """
    n = int(header.point_count)
    record = int(header.point_format.size)
    size = path.stat().st_size
    raw = n * record
    if header.are_points_compressed:
        if raw > MAX_LAZ_RATIO * size:
            raise InputError(
                path,
                f"header declares {n:,} points ({format_bytes(raw)} uncompressed) in a "
                f"{format_bytes(size)} LAZ file; that cannot be (corrupt header?)",
            )
    else:
        end = int(getattr(header, "start_of_first_evlr", 0) or 0) or size
        have = min(end, size) - int(header.offset_to_point_data)
        if raw > have:
            raise InputError(
                path,
                f"truncated: the header declares {n:,} points ({raw:,} bytes) but only "
                f"{max(have, 0):,} bytes of point data follow",
            )
        if have >= raw + record:
            extra = (have - raw) // record
            raise InputError(
                path,
                f"the header declares {n:,} points but the file holds data for {extra:,} more "
                "(wrong point count?)",
            )
    check_memory(n * (record + POINT_BYTES), f"{n:,} points", source=path)


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
