"""`flexreg odometry`: a rendered RGB-D sequence is tracked and written as a TUM trajectory
with a JSON report; a blank frame is reported and bridged; bad options and bad sequences print
one error line, exit 1 and write nothing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import one_error_line, room_walk, run_cli

from flexreg.io.trajectory import read_trajectory
from flexreg.odometry.evaluation import ate


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> Path:
    """6 rendered 320 x 240 RGB-D frames walking through a procedural room (TUM layout)."""
    from flexreg.synth import RGBDConfig, make_scene, write_tum_sequence

    folder = tmp_path_factory.mktemp("seq")
    cfg = RGBDConfig(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)
    write_tum_sequence(folder, make_scene("room", 3), room_walk(6), config=cfg)
    return folder


def _argv(seq: Path, out: Path, *extra: str) -> list[str]:
    return ["odometry", str(seq), "--out", str(out), "--features", "akaze", "--method", "svd",
            *extra]  # fmt: skip


def test_tracks_and_writes_tum_and_json(sequence, tmp_path):
    out, js = tmp_path / "new" / "traj.txt", tmp_path / "new" / "run.json"
    rc, stdout, stderr = run_cli(_argv(sequence, out, "--json", str(js), "--seed", "3"))
    assert rc == 0, stderr
    traj = read_trajectory(out, "tum")
    gt = read_trajectory(sequence / "groundtruth.txt", "tum")
    assert len(traj) == 6
    np.testing.assert_allclose(traj.timestamps, gt.timestamps, atol=1e-6)
    np.testing.assert_allclose(traj.poses[0], np.eye(4), atol=1e-12)  # first camera = world
    assert ate(gt, traj).rmse_m < 0.02
    doc = json.loads(js.read_text())
    assert doc["frames"] == 6 and doc["estimated"] == 5 and doc["bridged"] == 0
    assert doc["run_status"] == "done" and doc["warning"] is None and "warning" not in stderr
    assert doc["config"]["method"] == "svd" and doc["seed"] == 3
    assert doc["sequence"]["kind"] == "tum" and doc["sequence"]["groundtruth"] is True
    assert doc["evaluation"]["ate_rmse_m"] == pytest.approx(ate(gt, traj).rmse_m)
    assert {"rpe_trans_rmse_m", "rpe_trans_mean_m", "rpe_rot_mean_deg"} <= set(doc["evaluation"])
    assert all(a["ok"] and a["inliers"] >= 12 for a in doc["attempts"])
    assert "ATE" in stdout and "5 of 5 motions measured" in stdout and f"wrote {out}" in stdout
    # same seed, same bytes
    out2 = tmp_path / "again.txt"
    assert run_cli(_argv(sequence, out2, "--seed", "3"))[0] == 0
    assert out2.read_bytes() == out.read_bytes()
    # an existing result is refused without --overwrite, replaced with it
    rc, _, stderr = run_cli(_argv(sequence, out2, "--seed", "4"))
    assert rc == 1 and "give --overwrite to replace it" in one_error_line(stderr)
    assert out2.read_bytes() == out.read_bytes()
    assert run_cli(_argv(sequence, out2, "--seed", "3", "--overwrite"))[0] == 0


def test_svd_is_the_default_solver():
    """The most accurate measured setting (docs/odometry.md: 2-2.6x lower ATE)."""
    from flexreg.odometry.config import OdometryConfig

    assert OdometryConfig().method == "svd"


def test_blank_frame_is_reported_and_bridged(sequence, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(sequence, seq)
    lines = [ln for ln in (seq / "depth.txt").read_text().splitlines() if not ln.startswith("#")]
    blank = seq / lines[3].split()[1]
    assert cv2.imwrite(str(blank), np.zeros((240, 320), np.uint16))  # no reading at all
    out, js = tmp_path / "t.txt", tmp_path / "t.json"
    rc, _, stderr = run_cli(_argv(seq, out, "--json", str(js), "--min-inliers", "8"))
    # 1 of 5 frames bridged (more than 10 %): written, with a closing warning and exit 3
    assert rc == 3, stderr
    assert "frame 3: not solved against frame(s) 2" in stderr
    assert "bridged by constant velocity" in stderr
    flat = " ".join(stderr.split())
    assert "warning: 1 of 5 frames bridged: the trajectory is unreliable there" in flat
    doc = json.loads(js.read_text())
    assert doc["run_status"] == "unreliable" and doc["warning"].startswith("1 of 5 frames")
    assert doc["status"][3] == "bridged" and doc["failures"][0]["frame"] == 3
    assert doc["reference"][4] == 2  # the next frame is matched against the last good one
    assert len(read_trajectory(out, "tum")) == 6


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--n", "4"], "error: --n: must be an odd grid size"),
        (["--image", "depth"], "error: --image: unknown feature image 'depth'"),
        (["--method", "pnp"], "error: --method: must be one of essential, svd"),
        (["--ratio", "1.5"], "error: --ratio: must be in (0, 1]"),
        (["--json", "report.txt"], "must be a .json file"),
        (["--intrinsics", "0", "500", "320", "240"], "error: --intrinsics"),
        (["--delta-unit", "hours"], "error: --delta-unit"),
    ],
)
def test_bad_options_write_nothing(sequence, tmp_path, extra, message):
    out = tmp_path / "traj.txt"
    rc, _, err = run_cli(_argv(sequence, out, *extra))
    assert rc == 1 and message in one_error_line(err)
    assert list(tmp_path.iterdir()) == []


def test_bad_sequences_write_nothing(sequence, tmp_path):
    out = tmp_path / "out" / "traj.txt"
    rc, _, err = run_cli(_argv(tmp_path / "nowhere", out))
    assert rc == 1 and "nowhere: no such folder" in one_error_line(err)
    seq = tmp_path / "seq"
    shutil.copytree(sequence, seq)
    lines = [ln for ln in (seq / "depth.txt").read_text().splitlines() if not ln.startswith("#")]
    (seq / lines[2].split()[1]).unlink()
    rc, _, err = run_cli(_argv(seq, out))
    assert rc == 1 and "depth.txt: line 5: " in one_error_line(err)
    shutil.rmtree(seq / "rgb")
    (seq / "rgb.txt").unlink()
    for ln in lines[2:]:
        (seq / ln.split()[1]).unlink(missing_ok=True)
    (seq / "depth.txt").write_text("\n".join(lines[:2]) + "\n")
    rc, _, err = run_cli(_argv(seq, out, "--image", "color"))
    assert rc == 1 and "no colour image" in one_error_line(err)
    assert not (tmp_path / "out").exists()


def test_real_7scenes_frames(shared_data, tmp_path):
    out = tmp_path / "traj.txt"
    argv = ["odometry", str(shared_data / "rgbd_7scenes_redkitchen"), "--out", str(out),
            "--max-frames", "6", "--features", "akaze"]  # fmt: skip
    rc, stdout, stderr = run_cli(argv)
    assert rc == 0, stderr
    assert "7scenes, 6 frames" in stdout and "ATE" in stdout
    assert len(read_trajectory(out, "tum")) == 6
