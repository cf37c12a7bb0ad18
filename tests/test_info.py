"""`flexreg info` as a surveyor reads it: a multi-setup file one line per setup, a cloud in
project coordinates with the option that fixes it instead of a meaningless field of view, and
a 3DTK scan whose ``.pose`` holds the identity as a stored pose."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

from flexreg import Scan
from flexreg.core.transforms import make_transform, rotation_about_axis
from flexreg.io import read_scan, write_scan
from flexreg.io.info import pose_stored, scan_summary
from flexreg.io.threedtk import S_RH_FROM_LH, pose_file

#: a UTM-sized scanner position (easting, northing, height), metres
UTM = np.array([455013.25, 5455000.5, 121.75])


def _room(n: int = 600, seed: int = 0) -> np.ndarray:
    """Points all around a scanner at the origin (a scanner sees around itself)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(2.0, 8.0, size=(n, 1))


@pytest.fixture(scope="module")
def six_setups(tmp_path_factory):
    """An E57 with six setups, the last without a pose."""
    path = tmp_path_factory.mktemp("six") / "project.e57"
    scans = []
    for k in range(6):
        pose = make_transform(rotation_about_axis([0, 0, 1], 0.2 * k), [3.0 * k, 1.0, 0.0])
        T = pose if k < 5 else np.eye(4)
        scans.append(Scan(points=_room(100 + k, k), name=f"Station {k + 1}", T_world_scanner=T))
    write_scan(path, scans)
    return path


def test_multi_setup_file_one_line_per_setup(six_setups):
    rc, out, err = run_cli(["info", six_setups])
    assert rc == 0, err
    assert "6 setups" in out and f"{six_setups}#N" in out and "--detail" in out
    rows = [line for line in out.splitlines() if f"{six_setups}#" in line and "Station" in line]
    assert len(rows) == 6
    assert all(r.split()[-1] == "yes" for r in rows[:5]) and rows[5].split()[-1] == "no"
    assert "103" in rows[3] and "field of view" not in out
    assert len(out.splitlines()) <= 12  # not a table per setup


def test_multi_setup_detail_and_one_setup(six_setups):
    rc, out, _ = run_cli(["info", six_setups, "--detail"])
    assert rc == 0 and out.count("field of view") == 6
    rc, out, _ = run_cli(["info", f"{six_setups}#2"])
    assert rc == 0 and out.count("field of view") == 1 and "Station 3" in out
    rc, out, _ = run_cli(["info", six_setups, "--json"])
    doc = json.loads(out)
    assert len(doc) == 6 and [d["pose"]["stored"] for d in doc] == [True] * 5 + [False]


@pytest.fixture(scope="module")
def laz(tmp_path_factory):
    path = tmp_path_factory.mktemp("georef") / "station.laz"
    write_scan(path, Scan(points=_room() + UTM))
    return path


def test_georeferenced_cloud_gets_the_origin_hint_not_a_field_of_view(laz):
    rc, out, err = run_cli(["info", laz])
    assert rc == 0, err
    assert "│ field of view" not in out and "│ range " not in out
    flat = " ".join(out.split())
    assert "not centred on its scanner" in flat and "--origin X Y Z" in flat
    assert "--target-origin" in flat and "--source-origin" in flat
    assert "x 455005" in flat or "x 455006" in flat  # where the points are: the extent
    rc, out, _ = run_cli(["info", laz, "--json"])
    (d,) = json.loads(out)
    assert d["field_of_view"] is None and d["range_m"] is None
    assert "project or map coordinates" in d["not_centred"] and "--origin" in d["hint"]
    assert d["bounds_m"]["min"][1] > 5e6


def test_georeferenced_cloud_seen_from_its_origin(laz):
    rc, out, err = run_cli(["info", laz, "--origin", *map(repr, map(float, UTM))])
    assert rc == 0, err
    assert "field of view" in out and "not centred" not in out
    rc, out, _ = run_cli(["info", laz, "--origin", *map(repr, map(float, UTM)), "--json"])
    (d,) = json.loads(out)
    assert 2.0 - 1e-3 < d["range_m"]["min"] and d["range_m"]["max"] < 8.0 + 1e-3


def _write_3dtk(path, position_cm=None):
    """A small uos scan (20 profiles of 60 points), with a ``.pose`` when given."""
    el, az = np.meshgrid(
        np.radians(np.linspace(-40, 40, 20)), np.radians(np.linspace(80, -80, 60)), indexing="ij"
    )
    r = 5 + 0.5 * np.sin(3 * az)
    rh = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1) * r[..., None]
    lh = (rh.reshape(-1, 3) / 0.01) @ S_RH_FROM_LH  # p_rh = S p_lh / 100
    np.savetxt(path, lh, fmt="%.3f")
    if position_cm is not None:
        path.with_suffix(".pose").write_text(" ".join(map(str, position_cm)) + "\n0 0 0\n")


def test_3dtk_identity_pose_file_is_a_stored_pose(tmp_path):
    first, loose = tmp_path / "scan000.3d", tmp_path / "loose.3d"
    _write_3dtk(first, [0, 0, 0])  # 3DTK's first scan: at the world origin, said explicitly
    _write_3dtk(loose)  # no pose file: nothing stored
    assert pose_file(first) == tmp_path / "scan000.pose" and pose_file(loose) is None
    a, b = read_scan(first), read_scan(loose)
    np.testing.assert_array_equal(a.T_world_scanner, np.eye(4))
    np.testing.assert_array_equal(b.T_world_scanner, np.eye(4))
    assert pose_stored(a) and not pose_stored(b)
    assert scan_summary(a)["pose"]["stored"] and not scan_summary(b)["pose"]["stored"]
    rc, out, _ = run_cli(["info", first])
    assert rc == 0 and "(from scan000.pose)" in out and "none stored" not in out
    rc, out, _ = run_cli(["info", loose])
    assert rc == 0 and "none stored" in out


def test_identity_in_other_formats_is_no_pose():
    assert not pose_stored(Scan(points=_room()), "e57")
    posed = Scan(points=_room(), T_world_scanner=make_transform(np.eye(3), [1.0, 0.0, 0.0]))
    assert pose_stored(posed, "ptx")
