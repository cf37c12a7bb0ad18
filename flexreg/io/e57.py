"""ASTM E57 scans via pye57 (libE57Format): every scan of a file, its row/column grid and pose.

E57 stores each scan's points in the scanner's own frame together with a pose (unit quaternion
``w x y z`` + translation, metres) that maps them into the file's common frame, so the pose
becomes :attr:`Scan.T_world_scanner` and the points are left untouched. A gridded scan stores
only the points that hold a return, each with its ``rowIndex`` / ``columnIndex``; the grid size
comes from the scan's ``indexBounds``. The row and column directions are whatever the scanner
vendor chose (in the pump sample rows run upwards and columns against the azimuth); they are
kept as stored so that writing and reading back is exact.

A survey worker preparing a station needs only its points and its working image
(:func:`flexreg.stages.projection.working_image`): :func:`read_working` reads the fields it
needs in blocks of :data:`WORKING_BLOCK_POINTS` points, keeps each block's valid points as
float32 (float64 when a coordinate lies beyond :data:`~flexreg.core.scan.FLOAT32_MAX_M`) and
writes those on every ``k``-th row and column of the grid into the working image as they
stream past: 12 bytes a point, plus the image, plus one block of buffers, where :func:`read`
asks libE57Format for every field of every point at once as float64 (a 22 M-point
8192 x 4096 station: 2.7 GB at the peak of its preparation, 0.6 GB so). What is kept and which
point wins a pixel are those of :func:`read` followed by
:func:`flexreg.core.range_image.from_grid`.
"""

from __future__ import annotations

import hashlib
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.range_image import RangeImage, from_grid, working_stride
from flexreg.core.scan import FLOAT32_MAX_M, Scan
from flexreg.core.transforms import matrix_to_quat, quat_to_matrix
from flexreg.errors import InputError
from flexreg.io.e57_header import check_declared
from flexreg.io.selector import ScanRef, select_setup

__all__ = ["WORKING_BLOCK_POINTS", "headers", "read", "read_one", "read_working", "write"]

_CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
_COLORS = ("colorRed", "colorGreen", "colorBlue")


def read(path: Path, **options: Any) -> list[Scan]:
    """Read every scan of an E57 file.

    Parameters
    ----------
    path : Path
        The ``.e57`` file.
    **options
        None are accepted; an unknown option raises :class:`InputError`.

    Returns
    -------
    list of Scan
        One per ``data3D`` entry, in file order. Each holds

        - ``points`` (N, 3) float64, metres, scanner frame: the cartesian fields, or the
          spherical ones (range, azimuth, elevation) converted to cartesian when the cartesian
          ones are absent. Points whose ``cartesianInvalidState`` / ``sphericalInvalidState``
          is not 0 (1: direction only, 2: nothing valid) are dropped, as are exact
          ``(0, 0, 0)`` points; non-finite coordinates are no-returns in a gridded scan and an
          error otherwise.
        - ``grid_shape`` ``(rowMaximum + 1, columnMaximum + 1)`` from ``indexBounds`` (or the
          largest index + 1 if the bounds are missing or too small) and ``grid_index``
          ``(rowIndex, columnIndex)`` when both index fields are present.
        - ``intensity`` (N,) float32 and ``colors`` (N, 3) uint8 when present.
        - ``T_world_scanner`` (4, 4) from the scan's ``pose`` (identity when absent).
        - ``name`` from the scan's ``name`` (``"scan i"`` when absent).

    Raises
    ------
    InputError
        Unreadable or corrupt file, no scans, a scan without points or coordinates, or any
        field inconsistent with the point count.
    """
    _no_options(path, options)
    with _opened(path) as (e57, count):
        return [_read_checked(e57, i, path) for i in range(count)]


def read_one(path: Path, ref: ScanRef) -> Scan:
    """Read only the setup ``ref`` selects (by index or ``name``), as :func:`read` would.

    The other setups' points are not read: one station of a large project export costs its own
    points only.

    Raises
    ------
    InputError
        As :func:`read`, or a selector that matches no setup (the message lists them).
    """
    with _opened(path) as (e57, count):
        names = [_name(e57.get_header(i).node, i) for i in range(count)]
        return _read_checked(e57, select_setup(names, ref), path)


