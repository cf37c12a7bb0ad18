"""PLY and PCD point clouds via open3d's tensor I/O, with the header checked here first.

open3d decodes the data (including PCL's ``binary_compressed``), but on a truncated or
malformed file it only logs a warning and may hand back a cloud padded with zeros. So the
header is parsed here and the data section's length (binary) or line and token count (ASCII)
is checked against it before open3d reads anything; the number of points open3d returns is
checked again afterwards. A PCD with ``HEIGHT > 1`` is organised: it keeps its
``HEIGHT x WIDTH`` grid (rows x columns, row-major) with NaN / all-zero cells as no-returns.
A PCD's ``VIEWPOINT`` (``tx ty tz qw qx qy qz``, PCL's sensor acquisition pose) becomes
``T_world_scanner``; PLY carries no pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.scan import FLOAT32_MAX_M, POINT_BYTES, Scan
from flexreg.core.transforms import matrix_to_quat, quat_to_matrix
from flexreg.errors import InputError

__all__ = ["is_mesh", "read", "write", "write_pcd"]

_INTENSITY_NAMES = ("intensity", "intensities", "scalar_intensity", "reflectance", "remission")
_PLY_TYPE_SIZE = {
    "char": 1, "int8": 1, "uchar": 1, "uint8": 1,
    "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
    "int": 4, "int32": 4, "uint": 4, "uint32": 4,
    "float": 4, "float32": 4, "double": 8, "float64": 8,
}  # fmt: skip
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_MAX_HEADER_LINES = 100_000


# --------------------------------------------------------------------------------- reading
def _starts_as_ply(path: Path) -> bool:
    """Whether the file begins with PLY's magic line (``ply`` and a line end)."""
    with open(path, "rb") as f:
        head = f.read(4)
    return head[:3] == b"ply" and head[3:4] in (b"\n", b"\r")


def is_mesh(path: Path) -> bool:
    """Whether ``path`` is a PLY triangle mesh (its header declares faces), not a point cloud.

    Only the header is read. A file that is not PLY, or whose header cannot be parsed, is not
    called a mesh here: reading it reports what is wrong with it.

    Parameters
    ----------
    path : Path

    Returns
    -------
    bool
        True when the header has a ``face`` element with at least one face.
    """
    try:
        if not _starts_as_ply(path):
            return False
        face = _parse_ply_header(path).element("face")
    except (OSError, InputError):
        return False
    return face is not None and face.count > 0


def read(path: Path, **options: Any) -> list[Scan]:
    """Read a PLY or PCD point cloud (one scan).

    The format is recognised from the file's first bytes (``ply`` magic or a PCD header), so
    a ``format=`` override on an odd suffix works.

    Parameters
    ----------
    path : Path
    **options
        None are accepted; an unknown option raises :class:`InputError`.

    Returns
    -------
    list of Scan
        One scan: ``points`` (N, 3) float64 (file units, metres expected), ``intensity``
        (N,) float32 if the file has an ``intensity`` / ``reflectance`` / ``scalar_intensity``
        attribute, ``colors`` (N, 3) uint8 if it has colours. An organised PCD also gives
        ``grid_shape = (HEIGHT, WIDTH)`` and ``grid_index``; NaN / Inf / ``(0, 0, 0)`` cells are
        no-returns. An unorganised cloud drops exact ``(0, 0, 0)`` points (a sensor's
        no-return placeholder) and refuses NaN / Inf coordinates.

    Raises
    ------
    InputError
        Unrecognised or malformed header, data shorter than the header promises (truncated),
        ASCII rows with missing or non-numeric values, no points, NaN / Inf coordinates in an
        unorganised cloud.
    """
    if options:
        raise InputError(path, f"unknown PLY/PCD option(s): {', '.join(sorted(options))}")
    if _starts_as_ply(path):
        ply = _parse_ply_header(path)
        _check_ply_data(path, ply)
        return [_read_ply(path, ply)]
    pcd = _parse_pcd_header(path)
    _check_pcd_data(path, pcd)
    return [_read_pcd(path, pcd)]


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list[tuple[str, str | None]] = field(default_factory=list)  # (name, type|None=list)

    @property
    def has_list(self) -> bool:
        return any(t is None for _, t in self.props)

    @property
    def stride(self) -> int:
        return sum(_PLY_TYPE_SIZE[t] for _, t in self.props if t is not None)


