"""A surface is seen from its front: every dense check explains no point whose surface faces
away from the scanner it is checked against, and the quick ICP pairs no point with the other
face of a wall. Hand-built walls: a target scanner at the origin looking along +z at a wall
whose near face is at 3 m; points of that face, and points of the wall's far face (3.14 m,
normals pointing away from the target: what a scanner in the next room sees)."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import from_depth
from flexreg.errors import RegistrationError
from flexreg.registration.check import TOLERANCE, Check, check_masks
from flexreg.registration.fullres import full_masks, full_score, full_view
from flexreg.stages.normals import grid_normals
from flexreg.stages.refinement.projective import projective_icp
from flexreg.stages.sampling import area_sample_image, area_sample_pixels
from flexreg.stages.verification import (
    BACK_FACING_COS,
    back_facing,
    classify_points,
    classify_points_at,
    measured_image,
    range_slack,
    soft_score,
)

CAMERA = PinholeCamera(60.0, 60.0, 40.0, 30.0, 80, 60)
NEAR, FAR = 3.0, 3.14  # the wall's faces, metres


def _wall():
    """The target's view of the wall's near face (depth NEAR everywhere)."""
    image = from_depth(np.full(CAMERA.shape, NEAR), CAMERA)
    return image, measured_image(image), range_slack(image)


def _points(depth, n=200, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.0, 1.0, (n, 2))
    return np.column_stack([xy, np.full(n, depth)])


TOWARDS = np.array([0.0, 0.0, -1.0])  # the near face's normal: towards the target's scanner
AWAY = -TOWARDS


def test_back_facing_is_the_angle_past_grazing():
    q = np.array([[0.0, 0.0, 2.0]] * 5)
    c = np.array([0.5, 0.0, -0.19, -0.21, -1.0])  # cosines towards the scanner
    s = np.sqrt(1 - c**2)
    normals = np.column_stack([s, np.zeros(5), -c])  # n . (-q) / |q| = c
    assert back_facing(q, normals).tolist() == [False, False, False, True, True]
    assert BACK_FACING_COS == -0.2
    assert not back_facing(q[:1], np.full((1, 3), np.nan))[0]  # unknown: no test


def test_sampled_check_explains_only_surfaces_facing_the_scanner():
    image, ref, slack = _wall()
    p = _points(NEAR)
    tol, rel = TOLERANCE.fine(0.04)
    for normal, expected in ((TOWARDS, True), (AWAY, False)):
        normals = np.tile(normal, (len(p), 1)).astype(np.float32)
        _, ok, bad = classify_points(image, p, np.eye(4), tol, rel, slack, ref, normals)
        assert ok.all() == expected and ok.any() == expected
        assert not bad.any()  # on the surface: never in open space
        ((ok_at, bad_at),) = classify_points_at(
            image, p, np.eye(4), [(tol, rel)], slack, ref, normals
        )
        np.testing.assert_array_equal(ok_at, ok)
        np.testing.assert_array_equal(bad_at, bad)
        score, _, ok_s, _ = soft_score(image, p, np.eye(4), tol, rel, slack, ref, normals)
        np.testing.assert_array_equal(ok_s, ok)
        assert score == pytest.approx(1.0 if expected else 0.0)
        check = Check(image, ref, slack, p, normals)
        np.testing.assert_array_equal(check_masks(check, np.eye(4), 0.04)[0], ok)
    # without normals, as before: explained
    assert classify_points(image, p, np.eye(4), tol, rel, slack, ref)[1].all()


def test_a_turned_pose_turns_the_normals():
    """A half turn about the vertical maps the source's points and normals alike: a point of a
    surface facing the source's scanner from behind it faces the target's scanner."""
    image, ref, slack = _wall()
    T = np.diag([-1.0, 1.0, -1.0, 1.0])  # half turn about y
    p = _points(-NEAR)  # behind the source's scanner, at -3 m: at +3 m after the turn
    normals = np.tile([0.0, 0.0, 1.0], (len(p), 1))  # facing the source's scanner (towards -z)
    tol, rel = TOLERANCE.fine(0.04)
    assert classify_points(image, p, T, tol, rel, slack, ref, normals)[1].all()
    assert not classify_points(image, p, T, tol, rel, slack, ref, -normals)[1].any()


def test_full_resolution_check_explains_only_surfaces_facing_the_scanner():
    image, ref, slack = _wall()
    view = full_view(image, ref, slack)
    p = _points(NEAR).astype(np.float32)
    own = np.zeros(len(p), dtype=np.float32)
    for normal, expected in ((TOWARDS, True), (AWAY, False)):
        normals = np.tile(normal, (len(p), 1)).astype(np.float32)
        ok, bad = full_masks(view, p, own, np.eye(4), 0.04, normals)
        assert ok.all() == expected and ok.any() == expected
        assert not bad.any()
        score = full_score(view, p, own, np.eye(4), 0.04, normals=normals)
        assert score == pytest.approx(len(p) if expected else 0.0)
    nan = np.full((len(p), 3), np.nan, dtype=np.float32)
    assert full_masks(view, p, own, np.eye(4), 0.04, nan)[0].all()  # unknown normals: no test


def test_quick_icp_does_not_pull_a_wall_onto_its_other_face():
    """The far face, 14 cm behind the near one: point-to-plane ICP pulls it onto the near face
    (the wall's thickness off); with the points' normals no pair is made."""
    image, _, _ = _wall()
    normals = grid_normals(image)
    p = _points(FAR, n=500)
    slid = projective_icp(image, p, np.eye(4), max_distance_m=0.3, normals=normals)
    assert slid.T_target_source[2, 3] == pytest.approx(NEAR - FAR, abs=1e-6)
    away = np.tile(AWAY, (len(p), 1))
    with pytest.raises(RegistrationError, match="paired 0 points"):
        projective_icp(
            image, p, np.eye(4), max_distance_m=0.3, normals=normals, source_point_normals=away
        )
    same = projective_icp(
        image, p, np.eye(4), max_distance_m=0.3, normals=normals,
        source_point_normals=np.tile(TOWARDS, (len(p), 1)),
    )  # fmt: skip
    np.testing.assert_allclose(same.T_target_source, slid.T_target_source, atol=1e-9)


def test_area_sample_pixels_are_where_the_sample_comes_from():
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(40, 50, 3))
    valid = rng.random((40, 50)) < 0.8
    for samples in (100, 10_000):
        pts, pixels = area_sample_pixels(xyz, valid, samples)
        np.testing.assert_array_equal(pts, xyz.reshape(-1, 3)[pixels])
        assert valid.reshape(-1)[pixels].all()
        np.testing.assert_array_equal(pts, area_sample_image(xyz, valid, samples))
    assert len(area_sample_pixels(xyz, valid, 10_000)[0]) == valid.sum()
