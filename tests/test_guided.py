"""Guided matching, the dense overlap check and the levelled-scanner (plan) prior of register().

Hand-made keypoints with hand-computed descriptor distances pin down match_guided; a sphere of
constant range gives exact overlap fractions; synthetic TLS station pairs with exact ground
truth check the whole chain.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage, from_depth, from_grid
from flexreg.core.scan import Scan
from flexreg.core.transforms import (
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import ConfigError, RegistrationError
from flexreg.registration import RegistrationConfig, register
from flexreg.stages.keypoints import Features
from flexreg.stages.matching import descriptor_distances, match_guided
from flexreg.stages.priors import upright_priors
from flexreg.stages.projection import range_image
from flexreg.stages.sampling import area_cell, area_sample, area_sample_image
from flexreg.stages.verification import (
    classify_points_at,
    measured_image,
    open_space_witnesses,
    overlap_score,
    range_slack,
)
from flexreg.synth import station_pair


def _features(descriptors, method: str = "sift") -> Features:
    dtype = np.uint8 if method in ("orb", "akaze", "brisk") else np.float32
    d = np.asarray(descriptors, dtype=dtype)
    k = len(d)
    return Features(
        xy=np.zeros((k, 2)),
        descriptors=d,
        response=np.ones(k, np.float32),
        size=np.ones(k, np.float32),
        angle=np.full(k, -1.0, np.float32),
        method=method,
    )


SHIFT = make_transform(np.eye(3), [1.0, 0.0, 0.0])  # source x + 1 = target x


# ---------------------------------------------------------------------------- descriptor distances


def test_descriptor_distances_l2_hand_computed():
    t = _features([[3.0, 4.0, 0.0], [1.0, 1.0, 1.0]])
    s = _features([[0.0, 0.0, 0.0], [1.0, 1.0, 3.0]])
    d = descriptor_distances(t, s, np.array([0, 1, 0, 1]), np.array([0, 1, 1, 0]))
    np.testing.assert_allclose(d, [5.0, 2.0, math.sqrt(4 + 9 + 9), math.sqrt(3)], rtol=1e-6)
    assert d.dtype == np.float64


def test_descriptor_distances_hamming_is_bit_count(rng):
    t = _features(rng.integers(0, 256, (40, 32)), "orb")
    s = _features(rng.integers(0, 256, (30, 32)), "orb")
    ti, si = rng.integers(0, 40, 200), rng.integers(0, 30, 200)
    d = descriptor_distances(t, s, ti, si)
    bits = np.unpackbits(t.descriptors[ti] ^ s.descriptors[si], axis=1).sum(axis=1)
    np.testing.assert_array_equal(d, bits)
    ref = [
        cv2.norm(t.descriptors[i], s.descriptors[j], cv2.NORM_HAMMING)
        for i, j in zip(ti, si, strict=True)
    ]
    np.testing.assert_array_equal(d, ref)
    # by hand: 0b00000111 vs 0 is 3 bits, 0xFF 0xFF vs 0 is 16
    a = _features([[7] + [0] * 31, [255, 255] + [0] * 30], "orb")
    z = _features([[0] * 32], "orb")
    np.testing.assert_array_equal(
        descriptor_distances(a, z, np.array([0, 1]), np.array([0, 0])), [3, 16]
    )


# ---------------------------------------------------------------------------- match_guided


def test_guided_picks_nearest_descriptor_within_radius():
    # source 0 lands at (3, 0, 0) under SHIFT; two target candidates 5 cm away, one 0.5 m away
    txyz = np.array([[3.0, 0.05, 0.0], [3.0, -0.05, 0.0], [3.0, 0.0, 0.5]])
    sxyz = np.array([[2.0, 0.0, 0.0]])
    t = _features([[3.0, 0, 0, 0], [1.0, 0, 0, 0], [0.0, 0, 0, 0]])  # distances 3, 1, 0
    s = _features([[0.0, 0, 0, 0]])
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.2, ratio=0.9)
    assert pairs.dtype == np.int64
    np.testing.assert_array_equal(pairs, [[1, 0]])  # 1 < 0.9 * 3; target 2 is out of reach
    # a wider radius, or one growing with range (0.2 + 0.15 * 3 m), reaches the exact twin
    np.testing.assert_array_equal(match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.6), [[2, 0]])
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.2, radius_per_m=0.15)
    np.testing.assert_array_equal(pairs, [[2, 0]])
    # without the transform the prediction lands 1 m short: nothing in reach
    assert match_guided(t, s, txyz, sxyz, np.eye(4), radius_m=0.2).shape == (0, 2)


def test_guided_never_matches_outside_radius():
    txyz = np.array([[3.3, 0.0, 0.0]])  # 0.3 m from the prediction
    t, s = _features([[1.0, 2.0]]), _features([[1.0, 2.0]])  # identical descriptors
    sxyz = np.array([[2.0, 0.0, 0.0]])
    for r in (0.1, 0.2, 0.29):
        assert match_guided(t, s, txyz, sxyz, SHIFT, radius_m=r).shape == (0, 2)
    np.testing.assert_array_equal(match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.31), [[0, 0]])


def test_guided_ratio_test_rejects_near_ties():
    # source 0 has two candidates at descriptor distances 1.0 and 1.05; source 1 (at 6 m) has
    # a clear match, target 2
    txyz = np.array([[3.0, 0.05, 0.0], [3.0, -0.05, 0.0], [7.0, 0.0, 0.0]])
    sxyz = np.array([[2.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
    t = _features([[1.0, 0.0], [0.0, 1.05], [5.0, 5.0]])
    s = _features([[0.0, 0.0], [5.0, 5.0]])
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, ratio=0.9)
    np.testing.assert_array_equal(pairs, [[2, 1]])  # 1.0 >= 0.9 * 1.05
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, ratio=0.96)
    np.testing.assert_array_equal(pairs, [[0, 0], [2, 1]])  # 1.0 < 0.96 * 1.05
    np.testing.assert_array_equal(match_guided(t, s, txyz, sxyz, SHIFT, ratio=1.0), pairs)
    # a single candidate passes whatever its distance
    far = _features([[100.0, 0.0]])
    np.testing.assert_array_equal(match_guided(far, s, txyz[:1], sxyz, SHIFT, ratio=0.5), [[0, 0]])


def test_guided_all_rejected_gives_no_matches():
    txyz = np.array([[3.0, 0.05, 0.0], [3.0, -0.05, 0.0]])
    sxyz = np.array([[2.0, 0.0, 0.0]])
    t = _features([[1.0, 0.0], [0.0, 1.05]])
    s = _features([[0.0, 0.0]])
    assert match_guided(t, s, txyz, sxyz, SHIFT, ratio=0.9).shape == (0, 2)


def test_guided_nan_points_never_match():
    nan = [np.nan] * 3
    txyz = np.array([[3.0, 0.0, 0.0], nan, [7.0, 0.0, 0.0]])
    sxyz = np.array([nan, [2.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
    # source 0: unliftable; source 1: its only twin (target 1) is unliftable, target 0 is the
    # one candidate; source 2 meets target 2
    t = _features([[5.0, 5.0], [0.0, 0.0], [9.0, 9.0]])
    s = _features([[5.0, 5.0], [0.0, 0.0], [9.0, 9.0]])
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.5)
    np.testing.assert_array_equal(pairs, [[0, 1], [2, 2]])
    assert match_guided(t, s, np.full((3, 3), np.nan), sxyz, SHIFT).shape == (0, 2)
    assert match_guided(t, s, txyz, np.full((3, 3), np.nan), SHIFT).shape == (0, 2)


def test_guided_each_target_used_once():
    # sources 0, 1 and 2 all predict target 0 (their only candidate); source 1's descriptor is
    # nearest, so it keeps target 0 and the others go without; source 3 meets target 1
    txyz = np.array([[3.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    sxyz = np.array([[2.0, 0.1, 0.0], [2.0, -0.1, 0.0], [2.0, 0.0, 0.1], [4.0, 0.0, 0.0]])
    t = _features([[0.0, 0.0], [4.0, 4.0]])
    s = _features([[2.0, 0.0], [0.0, 1.0], [0.0, 3.0], [4.0, 4.5]])
    pairs = match_guided(t, s, txyz, sxyz, SHIFT, radius_m=0.2)
    np.testing.assert_array_equal(pairs, [[0, 1], [1, 3]])  # sorted by source index
    assert len(np.unique(pairs[:, 0])) == len(pairs)


def test_guided_binary_descriptors_use_hamming():
    txyz = np.array([[3.0, 0.05, 0.0], [3.0, -0.05, 0.0], [7.0, 0.0, 0.0]])
    sxyz = np.array([[2.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
    ones = [255] * 32
    # source 0 sees targets 0 and 1 at 16 and 3 bits; source 1 its twin, target 2
    t = _features([[255, 255] + [0] * 30, [7] + [0] * 31, ones], "orb")
    s = _features([[0] * 32, ones], "orb")
    np.testing.assert_array_equal(match_guided(t, s, txyz, sxyz, SHIFT), [[1, 0], [2, 1]])
    t2 = _features([[15] + [0] * 31, [7] + [0] * 31, ones], "orb")  # 4 and 3 bits
    pairs = match_guided(t2, s, txyz, sxyz, SHIFT, ratio=0.7)
    np.testing.assert_array_equal(pairs, [[2, 1]])  # 3 >= 0.7 * 4
    pairs = match_guided(t2, s, txyz, sxyz, SHIFT, ratio=0.8)
    np.testing.assert_array_equal(pairs, [[1, 0], [2, 1]])  # 3 < 0.8 * 4


# ---------------------------------------------------------------------------- overlap, slack


@pytest.fixture(scope="module")
def sphere_cam():
    return SphericalCamera.from_reference(72, 36, 0.0, math.pi)


def _sphere(cam: SphericalCamera, r: float) -> RangeImage:
    return from_depth(np.full(cam.shape, r), cam)


def test_overlap_identical_images_identity(sphere_cam):
    img = _sphere(sphere_cam, 5.0)
    assert overlap_score(img, img, np.eye(4)) == (1.0, 0.0)
    assert overlap_score(img, img, np.eye(4), samples=100) == (1.0, 0.0)


def test_overlap_source_in_front_conflicts(sphere_cam):
    target = _sphere(sphere_cam, 5.0)
    # every source point 1 m in front of what the target saw: tolerance 0.05 + 1% of 4 m
    assert overlap_score(target, _sphere(sphere_cam, 4.0), np.eye(4)) == (0.0, 1.0)
    # 4 cm off either way is within tolerance (0.05 m + 1% of the source point's range)
    assert overlap_score(target, _sphere(sphere_cam, 4.96), np.eye(4)) == (1.0, 0.0)
    assert overlap_score(target, _sphere(sphere_cam, 5.04), np.eye(4)) == (1.0, 0.0)
    # tolerances are knobs: 1 m is within 0.65 m + 10% of 4 m
    assert overlap_score(
        target, _sphere(sphere_cam, 4.0), np.eye(4), tolerance_m=0.65, tolerance_rel=0.1
    ) == (1.0, 0.0)
    # and so is a per-pixel slack of 1 m
    slack = np.full(sphere_cam.shape, 1.0, np.float32)
    assert overlap_score(target, _sphere(sphere_cam, 4.0), np.eye(4), slack=slack) == (1.0, 0.0)


def test_overlap_source_behind_is_occluded(sphere_cam):
    target = _sphere(sphere_cam, 5.0)
    # behind the target's surfaces: the target could not have seen it, no evidence either way
    assert overlap_score(target, _sphere(sphere_cam, 6.0), np.eye(4)) == (0.0, 0.0)


def test_overlap_transform_moves_source():
    # ranges 5, 5.5, 6 m repeating over the columns; the source scanner is turned one column
    # (5 degrees) further, so p_target = Rz(+5 deg) p_source
    cam = SphericalCamera(72, 36, -math.pi, math.pi, 0.2, math.pi - 0.2)
    r = np.tile(5.0 + 0.5 * (np.arange(72) % 3), (36, 1))
    target, source = from_depth(r, cam), from_depth(np.roll(r, -1, axis=1), cam)
    no_slack = np.zeros(cam.shape, np.float32)

    def yaw(k):
        return make_transform(rotation_about_axis([0.0, 0.0, 1.0], k * cam.dphi), [0, 0, 0])

    def score(T, sampling="pixels"):
        return overlap_score(target, source, T, slack=no_slack, sampling=sampling)

    assert score(yaw(1)) == score(yaw(1), "area") == (1.0, 0.0)
    # identity: 6 m lands on 5 m (conflict) in one column of three, behind in the other two
    assert score(yaw(0)) == (0.0, pytest.approx(1 / 3))
    assert score(yaw(-1)) == (0.0, pytest.approx(2 / 3))
    # a translation puts one side of a sphere in front (conflict), the other behind (occluded)
    sphere = _sphere(SphericalCamera.from_reference(72, 36, 0.0, math.pi), 5.0)
    ok, bad = overlap_score(sphere, sphere, SHIFT)
    assert ok < 0.2 and 0.3 < bad < 0.7


def test_overlap_without_camera_uses_nearest_neighbours():
    cam = PinholeCamera(20.0, 20.0, 9.5, 9.5, 20, 20)
    xyz = from_depth(np.full(cam.shape, 2.0), cam).xyz
    img = from_grid(Scan.from_organized(xyz))  # native grid, no camera model
    assert img.camera is None
    assert overlap_score(img, img, np.eye(4)) == (1.0, 0.0)
    moved = make_transform(np.eye(3), [0.0, 0.0, 1.0])
    assert overlap_score(img, img, moved) == (0.0, 0.0)  # far, but never a conflict


def test_range_slack_hand_computed():
    depth = np.array([[1.0, 1.0, 2.0], [1.0, 1.5, np.nan], [1.0, 1.0, 1.0]])
    img = from_depth(depth, PinholeCamera(10.0, 10.0, 1.0, 1.0, 3, 3), depth_kind="z")
    s = range_slack(img)
    assert s.dtype == np.float32 and s.shape == (3, 3)
    # largest |depth change| to the 4 neighbours, unknown neighbours ignored, 0 if none known
    np.testing.assert_array_equal(s, [[0.0, 1.0, 1.0], [0.5, 0.5, 0.0], [0.0, 0.5, 0.0]])


def test_range_slack_uses_range_on_panoramas(sphere_cam):
    r = np.full(sphere_cam.shape, 5.0)
    r[10, 20] = 7.0
    s = range_slack(from_depth(r, sphere_cam))
    expect = np.zeros(sphere_cam.shape)
    expect[10, 20] = expect[9, 20] = expect[11, 20] = expect[10, 19] = expect[10, 21] = 2.0
    np.testing.assert_allclose(s, expect, atol=1e-5)


def test_range_slack_wraps_on_full_turn(sphere_cam):
    r = np.full(sphere_cam.shape, 5.0)
    r[:, 0] = 6.0
    s = range_slack(from_depth(r, sphere_cam))
    np.testing.assert_allclose(s[1:-1, -1], 1.0, atol=1e-5)


def test_open_space_witnesses_hand_computed():
    depth = np.array([[1.0, 1.0, 2.0, 1.0], [1.0, 1.5, np.nan, 1.0], [1.0, 1.0, 1.0, 1.0]])
    img = from_depth(depth, PinholeCamera(10.0, 10.0, 1.5, 1.0, 4, 3), depth_kind="z")
    w = open_space_witnesses(measured_image(img), img.wraps)
    # measured, and each of its (existing) 4 neighbours measured: not beside the hole
    expect = [[1, 1, 0, 1], [1, 0, 0, 0], [1, 1, 0, 1]]
    np.testing.assert_array_equal(w, np.array(expect, dtype=bool))


def test_open_space_witnesses_wrap_on_full_turn(sphere_cam):
    r = np.full(sphere_cam.shape, 5.0)
    r[:, 0] = np.nan
    w = open_space_witnesses(measured_image(from_depth(r, sphere_cam)), True)
    assert not w[:, 0].any() and not w[:, 1].any() and not w[:, -1].any()
    assert w[:, 2:-1].all()


def test_witnesses_judge_only_bounded_pixels(sphere_cam):
    r = np.full(sphere_cam.shape, 5.0)
    r[10, 30] = np.nan  # no return: its neighbours do not bound their footprints
    target = from_depth(r, sphere_cam)
    ref = measured_image(target)
    # beside the hole and far from it: a point 2 m in front of what the target measured, and
    # one on it
    u, v = np.array([31.0, 20.0, 31.0, 20.0]), np.array([10.0, 20.0, 10.0, 20.0])
    pts = sphere_cam.backproject(u, v, np.array([3.0, 3.0, 5.0, 5.0]))
    tol = [(0.05, 0.0)]
    ((ok, bad),) = classify_points_at(target, pts, np.eye(4), tol, ref=ref)
    assert bad.tolist() == [True, True, False, False]
    assert ok.tolist() == [False, False, True, True]
    w = open_space_witnesses(ref, target.wraps)
    ((ok, bad),) = classify_points_at(target, pts, np.eye(4), tol, ref=ref, witnesses=w)
    assert bad.tolist() == [False, True, False, False]
    assert ok.tolist() == [False, False, False, True]


def test_overlap_point_just_before_the_seam(sphere_cam):
    target = _sphere(sphere_cam, 5.0)
    p = sphere_cam.backproject(np.array([71.7]), np.array([18.0]), np.array([5.0]))
    src = RangeImage(
        xyz=p.reshape(1, 1, 3), valid=np.ones((1, 1), bool), index=np.zeros((1, 1), np.int64)
    )
    assert overlap_score(target, src, np.eye(4)) == (1.0, 0.0)


# ---------------------------------------------------------------------------- register


# seeds tried at 1024 x 512, refine=False: room 0-5 and courtyard 0-5 all registered within
# 0.32 deg / 3.1 cm; these two have wide margins and many keypoint inliers
SEEDS = {"room": 4, "courtyard": 5}
CONFIG = RegistrationConfig(refine=False)


@pytest.fixture(scope="module")
def registered():
    """``registered(kind)``: the station pair of that scene and its registration (cached)."""
    cache = {}

    def get(kind):
        if kind not in cache:
            pair = station_pair(kind, seed=SEEDS[kind], resolution=(1024, 512))
            cache[kind] = pair, register(pair.target, pair.source, CONFIG)
        return cache[kind]

    return get


@pytest.mark.parametrize("kind", sorted(SEEDS))
def test_register_plan_prior_recovers_truth(registered, kind):
    pair, r = registered(kind)
    gt = pair.T_target_source
    assert rotation_error_deg(r.T_coarse, gt) < 0.5
    assert translation_error_m(r.T_coarse, gt) < 0.05
    np.testing.assert_array_equal(r.T_target_source, r.T_coarse)  # no refinement asked
    assert r.to_dict()["prior"] == r.prior
    # the plan prior competed, and its best candidate is right to its stated accuracy (about a
    # plan cell and a degree); whether it or the descriptors' candidate wins when both end in
    # the same place is a near tie that another CPU's last bits may break either way
    assert "plan views" in r.timings_s
    ti, si = range_image(pair.target), range_image(pair.source)
    plans = upright_priors(
        ti, si, max_tilt_rad=CONFIG.prior.max_tilt_rad, plan_cell_m=CONFIG.prior.plan_cell_m
    )
    best = plans[0]  # best first
    assert rotation_error_deg(best, gt) < 1.0
    assert translation_error_m(best, gt) < CONFIG.prior.plan_cell_m


def test_register_is_deterministic(registered):
    pair, r = registered("room")
    again = register(pair.target, pair.source, CONFIG)
    assert np.array_equal(again.T_target_source, r.T_target_source)
    assert again.prior == r.prior and again.inliers == r.inliers


def test_register_without_upright_prior(registered):
    pair, _ = registered("room")
    cfg = RegistrationConfig(refine=False, upright="off")
    try:
        r = register(pair.target, pair.source, cfg)
    except RegistrationError as e:  # descriptors alone may not suffice: say how far it got
        assert any(ch.isdigit() for ch in str(e)), str(e)
        return
    assert "plan" not in r.prior and "plan views" not in r.timings_s


def test_area_sample_spreads_over_surface_area():
    rng = np.random.default_rng(0)
    # a dense 1 m x 1 m patch (10 000 points) and a sparse 10 m x 10 m wall (5 000 points)
    near = np.c_[rng.uniform(0, 1, (10000, 2)), np.zeros(10000)]
    far = np.c_[rng.uniform(0, 10, (5000, 2)), np.full(5000, 20.0)]
    pts = np.vstack([near, far])
    sample = area_sample(pts, 1000)
    assert 700 <= len(sample) <= 1400
    share_far = np.mean(sample[:, 2] > 10)
    assert share_far > 0.9  # 100 of 101 m^2, although a third of the points
    # a subset, in input order, and the same every time
    assert np.all(np.isin(sample[:, 0], pts[:, 0]))
    assert np.all(np.diff(np.flatnonzero(np.isin(pts[:, 0], sample[:, 0]))) > 0)
    np.testing.assert_array_equal(sample, area_sample(pts, 1000))
    assert len(area_sample(pts[:500], 1000)) == 500  # fewer points than wanted: all of them
    cell = area_cell(far, 1000)  # 100 m^2 in about 1000 cells: about 0.3 m
    assert 0.25 < cell < 0.4


def test_area_sample_is_the_first_point_of_each_occupied_cell():
    # against a plain dictionary of the voxels at the chosen cell size
    rng = np.random.default_rng(3)
    pts = np.vstack([rng.normal(0, 2, (20000, 3)), rng.uniform(-8, 8, (3000, 3))])
    cell = area_cell(pts, 2000)
    k = np.floor((pts - pts.min(axis=0)) / cell).astype(np.int64)
    first: dict[tuple[int, int, int], int] = {}
    for i, key in enumerate(map(tuple, k)):
        first.setdefault(key, i)
    np.testing.assert_array_equal(area_sample(pts, 2000), pts[sorted(first.values())])


def test_area_sample_of_an_image_is_that_of_its_valid_points():
    """``area_sample_image`` gives exactly ``area_sample(xyz[valid])`` (no copy of the points),
    for float32 and float64 images, thinned or not, and with fewer points than wanted."""
    rng = np.random.default_rng(5)
    xyz = rng.normal(0, 3, (120, 250, 3))
    valid = rng.random((120, 250)) > 0.3
    xyz[~valid] = np.nan
    for dtype in (np.float32, np.float64):
        x = xyz.astype(dtype)
        for n in (300, 2000, 10**6):
            np.testing.assert_array_equal(area_sample_image(x, valid, n), area_sample(x[valid], n))
    assert area_sample_image(xyz, np.zeros(valid.shape, bool), 100).shape == (0, 3)


def test_overlap_area_sampling_weights_surfaces_not_pixels():
    # the source's lower half sees a floor 1 m away, the upper half a ceiling 10 m away; the
    # target saw the floor where the source does, but the ceiling at 12 m: the source's
    # ceiling sits in the target's free space
    cam = SphericalCamera(72, 36, -math.pi, math.pi, 0.2, math.pi - 0.2)
    r_src = np.where(np.arange(36)[:, None] < 18, 10.0, 1.0) * np.ones((1, 72))
    r_tgt = np.where(r_src > 5, 12.0, r_src)
    target, source = from_depth(r_tgt, cam), from_depth(r_src, cam)
    zero = np.zeros(cam.shape, np.float32)
    by_pixels = overlap_score(target, source, np.eye(4), slack=zero, sampling="pixels")
    assert by_pixels == (0.5, 0.5)
    ok, bad = overlap_score(target, source, np.eye(4), slack=zero, samples=200)
    assert bad > 0.9 and ok < 0.1  # the far half holds nearly all of the surface area
    with pytest.raises(ConfigError, match="sampling"):
        overlap_score(target, source, np.eye(4), sampling="voxels")
