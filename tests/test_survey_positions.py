"""Rough positions as priors: the CSV, which of a link's poses they pick, the site frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexreg.core.transforms import make_transform, rotation_about_axis
from flexreg.errors import InputError
from flexreg.survey.links import Alternative, Link
from flexreg.survey.positions import (
    Position,
    apply_positions,
    choose,
    read_positions_csv,
    sigmas_off,
    site_from_positions,
    sited_by_groups,
)

STEMS = ["s0", "s1", "s2"]


def _pose(x, y, yaw_deg=0.0):
    return make_transform(rotation_about_axis([0, 0, 1], math.radians(yaw_deg)), [x, y, 0.0])


def test_the_csv_takes_optional_columns_and_defaults(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("stem,x,y,z,heading_deg,sigma_m\ns0,1,2,,90,0.5\ns1.ptx,3,4,1.5,,\n")
    p = read_positions_csv(path, STEMS)
    assert set(p) == {"s0", "s1"}
    assert p["s0"].heading_rad == pytest.approx(math.pi / 2) and p["s0"].sigma_m == 0.5
    assert not p["s0"].has_z and p["s1"].has_z and p["s1"].xyz[2] == 1.5
    assert p["s1"].heading_rad is None and p["s1"].sigma_m == 1.0
    short = tmp_path / "short.csv"
    short.write_text("stem,x,y\ns2,5,6\n")
    assert read_positions_csv(short, STEMS)["s2"].xyz.tolist() == [5.0, 6.0, 0.0]


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("x,y\n1,2\n", "expected the header"),
        ("stem,x,y\nnope,1,2\n", "'nope' is not one of the stations"),
        ("stem,x,y\ns0,1,2\ns0,3,4\n", "s0 is given twice"),
        ("stem,x,y\ns0,1,\n", "x and y are needed"),
        ("stem,x,y\ns0,1,abc\n", "y is not a number"),
        ("stem,x,y,sigma_m\ns0,1,2,0\n", "sigma_m must be positive"),
        ("stem,x,y\n", "no station in the file"),
    ],
)
def test_a_bad_csv_is_one_error_naming_the_file(tmp_path, text, words):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(InputError) as e:
        read_positions_csv(path, STEMS)
    assert str(path) in str(e.value) and words in str(e.value)


def test_positions_pick_the_one_pose_within_three_sigma():
    """Two stations 6 m apart along a hall of 5.9 m bays, positions 0.5 m and 10 degrees
    off: of the answer (a bay too far) and its twins, the positions pick the true pose."""
    truth = _pose(6.0, 0.0)
    a = Position(np.array([0.3, -0.4, 0.0]), False, math.radians(10), 1.0)
    b = Position(np.array([6.2, 0.3, 0.0]), False, math.radians(-5), 1.0)
    poses = [truth @ _pose(5.9, 0.0), truth, truth @ _pose(-5.9, 0.0)]
    assert choose(poses, a, b) == (1, "")
    assert sigmas_off(truth, a, b) < 1.0
    turned = truth @ _pose(0, 0, 180)
    assert math.isinf(sigmas_off(turned, a, b))  # a half turn never agrees with headings


def test_positions_that_cannot_tell_say_so():
    far = Position(np.array([0.0, 0.0, 0.0]), False, None, 3.0)
    other = Position(np.array([6.0, 0.0, 0.0]), False, None, 3.0)
    i, why = choose([_pose(6.0, 0.0), _pose(0.0, 6.5)], far, other)
    assert i is None and "cannot tell" in why


def test_apply_positions_swaps_in_the_alternative_and_vouches():
    truth = _pose(6.0, 0.0)
    wrong = truth @ _pose(5.9, 0.0)
    e = Link("s0", "s1", T_target_source=wrong, verdict="uncertain")
    e.alternatives = [Alternative(truth, "twin", 0.9)]
    bad = Link("s0", "s2", T_target_source=_pose(30.0, 0.0), verdict="confident")
    pos = {
        "s0": Position(np.zeros(3), False, 0.0, 1.0),
        "s1": Position(np.array([6.4, 0.2, 0.0]), False, 0.05, 1.0),
        "s2": Position(np.array([0.0, 8.0, 0.0]), False, 0.0, 1.0),
    }
    assert apply_positions([e, bad], pos) == 1
    # the positions pick the pose; an uncertain link so picked still needs a loop to place
    assert e.vouched == "positions" and not e.trusted
    assert np.allclose(e.T_target_source, truth)
    assert e.alternatives[0].kind == "answer" and np.allclose(
        e.alternatives[0].T_target_source, wrong
    )
    assert bad.status == "rejected" and "positions refuse" in bad.why


def test_positions_pick_a_doorway_link_but_not_one_its_scans_contradict():
    """A link uncertain because its scans share a doorway's worth (``low_overlap``) fits what
    both see: the positions pick its pose. One whose answer puts points in open space or
    leaves an axis free fits nothing: they leave it, and say why."""

    def uncertain(*codes):
        e = Link("s0", "s1", T_target_source=_pose(6.0, 0.0), verdict="uncertain")
        e.reasons = [{"code": c, "message": c} for c in codes]
        return e

    pos = {
        "s0": Position(np.zeros(3), False, 0.0, 1.0),
        "s1": Position(np.array([6.4, 0.2, 0.0]), False, 0.05, 1.0),
    }
    doorway = uncertain("low_overlap")
    both = uncertain("low_overlap", "ambiguous")
    both.alternatives = [Alternative(_pose(6.0, 0.0) @ _pose(5.9, 0.0), "twin", 0.9)]
    opened, free = uncertain("low_overlap", "free_space"), uncertain("weak_axis")
    assert apply_positions([doorway, both, opened, free], pos) == 2
    assert doorway.vouched == both.vouched == "positions" and not doorway.trusted
    assert np.allclose(both.T_target_source, _pose(6.0, 0.0))
    for e in (opened, free):
        assert not e.vouched and "no pose of the link fits the scans" in e.undecided


def test_positions_pick_a_link_whose_open_space_only_the_sample_finds():
    """A right answer among racks is often uncertain for ``free_space`` on the even sample
    alone (stray returns between a rack and the wall, one sample cell each); where full
    resolution clears it (``open_clear``) the positions pick its pose. Not where full
    resolution contradicts it too, nor where it was not checked there."""

    def freed(clear):
        e = Link("s0", "s1", T_target_source=_pose(6.0, 0.0), verdict="uncertain")
        e.reasons = [{"code": "free_space", "message": "sample"}]
        e.open_clear = clear
        return e

    pos = {
        "s0": Position(np.zeros(3), False, 0.0, 1.0),
        "s1": Position(np.array([6.4, 0.2, 0.0]), False, 0.05, 1.0),
    }
    clear, contradicted, unchecked = freed(True), freed(False), freed(None)
    axis = freed(True)
    axis.reasons.append({"code": "weak_axis", "message": "tunnel"})
    assert apply_positions([clear, contradicted, unchecked, axis], pos) == 1
    assert clear.vouched == "positions" and not clear.trusted
    for e in (contradicted, unchecked, axis):
        assert not e.vouched and "no pose of the link fits the scans" in e.undecided


def test_the_site_frame_of_the_positions():
    """Registered poses in the reference's frame, rough positions in a site frame turned by
    30 degrees and shifted: the fit recovers the turn and the shift."""
    T_site_ref = _pose(100.0, 50.0, 30.0)
    poses = {s: _pose(*xy) for s, xy in zip(STEMS, [(0, 0), (8, 1), (3, 9)], strict=True)}
    positions = {s: Position((T_site_ref @ P)[:3, 3], False, None, 1.0) for s, P in poses.items()}
    T = site_from_positions(poses, positions)
    assert np.allclose(T, T_site_ref, atol=1e-9)
    assert site_from_positions({"s0": poses["s0"]}, {"s0": positions["s0"]}) is None


def test_a_pivot_no_station_agrees_with_is_not_flagged_by_its_own_zero():
    """Two placed stations whose stored poses disagree by 3 m: whichever the frames are tied
    through, it is not said to disagree by 0.00 degrees / 0.000 m; the other is flagged."""
    from flexreg.survey.stored import check_stations

    poses = {"s0": np.eye(4), "s1": _pose(8.0, 0.0)}
    stored = {"s0": _pose(100.0, 50.0), "s1": _pose(100.0, 50.0) @ _pose(11.0, 0.0)}
    checks = check_stations(poses, stored, 1.0, 0.1)
    pivot = checks["s0"]["pivot"]
    other = "s1" if pivot == "s0" else "s0"
    assert checks[pivot]["agrees"] is None and checks[pivot]["translation_m"] == 0.0
    assert checks[other]["agrees"] is False and checks[other]["translation_m"] > 2.9


def test_stored_poses_declared_rough_are_positions():
    from flexreg.survey.positions import stored_positions

    stored = {"s0": _pose(1.0, 2.0, 30.0)}
    assert stored_positions(stored, None) == {}
    (p,) = stored_positions(stored, 0.3).values()
    assert p.sigma_m == 0.3 and p.has_z and p.heading_rad == pytest.approx(math.radians(30))


def _row(n, spacing, heading_off_deg, sigma=1.0):
    """Stations ``s0..s{n-1}`` in a row along the site's x axis, ``spacing`` apart, facing
    the site's x axis; positions exact, headings ``heading_off_deg`` off each."""
    truth = {f"s{i}": _pose(i * spacing, 0.0) for i in range(n)}
    pos = {
        s: Position(T[:3, 3].copy(), False, math.radians(heading_off_deg), sigma)
        for s, T in truth.items()
    }
    return truth, pos


