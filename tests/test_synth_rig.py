"""`flexreg synth --rig`: a camera on a TLS station with its exact extrinsic. The files agree
with each other (gt.json's T_camera_lidar puts the station's returns onto the camera image where
the scene is), and `pick`/`calibrate` read the camera.json that synth writes (and the one of
its RGB-D sequences)."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from flexreg.calibration import project_points
from flexreg.cli import run
from flexreg.core.transforms import (
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import InputError
from flexreg.io import read_scan
from flexreg.io.correspondences import write_pairs
from flexreg.io.intrinsics import read_extrinsic, read_intrinsics
from flexreg.synth import read_scene
from flexreg.synth.rig import INIT_ROTATION_DEG, INIT_TRANSLATION_M

#: the station's range noise (synth's default, --noise-mm 3), metres
NOISE_M = 0.003


@functools.lru_cache(maxsize=1)
def _rig_folder(root: str) -> Path:
    out = Path(root) / "rig"
    args = ["synth", "--rig", "--resolution", "512x256", "--seed", "2", "--out", str(out)]
    assert run(args) == 0
    return out


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Path:
    return _rig_folder(str(tmp_path_factory.mktemp("synth-rig")))


def _agreement(folder: Path, T: np.ndarray) -> tuple[float, float]:
    """For the station's returns that ``T`` (T_camera_lidar) puts into the camera image: the
    median distance (metres) along the camera's ray between the return and the scene surface
    the camera sees there, and the correlation of the returns' colours with the image's."""
    gt = json.loads((folder / "gt.json").read_text())
    intr = read_intrinsics(folder / "camera.json")
    image = cv2.imread(str(folder / "camera.png"))
    scan = read_scan(folder / "station_00.ptx")
    scene = read_scene(folder / "scene.ply")
    T_world_camera = np.array(gt["rig"]["T_world_camera"])
    uv, z = project_points(scan.points, intr, T)
    W, H = intr.size
    ok = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
    cam = intr.pinhole()
    rays = np.column_stack(
        [(uv[ok, 0] - cam.cx) / cam.fx, (uv[ok, 1] - cam.cy) / cam.fy, np.ones(ok.sum())]
    )
    n = np.linalg.norm(rays, axis=1)
    hits = scene.cast(
        T_world_camera[:3, 3], ((rays / n[:, None]) @ T_world_camera[:3, :3].T).astype(np.float32)
    )
    depth_gap = float(np.median(np.abs(hits.t / n - z[ok])))
    px = np.rint(uv[ok]).astype(int)
    grey_image = image[px[:, 1], px[:, 0]].astype(np.float64).mean(axis=1)
    grey_lidar = scan.colors[ok].astype(np.float64).mean(axis=1)
    return depth_gap, float(np.corrcoef(grey_image, grey_lidar)[0, 1])


def test_rig_files_agree_with_each_other(rig):
    gt = json.loads((rig / "gt.json").read_text())
    assert gt["config"]["rig"] is True and len(gt["stations"]) == 1  # one station by default
    T = read_extrinsic(rig / "gt.json")  # what calibrate --truth reads
    T_world_scanner = np.array(gt["stations"][0]["T_world_scanner"])
    T_world_camera = np.array(gt["rig"]["T_world_camera"])
    np.testing.assert_allclose(T, invert(T_world_camera) @ T_world_scanner, atol=1e-12)
    np.testing.assert_allclose(np.array(gt["rig"]["T_lidar_camera"]) @ T, np.eye(4), atol=1e-12)
    assert 0.1 < np.linalg.norm(T[:3, 3]) < 0.3  # the camera rides on the scanner
    intr = read_intrinsics(rig / "camera.json")
    image = cv2.imread(str(rig / "camera.png"))
    assert intr.size == (image.shape[1], image.shape[0]) == (640, 480)
    # the rough guess: the truth turned by INIT_ROTATION_DEG about some axis through the
    # camera's centre and moved by INIT_TRANSLATION_M (which the turn of the lever arm adds to)
    T_init = read_extrinsic(rig / "init.json")
    assert rotation_error_deg(T_init, T) == pytest.approx(INIT_ROTATION_DEG, abs=1e-9)
    lever = np.linalg.norm(T[:3, 3])
    assert translation_error_m(T_init, T) <= (
        INIT_TRANSLATION_M + math.radians(INIT_ROTATION_DEG) * lever + 1e-12
    )


def test_rig_extrinsic_puts_the_returns_where_the_image_shows_them(rig):
    """The truth puts each return onto the surface the camera sees at its pixel (the median
    gap is the range noise's, 0.67 sigma, well within 2 sigma) and the returns' colours
    agree with the image there better than under any extrinsic half a degree off (which
    moves them by 2-4 cm at the scene's few metres: a texture cell)."""
    T = read_extrinsic(rig / "gt.json")
    gap, corr = _agreement(rig, T)
    assert gap < 2 * NOISE_M, gap
    for axis in np.eye(3):
        for sign in (-1.0, 1.0):
            off = make_transform(rotation_about_axis(axis, sign * math.radians(0.5)), [0, 0, 0])
            gap_off, corr_off = _agreement(rig, off @ T)
            assert corr > corr_off and gap < gap_off, (axis, sign, corr, corr_off)


def test_rig_is_reproducible_and_the_camera_sees_structure(tmp_path, rig):
    again = tmp_path / "again"
    args = ["synth", "--rig", "--resolution", "512x256", "--seed", "2", "--out", str(again)]
    assert run(args) == 0
    for name in ("camera.png", "camera.json", "init.json", "gt.json", "station_00.ptx"):
        assert (again / name).read_bytes() == (rig / name).read_bytes(), name
    # most of the picture is scene within the station's reach, not sky or a blank wall
    scan = read_scan(rig / "station_00.ptx")
    uv, z = project_points(
        scan.points, read_intrinsics(rig / "camera.json"), read_extrinsic(rig / "gt.json")
    )
    inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 640) & (uv[:, 1] >= 0) & (uv[:, 1] < 480)
    assert inside.sum() > 2000
    assert np.std(np.log(z[inside])) > 0.1  # near and far


def test_camera_json_of_synth_is_read_as_intrinsics(tmp_path, rig):
    """One reader for both forms flexreg writes: synth's {"camera": {"model": "pinhole",
    "fx", ...}} (the rig's and the RGB-D sequence's) and CameraIntrinsics.to_dict()."""
    intr = read_intrinsics(rig / "camera.json")
    cam = json.loads((rig / "camera.json").read_text())["camera"]
    K = [[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]]
    np.testing.assert_array_equal(intr.K, K)
    assert intr.distortion.size == 0 and intr.size == (cam["width"], cam["height"])
    again = tmp_path / "k.json"
    again.write_text(json.dumps(intr.to_dict()))
    np.testing.assert_array_equal(read_intrinsics(again).K, intr.K)
    seq = tmp_path / "seq"
    assert run(["synth", "--resolution", "64x32", "--rgbd-frames", "1", "--out", str(seq)]) == 0
    rgbd = read_intrinsics(seq / "rgbd" / "camera.json")
    assert rgbd.size == (640, 480) and rgbd.fx == 525.0
    bad = tmp_path / "bad.json"
    for doc, says in (
        ({"camera": {"model": "spherical", "width": 8, "height": 4}}, "pinhole camera"),
        ({"camera": {"model": "pinhole", "fx": 1.0, "fy": 1.0}}, "without cx, cy"),
        ({"fx": "a", "fy": 1, "cx": 1, "cy": 1}, "fx must be a number"),
    ):
        bad.write_text(json.dumps(doc))
        with pytest.raises(InputError, match=says):
            read_intrinsics(bad)


def test_calibrate_takes_synth_camera_json_and_the_truth(tmp_path, rig):
    """`calibrate` on the rig's files with exact pairs (returns and their true pixels) lands
    on gt.json's T_camera_lidar and reports the error against it (--truth gt.json)."""
    T = read_extrinsic(rig / "gt.json")
    scan = read_scan(rig / "station_00.ptx")
    uv, z = project_points(scan.points, read_intrinsics(rig / "camera.json"), T)
    inside = (z > 0) & (uv[:, 0] > 5) & (uv[:, 0] < 634) & (uv[:, 1] > 5) & (uv[:, 1] < 474)
    k = np.flatnonzero(inside)[:: max(1, inside.sum() // 40)]
    pairs = tmp_path / "pairs.csv"
    write_pairs(pairs, uv[k], xyz=scan.points[k])
    out = tmp_path / "calib.json"
    args = ["calibrate", "--image", str(rig / "camera.png"), "--camera", str(rig / "camera.json")]
    args += ["--scan", str(rig / "station_00.ptx"), "--pairs", str(pairs), "--out", str(out)]
    assert run([*args, "--truth", str(rig / "gt.json")]) == 0
    err = json.loads(out.read_text())["error_vs_truth"]
    # exact pairs, but written to CSV with finite decimals and solved to the solver's own
    # stopping tolerance: far under the 0.1 deg / 1 cm that counts, not to the last bit
    assert err["rotation_deg"] < 1e-4 and err["translation_m"] < 1e-4
