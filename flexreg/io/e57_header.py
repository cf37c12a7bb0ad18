"""What an E57 file declares, read from its own bytes before libE57 allocates anything.

libE57 (through pye57) trusts the XML: it allocates buffers for ``recordCount`` records of
every field, and reads only that many even when the binary section holds more. So the XML
section and each scan's binary section header are read here (the paged layout of ASTM E2807:
pages of 1024 bytes, the last 4 a checksum) and the declared record count is compared with:

- the data the binary section holds: each record takes a fixed number of bits (64 or 32 per
  ``Float``, ``ceil(log2(maximum - minimum + 1))`` per ``Integer`` / ``ScaledInteger``), so a
  section much longer than ``recordCount`` records is a lowered count (a half-read) and a
  shorter one a raised count or a truncated file;
- the memory budget, with the grid its ``indexBounds`` declare.
"""

from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from flexreg.core.budget import check_memory
from flexreg.core.scan import GRID_CELL_BYTES, POINT_BYTES
from flexreg.errors import InputError

__all__ = ["DeclaredScan", "check_declared", "declared_scans"]

_PAGE = 1024
_CRC = 4
#: a section may exceed its records' bits by packet headers; more than this share plus
#: :data:`_SLACK_BYTES` means records the XML does not declare
_SLACK_SHARE = 0.05
_SLACK_BYTES = 16 * 1024


@dataclass(frozen=True)
class DeclaredScan:
    """One ``data3D`` entry as the XML declares it."""

    index: int
    record_count: int
    bits_per_record: int  # 0 when a field has no fixed size (its data cannot be counted)
    fields: int
    section_bytes: int | None  # logical length of its binary section
    grid: tuple[int, int] | None  # (rowMaximum + 1, columnMaximum + 1)


def _logical(f: object, physical: int, n: int, size: int) -> bytes:
    """``n`` logical bytes from a physical offset, skipping each page's checksum."""
    out = bytearray()
    pos = physical
    while len(out) < n:
        if pos >= size:
            break
        in_page = pos % _PAGE
        if in_page >= _PAGE - _CRC:
            pos += _PAGE - in_page
            continue
        take = min(_PAGE - _CRC - in_page, n - len(out))
        f.seek(pos)  # type: ignore[attr-defined]
        chunk = f.read(take)  # type: ignore[attr-defined]
        if not chunk:
            break
        out += chunk
        pos += len(chunk)
    return bytes(out)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _bits(node: ET.Element) -> int | None:
    """Bits one record of a prototype field takes (None: variable, e.g. a String)."""
    kind = node.get("type")
    if kind == "Float":
        return 32 if node.get("precision") == "single" else 64
    if kind in ("Integer", "ScaledInteger"):
        lo = int(node.get("minimum", -(2**63)))
        hi = int(node.get("maximum", 2**63 - 1))
        return 0 if hi <= lo else math.ceil(math.log2(hi - lo + 1))
    return None


def _int(node: ET.Element | None, default: int = 0) -> int:
    if node is None or node.text is None or not node.text.strip():
        return default
    return int(node.text.strip())


def declared_scans(path: Path) -> list[DeclaredScan]:
    """The scans an E57 file declares (empty when it is not a paged E57; libE57 decides).

    Raises
    ------
    InputError
        A header or XML that cannot be what it claims (offsets beyond the file, unparsable
        XML, non-numeric counts).
    """
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(48)
        if len(head) < 48 or head[:8] != b"ASTM-E57":
            return []
        _, _, _, _, xml_offset, xml_length, page = struct.unpack("<8sIIQQQQ", head)
        if page != _PAGE:
            return []
        if xml_offset >= size or xml_length > size:
            raise InputError(path, "E57 header points its XML section beyond the end of the file")
        xml = _logical(f, xml_offset, xml_length, size)
        try:
            root = ET.fromstring(xml)
        except ET.ParseError as e:
            raise InputError(path, f"E57 XML section is not valid XML ({e})") from None
        data3d = next((c for c in root if _local(c.tag) == "data3D"), None)
        scans: list[DeclaredScan] = []
        for i, child in enumerate([] if data3d is None else list(data3d)):
            _check_pose(path, i, child)
            try:
                scans.append(_declared(f, path, i, child, size))
            except ValueError as e:
                if isinstance(e, InputError):
                    raise
                raise InputError(
                    path, f"scan {i}: E57 XML holds a non-numeric limit ({e})"
                ) from None
    return scans


