"""`flexreg synth`: files, ground truth from the files, byte-identical reruns, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexreg.cli import run
from flexreg.core.transforms import apply, invert
from flexreg.io import read_scan
from flexreg.synth import read_scene

SMALL = ["--resolution", "256x128", "--noise-mm", "3"]


def _files(folder):
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_synth_writes_stations_mesh_and_ground_truth(tmp_path, capsys):
    out = tmp_path / "set"
    args = ["synth", "--scene", "room", "--stations", "3", *SMALL, "--seed", "1", "--out", str(out)]
    assert run(args) == 0
    printed = capsys.readouterr().out
    assert "station_02" in printed and "overlap" in printed
    gt = json.loads((out / "gt.json").read_text())
    assert [s["file"] for s in gt["stations"]] == [
        "station_00.ptx",
        "station_01.ptx",
        "station_02.ptx",
    ]
    assert gt["config"]["seed"] == 1 and gt["sensor"]["width"] == 256
    assert gt["pairs"], "consecutive stations form pairs"
    poses = {s["name"]: np.array(s["T_world_scanner"]) for s in gt["stations"]}
    scene = read_scene(out / "scene.ply")
    assert scene.kind == "room" and scene.seed == 1
    scans = {n: read_scan(out / f"{n}.ptx") for n in poses}
    for name, scan in scans.items():
        np.testing.assert_array_equal(scan.T_world_scanner, np.eye(4))  # truth only in gt.json
        assert scan.grid_shape == (128, 256)
        assert len(scan) == next(s["points"] for s in gt["stations"] if s["name"] == name)
    for pair in gt["pairs"]:
        T = np.array(pair["T_target_source"])
        np.testing.assert_allclose(
            T, invert(poses[pair["target"]]) @ poses[pair["source"]], atol=1e-12
        )
        assert 2.0 <= pair["distance_m"] <= 10.0 and pair["overlap"] >= 0.5
        # the source file's points land on the scene surfaces through the target's pose
        src = scans[pair["source"]].points
        d = scene.distance(apply(poses[pair["target"]] @ T, src))
        assert np.median(d) < 0.003


def test_synth_same_seed_gives_identical_files(tmp_path):
    args = [
        "synth",
        "--scene",
        "courtyard",
        "--stations",
        "2",
        *SMALL,
        "--seed",
        "7",
        "--rgbd-frames",
        "2",
        "--lidar-frames",
        "1",
    ]
    assert run([*args, "--out", str(tmp_path / "a")]) == 0
    assert run([*args, "--out", str(tmp_path / "b")]) == 0
    a, b = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert sorted(a) == sorted(b)
    assert {
        "gt.json",
        "scene.ply",
        "station_00.ptx",
        "rgbd/groundtruth.txt",
        "rgbd/depth/0.000000.png",
        "lidar/lidar_00000.ptx",
    } <= set(a)
    for name in a:
        assert a[name] == b[name], name
    assert run([*args[:-4], "--seed", "8", "--out", str(tmp_path / "c")]) == 0
    c = _files(tmp_path / "c")
    assert c["gt.json"] != a["gt.json"] and c["station_00.ptx"] != a["station_00.ptx"]


def test_synth_npz_round_trips_exactly(tmp_path):
    out = tmp_path / "npz"
    assert (
        run(
            [
                "synth",
                "--scene",
                "hall",
                "--stations",
                "1",
                *SMALL,
                "--format",
                "npz",
                "--embed-poses",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    gt = json.loads((out / "gt.json").read_text())
    scan = read_scan(out / "station_00.npz")
    np.testing.assert_array_equal(
        scan.T_world_scanner, np.array(gt["stations"][0]["T_world_scanner"])
    )
    assert scan.grid_shape == (128, 256) and scan.intensity is not None


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scene", "garden"], "scene must be one of"),
        (["--resolution", "2048"], "--resolution"),
        (["--resolution", "2x1"], "resolution must be"),
        (["--stations", "0"], "stations must be a positive integer"),
        (["--noise-mm", "-1"], "range noise"),
        (["--format", "las"], "format must be one of"),
        (["--distance-m", "5,2"], "distance range"),
        (["--distance-m", "five"], "--distance-m"),
        (["--max-tilt-deg", "45"], "max tilt"),
        (["--min-overlap", "1.5"], "min overlap"),
        (["--distance-m", "60,80"], "could not place station 1"),
    ],
)
def test_synth_bad_input_one_line_error_nothing_written(tmp_path, capsys, extra, message):
    out = tmp_path / "never"
    args = ["synth", "--resolution", "64x32", "--out", str(out), *extra]
    assert run(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and message in err and "\n" not in err
    assert not out.exists()
