"""Generate the bad-input corpus: small good inputs, broken variants of them, and the cases.

Usage: ``python tests/badinput/make_corpus.py OUT_DIR`` writes one folder per case under
``OUT_DIR`` and ``OUT_DIR/cases.json``; ``tests/badinput/test_corpus.py`` builds it in a
temporary folder and runs every case through the command line.

Every case is a folder holding exactly the files its command needs and a command line in which
``{d}`` stands for that folder. A case passes when the command exits with status 1, prints one
``error:`` line naming one of ``names`` (the file or option at fault), no traceback, leaves the
folder byte-identical (nothing written, nothing replaced, no temporary left), within the time
limit, and, with ``memory_limit``, under an address-space limit of 1 GB.

To add a case: write its files with :class:`Corpus.case` and append it; the classes (``kind``)
are the failure classes of the safety and hardening work: ``overwrite``, ``partial``,
``header``, ``halfread``, ``option``, ``broken``, ``pair``.
"""

from __future__ import annotations

import json
import shutil
import struct
import sys
import zlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

#: address-space limit of the cases marked ``memory_limit`` (the issue's 1 GB)
MEMORY_LIMIT_BYTES = 1 << 30


@dataclass
class Case:
    """One command line that must fail cleanly."""

    id: str
    kind: str
    argv: list[str]
    names: list[str]
    memory_limit: bool = False
    note: str = ""
    env: dict[str, str] = field(default_factory=dict)
    #: what the case exercises, for the coverage table: the reader or kind of file at fault
    #: ("PTX", "pairs CSV", "option", ...); inferred from ``names`` when not given
    covers: list[str] = field(default_factory=list)


#: file suffix -> reader / kind of file, for cases that do not say what they cover
SUFFIX_COVERS = {
    ".ptx": "PTX", ".e57": "E57", ".ply": "PLY", ".pcd": "PCD", ".las": "LAS/LAZ",
    ".laz": "LAS/LAZ", ".bin": "KITTI .bin", ".3d": "3DTK", ".pose": "3DTK", ".npz": "npz",
    ".npy": "npz", ".png": "depth PNG", ".csv": "pairs CSV", ".toml": "config TOML",
}  # fmt: skip


def infer_covers(case: Case) -> list[str]:
    """What a case exercises: its own ``covers``, else the kind of the file it names."""
    if case.covers:
        return case.covers
    if case.kind in ("overwrite", "partial"):
        return ["output path"]
    if case.kind == "pair":
        return ["scan pair"]
    first = case.names[0]
    if first.startswith("-") or first.isupper():
        return ["option"]
    if first.endswith(".camera.json"):
        return ["camera sidecar"]
    if case.argv and "--truth" in case.argv and first.endswith((".json", ".txt")):
        return ["4x4 transform (--truth)"]
    if case.argv and case.argv[0] == "evaluate":
        return ["TUM trajectory"]
    suffix = Path(first).suffix.lower()
    return [SUFFIX_COVERS.get(suffix, suffix or first)]


# ---------------------------------------------------------------------------- good inputs
def room_grid(height: int = 48, width: int = 96, offset=(0.4, -0.3, 0.1)) -> np.ndarray:
    """(H, W, 3) float64 points of a 7 x 5 x 3 m box room with a pillar, seen from inside."""
    th = np.linspace(0.35, np.pi - 0.35, height)
    ph = np.linspace(-np.pi, np.pi, width, endpoint=False)
    P, T = np.meshgrid(ph, th)
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    lo = np.array([-3.5, -2.5, -1.5]) - offset
    hi = np.array([3.5, 2.5, 1.5]) - offset
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, hi / d, lo / d)
    t = np.where(np.isfinite(t) & (t > 0), t, np.inf).min(axis=-1)
    # a pillar at (1.5, 1) of 0.4 m radius
    c = np.array([1.5, 1.0]) - offset[:2]
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = -2 * (d[..., 0] * c[0] + d[..., 1] * c[1])
    disc = b**2 - 4 * a * (c @ c - 0.16)
    with np.errstate(invalid="ignore", divide="ignore"):
        tp = (-b - np.sqrt(disc)) / (2 * a)
    t = np.where((disc > 0) & (tp > 0) & (tp < t), tp, t)
    return d * t[..., None]


