"""`flexreg register`: a real scan against a displaced second station recovers the known
transform; JSON, text, match image and merged cloud agree with it; failures print one line,
exit 1 and write nothing."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import REPO, one_error_line, run_cli

import flexreg.registration.pipeline
from flexreg import Scan, __version__, read_scan, write_scan
from flexreg.cli import run
from flexreg.cli.register import SOURCE_RGB, TARGET_RGB
from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import to_scan
from flexreg.core.results import Hypothesis, Reason, Verdict
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.registration.config import DEFAULT_CHECKS
from flexreg.stages.projection import project

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"

#: every check of the judge, the optional Open3D figures included
ALL_CHECKS = "judge.checks=" + json.dumps([*DEFAULT_CHECKS, "open3d"])


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The real laser scan (npz) and a second station 0.67 m away, turned 75° (PTX). Both files
    carry an unrelated stored pose, which registration must ignore (scanner frames)."""
    folder = tmp_path_factory.mktemp("pair")
    target = read_scan(LASERSCAN)
    T_source_target = make_transform(
        rotation_about_axis([0.05, 0.02, 1.0], np.radians(75.0)), [0.6, -0.3, 0.05]
    )
    cam = SphericalCamera.from_reference(1799, 397, 0.80, 2.34)
    source = to_scan(project(Scan(points=apply(T_source_target, target.points)), cam))
    target.T_world_scanner = make_transform(rotation_about_axis([0, 0, 1], 0.4), [5, -2, 1])
    source.T_world_scanner = make_transform(rotation_about_axis([1, 0, 0], 1.0), [10, 20, 3])
    write_scan(folder / "target.npz", target)
    write_scan(folder / "source.ptx", source)
    return folder / "target.npz", folder / "source.ptx", invert(T_source_target)


@pytest.fixture(scope="module")
def registered(pair, tmp_path_factory):
    """One successful run with every output (into a folder that does not exist yet)."""
    target, source, _ = pair
    out = tmp_path_factory.mktemp("registered") / "new" / "folder"
    argv = [
        "register",
        str(target),
        str(source),
        "--out",
        str(out / "T.json"),
        "--txt",
        str(out / "T.txt"),
        "--matches",
        str(out / "matches.png"),
        "--merged",
        str(out / "merged.ply"),
        "--voxel",
        "0.08",
        "--truth",
        str(target.parent / "truth.txt"),
        "--set",
        ALL_CHECKS,
    ]
    np.savetxt(target.parent / "truth.txt", pair[2])
    results = []
    real_register = flexreg.registration.pipeline.register

    def spy(*args, **kwargs):
        results.append(real_register(*args, **kwargs))
        return results[-1]

    stdout, stderr = io.StringIO(), io.StringIO()
    with (
        pytest.MonkeyPatch.context() as mp,
        contextlib.redirect_stdout(stdout),
        contextlib.redirect_stderr(stderr),
    ):
        mp.setattr(flexreg.registration.pipeline, "register", spy)
        rc = run(argv)
    assert rc == 0, stderr.getvalue()
    (result,) = results
    return {
        "out": out,
        "stdout": stdout.getvalue(),
        "stderr": stderr.getvalue(),
        "result": result,
        "result_files": (target, source),
    }


# ------------------------------------------------------------------------ a successful run


def test_json_holds_the_true_transform_and_the_run(registered, pair):
    target, source, gt = pair
    doc = json.loads((registered["out"] / "T.json").read_text())
    T = np.array(doc["T_target_source"])
    assert rotation_error_deg(T, gt) < 0.05
    assert translation_error_m(T, gt) < 0.01
    result = registered["result"]
    np.testing.assert_array_equal(T, result.T_target_source)
    assert doc["target"] == str(target) and doc["source"] == str(source)
    assert doc["flexreg_version"] == __version__
    assert doc["inliers"] == result.inliers >= 50 and doc["matches"] >= doc["inliers"]
    assert 0 < doc["inlier_rmse_m"] < 0.05
    assert "voxel" in doc["stage_fitness_denominator"] and 0.5 < doc["stage_fitness"] <= 1.0
    ov = doc["overlap"]
    assert 0.5 < ov["share"] <= 1.0 and ov["source_points"] > 1000
    assert ov["distance_m"] == ov["voxel_m"] > 0 and "source points within" in ov["definition"]
    # Open3D's own figures on the same clouds, under its names, agree with ours
    assert doc["open3d_fitness"] == ov["open3d_fitness"] == pytest.approx(ov["share"], abs=2e-3)
    assert doc["open3d_inlier_rmse_m"] == pytest.approx(ov["rmse_m"], rel=0.02)
    assert doc["inliers_of"].startswith("matched keypoint pairs")
    assert {"features", "estimation", "refinement"} <= set(doc["timings_s"])
    assert doc["config"]["voxel_m"] == 0.08 and doc["config"]["features"] == "sift"
    assert doc["config"]["image"] == "flexion" and doc["config"]["n"] == 5
    assert doc["seed"] == 0 and doc["config"]["refine"] is True
    assert set(result.to_dict()) <= set(doc)


