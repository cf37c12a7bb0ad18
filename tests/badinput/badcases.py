"""The cases of the bad-input corpus (see ``make_corpus.py`` for what a case is and checks).

Grouped by failure class; each ``c.case(...)`` names the folder, the class, the command line
(``{d}`` = the case folder), the names one of which the error line must hold, and the files.
"""

from __future__ import annotations

import json
import os
import struct
import zipfile
from io import BytesIO
from pathlib import Path

import numpy as np
from make_corpus import (
    Corpus,
    e57_edit_xml,
    npy_header,
    pcd_bytes,
    ply_bytes,
    png_header_only,
)


def add_cases(c: Corpus) -> None:
    """Every case, class by class."""
    _overwrite(c)
    _partial(c)
    _header(c)
    _halfread(c)
    _options(c)
    _broken(c)


# ------------------------------------------------------------------------------ overwrite
def _overwrite(c: Corpus) -> None:
    depth = ("depth.png", "depth.camera.json")
    c.case(
        "convert-out-is-input",
        "overwrite",
        ["convert", "{d}/depth.png", "--kind", "flexion", "--out", "{d}/depth.png"],
        ["depth.png"],
        good=depth,
    )
    c.case(
        "project-out-is-input",
        "overwrite",
        ["project", "{d}/depth.png", "--out", "{d}/depth.png"],
        ["depth.png"],
        good=depth,
    )
    c.case(
        "project-npz-is-input",
        "overwrite",
        ["project", "{d}/depth.npz", "--resample", "--out", "{d}/depth.png"],
        ["depth.npz"],
        good=("room.npz",),
        setup=lambda d: os.replace(d / "room.npz", d / "depth.npz"),
    )
    c.case(
        "register-out-is-input-sidecar",
        "overwrite",
        ["register", "{d}/depth.png", "{d}/room.ptx", "--out", "{d}/depth.camera.json"],
        ["depth.camera.json"],
        good=(*depth, "room.ptx"),
    )
    c.case(
        "register-out-is-truth",
        "overwrite",
        [
            "register",
            "{d}/room.ptx",
            "{d}/room2.ptx",
            "--truth",
            "{d}/T.json",
            "--out",
            "{d}/T.json",
        ],
        ["T.json"],
        good=("room.ptx", "room2.ptx", "T.json"),
    )
    c.case(
        "register-txt-is-input",
        "overwrite",
        [
            "register",
            "{d}/room.ptx",
            "{d}/room2.ptx",
            "--out",
            "{d}/r.json",
            "--txt",
            "{d}/room.ptx",
        ],
        ["room.ptx"],
        good=("room.ptx", "room2.ptx"),
    )
    c.case(
        "register-out-is-config",
        "overwrite",
        [
            "register",
            "{d}/room.ptx",
            "{d}/room2.ptx",
            "--config",
            "{d}/run.json",
            "--out",
            "{d}/run.json",
        ],
        ["run.json"],
        good=("room.ptx", "room2.ptx"),
        files={"run.json": json.dumps({"config": {"n": 7}})},
    )
    c.case(
        "convert-out-symlink-to-input",
        "overwrite",
        ["convert", "{d}/depth.png", "--kind", "range", "--out", "{d}/link.png"],
        ["link.png"],
        good=depth,
        setup=lambda d: os.symlink("depth.png", d / "link.png"),
    )
    c.case(
        "project-out-hardlink-to-input",
        "overwrite",
        ["project", "{d}/depth.png", "--out", "{d}/hard.png"],
        ["hard.png"],
        good=depth,
        setup=lambda d: os.link(d / "depth.png", d / "hard.png"),
    )
    c.case(
        "evaluate-json-is-gt",
        "overwrite",
        ["evaluate", "--gt", "{d}/gt.json", "--est", "{d}/est.txt", "--json", "{d}/gt.json"],
        ["gt.json"],
        good=("est.txt",),
        files={"gt.json": c.good["gt.txt"]},
    )
    c.case(
        "convert-keep-float-npz-is-input",
        "overwrite",
        ["convert", "{d}/depth.npz", "--kind", "range", "--keep-float", "--out", "{d}/depth.png"],
        ["depth.npz"],
        good=("room.npz",),
        setup=lambda d: os.replace(d / "room.npz", d / "depth.npz"),
    )