@dataclass
class _PlyHeader:
    format: str
    elements: list[_PlyElement]
    header_bytes: int

    def element(self, name: str) -> _PlyElement | None:
        return next((e for e in self.elements if e.name == name), None)


def _header_lines(path: Path, end: str) -> tuple[list[str], int]:
    """Header lines up to and including the one starting with ``end``; and the header length."""
    lines: list[str] = []
    with open(path, "rb") as f:
        for _ in range(_MAX_HEADER_LINES):
            raw = f.readline()
            if not raw:
                break
            line = raw.decode("latin-1").strip()
            lines.append(line)
            if line.split(" ", 1)[0] == end:
                return lines, f.tell()
    raise InputError(path, f"header has no '{end}' line (not a valid file, or truncated header)")


def _parse_ply_header(path: Path) -> _PlyHeader:
    lines, nbytes = _header_lines(path, "end_header")
    fmt = None
    elements: list[_PlyElement] = []
    for k, line in enumerate(lines[1:-1], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        bad = InputError(path, f"PLY header line {k} is malformed: {line[:60]!r}")
        if tok[0] == "format":
            if len(tok) != 3 or tok[1] not in _PLY_FORMATS:
                raise bad
            fmt = tok[1]
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise bad
            elements.append(_PlyElement(tok[1], int(tok[2])))
        elif tok[0] == "property":
            if not elements:
                raise bad
            if len(tok) == 5 and tok[1] == "list":
                if tok[2] not in _PLY_TYPE_SIZE or tok[3] not in _PLY_TYPE_SIZE:
                    raise bad
                elements[-1].props.append((tok[4], None))
            elif len(tok) == 3 and tok[1] in _PLY_TYPE_SIZE:
                elements[-1].props.append((tok[2], tok[1]))
            else:
                raise bad
        else:
            raise bad
    if fmt is None:
        raise InputError(path, "PLY header has no 'format' line")
    header = _PlyHeader(fmt, elements, nbytes)
    vertex = header.element("vertex")
    if vertex is None:
        raise InputError(path, "PLY file has no 'vertex' element")
    names = [n for n, _ in vertex.props]
    if not {"x", "y", "z"} <= set(names):
        raise InputError(path, f"PLY vertices have no x y z properties (have: {' '.join(names)})")
    if vertex.count == 0:
        raise InputError(path, "PLY file holds no points (element vertex 0)")
    return header


def _check_ply_data(path: Path, ply: _PlyHeader) -> None:
    size = path.stat().st_size - ply.header_bytes
    vertex = ply.element("vertex")
    assert vertex is not None
    _check_points_budget(path, vertex.count)
    if ply.format != "ascii":
        need = 0
        for el in ply.elements:  # every fixed-size element up to the first with lists
            if el.has_list:
                break
            need += el.count * el.stride
        if vertex.has_list:
            raise InputError(path, "PLY vertex element with list properties is not supported")
        if size < need:
            raise InputError(
                path,
                f"truncated: the header declares {vertex.count} vertices ({need} bytes of data) "
                f"but only {size} bytes follow it",
            )
        if not any(el.has_list for el in ply.elements) and size - need >= vertex.stride:
            raise InputError(
                path,
                f"the header declares {vertex.count} vertices but {size - need} more bytes of "
                "data follow them (wrong vertex count?)",
            )
        return
    with open(path, "rb") as f:
        f.seek(ply.header_bytes)
        rows = [r for r in f.read().splitlines() if r.strip()]
    start = 0
    for el in ply.elements:
        if el is vertex:
            break
        start += el.count
    total = sum(el.count for el in ply.elements)
    if len(rows) > total:
        raise InputError(
            path,
            f"the header declares {total} data rows but {len(rows)} follow (wrong vertex count?)",
        )
    # open3d's ASCII PLY parser stops at 'nan' / 'inf' and pads with zeros: refuse them here
    _check_ascii_rows(
        path, rows[start : start + vertex.count], vertex.count, len(vertex.props), finite=True
    )


def _check_points_budget(path: Path, n: int) -> None:
    """Refuse a declared point count the memory budget cannot take (before open3d reads)."""
    check_memory(n * POINT_BYTES, f"{n:,} points", source=path)


def _check_ascii_rows(
    path: Path, rows: list[bytes], n: int, n_values: int, *, finite: bool = False
) -> None:
    """Require ``n`` rows of ``n_values`` numbers each (NaN allowed unless ``finite``)."""
    if len(rows) < n:
        raise InputError(
            path, f"truncated: the header declares {n} points but {len(rows)} rows follow"
        )
    tokens = [r.split() for r in rows]
    short = [k for k, t in enumerate(tokens) if len(t) != n_values]
    if short:
        k = short[0]
        raise InputError(
            path, f"data row {k + 1} has {len(tokens[k])} values, expected {n_values} (truncated?)"
        )
    try:
        values = np.array([v for t in tokens for v in t], dtype=np.bytes_).astype(np.float64)
    except ValueError:
        raise InputError(path, "data rows hold non-numeric values") from None
    if finite and not np.isfinite(values).all():
        bad = int(np.count_nonzero(~np.isfinite(values.reshape(n, n_values)).all(axis=1)))
        raise InputError(path, f"{bad} of {n} rows hold NaN or Inf values")


def _read_ply(path: Path, ply: _PlyHeader) -> Scan:
    vertex = ply.element("vertex")
    assert vertex is not None
    attrs = _o3d_read(path, "ply")
    return _make_unorganised(path, attrs, vertex.count, np.eye(4))


@dataclass
class _PcdHeader:
    fields: list[str]
    sizes: list[int]
    types: list[str]
    counts: list[int]
    width: int
    height: int
    points: int
    viewpoint: list[float]
    data: str
    header_bytes: int

    @property
    def point_bytes(self) -> int:
        return sum(s * c for s, c in zip(self.sizes, self.counts, strict=True))


def _parse_pcd_header(path: Path) -> _PcdHeader:
    try:
        lines, nbytes = _header_lines(path, "DATA")
    except InputError:
        raise InputError(
            path, "neither a PLY nor a PCD file (no 'ply' magic, no PCD 'DATA' line)"
        ) from None
    entries: dict[str, list[str]] = {}
    for line in lines:
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        entries[tok[0].upper()] = tok[1:]

    def ints(key: str, default: list[int] | None = None) -> list[int]:
        if key not in entries:
            if default is not None:
                return default
            raise InputError(path, f"PCD header has no {key} line")
        try:
            return [int(v) for v in entries[key]]
        except ValueError:
            raise InputError(path, f"PCD header {key} is not a list of integers") from None

    fields = entries.get("FIELDS")
    if not fields:
        raise InputError(path, "PCD header has no FIELDS line")
    sizes = ints("SIZE")
    types = entries.get("TYPE", [])
    counts = ints("COUNT", [1] * len(fields))
    if not (len(sizes) == len(types) == len(counts) == len(fields)):
        raise InputError(path, "PCD header FIELDS / SIZE / TYPE / COUNT have different lengths")

    def one(key: str, default: int | None = None) -> int:
        values = ints(key, None if default is None else [default])
        if len(values) != 1:
            raise InputError(path, f"PCD header {key} needs one integer, has {len(values)}")
        return values[0]

    width, height = one("WIDTH"), one("HEIGHT")
    points = one("POINTS", width * height)
    if width < 0 or height < 0 or points != width * height:
        raise InputError(path, f"PCD header POINTS {points} != WIDTH {width} x HEIGHT {height}")
    if points == 0:
        raise InputError(path, "PCD file holds no points (POINTS 0)")
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(path, f"PCD has no x y z fields (has: {' '.join(fields)})")
    try:
        viewpoint = [float(v) for v in entries.get("VIEWPOINT", "0 0 0 1 0 0 0".split())]
    except ValueError:
        raise InputError(path, "PCD header VIEWPOINT is not numeric") from None
    if len(viewpoint) != 7:
        raise InputError(path, f"PCD header VIEWPOINT needs 7 numbers, has {len(viewpoint)}")
    data = (entries.get("DATA") or [""])[0].lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise InputError(path, f"PCD DATA {data!r} is not ascii, binary or binary_compressed")
    return _PcdHeader(fields, sizes, types, counts, width, height, points, viewpoint, data, nbytes)


def _check_pcd_data(path: Path, pcd: _PcdHeader) -> None:
    size = path.stat().st_size - pcd.header_bytes
    need = pcd.points * pcd.point_bytes
    _check_points_budget(path, pcd.points)
    if pcd.data == "binary":
        if size < need:
            raise InputError(
                path,
                f"truncated: the header declares {pcd.points} points ({need} bytes) "
                f"but only {size} bytes follow it",
            )
        if size - need >= pcd.point_bytes:
            raise InputError(
                path,
                f"the header declares {pcd.points} points but {size - need} more bytes of data "
                "follow them (wrong POINTS count?)",
            )
    elif pcd.data == "binary_compressed":
        with open(path, "rb") as f:
            f.seek(pcd.header_bytes)
            sizes = np.frombuffer(f.read(8), dtype="<u4")
        if len(sizes) != 2:
            raise InputError(path, "truncated: no compressed-data sizes after the PCD header")
        compressed, uncompressed = (int(v) for v in sizes)
        if uncompressed != need:
            raise InputError(
                path,
                f"compressed data unpacks to {uncompressed} bytes but {pcd.points} points "
                f"need {need}",
            )
        if size < 8 + compressed:
            raise InputError(
                path, f"truncated: {compressed} compressed bytes declared, {size - 8} present"
            )
    else:
        with open(path, "rb") as f:
            f.seek(pcd.header_bytes)
            rows = [r for r in f.read().splitlines() if r.strip()]
        if len(rows) > pcd.points:
            raise InputError(
                path,
                f"the header declares {pcd.points} points but {len(rows)} rows follow "
                "(wrong POINTS count?)",
            )
        _check_ascii_rows(path, rows, pcd.points, sum(pcd.counts))


def _read_pcd(path: Path, pcd: _PcdHeader) -> Scan:
    T = _viewpoint_pose(path, pcd.viewpoint)
    attrs = _o3d_read(path, "pcd")
    if pcd.height <= 1:
        return _make_unorganised(path, attrs, pcd.points, T)
    xyz = _positions(path, attrs, pcd.points)
    H, W = pcd.height, pcd.width
    intensity = _intensity(attrs)
    colors = _colors(attrs)
    return Scan.from_organized(
        xyz.reshape(H, W, 3),
        intensity=None if intensity is None else intensity.reshape(H, W),
        colors=None if colors is None else colors.reshape(H, W, 3),
        T_world_scanner=T,
        path=path,
        name=path.stem,
    )


def _viewpoint_pose(path: Path, vp: list[float]) -> NDArray[np.float64]:
    """``T_world_scanner`` from a PCD ``VIEWPOINT tx ty tz qw qx qy qz``."""
    q = np.asarray(vp[3:], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not np.all(np.isfinite(vp)) or norm < 1e-9:
        raise InputError(path, f"PCD VIEWPOINT {vp} is not a pose")
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(q, order="wxyz")
    T[:3, 3] = vp[:3]
    return T


def _o3d_read(path: Path, fmt: str) -> dict[str, NDArray[Any]]:
    """All point attributes open3d decodes, as numpy arrays keyed by open3d's names."""
    try:
        import open3d as o3d
    except ImportError as exc:  # its 400 MB library does not map under a small ulimit -v
        raise InputError(
            path,
            f"cannot read {fmt.upper()}: Open3D does not load ({exc}); too small a memory "
            "limit (ulimit -v)?",
        ) from None
    try:
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            pc = o3d.t.io.read_point_cloud(
                path, format=fmt, remove_nan_points=False, remove_infinite_points=False
            )
    except Exception as exc:
        raise InputError(path, f"open3d cannot read this {fmt.upper()} file: {exc}") from None
    return {str(k): pc.point[k].numpy() for k in pc.point}


def _positions(path: Path, attrs: dict[str, NDArray[Any]], n: int) -> NDArray[np.float64]:
    xyz = attrs.get("positions")
    if xyz is None or len(xyz) == 0:
        raise InputError(path, "no points could be decoded (corrupt file?)")
    if xyz.shape != (n, 3):
        raise InputError(path, f"decoded {len(xyz)} points but the header declares {n}")
    return np.asarray(xyz, dtype=np.float64)


def _make_unorganised(
    path: Path, attrs: dict[str, NDArray[Any]], n: int, T: NDArray[np.float64]
) -> Scan:
    xyz = _positions(path, attrs, n)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        raise InputError(
            path,
            f"{int(np.count_nonzero(~finite))} of {n} points have NaN or Inf coordinates "
            "in an unorganised cloud",
        )
    keep = np.any(xyz != 0.0, axis=1)
    if not keep.any():
        raise InputError(path, f"all {n} points are (0, 0, 0): no returns")
    intensity = _intensity(attrs)
    colors = _colors(attrs)
    return Scan(
        points=xyz[keep],
        intensity=None if intensity is None else intensity[keep],
        colors=None if colors is None else colors[keep],
        T_world_scanner=T,
        path=path,
        name=path.stem,
    )


def _intensity(attrs: dict[str, NDArray[Any]]) -> NDArray[np.float32] | None:
    by_lower = {k.lower(): k for k in attrs}
    for name in _INTENSITY_NAMES:
        if name in by_lower:
            a = attrs[by_lower[name]]
            if a.ndim == 1 or (a.ndim == 2 and a.shape[1] == 1):
                return np.asarray(a, dtype=np.float32).reshape(-1)
    return None


def _colors(attrs: dict[str, NDArray[Any]]) -> NDArray[np.uint8] | None:
    c = attrs.get("colors")
    if c is None or c.ndim != 2 or c.shape[1] != 3:
        return None
    if c.dtype == np.uint8:
        return c
    if c.dtype == np.uint16:
        return (c >> 8).astype(np.uint8)
    c = np.nan_to_num(np.asarray(c, dtype=np.float64))
    if c.size and c.max() <= 1.0:  # open3d's float colours live in [0, 1]
        c = c * 255.0
    return np.clip(np.rint(c), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------------- writing
def write(path: Path, scans: list[Scan], *, ascii: bool = False, world: bool = False) -> None:
    """Write one scan as PLY (``double x y z``, ``uchar red green blue``, ``float intensity``)
    or, by the suffix ``.pcd``, as PCD (:func:`write_pcd`).

    Parameters
    ----------
    path : Path
        Destination ``.ply`` (or ``.pcd``).
    scans : list of Scan
        Exactly one scan (PLY holds one cloud; use E57 or PTX for several).
    ascii : bool
        ASCII instead of binary little-endian.
    world : bool
        Write ``points_world()`` instead of the scanner-frame points. PLY has no pose field,
        so a written scan always reads back with an identity pose; grid rows/columns are not
        kept either.

    Raises
    ------
    InputError
        Not exactly one scan, an empty scan, or open3d failing to write.
    """
    import open3d as o3d

    if Path(path).suffix.lower() == ".pcd":
        write_pcd(path, scans, ascii=ascii, world=world)
        return
    if len(scans) != 1:
        raise InputError(path, f"a PLY file holds one scan, got {len(scans)} (write E57 or PTX)")
    scan = scans[0]
    if len(scan) == 0:
        raise InputError(path, "scan has no points to write")
    pc = o3d.t.geometry.PointCloud()
    pts = scan.points_world() if world else scan.points
    pc.point["positions"] = o3d.core.Tensor.from_numpy(np.ascontiguousarray(pts, dtype=np.float64))
    if scan.colors is not None:
        pc.point["colors"] = o3d.core.Tensor.from_numpy(
            np.ascontiguousarray(scan.colors, dtype=np.uint8)
        )
    if scan.intensity is not None:
        inten = np.ascontiguousarray(scan.intensity, dtype=np.float32).reshape(-1, 1)
        pc.point["intensity"] = o3d.core.Tensor.from_numpy(inten)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        ok = o3d.t.io.write_point_cloud(path, pc, write_ascii=bool(ascii))
    if not ok:
        raise InputError(path, "open3d could not write the PLY file")


def write_pcd(path: Path, scans: list[Scan], *, ascii: bool = False, world: bool = False) -> None:
    """Write one scan as an unorganised PCD (v0.7): ``x y z`` and ``intensity`` when the scan
    has intensities, its pose as ``VIEWPOINT tx ty tz qw qx qy qz``.

    Coordinates are ``float`` (4 bytes) when they all lie within
    :data:`~flexreg.core.scan.FLOAT32_MAX_M` of the origin (0.5 mm or better), else
    ``double``; colours and the grid are not kept. Identical scans give identical bytes.

    Parameters
    ----------
    path : Path
        Destination ``.pcd``.
    scans : list of Scan
        Exactly one scan.
    ascii : bool
        ``DATA ascii`` (17 significant digits) instead of ``DATA binary`` (little-endian).
    world : bool
        Write ``points_world()`` with an identity ``VIEWPOINT`` instead of the scanner-frame
        points with the scan's pose (what the reader turns back into ``T_world_scanner``).

    Raises
    ------
    InputError
        Not exactly one scan, or an empty scan.
    """
    if len(scans) != 1:
        raise InputError(path, f"a PCD file holds one scan, got {len(scans)} (write E57 or PTX)")
    scan = scans[0]
    if len(scan) == 0:
        raise InputError(path, "scan has no points to write")
    pts = np.asarray(scan.points_world() if world else scan.points, dtype=np.float64)
    T = np.eye(4) if world else np.asarray(scan.T_world_scanner, dtype=np.float64)
    q = matrix_to_quat(T[:3, :3], order="wxyz")
    wide = float(np.abs(pts).max()) > FLOAT32_MAX_M
    xyz_type, size = ("<f8", 8) if wide else ("<f4", 4)
    fields = [("x", xyz_type), ("y", xyz_type), ("z", xyz_type)]
    if scan.intensity is not None:
        fields.append(("intensity", "<f4"))
    rows = np.empty(len(pts), dtype=np.dtype(fields))
    rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if scan.intensity is not None:
        rows["intensity"] = np.asarray(scan.intensity, dtype=np.float32)
    names = [f[0] for f in fields]
    sizes = [str(size)] * 3 + (["4"] if scan.intensity is not None else [])
    viewpoint = " ".join(repr(float(v)) for v in (*T[:3, 3], *q))
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(names)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join('F' for _ in names)}\n"
        f"COUNT {' '.join('1' for _ in names)}\nWIDTH {len(pts)}\nHEIGHT 1\n"
        f"VIEWPOINT {viewpoint}\nPOINTS {len(pts)}\nDATA {'ascii' if ascii else 'binary'}\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        if ascii:
            for r in rows.tolist():
                f.write((" ".join(f"{float(v):.17g}" for v in r) + "\n").encode("ascii"))
        else:
            f.write(rows.tobytes())
