"""The frame a survey's poses come out in: scanner origins of clouds in project coordinates
(georeferenced LAZ), the stored site frame of an E57 project, and the setups' own names."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest
from conftest import one_error_line, pose, room_project, run_cli

from flexreg.core.scan import Scan
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.errors import InputError
from flexreg.io import read_scan, write_scan
from flexreg.survey.frames import file_correction, read_origins_csv, shift, site_of_reference

UTM = np.array([455000.0, 5455000.0, 120.0])  # a UTM-like offset (metres)


def test_origins_csv_and_its_refusals(tmp_path) -> None:
    f = tmp_path / "o.csv"
    f.write_text("stem,x,y,z\na,1,2,3\nb.laz,455000.5,5455000.25,-1\n")
    assert read_origins_csv(f, ["a", "b"]) == {
        "a": (1.0, 2.0, 3.0),
        "b": (455000.5, 5455000.25, -1.0),
    }
    bad = {
        "c,1,2,3\n": "row 1: 'c' is not one of the stations",
        "a,1,2\n": "row 1: expected stem,x,y,z",
        "a,1,x,3\n": "row 1: x, y and z must be numbers (metres)",
        "a,1,nan,3\n": "row 1: x, y and z must be finite",
        "a,1,2,3\na,1,2,3\n": "row 2: 'a' is given twice",
        "stem,x,y,z\n": "no origins in the file",
    }
    for text, why in bad.items():
        f.write_text(text)
        with pytest.raises(InputError, match=re.escape(why)):
            read_origins_csv(f, ["a", "b"])


def test_site_frame_by_hand() -> None:
    """Registered poses that are the stored ones seen from another frame: the site frame is
    that frame, whichever stations tie it; the origins' frame is the shift to the
    reference's origin; a station's file correction undoes its origin."""
    T_site_ref = pose((0.01, -0.02, 0.7), (300.0, -20.0, 4.0))
    stored = {k: pose((0.0, 0.0, 0.3 * i), (2.0 * i, 1.0, 0.0)) for i, k in enumerate("abc")}
    poses = {k: invert(T_site_ref) @ T for k, T in stored.items()}
    checks = {k: {"agrees": True, "pivot": "a"} for k in stored}
    T, what = site_of_reference("stored", "a", poses, stored, checks, {})
    np.testing.assert_allclose(T, T_site_ref, atol=1e-12)
    assert "3 stations" in what
    T, _ = site_of_reference("stored", "a", poses, stored, {}, {})  # none checked: one ties it
    np.testing.assert_allclose(T, T_site_ref, atol=1e-12)
    with pytest.raises(InputError, match="no placed station stores a pose"):
        site_of_reference("stored", "a", poses, {}, {}, {})
    T, what = site_of_reference("reference", "a", poses, stored, checks, {"a": tuple(UTM)})
    np.testing.assert_array_equal(T, shift(UTM))
    assert "--origins" in what
    np.testing.assert_array_equal(
        site_of_reference("reference", "a", poses, {}, {}, {})[0], np.eye(4)
    )
    # a station at the origin o of its file, placed at o in the site: its correction is none
    o = UTM + [3.0, 4.0, 1.5]
    np.testing.assert_allclose(file_correction(shift(o), o), np.eye(4), atol=0)
    np.testing.assert_array_equal(file_correction(shift(o), None), shift(o))


@pytest.fixture(scope="module")
def georeferenced(tmp_path_factory):
    """Three co-registered room stations as LAZ in UTM-like coordinates (no grid), and their
    scanner positions in an origins CSV."""
    root = tmp_path_factory.mktemp("geo")
    room = room_project(root / "room", 3)
    gt = json.loads((room / "gt.json").read_text())
    scans = root / "scans"
    scans.mkdir()
    rows = ["stem,x,y,z"]
    for st in gt["stations"]:
        T = np.asarray(st["T_world_scanner"])
        s = read_scan(room / f"{st['name']}.ptx")
        write_scan(
            scans / f"{st['name']}.laz", Scan(points=s.points @ T[:3, :3].T + T[:3, 3] + UTM)
        )
        o = T[:3, 3] + UTM
        rows.append(f"{st['name']},{o[0]:.4f},{o[1]:.4f},{o[2]:.4f}")
    (root / "origins.csv").write_text("\n".join(rows) + "\n")
    return root


def test_georeferenced_laz_without_origins_one_line(georeferenced, tmp_path) -> None:
    rc, _, err = run_cli(
        ["survey", georeferenced / "scans", "--out", tmp_path / "o", "--workers", "1"]
    )
    assert rc == 1
    line = one_error_line(err)
    assert "not centred on its scanner" in line and "--origins FILE.csv" in line
    assert not (tmp_path / "o" / "poses.json").exists()


def test_georeferenced_laz_surveys_in_the_files_coordinates(georeferenced, tmp_path) -> None:
    """With the scanner positions, the stations register and every result is in the files'
    (UTM) coordinates: each station's correction moves its own points by millimetres (the
    files are co-registered already), and the merged LAZ lies where the files do."""
    out = tmp_path / "o"
    rc, _, err = run_cli(
        ["survey", georeferenced / "scans", "--out", out, "--workers", "1",
         "--origins", georeferenced / "origins.csv", "--merged", out / "merged.laz"]
    )  # fmt: skip
    assert rc in (0, 3), err
    doc = json.loads((out / "poses.json").read_text())
    assert doc["frame"]["kind"] == "origins"
    for stem, st in doc["stations"].items():
        assert st["placed"] and st["status"] in ("verified", "placed")
        T = np.asarray(st["T_site_file"])
        np.testing.assert_array_equal(np.loadtxt(out / "stations" / f"{stem}.txt"), T)
        p = read_scan(georeferenced / "scans" / f"{stem}.laz").points
        moved = np.linalg.norm(p @ T[:3, :3].T + T[:3, 3] - p, axis=1)
        assert np.median(moved) < 0.01 and moved.max() < 0.05
        assert np.linalg.norm(np.asarray(st["T_site_station"])[:3, 3] - st["origin"]) < 0.01
    merged = read_scan(out / "merged.laz").points
    files = np.vstack([read_scan(f).points for f in sorted((georeferenced / "scans").iterdir())])
    np.testing.assert_allclose(merged.min(axis=0), files.min(axis=0), atol=0.05)
    np.testing.assert_allclose(merged.max(axis=0), files.max(axis=0), atol=0.05)


def test_e57_setups_keep_their_names_and_site_frame(tmp_path) -> None:
    """One E57 of three named setups with their site poses: --frame stored writes the poses
    in that site frame (within the survey's tolerance of the stored ones) and the E57 it
    writes keeps the setups' names."""
    room = room_project(tmp_path / "room", 3)
    gt = json.loads((room / "gt.json").read_text())
    setups = []
    for i, st in enumerate(gt["stations"]):
        s = read_scan(room / f"{st['name']}.ptx")
        T = np.asarray(st["T_world_scanner"])
        setups.append(dataclasses.replace(s, name=f"Scan {i + 1:03d}", T_world_scanner=T))
    write_scan(tmp_path / "site.e57", setups)
    out = tmp_path / "o"
    rc, _, err = run_cli(
        ["survey", tmp_path / "site.e57", "--out", out, "--workers", "1", "--frame", "stored",
         "--e57", out / "site.e57"]
    )  # fmt: skip
    assert rc in (0, 3), err
    doc = json.loads((out / "poses.json").read_text())
    assert doc["frame"]["kind"] == "stored"
    for i, st in enumerate(gt["stations"]):
        mine = doc["stations"][f"site#{i}"]
        assert mine["setup_name"] == f"Scan {i + 1:03d}"
        T, W = np.asarray(mine["T_site_station"]), np.asarray(st["T_world_scanner"])
        assert rotation_error_deg(T, W) < 0.05 and translation_error_m(T, W) < 0.01
    from flexreg.io.setups import list_setups

    assert [s.name for s in list_setups(out / "site.e57")] == ["Scan 001", "Scan 002", "Scan 003"]


def test_a_stored_identity_pose_counts_when_the_file_says_so() -> None:
    """A 3DTK ``.pose`` file holding the identity (the first scan) is a stored pose; an E57 or
    PTX identity means none; an old cache entry that does not say keeps the old reading."""
    from flexreg.survey.stations import _stored_pose

    eye, T = np.eye(4), pose((0.0, 0.0, 0.4), (1.0, 2.0, 0.0))
    np.testing.assert_array_equal(_stored_pose(eye, True), eye)
    assert _stored_pose(eye, False) is None and _stored_pose(eye, None) is None
    np.testing.assert_array_equal(_stored_pose(T, None), T)
    assert _stored_pose(T, False) is None
    assert _stored_pose(np.diag([2.0, 1, 1, 1]), True) is None  # not rigid
