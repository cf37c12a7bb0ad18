"""flexreg.bench (compare, measure, methods, results) and flexreg.io.read_ground_truth:
ground-truth parsing, success and fit on hand-computed cases, measured calls (failures, crashes
and timeouts become rows), a compare run and its files."""

from __future__ import annotations

import json
import os
import time

import cv2
import numpy as np
import pytest

import flexreg.bench.measure as measure
import flexreg.bench.results as results
from flexreg import ConfigError, InputError, RegistrationError, read_scans
from flexreg.bench.compare import SuccessCriteria, compare
from flexreg.bench.measure import measure_call, preload_modules, run_isolated
from flexreg.bench.methods import parse_methods
from flexreg.bench.results import write_comparison
from flexreg.bench.tables import to_markdown
from flexreg.core.transforms import apply, invert, make_transform, rotation_about_axis
from flexreg.io.transform_io import read_ground_truth
from flexreg.stages.overlap import OverlapMeter


@pytest.fixture(scope="module")
def bunny(shared_data):
    a, b = read_scans(shared_data / "bunny_range_scans_gt" / "derived_bunny_grids_and_gt.npz")
    return a, b, invert(a.T_world_scanner) @ b.T_world_scanner


def test_parse_methods():
    assert parse_methods("flexreg, icp-plane,flexreg,,kiss-icp") == (
        "flexreg",
        "icp-plane",
        "kiss-icp",
    )
    with pytest.raises(ConfigError, match="unknown method 'icp'"):
        parse_methods("flexreg,icp")
    with pytest.raises(ConfigError, match="no method"):
        parse_methods(" , ")


def test_read_ground_truth_formats(tmp_path):
    T = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 3.0])
    p = tmp_path / "gt.json"
    p.write_text(json.dumps({"T_target_source": T.tolist(), "method": "survey"}))
    np.testing.assert_allclose(read_ground_truth(p), T)
    txt = tmp_path / "T.txt"
    txt.write_text("\n".join(" ".join(str(x) for x in row) for row in T))
    np.testing.assert_allclose(read_ground_truth(txt), T)
    # a flexreg synth gt.json: the pair by file stems, inverted when listed the other way
    synth = tmp_path / "synth.json"
    synth.write_text(
        json.dumps({"pairs": [{"target": "a", "source": "b", "T_target_source": T.tolist()}]})
    )
    np.testing.assert_allclose(read_ground_truth(synth, target="a", source="b"), T)
    np.testing.assert_allclose(read_ground_truth(synth, target="b", source="a"), invert(T))
    with pytest.raises(InputError, match="no pair c / a"):
        read_ground_truth(synth, target="c", source="a")


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ({"T_target_source": np.diag([1.0, 1.0, 2.0, 1.0]).tolist()}, "not a proper rotation"),
        ({"T_target_source": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}, "not a proper rotation"),
        ({"T_target_source": [[1, 0, 0], [0, 1, 0]]}, "4x4"),
        ({"T_target_source": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]}, "last row"),
        ({"transform": np.eye(4).tolist()}, "no 'T_target_source'"),
    ],
)
def test_read_ground_truth_rejects_non_rigid_matrices(tmp_path, content, problem):
    p = tmp_path / "gt.json"
    p.write_text(json.dumps(content))
    with pytest.raises(InputError, match=problem) as e:
        read_ground_truth(p)
    assert str(p) in str(e.value)


