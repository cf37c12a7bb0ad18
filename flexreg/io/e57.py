"""ASTM E57 scans via pye57 (libE57Format): every scan of a file, its row/column grid and pose.

E57 stores each scan's points in the scanner's own frame together with a pose (unit quaternion
``w x y z`` + translation, metres) that maps them into the file's common frame, so the pose
becomes :attr:`Scan.T_world_scanner` and the points are left untouched. A gridded scan stores
only the points that hold a return, each with its ``rowIndex`` / ``columnIndex``; the grid size
comes from the scan's ``indexBounds``. The row and column directions are whatever the scanner
vendor chose (in the pump sample rows run upwards and columns against the azimuth); they are
kept as stored so that writing and reading back is exact.
"""

from __future__ import annotations

import hashlib
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import matrix_to_quat, quat_to_matrix
from flexreg.errors import InputError
from flexreg.io.e57_header import check_declared
from flexreg.io.selector import ScanRef, select_setup

__all__ = ["headers", "read", "read_one", "write"]

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


def _read_one(e57: Any, i: int, path: Path) -> Scan:
    header = e57.get_header(i)
    node = header.node
    named = node.isDefined("name")
    name = _name(node, i)
    label = f"scan {i} ({name})" if named else f"scan {i}"
    fields = set(header.point_fields)
    n_total = int(header.point_count)
    if n_total == 0:
        raise InputError(path, f"{label} holds no points")

    data: dict[str, NDArray[Any]] = e57.read_scan_raw(i, ignore_unsupported_fields=True)
    for key, arr in data.items():
        if len(arr) != n_total:
            raise InputError(
                path, f"{label}: field {key} has {len(arr)} values for {n_total} points"
            )

    if all(f in fields for f in _CARTESIAN):
        xyz = np.stack([np.asarray(data[f], dtype=np.float64) for f in _CARTESIAN], axis=1)
        state_field = "cartesianInvalidState"
    elif all(f in fields for f in _SPHERICAL):
        rng, az, el = (np.asarray(data[f], dtype=np.float64) for f in _SPHERICAL)
        with np.errstate(invalid="ignore"):
            xyz = np.stack(
                [rng * np.cos(el) * np.cos(az), rng * np.cos(el) * np.sin(az), rng * np.sin(el)],
                axis=1,
            )
        state_field = "sphericalInvalidState"
    else:
        raise InputError(path, f"{label} has neither cartesian nor spherical coordinates")

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
