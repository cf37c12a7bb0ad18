"""Camera-lidar calibration: intrinsics/extrinsics readers, correspondence files, PnP accuracy on
a synthetic rig and on the real KITTI and PJLab sets, the result's conventions, the automatic
mode and the pictures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from flexreg import InputError, Scan, read_scan
from flexreg.calibration import (
    CalibrationConfig,
    CalibrationError,
    Correspondences2D3D,
    calibrate,
    calibrate_auto,
    check_correspondences,
    overlay_image,
    panorama_camera,
    picking_views,
    project_points,
    read_correspondences,
    render_flexion_view,
    reprojection_errors,
    scan_range_image,
    solve_pnp,
    usable_correspondences,
)
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import ConfigError
from flexreg.io.intrinsics import (
    CameraIntrinsics,
    read_extrinsic,
    read_intrinsics,
    read_kitti_calib,
)

# ------------------------------------------------------------------------------ fixtures


def ground_truth_pairs(
    points: np.ndarray,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: np.ndarray,
    n: int,
    rng: np.random.Generator,
    *,
    noise_px: float = 1.0,
    outliers: float = 0.0,
    visible: np.ndarray | None = None,
) -> tuple[Correspondences2D3D, np.ndarray]:
    """``n`` lidar points projected with the reference extrinsic plus Gaussian pixel noise;
    a fraction ``outliers`` of them get a random pixel instead. Returns the pairs and the
    outlier mask."""
    uv, z = project_points(points, intrinsics, T_camera_lidar)
    W, H = intrinsics.size
    ok = (z > 0.5) & (uv[:, 0] >= 3) & (uv[:, 0] <= W - 4) & (uv[:, 1] >= 3) & (uv[:, 1] <= H - 4)
    if visible is not None:
        ok &= visible
    sel = rng.choice(np.flatnonzero(ok), n, replace=False)
    px = uv[sel] + rng.normal(0.0, noise_px, (n, 2))
    bad = np.zeros(n, dtype=bool)
    bad[rng.choice(n, round(outliers * n), replace=False)] = True
    px[bad] = rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], (int(bad.sum()), 2))
    return Correspondences2D3D(px, points[sel]), bad


@pytest.fixture(scope="module")
def rig():
    """A spinning lidar (64 x 1024) in a synthetic room and a 1280 x 960 camera (f = 1050 px)
    mounted 33 cm away, turned 7 degrees off the lidar's axes; exact T_camera_lidar."""
    from flexreg.synth import (
        RGBDConfig,
        lidar_config,
        make_scene,
        place_stations,
        render_rgbd,
        scan_lidar,
    )

    scene = make_scene("room", 1)
    (T_world_lidar,) = place_stations(
        scene, 1, config=lidar_config(), rng=1, max_tilt_rad=math.radians(2.0)
    )
    axes = np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]).T  # camera x, y, z in lidar frame
    R = rotation_about_axis([0.3, 1.0, 0.2], math.radians(7.0)) @ axes
    T_lidar_camera = make_transform(R, [0.12, -0.25, -0.18])
    scan = scan_lidar(scene, T_world_lidar, rng=1)
    # depth at 640 x 480 for the visibility test, intrinsics of the same view at 2x
    frame = render_rgbd(scene, T_world_lidar @ T_lidar_camera, config=RGBDConfig(), rng=1)
    K = frame.camera.K.copy()
    K[:2] *= 2.0
    K[0, 2], K[1, 2] = (frame.camera.cx + 0.5) * 2 - 0.5, (frame.camera.cy + 0.5) * 2 - 0.5
    intr = CameraIntrinsics(K, np.zeros(0), 1280, 960, "synthetic camera")
    T = invert(T_lidar_camera)
    uv, z = project_points(scan.points, intr, T)
    iu = np.clip(np.rint((np.nan_to_num(uv) + 0.5) / 2 - 0.5).astype(int), 0, [639, 479])
    d = frame.depth[iu[:, 1], iu[:, 0]].astype(np.float64)
    with np.errstate(invalid="ignore"):
        visible = np.isfinite(d) & (np.abs(d - z) < 0.05 + 0.02 * z)
    return {"scan": scan, "intrinsics": intr, "T": T, "visible": visible, "frame": frame}


def _kitti(shared_data: Path):
    d = shared_data / "camlidar_kitti_object"
    image = cv2.imread(str(d / "image_2_000000.png"))
    intr, T = read_kitti_calib(d / "calib_000000.txt")
    return (
        image,
        intr.for_image(image.shape[1], image.shape[0]),
        T,
        read_scan(d / "velodyne_000000.bin"),
    )