def test_reading_straight_into_working_images_gives_the_same_result(registered, pair, tmp_path):
    """Without --matches the PTX source is read straight into its points and working image
    (no grid index or intensity kept): the same transform and overlap as the full read."""
    target, source, _ = pair
    calls = []
    real_register = flexreg.registration.pipeline.register

    def spy(*args, **kwargs):
        calls.append((args, kwargs))
        return real_register(*args, **kwargs)

    argv = ["register", str(target), str(source), "--out", str(tmp_path / "T.json")]
    argv += [
        "--voxel",
        "0.08",
        "--set",
        ALL_CHECKS,
    ]
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(io.StringIO()):
        mp.setattr(flexreg.registration.pipeline, "register", spy)
        assert run(argv) == 0
    ((args, kwargs),) = calls
    assert args[1].grid_index is None and args[1].intensity is None  # the PTX, read lean
    assert kwargs["images"][0] is None and kwargs["images"][1] is not None
    lean = json.loads((tmp_path / "T.json").read_text())
    full = json.loads((registered["out"] / "T.json").read_text())
    assert lean["T_target_source"] == full["T_target_source"]
    o3d = ("open3d_fitness", "open3d_inlier_rmse_m")  # Open3D's own sums: last bits vary
    for key, value in full["overlap"].items():
        if key in o3d:
            assert lean["overlap"][key] == pytest.approx(value, rel=1e-9)
        else:
            assert lean["overlap"][key] == value, key


def test_truth_errors_reported_and_stored(registered):
    doc = json.loads((registered["out"] / "T.json").read_text())
    err = doc["error_vs_truth"]
    assert err["truth"].endswith("truth.txt")
    assert err["rotation_deg"] < 0.05 and err["translation_m"] < 0.01
    assert err["coarse_rotation_deg"] < 0.5 and err["coarse_translation_m"] < 0.05
    assert "error vs truth" in registered["stdout"]


def test_truth_from_a_synth_ground_truth_file(tmp_path):
    from flexreg.cli.register import read_truth

    T = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 0.1])
    doc = {
        "pairs": [{"target": "station_00", "source": "station_01", "T_target_source": T.tolist()}]
    }
    gt = tmp_path / "gt.json"
    gt.write_text(json.dumps(doc))
    a, b = Path("x/station_00.ptx"), Path("y/station_01.e57")
    np.testing.assert_allclose(read_truth(gt, a, b), T)
    np.testing.assert_allclose(read_truth(gt, b, a), invert(T), atol=1e-12)
    from flexreg.errors import InputError

    with pytest.raises(InputError, match="no pair station_00 / station_02"):
        read_truth(gt, a, Path("station_02.ptx"))


def test_txt_is_the_same_matrix(registered):
    T_json = np.array(json.loads((registered["out"] / "T.json").read_text())["T_target_source"])
    T_txt = np.loadtxt(registered["out"] / "T.txt")
    assert T_txt.shape == (4, 4)
    np.testing.assert_array_equal(T_txt, T_json)


def test_match_image_stacks_both_feature_images(registered, pair):
    png = cv2.imread(str(registered["out"] / "matches.png"), cv2.IMREAD_UNCHANGED)
    # target 397 rows (the laser scan), source 397 rows (the simulated station), 1799 wide,
    # at one pixel per image pixel below a title band (the labels: tests/test_honest_numbers.py)
    assert png.dtype == np.uint8 and png.shape[1] == 1799
    assert 397 + 397 < png.shape[0] < 397 + 397 + 150
    body = png[-(397 + 397) :]
    colourful = (body.max(axis=2).astype(int) - body.min(axis=2)) > 60
    assert colourful[:397].any() and colourful[397:].any(), "lines reach both images"


