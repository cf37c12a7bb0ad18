"""`flexreg synth --views`: pinhole depth views on a ring around an object, with exact truth."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import one_error_line, run_cli
from scipy.spatial import cKDTree

from flexreg.core.transforms import apply, invert
from flexreg.io import read_scan
from flexreg.io.transform_io import read_pair_transform
from flexreg.synth import read_scene
from flexreg.synth.objectscan import ELEVATION_RAD, FLOOR_ELEVATION_RAD, VIEW_F_PX

BUNNY = "mesh_models/bun_zipper_res3.ply"


def _files(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*.*")}


@pytest.fixture(scope="module")
def ring(tmp_path_factory):
    """Five views of the procedural object, 40-90 degrees apart, 0.05 mm noise."""
    out = tmp_path_factory.mktemp("object") / "set"
    args = ["synth", "--scene", "object", "--views", "5", "--view-step-deg", "40,90"]
    rc, printed, err = run_cli([*args, "--noise-mm", "0.05", "--seed", "3", "--out", out])
    assert rc == 0, err
    assert "views: 5 depth views" in printed
    return out, json.loads((out / "gt.json").read_text())


def test_views_stand_on_a_ring_within_the_asked_steps(ring):
    _, gt = ring
    views = gt["views"]
    assert [v["file"] for v in views["views"]] == [f"views/view_0{i}.png" for i in range(5)]
    assert gt["stations"] == [] and gt["config"]["stations"] == 0
    c = np.array(views["object"]["center_m"])
    eyes = np.array([np.array(v["T_world_scanner"])[:3, 3] for v in views["views"]]) - c
    np.testing.assert_allclose(np.linalg.norm(eyes, axis=1), views["distance_m"], rtol=1e-12)
    az = np.degrees(np.arctan2(eyes[:, 1], eyes[:, 0]))
    steps = np.mod(np.diff(az), 360.0)
    assert np.all((steps >= 40 - 1e-9) & (steps <= 90 + 1e-9)), steps
    el = np.arcsin(eyes[:, 2] / np.linalg.norm(eyes, axis=1))
    assert np.all((el >= ELEVATION_RAD[0] - 1e-12) & (el <= ELEVATION_RAD[1] + 1e-12))
    kinds = {p["kind"] for p in gt["pairs"]}
    assert kinds == {"view"} and [p["step_deg"] for p in gt["pairs"]] == pytest.approx(steps)


def test_every_view_is_centred_on_the_whole_object(ring):
    out, gt = ring
    c = np.array(gt["views"]["object"]["center_m"])
    for v in gt["views"]["views"]:
        scan = read_scan(out / v["file"])
        cam = scan.camera
        assert (cam.width, cam.height, cam.fx) == (640, 480, VIEW_F_PX)
        assert len(scan) == v["points"] > 10_000
        u, w, z = cam.project(apply(invert(np.array(v["T_world_scanner"])), c[None]))
        assert abs(u[0] - cam.cx) < 1e-6 and abs(w[0] - cam.cy) < 1e-6 and z[0] > 0
        rows, cols = scan.grid_index[:, 0], scan.grid_index[:, 1]
        # alone in the air and inside the view: no reading on the image border
        assert rows.min() > 0 and cols.min() > 0
        assert rows.max() < cam.height - 1 and cols.max() < cam.width - 1


def test_the_truth_maps_one_view_onto_the_next_within_the_noise(ring):
    out, gt = ring
    scene = read_scene(out / "scene.ply")
    pair = gt["pairs"][0]
    target = read_scan(out / "views" / f"{pair['target']}.png", precise=True)
    source = read_scan(out / "views" / f"{pair['source']}.png", precise=True)
    T = read_pair_transform(out / "gt.json", pair["target"], pair["source"])
    poses = {v["name"]: np.array(v["T_world_scanner"]) for v in gt["views"]["views"]}
    np.testing.assert_allclose(T, invert(poses[pair["target"]]) @ poses[pair["source"]])
    # both views on the object's surface within the 0.05 mm noise (and the 11 µm depth step)
    for scan, pose in ((target, poses[pair["target"]]), (source, poses[pair["target"]] @ T)):
        d = scene.distance(apply(pose, scan.points))
        assert np.median(d) < 0.0001 and np.quantile(d, 0.9) < 0.0003
    # and on each other: where they overlap, the source's points lie among the target's,
    # and a transform 1 mm off puts them measurably beside them
    tree = cKDTree(target.points)
    near, _ = tree.query(apply(T, source.points), distance_upper_bound=0.003)
    shared = np.isfinite(near)
    assert shared.mean() >= pair["overlap"] - 0.1
    off = T.copy()
    off[:3, 3] += 0.001 * T[:3, :3] @ np.array([0.0, 0.0, 1.0])
    near_off, _ = tree.query(apply(off, source.points[shared]))
    assert np.median(near[shared]) < 0.0005 < np.median(near_off)


def test_the_same_seed_gives_identical_files(tmp_path):
    args = ["synth", "--scene", "object", "--views", "2", "--seed", "5"]
    for name in ("a", "b"):
        assert run_cli([*args, "--out", tmp_path / name])[0] == 0
    a, b = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert sorted(a) == sorted(b) and "views/view_01.camera.json" in a
    assert all(a[k] == b[k] for k in a)
    assert run_cli([*args[:-1], "6", "--out", tmp_path / "c"])[0] == 0
    assert _files(tmp_path / "c")["views/view_00.png"] != a["views/view_00.png"]


def test_a_mesh_on_a_floor_keeps_sub_millimetre_depth_steps(tmp_path, shared_data):
    out = tmp_path / "bunny"
    args = ["synth", "--scene", shared_data / BUNNY, "--mesh-up", "y", "--views", "3"]
    rc, _, err = run_cli([*args, "--floor", "--view-step-deg", "100,120", "--out", out])
    assert rc == 0, err
    gt = json.loads((out / "gt.json").read_text())
    views = gt["views"]
    assert views["floor"] and gt["scene"]["objects"]["floor"] == 1
    assert 0.05 < views["object"]["radius_m"] < 0.15  # the bunny, about 0.15 m tall
    assert views["depth_scale_m_per_unit"] <= 1e-5  # 10 µm or finer
    side = json.loads((out / "views" / "view_00.camera.json").read_text())
    assert side["depth_scale"] == views["depth_scale_m_per_unit"] and side["depth_kind"] == "z"
    c = np.array(views["object"]["center_m"])
    for v in views["views"]:
        el = math.asin((np.array(v["T_world_scanner"])[2, 3] - c[2]) / views["distance_m"])
        assert FLOOR_ELEVATION_RAD[0] - 1e-12 <= el <= FLOOR_ELEVATION_RAD[1] + 1e-12
    floor = read_scan(out / "views" / "view_00.png")
    z_world = apply(np.array(views["views"][0]["T_world_scanner"]), floor.points)[:, 2]
    assert np.mean(z_world < gt["scene"]["floor_z_m"] + 0.001) > 0.05  # the floor is seen


def test_register_reads_a_pair_of_views(ring, tmp_path):
    out, _ = ring
    a, b = out / "views" / "view_00.png", out / "views" / "view_01.png"
    rc, _, err = run_cli(
        ["register", a, b, "--out", tmp_path / "T.json", "--truth", out / "gt.json"]
    )
    assert rc in (0, 3) or "cannot read" not in err, err
    if rc in (0, 3):
        doc = json.loads((tmp_path / "T.json").read_text())
        assert "error_vs_truth" in doc


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scene", "room", "--views", "3"], "object views need scene 'object' or a mesh"),
        (["--scene", "object", "--views", "0"], "the object scene is scanned by object views"),
        (["--scene", "object", "--stations", "2"], "object views replace the stations"),
        (["--scene", "object", "--view-step-deg", "90,30"], "view step must satisfy"),
        (["--scene", "object", "--view-step-deg", "0,30"], "view step must satisfy"),
        (["--scene", "object", "--view-step-deg", "30"], "--view-step-deg"),
        (["--scene", "object", "--lidar-frames", "2"], "object views come alone"),
        (["--scene", "object", "--views", "1001"], "--views"),
        (["--scene", "room", "--floor"], "a floor goes under the object"),
        (["--scene", "object", "--embed-poses"], "depth PNGs, which hold no pose"),
    ],
)
def test_bad_options_one_line_error_nothing_written(tmp_path, extra, message):
    out = tmp_path / "never"
    rc, _, err = run_cli(["synth", "--out", out, *extra])
    assert rc == 1
    line = one_error_line(err)
    assert message in line, line
    assert not out.exists()