def _pjlab(shared_data: Path):
    d = shared_data / "camlidar_pjlab"
    image = cv2.imread(str(d / "scene_a_calib.png"))
    intr = read_intrinsics(d / "scene_a_center_camera-intrinsic.json")
    T = read_extrinsic(d / "scene_a_top_center_lidar-to-center_camera-extrinsic.json")
    return (
        image,
        intr.for_image(image.shape[1], image.shape[0]),
        T,
        read_scan(d / "scene_a_calib.pcd"),
    )


# ------------------------------------------------------------------------------ intrinsics


def test_opencv_yaml_written_by_filestorage_reads_back(tmp_path):
    K = np.array([[812.5, 0.0, 640.2], [0.0, 810.0, 359.7], [0.0, 0.0, 1.0]])
    D = np.array([[-0.21, 0.05, 0.001, -0.002, 0.01]])
    fs = cv2.FileStorage(str(tmp_path / "cam.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 720)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D)
    fs.release()
    c = read_intrinsics(tmp_path / "cam.yaml")
    np.testing.assert_array_equal(c.K, K)
    np.testing.assert_array_equal(c.distortion, D.ravel())
    assert c.size == (1280, 720) and c.has_distortion


def test_ros_camera_info_yaml(tmp_path):
    (tmp_path / "ros.yaml").write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: cam\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n"
        "  data: [500.0, 0.0, 320.0, 0.0, 501.0, 240.0, 0.0, 0.0, 1.0]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, -0.2, 0.0, 0.0, 0.0]\n"
    )
    c = read_intrinsics(tmp_path / "ros.yaml")
    assert (c.fx, c.fy, c.K[0, 2], c.K[1, 2]) == (500.0, 501.0, 320.0, 240.0)
    assert c.distortion.tolist() == [0.1, -0.2, 0.0, 0.0, 0.0] and c.size == (640, 480)


def test_plain_json_round_trips_to_dict(tmp_path):
    c = CameraIntrinsics(
        np.array([[700.0, 0.0, 600.0], [0.0, 705.0, 180.0], [0.0, 0.0, 1.0]]),
        np.array([0.01, 0.02, 0.0, 0.0]),
        1224,
        370,
    )
    (tmp_path / "cam.json").write_text(json.dumps(c.to_dict()))
    back = read_intrinsics(tmp_path / "cam.json")
    np.testing.assert_array_equal(back.K, c.K)
    np.testing.assert_array_equal(back.distortion, c.distortion)
    assert back.size == (1224, 370)


def test_pjlab_intrinsic_json(shared_data):
    c = read_intrinsics(shared_data / "camlidar_pjlab" / "scene_a_center_camera-intrinsic.json")
    assert (c.fx, c.fy, c.K[0, 2], c.K[1, 2]) == (2117.31, 2113.29, 924.681, 656.457)
    assert c.distortion.tolist() == [-0.102933, -0.040925, 0.00057951, -0.00419933, 0.429959]
    assert c.size == (1920, 1200)


def test_kitti_calib_convention_matches_the_projection_matrices(shared_data):
    """pixel = P2 R0_rect Tr_velo_to_cam X (the KITTI README) equals K2 (T_cam2_velo X)."""
    path = shared_data / "camlidar_kitti_object" / "calib_000000.txt"
    intr, T = read_kitti_calib(path)
    f = {}
    for line in path.read_text().splitlines():
        key, _, rest = line.partition(":")
        f[key] = np.array(rest.split(), dtype=float)
    P2 = f["P2"].reshape(3, 4)
    R0 = np.eye(4)
    R0[:3, :3] = f["R0_rect"].reshape(3, 3)
    Tr = np.eye(4)
    Tr[:3] = f["Tr_velo_to_cam"].reshape(3, 4)
    X = np.array([[10.0, 2.0, -1.0, 1.0], [25.0, -6.0, 0.5, 1.0], [5.0, 1.0, -1.5, 1.0]])
    x = (P2 @ R0 @ Tr @ X.T).T
    expected = x[:, :2] / x[:, 2:]
    uv, _ = project_points(X[:, :3], intr.for_image(1224, 370), T)
    np.testing.assert_allclose(uv, expected, atol=1e-3)  # rotations re-orthonormalised (7 digits)
    np.testing.assert_array_equal(intr.K, P2[:, :3])
    assert intr.size is None and not intr.has_distortion
    # the image-2 camera sits about 6 cm to the side of the rectified reference camera 0
    np.testing.assert_allclose(np.linalg.solve(P2[:, :3], P2[:, 3])[0], 0.0599, atol=1e-3)
    np.testing.assert_allclose(read_extrinsic(path), T)


@pytest.mark.parametrize(
    ("K", "dist", "size", "message"),
    [
        ([[500, 0, 320], [0, -500, 240], [0, 0, 1]], [], (640, 480), "focal lengths"),
        ([[500, 0, 320], [0, 500, 240], [0, 0, 2]], [], (640, 480), "K must be"),
        ([[500, 0, 320], [0, 500, 240], [0, 0, 1]], [0.1, 0.2, 0.3], (640, 480), "3 distortion"),
        ([[500, 0, 900], [0, 500, 240], [0, 0, 1]], [], (640, 480), "outside the 640x480"),
        ([[500, 0, 320], [0, 500, 240], [0, 0, 1]], [], (0, 480), "positive integer"),
    ],
)
def test_invalid_intrinsics_are_rejected(K, dist, size, message):
    with pytest.raises(InputError, match=message):
        CameraIntrinsics(np.array(K, float), np.array(dist, float), *size, source="cam.yaml")


def test_intrinsics_checked_against_the_image_size():
    c = CameraIntrinsics(
        np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.zeros(0), 640, 480
    )
    assert c.for_image(640, 480) is c
    with pytest.raises(InputError, match=r"img.png: image is 1280x720 px but the intrinsics"):
        c.for_image(1280, 720, image="img.png")
    sized = CameraIntrinsics(c.K, c.distortion).for_image(1280, 720)  # file without a size
    assert sized.size == (1280, 720)


def test_unreadable_intrinsics_files(tmp_path):
    (tmp_path / "bad.yaml").write_text("camera_matrix: [1, 2\n  nonsense: :\n")
    with pytest.raises(InputError, match=r"bad\.yaml"):
        read_intrinsics(tmp_path / "bad.yaml")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match=r"bad.json: invalid JSON"):
        read_intrinsics(tmp_path / "bad.json")
    (tmp_path / "nok.json").write_text('{"width": 10}')
    with pytest.raises(InputError, match="no camera matrix"):
        read_intrinsics(tmp_path / "nok.json")
    (tmp_path / "cam.txt").write_text("P0: 1 2 3\n")
    with pytest.raises(InputError, match="no P2 projection matrix"):
        read_intrinsics(tmp_path / "cam.txt")
    with pytest.raises(InputError, match="unknown intrinsics suffix"):
        (tmp_path / "cam.ini").write_text("x")
        read_intrinsics(tmp_path / "cam.ini")


