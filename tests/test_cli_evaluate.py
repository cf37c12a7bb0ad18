"""`flexreg evaluate`: the real TUM and KITTI sequences give the TUM tools' numbers in the table
and the JSON, the figure is written; bad options, malformed files and trajectories that do not
associate print one line, exit 1 and write nothing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line
from matplotlib.image import imread

from flexreg import __version__
from flexreg.cli import run
from flexreg.core.trajectory import Trajectory
from flexreg.io.trajectory import read_trajectory, write_trajectory


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture(scope="module")
def evo(shared_data) -> Path:
    return shared_data / "trajectories_evo"


def test_tum_sequence_table_json_and_plot(evo, tmp_path, capsys):
    gt, est = evo / "freiburg1_xyz-groundtruth.txt", evo / "freiburg1_xyz-rgbdslam.txt"
    out_json, out_png = tmp_path / "fr1.json", tmp_path / "fr1.png"
    argv = ["evaluate", "--gt", str(gt), "--est", str(est), "--delta", "1"]
    argv += ["--delta-unit", "seconds", "--json", str(out_json), "--plot", str(out_png)]
    assert run(argv) == 0
    out = capsys.readouterr().out
    # the TUM tools print ATE rmse 0.013473 m, RPE (1 s) rmse 0.021217 m, mean 0.841472 deg
    assert "ATE [m]" in out and "RPE translation [m]" in out and "RPE rotation [deg]" in out
    assert "0.013473" in out and "0.021217" in out and "0.8415" in out
    assert "786 of 788 estimate poses associated" in out
    assert "753 pose pairs 1 second apart, tools convention" in out
    doc = json.loads(out_json.read_text())
    assert doc["ate_rmse_m"] == pytest.approx(0.013473468, rel=1e-6)
    assert doc["rpe_trans_rmse_m"] == pytest.approx(0.021217444, rel=1e-6)
    assert doc["rpe_trans_mean_m"] == pytest.approx(0.019523664, rel=1e-6)
    assert doc["rpe_rot_mean_deg"] == pytest.approx(0.841472328, rel=1e-6)
    assert doc["ate_n_associated"] == 786 and doc["rpe_n_pairs"] == 753
    assert doc["rpe_delta"] == 1.0 and doc["rpe_delta_unit"] == "seconds"
    assert doc["format"] == "tum" and doc["flexreg_version"] == __version__
    assert doc["gt"] == str(gt) and np.asarray(doc["ate_T_gt_est"]).shape == (4, 4)
    image = imread(out_png)
    assert image.ndim == 3 and image.shape[0] > 400 and image.shape[1] > 800
    assert image[..., :3].std() > 0.05  # something was drawn
    assert _files(tmp_path) == ["fr1.json", "fr1.png"]  # no temporary files left behind


def test_kitti_sequence_with_scale_and_frames(evo, tmp_path, capsys):
    out_json = tmp_path / "kitti.json"
    argv = ["evaluate", "--gt", str(evo / "KITTI_00_gt.txt"), "--est"]
    argv += [str(evo / "KITTI_00_ORB.txt"), "--format", "kitti", "--delta", "10"]
    argv += ["--scale", "--json", str(out_json)]
    assert run(argv) == 0
    out = capsys.readouterr().out
    assert "alignment, similarity, scale 1.00" in out and "10 frames apart" in out
    doc = json.loads(out_json.read_text())
    assert doc["format"] == "kitti" and doc["ate_with_scale"] is True
    assert doc["ate_scale"] == pytest.approx(1.0047, abs=1e-4)
    assert doc["ate_rmse_m"] < 1.303449715  # a free scale can only lower the rigid ATE
    assert doc["rpe_n_pairs"] == 4531 and doc["rpe_scale"] == doc["ate_scale"]
    # rotation errors do not depend on the scale: evaluate_rpe.py's 10-frame numbers
    assert doc["rpe_rot_rmse_deg"] == pytest.approx(0.611535208, rel=0.01)
    assert doc["rpe_rot_mean_deg"] == pytest.approx(0.212058594, rel=0.01)


def test_time_offset_and_paper_convention(evo, tmp_path, capsys):
    gt = read_trajectory(evo / "freiburg1_xyz-groundtruth.txt")
    est = read_trajectory(evo / "freiburg1_xyz-rgbdslam.txt")
    late = write_trajectory(
        tmp_path / "late.txt", Trajectory(est.timestamps + 3.0, est.poses)
    )  # the estimate's clock runs 3 s late
    gt_path = evo / "freiburg1_xyz-groundtruth.txt"
    argv = ["evaluate", "--gt", str(gt_path), "--est", str(late), "--json"]
    assert run([*argv, str(tmp_path / "a.json"), "--offset-s", "-3"]) == 0
    a = json.loads((tmp_path / "a.json").read_text())
    assert a["ate_rmse_m"] == pytest.approx(0.013473468, rel=1e-6)
    assert a["rpe_trans_rmse_m"] == pytest.approx(0.005759956, rel=1e-6)  # 1 frame, tools
    assert (
        run([*argv, str(tmp_path / "b.json"), "--offset-s", "-3", "--rpe-convention", "paper"]) == 0
    )
    b = json.loads((tmp_path / "b.json").read_text())
    assert b["rpe_convention"] == "paper"
    assert b["rpe_trans_rmse_m"] == pytest.approx(0.005756195, rel=1e-6)
    assert b["rpe_rot_mean_deg"] == a["rpe_rot_mean_deg"]
    capsys.readouterr()
    assert len(gt) == 3000


def test_unassociated_timestamps_exit_1_and_write_nothing(evo, tmp_path, capsys):
    est = read_trajectory(evo / "freiburg1_xyz-rgbdslam.txt")
    late = write_trajectory(tmp_path / "late.txt", Trajectory(est.timestamps + 100.0, est.poses))
    argv = ["evaluate", "--gt", str(evo / "freiburg1_xyz-groundtruth.txt"), "--est", str(late)]
    argv += ["--json", str(tmp_path / "out.json"), "--plot", str(tmp_path / "out.png")]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"error: {late}: only 0 of its 788 poses have a ground-truth pose")
    assert "at least 3 are needed" in line and "1305031202.160407 .. " in line
    assert _files(tmp_path) == ["late.txt"]


def test_malformed_line_exit_1_names_file_and_line(evo, tmp_path, capsys):
    bad = tmp_path / "bad.txt"
    lines = (evo / "freiburg1_xyz-rgbdslam.txt").read_text().splitlines()
    lines[5] = lines[5].rsplit(" ", 1)[0]  # drop qw from the 6th line
    bad.write_text("\n".join(lines) + "\n")
    argv = ["evaluate", "--gt", str(evo / "freiburg1_xyz-groundtruth.txt"), "--est", str(bad)]
    assert run([*argv, "--json", str(tmp_path / "out.json")]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line == f"error: {bad}: line 6: expected 8 values (t tx ty tz qx qy qz qw), got 7"
    assert _files(tmp_path) == ["bad.txt"]


def test_formats_must_match(evo, tmp_path, capsys):
    argv = ["evaluate", "--gt", str(evo / "freiburg1_xyz-groundtruth.txt")]
    argv += ["--est", str(evo / "KITTI_00_ORB.txt")]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "KITTI_00_ORB.txt: is a kitti trajectory but --gt" in line and "is tum" in line


@pytest.mark.parametrize(
    ("args", "culprit"),
    [
        (["--delta", "0"], "--delta"),
        (["--delta", "1.5"], "--delta"),  # frames must be whole
        (["--delta-unit", "parsecs"], "--delta-unit"),
        (["--rpe-convention", "evo"], "--rpe-convention"),
        (["--format", "csv"], "--format"),
        (["--max-dt-s", "-0.1"], "--max-dt-s"),
        (["--offset-s", "nan"], "--offset-s"),
        (["--plot", "out.jpg"], "--plot"),
        (["--json", "out.txt"], "--json"),
        (["--json", "gt.json"], "--json"),  # the same file as --gt
    ],
)
def test_bad_options_exit_1_before_reading(args, culprit, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # the inputs do not exist: options are checked first
    argv = ["evaluate", "--gt", "gt.json", "--est", "est.txt", *args]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"error: {culprit}: "), line
    assert _files(tmp_path) == []


def test_missing_input_names_the_file(tmp_path, capsys):
    missing = tmp_path / "nope.txt"
    assert run(["evaluate", "--gt", str(missing), "--est", str(missing)]) == 1
    assert one_error_line(capsys.readouterr().err) == f"error: {missing}: no such file"