def _check_pose(path: Path, i: int, scan: ET.Element) -> None:
    """Refuse a pose number that is not a finite number (``nan``, ``inf``, ``1e400``, a
    word): libE57 reads such text as 0 (or the largest double) without a word, so a NaN pose
    would become a wrong one. Empty elements are 0 by the standard and stay accepted."""
    by = {_local(c.tag): c for c in scan}
    name = (by["name"].text or "").strip() if "name" in by else ""
    pose = by.get("pose")
    for part in [] if pose is None else list(pose):
        for axis in part:
            text = (axis.text or "").strip()
            try:
                finite = not text or math.isfinite(float(text))
            except ValueError:
                finite = False
            if not finite:
                raise InputError(
                    path,
                    f"scan {i} ({name or f'scan {i}'}): pose {_local(part.tag)} "
                    f"{_local(axis.tag)} is {text!r}, not a finite number",
                )


def _declared(f: object, path: Path, i: int, scan: ET.Element, size: int) -> DeclaredScan:
    points = next((c for c in scan if _local(c.tag) == "points"), None)
    if points is None:
        return DeclaredScan(i, 0, 0, 0, None, None)
    try:
        count = int(points.get("recordCount", "0"))
        offset = int(points.get("fileOffset", "0"))
    except ValueError:
        raise InputError(path, f"scan {i}: recordCount / fileOffset are not integers") from None
    proto = next((c for c in points if _local(c.tag) == "prototype"), None)
    fields = [] if proto is None else list(proto)
    each = [_bits(c) for c in fields]
    bits = 0 if None in each else sum(b for b in each if b is not None)  # 0: not checkable
    section = None
    if 0 < offset < size:
        header = _logical(f, offset, 32, size)
        if len(header) == 32 and header[0] == 1:
            section = struct.unpack("<Q", header[8:16])[0]
    grid = None
    bounds = next((c for c in scan if _local(c.tag) == "indexBounds"), None)
    if bounds is not None:
        by = {_local(c.tag): c for c in bounds}
        try:
            rows, cols = _int(by.get("rowMaximum")) + 1, _int(by.get("columnMaximum")) + 1
        except ValueError:
            raise InputError(path, f"scan {i}: indexBounds are not integers") from None
        grid = (rows, cols)
    return DeclaredScan(i, count, bits, len(fields), section, grid)


def check_declared(path: Path) -> None:
    """Refuse an E57 whose declared record counts or grids its data or the memory budget
    contradict (see the module docstring).

    Raises
    ------
    InputError
        ``scan 0: the XML declares 1,000 records but its data holds about 155,201`` and the
        like; :class:`~flexreg.errors.MemoryBudgetError` for what would not fit.
    """
    for s in declared_scans(path):
        n = s.record_count
        label = f"scan {s.index}"
        if n < 0:
            raise InputError(path, f"{label}: negative recordCount {n}")
        check_memory(n * (8 * s.fields + POINT_BYTES), f"{label}: {n:,} records", source=path)
        if s.grid is not None:
            rows, cols = s.grid
            if rows > 0 and cols > 0:
                check_memory(
                    rows * cols * GRID_CELL_BYTES,
                    f"{label}: its {rows} x {cols} grid (indexBounds)",
                    source=path,
                )
        if s.section_bytes is None or s.bits_per_record == 0:
            continue
        need = n * s.bits_per_record / 8
        held = int(s.section_bytes * 8 / s.bits_per_record)
        if s.section_bytes > need * (1 + _SLACK_SHARE) + _SLACK_BYTES:
            raise InputError(
                path,
                f"{label}: the XML declares {n:,} records but its data holds about {held:,} "
                "(wrong recordCount; refusing to read part of the scan)",
            )
        if need > s.section_bytes:
            raise InputError(
                path,
                f"{label}: the XML declares {n:,} records but its data holds at most {held:,} "
                "(truncated file or wrong recordCount)",
            )