def test_extrinsic_formats(tmp_path, shared_data):
    T = make_transform(rotation_about_axis([1, 2, 3], 0.4), [0.1, -0.2, 0.3])
    np.savetxt(tmp_path / "T.txt", T)
    np.testing.assert_allclose(read_extrinsic(tmp_path / "T.txt"), T, atol=1e-12)
    np.savetxt(tmp_path / "T34.txt", T[:3])
    np.testing.assert_allclose(read_extrinsic(tmp_path / "T34.txt"), T, atol=1e-12)
    (tmp_path / "T.json").write_text(json.dumps({"T_camera_lidar": T.tolist()}))
    np.testing.assert_allclose(read_extrinsic(tmp_path / "T.json"), T, atol=1e-12)
    pj = read_extrinsic(
        shared_data / "camlidar_pjlab" / "scene_a_top_center_lidar-to-center_camera-extrinsic.json"
    )
    np.testing.assert_allclose(pj[:3, 3], [-0.0125114, -0.379526, -0.551037])
    np.testing.assert_allclose(pj[:3, :3] @ pj[:3, :3].T, np.eye(3), atol=1e-12)
    (tmp_path / "bad.json").write_text('{"T_camera_lidar": [[1, 0], [0, 1]]}')
    with pytest.raises(InputError, match="4x4"):
        read_extrinsic(tmp_path / "bad.json")


# ------------------------------------------------------------------------------ CSV


def test_csv_with_xyz_columns_any_order_and_comments(tmp_path):
    p = tmp_path / "pairs.csv"
    p.write_text(
        "# picked by hand\nX, Y ,Z,u,v,note\n\n1.5,2,3,10,20,a\n# skip\n-1,0.5,4,11.5,21,b\n"
    )
    c = read_correspondences(p)
    np.testing.assert_array_equal(c.pixels, [[10, 20], [11.5, 21]])
    np.testing.assert_array_equal(c.points, [[1.5, 2, 3], [-1, 0.5, 4]])
    assert c.lines.tolist() == [4, 6] and c.source == str(p)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("u,v,X,Y,Z\n1,2,3,4,5\n1,2,3,4\n", r"line 3: expected 5 values \(u,v,x,y,z\), got 4"),
        ("u,v,X,Y,Z\n1,2,3,4,5\n\n1,2,3,four,5\n", r"line 4: Y is not a number: 'four'"),
        ("u,v,X,Y,Z\n1,2,3,4,nan\n", r"line 2: Z is not finite"),
        ("u,v,X,Y\n1,2,3,4\n", r"header must be u,v,X,Y,Z or u,v,row,col"),
        ("u,v,X,Y,Z,row,col\n1,2,3,4,5,6,7\n", "not both"),
        ("# only a comment\n", "empty correspondence file"),
    ],
)
def test_malformed_csv_names_file_and_line(tmp_path, text, message):
    p = tmp_path / "pairs.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=message) as e:
        read_correspondences(p)
    assert str(e.value).startswith(str(p))


