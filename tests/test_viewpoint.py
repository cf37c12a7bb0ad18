"""Where a cloud was seen from (stages.viewpoint): what it hides of itself, the virtual viewpoint
of a cloud in project coordinates, and a verdict that tests no open space in the view of a
cloud not taken from one point, and says so."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import from_depth
from flexreg.registration.check import Check
from flexreg.registration.verdict import decide
from flexreg.stages.verification import measured_image, range_slack
from flexreg.stages.viewpoint import (
    MAX_HIDDEN_SHARE,
    choose_viewpoint,
    hidden_share,
    one_viewpoint,
)


def _box_room(rng: np.random.Generator, n: int = 40_000) -> np.ndarray:
    """Points spread over the six faces of a 10 x 8 x 3 m room (x, y from 0, z from 0)."""
    size = np.array([10.0, 8.0, 3.0])
    p = rng.uniform(0, 1, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    side = rng.integers(0, 2, n)
    p[np.arange(n), axis] = side * size[axis]
    return p


def test_a_room_hides_nothing_from_inside_and_a_fused_cloud_does() -> None:
    """The room's walls seen from any point inside hide none of each other (but for a few
    points of surfaces seen at grazing angles sharing a pixel); with a pillar's
    faces seen from all around (a cloud fused from several viewpoints), the wall behind the
    pillar and the pillar's far faces are hidden from the middle of the room."""
    rng = np.random.default_rng(0)
    room = _box_room(rng)
    assert hidden_share(room, [5.0, 4.0, 1.5]) < MAX_HIDDEN_SHARE / 3
    assert hidden_share(room, [2.0, 6.0, 0.5]) < MAX_HIDDEN_SHARE / 3
    # a 1 m pillar at (7.5, 4), every face sampled densely: its far faces hide behind the near
    pillar = _box_room(rng, 20_000) * [0.1, 0.125, 1.0] + [7.0, 3.5, 0.0]
    fused = np.vstack([room, pillar])
    assert hidden_share(fused, [5.0, 4.0, 1.5]) > MAX_HIDDEN_SHARE
    assert one_viewpoint(None) and one_viewpoint(0.0) and not one_viewpoint(0.5)


def test_the_viewpoint_of_a_room_in_project_coordinates_is_inside_it() -> None:
    """The room moved 5e5 m away: the chosen viewpoint lies inside it and hides (almost)
    nothing of it; the same points give the same viewpoint."""
    room = _box_room(np.random.default_rng(1)) + [500_000.0, 5_400_000.0, 300.0]
    origin, hidden = choose_viewpoint(room)
    assert hidden < MAX_HIDDEN_SHARE / 3
    local = origin - [500_000.0, 5_400_000.0, 300.0]
    assert np.all(local > 0) and np.all(local < [10.0, 8.0, 3.0])
    np.testing.assert_array_equal(choose_viewpoint(room)[0], origin)


def test_no_open_space_in_the_view_of_a_cloud_not_taken_from_one_point() -> None:
    """A wall 10 m in front of a camera; a sample 5 m in front of it conflicts with the view of
    a cloud taken from the camera, and with none of a cloud that hides half of itself."""
    cam = PinholeCamera(50.0, 50.0, 20.0, 20.0, 41, 41)
    image = from_depth(np.full((41, 41), 10.0), cam)
    m, s = measured_image(image), range_slack(image)
    sample = np.array([[0.0, 0.0, 5.0], [0.5, 0.5, 10.0]])
    seen = Check(image, m, s, sample)
    blind = Check(image, m, s, sample, hidden=0.5)
    _, ok, bad = seen.classify(np.eye(4), 0.05, 0.002)
    assert bad.tolist() == [True, False] and ok.tolist() == [False, True]
    _, ok, bad = blind.classify(np.eye(4), 0.05, 0.002)
    assert bad.tolist() == [False, False] and ok.tolist() == [False, True]
    assert seen.judge(np.eye(4), 0.05, 0.002)[0] == pytest.approx(0.5 - 3 * 0.5)
    assert blind.judge(np.eye(4), 0.05, 0.002)[0] == pytest.approx(0.5)


def test_the_verdict_says_where_open_space_was_not_tested() -> None:
    ev = {
        "free_space": {
            "source_conflicting": 0.0,
            "target_conflicting": 0.001,
            "no_viewpoint": {"target": 0.05},
        }
    }
    notes = decide(ev).notes
    assert [n.code for n in notes] == ["free_space_unknown"]
    assert "the target hides 5%" in notes[0].message
    ev["free_space"]["no_viewpoint"] = {}
    assert decide(ev).notes == ()
