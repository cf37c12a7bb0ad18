"""Bad-input cases, reader by reader: every scan format flexreg reads, broken each way a real
file breaks (truncated, wrong header counts, non-numeric tokens, NaN/Inf/1e30 coordinates,
zero, one or identical points, points on one line, garbage with the right extension, empty,
a folder instead of a file, setups out of range), and degenerate clouds through ``register``.

See ``make_corpus.py`` for what a case is and what it must do.
"""

from __future__ import annotations

import json
import struct
import zipfile
from io import BytesIO

import numpy as np
from make_corpus import Corpus, e57_edit_xml, pcd_bytes, ply_bytes

#: random bytes, the same every run
GARBAGE = np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8).tobytes()


def ptx_bytes(
    points: np.ndarray, cols: int, rows: int, *, header: list[str] | None = None
) -> bytes:
    """A one-cloud PTX file of ``points`` ((cols * rows, 3), column by column)."""
    head = header or [
        str(cols), str(rows), "0 0 0", "1 0 0", "0 1 0", "0 0 1",
        "1 0 0 0", "0 1 0 0", "0 0 1 0", "0 0 0 1",
    ]  # fmt: skip
    body = [f"{x:.6g} {y:.6g} {z:.6g} 0.5" for x, y, z in points]
    return ("\n".join([*head, *body]) + "\n").encode()


def kitti_bytes(points: np.ndarray) -> bytes:
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.concatenate([pts, np.full((len(pts), 1), 0.5)], axis=1).astype("<f4").tobytes()


def identical(n: int = 2000) -> np.ndarray:
    return np.tile([[2.0, 1.0, 0.5]], (n, 1))


def on_a_line(n: int = 2000) -> np.ndarray:
    """Points on one straight line that does not pass through the scanner."""
    t = np.linspace(-5, 5, n)[:, None]
    return np.array([[1.0, 2.0, 0.3]]) + t * np.array([[0.6, -0.8, 0.0]])


def on_a_ray(n: int = 2000) -> np.ndarray:
    """Points on one ray from the scanner (all in one direction)."""
    return np.linspace(1, 10, n)[:, None] * np.array([[0.6, 0.3, 0.1]])


def add_reader_cases(c: Corpus) -> None:
    """Every reader, broken every way."""
    _ptx(c)
    _e57(c)
    _ply_pcd(c)
    _las(c)
    _kitti(c)
    _threedtk(c)
    _npz(c)
    _depth_png(c)
    _degenerate(c)


def _info(c: Corpus, id: str, name: str, content: bytes, covers: str, kind: str = "broken") -> None:
    c.case(
        id,
        kind,
        ["info", "{d}/" + name],
        [name],
        files={name: content},
        memory_limit=True,
        covers=[covers],
    )