def test_merged_cloud_has_both_scans_in_two_colours(registered, pair):
    target, source, _ = pair
    n_t, n_s = len(read_scan(target)), len(read_scan(source))
    merged = read_scan(registered["out"] / "merged.ply")
    assert len(merged) == n_t + n_s and merged.colors is not None
    np.testing.assert_array_equal(merged.colors[:n_t], np.tile(TARGET_RGB, (n_t, 1)))
    np.testing.assert_array_equal(merged.colors[n_t:], np.tile(SOURCE_RGB, (n_s, 1)))
    # target points are in their own scanner frame (its stored pose ignored), unmoved
    np.testing.assert_allclose(merged.points[:n_t], read_scan(target).points, atol=1e-9)


def test_summary_and_stage_progress(registered):
    out, err = registered["stdout"], registered["stderr"]
    for word in ("matches", "inliers", "inlier RMSE", "mm", "fitness", "voxel", "coarse", "°"):
        assert word in out, word
    target, source = registered["result_files"]
    flat = " ".join(out.split())
    assert f"target = {target}, source = {source}" in flat
    # the headline is the overlap with its denominator; inliers say what they are of
    assert "overlap" in flat and "% of" in flat and "source points within" in flat
    assert "matched keypoint pairs are inliers" in flat and "inlier_rmse" in flat
    assert "T.json" in out and "merged.ply" in out
    assert "Reading target.npz and source.ptx" in err  # both at once
    for name in registered["result"].timings_s:  # a spinner and a done line per stage
        assert f"{name[:1].upper()}{name[1:]} (" in err, name


def test_a_normal_pair_is_confident_exit_0(registered):
    """The fixture's run exited 0 (asserted there); its verdict, once the pipeline gives one,
    is confident and stored in T.json."""
    doc = json.loads((registered["out"] / "T.json").read_text())
    assert "verdict" in doc
    verdict = registered["result"].verdict
    if verdict is None:  # no verdict from the pipeline: nothing said, exit 0
        assert doc["verdict"] is None and "verdict:" not in registered["stdout"]
    else:
        assert verdict.confident and doc["verdict"]["status"] == "confident"
        assert "verdict: confident" in registered["stdout"]
        assert "uncertain" not in registered["stderr"]


# ------------------------------------------------------------------------ exit codes 0 / 3

#: the result a repeating structure might give: a runner-up 3.4 m along x that fits as well
_RUNNER = make_transform(np.eye(3), [3.4, 0.02, 0.0])
_UNCERTAIN = Verdict(
    "uncertain",
    reasons=(
        Reason(
            "ambiguous",
            "two poses 3.40 m apart along x fit almost equally well: repeating structure",
        ),
        Reason("weak_axis", "translation along x is weakly constrained (corridor)"),
    ),
    evidence={"overlap_target": 0.41, "overlap_source": 0.38, "inliers": 57},
    runner_up=(Hypothesis(_RUNNER, 0.97, 0.4, 3.4, "plan view 2"),),
)


def _with_verdict(registered, verdict):
    """The fixture's result with another verdict (translation zero, so the runner-up's offset
    is its own translation)."""
    T = np.eye(4)
    return dataclasses.replace(registered["result"], verdict=verdict, T_target_source=T)


def _register_with(registered, pair, tmp_path, monkeypatch, verdict, *extra):
    result = _with_verdict(registered, verdict)
    monkeypatch.setattr(flexreg.registration.pipeline, "register", lambda *a, **k: result)
    target, source, _ = pair
    out = tmp_path / "out"
    argv = ["register", target, source, "--out", out / "T.json", "--txt", out / "T.txt", *extra]
    rc, stdout, stderr = run_cli(argv)
    return rc, stdout, stderr, out