def test_row_col_pairs_lift_to_the_range_image_points(tmp_path):
    v, u = np.mgrid[0:20, 0:30].astype(float)
    xyz = np.stack([u * 0.1, v * 0.1, np.full_like(u, 5.0)], axis=-1)
    xyz[3:6, 3:6] = np.nan  # no returns (too large a gap to be filled)
    scan = Scan.from_organized(xyz)
    p = tmp_path / "pairs.csv"
    p.write_text("u,v,row,col\n100,200,2,7\n101,201,5.5,10.25\n")
    c = read_correspondences(p, scan=scan)
    np.testing.assert_allclose(c.points, [[0.7, 0.2, 5.0], [1.025, 0.55, 5.0]])
    p.write_text("u,v,row,col\n100,200,2,7\n100,200,4,4\n")
    with pytest.raises(InputError, match="line 3: range-image pixel row 4, col 4 has no lidar"):
        read_correspondences(p, scan=scan)
    p.write_text("u,v,row,col\n100,200,25,7\n")
    with pytest.raises(InputError, match="line 2: row 25, col 7 lies outside the scan's 30x20"):
        read_correspondences(p, scan=scan)
    with pytest.raises(InputError, match="need the scan"):
        read_correspondences(p)


# ------------------------------------------------------------------------------ checks


def _intr():
    return CameraIntrinsics(
        np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.zeros(0), 640, 480
    )


def test_checks_count_pixels_and_cheirality():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, 8), rng.uniform(-1, 1, 8), rng.uniform(4, 6, 8)])
    px = rng.uniform(0, 400, (8, 2))
    lines = np.arange(2, 10)
    check_correspondences(Correspondences2D3D(px, pts, lines, "p.csv"), _intr())
    with pytest.raises(InputError, match=r"p.csv: only 5 correspondence\(s\); .* at least 6"):
        check_correspondences(Correspondences2D3D(px[:5], pts[:5], lines[:5], "p.csv"), _intr())
    px2 = px.copy()
    px2[3] = [640.0, 10.0]
    with pytest.raises(InputError, match=r"line 5: pixel \(640, 10\) lies outside the 640x480"):
        check_correspondences(Correspondences2D3D(px2, pts, lines, "p.csv"), _intr())
    pts2 = pts.copy()
    pts2[6, 2] = -3.0
    with pytest.raises(InputError, match=r"line 8: lidar point .* behind the camera"):
        check_correspondences(
            Correspondences2D3D(px, pts2, lines, "p.csv"), _intr(), T_init=np.eye(4)
        )


def test_slips_are_left_out_and_named():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, 9), rng.uniform(-1, 1, 9), rng.uniform(4, 6, 9)])
    px = rng.uniform(0, 400, (9, 2))
    px[3] = [640.0, 10.0]
    pts[6, 2] = -3.0
    c = Correspondences2D3D(px, pts, np.arange(2, 11), "p.csv")
    kept, dropped = usable_correspondences(c, _intr(), T_camera_lidar=np.eye(4))
    assert kept.lines.tolist() == [2, 3, 4, 6, 7, 9, 10]
    assert [(d.where, d.line) for d in dropped] == [("line 5", 5), ("line 8", 8)]
    assert dropped[0].reason == "pixel (640, 10) outside the 640x480 image"
    assert dropped[1].reason == "behind the camera of the initial guess (z = -3.00 m)"
    kept, dropped = usable_correspondences(c, _intr())  # no pose: only the pixel is checked
    assert len(kept) == 8 and [d.line for d in dropped] == [5]
    assert usable_correspondences(kept.subset(np.arange(3)), _intr())[1] == ()


