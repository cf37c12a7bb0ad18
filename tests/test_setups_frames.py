"""Clouds in project coordinates: a georeferenced LAZ (written by flexreg's LAS writer) is
refused with the fix in one line (``project``), registered from virtual viewpoints
(``register``), and read with ``--origin`` / ``--target-origin`` / ``--source-origin``: moved
to the scanner in full float64 precision, then float32."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import one_error_line, run_cli
from test_setups_register import T_TRUE, _stations

from flexreg import Scan, read_scan, write_scan
from flexreg.core.transforms import apply, make_transform, rotation_about_axis, rotation_error_deg
from flexreg.io.origin import centring_problem, recentre

#: a UTM-sized position of the first station (easting, northing, height), metres
UTM = np.array([500123.25, 5432109.5, 312.75])


@pytest.fixture(scope="module")
def laz(tmp_path_factory):
    """Both stations as georeferenced LAZ files (no grid, no pose), and their positions."""
    folder = tmp_path_factory.mktemp("frames")
    first, second = _stations()
    W1 = make_transform(np.eye(3), UTM)
    W2 = W1 @ T_TRUE
    write_scan(folder / "t.laz", Scan(points=apply(W1, first.points[::3])))
    write_scan(folder / "s.laz", Scan(points=apply(W2, second.points[::3])))
    return folder / "t.laz", folder / "s.laz", UTM, W2[:3, 3]


def test_detection_and_recentring_keep_float64_precision():
    rng = np.random.default_rng(3)
    around = rng.normal(size=(500, 3)) * 10.0  # a scanner sees around itself: centred
    assert centring_problem(Scan(points=around)) is None
    assert "project or map" in centring_problem(Scan(points=around + UTM))
    site = np.abs(around) + [60.0, 0.0, 0.0]  # a site frame with the scanner 60 m away
    assert "outside its points' bounding box" in centring_problem(Scan(points=site))
    moved = recentre(Scan(points=around + UTM), UTM)
    np.testing.assert_allclose(moved.points, around, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(moved.T_world_scanner[:3, 3], UTM)


def test_laz_keeps_utm_coordinates_to_the_written_resolution(laz):
    t, *_ = laz
    first = _stations()[0]
    pts = read_scan(t).points
    assert np.abs(pts - (first.points[::3] + UTM)).max() < 1e-4  # LAS 0.1 mm integers


def test_project_refuses_a_project_frame_cloud_and_takes_origin(laz, tmp_path):
    t, _, o, _ = laz
    out = tmp_path / "t.png"
    rc, _, err = run_cli(["project", t, "--out", out])
    line = one_error_line(err)
    assert rc == 1 and not out.exists()
    assert "not centred on its scanner" in line and "--origin X Y Z" in line
    rc, stdout, err = run_cli(["project", t, "--out", out, "--origin", *map(repr, map(float, o))])
    assert rc == 0 and out.exists(), err
    assert "valid pixels" in stdout


def test_register_two_project_frame_clouds_with_their_origins(laz, tmp_path):
    t, s, o_t, o_s = laz
    out = tmp_path / "T.json"
    rc, _, err = run_cli(["register", t, s, "--out", out])
    assert rc in (0, 3), err  # seen from virtual viewpoints, said in a line naming the option
    lines = [x for x in err.splitlines() if "viewpoint chosen where it hides least" in x]
    assert len(lines) == 2 and "--target-origin X Y Z" in lines[0], err
    result = json.loads(out.read_text())
    chosen = np.asarray(result["origins"]["target"])
    assert np.linalg.norm(chosen - o_t) < 20.0  # among the points, not at the map's origin
    if rc == 0:  # a confident answer: the files are co-registered, their correction is nil
        T_files = np.asarray(result["T_target_source_in_files"])
        p = read_scan(s).points[::50]
        assert np.median(np.linalg.norm(apply(T_files, p) - p, axis=1)) < 0.03
    out.unlink()
    # the scanners' axes are the map's here: T_target_source is the offset of the positions
    truth = make_transform(np.eye(3), o_s - o_t)
    np.savetxt(tmp_path / "init.txt", truth @ make_transform(np.eye(3), [0.05, -0.05, 0.02]))
    argv = ["register", t, s, "--out", out, "--init", tmp_path / "init.txt", "--icp-only"]
    argv += ["--target-origin", *map(repr, map(float, o_t))]
    argv += ["--source-origin", *map(repr, map(float, o_s))]
    rc, _, err = run_cli(argv)
    assert rc == 0, err
    T = np.asarray(json.loads(out.read_text())["T_target_source"])
    assert rotation_error_deg(T, truth) < 0.3
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.03


def test_a_recentred_cloud_is_float32_near_its_scanner(laz):
    """Read with the scanner position, a georeferenced cloud is moved in float64 and then
    kept as float32 like any cloud read in its scanner's frame (within float32 rounding of
    the float64 difference); its pose keeps the position exactly."""
    from flexreg.cli._common import read_input

    t, _, o, _ = laz
    utm = read_scan(t)
    assert utm.points.dtype == np.float64  # project coordinates: float64 as read
    (near,) = read_input(t, origin=tuple(o), origin_option="--origin")
    assert near.points.dtype == np.float32
    np.testing.assert_array_equal(near.points, (utm.points - o).astype(np.float32))
    np.testing.assert_array_equal(near.T_world_scanner[:3, 3], o)


def test_file_frame_of_a_shift_is_the_identity_in_float64():
    """Two scans already in one project frame: the registration between the clouds moved to
    their scanners is the offset of the positions, and the same in the files' coordinates is
    the identity to float64 rounding, UTM-sized origins notwithstanding."""
    from flexreg.io.origin import in_file_frame

    o_t, o_s = UTM, UTM + [3.125, -1.75, 0.5]
    T = make_transform(np.eye(3), o_s - o_t)
    np.testing.assert_allclose(in_file_frame(T, o_t, o_s), np.eye(4), rtol=0, atol=1e-9)
    R = make_transform(rotation_about_axis([0, 0, 1], np.radians(30.0)), [1.0, 2.0, 0.0])
    T_file = in_file_frame(R, o_t, o_s)  # = O_t R O_s^-1, and maps o_s + p to o_t + R p
    p = np.array([[1.0, -2.0, 0.5], [10.0, 4.0, -1.0]])
    np.testing.assert_allclose(apply(T_file, p + o_s), apply(R, p) + o_t, rtol=0, atol=1e-8)
    assert in_file_frame(R, None, None).tolist() == R.tolist()


def test_register_txt_in_the_files_coordinates(laz, tmp_path):
    """`--txt` of a run with origins holds the correction in the files' coordinates (by
    default): for two co-registered georeferenced clouds it is the identity within the
    registration's accuracy; `--txt-frame scanner` gives the JSON's matrix; the JSON and the
    console say which is which."""
    t, s, o_t, o_s = laz
    truth = make_transform(np.eye(3), o_s - o_t)
    np.savetxt(tmp_path / "init.txt", truth @ make_transform(np.eye(3), [0.05, -0.05, 0.02]))
    argv = ["register", t, s, "--init", tmp_path / "init.txt", "--icp-only"]
    argv += ["--target-origin", *map(repr, map(float, o_t))]
    argv += ["--source-origin", *map(repr, map(float, o_s))]
    rc, stdout, err = run_cli([*argv, "--out", tmp_path / "T.json", "--txt", tmp_path / "T.txt"])
    assert rc == 0, err
    assert "T.txt (in the files' coordinates" in stdout and "moves its points by" in stdout
    T_file = np.loadtxt(tmp_path / "T.txt")
    assert rotation_error_deg(T_file, np.eye(4)) < 0.3
    points = read_scan(s).points  # UTM coordinates, float64
    moved = np.linalg.norm(apply(T_file, points) - points, axis=1)
    assert np.median(moved) < 0.03  # the files are registered already: (almost) no motion
    doc = json.loads((tmp_path / "T.json").read_text())
    assert doc["txt"]["frame"] == "file" and doc["origins"]["target"] == list(o_t)
    np.testing.assert_allclose(doc["T_target_source_in_files"], T_file, rtol=0, atol=1e-9)
    T = np.asarray(doc["T_target_source"])
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.03  # the scanners' frames: the offset

    rc, stdout, err = run_cli(
        [*argv, "--out", tmp_path / "S.json", "--txt", tmp_path / "S.txt", "--txt-frame", "scanner"]
    )
    assert rc == 0, err
    assert "not the files' coordinates" in stdout
    S = json.loads((tmp_path / "S.json").read_text())
    assert S["txt"]["frame"] == "scanner"
    np.testing.assert_allclose(np.loadtxt(tmp_path / "S.txt"), S["T_target_source"], atol=1e-12)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--txt-frame", "scanner"], "give --txt as well"),
        (["--txt", "x.txt", "--txt-frame", "world"], "must be file or scanner"),
    ],
)
def test_txt_frame_refused_one_line(laz, tmp_path, extra, message):
    t, s, *_ = laz
    extra = [str(tmp_path / e) if e.endswith(".txt") else e for e in extra]
    rc, _, err = run_cli(["register", t, s, "--out", tmp_path / "T.json", *extra])
    assert rc == 1 and message in one_error_line(err)
    assert not (tmp_path / "T.json").exists()


def test_register_refuses_a_cloud_of_one_point_before_choosing_a_viewpoint(tmp_path):
    """Copies of one point lie outside the file's origin, but there is no viewpoint to choose:
    one line naming the file, exit 1, nothing written."""
    one, other = tmp_path / "one.ply", tmp_path / "other.ply"
    write_scan(one, Scan(points=np.tile([[1.0, 2.0, 3.0]], (50, 1))))
    write_scan(other, Scan(points=np.random.default_rng(0).normal(size=(5000, 3)) * 5.0))
    out = tmp_path / "T.json"
    rc, _, err = run_cli(["register", one, other, "--out", out])
    line = one_error_line(err)
    assert rc == 1 and not out.exists()
    assert "one.ply" in line and "50 copies of one point" in line
