"""Settling near-ties: the count floor of a full-resolution duel, the sweep on the surfaces
facing the axis, and a refined pose pinned back on the cue (hand-made corridor and rooms of
``test_verdict``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_verdict import CORRIDOR, NICHE, _full_pair, _judged, _station, _with

from flexreg.core.transforms import make_transform, rotation_about_axis
from flexreg.registration import RegistrationConfig
from flexreg.registration.check import decisive_full
from flexreg.registration.config import FULL_DECISIVE_POINTS, JudgeConfig
from flexreg.registration.settle import (
    Settlement,
    _across,
    _FacingScorer,
    _peaks,
    _Scorer,
    pin_along,
    screen,
)
from flexreg.registration.verdict import decide

N = 850_000  # points of a 1024 x 512 pair's duel


@pytest.mark.parametrize(
    ("won", "lost", "points", "decisive"),
    [
        (17, 0, N, True),  # a forklift two bays away: below the share, above the floor
        (10, 0, N, True),
        (9, 0, N, False),
        (2, 0, N, False),  # empty arcades and tunnels: 0-2 points either way
        (17, 6, N, False),  # not 3 : 1
        (17, 0, 0, False),  # without the number of points only the share counts
        (100, 0, N, True),  # the share alone (100 > 85)
    ],
)
def test_full_duel_counts_a_small_lead_against_nothing(won, lost, points, decisive):
    assert decisive_full(won / N, lost / N, JudgeConfig(), points=points) is decisive


def test_count_floor_is_a_config_field_and_can_be_switched_off():
    assert not decisive_full(17 / N, 0.0, JudgeConfig())  # without the count, the share alone
    assert FULL_DECISIVE_POINTS == 10


@pytest.mark.parametrize(("won", "ambiguous"), [(17, False), (2, True)])
def test_runner_up_beaten_by_a_few_points_at_full_resolution_is_no_ambiguity(won, ambiguous):
    ev = _with()
    ev["runner_up"] = {
        "score_ratio": 0.97,
        "rotation_deg": 0.0,
        "translation_m": 3.5,
        "offset_m": [3.5, 0.0, 0.0],
        "refuted_share": 0.0,
        "refuting_share": 0.0,
        "full_refuted_share": won / N,
        "full_refuting_share": 0.0,
        "full_points": N,
    }
    ev["runner_ups"] = [ev["runner_up"]]
    ev["full_resolution"] = {"points": N, "open_space_share": 0.0}
    assert ("ambiguous" in [r.code for r in decide(ev).reasons]) is ambiguous


def test_peaks_keep_local_maxima_apart():
    s = np.array([0.0, 5.0, 4.9, 1.0, 3.0, 0.0, 2.0, 2.5])
    assert _peaks(s, 3, None) == [1, 4, 7]
    assert _peaks(s, 3, None, away=2) == [1, 4, 7]
    assert _peaks(s, 3, None, away=3) == [1, 7]  # 4 is only 3 from the better 1
    assert _peaks(s, 3, 1, away=2) == [4, 7]
    assert _peaks(s, 3, 1, away=3) == [4]
    assert _peaks(s, 1, None) == [1]


def test_facing_score_peaks_on_the_niche():
    """Slid along the corridor, the source's surfaces facing the axis (the niche's sides) score
    best at the true position; a pose a metre or more off scores clearly less."""
    pair, T = _full_pair(*CORRIDOR, NICHE, _station(0, 0), _station(-1.5, 0.3))
    axis = np.array([1.0, 0.0, 0.0])
    score = _FacingScorer.facing(pair, T, axis, 0.02)
    assert 0 < len(score.points) < len(pair.source.points) / 5
    offsets = np.arange(-4.0, 4.01, 0.25)
    s = np.array([score(make_transform(np.eye(3), d * axis) @ T) for d in offsets])
    assert offsets[int(np.argmax(s))] == 0.0
    assert s[np.abs(offsets) >= 1.0].max() < 0.5 * s.max()


def test_pin_along_keeps_the_placed_position_along_the_axis_only():
    """A refinement that slid 0.2 m along the settled axis and 3 cm across it is moved back
    along the axis only: ICP keeps the other degrees of freedom."""
    placed = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 0.5])
    slid = make_transform(rotation_about_axis([0, 0, 1], 0.301), [1.2, 2.03, 0.5])
    axis = np.array([1.0, 0.0, 0.0])
    weak = {"kind": "weak_axis"}
    settled = Settlement(coarse=None, sweep=weak, won=True, axis=axis)  # type: ignore[arg-type]
    pinned = pin_along(settled, slid, placed)
    np.testing.assert_allclose(pinned[:3, 3], [1.0, 2.03, 0.5], atol=1e-12)
    np.testing.assert_array_equal(pinned[:3, :3], slid[:3, :3])
    unsettled = Settlement(coarse=None)  # type: ignore[arg-type]
    np.testing.assert_array_equal(pin_along(unsettled, slid, placed), slid)


def test_a_repeat_is_not_pinned():
    """Along a row of bays (a repeat, the axis not weak) the overlap's structure holds ICP:
    the refined pose stays as ICP left it."""
    placed = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 0.5])
    slid = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.009, 2.0, 0.5])
    repeat = {"kind": "repeat"}
    settled = Settlement(coarse=None, sweep=repeat, won=True, axis=np.array([1.0, 0.0, 0.0]))  # type: ignore[arg-type]
    np.testing.assert_array_equal(pin_along(settled, slid, placed), slid)


def test_a_turned_pose_beside_the_walls_is_slid_back_across_the_axis():
    pair, T = _full_pair(*CORRIDOR, NICHE, _station(0, 0), _station(-1.5, 0.3))
    beside = make_transform(np.eye(3), [0.0, 0.6, 0.0]) @ T
    up, axis = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    back = _across(beside, axis, up, _Scorer.of(pair, 0.02))
    assert abs(back[1, 3] - T[1, 3]) < 0.051
    np.testing.assert_array_equal(back[[0, 2], 3], beside[[0, 2], 3])


def test_screen_keeps_the_first_and_the_least_contradicted():
    """Of two poses slid along the corridor, the one off the niche scores better on the
    samples but contradicts the niche; the screen keeps the true one."""
    pair, T = _full_pair(*CORRIDOR, NICHE, _station(0, 0), _station(-1.5, 0.3))
    first = _judged(make_transform(np.eye(3), [4.0, 0.0, 0.0]) @ T, 0.95)
    off = _judged(make_transform(np.eye(3), [0.5, 0.0, 0.0]) @ T, 0.99)
    truth = _judged(T, 0.9)
    assert screen([first, off, truth], pair, 0.02, size=2) == [first, truth]
    assert screen([first, off], pair, 0.02, size=2) == [first, off]


def test_a_degenerate_guided_fit_leaves_the_prior_a_candidate(monkeypatch):
    """Three collinear keypoint inliers around a prior make no rotation: the prior stays a
    candidate instead of ending the registration."""
    import flexreg.registration.candidates as cand
    from flexreg.errors import DegenerateGeometryError

    def degenerate(*args, **kwargs):
        raise DegenerateGeometryError("the 3 correspondences are collinear")

    monkeypatch.setattr(cand, "guided_fit", degenerate)
    T, kp = np.eye(4), SimpleNamespace(features=None, points=None)
    fams = cand.families([("plan", T), ("descriptors", T)], kp, kp, 0.05, RegistrationConfig())
    assert [[origin for origin, _ in f] for f in fams] == [["plan"]]


@pytest.mark.parametrize(
    ("own", "refuted", "refuting", "ambiguous"),
    [
        (0.00026, 0.00915, 0.00025, False),  # warehouse 07 <- 08: a bay off refuted outright
        (0.00026, 0.0025, 0.0, True),  # the runner-up under judge.settle_open_share (0.3 %)
        (0.0012, 0.00915, 0.0, True),  # the answer itself not clean (above 0.1 %)
        (0.00026, 0.00915, 0.0012, True),  # the runner-up refutes the answer too (< 10 x)
    ],
)
def test_a_runner_up_full_resolution_refutes_outright_is_no_ambiguity(
    own, refuted, refuting, ambiguous
):
    """Rack bays leave the right pose 0.026 % of points in open space, above the empty
    scenes' 0.01 % (``judge.full_max_conflict``); a pose one bay off puts 0.9 % there."""
    ev = _with()
    ev["runner_up"] = {
        "score_ratio": 1.0,
        "rotation_deg": 0.0,
        "translation_m": 5.65,
        "offset_m": [-4.35, 3.61, 0.0],
        "refuted_share": 0.04,
        "refuting_share": 0.02,
        "full_refuted_share": refuted,
        "full_refuting_share": refuting,
        "full_points": 757_580,
    }
    ev["runner_ups"] = [ev["runner_up"]]
    ev["full_resolution"] = {"points": 757_580, "open_space_share": own}
    assert ("ambiguous" in [r.code for r in decide(ev).reasons]) is ambiguous