def ply_bytes(points: np.ndarray, *, count: int | None = None, ascii: bool = False) -> bytes:
    n = len(points) if count is None else count
    fmt = "ascii" if ascii else "binary_little_endian"
    head = (
        f"ply\nformat {fmt} 1.0\nelement vertex {n}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()
    if ascii:
        body = "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in points).encode()
    else:
        body = points.astype("<f4").tobytes()
    return head + body


def pcd_bytes(
    points: np.ndarray,
    *,
    count: int | None = None,
    ascii: bool = False,
    width: int | None = None,
    height: int = 1,
) -> bytes:
    n = len(points) if count is None else count
    w = n if width is None else width
    head = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {w}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
        f"DATA {'ascii' if ascii else 'binary'}\n"
    ).encode()
    if ascii:
        return head + "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in points).encode()
    return head + points.astype("<f4").tobytes()


def las_bytes(points: np.ndarray, path: Path, *, laz: bool = False) -> bytes:
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(str(path))
    data = path.read_bytes()
    path.unlink()
    return data


def npy_header(shape: tuple[int, ...], dtype: str = "<f8") -> bytes:
    """A version 1.0 ``.npy`` header declaring ``shape`` (no data)."""
    d = f"{{'descr': '{dtype}', 'fortran_order': False, 'shape': {shape!r}, }}"
    pad = 64 - (10 + len(d) + 1) % 64
    text = (d + " " * pad + "\n").encode("latin1")
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text


# ------------------------------------------------------------------------------- E57 edits
def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


