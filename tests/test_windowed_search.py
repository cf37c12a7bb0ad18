"""A rough prior bounds the search: :class:`~flexreg.stages.alignment.Window`, matching and
RANSAC inside it, the registration with ``window`` and the windows of rough positions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import room_pair

from flexreg.core.transforms import (
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import ConfigError, DegenerateGeometryError, RegistrationError
from flexreg.registration import RegistrationConfig, register
from flexreg.stages.alignment import Window, ransac_rigid, windowed_fit
from flexreg.stages.keypoints import Features
from flexreg.stages.matching import match_window
from flexreg.survey.links import Link
from flexreg.survey.positions import Position, near_pairs, unsettled, window_of


def _yaw(deg: float, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    return make_transform(rotation_about_axis([0.0, 0.0, 1.0], math.radians(deg)), t)


# ------------------------------------------------------------------ the window


def test_a_window_holds_what_is_within_its_shift_and_turn():
    P = _yaw(30.0, (5.0, 1.0, 0.0))
    w = Window(P, shift_m=1.0, turn_rad=math.radians(10.0))
    Ts = np.stack(
        [
            P,
            _yaw(0.0, (0.9, 0.0, 0.0)) @ P,  # shifted 0.9 m
            _yaw(0.0, (0.0, 1.1, 0.0)) @ P,  # 1.1 m
            P @ _yaw(9.9),  # turned 9.9 degrees
            P @ _yaw(-10.1),
            # turned 10 degrees about the source's origin moves no origin: still inside
            P @ make_transform(rotation_about_axis([1.0, 0.0, 0.0], math.radians(9.0)), [0, 0, 0]),
        ]
    )
    assert w.contains(Ts).tolist() == [True, True, False, True, False, True]


def test_ransac_inside_a_window_finds_the_model_the_window_allows():
    """Two models among the correspondences, as a row of bays gives: the stronger one (60 %)
    a bay off, the weaker (30 %) the truth. Without a window RANSAC takes the stronger; a
    window around the truth leaves only the weaker."""
    rng = np.random.default_rng(7)
    truth = _yaw(20.0, (3.0, 1.0, 0.2))
    bay = _yaw(0.0, (8.0, 0.0, 0.0)) @ truth
    src = rng.uniform(-10, 10, (200, 3))
    tgt = np.empty_like(src)
    tgt[:120] = src[:120] @ bay[:3, :3].T + bay[:3, 3]
    tgt[120:180] = src[120:180] @ truth[:3, :3].T + truth[:3, 3]
    tgt[180:] = rng.uniform(-10, 10, (20, 3))
    free = ransac_rigid(tgt, src, threshold_m=0.05, rng=0)
    assert translation_error_m(free.T_target_source, bay) < 1e-6
    rough = _yaw(8.0, (0.7, -0.5, 0.0)) @ truth
    w = Window(rough, shift_m=3.0, turn_rad=math.radians(20.0))
    r = ransac_rigid(tgt, src, threshold_m=0.05, rng=0, window=w)
    assert translation_error_m(r.T_target_source, truth) < 1e-6
    assert r.n_inliers == 60
    # a window around neither model finds nothing
    with pytest.raises(DegenerateGeometryError):
        ransac_rigid(
            tgt, src, threshold_m=0.05, rng=0, window=Window(_yaw(90.0), 0.5, math.radians(5))
        )


def _features(desc: np.ndarray) -> Features:
    n = len(desc)
    z = np.zeros(n, dtype=np.float32)
    return Features(np.zeros((n, 2)), desc.astype(np.float32), z + 1, z + 4, z - 1, "test")


def test_window_matching_keeps_the_k_nearest_descriptors_where_the_prior_allows():
    # one source keypoint at 10 m; target keypoints at 0.5 m, 5 m and 50 m from where the
    # identity puts it, the farthest with the identical descriptor
    src = np.array([[10.0, 0.0, 0.0]])
    tgt = np.array([[10.5, 0.0, 0.0], [10.0, 5.0, 0.0], [60.0, 0.0, 0.0], [np.nan] * 3])
    ds = np.array([[1.0, 0.0]])
    dt = np.array([[0.0, 1.0], [0.5, 0.5], [1.0, 0.0], [1.0, 0.0]])
    # 1 m + 2 sin(15 deg) 10 m = 6.18 m around the prediction: the first two, nearest
    # descriptor first
    pairs = match_window(
        _features(dt), _features(ds), tgt, src, np.eye(4), shift_m=1.0,
        turn_rad=math.radians(30.0), k=3,
    )  # fmt: skip
    assert pairs.tolist() == [[1, 0], [0, 0]]
    pairs = match_window(
        _features(dt), _features(ds), tgt, src, np.eye(4), shift_m=1.0,
        turn_rad=math.radians(30.0), k=1,
    )  # fmt: skip
    assert pairs.tolist() == [[1, 0]]
    # a window of 1 m and no turn holds only the nearest
    pairs = match_window(
        _features(dt), _features(ds), tgt, src, np.eye(4), shift_m=1.0, turn_rad=1e-9, k=3
    )
    assert pairs.tolist() == [[0, 0]]


def test_windowed_fit_takes_a_partner_that_is_not_the_best_descriptor():
    """Look-alike keypoints: each source keypoint's best descriptor is its twin one bay
    (8 m) off, the true partner the second best. The window (2 m) drops the twins."""
    rng = np.random.default_rng(3)
    truth = _yaw(15.0, (2.0, -1.0, 0.1))
    src = rng.uniform(-6, 6, (40, 3))
    true_t = src @ truth[:3, :3].T + truth[:3, 3]
    twin_t = true_t + [8.0, 0.0, 0.0]
    tgt = np.vstack([true_t, twin_t])
    ds = rng.normal(size=(40, 16))
    dt = np.vstack([ds + 0.3, ds + 0.1])  # the twins' descriptors are the nearer
    w = Window(_yaw(5.0, (0.5, 0.5, 0.0)) @ truth, 2.0, math.radians(15.0))
    fit = windowed_fit(_features(dt), _features(ds), tgt, src, w, threshold_m=0.02, rng=0)
    assert fit is not None
    assert translation_error_m(fit.T_target_source, truth) < 1e-6
    assert rotation_error_deg(fit.T_target_source, truth) < 1e-6
    # a window around the twins' bay fits the twins instead: the window, not the
    # descriptors, decides between look-alikes
    twin = _yaw(0.0, (8.0, 0.0, 0.0)) @ truth
    fit = windowed_fit(
        _features(dt), _features(ds), tgt, src, Window(twin, 2.0, 0.2), threshold_m=0.02, rng=0
    )
    assert fit is not None and translation_error_m(fit.T_target_source, twin) < 1e-6


# ------------------------------------------------------------------ the registration


@pytest.fixture(scope="module")
def pair():
    return room_pair(4, (512, 256))


def test_a_rough_prior_with_its_window_registers_the_pair(pair):
    target, source, T = pair
    rough = make_transform(rotation_about_axis([0, 0, 1], math.radians(12.0)), [0.8, -0.6, 0]) @ T
    r = register(target, source, RegistrationConfig(), init=rough, window=(3.0, math.radians(25)))
    assert rotation_error_deg(r.T_target_source, T) < 0.05
    assert translation_error_m(r.T_target_source, T) < 0.01


def test_the_search_never_leaves_the_window(pair):
    """A prior 4 m off with a 1 m window: the truth is outside, so the answer is either
    refused or inside the window (the verdict judges it), never the truth."""
    target, source, T = pair
    wrong = make_transform(np.eye(3), [4.0, 0.0, 0.0]) @ T
    window = (1.0, math.radians(5.0))
    try:
        r = register(target, source, RegistrationConfig(), init=wrong, window=window)
    except RegistrationError:
        return
    assert translation_error_m(r.T_coarse, T) > 2.0
    assert Window(wrong, *window).contains(r.T_coarse)[0]
    assert not r.verdict.confident


@pytest.mark.parametrize(
    "init, window, message",
    [
        (None, (1.0, 0.1), "needs the rough T_target_source"),
        (np.eye(4), (0.0, 0.1), "positive shift"),
        (np.eye(4), (1.0, float("nan")), "positive shift"),
    ],
)
def test_a_bad_window_is_a_config_error(pair, init, window, message):
    target, source, _ = pair
    with pytest.raises(ConfigError, match=message):
        register(target, source, RegistrationConfig(), init=init, window=window)


# ------------------------------------------------------------------ rough positions


def _pos(x: float, y: float, heading: float | None = 0.0, sigma: float = 1.0) -> Position:
    return Position(np.array([x, y, 0.0]), False, heading, sigma)


def test_the_window_of_two_positions_is_their_agreement_bounds():
    """Three sigma of both positions and of what the target's heading error (10 degrees)
    turns the 5 m offset by; the turn the headings agree within."""
    shift, turn = window_of(_pos(0, 0, sigma=0.3), _pos(5, 0, math.radians(40), sigma=0.4))
    assert shift == pytest.approx(3 * math.hypot(0.5, 5 * math.radians(10)))
    assert math.degrees(turn) == pytest.approx(30.0)
    assert window_of(_pos(0, 0, None), _pos(5, 0)) is None


def test_near_pairs_are_the_stations_within_reach_nearest_first():
    positions = {"a": _pos(0, 0), "b": _pos(11, 0), "c": _pos(3, 4), "d": _pos(30, 0)}
    stems = ["a", "b", "c", "d", "e"]  # e has no position
    assert near_pairs(stems, positions, 12.0) == [("a", "c"), ("b", "c"), ("a", "b")]


def test_links_the_positions_do_not_confirm_are_registered_again():
    positions = {"a": _pos(0, 0), "b": _pos(6, 0), "c": _pos(12, 0)}
    T_ok, T_bay = _yaw(0.0, (6.2, 0.0, 0.0)), _yaw(0.0, (14.0, 0.0, 0.0))

    def link(t, s, T, verdict="confident", status="accepted", vouched=""):
        return Link(t, s, T_target_source=T, verdict=verdict, status=status, vouched=vouched)

    links = [
        link("a", "b", T_ok),  # confident where the positions put it: kept
        link("b", "c", T_bay),  # confident a bay off: again
        link("a", "c", _yaw(0.0, (12.1, 0, 0)), verdict="uncertain"),  # uncertain: again
        link("a", "b", None, status="failed"),  # failed: again
        link("b", "c", T_bay, vouched="hand"),  # by hand: left alone
        link("a", "x", T_bay),  # x has no position: left alone
    ]
    again = unsettled(links, positions)
    assert [links.index(e) for e in again] == [1, 2, 3]


def test_the_predicted_pose_is_inside_its_own_window():
    from flexreg.survey.positions import predicted_T_target_source

    a, b = _pos(1, 2, 0.3), _pos(7, -1, -1.2, 0.5)
    T = predicted_T_target_source(a, b)
    assert Window(T, *window_of(a, b)).contains(T)[0]
    # and the truth a sigma away in position and 10 degrees in heading is inside too
    truth = invert(
        make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.5, 2.5, 0])
    ) @ make_transform(rotation_about_axis([0, 0, 1], -1.2 + math.radians(10)), [7, -1, 0])
    assert Window(T, *window_of(a, b)).contains(truth)[0]