def test_uncertain_result_is_written_with_its_verdict_exit_3(
    registered, pair, tmp_path, monkeypatch
):
    rc, stdout, stderr, out = _register_with(registered, pair, tmp_path, monkeypatch, _UNCERTAIN)
    assert rc == 3, stderr
    assert _files(out) == ["T.json", "T.txt"]
    doc = json.loads((out / "T.json").read_text())
    v = doc["verdict"]
    assert v["status"] == "uncertain"
    assert [r["code"] for r in v["reasons"]] == ["ambiguous", "weak_axis"]
    assert "repeating structure" in v["reasons"][0]["message"]
    assert v["evidence"]["overlap_target"] == 0.41
    (runner,) = v["runner_up"]
    np.testing.assert_array_equal(runner["T_target_source"], _RUNNER)
    assert runner["score_ratio"] == 0.97 and runner["translation_m"] == 3.4
    # the summary in words: status, every reason, how far the runner-up is and how good
    assert "verdict: UNCERTAIN" in stdout
    assert "two poses 3.40 m apart along x fit almost equally well" in stdout
    assert "[weak_axis]" in stdout
    assert "runner-up 1: 0.4° and 3.40 m away (mostly along x)" in stdout
    assert "explains 3 % less of the data than the answer (score ratio 0.97)" in stdout
    assert "plan view 2" in stdout
    assert f"wrote {out / 'T.json'}" in stdout
    # the last line says what happened and what to do
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("uncertain (exit status 3): ") and str(out / "T.json") in last
    assert "runner-up transforms" in last and "--merged" in last
    assert "error:" not in stderr


@pytest.mark.parametrize(
    ("ratio", "words"),
    [
        (0.86, "explains 14 % less of the data than the answer (score ratio 0.86)"),
        (1.0, "explains the data as well as the answer (score ratio 1.00)"),
        (1.05, "explains 5 % more of the data than the answer (score ratio 1.05)"),
        (0.0, "explains next to nothing of what the answer explains (score ratio 0.00)"),
        (-0.14, "the data contradict it: it fits far worse than the answer (score ratio -0.14)"),
    ],
)
def test_a_runner_up_reads_sensibly_whatever_its_score_ratio(ratio, words):
    """A runner-up whose score is negative (it contradicts the data more than it explains
    them) once read 'explains the data -14 % as well as the answer'."""
    from flexreg.cli._common import verdict_lines

    verdict = dataclasses.replace(
        _UNCERTAIN, runner_up=(Hypothesis(_RUNNER, ratio, 0.4, 3.4, "plan"),)
    )
    (line,) = [x for x in verdict_lines(verdict) if "runner-up" in x]
    assert line == f"  runner-up 1: 0.4° and 3.40 m away, {words}, from plan"
    assert "-14 %" not in line


def test_confident_result_exit_0(registered, pair, tmp_path, monkeypatch):
    verdict = Verdict("confident", evidence={"overlap_target": 0.8})
    rc, stdout, stderr, out = _register_with(registered, pair, tmp_path, monkeypatch, verdict)
    assert rc == 0, stderr
    assert _files(out) == ["T.json", "T.txt"]
    assert json.loads((out / "T.json").read_text())["verdict"]["status"] == "confident"
    assert "verdict: confident" in stdout and "uncertain" not in stdout + stderr


def test_no_verdict_yet_is_exit_0(registered, pair, tmp_path, monkeypatch):
    rc, stdout, stderr, out = _register_with(registered, pair, tmp_path, monkeypatch, None)
    assert rc == 0, stderr
    assert json.loads((out / "T.json").read_text())["verdict"] is None
    assert "verdict:" not in stdout


def test_exit_codes_in_help():
    for argv in (["register", "--help"], ["--help"]):
        rc, stdout, _ = run_cli(argv)
        assert rc == 0
        text = " ".join(stdout.split())
        assert "0 " in text and "3 written, but uncertain" in text, argv
        assert "1 failed: one error line, nothing written" in text, argv


# ------------------------------------------------------------------------ failures


def test_unrelated_scans_exit_1_and_write_nothing(pair, tmp_path, capsys):
    target, _, _ = pair
    rng = np.random.default_rng(0)
    cam = SphericalCamera.from_reference(600, 200, 0.8, 2.3)
    noise = to_scan(project(Scan(points=rng.normal(0, 5, (60000, 3))), cam))
    write_scan(tmp_path / "noise.npz", noise)
    out = tmp_path / "out"
    argv = [
        "register",
        str(target),
        str(tmp_path / "noise.npz"),
        "--out",
        str(out / "T.json"),
        "--txt",
        str(out / "T.txt"),
        "--matches",
        str(out / "m.png"),
        "--merged",
        str(out / "m.ply"),
    ]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert any(c.isdigit() for c in line)  # the counts that fell short
    assert _files(out) == []