_CRC32C = _crc_table()


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli), the checksum of each E57 page."""
    c = 0xFFFFFFFF
    for b in data:
        c = _CRC32C[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


def e57_edit_xml(data: bytes, edit: Callable[[str], str]) -> bytes:
    """An E57 file with its XML section rewritten by ``edit``, every page checksum valid (as a
    careless tool or a hostile file would produce it)."""
    page, logical_page = 1024, 1020
    logical = b"".join(data[i : i + logical_page] for i in range(0, len(data), page))
    _, _, _, _, xml_off, xml_len, _ = struct.unpack("<8sIIQQQQ", data[:48])
    xml_logical = (xml_off // page) * logical_page + xml_off % page
    xml = logical[xml_logical : xml_logical + xml_len].decode("utf-8")
    new = edit(xml).encode("utf-8")
    body = bytearray(logical[:xml_logical] + new)
    n_pages = -(-len(body) // logical_page)
    body += bytes(n_pages * logical_page - len(body))
    struct.pack_into("<Q", body, 16, n_pages * page)
    struct.pack_into("<Q", body, 32, len(new))
    out = bytearray()
    for i in range(n_pages):
        chunk = bytes(body[i * logical_page : (i + 1) * logical_page])
        out += chunk + crc32c(chunk).to_bytes(4, "big")
    return bytes(out)


def png_header_only(width: int, height: int) -> bytes:
    """A PNG signature and IHDR declaring ``width x height`` 16-bit grey, and no pixels."""
    ihdr = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return (
        b"\x89PNG\r\n\x1a\n"
        + struct.pack(">I", len(ihdr))
        + chunk
        + struct.pack(">I", zlib.crc32(chunk) & 0xFFFFFFFF)
        + b"\x00\x00\x00\x00IEND\xaeB`\x82"
    )


# ------------------------------------------------------------------------------- the corpus
class Corpus:
    """Builds case folders under ``root`` from the good inputs."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.cases: list[Case] = []
        self.good: dict[str, bytes] = {}

    def case(
        self,
        id: str,
        kind: str,
        argv: list[str],
        names: list[str],
        files: dict[str, bytes | str] | None = None,
        *,
        good: tuple[str, ...] = (),
        memory_limit: bool = False,
        note: str = "",
        env: dict[str, str] | None = None,
        setup: Callable[[Path], None] | None = None,
        covers: list[str] | None = None,
    ) -> None:
        """Add a case: ``good`` copies named good inputs, ``files`` adds (broken) ones."""
        assert all(c.id != id for c in self.cases), id
        d = self.root / id
        d.mkdir(parents=True)
        for name in good:
            (d / name).write_bytes(self.good[name])
        for name, content in (files or {}).items():
            (d / name).write_bytes(content.encode() if isinstance(content, str) else content)
        if setup is not None:
            setup(d)
        self.cases.append(
            Case(id, kind, argv, names, memory_limit, note, env or {}, list(covers or ()))
        )

    def make_good(self, tmp: Path) -> None:
        """Good inputs: a gridded room scan in every format, a depth PNG with its sidecar,
        trajectories and a transform."""
        from flexreg.core.scan import Scan
        from flexreg.io import write_scan, write_transform_json
        from flexreg.io.info import write_range_image
        from flexreg.stages.projection import auto_spherical_camera, project

        xyz = room_grid()
        scan = Scan.from_organized(xyz, name="room")
        flat = xyz.reshape(-1, 3)
        tmp.mkdir(parents=True, exist_ok=True)
        for suffix in (".ptx", ".e57", ".npz"):
            write_scan(tmp / f"room{suffix}", scan)
        other = Scan.from_organized(room_grid(offset=(-0.5, 0.6, 0.0)), name="room2")
        write_scan(tmp / "room2.ptx", other)
        cloud = Scan(points=xyz.reshape(-1, 3), name="cloud")
        write_range_image(tmp / "depth.png", project(cloud, auto_spherical_camera(cloud.points)))
        (tmp / "depth.npz").unlink()
        rng = np.random.default_rng(0)
        write_transform_json(tmp / "T.json", np.eye(4))
        t = np.arange(20) * 0.1
        pos = np.stack([t, 0.5 * t, 0 * t], axis=1)
        gt = "".join(
            f"{a:.2f} {x:.4f} {y:.4f} {z:.4f} 0 0 0 1\n"
            for a, (x, y, z) in zip(t, pos, strict=True)
        )
        noisy = pos + rng.normal(0, 0.01, pos.shape)
        est = "".join(
            f"{a:.2f} {x:.4f} {y:.4f} {z:.4f} 0 0 0 1\n"
            for a, (x, y, z) in zip(t, noisy, strict=True)
        )
        (tmp / "gt.txt").write_text(gt)
        (tmp / "est.txt").write_text(est)
        for p in tmp.iterdir():
            self.good[p.name] = p.read_bytes()
        self.good["room.ply"] = ply_bytes(flat)
        self.good["room.pcd"] = pcd_bytes(flat)
        self.good["room.las"] = las_bytes(flat, tmp / "room.las")
        self.good["room.laz"] = las_bytes(flat, tmp / "room.laz")
        kitti = np.concatenate([flat, np.full((len(flat), 1), 0.5)], axis=1)
        self.good["room.bin"] = kitti.astype("<f4").tobytes()
        self.good["ident.txt"] = b"1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
        self.flat = flat


def build(root: Path) -> list[Case]:
    """Write the corpus under ``root`` (one folder per case, ``cases.json``); return the cases."""
    root = Path(root)
    if root.exists():
        shutil.rmtree(root)
    c = Corpus(root / "cases")
    c.make_good(root / "good")
    # the case lists live beside this script
    from badcases import add_cases
    from badcases_files import add_file_cases
    from badcases_readers import add_reader_cases

    add_cases(c)
    add_reader_cases(c)
    add_file_cases(c)
    for case in c.cases:
        case.covers = infer_covers(case)
    (root / "cases.json").write_text(json.dumps([asdict(k) for k in c.cases], indent=1))
    return c.cases


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "badinput-corpus")
    cases = build(out)
    kinds = sorted({k.kind for k in cases})
    print(f"{len(cases)} cases in {out} ({', '.join(kinds)})")