def test_solver_leaves_slips_out_but_keeps_six_usable():
    rng = np.random.default_rng(3)
    T = make_transform(rotation_about_axis([0.2, 1.0, 0.1], 0.1), [0.1, -0.05, 0.2])
    pts = np.column_stack(
        [rng.uniform(-2, 2, 12), rng.uniform(-1.5, 1.5, 12), rng.uniform(3, 8, 12)]
    )
    uv, _ = project_points(pts, _intr(), T)
    uv[2] = [700.0, 5.0]  # outside
    pts[5] = -pts[5]  # behind the camera under the solution
    c = Correspondences2D3D(uv, pts, np.arange(2, 14), "p.csv")
    res = solve_pnp(c, _intr())
    assert rotation_error_deg(res.T_camera_lidar, T) < 1e-6
    assert [(d.line, d.reason.split(" (")[0]) for d in res.dropped] == [
        (4, "pixel"),
        (7, "behind the camera of the solution"),
    ]
    assert len(res.correspondences) == 10 and res.inliers == 10
    assert res.to_dict()["dropped"][1]["line"] == 7
    with pytest.raises(InputError, match=r"only 5 usable correspondence\(s\) \(1 left out: line 4"):
        solve_pnp(c.subset(np.arange(6)), _intr())


# ------------------------------------------------------------------------------ solver


def test_exact_pairs_recover_the_pose_exactly():
    rng = np.random.default_rng(1)
    T = make_transform(rotation_about_axis([0.2, -1, 0.4], 0.3), [0.2, -0.1, 0.5])
    uv = rng.uniform([0, 0], [639, 479], (40, 2))
    rays = np.column_stack([(uv - [320, 240]) / 500.0, np.ones(40)])
    pts = apply(invert(T), rays * rng.uniform(3, 9, (40, 1)))  # lidar frame, in view
    r = solve_pnp(Correspondences2D3D(uv, pts), _intr())
    assert rotation_error_deg(r.T_camera_lidar, T) < 1e-6
    assert translation_error_m(r.T_camera_lidar, T) < 1e-8
    assert r.inliers == 40 and r.reprojection_rmse_px < 1e-6


def test_synthetic_rig_1px_noise_30pct_outliers(rig):
    """Acceptance: 200 pairs, 1 px noise, 30 % outliers -> within 0.1 deg and 1 cm."""
    for seed in range(4):
        rng = np.random.default_rng(seed)
        pairs, bad = ground_truth_pairs(
            rig["scan"].points,
            rig["intrinsics"],
            rig["T"],
            200,
            rng,
            outliers=0.3,
            visible=rig["visible"],
        )
        r = solve_pnp(pairs, rig["intrinsics"], config=CalibrationConfig(seed=seed))
        assert rotation_error_deg(r.T_camera_lidar, rig["T"]) < 0.1
        assert translation_error_m(r.T_camera_lidar, rig["T"]) < 0.01
        # the outliers are found (a random pixel may land near the truth by chance)
        assert np.count_nonzero(r.inlier_mask & bad) <= 2
        assert np.count_nonzero(r.inlier_mask & ~bad) >= 0.95 * np.count_nonzero(~bad)
        assert 0.8 < r.reprojection_rmse_px < 1.8  # 1 px per axis: sqrt(2) expected


def test_same_seed_same_result(rig):
    pairs, _ = ground_truth_pairs(
        rig["scan"].points, rig["intrinsics"], rig["T"], 60, np.random.default_rng(7), outliers=0.4
    )
    a = solve_pnp(pairs, rig["intrinsics"], config=CalibrationConfig(seed=3))
    b = solve_pnp(pairs, rig["intrinsics"], config=CalibrationConfig(seed=3))
    np.testing.assert_array_equal(a.T_camera_lidar, b.T_camera_lidar)
    np.testing.assert_array_equal(a.inlier_mask, b.inlier_mask)


@pytest.mark.parametrize("dataset", ["kitti", "pjlab"])
def test_real_reference_recovered_from_projected_pairs(shared_data, dataset):
    """Acceptance: reference projection + 1 px noise -> within 0.2 deg and 2 cm."""
    image, intr, T, scan = (_kitti if dataset == "kitti" else _pjlab)(shared_data)
    for seed in range(3):
        pairs, _ = ground_truth_pairs(scan.points, intr, T, 100, np.random.default_rng(seed))
        r = calibrate(image, scan, intr, pairs=pairs, config=CalibrationConfig(seed=seed))
        assert rotation_error_deg(r.T_camera_lidar, T) < 0.2
        assert translation_error_m(r.T_camera_lidar, T) < 0.02
        assert r.inliers >= 95


def test_too_few_consistent_pairs_raise():
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-3, 3, 12), rng.uniform(-2, 2, 12), rng.uniform(3, 9, 12)])
    px = rng.uniform(0, 480, (12, 2))  # no pose explains random pixels
    with pytest.raises(CalibrationError):
        solve_pnp(Correspondences2D3D(px, pts), _intr(), config=CalibrationConfig(threshold_px=1.0))


# ------------------------------------------------------------------------------ result