# ------------------------------------------------------------------------------------- PTX
def _ptx(c: Corpus) -> None:
    good = c.good["room.ptx"]
    lines = good.split(b"\n")
    body = lines[10:]
    k = len(body) // 3
    body_bad = list(body)
    body_bad[k] = b"1.2 abc 3.4 0.5"
    _info(c, "ptx-non-numeric-token", "word.ptx", b"\n".join([*lines[:10], *body_bad]), "PTX")
    head = list(lines[:10])
    head[2] = b"0 0"
    _info(c, "ptx-header-line-count-wrong", "head.ptx", b"\n".join([*head, *body]), "PTX")
    _info(
        c,
        "ptx-header-cols-not-integer",
        "cols.ptx",
        b"\n".join([b"96.5", *lines[1:]]),
        "PTX",
    )
    body_bad = list(body)
    body_bad[k] = b"1.2 3.4 5.6 0.5 7"
    _info(c, "ptx-five-values-on-a-line", "five.ptx", b"\n".join([*lines[:10], *body_bad]), "PTX")
    _info(c, "ptx-truncated-mid-line", "cut.ptx", good[: len(good) // 2 + 7], "PTX", "halfread")
    _info(c, "ptx-garbage", "garbage.ptx", GARBAGE, "PTX")
    _info(
        c,
        "ptx-inf-coordinate",
        "inf.ptx",
        ptx_bytes(np.array([[1, 2, 3], [np.inf, 1, 1]]), 1, 2),
        "PTX",
    )
    _info(
        c,
        "ptx-all-cells-empty",
        "zero.ptx",
        ptx_bytes(np.zeros((64, 3)), 8, 8),
        "PTX",
    )
    xyz = c.flat.copy()
    xyz[::7] = 1e30
    c.case(
        "ptx-1e30-coordinates-register",
        "broken",
        ["register", "{d}/room.ptx", "{d}/far.ptx", "--out", "{d}/T.json"],
        ["far.ptx"],
        good=("room.ptx",),
        files={"far.ptx": ptx_bytes(xyz, 96, 48)},
        covers=["PTX"],
    )
    c.case(
        "ptx-setup-out-of-range",
        "broken",
        ["info", "{d}/room.ptx#9"],
        ["room.ptx"],
        good=("room.ptx",),
        memory_limit=True,
        covers=["PTX", "setup selector"],
    )
    c.case(
        "ptx-setup-name-unknown",
        "broken",
        ["register", "{d}/room.ptx#nosuch", "{d}/room2.ptx", "--out", "{d}/T.json"],
        ["room.ptx"],
        good=("room.ptx", "room2.ptx"),
        covers=["PTX", "setup selector"],
    )


# ------------------------------------------------------------------------------------- E57
def _e57(c: Corpus) -> None:
    good = c.good["room.e57"]
    crc = bytearray(good)
    crc[1500] ^= 0xFF  # a byte of the second page: its checksum no longer holds
    _info(c, "e57-page-checksum-broken", "crc.e57", bytes(crc), "E57")
    _info(
        c,
        "e57-xml-broken",
        "xml.e57",
        e57_edit_xml(good, lambda x: x.replace("</data3D>", "</data3X>", 1)),
        "E57",
    )
    _info(
        c,
        "e57-xml-not-xml",
        "notxml.e57",
        e57_edit_xml(good, lambda x: "<?xml version='1.0'?><e57Root><<<"),
        "E57",
    )
    _info(c, "e57-truncated", "cut.e57", good[: len(good) // 2], "E57", "halfread")
    _info(c, "e57-empty", "empty.e57", b"", "E57")
    _info(c, "e57-signature-only", "sig.e57", b"ASTM-E57" + bytes(40), "E57")
    # libE57 reads a pose number it cannot parse as 0 (and 1e400 as the largest double)
    for label, old, new in (
        ("translation-nan", "<translation type=\"Structure\">\n          <x type=\"Float\"/>",
         "<translation type=\"Structure\">\n          <x type=\"Float\">nan</x>"),
        ("rotation-nan", "<x type=\"Float\"/>", "<x type=\"Float\">NaN</x>"),
        ("translation-overflow", "<translation type=\"Structure\">\n          <x type=\"Float\"/>",
         "<translation type=\"Structure\">\n          <x type=\"Float\">1e400</x>"),
    ):  # fmt: skip
        c.case(
            f"e57-pose-{label}",
            "broken",
            ["info", "{d}/pose.e57"],
            ["pose.e57"],
            files={"pose.e57": e57_edit_xml(good, lambda x, o=old, n=new: _replace(x, o, n))},
            memory_limit=True,
            covers=["E57"],
        )
    c.case(
        "e57-setup-out-of-range",
        "broken",
        ["info", "{d}/room.e57#9"],
        ["room.e57"],
        good=("room.e57",),
        memory_limit=True,
        covers=["E57", "setup selector"],
    )


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


# ------------------------------------------------------------------------------ PLY and PCD
def _ply_pcd(c: Corpus) -> None:
    flat = c.flat
    ply = ply_bytes(flat)
    _info(c, "ply-binary-truncated", "cut.ply", ply[: len(ply) // 2], "PLY", "halfread")
    head, rows = ply_bytes(flat[:50], ascii=True).split(b"end_header\n")
    rows = rows.split(b"\n")
    rows[7] = b"0.5 abc 1.25"
    text = head + b"end_header\n" + b"\n".join(rows)
    _info(c, "ply-ascii-non-numeric", "word.ply", text, "PLY")
    nan = flat[:200].copy()
    nan[5] = np.nan
    _info(c, "ply-nan-vertex", "nan.ply", ply_bytes(nan), "PLY")
    _info(c, "ply-zero-vertices", "none.ply", ply_bytes(flat[:0]), "PLY")
    _info(c, "ply-empty", "empty.ply", b"", "PLY")
    _info(c, "ply-garbage", "garbage.ply", GARBAGE, "PLY")
    _info(
        c,
        "ply-header-never-ends",
        "open.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n" * 50,
        "PLY",
    )
    pcd = pcd_bytes(flat)
    _info(c, "pcd-binary-truncated", "cut.pcd", pcd[: len(pcd) // 2], "PCD", "halfread")
    _info(c, "pcd-garbage", "garbage.pcd", GARBAGE, "PCD")
    _info(c, "pcd-ascii-nan", "nan.pcd", pcd_bytes(nan, ascii=True), "PCD")
    _info(c, "pcd-empty", "empty.pcd", b"", "PCD")
    _info(
        c,
        "pcd-fields-without-z",
        "xy.pcd",
        pcd_bytes(flat[:10], ascii=True).replace(b"FIELDS x y z", b"FIELDS x y w"),
        "PCD",
    )


# ------------------------------------------------------------------------------- LAS / LAZ
def _las(c: Corpus) -> None:
    las = c.good["room.las"]
    _info(c, "las-empty", "empty.las", b"", "LAS/LAZ")
    _info(c, "las-garbage-with-signature", "garbage.las", b"LASF" + GARBAGE, "LAS/LAZ")
    _info(c, "las-truncated", "cut.las", las[: len(las) // 2], "LAS/LAZ", "halfread")
    zero = bytearray(las[:227])  # header only, declaring no points
    struct.pack_into("<I", zero, 107, 0)
    struct.pack_into("<I", zero, 96, 227)  # offset to point data: right after the header
    _info(c, "las-no-points", "none.las", bytes(zero), "LAS/LAZ")
    laz = c.good["room.laz"]
    _info(c, "laz-truncated", "cut.laz", laz[: len(laz) // 2], "LAS/LAZ", "halfread")
    _info(c, "laz-empty", "empty.laz", b"", "LAS/LAZ")


# ----------------------------------------------------------------------------------- KITTI
def _kitti(c: Corpus) -> None:
    good = c.good["room.bin"]
    _info(c, "kitti-empty", "empty.bin", b"", "KITTI .bin")
    _info(c, "kitti-size-not-records", "odd.bin", good[:-6], "KITTI .bin", "halfread")
    rec = np.frombuffer(good, dtype="<f4").reshape(-1, 4).copy()
    rec[10, 1] = np.nan
    _info(c, "kitti-nan", "nan.bin", rec.tobytes(), "KITTI .bin")
    _info(c, "kitti-garbage", "garbage.bin", GARBAGE, "KITTI .bin")


# ------------------------------------------------------------------------------------ 3DTK
def _threedtk(c: Corpus) -> None:
    pts = c.flat[:300] * 100  # centimetres
    text = "".join(f"{-y:.2f} {z:.2f} {x:.2f}\n" for x, y, z in pts)
    _info(c, "3dtk-empty", "scan000.3d", b"", "3DTK")
    _info(
        c,
        "3dtk-non-numeric",
        "scan000.3d",
        (text[:2000] + "12.5 abc 3\n" + text[2000:]).encode(),
        "3DTK",
    )
    _info(c, "3dtk-nan", "scan000.3d", (text + "nan 1 2\n").encode(), "3DTK")
    _info(c, "3dtk-garbage", "scan000.3d", GARBAGE, "3DTK")
    c.case(
        "3dtk-pose-five-numbers",
        "broken",
        ["info", "{d}/scan000.3d"],
        ["scan000.pose"],
        files={"scan000.3d": text, "scan000.pose": "1 2 3\n4 5\n"},
        memory_limit=True,
        covers=["3DTK"],
    )
    c.case(
        "3dtk-pose-nan",
        "broken",
        ["info", "{d}/scan000.3d"],
        ["scan000.pose"],
        files={"scan000.3d": text, "scan000.pose": "1 2 3\n4 nan 6\n"},
        memory_limit=True,
        covers=["3DTK"],
    )


# ------------------------------------------------------------------------------------- npz
def _npz(c: Corpus) -> None:
    buf = BytesIO()
    np.savez(buf, intensity=np.zeros(10, np.float32))
    _info(c, "npz-no-points-member", "nopts.npz", buf.getvalue(), "npz")
    buf = BytesIO()
    pts = c.flat[:100].copy()
    pts[3, 2] = np.inf
    np.savez(buf, points=pts)
    _info(c, "npz-inf-points", "inf.npz", buf.getvalue(), "npz")
    buf = BytesIO()
    np.savez(buf, points=np.zeros((10, 2)))
    _info(c, "npz-points-two-columns", "flat.npz", buf.getvalue(), "npz")
    buf = BytesIO()
    np.savez(buf, points=np.array(["a", "b", "c"]))
    _info(c, "npz-points-are-strings", "words.npz", buf.getvalue(), "npz")
    _info(c, "npz-empty", "empty.npz", b"", "npz")
    buf = BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("points.npy", b"not a numpy array")
    _info(c, "npz-member-not-npy", "member.npz", buf.getvalue(), "npz")
    buf = BytesIO()
    np.save(buf, np.array({"points": 1}, dtype=object), allow_pickle=True)
    _info(c, "npy-pickled-object", "pickle.npy", buf.getvalue(), "npz")
    buf = BytesIO()
    np.save(buf, c.flat + 1j)  # casting to coordinates would drop the imaginary part
    _info(c, "npy-complex-points", "complex.npy", buf.getvalue(), "npz")
    buf = BytesIO()
    np.save(buf, np.zeros((10, 3), np.complex128))  # was an IndexError deep in projection
    _info(c, "npy-complex-zeros", "zeros.npy", buf.getvalue(), "npz")
    good = dict(np.load(BytesIO(c.good["room.npz"])))
    for label, key, value in (
        ("grid-shape-scalar", "grid_shape", np.array(48)),
        ("grid-shape-three", "grid_shape", np.array([48, 96, 1])),
        ("grid-shape-float", "grid_shape", np.array([48.0, 96.0])),
    ):
        buf = BytesIO()
        np.savez(buf, **{**good, key: value})
        _info(c, f"npz-{label}", f"{label}.npz", buf.getvalue(), "npz")


# ---------------------------------------------------------------- depth PNG + camera sidecar
def _png(image: np.ndarray) -> bytes:
    import cv2

    ok, data = cv2.imencode(".png", image)
    assert ok
    return data.tobytes()


def _depth_png(c: Corpus) -> None:
    import cv2

    depth = cv2.imdecode(np.frombuffer(c.good["depth.png"], np.uint8), cv2.IMREAD_UNCHANGED)
    side = c.good["depth.camera.json"]
    c.case(
        "depth-png-8-bit",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.png"],
        files={"depth.png": _png((depth >> 8).astype(np.uint8)), "depth.camera.json": side},
        memory_limit=True,
        covers=["depth PNG"],
    )
    rgb = np.repeat(depth[..., None], 3, axis=2)
    c.case(
        "depth-png-three-channels",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.png"],
        files={"depth.png": _png(rgb), "depth.camera.json": side},
        memory_limit=True,
        covers=["depth PNG"],
    )
    data = c.good["depth.png"]
    c.case(
        "depth-png-truncated",
        "halfread",
        ["info", "{d}/depth.png"],
        ["depth.png"],
        files={"depth.png": data[: len(data) // 2], "depth.camera.json": side},
        memory_limit=True,
        covers=["depth PNG"],
    )
    c.case(
        "depth-png-garbage",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.png"],
        files={"depth.png": GARBAGE, "depth.camera.json": side},
        memory_limit=True,
        covers=["depth PNG"],
    )
    c.case(
        "depth-png-no-sidecar-no-intrinsics",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.png"],
        good=("depth.png",),
        memory_limit=True,
        covers=["depth PNG"],
    )
    pin = {"model": "pinhole", "fx": 60.0, "fy": 60.0, "cx": 48.0, "cy": 24.0,
           "width": 96, "height": 48}  # fmt: skip
    small = _png(np.full((48, 96), 3000, np.uint16))
    for label, change in (
        ("negative-fx", {"fx": -60.0}),
        ("nan-fy", {"fy": float("nan")}),
        ("infinite-cx", {"cx": float("inf")}),
        ("missing-fx", {"fx": None}),
        ("zero-width", {"width": 0}),
        ("size-not-the-image", {"width": 640, "height": 480}),
        ("unknown-model", {"model": "fisheye"}),
    ):
        cam = {k: v for k, v in {**pin, **change}.items() if v is not None}
        c.case(
            f"sidecar-{label}",
            "broken",
            ["info", "{d}/depth.png"],
            ["depth.camera.json", *(["depth.png"] if label == "size-not-the-image" else [])],
            files={"depth.png": small, "depth.camera.json": json.dumps({"camera": cam})},
            memory_limit=True,
            covers=["camera sidecar"],
        )
    c.case(
        "sidecar-not-json",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.camera.json"],
        files={"depth.png": small, "depth.camera.json": "camera: pinhole\n"},
        memory_limit=True,
        covers=["camera sidecar"],
    )
    sph = {"model": "spherical", "width": 96, "height": 48, "phi_min": -3.1, "phi_max": 3.1,
           "theta_min": 2.0, "theta_max": 1.0}  # fmt: skip
    c.case(
        "sidecar-spherical-theta-reversed",
        "broken",
        ["info", "{d}/depth.png"],
        ["depth.camera.json"],
        files={"depth.png": small, "depth.camera.json": json.dumps({"camera": sph})},
        memory_limit=True,
        covers=["camera sidecar"],
    )
    for label, argv in (
        ("negative", ["--pinhole", "-60", "60", "48", "24"]),
        ("nan", ["--pinhole", "60", "nan", "48", "24"]),
    ):
        c.case(
            f"depth-pinhole-option-{label}",
            "option",
            ["info", "{d}/plain.png", *argv],
            ["--pinhole"],
            files={"plain.png": small},
            memory_limit=True,
            covers=["depth PNG", "option"],
        )


# ------------------------------------------------------------------- degenerate clouds
def _degenerate(c: Corpus) -> None:
    """Clouds that read fine but cannot be registered: one error naming the file, not a
    ZeroDivisionError (the issue's report)."""
    for label, pts in (
        ("identical-points", identical()),
        ("points-on-a-line", on_a_line()),
        ("points-on-a-ray", on_a_ray()),
        ("one-point", identical(1)),
    ):
        c.case(
            f"register-kitti-{label}",
            "broken",
            ["register", "{d}/room.ptx", "{d}/bad.bin", "--out", "{d}/T.json"],
            ["bad.bin"],
            good=("room.ptx",),
            files={"bad.bin": kitti_bytes(pts)},
            covers=["KITTI .bin", "degenerate cloud"],
        )
    for label, pts in (
        ("identical-points", identical(48 * 96)),
        ("points-on-a-line", on_a_line(48 * 96)),
    ):
        c.case(
            f"register-ptx-{label}",
            "broken",
            ["register", "{d}/bad.ptx", "{d}/room.ptx", "--out", "{d}/T.json"],
            ["bad.ptx"],
            good=("room.ptx",),
            files={"bad.ptx": ptx_bytes(pts, 96, 48)},
            covers=["PTX", "degenerate cloud"],
        )
    c.case(
        "project-points-on-a-ray",
        "broken",
        ["project", "{d}/ray.bin", "--out", "{d}/r.png"],
        ["ray.bin"],
        files={"ray.bin": kitti_bytes(on_a_ray())},
        memory_limit=True,
        covers=["KITTI .bin", "degenerate cloud"],
    )
    c.case(
        "convert-one-point-ply",
        "broken",
        ["convert", "{d}/one.ply", "--kind", "flexion", "--out", "{d}/f.png"],
        ["one.ply"],
        files={"one.ply": ply_bytes(np.array([[1.0, 2.0, 0.5]]))},
        covers=["PLY", "degenerate cloud"],
    )