def test_read_ground_truth_missing_or_broken(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_ground_truth(tmp_path / "nope.json")
    p = tmp_path / "broken.json"
    p.write_text("{not json")
    with pytest.raises(InputError, match="invalid JSON"):
        read_ground_truth(p)


def test_success_criteria_limits_are_inclusive():
    c = SuccessCriteria(rotation_deg=0.5, translation_m=0.05)
    assert c.met(0.5, 0.05) and c.met(0.0, 0.0)
    assert not c.met(0.5001, 0.01) and not c.met(0.1, 0.0501)
    assert c.label() == "≤ 0.5° and ≤ 5 cm"
    with pytest.raises(ConfigError, match="rotation_deg"):
        SuccessCriteria(rotation_deg=0.0)
    with pytest.raises(ConfigError, match="translation_m"):
        SuccessCriteria(translation_m=float("nan"))


def test_fit_on_a_hand_computed_case():
    # target: 4 points; source: 4 points of which, at T = identity, two lie 0.1 m and one
    # 0.3 m from a target point and one 5 m away; distance limit 0.25 m
    target = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    source = np.array([[0.1, 0, 0], [1, 0.1, 0], [0, 1.3, 0], [5, 5, 5]])
    # (points farther apart than the voxel: voxelising keeps each as it is)
    fit = OverlapMeter(target, source, voxel_m=0.25)
    ov = fit(np.eye(4))
    assert ov.share == 0.5 and ov.source_points == 4 and ov.distance_m == 0.25
    assert ov.rmse_m == pytest.approx(0.1)
    # moving the source by -0.1 m in x puts the first point exactly on the target
    ov = fit(make_transform(np.eye(3), [-0.1, 0.0, 0.0]))
    assert ov.share == 0.5
    assert ov.rmse_m == pytest.approx(np.sqrt((0.0 + 0.02) / 2))
    # Open3D's figures on the same clouds agree
    assert ov.open3d_fitness == pytest.approx(0.5)
    assert ov.open3d_inlier_rmse_m == pytest.approx(ov.rmse_m)
    assert ov.headline().startswith("50.0 % of 4 source points within 25 cm of a target point")


def _raise_registration_error():
    raise RegistrationError("too few inliers: 2")


def _raise_value_error():
    raise ValueError("boom")


def test_measure_call_statuses_time_and_memory():
    m = measure_call(_raise_registration_error)
    assert (m.status, m.message, m.result) == ("failed", "too few inliers: 2", None)
    m = measure_call(_raise_value_error)
    assert (m.status, m.message) == ("error", "ValueError: boom")

    def allocate():
        a = np.ones(40_000_000)  # 305 MiB, touched
        time.sleep(0.05)
        return float(a.sum())

    m = measure_call(allocate)  # type: ignore[arg-type]
    assert m.status == "ok" and m.result == 40_000_000.0
    assert m.time_s >= 0.05
    if measure.reset_high_water_mark():  # Linux: the kernel's peak resident size
        assert 280 < m.peak_memory_mb < 1000


def test_run_isolated_reports_crashes_and_timeouts():
    crashed = run_isolated(os.abort)
    assert crashed.status == "crashed" and "signal" in crashed.message
    timeout = run_isolated(time.sleep, (30,), timeout_s=1.0)
    assert timeout.status == "timeout" and timeout.time_s == 1.0
    assert timeout.message == "no result within 1 s"


def test_a_method_that_ends_after_its_parent_stopped_listening_exits_quietly():
    """Ctrl-C closes the parent's end of the pipe while a method may be finishing: the
    child's send then meets a broken pipe, which is not an error of the child's (a
    traceback there is printed on the user's console)."""
    ctx = measure._context()
    recv, send = ctx.Pipe(duplex=False)
    recv.close()  # the parent has stopped listening before the result is ready
    proc = ctx.Process(target=measure._child, args=(send, abs, (-2.0,), {}))
    proc.start()
    send.close()
    proc.join(60)
    assert proc.exitcode == 0


def test_compare_gives_every_method_a_row(bunny, tmp_path):
    a, b, T = bunny
    far = make_transform(np.eye(3), [0.5, 0.0, 0.0])
    # the source moved 0.5 m away (the bunny is 15 cm across): ICP from the identity finds no
    # correspondence (a failed row), FPFH + RANSAC is global and still registers it
    source = apply(invert(far), b.points)
    T_gt = T @ far
    cmp = compare(
        a.points,
        source,
        methods="icp-point,fpfh-ransac",
        T_gt=T_gt,
        criteria=SuccessCriteria(rotation_deg=1.0, translation_m=0.005),
        timeout_s=120,
        names=("bun000", "bun045 moved"),
    )
    icp_row, fpfh = cmp.runs
    assert (icp_row.method, icp_row.status) == ("icp-point", "failed")
    assert "no correspondence" in icp_row.message and icp_row.success is False
    assert icp_row.T_target_source is None and icp_row.rotation_error_deg is None
    assert fpfh.status == "ok" and fpfh.success is True
    assert fpfh.rotation_error_deg < 1.0 and fpfh.translation_error_m < 0.005
    assert fpfh.coarse_rotation_error_deg is not None and fpfh.fitness > 0.3
    assert fpfh.time_s > 0 and fpfh.peak_memory_mb is not None and fpfh.peak_memory_mb > 0
    assert fpfh.details["config"]["method"] == "fpfh-ransac"

    md = to_markdown(cmp)
    assert "| icp-point | failed: ICP (point-to-point) found no correspondence" in md
    assert "| fpfh-ransac | ok |" in md

    out = tmp_path / "report"
    paths = write_comparison(cmp, out)
    assert sorted(p.name for p in paths) == ["comparison.json", "comparison.md", "comparison.png"]
    doc = json.loads((out / "comparison.json").read_text())
    assert [m["method"] for m in doc["methods"]] == ["icp-point", "fpfh-ransac"]
    assert doc["methods"][0]["status"] == "failed" and doc["methods"][1]["success"] is True
    assert doc["success_criteria"] == {"rotation_deg": 1.0, "translation_m": 0.005}
    png = cv2.imread(str(out / "comparison.png"))
    assert png is not None and png.shape[0] > 200


def test_compare_refuses_pairs_without_overlap(bunny):
    a, b, T = bunny
    shifted = b.points + [0.0, 0.0, 1000.0]
    with pytest.raises(InputError, match="do not overlap at the ground-truth pose"):
        compare(a.points, shifted, methods="icp-point", T_gt=T, isolate=False)
    with pytest.raises(RegistrationError, match="no overlap found"):
        compare(a.points, shifted, methods="icp-point", isolate=False)


def test_compare_rejects_bad_options(bunny):
    a, b, _ = bunny
    with pytest.raises(ConfigError, match="unknown method"):
        compare(a, b, methods="flexreg,sift-icp")
    with pytest.raises(ConfigError, match="time limit"):
        compare(a, b, methods="icp-point", timeout_s=0)
    with pytest.raises(InputError, match="ground truth"):
        compare(a, b, methods="icp-point", T_gt=np.diag([1.0, 2.0, 1.0, 1.0]))


def test_write_comparison_leaves_nothing_when_a_file_fails(bunny, tmp_path, monkeypatch):
    a, b, T = bunny
    cmp = compare(a.points, b.points, methods="icp-plane", T_gt=T, isolate=False)
    assert cmp.run("icp-plane").status == "ok"

    def broken_plot(*_args, **_kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(results, "plot_comparison", broken_plot)
    out = tmp_path / "report"
    with pytest.raises(InputError, match="No space left"):
        write_comparison(cmp, out)
    assert not out.exists() or list(out.iterdir()) == []


def test_fork_server_preloads_importable_modules():
    """Every flexreg module the fork server imports exists (a typo would silently cost the
    first measured call its import time)."""
    import importlib

    modules = preload_modules()
    for name in modules:
        if name.startswith("flexreg"):
            importlib.import_module(name)
    assert "flexreg.bench._preload" in modules and "flexreg.stages.refinement.projective" in modules


def test_fork_server_preloads_every_module_a_method_imports(shared_data):
    """After the listed modules (without the kernel loader, which imports all of flexreg), one
    run of every default method imports no further flexreg module: a module added to a method
    and missing from the list would make its first measured call pay its import. flexreg runs
    on the bunny pair whole (its stages import as they are reached); the baselines, whose
    imports do not depend on the data, on every other row and column of it (a fifth of the
    time)."""
    import subprocess
    import sys

    code = (
        "import importlib, sys\n"
        "from flexreg import read_scans\n"
        "from flexreg.bench.measure import preload_modules\n"
        "from flexreg.core.scan import Scan\n"
        f"a, b = read_scans({str(shared_data / 'bunny_range_scans_gt')!r} + "
        "'/derived_bunny_grids_and_gt.npz')\n"
        "def half(s):\n"
        "    xyz, ok = s.organized()\n"
        "    return Scan.from_organized(xyz[::2, ::2], ok[::2, ::2], name=s.name)\n"
        "small = half(a), half(b)\n"
        "for m in preload_modules():\n"
        "    if m != 'flexreg.bench._preload':\n"
        "        importlib.import_module(m)\n"
        "before = set(sys.modules)\n"
        "from flexreg.bench.methods import DEFAULT_METHODS, run_method\n"
        "for name in DEFAULT_METHODS:\n"
        "    try:\n"
        "        run_method(name, *((a, b) if name == 'flexreg' else small))\n"
        "    except Exception:\n"
        "        pass\n"
        "print(sorted(m for m in set(sys.modules) - before if m.startswith('flexreg')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_startup_loads_cached_serial_kernels_without_compiling():
    """A kernel compiled once (and cached on disk) is loaded when a new process imports
    flexreg.bench._preload, before its first call; parallel kernels are left alone (they would start
    OpenMP threads in the fork server)."""
    import subprocess
    import sys

    from flexreg.core.range_image import RangeImage
    from flexreg.stages.projection import fill_holes

    xyz = np.ones((3, 3, 3))
    valid = np.ones((3, 3), bool)
    valid[1, 1] = False
    fill_holes(RangeImage(xyz=xyz, valid=valid, index=np.zeros((3, 3), np.int64)))
    code = (
        "import flexreg.bench._preload as s\n"
        "from flexreg.stages.projection import _fill_holes\n"
        "from flexreg.stages.refinement.projective import _associate\n"
        "print(len(_fill_holes.signatures), len(_associate.signatures))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert int(out[0]) >= 1 and int(out[1]) == 0


def test_two_runs_started_in_one_second_write_two_folders(tmp_path):
    """Two benchmark runs started at once (the same timestamp) never share a results folder:
    the second one's records would overwrite the first one's."""
    from datetime import datetime

    from flexreg.bench.harness import results_folder

    when = datetime(2026, 1, 2, 3, 4, 5)
    a = results_folder(tmp_path, "clouds", when=when)
    b = results_folder(tmp_path, "clouds", when=when)
    assert a.name == "clouds-20260102-030405" and b.name == "clouds-20260102-030405-2"
    assert a.is_dir() and b.is_dir()