def test_result_conventions_and_dict(rig):
    pairs, _ = ground_truth_pairs(
        rig["scan"].points, rig["intrinsics"], rig["T"], 50, np.random.default_rng(3)
    )
    r = solve_pnp(pairs, rig["intrinsics"])
    T = r.T_camera_lidar
    np.testing.assert_allclose(r.T_lidar_camera @ T, np.eye(4), atol=1e-12)
    # T maps lidar points into the camera frame: the camera sees them in front
    assert (apply(T, pairs.points)[:, 2] > 0).all()
    q = r.quaternion_xyzw
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), T[:3, :3], atol=1e-12)
    np.testing.assert_array_equal(r.quaternion_wxyz, [q[3], q[0], q[1], q[2]])
    np.testing.assert_allclose(r.residuals_px, reprojection_errors(pairs, rig["intrinsics"], T))
    d = json.loads(json.dumps(r.to_dict()))
    assert d["rotation_camera_lidar"]["quaternion_xyzw"] == q.tolist()
    assert d["rotation_camera_lidar"]["quaternion_wxyz"] == r.quaternion_wxyz.tolist()
    np.testing.assert_allclose(d["camera_position_in_lidar_m"], [0.12, -0.25, -0.18], atol=0.01)
    assert d["inliers"] == r.inliers and len(d["pairs"]) == 50
    assert math.isclose(d["reprojection_rmse_px"], r.reprojection_rmse_px)
    assert d["config"]["threshold_px"] == 3.0 and d["seed"] == 0
    assert "CalibrationResult(pairs, " in repr(r)


def test_projection_with_distortion_matches_opencv():
    K = np.array([[800.0, 0.0, 640.0], [0.0, 790.0, 360.0], [0.0, 0.0, 1.0]])
    D = np.array([-0.3, 0.1, 0.001, -0.002, 0.0])
    intr = CameraIntrinsics(K, D, 1280, 720)
    T = make_transform(rotation_about_axis([0, 1, 0], 0.1), [0.1, 0.0, 0.2])
    P = np.array([[1.0, 0.5, 6.0], [-2.0, -1.0, 5.0], [0.0, 0.0, -4.0]])
    uv, z = project_points(P, intr, T)
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    ref, _ = cv2.projectPoints(P[:2], rvec, T[:3, 3], K, D)
    np.testing.assert_allclose(uv[:2], ref.reshape(-1, 2), atol=1e-9)
    assert np.isnan(uv[2]).all() and z[2] < 0


# ------------------------------------------------------------------------------ automatic


def test_automatic_mode_improves_a_perturbed_kitti_guess(shared_data):
    image, intr, T, scan = _kitti(shared_data)
    P = make_transform(
        rotation_about_axis([0.4, -0.8, 0.45], math.radians(2.0)), [0.06, -0.05, 0.06]
    )
    T0 = P @ T
    r = calibrate(image, scan, intr, T_init=T0, auto=True)
    assert r.method == "auto" and r.auto is not None
    assert r.auto["edge_score_final"] > r.auto["edge_score_init"]
    assert rotation_error_deg(r.T_camera_lidar, T) < 0.75 < rotation_error_deg(T0, T)
    assert r.inliers >= CalibrationConfig().min_inliers


def test_automatic_mode_refuses_an_image_without_structure(shared_data):
    _, intr, T, scan = _kitti(shared_data)
    noise = np.random.default_rng(0).integers(0, 256, (370, 1224, 3), dtype=np.uint8)
    with pytest.raises(CalibrationError, match="no pose better aligned than the initial guess"):
        calibrate_auto(noise, scan, intr, T)


def test_flexion_view_lifts_to_the_rendered_points(rig):
    view = render_flexion_view(rig["scan"], rig["intrinsics"], rig["T"], scale=0.25)
    assert view.flexion.shape == (240, 320) and view.valid.mean() > 0.5
    seen = view.index >= 0
    pts = rig["scan"].points[view.index[seen]]
    u, v, _ = view.camera.project(apply(rig["T"], pts))
    rows, cols = np.nonzero(seen)
    assert np.abs(u - cols).max() <= 0.5 + 1e-9 and np.abs(v - rows).max() <= 0.5 + 1e-9


def test_config_validation():
    with pytest.raises(ConfigError, match="threshold_px"):
        CalibrationConfig(threshold_px=0)
    with pytest.raises(ConfigError, match="patch_px"):
        CalibrationConfig(patch_px=20)
    with pytest.raises(ConfigError, match="seed"):
        CalibrationConfig(seed=-1)


# ------------------------------------------------------------------------------ pictures


def test_overlay_colours_points_where_they_project(rig):
    image = np.full((960, 1280, 3), 128, np.uint8)
    pts = np.array([[4.0, 0.0, 0.0], [4.0, 0.8, 0.3]])  # lidar frame, ahead of the camera
    out = overlay_image(image, pts, rig["intrinsics"], rig["T"], max_range_m=10.0)
    assert out.shape == image.shape and out.dtype == np.uint8
    uv, _ = project_points(pts, rig["intrinsics"], rig["T"])
    for x, y in np.rint(uv).astype(int):
        assert (out[y, x] != 128).any()
    untouched = np.all(out == 128, axis=2)
    assert untouched.mean() > 0.95  # only the dots and the colour bar


