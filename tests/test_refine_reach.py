"""The refinement's reach: from a doorway pair's coarse pose slid by the wall's thickness (its
far face laid on its near face), the refinement from two plan cells' reach, pairing only
surfaces seen from one side, finds the truth; a close pose comes out as without it. (On the
survey's doorway links the slid pose is a fixed point of pairs within three inlier thresholds:
docs/benchmarks.md; in this box of a scene the corners' pairs pull it back either way.)"""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.camera import SphericalCamera
from flexreg.core.range_image import from_depth
from flexreg.core.transforms import make_transform, rotation_error_deg, translation_error_m
from flexreg.stages.refinement import refine

WALL_M = 0.15  # the wall between the rooms, from x = 0 to x = 0.15
#: solid boxes (low corner, high corner; metres): floor, ceiling, outer walls, the wall
#: between the rooms with a doorway 1 m wide and 2.1 m high, a cabinet in each room
SOLIDS = [
    ((-6.2, -3.2, -0.2), (6.2, 3.2, 0.0)),
    ((-6.2, -3.2, 2.6), (6.2, 3.2, 2.8)),
    ((-6.2, -3.2, 0.0), (-6.0, 3.2, 2.6)),
    ((6.0, -3.2, 0.0), (6.2, 3.2, 2.6)),
    ((-6.2, -3.2, 0.0), (6.2, -3.0, 2.6)),
    ((-6.2, 3.0, 0.0), (6.2, 3.2, 2.6)),
    ((0.0, -3.0, 0.0), (WALL_M, -0.5, 2.6)),
    ((0.0, 0.5, 0.0), (WALL_M, 3.0, 2.6)),
    ((0.0, -0.5, 2.1), (WALL_M, 0.5, 2.6)),
    ((3.0, 1.0, 0.0), (3.6, 2.2, 1.0)),
    ((-4.0, -2.0, 0.0), (-3.2, -1.2, 1.3)),
]


def _scan(at: tuple[float, float, float], rng: np.random.Generator):
    """A panorama (512 x 256, 2 mm range noise) from ``at``: the nearest solid along each ray."""
    cam = SphericalCamera.from_reference(512, 256, 0.2, np.pi - 0.2)
    d = cam.rays().reshape(-1, 3)
    o = np.asarray(at, dtype=np.float64)
    best = np.full(len(d), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for lo, hi in SOLIDS:
            t1, t2 = (np.asarray(lo) - o) / d, (np.asarray(hi) - o) / d
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (near > 0) & (far >= near)
            best = np.where(hit & (near < best), near, best)
    best = np.where(np.isfinite(best), best + rng.normal(0, 0.002, len(best)), np.nan)
    return from_depth(best.reshape(cam.shape), cam)


@pytest.fixture(scope="module")
def doorway():
    rng = np.random.default_rng(3)
    a, b = (-2.5, 0.3, 1.5), (2.4, -0.2, 1.5)
    truth = make_transform(np.eye(3), np.subtract(b, a))  # T_target_source, no turn
    return _scan(a, rng), _scan(b, rng), truth


def test_a_pose_slid_through_the_wall_is_left_for_the_truth_from_two_plan_cells(doorway):
    target, source, truth = doorway
    # the source's face of the wall (x = 0.15) laid on the target's (x = 0): only pairs seen
    # from one side reach across it
    slid = make_transform(np.eye(3), truth[:3, 3] - [WALL_M, 0.0, 0.0])
    wide = refine(target, source, slid, threshold_m=0.03, reach_m=0.5)
    assert translation_error_m(wide.T_target_source, truth) < 0.01
    assert rotation_error_deg(wide.T_target_source, truth) < 0.1


def test_the_reach_changes_nothing_where_the_coarse_pose_is_close(doorway):
    target, source, truth = doorway
    near = make_transform(np.eye(3), truth[:3, 3] + [0.02, -0.01, 0.0])
    for reach in (None, 0.5):
        r = refine(target, source, near, threshold_m=0.03, reach_m=reach)
        assert translation_error_m(r.T_target_source, truth) < 0.01
