"""Depth-sequence odometry: both pose solvers recover known motions, the chain reproduces a known
trajectory, unsolvable pairs are reported and bridged (never identity), runs are deterministic,
and whole sequences (synthetic and the real 7-Scenes frames) are tracked within tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import room_walk

from flexreg.core.camera import PinholeCamera
from flexreg.core.transforms import (
    apply,
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    scale_motion,
    translation_error_m,
)
from flexreg.errors import ConfigError, RegistrationError
from flexreg.io.sequence import read_sequence
from flexreg.odometry import (
    FrameFeatures,
    OdometryConfig,
    ate,
    essential_pose,
    feature_image,
    odometry,
    svd_pose,
    track,
)
from flexreg.stages.keypoints import Features

CAM = PinholeCamera(500.0, 500.0, 319.5, 239.5, 640, 480)


def _motion(deg: float, axis, t) -> np.ndarray:
    return make_transform(rotation_about_axis(axis, math.radians(deg)), t)


def _world_points(rng: np.random.Generator, n: int = 300) -> np.ndarray:
    """Points 2-6 m in front of a camera at the origin looking along +z."""
    z = rng.uniform(2.0, 6.0, n)
    x = rng.uniform(-0.5, 0.5, n) * z
    y = rng.uniform(-0.4, 0.4, n) * z
    return np.column_stack([x, y, z])


def _frame(index: int, world: np.ndarray, desc: np.ndarray, T_world_cam: np.ndarray):
    """FrameFeatures of a camera at ``T_world_cam`` seeing ``world`` (same descriptor per
    world point in every frame, so matching is exact)."""
    P = apply(invert(T_world_cam), world)
    u, v, _ = CAM.project(P)
    inside = (P[:, 2] > 0.1) & (u >= 0) & (u < CAM.width) & (v >= 0) & (v < CAM.height)
    k = np.flatnonzero(inside)
    feats = Features(
        xy=np.column_stack([u[k], v[k]]),
        descriptors=desc[k],
        response=np.ones(len(k), np.float32),
        size=np.full(len(k), 7.0, np.float32),
        angle=np.zeros(len(k), np.float32),
        method="orb",
    )
    return FrameFeatures(index=index, features=feats, xyz=P[k], camera=CAM)


def _empty_frame(index: int) -> FrameFeatures:
    feats = Features(
        xy=np.zeros((0, 2)),
        descriptors=np.zeros((0, 32), np.uint8),
        response=np.zeros(0, np.float32),
        size=np.zeros(0, np.float32),
        angle=np.zeros(0, np.float32),
        method="orb",
    )
    return FrameFeatures(index=index, features=feats, xyz=np.zeros((0, 3)), camera=CAM)


@pytest.fixture()
def scene(rng):
    """World points, unique binary descriptors, and a camera path: a forward walk with a slow
    turn, 8 frames at 30 Hz."""
    world = _world_points(rng, 400)
    desc = rng.integers(0, 256, size=(len(world), 32), dtype=np.uint8)
    step = _motion(0.8, [0.1, 1.0, 0.05], [0.02, -0.005, 0.06])
    poses = [np.eye(4)]
    for _ in range(7):
        poses.append(poses[-1] @ step)
    stamps = np.arange(8) / 30.0
    return world, desc, poses, stamps


# ------------------------------------------------------------------------------ solvers


def test_essential_pose_recovers_metric_motion(rng):
    world = _world_points(rng)
    T_true = _motion(2.0, [0.2, 1.0, -0.1], [0.10, 0.02, 0.05])  # T_target_source
    src = apply(invert(T_true), world)  # source camera sees the points here
    ut, vt, _ = CAM.project(world)
    us, vs, _ = CAM.project(src)
    T, inl = essential_pose(np.column_stack([ut, vt]), np.column_stack([us, vs]), world, src, CAM)
    assert inl.all()
    assert rotation_error_deg(T, T_true) < 1e-3
    assert translation_error_m(T, T_true) < 1e-5  # metric, from the depth of the inliers


def test_essential_pose_survives_outliers_and_reports_too_few(rng):
    world = _world_points(rng)
    T_true = _motion(-1.5, [0.0, 1.0, 0.0], [-0.08, 0.0, 0.12])
    src = apply(invert(T_true), world)
    xt = np.column_stack(CAM.project(world)[:2])
    xs = np.column_stack(CAM.project(src)[:2])
    bad = rng.choice(len(world), 60, replace=False)  # 20 % wrong matches
    xs[bad] = rng.uniform([0, 0], [640, 480], size=(60, 2))
    T, inl = essential_pose(xt, xs, world, src, CAM)
    assert rotation_error_deg(T, T_true) < 0.01 and translation_error_m(T, T_true) < 1e-3
    assert not inl[bad].any() or inl[bad].mean() < 0.05
    with pytest.raises(RegistrationError, match="matches, need at least"):
        essential_pose(xt[:6], xs[:6], world[:6], src[:6], CAM)
    no_depth = np.full_like(src, np.nan)
    with pytest.raises(RegistrationError, match="metric scale undetermined"):
        essential_pose(xt, xs, world, no_depth, CAM)


def test_svd_pose_with_outliers(rng):
    world = _world_points(rng)
    T_true = _motion(3.0, [1.0, 0.2, 0.0], [0.05, -0.03, 0.2])
    src = apply(invert(T_true), world) + rng.normal(0, 0.002, world.shape)
    tgt = world.copy()
    bad = rng.choice(len(world), 90, replace=False)
    tgt[bad] += rng.uniform(-1, 1, (90, 3))
    src[:5] = np.nan  # keypoints without depth are skipped
    T, inl, thr = svd_pose(tgt, src, rng=0)
    ranges = np.linalg.norm(src[5:], axis=1)
    assert thr == pytest.approx(max(0.01, 0.015 * np.median(ranges)))
    assert rotation_error_deg(T, T_true) < 0.1 and translation_error_m(T, T_true) < 0.005
    assert not inl[:5].any() and inl.sum() > 0.9 * (len(world) - 95)
    T2, _, _ = svd_pose(tgt, src, rng=0)
    np.testing.assert_array_equal(T, T2)  # same seed, same answer
    with pytest.raises(RegistrationError, match="depth in both frames"):
        svd_pose(tgt[:5], src[:5])


def test_scale_motion_is_constant_velocity():
    V = _motion(6.0, [0, 0, 1], [0.3, 0.0, 0.0])
    half = scale_motion(V, 0.5)
    assert rotation_error_deg(half, np.eye(4)) == pytest.approx(3.0)
    np.testing.assert_allclose(half @ half, V, atol=1e-12)  # two half steps make one
    np.testing.assert_allclose(scale_motion(V, 1.0), V, atol=1e-12)
    np.testing.assert_allclose(scale_motion(V, 2.0), V @ V, atol=1e-12)
    np.testing.assert_allclose(scale_motion(V, 0.0), np.eye(4), atol=1e-12)
    pure = scale_motion(make_transform(np.eye(3), [0.3, 0.0, -0.1]), 0.5)
    np.testing.assert_allclose(pure[:3, 3], [0.15, 0.0, -0.05], atol=1e-12)


# ------------------------------------------------------------------------------ chaining


@pytest.mark.parametrize("method", ["svd", "essential"])
def test_track_reproduces_a_known_trajectory(scene, method):
    world, desc, poses, stamps = scene
    frames = [_frame(i, world, desc, T) for i, T in enumerate(poses)]
    res = track(frames, stamps, OdometryConfig(method=method))
    assert res.status == ("start",) + ("estimated",) * 7
    assert res.failures == [] and res.reference.tolist() == [-1, 0, 1, 2, 3, 4, 5, 6]
    # noise-free matches: SVD is exact; OpenCV's plain RANSAC (the paper's) keeps the first
    # minimal 5-point model that explains every match within 1 px, without a final
    # least-squares fit, so a step can be off by a few hundredths of a degree
    rot_tol, trans_tol = (1e-3, 1e-4) if method == "svd" else (0.1, 0.01)
    for est, true in zip(res.trajectory.poses, poses, strict=True):
        assert rotation_error_deg(est, true) < rot_tol
        assert translation_error_m(est, true) < trans_tol
    np.testing.assert_array_equal(res.trajectory.timestamps, stamps)


def test_unsolvable_frame_is_reported_and_bridged(scene, caplog):
    world, desc, poses, stamps = scene
    frames = [_frame(i, world, desc, T) for i, T in enumerate(poses)]
    frames[3] = _empty_frame(3)  # e.g. a blank depth image: nothing to match
    with caplog.at_level("WARNING", logger="flexreg.odometry.track"):
        res = track(frames, stamps, OdometryConfig(method="svd"))
    assert res.status[3] == "bridged" and res.reference[3] == -1
    (f,) = res.failures
    assert f.frame == 3 and f.tried == (2,) and "0 matches" in f.reasons[0]
    assert f.bridge == "constant velocity"
    assert "frame 3 could not be solved" in caplog.text
    # the bridge extrapolates the measured motion: here exactly the true pose
    assert translation_error_m(res.trajectory.poses[3], poses[3]) < 1e-4
    assert not np.allclose(res.trajectory.poses[3], res.trajectory.poses[2])  # not identity
    # frame 4 is matched against the last good frame (2), not the bridged one
    assert res.status[4] == "estimated" and res.reference[4] == 2
    assert translation_error_m(res.trajectory.poses[4], poses[4]) < 1e-4
    failed = res.failed_pairs
    assert [(a.target, a.source) for a in failed] == [(2, 3)]
    d = res.to_dict()
    assert d["bridged"] == 1 and d["failures"][0]["frame"] == 3


def test_bridge_scales_velocity_with_the_time_step(scene):
    world, desc, poses, _ = scene
    stamps = np.array([0.0, 0.1, 0.2, 0.4, 0.5])  # the third step is twice as long
    frames = [_frame(i, world, desc, T) for i, T in enumerate(poses[:5])]
    frames[3] = _empty_frame(3)
    res = track(frames, stamps, OdometryConfig(method="svd"))
    step = invert(poses[1]) @ poses[2]
    expected = poses[2] @ scale_motion(step, 2.0)
    assert translation_error_m(res.trajectory.poses[3], expected) < 1e-4


def test_first_pair_failing_is_zero_velocity_and_all_failing_raises(scene):
    world, desc, poses, stamps = scene
    frames = [_frame(i, world, desc, T) for i, T in enumerate(poses[:4])]
    frames[1] = _empty_frame(1)
    res = track(frames, stamps[:4], OdometryConfig(method="svd"))
    assert res.status[1] == "bridged"
    assert "zero velocity" in res.failures[0].bridge  # stated, not silent
    assert res.status[2] == "estimated" and res.reference[2] == 0
    blank = [_empty_frame(i) for i in range(4)]
    with pytest.raises(RegistrationError, match="none of the 3 frame pairs"):
        track(blank, stamps[:4], OdometryConfig(method="svd"))


def test_config_is_validated():
    for bad in (
        {"image": "depth"},
        {"n": 4},
        {"method": "pnp"},
        {"features": "fast"},
        {"ratio": 0.0},
        {"min_inliers": 2},
        {"median": 7},
        {"threshold_m": -1.0},
    ):
        with pytest.raises(ConfigError):
            OdometryConfig(**bad)


def test_feature_image_is_the_paper_8bit_mapping():
    """A plane facing the camera has Flexion 1 (-> 255); the colour path passes grey through."""
    from flexreg.core.range_image import from_depth

    cam = PinholeCamera(100.0, 100.0, 15.5, 11.5, 32, 24)
    img = from_depth(np.full((24, 32), 2.0), cam)
    g, valid = feature_image(img, OdometryConfig(image="flexion", n=3, median=0))
    assert g.dtype == np.uint8 and valid[5:-5, 5:-5].all()
    assert (g[valid] == 255).all() and (g[~valid] == 0).all()
    grey = np.arange(24 * 32, dtype=np.uint8).reshape(24, 32)
    g2, v2 = feature_image(img, OdometryConfig(image="color"), color=grey)
    assert g2 is grey and v2.all()
    with pytest.raises(Exception, match="colour"):
        feature_image(img, OdometryConfig(image="color"))


# ------------------------------------------------------------------------------ sequences


@pytest.fixture(scope="module")
def synth_sequence(tmp_path_factory):
    """A rendered TUM-style RGB-D sequence: 8 frames of 320 x 240 in a procedural room."""
    from flexreg.synth import RGBDConfig, make_scene, write_tum_sequence

    folder = tmp_path_factory.mktemp("rgbd")
    cfg = RGBDConfig(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)
    write_tum_sequence(folder, make_scene("room", 3), room_walk(8), config=cfg, rng=0)
    return folder


def test_synthetic_sequence_is_tracked_and_deterministic(synth_sequence):
    seq = read_sequence(synth_sequence)
    cfg = OdometryConfig(image="flexion", n=5, features="akaze", method="svd", seed=4)
    res = odometry(seq, cfg)
    assert res.n_estimated == 7 and not res.failures
    err = ate(seq.groundtruth, res.trajectory)
    assert err.rmse_m < 0.02  # 14 cm walk, 3D-3D on noisy synthetic depth
    again = odometry(seq, cfg)
    np.testing.assert_array_equal(again.trajectory.poses, res.trajectory.poses)
    assert set(res.timings_s) >= {"load", "image", "features", "match", "solve"}


def test_colour_needs_colour_and_essential_needs_pinhole(synth_sequence, tmp_path):
    seq = read_sequence(synth_sequence)
    res = odometry(seq, OdometryConfig(image="color", features="orb", method="svd"))
    # ORB keypoints are whole pixels (1 cm at the 2.5 m seen), chained over 7 steps: ~sqrt(7) cm
    assert ate(seq.groundtruth, res.trajectory).rmse_m < 0.03
    for f in ("rgb.txt",):
        (tmp_path / "d").mkdir()
        for p in synth_sequence.iterdir():
            if p.name != f:
                (tmp_path / "d" / p.name).symlink_to(p)
    no_colour = read_sequence(tmp_path / "d")
    with pytest.raises(ConfigError, match="no colour image"):
        odometry(no_colour, OdometryConfig(image="color"))


def test_real_7scenes_frames(shared_data):
    """The first 12 real Kinect frames of 7-Scenes redkitchen (camera moves ~5 cm): both
    solvers on Flexion 5x5 with AKAZE stay within 1 cm ATE of the KinectFusion poses."""
    seq = read_sequence(shared_data / "rgbd_7scenes_redkitchen", max_frames=12)
    for method, tol in (("svd", 0.005), ("essential", 0.01)):
        res = odometry(seq, OdometryConfig(image="flexion", n=5, features="akaze", method=method))
        assert res.n_estimated == 11, res.failures
        assert ate(seq.groundtruth, res.trajectory).rmse_m < tol, method


def test_folder_of_lidar_scans(tmp_path):
    """Spinning-lidar sweeps of `flexreg synth --lidar-frames` (0.5 m apart): read as a folder
    of scans with the sensor poses of its gt.json, tracked 3D-3D on panoramic Flexion images;
    the 2D-2D solver needs pinhole images and says so."""
    from flexreg.synth.config import SynthConfig
    from flexreg.synth.dataset import synthesize

    cfg = SynthConfig(
        scene="courtyard", stations=1, width=64, height=32, lidar_frames=4, format="npz", seed=1
    )
    synthesize(tmp_path, cfg)
    seq = read_sequence(tmp_path / "lidar")
    assert seq.kind == "scans" and seq.camera is None and len(seq.groundtruth) == 4
    res = odometry(seq, OdometryConfig(image="flexion", n=3, features="sift", method="svd"))
    assert res.n_estimated == 3
    assert ate(seq.groundtruth, res.trajectory).rmse_m < 0.05  # 1.5 m driven
    with pytest.raises(ConfigError, match="needs pinhole depth images"):
        odometry(seq, OdometryConfig(method="essential"))
