"""Bad-input cases for every text, CSV, JSON and configuration file the command line reads
(correspondence CSVs, survey pairs, trajectories, intrinsics, --config TOML, --set, 4x4
transforms for --init and --truth), outputs that cannot be written, survey folders, and the
options of every command.

See ``make_corpus.py`` for what a case is and what it must do.
"""

from __future__ import annotations

import json

import numpy as np
from make_corpus import Corpus

PAIR = ("room.ptx", "room2.ptx")
#: ten correspondences in general position (u, v pixels of a 160 x 120 image; X Y Z metres)
GOOD_PAIRS = "u,v,X,Y,Z\n" + "".join(
    f"{u:.1f},{v:.1f},{x:.3f},{y:.3f},{z:.3f}\n"
    for (u, v), (x, y, z) in zip(
        np.random.default_rng(2).uniform([10, 10], [150, 110], (10, 2)),
        np.random.default_rng(3).uniform([-2, -2, 2], [2, 2, 5], (10, 3)),
        strict=True,
    )
)
REG = ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/T.json"]


def add_file_cases(c: Corpus) -> None:
    """Every text input and every command's options."""
    _calibration(c)
    _survey(c)
    _trajectories(c)
    _configs(c)
    _transforms(c)
    _outputs(c)
    _command_options(c)
    _pick_and_config(c)
    _odometry_sequences(c)


def _camera_png() -> bytes:
    import cv2

    img = (np.random.default_rng(1).integers(0, 255, (120, 160))).astype(np.uint8)
    return cv2.imencode(".png", img)[1].tobytes()


# ----------------------------------------------------------------- calibrate: pairs, camera
def _calibration(c: Corpus) -> None:
    cal = [
        "calibrate", "--image", "{d}/camera.png", "--scan", "{d}/room.ptx",
        "--out", "{d}/calib.json",
    ]  # fmt: skip
    pin = ["--pinhole", "100", "100", "80", "60"]
    rng = np.random.default_rng(2)
    uv = rng.uniform([10, 10], [150, 110], (10, 2))
    xyz = rng.uniform([-2, -2, 2], [2, 2, 5], (10, 3))
    good = "u,v,X,Y,Z\n" + "".join(
        f"{u:.1f},{v:.1f},{x:.3f},{y:.3f},{z:.3f}\n"
        for (u, v), (x, y, z) in zip(uv, xyz, strict=True)
    )
    line = "u,v,X,Y,Z\n" + "".join(
        f"{u:.1f},{v:.1f},{t:.3f},{2 * t:.3f},{3 + t:.3f}\n"
        for (u, v), t in zip(uv, np.linspace(0, 1, 10), strict=True)
    )
    rows = good.splitlines()
    for label, text in (
        ("non-numeric", "\n".join([*rows[:3], "12,abc,1,2,3", *rows[3:]]) + "\n"),
        ("wrong-field-count", "\n".join([*rows[:3], "12,13,1,2", *rows[3:]]) + "\n"),
        ("bad-header", "a,b,c,d,e\n" + "\n".join(rows[1:]) + "\n"),
        ("nan-point", "\n".join([*rows[:3], "12,13,nan,2,3", *rows[3:]]) + "\n"),
        ("empty", ""),
        ("too-few-pairs", "\n".join(rows[:4]) + "\n"),
        ("points-on-one-line", line),
    ):
        c.case(
            f"calibrate-pairs-{label}",
            "broken",
            [*cal, *pin, "--pairs", "{d}/pairs.csv"],
            ["pairs.csv"],
            good=("room.ptx",),
            files={"camera.png": _camera_png(), "pairs.csv": text},
            covers=["pairs CSV"],
        )
    K = [[100, 0, 80], [0, 100, 60], [0, 0, 1]]
    for label, doc, name in (
        ("negative-fx", {"K": [[-100, 0, 80], [0, 100, 60], [0, 0, 1]]}, "cam.json"),
        ("nan-fy", {"K": [[100, 0, 80], [0, float("nan"), 60], [0, 0, 1]]}, "cam.json"),
        ("k-wrong-shape", {"K": [[100, 0, 80], [0, 100, 60]]}, "cam.json"),
        ("missing-k", {"distortion": [0, 0, 0, 0]}, "cam.json"),
        ("distortion-length-3", {"K": K, "distortion": [0.1, 0.2, 0.3]}, "cam.json"),
        ("yaml-garbage", "%YAML:1.0\n---\ncamera_matrix: [[[\n", "cam.yaml"),
        ("unknown-suffix", {"K": K}, "cam.ini"),
    ):
        c.case(
            f"calibrate-intrinsics-{label}",
            "broken",
            [*cal, "--camera", "{d}/" + name, "--pairs", "{d}/pairs.csv"],
            [name],
            good=("room.ptx",),
            files={
                "camera.png": _camera_png(),
                "pairs.csv": good,
                name: doc if isinstance(doc, str) else json.dumps(doc),
            },
            covers=["intrinsics"],
        )
    c.case(
        "calibrate-init-not-rigid",
        "broken",
        [*cal, *pin, "--auto", "--init", "{d}/init.txt"],
        ["init.txt"],
        good=("room.ptx",),
        files={"camera.png": _camera_png(), "init.txt": "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"},
        covers=["4x4 transform (--init)"],
    )


