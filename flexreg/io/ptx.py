"""Leica PTX (ASCII) reader and writer.

Layout of one cloud (a file may hold several, one after another)::

    COLS
    ROWS
    sx sy sz                 scanner position in the registered frame
    ax ay az                 scanner x axis  (3 lines: the axes as rows)
    bx by bz                 scanner y axis
    cx cy cz                 scanner z axis
    m00 m10 m20 m30          the 4x4 transform written TRANSPOSED:
    m01 m11 m21 m31          translation on the 4th line
    m02 m12 m22 m32
    m03 m13 m23 m33
    x y z i [r g b]          COLS*ROWS lines, column by column (all rows of column 0 first)

Points are in the scanner's own frame; ``0 0 0`` marks a cell with no return, which is not a
point. The parser is a parallel numba kernel over the raw bytes (tens of millions of points per
second), validating every line: a wrong value count, a non-number, NaN/Inf or a truncated cloud
raises :class:`~flexreg.errors.InputError` naming the file and the line.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from pathlib import Path

import numba
import numpy as np
from numba import prange
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.range_image import RangeImage, working_stride
from flexreg.core.scan import FLOAT32_MAX_M, Scan
from flexreg.core.transforms import is_rigid
from flexreg.errors import InputError
from flexreg.io._ptx_parse import POW10, TOO_MANY, parse_all

log = logging.getLogger(__name__)

_HEADER_LINES = 10


# ------------------------------------------------------------------------------ reader

_HEADER_COUNTS = [1, 1, 3, 3, 3, 3, 4, 4, 4, 4]
#: bytes of text parsed at a time: the parser's buffers are bounded by this, not by the file
_CHUNK_BYTES = 1 << 26
#: shortest possible point line (``0 0 0`` and its newline), bytes: bounds a cloud's lines
_MIN_LINE_BYTES = 6
#: smaller files are parsed in chunks of an eighth of their size, down to this: the parsed
#: values of a chunk take 1.3 times its text, so a chunk as large as the whole file would add
#: 2.3 times its size to the scan being read
_MIN_CHUNK_BYTES = 1 << 24


def _chunk_bytes(size: int) -> int:
    """Bytes of text parsed at a time in a file of ``size`` bytes: an eighth of the file
    between :data:`_MIN_CHUNK_BYTES` and :data:`_CHUNK_BYTES` (larger chunks are fewer
    parallel regions, which a loaded machine starts slowly)."""
    return min(_CHUNK_BYTES, max(_MIN_CHUNK_BYTES, size // 8))


@numba.njit(cache=True, nogil=True)
def _last_newline(buf: NDArray[np.uint8], n: int) -> int:
    """Index of the last ``\\n`` in ``buf[:n]``, -1 when there is none."""
    for i in range(n - 1, -1, -1):
        if buf[i] == 10:
            return i
    return -1


Lines = tuple[NDArray[np.float64], NDArray[np.float32], NDArray[np.int8], NDArray[np.int8]]


#: one parallel parse at a time: files read in several threads share the cores through the
#: parser's own threads (not every numba threading layer accepts concurrent parallel calls)
_PARSE_LOCK = threading.Lock()


def _parse(buf: NDArray[np.uint8]) -> Lines:
    n_chunks = numba.get_num_threads() * max(1, min(64, buf.shape[0] >> 22))
    with _PARSE_LOCK:
        return parse_all(buf, n_chunks, POW10)


def _chunks(path: Path, size: int, chunk: int | None = None) -> Iterator[tuple[int, Lines]]:
    """The file's lines parsed about :data:`_CHUNK_BYTES` at a time (whole lines only):
    ``(offset of the chunk's first byte, (head, tail, counts, errors))`` of
    :func:`parse_all`. One buffer is reused; it grows only for a line longer than a chunk.
    ``chunk``: bytes per chunk instead of :func:`_chunk_bytes`."""
    buf = np.empty(min(chunk or _chunk_bytes(size), max(size, 1)), dtype=np.uint8)
    filled, offset = 0, 0
    with open(path, "rb") as f:
        while True:
            if filled == len(buf):  # one line fills the buffer: grow it
                check_memory(2 * len(buf), "a line longer than the buffer", source=path)
                buf = np.concatenate([buf, np.empty_like(buf)])
            got = f.readinto(memoryview(buf)[filled:])  # type: ignore[arg-type]
            if not got:
                if filled:  # the last line has no newline
                    yield offset, _parse(buf[:filled])
                return
            filled += got
            cut = _last_newline(buf, filled) + 1
            if cut == 0:
                continue
            yield offset, _parse(buf[:cut])
            rest = filled - cut
            buf[:rest] = buf[cut:filled].copy()
            offset += cut
            filled = rest


_NO_INTENSITY = np.empty(0, dtype=np.float32)
_NO_COLORS = np.empty((0, 3), dtype=np.uint8)


@numba.njit(cache=True, nogil=True)
def _keep_valid(
    head, tail, lo, hi, seen, rows, kept, points, grid_index, intensity, colors
):  # pragma: no cover - compiled
    """Append the valid points (not ``0 0 0``) of parsed lines ``lo:hi`` to the cloud's arrays
    from row ``kept`` on: point, grid cell (line ``k`` of the cloud, ``k = seen + i - lo``, is
    row ``k % rows`` of column ``k // rows``), intensity and colour (clipped to 0..255) when
    those arrays are not empty. Returns the new number of kept points."""
    has_i = intensity.shape[0] > 0
    has_c = colors.shape[0] > 0
    for i in range(lo, hi):
        x, y, z = head[i, 0], head[i, 1], head[i, 2]
        if x == 0.0 and y == 0.0 and z == 0.0:
            continue
        points[kept, 0] = x
        points[kept, 1] = y
        points[kept, 2] = z
        k = seen + i - lo
        grid_index[kept, 0] = k % rows
        grid_index[kept, 1] = k // rows
        if has_i:
            intensity[kept] = head[i, 3]
        if has_c:
            for j in range(3):
                colors[kept, j] = np.uint8(min(max(tail[i, j], np.float32(0)), np.float32(255)))
        kept += 1
    return kept


@numba.njit(cache=True, nogil=True)
def _keep_valid_image(
    head, lo, hi, seen, rows, kept, points, xyz, valid, stride
):  # pragma: no cover - compiled
    """:func:`_keep_valid` without grid index, intensity or colour: each valid point of lines
    ``lo:hi`` is appended to ``points`` and, when it lies on every ``stride``-th row and
    column of the grid, also written into its pixel of the working image ``xyz`` / ``valid``
    (as :func:`flexreg.core.range_image.from_grid` gathers it). Returns the new number of
    kept points."""
    # the grid cell of line lo, then followed line by line (no divisions per point): row r,
    # column c; the pixel (r // stride, c // stride) when both are multiples of stride
    r = seen % rows
    c = seen // rows
    on_column = c % stride == 0
    for i in range(lo, hi):
        x, y, z = head[i, 0], head[i, 1], head[i, 2]
        if not (x == 0.0 and y == 0.0 and z == 0.0):
            points[kept, 0] = x
            points[kept, 1] = y
            points[kept, 2] = z
            if on_column and (stride == 1 or r % stride == 0):
                pr = r if stride == 1 else r // stride
                pc = c if stride == 1 else c // stride
                xyz[pr, pc, 0] = points[kept, 0]
                xyz[pr, pc, 1] = points[kept, 1]
                xyz[pr, pc, 2] = points[kept, 2]
                valid[pr, pc] = True
            kept += 1
        r += 1
        if r == rows:
            r = 0
            c += 1
            on_column = c % stride == 0
    return kept


class _Cloud:
    """One cloud's point lines as they stream past: valid points written straight into their
    final arrays (no file- or line-sized intermediate); problems are kept in the order
    :func:`read` reports them and raised once the cloud's lines are all seen."""

    def __init__(
        self,
        path: Path,
        index: int,
        first: int,
        rows: int,
        cols: int,
        cap: int,
        dtype: type,
        intensity: bool = True,
        stride: int | None = None,
    ):
        self.dtype, self.keep_intensity, self.stride = dtype, intensity and not stride, stride
        self.image: RangeImage | None = None
        self.xyz: NDArray[np.floating] | None = None
        self.valid: NDArray[np.bool_] | None = None
        self.path, self.index, self.first, self.rows, self.cols = path, index, first, rows, cols
        self.n, self.cap, self.seen, self.kept = rows * cols, cap, 0, 0
        self.ncol = -1
        self.bad: tuple[int, int] | None = None  # (line, error code) of the first bad number
        self.wrong: tuple[int, int] | None = None  # (line, count) of the first ragged line
        self.points: NDArray[np.floating] | None = None
        self.grid_index: NDArray[np.int32] | None = None
        self.intensity: NDArray[np.float32] | None = None
        self.colors: NDArray[np.uint8] | None = None

    @property
    def remaining(self) -> int:
        return self.n - self.seen

    def _allocate(self, ncol: int) -> None:
        cap = self.cap
        if self.stride:  # points and the working image only
            s = self.stride
            h, w = -(-self.rows // s), -(-self.cols // s)
            size = np.dtype(self.dtype).itemsize
            what = f"cloud {self.index}: its {self.n:,} points"
            check_memory(3 * size * (cap + h * w), what, source=self.path)
            self.points = np.empty((cap, 3), dtype=self.dtype)
            self.xyz = np.full((h, w, 3), np.nan, dtype=self.dtype)
            self.valid = np.zeros((h, w), dtype=bool)
            return
        per = (
            3 * np.dtype(self.dtype).itemsize
            + 8
            + (4 if ncol >= 4 and self.keep_intensity else 0)
            + (3 if ncol == 7 else 0)
        )
        check_memory(cap * per, f"cloud {self.index}: its {self.n:,} points", source=self.path)
        self.points = np.empty((cap, 3), dtype=self.dtype)
        self.grid_index = np.empty((cap, 2), dtype=np.int32)
        keep = ncol >= 4 and self.keep_intensity
        self.intensity = np.empty(cap, dtype=np.float32) if keep else None
        self.colors = np.empty((cap, 3), dtype=np.uint8) if ncol == 7 else None

    def add(self, lines: Lines, lo: int, hi: int, line0: int) -> None:
        """Take lines ``lo:hi`` of a parsed chunk whose line ``lo`` is file line ``line0``."""
        _, _, counts, errors = lines
        if self.seen == 0:
            self.ncol = int(counts[lo])
            if self.ncol in (3, 4, 7):
                self._allocate(self.ncol)
        if self.bad is None:
            bad = np.flatnonzero(errors[lo:hi])
            if len(bad):
                self.bad = (line0 + int(bad[0]), int(errors[lo + bad[0]]))
        if self.wrong is None:
            wrong = np.flatnonzero(counts[lo:hi] != self.ncol)
            if len(wrong):
                self.wrong = (line0 + int(wrong[0]), int(counts[lo + wrong[0]]))
        if self.bad is None and self.wrong is None and self.points is not None:
            self._keep(lines, lo, hi)
        self.seen += hi - lo

    def _keep(self, lines: Lines, lo: int, hi: int) -> None:
        """Copy the valid points (not ``0 0 0``) of lines ``lo:hi`` and their attributes."""
        head, tail, _, _ = lines
        if self.stride:
            assert self.points is not None and self.xyz is not None and self.valid is not None
            self.kept = _keep_valid_image(
                head,
                lo,
                hi,
                self.seen,
                self.rows,
                self.kept,
                self.points,
                self.xyz,
                self.valid,
                self.stride,
            )
            return
        assert self.points is not None and self.grid_index is not None
        self.kept = _keep_valid(
            head,
            tail,
            lo,
            hi,
            self.seen,
            self.rows,
            self.kept,
            self.points,
            self.grid_index,
            _NO_INTENSITY if self.intensity is None else self.intensity,
            _NO_COLORS if self.colors is None else self.colors,
        )

    def truncated(self) -> InputError:
        return InputError(
            self.path,
            f"cloud {self.index}: header announces {self.cols} x {self.rows} = {self.n} points "
            f"but only {self.seen} lines follow (truncated file?)",
        )

    def finish(self, M: NDArray[np.float64]) -> Scan:
        """The scan, once all its lines are seen (raises the first problem found)."""
        path = self.path
        if self.bad is not None:
            k, err = self.bad
            what = "more than 7 values" if err == TOO_MANY else "not a valid number"
            raise InputError(path, f"line {k + 1}: {what}")
        if self.ncol not in (3, 4, 7):
            raise InputError(
                path, f"line {self.first + 1}: expected 3, 4 or 7 values, got {self.ncol}"
            )
        if self.wrong is not None:
            k, cnt = self.wrong
            raise InputError(
                path,
                f"line {k + 1}: expected {self.ncol} values like the cloud's first point, got "
                f"{cnt} (header {self.cols} x {self.rows} does not match the data?)",
            )
        m = self.kept
        for a in (self.points, self.grid_index, self.intensity, self.colors):
            if a is not None:  # shrink in place: no second copy of the points
                a.resize((m, *a.shape[1:]), refcheck=False)
        if self.dtype == np.float32 and m and self.points is not None:
            lo, hi = float(self.points.min()), float(self.points.max())
            if not (-FLOAT32_MAX_M <= lo and hi <= FLOAT32_MAX_M):
                raise _Wide()
        if self.intensity is not None and m and not np.isfinite(self.intensity).all():
            raise InputError(path, f"cloud {self.index}: an intensity beyond float32's range")
        if not is_rigid(M):
            log.warning("%s: cloud %d has a non-rigid transform (kept as given)", path, self.index)
        if self.stride:
            assert self.xyz is not None and self.valid is not None
            self.image = RangeImage(
                self.xyz, self.valid, np.broadcast_to(np.int64(-1), self.valid.shape)
            )
        try:
            return Scan(
                points=self.points,  # type: ignore[arg-type]
                intensity=self.intensity,
                colors=self.colors,
                grid_shape=None if self.stride else (self.rows, self.cols),
                grid_index=None if self.stride else self.grid_index,
                T_world_scanner=M,
                path=path,
                name=path.stem if self.index == 0 else f"{path.stem}#{self.index}",
            )
        except InputError as e:
            raise InputError(path, f"cloud {self.index}: {e.problem}") from None


def _header_cloud(
    path: Path,
    index: int,
    line: int,
    head: list[NDArray[np.float64]],
    counts: list[int],
    errors: list[int],
    bytes_left: int,
    dtype: type,
    intensity: bool = True,
    max_pixels: int | None = None,
) -> tuple[_Cloud, NDArray[np.float64]]:
    """The cloud a complete 10-line header (starting at file line ``line``) announces, and its
    pose; ``bytes_left`` bounds how many point lines can follow."""
    if any(errors) or counts != _HEADER_COUNTS:
        raise InputError(
            path,
            f"cloud {index}: malformed header at lines {line + 1}-{line + _HEADER_LINES} "
            "(expected COLS, ROWS, position, 3 axes, transposed 4x4 transform)",
        )
    cols_f, rows_f = head[0][0], head[1][0]
    if cols_f != int(cols_f) or rows_f != int(rows_f) or cols_f <= 0 or rows_f <= 0:
        raise InputError(path, f"cloud {index}: grid size {cols_f:g} x {rows_f:g} is not valid")
    cols, rows = int(cols_f), int(rows_f)
    if rows * cols >= 2**62:  # no file holds that many lines; the counters are 64-bit
        raise InputError(
            path, f"cloud {index}: grid size {cols_f:g} x {rows_f:g} is not valid (too large)"
        )
    M = header_pose(np.stack(head[2:10])[:, :4])
    cap = min(rows * cols, bytes_left // _MIN_LINE_BYTES + 1)
    stride = None if max_pixels is None else working_stride(rows, cols, max_pixels)
    cloud = _Cloud(path, index, line + _HEADER_LINES, rows, cols, cap, dtype, intensity, stride)
    return cloud, M


class _Wide(Exception):
    """A cloud read as float32 has coordinates beyond :data:`FLOAT32_MAX_M`."""


def read(path: Path, *, precise: bool = False, intensity: bool = True, **_: object) -> list[Scan]:
    """Read every cloud of a PTX file.

    The text is parsed 16 to 64 MiB at a time (:func:`_chunk_bytes`) and each cloud's valid
    points go straight into their final arrays: the memory taken beyond the scans themselves
    is a few chunk-sized buffers, whatever the file's size.

    Points are stored as float32 (half the memory of float64; 0.5 mm or better within
    :data:`~flexreg.core.scan.FLOAT32_MAX_M` of the scanner). A file with a coordinate beyond
    that (points in project coordinates) is read again as float64, and so is every file with
    ``precise=True`` (the values exactly as written, to write them back unchanged).
    ``intensity=False`` does not keep the intensities (4 bytes per point less, for callers
    that never read them); the lines are validated all the same.

    Returns
    -------
    list of Scan
        One per cloud: valid points (N, 3) float32 (float64 for far coordinates) in the
        scanner frame, intensity (N,)
        float32, colours (N, 3) uint8 when the file has RGB, grid ``(rows, cols)`` with
        ``grid_index`` in file order (line ``k`` of a cloud is row ``k % rows`` of column
        ``k // rows``), and ``T_world_scanner`` = the file's (transposed-back) 4x4 matrix, or
        the scanner registration lines (position, axes) when the matrix is the identity and
        they are not.
    """
    return [scan for scan, _ in _read_any(path, precise, intensity, None)]


def read_working(
    path: Path, *, max_pixels: int, precise: bool = False
) -> list[tuple[Scan, RangeImage]]:
    """Every cloud of a PTX file as its points and its working image, read at once: no grid
    index, intensity or colour is kept (12 bytes per point instead of 24 for float32).

    The working image is :func:`flexreg.stages.projection.working_image` of the scan
    :func:`read` gives (every ``k``-th row and column, ``k`` from ``max_pixels``:
    :func:`~flexreg.core.range_image.working_stride`), built while the lines stream past; its
    ``index`` is not kept (a read-only -1 view). The points are those of :func:`read`, in
    the same order, in a :class:`Scan` without grid. Errors are those of :func:`read`.

    Returns
    -------
    list of (Scan, RangeImage)
        One per cloud.
    """
    pairs = _read_any(path, precise, False, max_pixels)
    return [(scan, image) for scan, image in pairs if image is not None]


#: chunk size of :func:`read_working` (survey workers, where memory counts most): the
#: smallest of :func:`_chunk_bytes`; parsing a 4096 x 2048 station peaks 0.07 GB lower than
#: with its eighth-of-the-file chunks, for about 20 % more parsing time
_WORKING_CHUNK_BYTES = _MIN_CHUNK_BYTES


def _read_any(
    path: Path, precise: bool, intensity: bool, max_pixels: int | None
) -> list[tuple[Scan, RangeImage | None]]:
    size = path.stat().st_size
    check_memory(3 * min(size, _chunk_bytes(size)), "parsing it", source=path)
    if precise:
        return _read(path, size, np.float64, intensity, max_pixels)
    try:
        return _read(path, size, np.float32, intensity, max_pixels)
    except _Wide:
        log.info("%s: coordinates beyond %g m, read as float64", path, FLOAT32_MAX_M)
        return _read(path, size, np.float64, intensity, max_pixels)


def _read(
    path: Path, size: int, dtype: type, intensity: bool = True, max_pixels: int | None = None
) -> list[tuple[Scan, RangeImage | None]]:
    """:func:`read` with points of ``dtype``."""
    scans: list[tuple[Scan, RangeImage | None]] = []
    cloud: _Cloud | None = None
    pose = np.eye(4)
    hdr: tuple[list[NDArray[np.float64]], list[int], list[int]] = ([], [], [])
    hdr_line = 0
    base = 0  # file line number of the chunk's first line
    chunk = _chunk_bytes(size)
    if max_pixels is not None:
        chunk = min(chunk, _WORKING_CHUNK_BYTES)
    for offset, lines in _chunks(path, size, chunk):
        head, counts, errors = lines[0], lines[2], lines[3]
        n_lines, i = len(counts), 0
        while i < n_lines:
            if cloud is not None:
                j = min(n_lines, i + cloud.remaining)
                cloud.add(lines, i, j, base + i)
                i = j
                if cloud.remaining == 0:
                    scans.append((cloud.finish(pose), cloud.image))
                    cloud = None
                continue
            if not hdr[1] and counts[i] == 0 and errors[i] == 0:  # blank line between clouds
                i += 1
                continue
            if not hdr[1]:
                hdr_line = base + i
            hdr[0].append(head[i].copy())
            hdr[1].append(int(counts[i]))
            hdr[2].append(int(errors[i]))
            i += 1
            if len(hdr[1]) == _HEADER_LINES:
                cloud, pose = _header_cloud(
                    path,
                    len(scans),
                    hdr_line,
                    *hdr,
                    bytes_left=size - offset,
                    dtype=dtype,
                    intensity=intensity,
                    max_pixels=max_pixels,
                )
                hdr = ([], [], [])
        base += n_lines
    if cloud is not None:
        raise cloud.truncated()
    if hdr[1]:
        raise InputError(path, f"cloud {len(scans)}: truncated header at line {hdr_line + 1}")
    if not scans:
        raise InputError(path, "no cloud in file")
    return scans


def header_pose(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """``T_world_scanner`` of a cloud's header lines 3-10: the 4x4 transform (written
    transposed), or, when that is the identity and the scanner registration lines are not,
    the pose those give (position; the scanner's x, y, z axes as rows)."""
    M = rows[4:8].T.copy()
    if not np.array_equal(M, np.eye(4)):
        return M
    position, axes = rows[0, :3], rows[1:4, :3]
    if np.array_equal(position, np.zeros(3)) and np.array_equal(axes, np.eye(3)):
        return M
    T = np.eye(4)
    T[:3, :3] = axes.T
    T[:3, 3] = position
    return T


# ------------------------------------------------------------------------------ writer


@numba.njit(cache=True, nogil=True, inline="always")
def _fmt_len(v: float, decimals: int, scale: float) -> int:
    q = np.int64(np.floor(abs(v) * scale + 0.5))
    ip = q // np.int64(scale)
    n = 1
    while ip >= 10:
        ip //= 10
        n += 1
    neg = 1 if (v < 0 and q != 0) else 0
    return neg + n + (1 + decimals if decimals > 0 else 0)


@numba.njit(cache=True, nogil=True, inline="always")
def _fmt_write(out: NDArray[np.uint8], pos: int, v: float, decimals: int, scale: float) -> int:
    q = np.int64(np.floor(abs(v) * scale + 0.5))
    p10 = np.int64(scale)
    ip = q // p10
    fp = q % p10
    if v < 0 and q != 0:
        out[pos] = 45
        pos += 1
    n = 1
    t = ip
    while t >= 10:
        t //= 10
        n += 1
    for j in range(n - 1, -1, -1):
        out[pos + j] = 48 + ip % 10
        ip //= 10
    pos += n
    if decimals > 0:
        out[pos] = 46
        pos += 1
        for j in range(decimals - 1, -1, -1):
            out[pos + j] = 48 + fp % 10
            fp //= 10
        pos += decimals
    return pos


@numba.njit(cache=True, nogil=True, parallel=True)
def _format_lines(vals: NDArray[np.float64], decimals: NDArray[np.int64]) -> NDArray[np.uint8]:
    """Format rows of ``vals`` as space-separated fixed-point text lines."""
    n, m = vals.shape
    scales = np.empty(m)
    for j in range(m):
        scales[j] = 10.0 ** decimals[j]
    lens = np.empty(n, dtype=np.int64)
    for i in prange(n):
        s = m  # separators and the newline
        for j in range(m):
            s += _fmt_len(vals[i, j], decimals[j], scales[j])
        lens[i] = s
    offs = np.empty(n + 1, dtype=np.int64)
    offs[0] = 0
    for i in range(n):
        offs[i + 1] = offs[i] + lens[i]
    out = np.empty(offs[n], dtype=np.uint8)
    for i in prange(n):
        pos = offs[i]
        for j in range(m):
            pos = _fmt_write(out, pos, vals[i, j], decimals[j], scales[j])
            out[pos] = 32 if j < m - 1 else 10
            pos += 1
    return out


def _header(cols: int, rows: int, T: NDArray[np.float64]) -> str:
    def row(v: NDArray[np.float64]) -> str:
        return " ".join(repr(float(x)) for x in v)

    lines = [str(cols), str(rows), row(T[:3, 3])]
    lines += [row(T[:3, k]) for k in range(3)]  # the scanner axes as rows
    lines += [row(T[:, k]) for k in range(4)]  # the matrix, transposed
    return "\n".join(lines) + "\n"


def write(path: Path, scans: list[Scan], *, decimals: int = 6, **_: object) -> None:
    """Write scans as PTX clouds, column by column, ``0 0 0 0.5`` for empty cells.

    Parameters
    ----------
    path : Path
    scans : list of Scan
        A gridded scan keeps its grid; a scan without a grid becomes one column of N rows.
    decimals : int
        Digits after the decimal point for coordinates and intensity (6 = micrometres).
    """
    if not 0 <= decimals <= 12:
        raise InputError(path, f"decimals must be 0..12, got {decimals}")
    with open(path, "wb") as f:
        for scan in scans:
            if scan.grid_shape is not None and scan.grid_index is not None:
                rows, cols = scan.grid_shape
                lin = scan.grid_index[:, 1].astype(np.int64) * rows + scan.grid_index[:, 0]
            else:
                rows, cols = len(scan), 1
                lin = np.arange(len(scan), dtype=np.int64)
            has_color = scan.colors is not None
            m = 7 if has_color else 4
            vals = np.zeros((rows * cols, m))
            vals[:, 3] = 0.5  # the intensity Leica writes for no-return cells
            vals[lin, :3] = scan.points
            vals[lin, 3] = scan.intensity if scan.intensity is not None else 0.5
            if has_color:
                vals[lin, 4:7] = scan.colors
            dec = np.array([decimals] * 4 + [0] * (m - 4), dtype=np.int64)
            f.write(_header(cols, rows, scan.T_world_scanner).encode("ascii"))
            f.write(_format_lines(vals, dec).tobytes())