def test_picking_views_share_the_panorama_grid_with_the_csv(rig, tmp_path):
    image = np.full((960, 1280, 3), 90, np.uint8)
    views = picking_views(image, rig["scan"], intrinsics=rig["intrinsics"], T_init=rig["T"])
    assert set(views) == {"camera", "panorama", "flexion-view"}
    assert views["camera"].shape == views["flexion-view"].shape == (960, 1280, 3)
    ri = scan_range_image(rig["scan"])
    assert views["panorama"].shape[:2] == ri.shape
    # a gridded scan keeps its 64 x 1024 grid; row/col pick the point the panorama shows
    assert ri.shape == (64, 1024)
    r, c = np.argwhere(ri.index >= 0)[100]
    (tmp_path / "p.csv").write_text(f"u,v,row,col\n1,2,{r},{c}\n")
    lifted = read_correspondences(tmp_path / "p.csv", scan=rig["scan"]).points[0]
    np.testing.assert_allclose(lifted, rig["scan"].points[ri.index[r, c]])


def test_unstructured_lidar_panorama_has_lidar_pitch(rig):
    """The cloud of a 64 x 1024 lidar (0.35 deg azimuth, 0.625 deg rings) without its grid, and
    the same with the rings' elevations jittered (as a real multi-laser head's are).

    Tolerances come from the sensor, not from one machine's ray casting: the lidar fires 1024
    times a turn, so the panorama has exactly 1024 columns whatever number of rays the scene
    returns (which differs between CPUs); ray directions are float32 (1e-7 rad). A ring tilt of
    N(0, 0.1 deg) moves each of the 63 ring gaps by N(0, 0.14 deg); their median has a standard
    error of 1.25 * 0.14 / sqrt(63) = 0.022 deg, and the test allows four of them (0.09 deg).
    """
    cloud = Scan(points=rig["scan"].points)
    cam = panorama_camera(cloud.points)
    assert (cam.width, cam.height) == (1024, 64)
    assert cam.dphi == pytest.approx(2 * math.pi / 1024, rel=1e-9)
    assert cam.dtheta == pytest.approx(math.radians(40 / 64), abs=1e-6)  # 64 rows over 40 deg
    # ~2,400 rays fewer (as another CPU's ray caster returned): the same camera
    fewer = np.random.default_rng(1).random(len(cloud.points)) > 2400 / len(cloud.points)
    assert panorama_camera(cloud.points[fewer]) == cam
    rows = rig["scan"].grid_index[:, 0]
    tilt = np.random.default_rng(0).normal(0.0, math.radians(0.1), 64)[rows]
    P = rig["scan"].points
    r = np.linalg.norm(P, axis=1)
    theta = np.arccos(P[:, 2] / r) + tilt
    phi = np.arctan2(P[:, 1], P[:, 0])
    jittered = (
        np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        * r[:, None]
    )
    cam = panorama_camera(jittered)
    assert cam.width == 1024  # the tilt leaves the azimuths alone
    assert cam.dphi == pytest.approx(2 * math.pi / 1024, rel=1e-9)
    assert math.degrees(cam.dtheta) == pytest.approx(40 / 64, abs=0.09)
    ri = scan_range_image(Scan(points=jittered))
    assert ri.shape == (cam.height, cam.width)
    assert (ri.index[ri.valid] >= 0).all()  # every pixel shows a real return
    assert ri.valid.mean() > 0.8


# ------------------------------------------------------------------------------ verdict


def _hand_made(kind: str, seed: int = 0):
    """Hand-made pairs on the 640 x 480 camera (f = 500 px) with 1 px noise: camera-frame
    points of one kind mapped into a lidar frame, and the true T_camera_lidar."""
    rng = np.random.default_rng(seed)
    T = make_transform(rotation_about_axis([0.3, 1.0, -0.2], 0.4), [0.2, -0.1, 0.3])
    n = 7 if kind in ("few", "line") else 30
    if kind == "plane":  # one tilted wall 6 m away, 3 m x 2 m
        pc = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n), np.full(n, 6.0)])
        pc = pc @ rotation_about_axis([1, 0.3, 0], 0.3).T
    elif kind == "line":  # along one 3D line, exactly
        a, b = np.array([-2.0, 1.0, 5.0]), np.array([2.5, -0.5, 12.0])
        pc = a + np.linspace(0, 1, n)[:, None] * (b - a)
    else:
        lo, hi = ([5, 5], [100, 80]) if kind == "corner" else ([5, 5], [634, 474])
        uv = rng.uniform(lo, hi, (n, 2))
        pc = np.column_stack([(uv - [320, 240]) / 500, np.ones(n)]) * rng.uniform(3, 20, (n, 1))
    uv = pc[:, :2] / pc[:, 2:] * 500 + [320, 240] + rng.normal(0, 1, (n, 2))
    assert (uv >= 0).all() and (uv[:, 0] < 639).all() and (uv[:, 1] < 479).all()
    return Correspondences2D3D(uv, apply(invert(T), pc)), T


