"""`flexreg compare` and `flexreg bench`: a table and files on success; bad input gives one
error line, exit status 1 and no files."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from flexreg import read_scans, write_scan
from flexreg.core.transforms import invert, make_transform
from flexreg.io.files import MANIFEST


@pytest.fixture(scope="module")
def files(shared_data, tmp_path_factory):
    """The bunny pair as two npz scan files with its ground truth as JSON."""
    folder = tmp_path_factory.mktemp("bunny")
    a, b = read_scans(shared_data / "bunny_range_scans_gt" / "derived_bunny_grids_and_gt.npz")
    T = invert(a.T_world_scanner) @ b.T_world_scanner
    write_scan(folder / "bun000.npz", a)
    write_scan(folder / "bun045.npz", b)
    (folder / "gt.json").write_text(json.dumps({"T_target_source": T.tolist()}))
    return folder / "bun000.npz", folder / "bun045.npz", folder / "gt.json", T


def test_compare_prints_a_table_and_writes_three_files(files, tmp_path):
    target, source, gt, T = files
    out = tmp_path / "new" / "report"
    init = tmp_path / "init.txt"
    start = T @ make_transform(np.eye(3), [0.002, -0.001, 0.0])
    np.savetxt(init, start)
    rc, stdout, stderr = run_cli(
        [
            "compare",
            target,
            source,
            "--gt",
            gt,
            "--methods",
            "icp-plane,fpfh-ransac",
            "--init",
            init,
            "--success-deg",
            "1",
            "--success-m",
            "0.005",
            "--out",
            out,
        ]
    )
    assert rc == 0, stderr
    for word in ("icp-plane", "fpfh-ransac", "rot. err °", "peak MB", "Success: final transform"):
        assert word in stdout, word
    assert "wrote" in stdout and "comparison.png" in stdout
    doc = json.loads((out / "comparison.json").read_text())
    rows = {m["method"]: m for m in doc["methods"]}
    assert set(rows) == {"icp-plane", "fpfh-ransac"}
    assert rows["icp-plane"]["success"] is True and rows["fpfh-ransac"]["success"] is True
    np.testing.assert_allclose(doc["initial_guess"], start)
    assert rows["icp-plane"]["details"]["start"] == "initial guess"
    assert rows["fpfh-ransac"]["details"]["start"] == "fpfh-ransac"
    assert doc["target"] == str(target) and doc["points"][0] == 40256
    assert "| icp-plane | ok |" in (out / "comparison.md").read_text()
    # the baselines give no verdict: "n/a" in the table, the Markdown and the JSON
    assert "verdict" in stdout and "n/a" in stdout
    assert rows["icp-plane"]["verdict"] == rows["fpfh-ransac"]["verdict"] == "n/a"
    assert rows["icp-plane"]["details"]["verdict"] is None
    md = (out / "comparison.md").read_text()
    assert "| success | verdict |" in md and "| yes | n/a |" in md
    # the settings it ran with, so that --config comparison.json repeats the run
    assert doc["config"]["methods"] == "icp-plane,fpfh-ransac"
    assert doc["config"]["success_deg"] == 1.0 and doc["config"]["success_m"] == 0.005
    from flexreg.bench.config import CompareConfig
    from flexreg.config import load_config

    assert load_config(CompareConfig, out / "comparison.json").success_m == 0.005


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--methods", "flexreg,icp-fast"], "unknown method 'icp-fast'"),
        (["--voxel", "-0.1"], "--voxel: must be in [0.0001, 10] (got -0.1)"),
        (["--success-deg", "0"], "--success-deg"),
        (["--timeout-s", "nan"], "--timeout-s"),
    ],
)
def test_compare_bad_options(files, tmp_path, extra, message):
    target, source, _, _ = files
    out = tmp_path / "report"
    rc, _, err = run_cli(["compare", target, source, "--out", out, *extra])
    assert rc == 1
    assert message in one_error_line(err)
    assert not out.exists()


def test_compare_non_rigid_ground_truth(files, tmp_path):
    target, source, _, _ = files
    gt = tmp_path / "scaled.json"
    gt.write_text(json.dumps({"T_target_source": np.diag([2.0, 2.0, 2.0, 1.0]).tolist()}))
    out = tmp_path / "report"
    rc, _, err = run_cli(["compare", target, source, "--gt", gt, "--out", out])
    assert rc == 1
    line = one_error_line(err)
    assert str(gt) in line and "not a proper rotation" in line
    assert not out.exists()


def test_compare_pair_without_overlap(files, tmp_path):
    target, _, _, _ = files
    a = read_scans(target)[0]
    far = tmp_path / "far.npz"
    a.points = a.points + [0.0, 0.0, 500.0]  # the same object 500 m away, the truth: identity
    write_scan(far, a)
    gt = tmp_path / "identity.json"
    gt.write_text(json.dumps({"T_target_source": np.eye(4).tolist()}))
    out = tmp_path / "report"
    rc, _, err = run_cli(["compare", target, far, "--gt", gt, "--out", out])
    assert rc == 1
    assert "do not overlap at the ground-truth pose" in one_error_line(err)
    assert not out.exists()


def test_compare_out_is_a_file(files, tmp_path):
    target, source, _, _ = files
    out = tmp_path / "report.txt"
    out.write_text("keep me")
    rc, _, err = run_cli(["compare", target, source, "--out", out])
    assert rc == 1 and "exists and is not a folder" in one_error_line(err)
    assert out.read_text() == "keep me"


def test_bench_quick_real_suite(shared_data, tmp_path):
    out = tmp_path / "bench"
    rc, stdout, stderr = run_cli(
        [
            "bench",
            "--suite",
            "real",
            "--quick",
            "--methods",
            "kiss-icp,icp-plane",
            "--data",
            shared_data,
            "--out",
            out,
        ]
    )
    assert rc == 0, stderr
    (folder,) = [p for p in out.iterdir() if p.name != MANIFEST]
    assert folder.name.startswith("bench-")
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["cases.csv", "config.json", "results.json", "summary.csv", "summary.md"]
    rows = list(csv.DictReader((folder / "cases.csv").open()))
    assert [(r["name"], r["method"]) for r in rows] == [
        ("bunny bun000 <- bun045", "kiss-icp"),
        ("bunny bun000 <- bun045", "icp-plane"),
        ("Ouster frame 0 <- 1", "kiss-icp"),
        ("Ouster frame 0 <- 1", "icp-plane"),
    ]
    assert all(r["status"] in ("ok", "failed") for r in rows)
    by = {(r["name"], r["method"]): r for r in rows}
    # the bunny's scans differ by 34°: local methods from the identity do not get there ...
    assert by[("bunny bun000 <- bun045", "kiss-icp")]["success"] == "False"
    # ... while consecutive lidar frames 25 cm apart are what they are made for
    assert by[("Ouster frame 0 <- 1", "kiss-icp")]["success"] == "True"
    cfg = json.loads((folder / "config.json").read_text())
    assert cfg["suite"] == "real" and cfg["quick"] is True
    assert cfg["methods"] == ["kiss-icp", "icp-plane"]
    md = (folder / "summary.md").read_text()
    assert "### Real pairs" in md and "flexreg bench --suite real --quick" in md
    assert "kiss-icp" in stdout and "wrote" in stdout


def test_bench_quick_synthetic_suite_plots(tmp_path):
    out = tmp_path / "bench"
    rc, _, stderr = run_cli(
        ["bench", "--suite", "synthetic", "--quick", "--methods", "kiss-icp", "--out", out]
    )
    assert rc == 0, stderr
    (folder,) = [p for p in out.iterdir() if p.name != MANIFEST]
    for name in (
        "success_vs_distance.png",
        "success_vs_yaw.png",
        "time_vs_resolution.png",
        "memory_vs_resolution.png",
    ):
        assert (folder / name).stat().st_size > 10_000, name
    rows = list(csv.DictReader((folder / "cases.csv").open()))
    synthetic = [r for r in rows if r["suite"] == "synthetic"]
    sweep = [r for r in rows if r["suite"] == "resolution"]
    assert len(synthetic) == 4 and len(sweep) == 2
    # one pair per distance bin (1-4, 4-8, 8-12, 12-15 m) and per yaw bin (45° each)
    distances = sorted(float(r["distance_m"]) for r in synthetic)
    assert [int(d >= 4) + int(d >= 8) + int(d >= 12) for d in distances] == [0, 1, 2, 3]
    assert sorted(int(float(r["yaw_deg"]) // 45) for r in synthetic) == [0, 1, 2, 3]
    assert [(r["width"], r["height"]) for r in sweep] == [("256", "128"), ("384", "192")]
    assert {(r["width"], r["height"]) for r in synthetic} == {("384", "192")}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suite", "everything"], "--suite: must be one of synthetic, real, all"),
        (["--suite", "real", "--data", "no/such/folder"], "real data folder not found"),
        (["--methods", "flexreg,ndt"], "unknown method 'ndt'"),
    ],
)
def test_bench_bad_options(tmp_path, argv, message):
    out = tmp_path / "bench"
    rc, _, err = run_cli(["bench", *argv, "--out", out])
    assert rc == 1
    assert message in one_error_line(err)
    assert not out.exists()


def test_bench_pair_that_cannot_be_loaded_is_a_row(shared_data, tmp_path, monkeypatch):
    import flexreg.bench.suite as bs

    def broken(*_args, **_kwargs):
        raise bs.InputError(Path("scan.ply"), "truncated file")

    monkeypatch.setattr(bs, "real_case", broken)
    out = tmp_path / "bench"
    rc, _, err = run_cli(
        ["bench", "--suite", "real", "--quick", "--methods", "kiss-icp", "--data", shared_data]
        + ["--out", out]
    )
    assert rc == 0, err
    (folder,) = [p for p in out.iterdir() if p.name != MANIFEST]
    rows = list(csv.DictReader((folder / "cases.csv").open()))
    assert len(rows) == 2
    assert all(r["status"] == "error" for r in rows)
    assert all(r["message"] == "pair not loaded: scan.ply: truncated file" for r in rows)
    assert all(r["success"] == "False" for r in rows)


def test_bench_writes_nothing_when_writing_fails(shared_data, tmp_path, monkeypatch):
    import flexreg.bench.results as bs

    def full_disk(*_args, **_kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(bs, "to_csv", full_disk)
    out = tmp_path / "bench"
    rc, _, err = run_cli(
        ["bench", "--suite", "real", "--quick", "--methods", "kiss-icp", "--data", shared_data]
        + ["--out", out]
    )
    assert rc == 1 and "No space left on device" in one_error_line(err)
    assert not out.exists()


# ------------------------------------------------------------------------ the verdict column


def _measured_with(verdict):
    """A measured call whose result carries ``verdict`` (flexreg's) or none (a baseline's)."""
    from flexreg.bench.measure import Measured
    from flexreg.core.results import PairResult
    from flexreg.registration.config import RegistrationConfig

    result = PairResult(
        T_target_source=np.eye(4),
        T_coarse=np.eye(4),
        matches=120,
        inliers=40,
        inlier_rmse_m=0.01,
        fitness=0.5,
        fitness_denominator="source points",
        information=np.eye(6),
        timings_s={"total": 1.0},
        threshold_m=0.05,
        config=RegistrationConfig(),
        correspondences=np.zeros((0, 2, 3)),
        inlier_mask=np.zeros(0, dtype=bool),
        keypoints=(np.zeros((0, 2)), np.zeros((0, 2))),
        verdict=verdict,
    )
    return Measured("ok", result, None, 1.0, 10.0)


def test_verdict_column_per_method():
    """flexreg's rows show its verdict (reasons in the JSON details), a baseline's "n/a", a
    failed method's none; the console, Markdown and JSON take the same cells."""
    from flexreg.bench.compare import Comparison, SuccessCriteria, make_row
    from flexreg.bench.tables import COLUMNS, table_rows, to_markdown
    from flexreg.core.results import Reason, Verdict

    uncertain = Verdict("uncertain", (Reason("low_overlap", "the scans overlap by 8 %"),))
    criteria = SuccessCriteria()
    T_gt = np.eye(4)
    runs = [
        make_row("flexreg", _measured_with(uncertain), T_gt=T_gt, criteria=criteria, fit=None),
        make_row("icp-plane", _measured_with(None), T_gt=T_gt, criteria=criteria, fit=None),
    ]
    from flexreg.bench.measure import Measured

    failed = Measured("failed", None, "too few inliers", 1.0, None)
    runs.append(make_row("gicp", failed, T_gt=T_gt, criteria=criteria, fit=None))
    assert [r.verdict for r in runs] == ["uncertain", "n/a", None]
    assert runs[0].details["verdict"]["reasons"][0]["code"] == "low_overlap"
    assert runs[0].to_dict()["verdict"] == "uncertain"
    confident = make_row(
        "flexreg", _measured_with(Verdict("confident")), T_gt=T_gt, criteria=criteria, fit=None
    )
    assert confident.verdict == "confident"

    cmp = Comparison(
        target="a",
        source="b",
        runs=runs,
        criteria=criteria,
        T_gt=T_gt,
        T_init=None,
        scale_m=0.05,
        scale_source="given",
        fit_denominator="source points",
        peak_memory="ru_maxrss",
        isolation="one process",
        points=(10, 10),
        seed=0,
    )
    assert [row["verdict"] for row in table_rows(cmp)] == ["uncertain", "n/a", "–"]
    assert "verdict" in COLUMNS
    md = to_markdown(cmp).splitlines()
    assert len(md[1].split("|")) == len(md[0].split("|")) == len(COLUMNS) + 2
    assert "| yes | uncertain |" in md[2] and "| yes | n/a |" in md[3]
    assert any("Verdict:" in line and "n/a" in line for line in md)