# -------------------------------------------------------------------------------- partial
def _partial(c: Corpus) -> None:
    def blocked_sidecar(d: Path) -> None:
        (d / "prev.png").write_bytes(b"previous range image")
        (d / "prev.npz").write_bytes(b"previous arrays")
        (d / "prev.camera.json").mkdir()  # the third output cannot be written

    c.case(
        "project-third-output-fails",
        "partial",
        ["project", "{d}/depth.png", "--out", "{d}/prev.png", "--overwrite"],
        ["prev.camera.json"],
        good=("depth.png", "depth.camera.json"),
        setup=blocked_sidecar,
        note="png and npz are staged before the sidecar fails: the previous ones stay",
    )

    def blocked_json(d: Path) -> None:
        (d / "prev.png").write_bytes(b"previous plot")
        (d / "blocker").write_text("a file where a folder is needed")

    c.case(
        "evaluate-second-output-fails",
        "partial",
        [
            "evaluate",
            "--gt",
            "{d}/gt.txt",
            "--est",
            "{d}/est.txt",
            "--plot",
            "{d}/prev.png",
            "--json",
            "{d}/blocker/run.json",
            "--overwrite",
        ],
        ["blocker"],
        good=("gt.txt", "est.txt"),
        setup=blocked_json,
    )


# --------------------------------------------------------------------------------- header
def _header(c: Corpus) -> None:
    flat = c.flat
    las = bytearray(c.good["room.las"])
    struct.pack_into("<I", las, 107, 400_000_000)
    c.case(
        "las-claims-400M-points",
        "header",
        ["info", "{d}/huge.las"],
        ["huge.las"],
        files={"huge.las": bytes(las)},
        memory_limit=True,
    )
    laz = bytearray(c.good["room.laz"])
    struct.pack_into("<I", laz, 107, 400_000_000)
    c.case(
        "laz-claims-400M-points",
        "header",
        ["info", "{d}/huge.laz"],
        ["huge.laz"],
        files={"huge.laz": bytes(laz)},
        memory_limit=True,
    )
    c.case(
        "e57-grid-bounds-40001",
        "header",
        ["info", "{d}/grid.e57"],
        ["grid.e57"],
        files={"grid.e57": _e57_bounds(c.good["room.e57"], 40000)},
        memory_limit=True,
    )
    c.case(
        "e57-record-count-raised",
        "header",
        ["info", "{d}/raised.e57"],
        ["raised.e57"],
        files={"raised.e57": _e57_count(c.good["room.e57"], lambda n: n * 1000)},
        memory_limit=True,
    )
    c.case(
        "ply-claims-400M-vertices",
        "header",
        ["info", "{d}/huge.ply"],
        ["huge.ply"],
        files={"huge.ply": ply_bytes(flat, count=400_000_000)},
        memory_limit=True,
    )
    c.case(
        "pcd-claims-400M-points",
        "header",
        ["info", "{d}/huge.pcd"],
        ["huge.pcd"],
        files={"huge.pcd": pcd_bytes(flat, count=400_000_000)},
        memory_limit=True,
    )
    c.case(
        "pcd-organised-claims-40001-squared",
        "header",
        ["info", "{d}/grid.pcd"],
        ["grid.pcd"],
        files={"grid.pcd": pcd_bytes(flat, count=40001 * 40001, width=40001, height=40001)},
        memory_limit=True,
    )
    c.case(
        "npz-claims-30000-squared-grid",
        "header",
        ["info", "{d}/grid.npz"],
        ["grid.npz"],
        files={"grid.npz": _npz_grid(c.good["room.npz"], (30000, 30000))},
        memory_limit=True,
    )
    c.case(
        "npz-member-header-claims-2G-points",
        "header",
        ["info", "{d}/big.npz"],
        ["big.npz"],
        files={"big.npz": _npz_raw({"points.npy": npy_header((2_000_000_000, 3)) + bytes(96)})},
        memory_limit=True,
    )
    c.case(
        "npy-header-claims-2G-points",
        "header",
        ["info", "{d}/big.npy"],
        ["big.npy"],
        files={"big.npy": npy_header((2_000_000_000, 3)) + bytes(96)},
        memory_limit=True,
    )
    ptx = c.good["room.ptx"].split(b"\n")
    c.case(
        "ptx-header-claims-40001-squared",
        "header",
        ["info", "{d}/grid.ptx"],
        ["grid.ptx"],
        files={"grid.ptx": b"\n".join([b"40001", b"40001", *ptx[2:]])},
        memory_limit=True,
    )
    c.case(
        "png-header-claims-100000-squared",
        "header",
        ["info", "{d}/huge.png"],
        ["huge.png"],
        files={
            "huge.png": png_header_only(100_000, 100_000),
            "huge.camera.json": json.dumps(
                {
                    "camera": {
                        "model": "pinhole",
                        "fx": 5e4,
                        "fy": 5e4,
                        "cx": 5e4,
                        "cy": 5e4,
                        "width": 100_000,
                        "height": 100_000,
                    }
                }
            ),
        },
        memory_limit=True,
    )
    c.case(
        "calibrate-image-header-claims-100000-squared",
        "header",
        [
            "calibrate",
            "--image",
            "{d}/camera.png",
            "--pinhole",
            "500",
            "500",
            "320",
            "240",
            "--scan",
            "{d}/room.ptx",
            "--pairs",
            "{d}/pairs.csv",
            "--out",
            "{d}/calib.json",
        ],
        ["camera.png"],
        good=("room.ptx",),
        files={"camera.png": png_header_only(100_000, 100_000), "pairs.csv": "u,v,X,Y,Z\n"},
        memory_limit=True,
    )
    c.case(
        "memory-budget-too-small-for-scan",
        "header",
        ["--memory-budget", "64K", "info", "{d}/room.ptx"],
        ["room.ptx"],
        good=("room.ptx",),
        memory_limit=True,
    )
    c.case(
        "budget-from-environment",
        "header",
        ["info", "{d}/room.e57"],
        ["room.e57"],
        good=("room.e57",),
        env={"FLEXREG_MEMORY_BUDGET": "100K"},
        memory_limit=True,
    )