# ------------------------------------------------------------------------------- survey
def _survey(c: Corpus) -> None:
    stations = ("room.ptx", "room2.ptx")
    sv = ["survey", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/out", "--workers", "1"]
    for label, text in (
        ("unknown-station", "target,source\nroom,nosuch\n"),
        ("self-pair", "room,room\n"),
        ("one-column", "room\n"),
        ("no-pairs", "target,source\n"),
        ("binary", "\x00\x01\x02room,room2\xff\n"),
    ):
        c.case(
            f"survey-pairs-{label}",
            "broken",
            [*sv, "--pairs", "{d}/pairs.csv"],
            ["pairs.csv"],
            good=stations,
            files={"pairs.csv": text},
            covers=["survey pairs CSV"],
        )
    c.case(
        "survey-empty-folder",
        "broken",
        ["survey", "{d}/scans", "--out", "{d}/out"],
        ["scans"],
        setup=lambda d: (d / "scans").mkdir(),
        covers=["survey folder"],
    )
    c.case(
        "survey-folder-of-garbage",
        "broken",
        ["survey", "{d}/scans", "--out", "{d}/out", "--workers", "1"],
        ["scans"],
        setup=_garbage_scans,
        covers=["survey folder"],
    )
    c.case(
        "survey-one-station",
        "broken",
        ["survey", "{d}/room.ptx", "--out", "{d}/out"],
        ["room.ptx", "station"],
        good=("room.ptx",),
        covers=["survey folder"],
    )
    c.case(
        "survey-out-is-a-file",
        "broken",
        [*sv[:3], "--out", "{d}/room.ptx"],
        ["room.ptx"],
        good=stations,
        covers=["output path"],
    )
    c.case(
        "survey-missing-station",
        "broken",
        ["survey", "{d}/room.ptx", "{d}/none.ptx", "--out", "{d}/out"],
        ["none.ptx"],
        good=("room.ptx",),
        covers=["survey folder"],
    )


def _pick_and_config(c: Corpus) -> None:
    """``pick`` refuses its inputs before starting a server; ``config show`` an unknown name."""
    pick = [
        "pick", "--image", "{d}/camera.png", "--scan", "{d}/room.ptx", "--out", "{d}/p.csv",
        "--no-browser", "--pinhole", "100", "100", "80", "60",
    ]  # fmt: skip
    for label, files, names in (
        ("image-garbage", {"camera.png": b"not an image"}, ["camera.png"]),
        (
            "pairs-non-numeric",
            {"camera.png": _camera_png(), "old.csv": "u,v,X,Y,Z\n1,2,a,4,5\n"},
            ["old.csv"],
        ),
    ):
        extra = ["--pairs", "{d}/old.csv"] if "old.csv" in files else []
        c.case(
            f"pick-{label}",
            "broken",
            [*pick, *extra],
            names,
            good=("room.ptx",),
            files=files,
            covers=["pairs CSV" if extra else "option"],
        )
    c.case(
        "pick-out-is-the-scan",
        "overwrite",
        [*pick[:6], "{d}/room.ptx", *pick[7:]],
        ["room.ptx"],
        good=("room.ptx",),
        files={"camera.png": _camera_png()},
        covers=["output path"],
    )
    c.case(
        "config-show-unknown-name",
        "option",
        ["config", "show", "nosuch"],
        ["nosuch"],
        covers=["option"],
    )


def _odometry_sequences(c: Corpus) -> None:
    """A TUM RGB-D sequence whose list files or depth images are broken."""

    def missing_frame(d) -> None:
        _tum_sequence(d)
        (d / "seq" / "depth.txt").write_text("0.0 depth/0.png\n0.1 depth/9.png\n")

    def word_timestamp(d) -> None:
        _tum_sequence(d)
        (d / "seq" / "depth.txt").write_text("zero depth/0.png\n0.1 depth/1.png\n")

    def eight_bit(d) -> None:
        import cv2

        _tum_sequence(d)
        cv2.imwrite(str(d / "seq" / "depth" / "1.png"), np.full((48, 64), 50, np.uint8))

    for label, setup, names in (
        ("missing-frame", missing_frame, ["depth.txt"]),
        ("non-numeric-timestamp", word_timestamp, ["depth.txt"]),
        ("8-bit-depth-frame", eight_bit, ["1.png"]),
    ):
        c.case(
            f"odometry-{label}",
            "broken",
            ["odometry", "{d}/seq", "--out", "{d}/t.txt"],
            names,
            setup=setup,
            covers=["odometry sequence"],
        )


def _garbage_scans(d) -> None:
    (d / "scans").mkdir()
    for i in range(3):
        (d / "scans" / f"st{i}.ptx").write_bytes(b"not a ptx file\n" * (i + 1))


# ------------------------------------------------------------------------- trajectories
def _trajectories(c: Corpus) -> None:
    gt = c.good["gt.txt"].decode().splitlines()
    ev = ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/est.txt"]
    for label, lines in (
        ("duplicate-timestamp", [*gt[:5], gt[4].split()[0] + " 5 5 5 0 0 0 1", *gt[5:]]),
        ("non-monotonic-timestamps", [gt[0], gt[2], gt[1], *gt[3:]]),
        ("quaternion-not-unit", [*gt[:3], gt[3].rsplit(" ", 1)[0] + " 3", *gt[4:]]),
        ("wrong-value-count", [*gt[:3], "0.33 1 2 3", *gt[3:]]),
        ("nan-position", [*gt[:3], "0.33 nan 0 0 0 0 0 1", *gt[3:]]),
        ("only-comments", ["# nothing here", ""]),
    ):
        c.case(
            f"evaluate-gt-{label}",
            "broken",
            ev,
            ["gt.txt"],
            good=("est.txt",),
            files={"gt.txt": "\n".join(lines) + "\n"},
            covers=["TUM trajectory"],
        )
    kitti = ["1 0 0 0 0 1 0 0 0 0 1 0", "1 0 0 1 0 1 0 0 0 0 1 0", "1 0 0 2 0 1 0 0 0 0 1 0"]
    for label, lines in (
        ("kitti-not-rotation", [kitti[0], "2 0 0 1 0 1 0 0 0 0 1 0", kitti[2]]),
        ("kitti-reflection", [kitti[0], "-1 0 0 1 0 1 0 0 0 0 1 0", kitti[2]]),
        ("kitti-eleven-values", [kitti[0], kitti[1][:-2], kitti[2]]),
    ):
        c.case(
            f"evaluate-{label}",
            "broken",
            ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/est.txt", "--format", "kitti"],
            ["est.txt"],
            files={"gt.txt": "\n".join(kitti) + "\n", "est.txt": "\n".join(lines) + "\n"},
            covers=["KITTI trajectory"],
        )
    c.case(
        "evaluate-no-common-timestamps",
        "broken",
        ev,
        ["est.txt", "gt.txt"],
        good=("gt.txt",),
        files={"est.txt": "100.0 0 0 0 0 0 0 1\n100.1 1 0 0 0 0 0 1\n"},
        covers=["TUM trajectory"],
    )
    c.case(
        "evaluate-gt-is-a-folder",
        "broken",
        ev,
        ["gt.txt"],
        good=("est.txt",),
        setup=lambda d: (d / "gt.txt").mkdir(),
        covers=["TUM trajectory"],
    )


# ---------------------------------------------------------------- --config TOML and --set
def _configs(c: Corpus) -> None:
    for label, text, name in (
        ("toml-syntax", "n = = 7\n", "--config"),
        ("unknown-field", "no_such_field = 3\n", "no_such_field"),
        ("wrong-type", 'n = "seven"\n', "run.toml"),
        ("out-of-range", "n = 4\n", "run.toml"),
        ("nan-threshold", "ratio = nan\n", "run.toml"),
        ("binary", "\x00\xff\xfe", "run.toml"),
        ("array-instead-of-table", "[[n]]\nx = 1\n", "run.toml"),
    ):
        c.case(
            f"config-{label}",
            "broken",
            [*REG, "--config", "{d}/run.toml"],
            [name, "run.toml"],
            good=PAIR,
            files={"run.toml": text},
            covers=["config TOML"],
        )
    c.case(
        "config-missing-file",
        "broken",
        [*REG, "--config", "{d}/none.toml"],
        ["none.toml"],
        good=PAIR,
        covers=["config TOML"],
    )
    c.case(
        "config-yaml-suffix",
        "broken",
        [*REG, "--config", "{d}/run.yaml"],
        ["run.yaml"],
        good=PAIR,
        files={"run.yaml": "n: 7\n"},
        covers=["config TOML"],
    )
    for cmd_argv, label in (
        (["synth", "--out", "{d}/s", "--config", "{d}/run.toml"], "synth"),
        (
            ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/gt.txt", "--config", "{d}/run.toml"],
            "evaluate",
        ),
    ):
        c.case(
            f"config-unknown-field-{label}",
            "broken",
            cmd_argv,
            ["no_such_field"],
            good=("gt.txt",),
            files={"run.toml": "no_such_field = 1\n"},
            covers=["config TOML"],
        )
    for label, item, names in (
        ("no-equals", "n7", ["--set"]),
        ("empty-key", "=7", ["--set"]),
        ("unknown-key", "bogus=1", ["bogus"]),
        ("bad-value", "ratio=abc", ["ratio"]),
        ("out-of-range", "n=2", ["n"]),
        ("nan", "ratio=nan", ["ratio"]),
    ):
        c.case(
            f"set-{label}",
            "option",
            [*REG, "--set", item],
            names,
            good=PAIR,
            covers=["--set"],
        )
    c.case(
        "set-unknown-key-survey",
        "option",
        ["survey", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/o", "--set", "bogus=1"],
        ["bogus"],
        good=PAIR,
        covers=["--set"],
    )


# ------------------------------------------------------------------- 4x4 transform files
def _transforms(c: Corpus) -> None:
    for label, name, text in (
        ("not-orthonormal", "init.txt", "1 0.2 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("scaled", "init.txt", "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n"),
        ("reflection", "init.txt", "-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("three-by-three", "init.txt", "1 0 0\n0 1 0\n0 0 1\n"),
        ("five-rows", "init.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n0 0 0 1\n"),
        ("nan", "init.txt", "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("bad-last-row", "init.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n1 0 0 1\n"),
        ("empty", "init.txt", ""),
        ("json-4x3", "init.json", json.dumps({"T_target_source": [[1, 0, 0]] * 4})),
        ("json-not-json", "init.json", "{T_target_source: identity"),
        ("json-no-entry", "init.json", json.dumps({"T": np.eye(4).tolist()})),
    ):
        c.case(
            f"init-{label}",
            "broken",
            [*REG, "--init", "{d}/" + name],
            [name],
            good=PAIR,
            files={name: text},
            covers=["4x4 transform (--init)"],
        )
    c.case(
        "init-missing-file",
        "broken",
        [*REG, "--init", "{d}/none.txt"],
        ["none.txt"],
        good=PAIR,
        covers=["4x4 transform (--init)"],
    )
    c.case(
        "init-stored-without-pose",
        "broken",
        [*REG, "--init", "stored", "--icp-only"],
        ["stored", "room.ptx", "room2.ptx"],
        good=PAIR,
        covers=["4x4 transform (--init)"],
    )
    for label, name, text in (
        ("nan", "truth.txt", "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
        ("empty", "truth.txt", ""),
        ("npy-garbage", "truth.npy", "not numpy"),
        ("pair-missing", "gt.json", json.dumps({"pairs": [{"target": "a", "source": "b"}]})),
        (
            "pair-entry-not-object",
            "gt.json",
            json.dumps({"pairs": [["room", "room2"]]}),
        ),
    ):
        c.case(
            f"truth-{label}",
            "broken",
            [*REG, "--truth", "{d}/" + name],
            [name],
            good=PAIR,
            files={name: text},
            covers=["4x4 transform (--truth)"],
        )
    cmp = ["compare", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/cmp"]
    c.case(
        "compare-gt-not-rigid",
        "broken",
        [*cmp, "--gt", "{d}/gt.txt"],
        ["gt.txt"],
        good=PAIR,
        files={"gt.txt": "1 0.5 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"},
        covers=["4x4 transform (--truth)"],
    )
    eye = np.eye(4).tolist()
    for label, pairs in (
        ("pairs-are-lists", [["room", "room2", eye]]),
        ("pairs-not-a-list", {"room": eye}),
    ):
        c.case(
            f"compare-gt-{label}",
            "broken",
            [*cmp, "--gt", "{d}/gt.json"],
            ["gt.json"],
            good=PAIR,
            files={"gt.json": json.dumps({"pairs": pairs})},
            covers=["4x4 transform (--truth)"],
        )


# ------------------------------------------------------------------------------ outputs
def _outputs(c: Corpus) -> None:
    c.case(
        "register-out-folder-is-a-file",
        "broken",
        ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/notes.txt/T.json"],
        ["notes.txt"],
        good=PAIR,
        files={"notes.txt": "a file where a folder is needed\n"},
        covers=["output path"],
    )
    c.case(
        "register-out-is-a-folder",
        "broken",
        ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/res.json"],
        ["res.json"],
        good=PAIR,
        setup=lambda d: (d / "res.json").mkdir(),
        covers=["output path"],
    )
    c.case(
        "register-out-is-source",
        "overwrite",
        ["register", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/room2.ptx"],
        ["room2.ptx"],
        good=PAIR,
        covers=["output path"],
    )
    c.case(
        "compare-out-is-input",
        "overwrite",
        ["compare", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/room.ptx"],
        ["room.ptx"],
        good=PAIR,
        covers=["output path"],
    )
    c.case(
        "evaluate-plot-is-est",
        "overwrite",
        ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/est.txt", "--plot", "{d}/est.txt"],
        ["est.txt"],
        good=("gt.txt", "est.txt"),
        covers=["output path"],
    )
    c.case(
        "calibrate-out-is-image",
        "overwrite",
        [
            "calibrate",
            "--image",
            "{d}/camera.png",
            "--scan",
            "{d}/room.ptx",
            "--pinhole",
            "100",
            "100",
            "80",
            "60",
            "--pairs",
            "{d}/pairs.csv",
            "--overlay",
            "{d}/camera.png",
            "--out",
            "{d}/calib.json",
        ],
        ["camera.png"],
        good=("room.ptx",),
        files={"camera.png": _camera_png(), "pairs.csv": GOOD_PAIRS},
        covers=["output path"],
    )
    c.case(
        "project-sidecar-is-a-folder",
        "partial",
        ["project", "{d}/room.ptx", "--out", "{d}/r.png"],
        ["r.camera.json"],
        good=("room.ptx",),
        setup=lambda d: (d / "r.camera.json").mkdir(),
        covers=["output path"],
    )
    c.case(
        "project-sidecar-is-a-folder-overwrite",
        "partial",
        ["project", "{d}/room.ptx", "--out", "{d}/r.png", "--overwrite"],
        ["r.camera.json"],
        good=("room.ptx",),
        setup=lambda d: (d / "r.camera.json").mkdir(),
        covers=["output path"],
    )
    c.case(
        "convert-keep-float-npz-is-a-folder",
        "partial",
        [
            "convert",
            "{d}/room.ptx",
            "--kind",
            "flexion",
            "--keep-float",
            "--out",
            "{d}/f.png",
            "--overwrite",
        ],
        ["f.npz"],
        good=("room.ptx",),
        setup=lambda d: (d / "f.npz").mkdir(),
        covers=["output path"],
    )
    c.case(
        "odometry-out-is-groundtruth",
        "overwrite",
        ["odometry", "{d}/seq", "--out", "{d}/seq/groundtruth.txt"],
        ["groundtruth.txt"],
        setup=_tum_sequence,
        covers=["output path"],
    )


def _tum_sequence(d) -> None:
    """A tiny TUM RGB-D layout (2 frames)."""
    import cv2

    seq = d / "seq"
    (seq / "depth").mkdir(parents=True)
    (seq / "rgb").mkdir()
    depth = np.full((48, 64), 5000, np.uint16)
    for i in range(2):
        cv2.imwrite(str(seq / "depth" / f"{i}.png"), depth)
        cv2.imwrite(str(seq / "rgb" / f"{i}.png"), np.zeros((48, 64, 3), np.uint8))
    (seq / "depth.txt").write_text("0.0 depth/0.png\n0.1 depth/1.png\n")
    (seq / "rgb.txt").write_text("0.0 rgb/0.png\n0.1 rgb/1.png\n")
    (seq / "groundtruth.txt").write_text("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n")


# ------------------------------------------------------------------------- every command
def _command_options(c: Corpus) -> None:
    cmp_ = ["compare", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/cmp"]
    ev = ["evaluate", "--gt", "{d}/gt.txt", "--est", "{d}/est.txt"]
    sv = ["survey", "{d}/room.ptx", "{d}/room2.ptx", "--out", "{d}/o"]
    cal = [
        "calibrate", "--image", "{d}/camera.png", "--scan", "{d}/room.ptx",
        "--pinhole", "100", "100", "80", "60", "--pairs", "{d}/pairs.csv", "--out", "{d}/c.json",
    ]  # fmt: skip
    syn = ["synth", "--out", "{d}/s"]
    for id, argv, names, good, files in (
        (
            "compare-success-deg-negative",
            [*cmp_, "--success-deg", "-1"],
            ["--success-deg"],
            PAIR,
            {},
        ),
        ("compare-timeout-zero", [*cmp_, "--timeout-s", "0"], ["--timeout-s"], PAIR, {}),
        ("compare-unknown-method", [*cmp_, "--methods", "flexreg,magic"], ["magic"], PAIR, {}),
        (
            "bench-unknown-suite",
            ["bench", "--suite", "nope", "--out", "{d}/b"],
            ["nope", "--suite"],
            (),
            {},
        ),
        (
            "bench-timeout-negative",
            ["bench", "--timeout-s", "-5", "--out", "{d}/b"],
            ["--timeout-s"],
            (),
            {},
        ),
        (
            "bench-data-missing",
            ["bench", "--suite", "real", "--data", "{d}/none", "--out", "{d}/b"],
            ["none"],
            (),
            {},
        ),
        ("evaluate-delta-zero", [*ev, "--delta", "0"], ["--delta"], ("gt.txt", "est.txt"), {}),
        (
            "evaluate-max-dt-negative",
            [*ev, "--max-dt-s", "-1"],
            ["--max-dt-s"],
            ("gt.txt", "est.txt"),
            {},
        ),
        (
            "evaluate-unknown-format",
            [*ev, "--format", "csv"],
            ["--format", "csv"],
            ("gt.txt", "est.txt"),
            {},
        ),
        (
            "odometry-missing-sequence",
            ["odometry", "{d}/none", "--out", "{d}/t.txt"],
            ["none"],
            (),
            {},
        ),
        ("survey-workers-zero", [*sv, "--workers", "0"], ["--workers"], PAIR, {}),
        ("survey-unknown-reference", [*sv, "--reference", "nosuch"], ["nosuch"], PAIR, {}),
        ("survey-voxel-negative", [*sv, "--voxel", "-1"], ["--voxel"], PAIR, {}),
        (
            "calibrate-threshold-negative",
            [*cal, "--threshold-px", "-1"],
            ["--threshold-px"],
            ("room.ptx",),
            {"camera.png": _camera_png(), "pairs.csv": GOOD_PAIRS},
        ),
        (
            "calibrate-kitti-camera-7",
            [*cal, "--kitti-camera", "7"],
            ["--kitti-camera"],
            ("room.ptx",),
            {"camera.png": _camera_png(), "pairs.csv": GOOD_PAIRS},
        ),
        (
            "calibrate-image-not-an-image",
            [*cal],
            ["camera.png"],
            ("room.ptx",),
            {"camera.png": b"not a png", "pairs.csv": GOOD_PAIRS},
        ),
        (
            "info-depth-scale-negative",
            ["info", "{d}/depth.png", "--depth-scale", "-1"],
            ["--depth-scale"],
            ("depth.png", "depth.camera.json"),
            {},
        ),
        (
            "project-png-scale-zero",
            ["project", "{d}/room.npz", "--png-scale", "0", "--out", "{d}/r.png"],
            ["--png-scale"],
            ("room.npz",),
            {},
        ),
        (
            "project-index-9",
            ["project", "{d}/room.ptx", "--index", "9", "--out", "{d}/r.png"],
            ["room.ptx", "--index"],
            ("room.ptx",),
            {},
        ),
        ("synth-stations-zero", [*syn, "--stations", "0"], ["--stations"], (), {}),
        ("synth-noise-negative", [*syn, "--noise-mm", "-1"], ["--noise-mm"], (), {}),
        ("synth-unknown-scene", [*syn, "--scene", "moon"], ["moon", "--scene"], (), {}),
        ("synth-resolution-words", [*syn, "--resolution", "bigxsmall"], ["--resolution"], (), {}),
        (
            "convert-bits-12",
            ["convert", "{d}/depth.png", "--kind", "flexion", "--bits", "12", "--out", "{d}/f.png"],
            ["--bits"],
            ("depth.png", "depth.camera.json"),
            {},
        ),
        (
            "convert-unknown-kind",
            ["convert", "{d}/depth.png", "--kind", "sparkle", "--out", "{d}/f.png"],
            ["sparkle", "kind"],
            ("depth.png", "depth.camera.json"),
            {},
        ),
        ("register-n-even", [*REG, "--n", "4"], ["--n"], PAIR, {}),
        (
            "register-unknown-features",
            [*REG, "--features", "magic"],
            ["magic", "--features"],
            PAIR,
            {},
        ),
        ("register-threshold-negative", [*REG, "--threshold", "-0.1"], ["--threshold"], PAIR, {}),
    ):
        c.case(id, "option", argv, names, good=good, files=files, covers=["option"])
