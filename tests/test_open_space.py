"""The dense check's open space with the sampled points' own range slack
(:func:`flexreg.stages.verification.own_slack`): hand-computed cases on a sphere of ranges."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.registration.check import TOLERANCE
from flexreg.stages.verification import (
    MAX_SLACK_PER_M,
    classify_points,
    measured_image,
    own_slack,
    range_slack,
)

CAM = SphericalCamera.from_reference(96, 48, 0.2, 2.9)
THR = 0.02


def _image(ranges):
    image = from_depth(np.asarray(ranges, dtype=np.float64), CAM)
    return image, range_slack(image), measured_image(image)


def _on_ray(image, row, col, r):
    """The point at range ``r`` on the ray of pixel (row, col)."""
    p = image.xyz[row, col].astype(np.float64)
    return p / np.linalg.norm(p) * r


def test_own_slack_is_the_pixels_slack_and_infinite_on_a_silhouette():
    """A wall at 5 m on the left half, 10 m on the right: a point inside either half has no
    slack of its own; one at the step (5 m to its neighbour, over 5 % of its range) is on its
    silhouette."""
    H, W = CAM.shape
    ranges = np.full((H, W), 10.0)
    ranges[:, : W // 2] = 5.0
    image, slack, _ = _image(ranges)
    pts = np.array([_on_ray(image, 24, 10, 5.0), _on_ray(image, 24, 70, 10.0)])
    edge = _on_ray(image, 24, W // 2 - 1, 5.0)
    own = own_slack(image, slack, np.vstack([pts, edge]))
    assert own[0] == pytest.approx(0.0, abs=1e-5) and own[1] == pytest.approx(0.0, abs=1e-5)
    assert 5.0 > MAX_SLACK_PER_M * 5.0 and np.isinf(own[2])


@pytest.mark.parametrize(
    ("own", "conflicts"),
    [(None, True), (0.0, True), (0.3, True), (0.4, False), (np.inf, False)],
)
def test_a_point_in_front_conflicts_only_beyond_its_own_slack(own, conflicts):
    """The target saw 10 m on every ray; a source point at 9.5 m on one ray is 0.5 m in
    front. The free-space tolerance there is 2.5 x 2 cm + 1 % of 9.5 m = 0.145 m: in open
    space without its own slack, and still with 0.3 m of it (0.445 m), not with 0.4 m
    (0.545 m), never on its silhouette."""
    image, slack, measured = _image(np.full(CAM.shape, 10.0))
    p = _on_ray(image, 20, 30, 9.5)[None]
    tol, rel = TOLERANCE.free(THR)
    assert tol + rel * 9.5 == pytest.approx(0.145)
    own_arr = None if own is None else np.array([own])
    _, ok, bad = classify_points(image, p, np.eye(4), tol, rel, slack, measured, own_arr)
    assert not ok[0] and bool(bad[0]) is conflicts
