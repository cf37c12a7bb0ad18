"""PTX reader/writer, npz, depth PNGs, transforms: real fixtures, round trips, bad input."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from flexreg import Scan, read_scan, read_scans, write_scan
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.transforms import apply, make_transform, rotation_about_axis
from flexreg.errors import InputError
from flexreg.io import read_transform, write_transform_json, write_transform_txt


def _gridded_scan(rng, rows=7, cols=5, colors=True) -> Scan:
    cam = SphericalCamera(cols, rows, -0.5, 0.5, 1.2, 1.9)
    xyz = cam.backproject(
        *np.meshgrid(np.arange(cols), np.arange(rows)), rng.uniform(1, 40, (rows, cols))
    )
    valid = rng.random((rows, cols)) > 0.25
    T = make_transform(rotation_about_axis([0.1, 0.3, 1.0], 0.7), [10.5, -3.25, 1.125])
    return Scan.from_organized(
        np.round(xyz, 6),
        valid,
        intensity=np.round(rng.random((rows, cols)), 6),
        colors=rng.integers(0, 256, (rows, cols, 3)).astype(np.uint8) if colors else None,
        T_world_scanner=T,
        name="station",
    )


# ----------------------------------------------------------------------------- real fixtures


def test_pdal_multiple_and_transform(shared_data):
    path = shared_data / "ptx_pdal_fixtures" / "multiple-and-transform.ptx"
    first, second = read_scans(path)
    assert first.grid_shape == (2, 2) and second.grid_shape == (1, 4)
    assert len(first) == 4 and len(second) == 4
    # the file's (transposed) matrix maps its first cloud onto its second, registered one
    np.testing.assert_allclose(apply(first.T_world_scanner, first.points), second.points, atol=1e-6)
    np.testing.assert_allclose(first.points_world()[0], [637012.24, 849028.31, 431.66], atol=1e-6)


def test_pdal_complex_transform_missing_points_and_colour(shared_data):
    scan = read_scan(shared_data / "ptx_pdal_fixtures" / "complex-transform.ptx")
    assert scan.grid_shape == (6, 2)  # 2 columns x 6 rows
    assert len(scan) == 4  # eight "0 0 0" cells are not points
    # column-major: lines 5-8 of the data are rows 4, 5 of column 0 and rows 0, 1 of column 1
    assert scan.grid_index.tolist() == [[4, 0], [5, 0], [0, 1], [1, 1]]
    np.testing.assert_allclose(scan.points[0], [-0.005630, 0.645218, -0.440506])
    assert scan.colors[0].tolist() == [33, 38, 24]
    assert scan.intensity[1] == pytest.approx(0.489845)
    np.testing.assert_allclose(scan.T_world_scanner[:3, 3], [-3.028748, -3.819741, -1.384333])
    # written transposed: the first matrix line is the first column (the scanner's x axis)
    np.testing.assert_allclose(scan.T_world_scanner[:3, 0], [0.999979, -0.003604, -0.005365])
    np.testing.assert_allclose(scan.T_world_scanner[0, :3], [0.999979, 0.003613, 0.005359])


def test_pdal_colour_and_no_colour(shared_data):
    c = read_scan(shared_data / "ptx_pdal_fixtures" / "1.2-with-color.ptx")
    assert c.grid_shape == (71, 15) and c.colors is not None
    n = read_scan(shared_data / "ptx_pdal_fixtures" / "no-color.ptx")
    assert n.grid_shape == (1, 15) and n.colors is None and n.intensity is not None


# ----------------------------------------------------------------------------- round trips


def test_ptx_round_trip_exact(tmp_path, rng):
    scan = _gridded_scan(rng)
    p1, p2 = tmp_path / "a.ptx", tmp_path / "b.ptx"
    write_scan(p1, [scan, _gridded_scan(rng, 3, 4, colors=True)])
    back = read_scans(p1, precise=True)  # float64: the file's values exactly
    assert len(back) == 2
    b = back[0]
    assert b.grid_shape == scan.grid_shape
    order = np.lexsort((scan.grid_index[:, 0], scan.grid_index[:, 1]))  # file order: by column
    np.testing.assert_array_equal(b.grid_index, scan.grid_index[order])
    np.testing.assert_allclose(b.points, scan.points[order], atol=5e-7)  # 6 decimals
    np.testing.assert_allclose(b.intensity, scan.intensity[order], atol=5e-7)
    np.testing.assert_array_equal(b.colors, scan.colors[order])
    np.testing.assert_array_equal(b.T_world_scanner, scan.T_world_scanner)  # exact repr
    write_scan(p2, back)
    assert p1.read_bytes() == p2.read_bytes()


def test_ptx_points_are_float32_within_a_scanners_reach(tmp_path, rng):
    """By default the points are float32 (half the memory): each is the file's value rounded
    to float32, so within 1e-7 relative (0.01 mm at 100 m)."""
    scan = _gridded_scan(rng)
    scan.points[0] = [123.456789, -98.765432, 0.000001]
    p = tmp_path / "a.ptx"
    write_scan(p, scan)
    precise, small = read_scan(p, precise=True), read_scan(p)
    assert precise.points.dtype == np.float64 and small.points.dtype == np.float32
    np.testing.assert_array_equal(small.points, precise.points.astype(np.float32))
    np.testing.assert_array_equal(small.grid_index, precise.grid_index)
    assert np.abs(small.points - precise.points).max() <= 1e-7 * np.abs(precise.points).max()


def test_ptx_far_coordinates_stay_float64(tmp_path, rng):
    """A cloud in project coordinates (beyond FLOAT32_MAX_M) is read as float64: float32
    would round a UTM northing to half a metre."""
    far = _gridded_scan(rng)
    far.points[:] += [512_345.678901, 5_412_345.678901, 0.0]
    p = tmp_path / "far.ptx"
    write_scan(p, [_gridded_scan(rng), far])
    near_back, far_back = read_scans(p)
    assert near_back.points.dtype == far_back.points.dtype == np.float64
    order = np.lexsort((far.grid_index[:, 0], far.grid_index[:, 1]))
    np.testing.assert_allclose(far_back.points, far.points[order], rtol=0, atol=5e-7)


def test_ptx_parser_number_forms(tmp_path):
    p = tmp_path / "forms.ptx"
    header = "1\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
    p.write_text(
        header + "1.5 -2 3e2 .5\r\n-0.25 +1.0 1E-3 1\n12345678.123456 -0.000001 7.0 0\n0 0 0 0.5"
    )
    s = read_scan(p)
    assert s.grid_shape == (4, 1) and len(s) == 3
    np.testing.assert_array_equal(
        s.points, [[1.5, -2.0, 300.0], [-0.25, 1.0, 0.001], [12345678.123456, -0.000001, 7.0]]
    )
    np.testing.assert_array_equal(s.intensity, np.float32([0.5, 1.0, 0.0]))


def test_npz_round_trip_keeps_everything(tmp_path, rng):
    scan = _gridded_scan(rng)
    scan.camera = PinholeCamera(100.0, 100.0, 2.0, 3.0, 5, 7)
    write_scan(tmp_path / "s.npz", scan)
    b = read_scan(tmp_path / "s.npz")
    for attr in ("points", "intensity", "colors", "grid_index", "T_world_scanner"):
        np.testing.assert_array_equal(getattr(b, attr), getattr(scan, attr))
    assert b.grid_shape == scan.grid_shape and b.camera == scan.camera and b.name == "station"


def test_foreign_npy(shared_data, tmp_path):
    ref = read_scan(shared_data / "reg_3dmatch_geotransformer_demo" / "ref.npy")
    assert (
        ref.points.shape
        == np.load(shared_data / "reg_3dmatch_geotransformer_demo" / "ref.npy").shape
    )
    org = np.full((2, 3, 3), np.nan)
    org[1, 2] = [1, 2, 3]
    np.save(tmp_path / "org.npy", org)
    s = read_scan(tmp_path / "org.npy")
    assert s.grid_shape == (2, 3) and s.grid_index.tolist() == [[1, 2]]


def test_depth_png_conventions(tmp_path):
    raw = np.zeros((4, 6), dtype=np.uint16)
    raw[1, 2] = 10000  # TUM: 5000 per metre -> 2 m
    raw[3, 5] = 65535
    cv2.imwrite(str(tmp_path / "d.png"), raw)
    cam = PinholeCamera(10.0, 10.0, 2.0, 1.0, 6, 4)
    s = read_scan(tmp_path / "d.png", camera=cam, depth_scale=1 / 5000, invalid_values=(65535,))
    assert len(s) == 1 and s.grid_index.tolist() == [[1, 2]]
    np.testing.assert_allclose(s.points[0], [0.0, 0.0, 2.0])
    # the same value read as Euclidean range along an off-axis ray
    raw2 = np.zeros((4, 6), dtype=np.uint16)
    raw2[1, 5] = 5000
    cv2.imwrite(str(tmp_path / "r.png"), raw2)
    r = read_scan(tmp_path / "r.png", camera=cam, depth_scale=1 / 5000, depth_kind="range")
    assert np.linalg.norm(r.points[0]) == pytest.approx(1.0)
    assert r.points[0, 2] == pytest.approx(1 / np.sqrt(1 + 0.3**2))


def test_embedded_laserscan_sidecar(tmp_path):
    from conftest import REPO

    s = read_scan(REPO / "data" / "laserscan" / "laserscan-depth.png")
    assert s.grid_shape == (397, 1799)
    assert isinstance(s.camera, SphericalCamera) and s.camera.theta_min == 0.87
    raw = cv2.imread(str(REPO / "data" / "laserscan" / "laserscan-depth.png"), -1)
    assert len(s) == int(((raw > 0) & (raw < 65535)).sum())
    r = np.linalg.norm(s.points, axis=1)
    # float32 points (the default): each range within float32's rounding of the stored value
    np.testing.assert_allclose(
        np.sort(r), np.sort(raw[(raw > 0) & (raw < 65535)] / 1000.0), rtol=2e-7
    )


def test_transform_files_round_trip(tmp_path):
    T = make_transform(rotation_about_axis([1, 2, 3], 0.4), [1.0, -2.0, 1e-9])
    write_transform_txt(tmp_path / "T.txt", T)
    np.testing.assert_array_equal(read_transform(tmp_path / "T.txt"), T)
    rows = (tmp_path / "T.txt").read_text().splitlines()
    assert len(rows) == 4 and all(len(r.split()) == 4 for r in rows)
    write_transform_json(tmp_path / "T.json", T, inliers=12, method="test")
    doc = json.loads((tmp_path / "T.json").read_text())
    assert doc["inliers"] == 12 and doc["method"] == "test"
    np.testing.assert_array_equal(read_transform(tmp_path / "T.json"), T)


# ----------------------------------------------------------------------------- bad input

HEADER = "2\n2\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
BAD_PTX = {
    "truncated": (HEADER + "1 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n", "only 3 lines follow"),
    "corrupt number": (HEADER + "1 2 3 0.5\n1 2 x 0.5\n1 2 3 0.5\n1 2 3 0.5\n", "line 12"),
    "nan coordinate": (HEADER + "1 2 3 0.5\nnan 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n", "line 12"),
    "inf coordinate": (HEADER + "1 2 3 0.5\n1 2 3 0.5\n1 inf 3 0.5\n1 2 3 0.5\n", "line 13"),
    "huge exponent": (HEADER + "1 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n1e999 2 3 0.5\n", "line 14"),
    "header/count mismatch": (
        HEADER + "1 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n1 2 3 0.5\n",
        "header",
    ),
    "ragged line": (HEADER + "1 2 3 0.5\n1 2 3\n1 2 3 0.5\n1 2 3 0.5\n", "line 12"),
    "bad header": ("2\n2\n0 0\n" + HEADER[6:], "malformed header"),
    "fractional size": ("2.5\n2\n" + HEADER[4:] + "1 2 3\n" * 5, "not valid"),
    "binary garbage": ("\x00\x01\x02garbage\n" * 20, "malformed header"),
}


@pytest.mark.parametrize("case", sorted(BAD_PTX))
def test_bad_ptx_raises_input_error(tmp_path, case):
    text, fragment = BAD_PTX[case]
    p = tmp_path / "bad.ptx"
    p.write_text(text)
    with pytest.raises(InputError) as e:
        read_scans(p)
    assert str(p) in str(e.value) and fragment in str(e.value)


@pytest.mark.parametrize(
    "name, content, fragment",
    [
        ("empty.ptx", b"", "file is empty"),
        ("scan.xyzrgb", b"1 2 3\n", "unknown scan suffix"),
        ("bad.npz", b"not a zip", "not a readable NumPy file"),
        ("nan.npy", None, "NaN or Inf"),
        ("notpng.png", b"PNG? no", "not a readable PNG"),
    ],
)
def test_bad_files_raise_input_error(tmp_path, name, content, fragment):
    p = tmp_path / name
    if content is None:
        np.save(p, np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 1.0]]))
    else:
        p.write_bytes(content)
    with pytest.raises(InputError) as e:
        read_scan(p, camera=PinholeCamera(1, 1, 0, 0, 2, 2)) if name.endswith(
            ".png"
        ) else read_scan(p)
    assert str(p) in str(e.value) and fragment in str(e.value)


def test_missing_file_and_depth_without_camera(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_scan(tmp_path / "nope.ptx")
    cv2.imwrite(str(tmp_path / "d.png"), np.ones((4, 6), dtype=np.uint16))
    with pytest.raises(InputError, match="intrinsics"):
        read_scan(tmp_path / "d.png")
    with pytest.raises(InputError, match="6x4 but the intrinsics are for 640x480"):
        read_scan(tmp_path / "d.png", camera=PinholeCamera(500, 500, 320, 240, 640, 480))


def test_failed_write_leaves_no_file(tmp_path):
    scan = Scan(points=np.ones((3, 3)))
    with pytest.raises(InputError):
        write_scan(tmp_path / "out.ptx", scan, decimals=99)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="cannot write"):
        write_scan(tmp_path / "out.xyz", scan)
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- more real data


def test_ouster_destaggered_frames(shared_data):
    path = shared_data / "lidar_ouster_os1_128_3scans" / "derived_destaggered_3scans.npz"
    scans = read_scans(path)
    with np.load(path) as z:
        xyz = z["xyz_m"]
    assert len(scans) == 3
    for i, s in enumerate(scans):
        assert s.grid_shape == (128, 1024) and s.intensity is not None
        valid = np.any(xyz[i] != 0, axis=2)
        assert len(s) == int(valid.sum())  # (0, 0, 0) no-returns are not points
        np.testing.assert_array_equal(s.points, xyz[i][valid])


def test_bunny_grids_and_ground_truth(shared_data):
    from scipy.spatial import cKDTree

    a, b = read_scans(shared_data / "bunny_range_scans_gt" / "derived_bunny_grids_and_gt.npz")
    assert (a.name, a.grid_shape, len(a)) == ("bun000", (400, 512), 40256)
    assert (b.name, b.grid_shape, len(b)) == ("bun045", (400, 512), 40097)
    # the poses put bun045 onto bun000 (README: 91 % of points within 1 mm)
    d, _ = cKDTree(a.points_world()).query(b.points_world())
    assert np.mean(d < 0.001) > 0.85


def test_7scenes_depth_frames(shared_data):
    folder = shared_data / "rgbd_7scenes_redkitchen"
    K = np.loadtxt(folder / "camera-intrinsics.txt")
    cam = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], 640, 480)
    png = sorted(folder.glob("frame-*.depth.png"))[0]
    raw = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    s = read_scan(png, camera=cam, depth_scale=0.001, invalid_values=(65535,))
    valid = (raw > 0) & (raw < 65535)
    assert s.grid_shape == (480, 640) and len(s) == int(valid.sum())
    np.testing.assert_allclose(np.sort(s.points[:, 2]), np.sort(raw[valid] / 1000.0))
    assert 0.3 < np.median(s.points[:, 2]) < 4.0  # a kitchen seen from arm's length


def test_an_intensity_beyond_float32_is_refused(tmp_path):
    """1e39 does not fit the float32 intensities (it would read as inf): one error line."""
    from flexreg.errors import InputError
    from flexreg.io import ptx

    text = (
        "2\n2\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0.5 -1 2 1\n"
        "1 2 3 1e39\n0 0 0 0\n-1 2.5 3 0.25\n4 -5 6e-1 1\n"
    )
    (tmp_path / "big.ptx").write_text(text)
    with pytest.raises(InputError, match="intensity beyond float32"):
        ptx.read(tmp_path / "big.ptx")