def test_a_group_carries_the_heading_a_far_bay_twin_is_refused_by():
    """A station 17 m away along a hall of 5.65 m bays, headings 10 degrees off: from the
    station's rough heading a pose one bay off (5.65 m across the line of sight) lies
    within three of its sigma (the heading's error moves the station 17 m away by 3 m), so
    the positions cannot tell it from the true pose. Five stations in a row whose
    registrations hold them together carry their fitted heading (to about 2 degrees): the
    bay is then refused and the true pose picked."""
    truth, pos = _row(5, 8.0, 10.0)
    pos["s5"] = Position(np.array([16.0, 17.0, 0.0]), False, math.radians(10.0), 1.0)
    truth["s5"] = _pose(16.0, 17.0)
    right = np.linalg.inv(truth["s2"]) @ truth["s5"]
    twin = right @ _pose(5.65, 0.0)  # one bay along, across the line of sight
    assert sigmas_off(twin, pos["s2"], pos["s5"]) < 3.0
    assert choose([twin, right], pos["s2"], pos["s5"])[0] is None
    row = [f"s{i}" for i in range(5)]
    group = {s: np.linalg.inv(truth["s0"]) @ truth[s] for s in row}
    sited = sited_by_groups(pos, [row, ["s5"]], group)
    assert math.degrees(sited["s2"].heading_sigma_rad) < 3.0
    assert abs(math.degrees(sited["s2"].heading_rad)) < 3.0  # the fit outweighs 10 degrees
    assert sited["s5"] == pos["s5"]  # alone: as given
    assert choose([twin, right], sited["s2"], sited["s5"]) == (1, "")
    e = Link("s2", "s5", T_target_source=twin, verdict="uncertain")
    e.reasons = [{"code": "ambiguous", "message": "bays"}]
    e.alternatives = [Alternative(right, "twin", 0.95)]
    assert apply_positions([e], pos) == 0 and e.alternatives  # both kept: cannot tell
    assert apply_positions([e], sited) == 1
    assert np.allclose(e.T_target_source, right) and e.vouched == "positions"
    # decided again with the rough positions: the pick is undone, nothing refused
    assert apply_positions([e], pos) == 0
    assert np.allclose(e.T_target_source, twin) and not e.vouched and not e.refused
    assert len(e.alternatives) == 1 and np.allclose(e.alternatives[0].T_target_source, right)