def headers(path: Path) -> list[tuple[str, int, NDArray[np.float64]]]:
    """``(name, stored point count, T_world_scanner)`` of every scan, without reading points.

    Raises
    ------
    InputError
        As :func:`read` for an unreadable file or pose.
    """
    out = []
    with _opened(path) as (e57, count):
        for i in range(count):
            try:
                h = e57.get_header(i)
                name = _name(h.node, i)
                label = f"scan {i} ({name})"
                out.append((name, int(h.point_count), _pose(h.node, path, label)))
            except InputError:
                raise
            except Exception as exc:
                raise InputError(path, f"scan {i} cannot be read: {_e57_message(exc)}") from None
    return out


@contextmanager
def _opened(path: Path) -> Iterator[tuple[Any, int]]:
    """The open pye57 file and its scan count (at least 1); closed on exit."""
    import pye57
    from pye57 import libe57

    check_declared(path)
    try:
        e57 = pye57.E57(str(path))
    except libe57.E57Exception as exc:
        raise InputError(path, f"not a readable E57 file: {_e57_message(exc)}") from None
    except Exception as exc:  # pye57 may raise plain Python errors as well
        raise InputError(path, f"not a readable E57 file: {exc}") from None
    try:
        try:
            count = e57.scan_count
        except Exception as exc:
            raise InputError(
                path, f"E57 file has no readable data3D list: {_e57_message(exc)}"
            ) from None
        if count == 0:
            raise InputError(path, "E57 file holds no scans (its data3D list is empty)")
        yield e57, count
    finally:
        e57.close()


def _read_checked(e57: Any, i: int, path: Path) -> Scan:
    try:
        return _read_one(e57, i, path)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(path, f"scan {i} cannot be read: {_e57_message(exc)}") from None


def _name(node: Any, i: int) -> str:
    return str(node["name"].value()) if node.isDefined("name") else f"scan {i}"


def _layout(e57: Any, i: int, path: Path) -> tuple[Any, str, str, set[str], int, bool | None]:
    """A scan's header (pye57's: its ``node``, its ``points``), name, label for messages,
    point fields and count, and whether its coordinates are spherical (None: neither
    cartesian nor spherical ones).

    Raises
    ------
    InputError
        The scan holds no points.
    """
    header = e57.get_header(i)
    node = header.node
    name = _name(node, i)
    label = f"scan {i} ({name})" if node.isDefined("name") else f"scan {i}"
    fields = set(header.point_fields)
    n_total = int(header.point_count)
    if n_total == 0:
        raise InputError(path, f"{label} holds no points")
    spherical = (
        False
        if all(f in fields for f in _CARTESIAN)
        else True
        if all(f in fields for f in _SPHERICAL)
        else None
    )
    return header, name, label, fields, n_total, spherical


