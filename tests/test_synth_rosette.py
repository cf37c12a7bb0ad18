"""`flexreg synth --lidar-kind rosette`: narrow-field, non-repetitive lidar frames as PCD."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from flexreg.core.transforms import apply
from flexreg.io import read_scan
from flexreg.io.transform_io import read_pair_transform
from flexreg.synth import read_scene
from flexreg.synth.config import RosetteConfig
from flexreg.synth.rosette import MIN_RANGE_M, fov_ellipse, rosette_angles

SMALL = ["--set", "rosette.points=6000", "--set", "rosette.range_noise_m=0.001"]


def test_the_rosette_fills_its_field_of_view_and_never_repeats():
    cfg = RosetteConfig()
    hx, hy = (math.radians(f) / 2 for f in cfg.fov_deg)
    cells: set[tuple[float, float]] = set()
    seen: set[tuple[float, float]] = set()
    coverage = []
    for frame in range(4):
        az, el = rosette_angles(cfg, frame)
        assert len(az) == cfg.points
        e = (az / hx) ** 2 + (el / hy) ** 2
        assert e.max() <= 1 + 1e-12 and e.max() > 0.999 and e.min() < 1e-3  # rim and centre
        shots = set(zip(az.tolist(), el.tolist(), strict=True))
        assert not shots & seen  # the same part of the pattern never comes back
        seen |= shots
        cells |= set(zip(np.floor(np.degrees(az)), np.floor(np.degrees(el)), strict=True))
        coverage.append(len(cells))
    assert coverage[0] < coverage[1] < coverage[3]  # integrating frames covers more
    # directions are unit vectors whose angles are the pattern's (sensor x forward, y left)
    az, el = rosette_angles(cfg, 0)
    d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    np.testing.assert_allclose(fov_ellipse(cfg, 7.0 * d), (az / hx) ** 2 + (el / hy) ** 2)


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    out = tmp_path_factory.mktemp("rosette") / "set"
    args = ["synth", "--scene", "room", "--stations", "0", "--lidar-frames", "3"]
    rc, printed, err = run_cli([*args, "--lidar-kind", "rosette", *SMALL, "--out", out])
    assert rc == 0, err
    assert "rosette frames of 6000 shots" in printed
    return out, json.loads((out / "gt.json").read_text())


def test_frames_are_pcd_in_the_sensor_frame_within_the_field_of_view(frames):
    out, gt = frames
    lidar = gt["lidar"]
    assert lidar["kind"] == "rosette" and lidar["sensor"]["points"] == 6000
    assert sorted(p.name for p in (out / "lidar").iterdir()) == [
        f"lidar_0000{i}.pcd" for i in range(3)
    ]
    scene = read_scene(out / "scene.ply")
    cfg = RosetteConfig(points=6000)
    for f in lidar["frames"]:
        scan = read_scan(out / f["file"])
        np.testing.assert_array_equal(scan.T_world_scanner, np.eye(4))  # the truth: gt.json
        assert scan.grid_shape is None and 1000 < len(scan) == f["points"] <= 6000
        assert fov_ellipse(cfg, scan.points).max() <= 1 + 1e-6
        r = np.linalg.norm(scan.points, axis=1)
        assert r.min() >= MIN_RANGE_M - 0.01
        d = scene.distance(apply(np.array(f["T_world_sensor"]), scan.points))
        assert np.median(d) < 0.0015  # 1 mm range noise


def test_the_truth_maps_each_frame_onto_the_previous_ones_surfaces(frames):
    out, gt = frames
    scene = read_scene(out / "scene.ply")
    poses = {f["name"]: np.array(f["T_world_sensor"]) for f in gt["lidar"]["frames"]}
    assert [(p["target"], p["source"]) for p in gt["pairs"]] == [
        ("lidar_00000", "lidar_00001"),
        ("lidar_00001", "lidar_00002"),
    ]
    for pair in gt["pairs"]:
        T = read_pair_transform(out / "gt.json", pair["target"], pair["source"])
        np.testing.assert_allclose(T, np.linalg.inv(poses[pair["target"]]) @ poses[pair["source"]])
        assert pair["kind"] == "lidar" and 0.5 < pair["overlap"] <= 1
        assert pair["distance_m"] == pytest.approx(1.5 / 10, abs=1e-3)  # 1.5 m/s at 10 Hz
        src = read_scan(out / "lidar" / f"{pair['source']}.pcd", precise=True).points
        on_target = apply(poses[pair["target"]] @ T, src)
        assert np.median(scene.distance(on_target)) < 0.0015


def test_embedded_poses_are_the_pcd_viewpoint(tmp_path):
    args = ["synth", "--scene", "hall", "--stations", "0", "--lidar-frames", "2", *SMALL]
    rc, _, err = run_cli([*args, "--lidar-kind", "rosette", "--embed-poses", "--out", tmp_path])
    assert rc == 0, err
    gt = json.loads((tmp_path / "gt.json").read_text())
    for f in gt["lidar"]["frames"]:
        scan = read_scan(tmp_path / f["file"])
        np.testing.assert_allclose(scan.T_world_scanner, f["T_world_sensor"], atol=1e-12)


def test_the_same_seed_gives_identical_files(tmp_path):
    args = ["synth", "--scene", "courtyard", "--stations", "0", "--lidar-frames", "2"]
    args += ["--lidar-kind", "rosette", *SMALL, "--seed", "4"]
    for name in ("a", "b"):
        assert run_cli([*args, "--out", tmp_path / name])[0] == 0
    a, b = ((tmp_path / n / "lidar" / "lidar_00001.pcd").read_bytes() for n in ("a", "b"))
    assert a == b
    assert (tmp_path / "a" / "gt.json").read_bytes() == (tmp_path / "b" / "gt.json").read_bytes()
    assert run_cli([*args[:-1], "5", "--out", tmp_path / "c"])[0] == 0
    assert (tmp_path / "c" / "lidar" / "lidar_00001.pcd").read_bytes() != a


def test_register_reads_a_pair_of_frames(frames, tmp_path):
    out, _ = frames
    a, b = out / "lidar" / "lidar_00000.pcd", out / "lidar" / "lidar_00001.pcd"
    rc, _, err = run_cli(
        ["register", a, b, "--out", tmp_path / "T.json", "--truth", out / "gt.json"]
    )
    assert rc in (0, 3) or "cannot read" not in err, err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--lidar-kind", "rosette"], "rosette frames need lidar_frames"),
        (["--lidar-frames", "2", "--lidar-kind", "solid"], "--lidar-kind: must be one of"),
        (["--lidar-frames", "2", "--set", "rosette.fov_deg=[200,30]"], "field of view"),
        (["--lidar-frames", "2", "--set", "rosette.points=10"], "rosette.points"),
        (["--lidar-frames", "2", "--set", "rosette.rate_hz=0"], "rosette.rate_hz"),
        (["--stations", "0"], "stations must be a positive integer"),
    ],
)
def test_bad_options_one_line_error_nothing_written(tmp_path, extra, message):
    out = tmp_path / "never"
    rc, _, err = run_cli(["synth", "--resolution", "64x32", "--out", out, *extra])
    assert rc == 1
    line = one_error_line(err)
    assert message in line, line
    assert not out.exists()
