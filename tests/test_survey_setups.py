"""A project that arrives as one E57 file: every setup is a station, stored poses seed the
links and are checked against the result (a wrong stored pose is flagged, exit 3)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import room_project, run_cli

from flexreg.core.transforms import make_transform, rotation_about_axis
from flexreg.io import read_scan, write_scan
from flexreg.io.setups import list_setups, ptx_headers
from flexreg.survey import evaluate
from flexreg.survey.stored import check_stations


def _pose(yaw_deg: float, t: list[float]) -> np.ndarray:
    return make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_deg)), t)


def test_check_stations_ties_the_frames_by_the_agreeing_majority():
    T_world_ref = _pose(30.0, [100.0, 200.0, 5.0])  # the stored frame is anywhere
    truth = {"a": np.eye(4), "b": _pose(10, [4, 0, 0]), "c": _pose(-20, [0, 6, 0])}
    stored = {s: T_world_ref @ T for s, T in truth.items()}
    stored["c"] = stored["c"] @ _pose(2.0, [0.5, 0, 0])  # one wrong stored pose
    checks = check_stations(truth, stored, max_deg=1.0, max_m=0.1)
    assert {s: c["agrees"] for s, c in checks.items()} == {"a": True, "b": True, "c": False}
    assert checks["c"]["rotation_deg"] == pytest.approx(2.0, abs=1e-9)
    assert checks["c"]["translation_m"] > 0.4
    assert checks["a"]["pivot"] in ("a", "b")
    # one station storing a pose: nothing to compare
    assert check_stations(truth, {"a": stored["a"]}, 1.0, 0.1) == {}


def test_ptx_headers_count_lines_and_refuse_a_short_file(tmp_path):
    rng = np.random.default_rng(3)
    from flexreg import Scan

    scans = [
        Scan(points=rng.normal(size=(50, 3)) + 3, name="a"),
        Scan(points=rng.normal(size=(70, 3)) + 3, name="b", T_world_scanner=_pose(5, [1, 2, 3])),
    ]
    path = tmp_path / "two.ptx"
    write_scan(path, scans)
    heads = ptx_headers(path)
    assert [(n, c) for n, c, _ in heads] == [("two", 50), ("two#1", 70)]
    np.testing.assert_allclose(heads[1][2], scans[1].T_world_scanner, atol=1e-6)
    short = tmp_path / "short.ptx"
    short.write_bytes(path.read_bytes()[:-200])
    from flexreg.errors import InputError

    with pytest.raises(InputError, match="ends early"):
        ptx_headers(short)


@pytest.fixture(scope="module")
def project_e57(tmp_path_factory) -> tuple[Path, dict]:
    """Three synthetic stations in one E57; stored poses from the truth, station 2's wrong."""
    folder = room_project(tmp_path_factory.mktemp("setups"), 3)
    gt = json.loads((folder / "gt.json").read_text())
    scans = []
    for i, st in enumerate(gt["stations"]):
        T = np.asarray(st["T_world_scanner"])
        if i == 2:
            T = T @ _pose(3.0, [0.6, 0.0, 0.0])
        scans.append(replace(read_scan(folder / st["file"]), T_world_scanner=T, name=st["name"]))
    path = folder / "project.e57"
    write_scan(path, scans)
    return path, gt


def test_every_setup_is_a_station_and_a_wrong_stored_pose_is_flagged(project_e57, tmp_path):
    path, gt = project_e57
    assert len(list_setups(path)) == 3
    out = tmp_path / "out"
    rc, stdout, err = run_cli(["survey", path, "--out", out, "--workers", "1"])
    assert rc == 3, err + stdout
    doc = json.loads((out / "poses.json").read_text())
    names = ["project#0", "project#1", "project#2"]
    assert sorted(doc["stations"]) == names
    for i, stem in enumerate(names):
        st = doc["stations"][stem]
        assert st["placed"] and st["setup"] == i and st["setup_name"] == f"station_0{i}"
        assert (out / "stations" / f"{stem}.txt").is_file()
    checks = {s: doc["stations"][s]["stored_pose_check"] for s in names}
    assert [checks[s]["agrees"] for s in names] == [True, True, False]
    assert checks["project#2"]["rotation_deg"] == pytest.approx(3.0, abs=0.3)
    flagged = [ln for ln in err.splitlines() if ln.startswith("project#2: the pose stored")]
    assert len(flagged) == 1 and "disagrees" in flagged[0]
    # the registration, not the wrong stored pose, placed station 2: right against the truth
    truth = {
        **gt,
        "stations": [{**s, "name": f"project#{i}"} for i, s in enumerate(gt["stations"])],
    }
    ev = evaluate(doc, truth)
    assert ev["wrong"] == []
    for e in ev["stations"].values():
        assert e["rotation_deg"] < 0.3 and e["translation_m"] < 0.03
    # each link between stations that store poses reports its disagreement with them
    devs = [e["stored_deviation"] for e in doc["links"] if e["T_target_source"] is not None]
    assert devs and all(d is not None for d in devs)
    wrong = [
        e["stored_deviation"]["rotation_deg"]
        for e in doc["links"]
        if e["T_target_source"] is not None and "project#2" in (e["target"], e["source"])
    ]
    assert wrong and all(d == pytest.approx(3.0, abs=0.3) for d in wrong)