@pytest.mark.parametrize(
    ("kind", "codes"),
    [
        ("plane", {"coplanar_points"}),
        ("corner", {"clustered_pixels"}),
        ("few", {"few_inliers"}),
    ],
)
def test_near_degenerate_pairs_are_uncertain(kind, codes):
    pairs, _ = _hand_made(kind)
    r = solve_pnp(pairs, _intr())
    v = r.verdict
    assert v.status == "uncertain" and not v.confident
    assert codes <= {reason.code for reason in v.reasons}, v.reasons
    assert all(reason.message for reason in v.reasons)
    d = json.loads(json.dumps(r.to_dict()))["verdict"]
    assert d["status"] == "uncertain" and codes <= {x["code"] for x in d["reasons"]}
    assert d["evidence"]["inliers"] == r.inliers
    assert "uncertain" in repr(r)


def test_well_spread_pairs_are_confident():
    pairs, T = _hand_made("spread")
    r = solve_pnp(pairs, _intr())
    assert r.verdict.confident, r.verdict.reasons
    assert rotation_error_deg(r.T_camera_lidar, T) < 0.2
    e = r.verdict.evidence
    assert e["image_coverage"] > 0.5 and e["thickness_ratio"] > 0.05
    assert max(e["rotation_std_deg"].values()) < 0.5
    assert max(e["translation_std_m"].values()) < 0.05


def test_a_plane_far_away_lists_the_mirrored_pose():
    """A small wall far away: planar PnP's second pose fits almost as well and is listed."""
    rng = np.random.default_rng(4)
    T = make_transform(rotation_about_axis([0.3, 1.0, -0.2], 0.4), [0.2, -0.1, 0.3])
    pc = np.column_stack([rng.uniform(-1, 1, 20), rng.uniform(-0.7, 0.7, 20), np.full(20, 20.0)])
    pc = pc @ rotation_about_axis([1, 0.3, 0], 0.3).T
    uv = pc[:, :2] / pc[:, 2:] * 500 + [320, 240] + rng.normal(0, 1, (20, 2))
    r = solve_pnp(Correspondences2D3D(uv, apply(invert(T), pc)), _intr())
    assert r.verdict.status == "uncertain"
    assert "coplanar_points" in {x.code for x in r.verdict.reasons}
    (mirror,) = r.verdict.runner_up
    assert mirror.score_ratio > 0.5 and mirror.rotation_deg > 5
    assert "mirrored" in mirror.origin


def test_collinear_points_leave_the_pose_undetermined():
    pairs, _ = _hand_made("line")
    with pytest.raises(CalibrationError, match=r"lie on one line.*not determined"):
        solve_pnp(pairs, _intr())


def test_verdict_thresholds_are_validated():
    with pytest.raises(ConfigError, match="collinear_ratio"):
        CalibrationConfig(collinear_ratio=0.2)
    with pytest.raises(ConfigError, match="verdict_min_inliers"):
        CalibrationConfig(verdict_min_inliers=3)
    with pytest.raises(ConfigError, match="verdict_min_image_coverage"):
        CalibrationConfig(verdict_min_image_coverage=1.5)
    # stricter thresholds turn a confident set uncertain
    pairs, _ = _hand_made("spread")
    strict = CalibrationConfig(verdict_min_inliers=40)
    assert solve_pnp(pairs, _intr(), config=strict).verdict.status == "uncertain"


def test_a_kitti_calibration_with_a_number_that_is_not_finite_names_its_line(tmp_path):
    """Refused when read, before any product of the matrices (which would turn the infinity
    into NaN with a warning and fail later, less clearly)."""
    p = tmp_path / "calib.txt"
    p.write_text(
        "P2: 700 0 600 45 0 700 170 0 0 0 1 0\n"
        "R0_rect: 1 0 0 0 1 0 0 0 1\n"
        "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 inf 0\n"
    )
    with pytest.raises(InputError, match="line 3: Tr_velo_to_cam holds a number that is not "):
        read_kitti_calib(p)
    p.write_text(p.read_text().replace("inf", "0"))
    _, T = read_kitti_calib(p)
    assert np.isfinite(T).all()