def test_rescue_replaces_an_answer_full_resolution_contradicts():
    """A box with a cupboard: the answer is the pose turned 180° about the centre (its
    cupboard lands where the other scanner saw the wall); the truth among the candidates is
    clean and beats it; without the truth, nothing replaces the answer."""
    from test_verdict import BOX, CUPBOARD, _turn_about_centre

    from flexreg.core.transforms import invert
    from flexreg.registration.fullres import pose_masks
    from flexreg.registration.settle import open_share, rescue

    T_wt, T_ws = _station(0.6, 0.4), _station(-1.0, 0.5, 30)
    pair, T = _full_pair(*BOX, CUPBOARD, T_wt, T_ws)
    wrong = invert(T_wt) @ _turn_about_centre(180) @ T_ws
    cfg = JudgeConfig(open_share=0.005 / 30)  # the hand-made box is tiny: 0.01 % to rescue
    masks = pose_masks(pair, wrong, 0.02)
    assert open_share(masks) >= cfg.settle_open_share
    out = rescue(masks, [_judged(T), _judged(wrong)], wrong, pair, 0.02, cfg)
    assert out is not None and np.allclose(out.T_target_source, T)
    far = make_transform(np.eye(3), [0.0, 40.0, 0.0]) @ T  # clean only by seeing nothing
    assert rescue(masks, [_judged(far)], wrong, pair, 0.02, cfg) is None