def _cartesian(
    r: NDArray[np.float64], az: NDArray[np.float64], el: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Cartesian coordinates of E57 spherical ones (range, azimuth, elevation)."""
    with np.errstate(invalid="ignore"):
        return r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)


def _read_one(e57: Any, i: int, path: Path) -> Scan:
    header, name, label, _, n_total, spherical = _layout(e57, i, path)
    node = header.node
    data: dict[str, NDArray[Any]] = e57.read_scan_raw(i, ignore_unsupported_fields=True)
    for key, arr in data.items():
        if len(arr) != n_total:
            raise InputError(
                path, f"{label}: field {key} has {len(arr)} values for {n_total} points"
            )
    if spherical is None:
        raise InputError(path, f"{label} has neither cartesian nor spherical coordinates")
    coords = _SPHERICAL if spherical else _CARTESIAN
    columns = [np.asarray(data[f], dtype=np.float64) for f in coords]
    xyz = np.stack(_cartesian(*columns) if spherical else columns, axis=1)
    state_field = "sphericalInvalidState" if spherical else "cartesianInvalidState"

    keep: NDArray[np.bool_] = np.any(xyz != 0.0, axis=1)
    if state_field in data:
        keep = keep & (np.asarray(data[state_field]) == 0)

    gridded = "rowIndex" in data and "columnIndex" in data
    finite = np.asarray(np.isfinite(xyz).all(axis=1))
    if gridded:
        keep = keep & finite  # a NaN cell of a grid is a no-return, not a point
    elif not finite[keep].all():
        bad = int(np.count_nonzero(~finite[keep]))
        raise InputError(path, f"{label}: {bad} valid-flagged point(s) have NaN or Inf coordinates")
    if not keep.any():
        raise InputError(path, f"{label} holds no valid points ({n_total} all flagged invalid)")

    grid_shape: tuple[int, int] | None = None
    grid_index: NDArray[np.int32] | None = None
    if gridded:
        rows = np.asarray(data["rowIndex"], dtype=np.int64)[keep]
        cols = np.asarray(data["columnIndex"], dtype=np.int64)[keep]
        if rows.min() < 0 or cols.min() < 0:
            raise InputError(path, f"{label} has negative row/column indices")
        n_rows, n_cols = int(rows.max()) + 1, int(cols.max()) + 1
        if node.isDefined("indexBounds"):
            bounds = node["indexBounds"]
            if bounds.isDefined("rowMaximum") and bounds.isDefined("columnMaximum"):
                n_rows = max(n_rows, int(bounds["rowMaximum"].value()) + 1)
                n_cols = max(n_cols, int(bounds["columnMaximum"].value()) + 1)
        grid_shape = (n_rows, n_cols)
        grid_index = np.stack([rows, cols], axis=1).astype(np.int32)

    intensity = None
    if "intensity" in data:
        intensity = np.asarray(data["intensity"], dtype=np.float32)[keep]
    colors = None
    if all(c in data for c in _COLORS):
        colors = np.stack([np.asarray(data[c]) for c in _COLORS], axis=1)[keep].astype(np.uint8)

    return Scan(
        points=xyz[keep],
        intensity=intensity,
        colors=colors,
        grid_shape=grid_shape,
        grid_index=grid_index,
        T_world_scanner=_pose(node, path, label),
        path=path,
        name=name,
    )


def _pose(node: Any, path: Path, label: str) -> NDArray[np.float64]:
    """``T_world_scanner`` from a scan node's optional ``pose`` (quaternion w x y z + t)."""
    T = np.eye(4)
    if not node.isDefined("pose"):
        return T
    pose = node["pose"]
    if pose.isDefined("rotation"):
        rot = pose["rotation"]
        q = np.array([float(rot[k].value()) for k in ("w", "x", "y", "z")])
        norm = float(np.linalg.norm(q))
        if not np.isfinite(norm) or norm < 1e-9:
            raise InputError(
                path, f"{label}: pose rotation quaternion {q.tolist()} is not a rotation"
            )
        T[:3, :3] = quat_to_matrix(q, order="wxyz")
    if pose.isDefined("translation"):
        tr = pose["translation"]
        T[:3, 3] = [float(tr[k].value()) for k in ("x", "y", "z")]
    if not np.all(np.isfinite(T)):
        raise InputError(path, f"{label}: pose holds NaN or Inf")
    return T


def write(path: Path, scans: Sequence[Scan], **options: Any) -> None:
    """Write scans to one E57 file, coordinates in double precision.

    Each scan becomes a ``data3D`` entry with its name, pose (``T_world_scanner`` as quaternion
    ``wxyz`` + translation), ``indexBounds`` and ``rowIndex`` / ``columnIndex`` when it has a
    grid, ``intensity`` (float32) and ``colorRed/Green/Blue`` (0..255) when present.
    Reading the file back with :func:`read` returns the same points, grid, intensity and
    colours bit for bit and the same pose to rounding (~1e-16).

    Parameters
    ----------
    path : Path
        Destination (``write_scan`` passes a temporary name and renames it afterwards).
    scans : sequence of Scan
        At least one scan, each with at least one point. Walked three times in order
        (checks, content GUID, points), so a sequence that reads each scan when asked for
        writes a project without holding all of it in memory.

    Raises
    ------
    InputError
        No scans, an empty scan, a grid too large for E57's 16-bit index buffers in pye57,
        or a libE57 failure.
    """
    _no_options(path, options)
    from pye57 import libe57

    if not scans:
        raise InputError(path, "no scans to write")
    for i, s in enumerate(scans):
        if len(s) == 0:
            raise InputError(path, f"scan {i} ({s.name or 'unnamed'}) has no points to write")
        if s.grid_shape is not None and max(s.grid_shape) > np.iinfo(np.uint16).max + 1:
            raise InputError(path, f"scan {i}: grid {s.grid_shape} exceeds 65536 rows/columns")
    try:
        imf = libe57.ImageFile(str(path), "w")
    except Exception as exc:
        raise InputError(path, f"cannot create E57 file: {_e57_message(exc)}") from None
    try:
        data3d = _write_header(imf, libe57, _guid(b"file", *(_digest(s) for s in scans)))
        for i, s in enumerate(scans):
            _write_one(imf, data3d, libe57, s, i)
    except libe57.E57Exception as exc:
        raise InputError(path, f"E57 write failed: {_e57_message(exc)}") from None
    finally:
        imf.close()


def _digest(scan: Scan) -> bytes:
    """Content hash of a scan (points, grid, pose, attributes, name)."""
    h = hashlib.sha256()
    for a in (scan.points, scan.grid_index, scan.intensity, scan.colors, scan.T_world_scanner):
        h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
    h.update(scan.name.encode())
    return h.digest()


def _guid(*parts: bytes) -> str:
    """A GUID derived from content, so the same scans give byte-identical files."""
    digest = hashlib.sha256(b"".join(parts)).hexdigest()
    return f"{{{uuid.uuid5(uuid.NAMESPACE_OID, digest)}}}"


def _write_header(imf: Any, libe57: Any, guid: str) -> Any:
    """The E57 root elements (ASTM E2807 section 8.4.1); returns the data3D vector node."""
    root = imf.root()
    imf.extensionsAdd("", libe57.E57_V1_0_URI)
    root.set("formatName", libe57.StringNode(imf, "ASTM E57 3D Imaging Data File"))
    root.set("guid", libe57.StringNode(imf, guid))
    root.set("versionMajor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MAJOR))
    root.set("versionMinor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MINOR))
    root.set("e57LibraryVersion", libe57.StringNode(imf, libe57.E57_LIBRARY_ID))
    root.set("coordinateMetadata", libe57.StringNode(imf, ""))
    created = libe57.StructureNode(imf)
    created.set("dateTimeValue", libe57.FloatNode(imf, 0.0))
    created.set("isAtomicClockReferenced", libe57.IntegerNode(imf, 0))
    root.set("creationDateTime", created)
    data3d = libe57.VectorNode(imf, True)
    root.set("data3D", data3d)
    root.set("images2D", libe57.VectorNode(imf, True))
    return data3d


def _write_one(imf: Any, data3d: Any, libe57: Any, scan: Scan, i: int) -> None:
    n = len(scan)
    node = libe57.StructureNode(imf)
    node.set("guid", libe57.StringNode(imf, _guid(b"scan", str(i).encode(), _digest(scan))))
    node.set("name", libe57.StringNode(imf, scan.name or f"scan {i}"))
    node.set("description", libe57.StringNode(imf, "written by flexreg"))

    T = scan.T_world_scanner
    q = matrix_to_quat(T[:3, :3], order="wxyz")
    pose = libe57.StructureNode(imf)
    rot = libe57.StructureNode(imf)
    for axis, v in zip("wxyz", q, strict=True):
        rot.set(axis, libe57.FloatNode(imf, float(v)))
    tr = libe57.StructureNode(imf)
    for axis, v in zip("xyz", T[:3, 3], strict=True):
        tr.set(axis, libe57.FloatNode(imf, float(v)))
    pose.set("rotation", rot)
    pose.set("translation", tr)
    node.set("pose", pose)

    lo, hi = scan.points.min(axis=0), scan.points.max(axis=0)
    bounds = libe57.StructureNode(imf)
    for axis, a, b in zip("xyz", lo, hi, strict=True):
        bounds.set(f"{axis}Minimum", libe57.FloatNode(imf, float(a)))
        bounds.set(f"{axis}Maximum", libe57.FloatNode(imf, float(b)))
    node.set("cartesianBounds", bounds)

    proto = libe57.StructureNode(imf)
    columns: dict[str, NDArray[Any]] = {}
    for k, name in enumerate(_CARTESIAN):
        proto.set(name, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE))
        columns[name] = np.ascontiguousarray(scan.points[:, k], dtype=np.float64)
    if scan.intensity is not None:
        proto.set(
            "intensity",
            libe57.FloatNode(
                imf, 0.0, libe57.E57_SINGLE, libe57.E57_FLOAT_MIN, libe57.E57_FLOAT_MAX
            ),
        )
        columns["intensity"] = np.ascontiguousarray(scan.intensity, dtype=np.float32)
        limits = libe57.StructureNode(imf)
        limits.set("intensityMinimum", libe57.FloatNode(imf, float(scan.intensity.min())))
        limits.set("intensityMaximum", libe57.FloatNode(imf, float(scan.intensity.max())))
        node.set("intensityLimits", limits)
    if scan.colors is not None:
        limits = libe57.StructureNode(imf)
        for k, name in enumerate(_COLORS):
            proto.set(name, libe57.IntegerNode(imf, 0, 0, 255))
            columns[name] = np.ascontiguousarray(scan.colors[:, k], dtype=np.uint8)
            limits.set(f"{name}Minimum", libe57.IntegerNode(imf, 0))
            limits.set(f"{name}Maximum", libe57.IntegerNode(imf, 255))
        node.set("colorLimits", limits)
    if scan.grid_shape is not None and scan.grid_index is not None:
        rows, cols = scan.grid_shape
        proto.set("rowIndex", libe57.IntegerNode(imf, 0, 0, rows - 1))
        proto.set("columnIndex", libe57.IntegerNode(imf, 0, 0, cols - 1))
        columns["rowIndex"] = np.ascontiguousarray(scan.grid_index[:, 0], dtype=np.uint16)
        columns["columnIndex"] = np.ascontiguousarray(scan.grid_index[:, 1], dtype=np.uint16)
        ib = libe57.StructureNode(imf)
        for key, value in (
            ("rowMinimum", 0),
            ("rowMaximum", rows - 1),
            ("columnMinimum", 0),
            ("columnMaximum", cols - 1),
            ("returnMinimum", 0),
            ("returnMaximum", 0),
        ):
            ib.set(key, libe57.IntegerNode(imf, value))
        node.set("indexBounds", ib)

    points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
    node.set("points", points)
    data3d.append(node)  # the points must hang in the tree before they can be written

    buffers = libe57.VectorSourceDestBuffer()
    for name, arr in columns.items():
        buffers.append(libe57.SourceDestBuffer(imf, name, arr, n, True, True))
    writer = points.writer(buffers)
    writer.write(n)
    writer.close()


def _e57_message(exc: BaseException) -> str:
    """First line of a libE57 exception (the rest is a debug dump)."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _no_options(path: Path, options: dict[str, Any]) -> None:
    if options:
        raise InputError(path, f"unknown E57 option(s): {', '.join(sorted(options))}")


# ------------------------------------------------------------------ read block by block

#: points read per block (each field's buffer holds this many values: about 40 MB in all)
WORKING_BLOCK_POINTS = 1 << 20


def read_working(
    path: Path, *, max_pixels: int, ref: ScanRef | None = None
) -> list[tuple[Scan, RangeImage | None]]:
    """Every scan of an E57 file (or the one ``ref`` selects) as its points and working image.

    Parameters
    ----------
    path : Path
        The ``.e57`` file.
    max_pixels : int, pixels
        The working image's budget (:func:`~flexreg.core.range_image.working_stride`).
    ref : ScanRef, optional
        A ``FILE#N`` / ``FILE#NAME`` selector; only that scan's points are read.

    Returns
    -------
    list of (Scan, RangeImage or None)
        Per scan: a :class:`Scan` of its valid points (N, 3) float32 (float64 beyond
        :data:`~flexreg.core.scan.FLOAT32_MAX_M`), metres, scanner frame, in file order, with
        its pose and name but no grid, intensity or colour; and its working image (``xyz``
        (h, w, 3) of the points' type, ``valid``; ``index`` a read-only -1 view), or None for
        a scan without row and column indices (the caller projects it).

    Raises
    ------
    InputError
        As :func:`flexreg.io.e57.read`, and for a scan whose points end before its declared
        count.
    """
    with _opened(path) as (e57, count):
        if ref is None:
            chosen = list(range(count))
        else:
            names = [_name(e57.get_header(i).node, i) for i in range(count)]
            chosen = [select_setup(names, ref)]
        out = []
        for i in chosen:
            try:
                out.append(_read_retrying(e57, i, path, max_pixels))
            except InputError:
                raise
            except Exception as exc:
                msg = f"scan {i} cannot be read: {_e57_message(exc)}"
                raise InputError(path, msg) from None
        return out


class _Wide(Exception):
    """A scan read as float32 has coordinates beyond :data:`FLOAT32_MAX_M`."""


class _Beyond(Exception):
    """A point's row or column lies beyond the grid the scan's ``indexBounds`` declare."""


def _read_retrying(e57: Any, i: int, path: Path, max_pixels: int) -> tuple[Scan, RangeImage | None]:
    """:func:`_read` as float32 into an image of the declared grid; read again as float64
    when a coordinate is too far for float32, and keeping every index (the image made at
    the end, on the grid the indices span) when one lies beyond the declared grid."""
    dtype: type = np.float32
    bounded = True
    while True:
        try:
            return _read(e57, i, path, max_pixels, dtype, bounded)
        except _Wide:
            dtype = np.float64
        except _Beyond:
            bounded = False


def _grid_of(node: Any, fields: set[str]) -> tuple[int, int] | None:
    """The grid ``(rows, columns)`` a scan's ``indexBounds`` declare (None: no indices, or
    no bounds: the image is then made once the indices are all read)."""
    if "rowIndex" not in fields or "columnIndex" not in fields:
        return None
    if not node.isDefined("indexBounds"):
        return None
    b = node["indexBounds"]
    if not (b.isDefined("rowMaximum") and b.isDefined("columnMaximum")):
        return None
    return int(b["rowMaximum"].value()) + 1, int(b["columnMaximum"].value()) + 1


class _Image:
    """The working image of a grid with known bounds, filled block by block."""

    def __init__(self, grid: tuple[int, int], max_pixels: int, dtype: type) -> None:
        self.rows, self.cols = grid
        self.stride = working_stride(self.rows, self.cols, max_pixels)
        h, w = -(-self.rows // self.stride), -(-self.cols // self.stride)
        self.xyz: NDArray[np.floating] = np.full((h, w, 3), np.nan, dtype=dtype)
        self.valid = np.zeros((h, w), dtype=bool)

    def image(self) -> RangeImage:
        return RangeImage(self.xyz, self.valid, np.broadcast_to(np.int64(-1), self.valid.shape))


@numba.njit(cache=True, nogil=True)
def _keep_block(xyz_in, state, rows, cols, out, kept, grid):  # pragma: no cover - compiled
    """Append a block's valid points to ``points`` from row ``kept`` on, as
    :func:`flexreg.io.e57.read` keeps them: not ``(0, 0, 0)``, invalid state 0 (when
    ``state`` is not empty), finite (a non-finite point of a grid is a no-return; of a
    scan without grid, counted as bad). ``out``: ``(points, index, xyz, valid)``; each
    kept point's ``(row, column)`` goes to ``index`` when it is not empty, and, when the
    stride is not 0, the points on every ``stride``-th row and column into their pixel of
    ``xyz`` / ``valid`` (a later point wins). ``grid``: ``(stride, rows, columns, far)``.
    Returns the new number of kept points, the bad ones, whether an index lies beyond the
    grid and whether a coordinate lies beyond ``far``."""
    x, y, z = xyz_in
    points, index, xyz, valid = out
    s, n_rows, n_cols, far = grid
    has_state, gridded, keep_index = state.shape[0] > 0, rows.shape[0] > 0, index.shape[0] > 0
    bad, beyond, wide = 0, False, False
    for i in range(x.shape[0]):
        xi, yi, zi = x[i], y[i], z[i]
        if (xi == 0.0 and yi == 0.0 and zi == 0.0) or (has_state and state[i] != 0):
            continue
        if not (np.isfinite(xi) and np.isfinite(yi) and np.isfinite(zi)):
            if not gridded:
                bad += 1
            continue
        if abs(xi) > far or abs(yi) > far or abs(zi) > far:
            wide = True
        points[kept, 0] = xi
        points[kept, 1] = yi
        points[kept, 2] = zi
        if gridded:
            r, c = np.int64(rows[i]), np.int64(cols[i])
            if keep_index:
                index[kept, 0] = r
                index[kept, 1] = c
            elif s > 0:
                if r >= n_rows or c >= n_cols:
                    beyond = True
                elif r % s == 0 and c % s == 0:
                    xyz[r // s, c // s, 0] = points[kept, 0]
                    xyz[r // s, c // s, 1] = points[kept, 1]
                    xyz[r // s, c // s, 2] = points[kept, 2]
                    valid[r // s, c // s] = True
        kept += 1
    return kept, bad, beyond, wide


def _block_xyz(
    data: dict[str, NDArray[Any]], n: int, spherical: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A block's cartesian coordinates, three (n,) float64 arrays."""
    if not spherical:
        return data["cartesianX"][:n], data["cartesianY"][:n], data["cartesianZ"][:n]
    r, az, el = (data[f][:n] for f in _SPHERICAL)
    return _cartesian(r, az, el)


def _read(
    e57: Any, i: int, path: Path, max_pixels: int, dtype: type, bounded: bool
) -> tuple[Scan, RangeImage | None]:
    """One scan of the open file read block by block (:func:`read_working`); ``bounded``:
    the image is filled as the blocks stream past when the scan declares its grid."""
    header, name, label, fields, n_total, spherical = _layout(e57, i, path)
    node = header.node
    if spherical is None:
        raise InputError(path, f"{label} has neither cartesian nor spherical coordinates")
    coords = _SPHERICAL if spherical else _CARTESIAN
    state = "sphericalInvalidState" if spherical else "cartesianInvalidState"
    gridded = "rowIndex" in fields and "columnIndex" in fields
    wanted = [*coords, *([state] if state in fields else [])]
    wanted += ["rowIndex", "columnIndex"] if gridded else []
    block = min(n_total, WORKING_BLOCK_POINTS)
    size = np.dtype(dtype).itemsize
    check_memory(3 * size * n_total, f"{label}: its {n_total:,} points", source=path)
    from pye57 import libe57

    data, buffers = {}, libe57.VectorSourceDestBuffer()
    for f in wanted:
        data[f], buf = e57.make_buffer(f, block)
        buffers.append(buf)
    grid = _grid_of(node, fields)
    image = _Image(grid, max_pixels, dtype) if grid is not None and bounded else None
    points: NDArray[np.floating] = np.empty((n_total, 3), dtype=dtype)
    # every kept point's (row, column) when the image is made at the end
    index = np.empty((n_total if gridded and image is None else 0, 2), dtype=np.int32)
    img = image or _Image((1, 1), 1, dtype)  # a 1-pixel stand-in the kernel never writes
    no_state, no_index = np.zeros(0, dtype=np.int8), np.zeros(0, dtype=np.uint16)
    far = FLOAT32_MAX_M if dtype == np.float32 else np.inf
    kept = seen = 0
    reader = header.points.reader(buffers)
    try:
        while (n := int(reader.read())) > 0:
            x, y, z = _block_xyz(data, n, spherical)
            kept, bad, beyond, wide = _keep_block(
                (x, y, z),
                data[state][:n] if state in data else no_state,
                data["rowIndex"][:n] if gridded else no_index,
                data["columnIndex"][:n] if gridded else no_index,
                (points, index, img.xyz, img.valid),
                kept,
                (img.stride if image is not None else 0, img.rows, img.cols, far),
            )
            if bad:
                raise InputError(
                    path, f"{label}: {bad} valid-flagged point(s) have NaN or Inf coordinates"
                )
            if wide:
                raise _Wide()
            if beyond:
                raise _Beyond()
            seen += n
    finally:
        reader.close()
    if seen != n_total:
        raise InputError(path, f"{label}: {seen:,} of its {n_total:,} points could be read")
    if kept == 0:
        raise InputError(path, f"{label} holds no valid points ({n_total} all flagged invalid)")
    points.resize((kept, 3), refcheck=False)  # in place: no second copy of the points
    scan = Scan(points=points, T_world_scanner=_pose(node, path, label), path=path, name=name)
    if image is not None:
        return scan, image.image()
    if not gridded:
        return scan, None
    index.resize((kept, 2), refcheck=False)
    return scan, _image_from_indices(scan, index, grid, max_pixels)


def _image_from_indices(
    scan: Scan, index: NDArray[np.int32], grid: tuple[int, int] | None, max_pixels: int
) -> RangeImage:
    """The working image of a gridded scan whose grid is known only once every index is read
    (no ``indexBounds``, or indices beyond them): the grid the indices span, at least the
    declared one, as :func:`flexreg.io.e57.read` sizes it."""
    rows, cols = int(index[:, 0].max()) + 1, int(index[:, 1].max()) + 1
    if grid is not None:
        rows, cols = max(rows, grid[0]), max(cols, grid[1])
    gridded = Scan(points=scan.points, grid_shape=(rows, cols), grid_index=index)
    img = from_grid(gridded, stride=working_stride(rows, cols, max_pixels))
    return RangeImage(img.xyz, img.valid, np.broadcast_to(np.int64(-1), img.valid.shape))