def test_missing_input_names_the_file(pair, tmp_path, capsys):
    target, _, _ = pair
    missing = tmp_path / "nope.ptx"
    assert run(["register", str(target), str(missing), "--out", str(tmp_path / "T.json")]) == 1
    assert one_error_line(capsys.readouterr().err).startswith(f"error: {missing}: ")
    assert _files(tmp_path) == []


@pytest.mark.parametrize(
    ("args", "culprit"),
    [
        (["--image", "flexon"], "--image"),
        (["--features", "surfish"], "--features"),
        (["--n", "4"], "--n"),
        (["--n", "1"], "--n"),
        (["--icp", "p2p"], "--icp"),
        (["--voxel", "0"], "--voxel"),
        (["--voxel", "nan"], "--voxel"),
        (["--threshold", "-0.1"], "--threshold"),
        (["--seed", "-1"], "--seed"),
        (["--upright", "yes"], "--upright"),
        (["--matches", "m.jpg"], "--matches"),
        (["--merged", "m.pcd"], "--merged"),
        (["--txt", "T.json"], "--txt"),
        (["--txt", "a.ptx"], "--txt"),  # would overwrite an input
    ],
)
def test_bad_options_exit_1_before_reading(args, culprit, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    # the inputs do not exist: the option is refused before anything is read
    argv = ["register", "a.ptx", "b.ptx", "--out", "T.json", *args]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"error: {culprit}: "), line
    assert _files(tmp_path) == []


def test_out_must_be_json(tmp_path, capsys):
    assert run(["register", "a.ptx", "b.ptx", "--out", str(tmp_path / "T.txt")]) == 1
    assert one_error_line(capsys.readouterr().err).startswith("error: --out: ")


def test_failed_write_removes_the_outputs_already_written(
    registered, pair, tmp_path, monkeypatch, capsys
):
    """T.json is written last; when it cannot be, the PLY, PNG and text written before it go."""
    target, source, _ = pair
    monkeypatch.setattr(
        flexreg.registration.pipeline, "register", lambda *a, **k: registered["result"]
    )
    (tmp_path / "blocker").write_text("a file where a folder is needed")
    out = tmp_path / "out"
    argv = [
        "register",
        str(target),
        str(source),
        "--out",
        str(tmp_path / "blocker" / "T.json"),
        "--txt",
        str(out / "T.txt"),
        "--matches",
        str(out / "m.png"),
        "--merged",
        str(out / "m.ply"),
    ]
    assert run(argv) == 1
    line = one_error_line(capsys.readouterr().err)
    assert str(tmp_path / "blocker" / "T.json") in line
    assert _files(out) == []


def test_failed_write_leaves_an_earlier_result_byte_identical(
    registered, pair, tmp_path, monkeypatch, capsys
):
    """An earlier run's T.txt and match image survive a run whose T.json cannot be written
    (they used to be replaced, then deleted by the clean-up)."""
    target, source, _ = pair
    monkeypatch.setattr(
        flexreg.registration.pipeline, "register", lambda *a, **k: registered["result"]
    )
    out = tmp_path / "out"
    out.mkdir()
    (out / "T.txt").write_bytes(b"earlier matrix\n")
    (out / "m.png").write_bytes(b"earlier picture")
    (tmp_path / "blocker").write_text("a file where a folder is needed")
    argv = [
        "register", str(target), str(source), "--out", str(tmp_path / "blocker" / "T.json"),
        "--txt", str(out / "T.txt"), "--matches", str(out / "m.png"), "--overwrite",
    ]  # fmt: skip
    assert run(argv) == 1
    assert str(tmp_path / "blocker" / "T.json") in one_error_line(capsys.readouterr().err)
    assert (out / "T.txt").read_bytes() == b"earlier matrix\n"
    assert (out / "m.png").read_bytes() == b"earlier picture"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["T.txt", "blocker", "m.png", "out"]
