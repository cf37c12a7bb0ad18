"""`flexreg calibrate`: the real KITTI and PJLab sets recover their reference extrinsic from
projected correspondences (X,Y,Z or row,col picked on the exported panorama); JSON, overlay and
picking views; the automatic mode; bad input prints one line, exits 1 and writes nothing."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import one_error_line, run_cli

from flexreg import __version__, read_scan
from flexreg.calibration import project_points, scan_range_image
from flexreg.core.transforms import (
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.io.files import MANIFEST
from flexreg.io.intrinsics import read_extrinsic, read_intrinsics, read_kitti_calib


@pytest.fixture(scope="module")
def kitti(shared_data):
    d = shared_data / "camlidar_kitti_object"
    image = d / "image_2_000000.png"
    calib = d / "calib_000000.txt"
    scan = d / "velodyne_000000.bin"
    intr, T = read_kitti_calib(calib)
    intr = intr.for_image(1224, 370)
    points = read_scan(scan).points
    uv, z = project_points(points, intr, T)
    ok = (z > 1) & (uv[:, 0] > 5) & (uv[:, 0] < 1218) & (uv[:, 1] > 5) & (uv[:, 1] < 364)
    return {"image": image, "calib": calib, "scan": scan, "T": T, "intr": intr, "uv": uv, "ok": ok}


def _xyz_csv(path: Path, uv: np.ndarray, xyz: np.ndarray) -> Path:
    rows = ["u,v,X,Y,Z"] + [
        f"{u:.3f},{v:.3f},{x:.5f},{y:.5f},{zz:.5f}"
        for (u, v), (x, y, zz) in zip(uv, xyz, strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")
    return path


def _kitti_pairs(kitti, path: Path, n: int = 100, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    sel = rng.choice(np.flatnonzero(kitti["ok"]), n, replace=False)
    uv = kitti["uv"][sel] + rng.normal(0.0, 1.0, (n, 2))
    return _xyz_csv(path, uv, read_scan(kitti["scan"]).points[sel])


def _base(kitti, out: Path) -> list[str]:
    return [
        "calibrate",
        "--image",
        str(kitti["image"]),
        "--camera",
        str(kitti["calib"]),
        "--scan",
        str(kitti["scan"]),
        "--out",
        str(out / "calib.json"),
    ]


# ------------------------------------------------------------------------ successful runs


def test_kitti_pairs_recover_the_official_extrinsic(kitti, tmp_path):
    pairs = _kitti_pairs(kitti, tmp_path / "pairs.csv")
    out = tmp_path / "new" / "folder"
    argv = [
        *_base(kitti, out),
        "--pairs",
        str(pairs),
        "--overlay",
        str(out / "overlay.png"),
        "--init",
        str(kitti["calib"]),
        "--truth",
        str(kitti["calib"]),
    ]
    rc, stdout, stderr = run_cli(argv)
    assert rc == 0, stderr
    doc = json.loads((out / "calib.json").read_text())
    T = np.array(doc["T_camera_lidar"])
    assert rotation_error_deg(T, kitti["T"]) < 0.2 and translation_error_m(T, kitti["T"]) < 0.02
    np.testing.assert_allclose(np.array(doc["T_lidar_camera"]) @ T, np.eye(4), atol=1e-12)
    assert len(doc["rotation_camera_lidar"]["quaternion_xyzw"]) == 4
    assert doc["inliers"] >= 95 and doc["correspondences"] == 100 and len(doc["pairs"]) == 100
    assert doc["pairs"][0]["line"] == 2 and 0.8 < doc["reprojection_rmse_px"] < 1.8
    assert doc["scan"] == str(kitti["scan"]) and doc["flexreg_version"] == __version__
    assert doc["intrinsics"]["width"] == 1224 and doc["config"]["seed"] == 0
    err = doc["error_vs_truth"]
    assert err["rotation_deg"] < 0.2 and err["translation_m"] < 0.02
    overlay = cv2.imread(str(out / "overlay.png"))
    assert overlay.shape == (370, 1224, 3)
    assert "quaternion xyzw" in stdout and "error vs truth" in stdout
    assert f"wrote {out / 'calib.json'}" in stdout
    # the output is a valid initial guess / truth for the next run
    np.testing.assert_allclose(read_extrinsic(out / "calib.json"), T, atol=1e-9)


def test_rowcol_pairs_read_on_the_exported_panorama(kitti, tmp_path):
    """The picking workflow: export the views, read row,col on the panorama, u,v on the
    camera image (here: the reference projection of the point the panorama shows)."""
    views = tmp_path / "views"
    rc, _, stderr = run_cli(
        [
            "calibrate",
            "--image",
            str(kitti["image"]),
            "--camera",
            str(kitti["calib"]),
            "--scan",
            str(kitti["scan"]),
            "--export-views",
            str(views),
            "--init",
            str(kitti["calib"]),
        ]
    )
    assert rc == 0, stderr
    names = sorted(p.name for p in views.iterdir() if p.name != MANIFEST)
    assert names == ["camera.png", "flexion-view.png", "pairs-template.csv", "panorama.png"]
    assert not (tmp_path / "calib.json").exists()
    template = (views / "pairs-template.csv").read_text()
    assert "u,v,row,col" in template.splitlines()
    pano = cv2.imread(str(views / "panorama.png"))
    scan = read_scan(kitti["scan"])
    ri = scan_range_image(scan)
    assert pano.shape[:2] == ri.shape
    assert cv2.imread(str(views / "camera.png")).shape == (370, 1224, 3)
    # 60 pixels of the panorama whose points the camera sees
    idx = np.where(ri.valid, ri.index, -1)
    cand = np.argwhere((idx >= 0) & kitti["ok"][np.maximum(idx, 0)])
    rng = np.random.default_rng(5)
    pick = cand[rng.choice(len(cand), 60, replace=False)]
    uv = kitti["uv"][idx[pick[:, 0], pick[:, 1]]] + rng.normal(0.0, 1.0, (60, 2))
    lines = ["u,v,row,col"] + [
        f"{u:.2f},{v:.2f},{r},{c}" for (u, v), (r, c) in zip(uv, pick, strict=True)
    ]
    template_path = tmp_path / "picked.csv"
    template_path.write_text(template + "\n".join(lines[1:]) + "\n")
    rc, _, stderr = run_cli([*_base(kitti, tmp_path), "--pairs", str(template_path)])
    assert rc == 0, stderr
    T = np.array(json.loads((tmp_path / "calib.json").read_text())["T_camera_lidar"])
    assert rotation_error_deg(T, kitti["T"]) < 0.2 and translation_error_m(T, kitti["T"]) < 0.02


def test_pinhole_options_equal_the_camera_file(shared_data, tmp_path):
    d = shared_data / "camlidar_pjlab"
    intr = read_intrinsics(d / "scene_a_center_camera-intrinsic.json")
    T = read_extrinsic(d / "scene_a_top_center_lidar-to-center_camera-extrinsic.json")
    points = read_scan(d / "scene_a_calib.pcd").points
    uv, z = project_points(points, intr, T)
    ok = np.flatnonzero((z > 1) & (uv[:, 0] > 5) & (uv[:, 0] < 1914) & (uv[:, 1] > 5))
    ok = ok[uv[ok, 1] < 1194]
    rng = np.random.default_rng(1)
    sel = rng.choice(ok, 80, replace=False)
    pairs = _xyz_csv(tmp_path / "pairs.csv", uv[sel] + rng.normal(0, 1, (80, 2)), points[sel])
    common = ["calibrate", "--image", str(d / "scene_a_calib.png"), "--scan"]
    common += [str(d / "scene_a_calib.pcd"), "--pairs", str(pairs)]
    rc, _, err = run_cli(
        [*common, "--camera", str(d / "scene_a_center_camera-intrinsic.json"), "--out"]
        + [str(tmp_path / "a.json")]
    )
    assert rc == 0, err
    K = intr.K
    rc, _, err = run_cli(
        [*common, "--pinhole", *(str(x) for x in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))]
        + ["--distortion", ",".join(str(x) for x in intr.distortion)]
        + ["--out", str(tmp_path / "b.json")]
    )
    assert rc == 0, err
    a = np.array(json.loads((tmp_path / "a.json").read_text())["T_camera_lidar"])
    b = np.array(json.loads((tmp_path / "b.json").read_text())["T_camera_lidar"])
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert rotation_error_deg(a, T) < 0.2 and translation_error_m(a, T) < 0.02


def test_auto_mode_from_a_perturbed_guess(kitti, tmp_path):
    P = make_transform(
        rotation_about_axis([-0.5, 0.3, 0.8], math.radians(2.0)), [-0.05, 0.07, 0.04]
    )
    T0 = P @ kitti["T"]
    (tmp_path / "init.json").write_text(json.dumps({"T_camera_lidar": T0.tolist()}))
    rc, stdout, stderr = run_cli(
        [*_base(kitti, tmp_path), "--auto", "--init", str(tmp_path / "init.json")]
        + ["--overlay", str(tmp_path / "overlay.png")]
    )
    assert rc == 0, stderr
    doc = json.loads((tmp_path / "calib.json").read_text())
    T = np.array(doc["T_camera_lidar"])
    assert doc["method"] == "auto" and len(doc["auto"]["rounds"]) >= 1
    assert rotation_error_deg(T, kitti["T"]) < 0.75 < rotation_error_deg(T0, kitti["T"])
    assert "edge score" in stdout and (tmp_path / "overlay.png").is_file()


# ------------------------------------------------------------------------ bad input


def _pairs_text(kitti, n: int) -> list[str]:
    rng = np.random.default_rng(3)
    sel = rng.choice(np.flatnonzero(kitti["ok"]), n, replace=False)
    pts = read_scan(kitti["scan"]).points[sel]
    uv = kitti["uv"][sel]
    return [
        f"{u:.2f},{v:.2f},{x:.4f},{y:.4f},{z:.4f}"
        for (u, v), (x, y, z) in zip(uv, pts, strict=True)
    ]


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("five pairs", r"only 5 usable correspondence\(s\); camera-lidar calibration needs"),
        (
            "seven pairs, two slips",
            r"only 5 usable correspondence\(s\) \(2 left out: line 4 \(behind the camera of the "
            r"initial guess .*\), line 6 \(pixel \(1300, 20\) outside the 1224x370 image\)\)",
        ),
        ("malformed", r"line 5: expected 5 values \(u,v,x,y,z\), got 3"),
        ("size", r"image is 1224x370 px but the intrinsics .* are for 1242x375"),
    ],
)
def test_bad_input_one_line_exit_1_nothing_written(kitti, tmp_path, case, message):
    rows = _pairs_text(kitti, 12)
    camera = kitti["calib"]
    extra = ["--init", str(kitti["calib"])]
    if case == "five pairs":
        rows = rows[:5]
    elif case == "seven pairs, two slips":
        rows = rows[:7]
        u, v, x, y, z = rows[2].split(",")
        rows[2] = ",".join([u, v, str(-float(x)), y, z])  # a point behind the lidar's front
        rows[4] = "1300,20," + ",".join(rows[4].split(",")[2:])
    elif case == "malformed":
        rows[3] = "1,2,3"
    elif case == "size":
        intr = read_kitti_calib(kitti["calib"])[0]
        camera = tmp_path / "camera.json"
        camera.write_text(json.dumps({"K": intr.K.tolist(), "width": 1242, "height": 375}))
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("u,v,X,Y,Z\n" + "\n".join(rows) + "\n")
    argv = [
        "calibrate",
        "--image",
        str(kitti["image"]),
        "--camera",
        str(camera),
        "--scan",
        str(kitti["scan"]),
        "--pairs",
        str(pairs),
        "--out",
        str(tmp_path / "out" / "calib.json"),
        "--overlay",
        str(tmp_path / "out" / "overlay.png"),
        *extra,
    ]
    rc, _, err = run_cli(argv)
    assert rc == 1
    line = one_error_line(err)
    assert re.search(message, line), line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--camera", "c.yaml", "--pinhole", "1", "1", "1", "1"],
            "either --camera FILE or --pinhole",
        ),
        (["--camera", "c.yaml", "--auto", "--out", "o.json"], "--auto: needs an initial guess"),
        (
            ["--camera", "c.yaml", "--pairs", "p.csv", "--out", "o.txt"],
            "--out: o.txt: must be a .json",
        ),
        (["--camera", "c.yaml"], "nothing to do"),
        (["--camera", "c.yaml", "--pairs", "p.csv"], "--out: required"),
        (
            ["--camera", "c.yaml", "--distortion", "0,0,0,0", "--pairs", "p.csv"],
            "only with --pinhole",
        ),
        (["--camera", "c.yaml", "--pairs", "p.csv", "--out", "o.json", "--seed", "-1"], "--seed"),
    ],
)
def test_options_are_checked_before_any_input_is_read(tmp_path, options, message):
    """The input paths do not exist: the option error must come first."""
    rc, _, err = run_cli(
        ["calibrate", "--image", str(tmp_path / "none.png"), "--scan", str(tmp_path / "none.bin")]
        + options
    )
    assert rc == 1
    assert message in one_error_line(err)


def test_missing_scan_is_one_line(kitti, tmp_path):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("u,v,X,Y,Z\n" + "\n".join(_pairs_text(kitti, 8)) + "\n")
    argv = _base(kitti, tmp_path)
    argv[argv.index("--scan") + 1] = str(tmp_path / "missing.bin")
    rc, _, err = run_cli([*argv, "--pairs", str(pairs)])
    assert rc == 1 and "missing.bin: no such file" in one_error_line(err)
    assert not (tmp_path / "calib.json").exists()


# ------------------------------------------------------------------------ exit codes 0 / 3 / 1


def test_few_pairs_are_written_but_uncertain_exit_3(kitti, tmp_path):
    """Eight correct pairs: PnP solves them, but too few to check one another -> exit 3,
    the calibration written with its verdict; a well spread set (above) exits 0."""
    pairs = _kitti_pairs(kitti, tmp_path / "pairs.csv", n=8, seed=1)
    out = tmp_path / "out"
    rc, stdout, stderr = run_cli([*_base(kitti, out), "--pairs", str(pairs)])
    assert rc == 3, stderr
    doc = json.loads((out / "calib.json").read_text())
    assert doc["verdict"]["status"] == "uncertain"
    assert "few_inliers" in {r["code"] for r in doc["verdict"]["reasons"]}
    assert doc["verdict"]["evidence"]["inliers"] == doc["inliers"] == 8
    T = np.array(doc["T_camera_lidar"])
    assert rotation_error_deg(T, kitti["T"]) < 1.0
    assert "verdict: UNCERTAIN" in stdout and "[few_inliers]" in stdout
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("uncertain (exit status 3): ") and "calib.json" in last
    assert "--overlay" in last


def test_well_spread_pairs_exit_0_confident(kitti, tmp_path):
    pairs = _kitti_pairs(kitti, tmp_path / "pairs.csv", n=30)
    rc, stdout, stderr = run_cli([*_base(kitti, tmp_path), "--pairs", str(pairs)])
    assert rc == 0, stderr
    assert json.loads((tmp_path / "calib.json").read_text())["verdict"]["status"] == "confident"
    assert "verdict: confident" in stdout


def test_pairs_on_one_line_exit_1_nothing_written(kitti, tmp_path):
    """Seven pairs on one 3D line cannot determine the pose: one error line, exit 1."""
    from flexreg.core.transforms import apply, invert

    pc = np.array([-3.0, 1.2, 8.0]) + np.linspace(0, 1, 7)[:, None] * [6.0, 0.3, 10.0]
    xyz = apply(invert(kitti["T"]), pc)
    uv, _ = project_points(xyz, kitti["intr"], kitti["T"])
    pairs = _xyz_csv(tmp_path / "line.csv", uv, xyz)
    out = tmp_path / "out"
    rc, _, err = run_cli([*_base(kitti, out), "--pairs", str(pairs)])
    assert rc == 1
    assert "lie on one line" in one_error_line(err) and "not determined" in err
    assert not out.exists()


def test_exit_codes_in_help():
    rc, stdout, _ = run_cli(["calibrate", "--help"])
    text = " ".join(stdout.split())
    assert rc == 0 and "3 written, but uncertain" in text and "1 failed" in text


def test_slips_in_a_pairs_file_are_left_out_with_a_warning(kitti, tmp_path):
    """A pixel outside the image and a point behind the camera (of the guess, and of the
    solution without a guess) no longer refuse the file: those rows are left out, named."""
    rows = _pairs_text(kitti, 30)
    u, v, x, y, z = rows[2].split(",")
    rows[2] = ",".join([u, v, str(-float(x)), str(-float(y)), z])  # behind the camera
    rows[4] = "1300,20," + ",".join(rows[4].split(",")[2:])  # right of the 1224-px image
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("u,v,X,Y,Z\n" + "\n".join(rows) + "\n")
    for extra, behind in ((["--init", str(kitti["calib"])], "initial guess"), ([], "solution")):
        out = tmp_path / behind.replace(" ", "-") / "calib.json"
        argv = [*_base(kitti, out.parent), "--pairs", str(pairs), *extra]
        rc, _, err = run_cli(argv)
        assert rc in (0, 3), err
        warning = [line for line in err.splitlines() if line.startswith("warning:")]
        assert len(warning) == 1, err
        assert f"line 4 (behind the camera of the {behind}" in warning[0]
        assert "line 6 (pixel (1300, 20) outside the 1224x370 image)" in warning[0]
        doc = json.loads(out.read_text())
        assert [d["line"] for d in doc["dropped"]] == [4, 6]
        assert doc["correspondences"] == 28 and 4 not in [p["line"] for p in doc["pairs"]]
        T = np.array(doc["T_camera_lidar"])
        assert rotation_error_deg(T, kitti["T"]) < 0.5 and translation_error_m(T, kitti["T"]) < 0.05