def test_a_group_misplaced_against_its_positions_carries_nothing():
    """A group whose solved poses put a station 5 m from its position (a wrong link, or a
    wrong position) does not lend its fit to anyone."""
    truth, pos = _row(3, 8.0, 0.0)
    group = {s: np.linalg.inv(truth["s0"]) @ truth[s] for s in truth}
    group["s2"] = group["s2"] @ _pose(5.0, 0.0)
    assert sited_by_groups(pos, [list(truth)], group) == pos


def test_poses_the_positions_refuse_are_no_hypotheses():
    """Of a link's three poses, two agree with the positions (they cannot tell) and one, a
    bay off across the line of sight, lies further than three sigma: it is dropped; a
    link none of whose poses agrees is refused."""
    pos = {
        "s0": Position(np.zeros(3), False, 0.0, 0.3, math.radians(1.0)),
        "s1": Position(np.array([8.0, 0.0, 0.0]), False, 0.0, 0.3, math.radians(1.0)),
    }
    e = Link("s0", "s1", T_target_source=_pose(8.0, 6.0), verdict="uncertain")
    e.reasons = [{"code": "ambiguous", "message": "bays"}]
    e.alternatives = [Alternative(_pose(8.0, 0.0), "twin", 0.9)]
    e.alternatives.append(Alternative(_pose(8.3, 0.2), "runner_up", 0.8))
    assert apply_positions([e], pos) == 0 and "cannot tell" in e.undecided
    assert np.allclose(e.T_target_source, _pose(8.0, 0.0))
    assert [a.kind for a in e.alternatives] == ["runner_up"]
    far = Link("s0", "s1", T_target_source=_pose(13.65, 0.0), verdict="confident")
    apply_positions([far], pos)
    assert far.status == "rejected" and far.refused.startswith("the positions refuse")