def _e57_bounds(data: bytes, maximum: int) -> bytes:
    import re

    def edit(xml: str) -> str:
        xml = re.sub(r"(<rowMaximum[^>]*>)\d+(<)", rf"\g<1>{maximum}\g<2>", xml)
        return re.sub(r"(<columnMaximum[^>]*>)\d+(<)", rf"\g<1>{maximum}\g<2>", xml)

    return e57_edit_xml(data, edit)


def _e57_count(data: bytes, change) -> bytes:
    import re

    def edit(xml: str) -> str:
        return re.sub(
            r'recordCount="(\d+)"', lambda m: f'recordCount="{change(int(m.group(1)))}"', xml
        )

    return e57_edit_xml(data, edit)


def _npz_grid(data: bytes, shape: tuple[int, int]) -> bytes:
    with np.load(BytesIO(data)) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["grid_shape"] = np.array(shape, dtype=np.int64)
    buf = BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _npz_raw(members: dict[str, bytes]) -> bytes:
    buf = BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, content in members.items():
            z.writestr(name, content)
    return buf.getvalue()


# ------------------------------------------------------------------------------- halfread
def _halfread(c: Corpus) -> None:
    flat = c.flat
    n = len(flat)
    c.case(
        "ply-vertex-count-100-low",
        "halfread",
        ["info", "{d}/low.ply"],
        ["low.ply"],
        files={"low.ply": ply_bytes(flat, count=n - 100)},
        memory_limit=True,
    )
    c.case(
        "ply-ascii-vertex-count-low",
        "halfread",
        ["info", "{d}/low.ply"],
        ["low.ply"],
        files={"low.ply": ply_bytes(flat, count=n - 100, ascii=True)},
        memory_limit=True,
    )
    c.case(
        "pcd-points-low",
        "halfread",
        ["info", "{d}/low.pcd"],
        ["low.pcd"],
        files={"low.pcd": pcd_bytes(flat, count=n - 100)},
        memory_limit=True,
    )
    c.case(
        "pcd-ascii-points-low",
        "halfread",
        ["info", "{d}/low.pcd"],
        ["low.pcd"],
        files={"low.pcd": pcd_bytes(flat, count=n - 100, ascii=True)},
        memory_limit=True,
    )
    las = bytearray(c.good["room.las"])
    struct.pack_into("<I", las, 107, n - 100)
    c.case(
        "las-point-count-low",
        "halfread",
        ["info", "{d}/low.las"],
        ["low.las"],
        files={"low.las": bytes(las)},
        memory_limit=True,
    )
    c.case(
        "e57-record-count-lowered",
        "halfread",
        ["info", "{d}/low.e57"],
        ["low.e57"],
        files={"low.e57": _e57_count(c.good["room.e57"], lambda k: k // 4)},
        memory_limit=True,
    )
    ptx = c.good["room.ptx"].split(b"\n")
    c.case(
        "ptx-fewer-lines-than-header",
        "halfread",
        ["info", "{d}/cut.ptx"],
        ["cut.ptx"],
        files={"cut.ptx": b"\n".join(ptx[: len(ptx) // 2])},
        memory_limit=True,
    )
    side = json.loads(c.good["depth.camera.json"])
    for key, value, label in (
        ("depth_scale", None, "null"),
        ("depth_scale", "0.001", "string"),
        ("depth_scale", -1.0, "negative"),
        ("depth_kind", 3, "number"),
        ("invalid_values", "0", "string"),
    ):
        doc = {**side, key: value}
        c.case(
            f"sidecar-{key.replace('_', '-')}-{label}",
            "halfread",
            ["info", "{d}/depth.png"],
            ["depth.camera.json"],
            good=("depth.png",),
            files={"depth.camera.json": json.dumps(doc)},
            memory_limit=True,
        )
    cam = dict(side["camera"])
    cam["width"] = "wide"
    c.case(
        "sidecar-camera-field-wrong-type",
        "halfread",
        ["info", "{d}/depth.png"],
        ["depth.camera.json"],
        good=("depth.png",),
        files={"depth.camera.json": json.dumps({**side, "camera": cam})},
        memory_limit=True,
    )
    c.case(
        "sidecar-camera-missing",
        "halfread",
        ["info", "{d}/depth.png"],
        ["depth.camera.json"],
        good=("depth.png",),
        files={"depth.camera.json": json.dumps({"depth_scale": 0.001})},
        memory_limit=True,
    )
    text = b"".join(f"{x:.3f} {y:.3f} {z:.3f} 0.5\n".encode() for x, y, z in flat[:400])
    text += b" " * (-len(text) % 16)
    c.case(
        "kitti-text-file",
        "halfread",
        ["info", "{d}/text.bin"],
        ["text.bin"],
        files={"text.bin": text},
        memory_limit=True,
    )
    kitti = np.frombuffer(c.good["room.bin"], dtype="<f4").reshape(-1, 4)
    c.case(
        "kitti-float64-file",
        "halfread",
        ["info", "{d}/f64.bin"],
        ["f64.bin"],
        files={"f64.bin": kitti.astype("<f8").tobytes()},
        memory_limit=True,
    )
    c.case(
        "npz-corrupt-member",
        "halfread",
        ["info", "{d}/bad.npz"],
        ["bad.npz"],
        files={"bad.npz": _corrupt_npz(c.good["room.npz"])},
        memory_limit=True,
    )


def _corrupt_npz(data: bytes) -> bytes:
    """Flip bytes inside the compressed data of the ``points`` member (CRC no longer holds)."""
    b = bytearray(data)
    with zipfile.ZipFile(BytesIO(data)) as z:
        info = z.getinfo("points.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 40
    for k in range(start, start + 64):
        b[k] ^= 0x5A
    return bytes(b)


# -------------------------------------------------------------------------------- options
def _options(c: Corpus) -> None:
    depth = ("depth.png", "depth.camera.json")
    pair = ("room.ptx", "room2.ptx")
    reg = ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/T.json"]
    conv = ["convert", "{d}/depth.png", "--kind", "flexion", "--out", "{d}/f.png"]
    for id, argv, names, good in (
        ("convert-n-999", [*conv, "--n", "999"], ["--n"], depth),
        ("convert-n-100001", [*conv, "--n", "100001"], ["--n"], depth),
        ("convert-n-even", [*conv, "--n", "4"], ["--n"], depth),
        ("register-threshold-1e9", [*reg, "--threshold", "1e9"], ["--threshold"], pair),
        ("register-voxel-1e-12", [*reg, "--voxel", "1e-12"], ["--voxel"], pair),
        ("register-voxel-nan", [*reg, "--voxel", "nan"], ["--voxel"], pair),
        ("synth-size-nan", ["synth", "--size-m", "nanxnan", "--out", "{d}/s"], ["--size-m"], ()),
        (
            "synth-resolution-beyond-maximum",
            ["synth", "--resolution", "20000x10000", "--out", "{d}/s"],
            ["--resolution"],
            (),
        ),
        (
            "synth-resolution-beyond-budget",
            ["--memory-budget", "1G", "synth", "--resolution", "8192x4096", "--out", "{d}/s"],
            ["--resolution"],
            (),
        ),
        (
            "project-resolution-deg-0.0005",
            [
                "project",
                "{d}/room.npz",
                "--resample",
                "--resolution-deg",
                "0.0005",
                "--out",
                "{d}/r.png",
            ],
            ["--resolution-deg"],
            ("room.npz",),
        ),
        (
            "project-resolution-deg-nan",
            ["project", "{d}/room.npz", "--resolution-deg", "nan", "--out", "{d}/r.png"],
            ["--resolution-deg"],
            ("room.npz",),
        ),
        (
            "memory-budget-not-a-size",
            ["--memory-budget", "lots", "info", "{d}/room.npz"],
            ["--memory-budget"],
            ("room.npz",),
        ),
        (
            "memory-budget-env-not-a-size",
            ["info", "{d}/room.npz"],
            ["FLEXREG_MEMORY_BUDGET"],
            ("room.npz",),
        ),
    ):
        env = {"FLEXREG_MEMORY_BUDGET": "-3G"} if id == "memory-budget-env-not-a-size" else {}
        c.case(
            id,
            "option",
            argv,
            names,
            good=good,
            env=env,
            memory_limit=not id.startswith(("register", "convert")),
        )


# --------------------------------------------------------------------------------- broken
def _broken(c: Corpus) -> None:
    flat = c.flat
    for name, content in (
        ("empty.ptx", b""),
        ("garbage.e57", b"this is not an E57 file at all\n" * 40),
        (
            "garbage.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n",
        ),
        ("garbage.laz", b"LASF" + bytes(range(256)) * 8),
        ("garbage.npz", b"PK\x03\x04" + bytes(500)),
        (
            "nan.ptx",
            b"2\n1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
            b"nan 1 2 0.5\n1 2 3 0.5\n",
        ),
        ("e30.bin", np.tile(np.array([1e30, 0, 0, 0.5], "<f4"), 64).tobytes()),
    ):
        c.case(
            f"broken-{name.replace('.', '-')}",
            "broken",
            ["info", "{d}/" + name],
            [name],
            files={name: content},
            memory_limit=True,
        )
    c.case(
        "broken-folder-as-scan",
        "broken",
        ["info", "{d}/scan.ptx"],
        ["scan.ptx"],
        setup=lambda d: (d / "scan.ptx").mkdir(),
        memory_limit=True,
    )
    c.case(
        "broken-missing-scan", "broken", ["info", "{d}/none.ptx"], ["none.ptx"], memory_limit=True
    )
    reg = ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/T2.json", "--truth"]
    pair = ("room.ptx", "room2.ptx")
    for name, text in (
        ("ragged.txt", "1 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("words.txt", "one 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("ragged.json", json.dumps({"T_target_source": [[1, 0, 0, 0], [0, 1, 0], [0, 0, 1, 0]]})),
        ("words.json", json.dumps({"T_target_source": "identity"})),
        (
            "pairs.json",
            json.dumps(
                {"pairs": [{"target": "room", "source": "room2", "T_target_source": [[1, 2], [3]]}]}
            ),
        ),
        ("pairs-list.json", json.dumps({"pairs": [1, 2, 3]})),
        ("skew.txt", "1 0.5 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
    ):
        c.case(
            f"truth-{name.replace('.', '-')}",
            "broken",
            [*reg, "{d}/" + name],
            [name],
            good=pair,
            files={name: text},
        )
    c.case(
        "evaluate-non-numeric-estimate",
        "broken",
        ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/est.txt"],
        ["est.txt"],
        good=("gt.txt",),
        files={"est.txt": "0.0 0 0 0 0 0 0 1\n0.1 zero 0 0 0 0 0 1\n"},
    )
    c.case(
        "register-unrelated-scans-names-both",
        "pair",
        ["register", "{d}/room.ptx", "{d}/noise.bin", "--out", "{d}/T.json"],
        ["room.ptx ↔", "noise.bin"],
        good=("room.ptx",),
        files={"noise.bin": _noise_bin()},
    )
    del flat


def _noise_bin() -> bytes:
    rng = np.random.default_rng(3)
    pts = rng.uniform(-20, 20, (3000, 3))
    return np.concatenate([pts, np.full((3000, 1), 0.5)], axis=1).astype("<f4").tobytes()
