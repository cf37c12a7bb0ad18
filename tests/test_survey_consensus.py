"""The graph's one mechanism on hand-built graphs: hypotheses that agree around cycles."""

from __future__ import annotations

import numpy as np

from flexreg.core.transforms import invert, make_transform, rotation_about_axis
from flexreg.survey.config import SurveyConfig
from flexreg.survey.graph import Link, Veto, solve_graph, uncertain_via
from flexreg.survey.hypotheses import LoopTolerance, cycle_votes, hypotheses_of
from flexreg.survey.links import Alternative
from flexreg.survey.mapcheck import PairJudge, PairLook

INFO = np.diag([2e5, 2e5, 2e5, 1e4, 1e4, 1e4])
TOL = LoopTolerance(0.3, 0.03, 0.01)


def _poses(n=6):
    return {
        f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.2 * i), [4.0 * i, 1.0 * i, 0])
        for i in range(n)
    }


def _link(P, a, b, verdict="confident", T=None):
    T = invert(P[a]) @ P[b] if T is None else T
    return Link(a, b, T, INFO, verdict, overlap_target=0.4, overlap_source=0.4, doubt=0.05)


def _moved(P, a, b, offset):
    """``a <- b`` moved by ``offset`` metres in ``a``'s frame (a look-alike room or bay)."""
    return make_transform(np.eye(3), offset) @ invert(P[a]) @ P[b]


class _Judge:
    """The map's free-space check knowing the truth: at the true relative pose ``clean`` of
    a scan lands in the other's free space and ``explained`` on its surfaces; anywhere else
    ``wrong`` and a tenth as much (judged as :class:`PairJudge` does)."""

    def __init__(self, P, *, clean=0.01, wrong=0.12, explained=0.3):
        self.P, self.clean, self.wrong, self.explained = P, clean, wrong, explained
        self.asked = 0

    def __call__(self, a, b, T):
        self.asked += 1
        true = invert(self.P[a]) @ self.P[b]
        right = np.linalg.norm(T[:3, 3] - true[:3, 3]) < 0.5
        c, x = (self.clean, self.explained) if right else (self.wrong, self.explained / 10)
        look = PairLook(a, b, T, (x, x), (c, c), (1000, 1000))
        return PairJudge({}, {}, SurveyConfig()).contradiction(look)


def _by_pair(links):
    out = {}
    for e in links:
        out.setdefault(frozenset((e.target, e.source)), []).extend(hypotheses_of(e))
    return out


def test_cycle_votes_count_the_closing_cycles_of_each_hypothesis():
    """A square s0-s1-s2-s3 with the diagonal s0-s2: two triangles and the square. The
    diagonal's answer is 2 m off and its twin right: the twin closes both triangles, the
    answer none; every right answer closes its triangle and the square."""
    P = _poses(4)
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s2", "s3"),
             _link(P, "s0", "s3")]  # fmt: skip
    diag = _link(P, "s0", "s2", "uncertain", T=_moved(P, "s0", "s2", [2.0, 0, 0]))
    diag.alternatives = [Alternative(invert(P["s0"]) @ P["s2"], "twin", 0.9)]
    hyps = _by_pair([*links, diag])
    assert cycle_votes(hyps, TOL) == []  # no cycle of trusted answers fails to close
    answer, twin = hyps[frozenset(("s0", "s2"))]
    assert (answer.votes, twin.votes) == (0, 2)
    assert [hyps[frozenset(p)][0].votes for p in (("s0", "s1"), ("s1", "s2"))] == [2, 2]
    assert twin.misfit < 1e-6


def test_a_chain_closed_by_a_long_cycle_is_confirmed():
    """Six stations in a ring of confident links: no cycle of three or four, the ring of
    six confirms every link. Without the closing link the chain still places them, each
    link unchecked; with it one metre off, nothing tells which link is wrong: nothing."""
    P = _poses(6)
    ring = [_link(P, f"s{i}", f"s{(i + 1) % 6}") for i in range(6)]
    sol = solve_graph(sorted(P), ring, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == sorted(P)
    assert all(e.status == "accepted" and e.confirmed_by_loop for e in ring)
    sol = solve_graph(sorted(P), ring[:5], SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == sorted(P)
    assert not any(e.confirmed_by_loop for e in ring[:5])
    ring[5] = _link(P, "s5", "s0", T=_moved(P, "s5", "s0", [1.0, 0, 0]))
    sol = solve_graph(sorted(P), ring, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) == 1 and all(e.status == "rejected" for e in ring)


def _two_groups(P):
    """s0-s1-s2 and s3-s4-s5 each a triangle of confident links; between them only
    uncertain links: s2-s3 right (a doorway), s1-s3 wrong (an identical room 6 m off)."""
    return [
        _link(P, "s0", "s1"),
        _link(P, "s1", "s2"),
        _link(P, "s0", "s2"),
        _link(P, "s3", "s4"),
        _link(P, "s4", "s5"),
        _link(P, "s3", "s5"),
        _link(P, "s2", "s3", "uncertain"),
        _link(P, "s1", "s3", "uncertain", T=_moved(P, "s1", "s3", [6.0, 0, 0])),
    ]


def test_the_map_picks_the_only_placement_no_station_contradicts():
    P = _poses()
    links = _two_groups(P)
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) == 3  # two placements, one link each: nothing tells
    assert "no loop or rough position" in (links[6].why or "") + (links[7].why or "") or (
        links[6].status == links[7].status == "rejected"
    )
    links = _two_groups(P)
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", judge=_Judge(P))
    assert sorted(sol.groups[0]) == sorted(P)
    for s in ("s3", "s4", "s5"):
        np.testing.assert_allclose(sol.poses[s], invert(P["s0"]) @ P[s], atol=1e-6)
        assert sol.confidence[s] == "uncertain"  # joined through an uncertain link
    assert links[6].status == "accepted" and links[6].map_joined
    assert links[7].status == "rejected"


def test_no_join_when_the_map_accepts_both_placements_or_cannot_tell():
    P = _poses()
    for judge in (_Judge(P, wrong=0.02), _Judge(P, explained=0.005, clean=0.001, wrong=0.001)):
        links = _two_groups(P)
        sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", judge=judge)
        assert len(sol.groups[0]) == 3 and judge.asked > 0


def test_two_separate_sites_are_never_fused_when_every_placement_contradicts():
    P = _poses()
    links = _two_groups(P)
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", judge=_Judge(P, clean=0.5))
    assert len(sol.groups[0]) == 3 and len(sol.groups[1]) == 3


def test_look_alike_links_wrong_the_same_way_place_nothing():
    """s3 seen from s1 and s2 through two uncertain links both one bay (6 m) off the same
    way, each with the right pose as its twin: two placements of s3 equally supported by
    two links each, so s3 stays unplaced, its link naming the poses it fits."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    bay = [6.0, 0.0, 0.0]
    wrong = []
    for a in ("s1", "s2"):
        shifted = invert(P[a]) @ make_transform(np.eye(3), bay) @ P["s3"]
        e = _link(P, a, "s3", "uncertain", T=shifted)
        e.alternatives = [Alternative(invert(P[a]) @ P["s3"], "twin", 1.0)]
        wrong.append(e)
    sol = solve_graph(sorted(P), [*base, *wrong], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    assert all("fits 2 poses" in e.why for e in wrong)
    assert "fits 2 poses" in sol.reasons["s3"]


def test_a_hand_link_places_a_station_alone_and_a_wrong_one_is_refused_by_its_loop():
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    hand = _link(P, "s2", "s3")
    hand.vouched = "hand"
    sol = solve_graph(sorted(P), [*base, hand], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and hand.status == "accepted"
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    # one metre off, with two confident automatic links that agree on s3 (a loop of
    # confident links): refused, with its loop error
    hand = _link(P, "s2", "s3", T=_moved(P, "s2", "s3", [1.0, 0, 0]))
    hand.vouched = "hand"
    auto = [_link(P, "s1", "s3"), _link(P, "s0", "s3")]
    sol = solve_graph(sorted(P), [*base, hand, *auto], SurveyConfig(), reference="s0")
    assert hand.status == "rejected" and "loop" in hand.why
    assert abs(hand.loop_error_m - 1.0) < 1e-6
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)


def test_uncertain_links_do_not_settle_a_dispute_between_confident_ones():
    """The surveyor's link s2-s3 is a metre off and one confident link s1-s3 disagrees;
    beside it only an uncertain link s0-s3 (in look-alike rooms several are wrong the same
    way, and may side with the wrong one). Neither is placed on that: s3 stays unplaced and
    its reason names the two links that disagree."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    hand = _link(P, "s2", "s3", T=_moved(P, "s2", "s3", [1.0, 0, 0]))
    hand.vouched = "hand"
    auto = [_link(P, "s1", "s3"), _link(P, "s0", "s3", "uncertain")]
    sol = solve_graph(sorted(P), [*base, hand, *auto], SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert "s2 <- s3" in sol.reasons["s3"] and "s1 <- s3" in sol.reasons["s3"]
    assert hand.status == auto[0].status == "rejected" and "does not close" in hand.why


def test_a_half_turned_group_backed_by_one_station_is_not_placed():
    """Held-out building 727: a group of three stations (s3-s5, confident among them) is
    joined to the reference's group (s0-s2) by one confident link s2-s5 that is right and
    one confident link s0-s5 that turns the group half round into a look-alike room, with
    two uncertain links s0-s3, s0-s4 that agree with the turn (a room of s0 that looks the
    same turned round aliases all of its links alike). The confident links contradict each
    other and only uncertain links side with one: the group is not placed (before, it was
    placed half turned, 'verified'); with the map the right placement wins."""
    P = _poses(6)
    turn = make_transform(rotation_about_axis([0, 0, 1], np.pi), [6.0, 3.0, 0.0])

    def links():
        pairs = [("s0", "s1"), ("s1", "s2"), ("s0", "s2"), ("s3", "s4"), ("s4", "s5"), ("s3", "s5")]
        inside = [_link(P, a, b) for a, b in pairs]
        turned = [("s5", "confident"), ("s3", "uncertain"), ("s4", "uncertain")]
        alias = [_link(P, "s0", b, v, T=turn @ invert(P["s0"]) @ P[b]) for b, v in turned]
        return [*inside, *alias, _link(P, "s2", "s5")]

    sol = solve_graph(sorted(P), links(), SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert "s0 <- s5" in sol.reasons["s5"] and "s2 <- s5" in sol.reasons["s5"]
    sol = solve_graph(sorted(P), links(), SurveyConfig(), reference="s0", judge=_Judge(P))
    assert sorted(sol.groups[0]) == sorted(P)
    for s in P:
        np.testing.assert_allclose(sol.poses[s], invert(P["s0"]) @ P[s], atol=1e-6)


def test_the_map_names_the_wrong_link_of_a_triangle_that_does_not_close():
    """Three confident links, s0-s2 overlaying two look-alike rooms: the triangle does not
    close and no loop says which link is wrong. Without the map nothing is placed; with it,
    "s0-s2 is wrong" is the one hypothesis under which s0 and s2 sit at ease, and the other
    two place all three."""
    P = _poses(3)
    twin = make_transform(rotation_about_axis([0, 0, 1], np.pi), [3.0, 2.0, 0.0])
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"),
             _link(P, "s0", "s2", T=twin @ invert(P["s0"]) @ P["s2"])]  # fmt: skip
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) == 1
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", judge=_Judge(P))
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert [e.status for e in links] == ["accepted", "accepted", "rejected"]
    assert "loop" in links[2].why and links[2].loop_error_deg > 100
    np.testing.assert_allclose(sol.poses["s2"], invert(P["s0"]) @ P["s2"], atol=1e-6)


def _windowed(P, a, b, T=None):
    """A link confident inside rough positions' window, vouched for by them."""
    e = _link(P, a, b, T=T)
    e.windowed, e.vouched = True, "positions"
    return e


def test_two_windowed_links_that_agree_place_a_station_and_one_alone_does_not():
    """s3 registered only inside rough positions' windows: one such link, confident, places
    nothing on its own (a pose slid inside a window can be confident); two of them, to
    different stations of the group, that agree around the loop place it; two that disagree
    by a slide of 14 cm (a wall's thickness) place nothing."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    one = [_windowed(P, "s2", "s3")]
    sol = solve_graph(sorted(P), [*base, *one], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0] and one[0].status != "accepted"
    two = [_windowed(P, "s2", "s3"), _windowed(P, "s1", "s3")]
    sol = solve_graph(sorted(P), [*base, *two], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and all(e.status == "accepted" for e in two)
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert sol.confidence["s3"] == "confident"  # a loop of confident links placed it
    slid = [_windowed(P, "s2", "s3"), _windowed(P, "s1", "s3", _moved(P, "s1", "s3", [0.14, 0, 0]))]
    sol = solve_graph(sorted(P), [*base, *slid], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]


def _plain(P, a, b, T=None, codes=("low_overlap",)):
    """An uncertain link doubted only for how little its scans share (a doorway's worth)."""
    e = _link(P, a, b, "uncertain", T=T)
    e.reasons = [{"code": c, "message": c} for c in codes]
    return e


def test_two_answers_uncertain_only_for_their_overlap_that_agree_place_a_station():
    """s3 seen through two doorways, from s1 and from s2, each link uncertain only for its
    small overlap: two registrations of different pairs of scans that agree around the loop
    place it (confidence ``uncertain``: the map then tests it at full resolution); one of
    them alone places nothing, nor do two 14 cm apart (one slid by a wall's thickness), nor
    two that agree but are also doubted for something their scans contradict (open space:
    look-alike rooms alias such links alike), unless full resolution clears both of open
    space."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    two = [_plain(P, "s2", "s3"), _plain(P, "s1", "s3")]
    assert all(e.plain for e in two) and not base[0].plain
    sol = solve_graph(sorted(P), [*base, *two], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and all(e.status == "accepted" for e in two)
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert sol.confidence["s3"] == "uncertain"
    assert uncertain_via("s3", "s0", [*base, *two]) in (["s2 <- s3"], ["s1 <- s3"])
    assert uncertain_via("s2", "s0", [*base, *two]) == []  # confident links all the way
    held = frozenset({"s0", "s1", "s2"})
    refuted = Veto("s0", "s3", invert(P["s0"]) @ P["s3"], "open space", held)
    two = [_plain(P, "s2", "s3"), _plain(P, "s1", "s3")]
    sol = solve_graph(sorted(P), [*base, *two], SurveyConfig(), reference="s0", vetoes=[refuted])
    assert "s3" not in sol.groups[0]  # the map refuted it at full resolution
    one = [_plain(P, "s2", "s3")]
    sol = solve_graph(sorted(P), [*base, *one], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    slid = [_plain(P, "s2", "s3"), _plain(P, "s1", "s3", _moved(P, "s1", "s3", [0.14, 0, 0]))]
    sol = solve_graph(sorted(P), [*base, *slid], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    doubted = [_plain(P, a, "s3", codes=("low_overlap", "free_space")) for a in ("s2", "s1")]
    assert not any(e.plain for e in doubted)
    sol = solve_graph(sorted(P), [*base, *doubted], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    # open space only the even sample finds, full resolution clearing each answer (stray
    # returns among racks): as plain as a doorway's
    for e in doubted:
        e.open_clear = True
    assert all(e.plain for e in doubted)
    sol = solve_graph(sorted(P), [*base, *doubted], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and sol.confidence["s3"] == "uncertain"
    doubted[0].open_clear = False  # one of them in open space at full resolution too
    sol = solve_graph(sorted(P), [*base, *doubted], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]


def _picked(P, a, b, right=True):
    """An uncertain link whose scans fit two poses a bay (6 m) apart, the rough positions
    having picked one (``right``: the true one) as its pose, the other kept as its twin."""
    true, bay = invert(P[a]) @ P[b], _moved(P, a, b, [6.0, 0, 0])
    e = _link(P, a, b, "uncertain", T=true if right else bay)
    e.reasons = [{"code": "ambiguous", "message": "two poses a bay apart fit"}]
    e.alternatives = [Alternative(bay if right else true, "twin", 0.95)]
    e.vouched = "positions"
    return e


def test_a_pose_rough_positions_picked_confirms_a_windowed_link_around_a_loop():
    """s3 seen from s2 by a link confident inside rough positions' window and from s1 by an
    uncertain one whose two poses a bay apart the positions decided between: when they
    agree around the loop s3 is placed (each pose registered on its own scans, the bay
    picked by the positions); the uncertain link alone places nothing, nor does one whose
    pose, undecided, is only its answer; a picked pose a bay off the windowed one places
    nothing either. Two picked poses with no confident registration among them place it
    when they agree around the loop (two registrations, the bay picked by the positions)
    and not when one is slid 14 cm (positions pick a bay, not centimetres)."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    two = [_windowed(P, "s2", "s3"), _picked(P, "s1", "s3")]
    sol = solve_graph(sorted(P), [*base, *two], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and all(e.status == "accepted" for e in two)
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    alone = [_picked(P, "s1", "s3")]
    sol = solve_graph(sorted(P), [*base, *alone], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    undecided = [_windowed(P, "s2", "s3"), _picked(P, "s1", "s3")]
    undecided[1].vouched = ""
    sol = solve_graph(sorted(P), [*base, *undecided], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    apart = [_windowed(P, "s2", "s3"), _picked(P, "s1", "s3", right=False)]
    sol = solve_graph(sorted(P), [*base, *apart], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    both = [_picked(P, "s2", "s3"), _picked(P, "s1", "s3")]  # no registration confident
    sol = solve_graph(sorted(P), [*base, *both], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and all(e.status == "accepted" for e in both)
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    slid = [_picked(P, "s2", "s3"), _picked(P, "s1", "s3")]
    slid[1].T_target_source = _moved(P, "s1", "s3", [0.14, 0, 0])
    sol = solve_graph(sorted(P), [*base, *slid], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]


def test_two_picked_poses_slid_alike_do_not_outrank_a_confident_link():
    """s3 seen by a link confident on its own (right) and by two doorway links whose poses
    the positions picked, both slid 12 cm alike (a wall's thickness: they agree with each
    other around the loop, not with the confident link): s3 is placed where the confident
    registration puts it, and the slid links are rejected with their loop error."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    slid_s3 = make_transform(np.eye(3), [0.12, 0.0, 0.0]) @ P["s3"]
    doors = [_picked(P, a, "s3") for a in ("s0", "s1")]
    for e in doors:
        e.T_target_source = invert(P[e.target]) @ slid_s3
    right = _link(P, "s2", "s3")
    sol = solve_graph(sorted(P), [*base, right, *doors], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and right.status == "accepted"
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert all(e.status == "rejected" and e.loop_error_m > 0.1 for e in doors)


class _Full:
    """The map's full-resolution test knowing the truth: at the true relative pose none of
    either scan in the other's open space and ``seen`` explained; anywhere else ``wrong`` in
    open space (a pose a few degrees off puts walls where the other saw through)."""

    def __init__(self, P, *, wrong=0.03, seen=0.2):
        self.P, self.wrong, self.seen, self.asked = P, wrong, seen, 0

    def __call__(self, a, b, T):
        self.asked += 1
        E = invert(invert(self.P[a]) @ self.P[b]) @ T
        right = np.linalg.norm(E[:3, 3]) < 0.05 and np.trace(E[:3, :3]) > 3 - 1e-5
        return (0.0 if right else self.wrong, self.seen, 100_000)


def _blind(a, b, T):
    """The sample's map check where stray returns at depth edges fill a tenth of every
    sample at every pose: it sees the stations, refutes nothing and cannot tell."""
    return (0.4, 0.1, 0.12)


def test_a_pose_rough_positions_picked_alone_is_placed_where_full_resolution_confirms_it():
    """s3 reached only by poses the rough positions picked, with no loop and no confident
    registration: the right one (s1 <- s3), and one turned 10 degrees (s2 <- s3; the
    positions' window allows 30), which the sample's map check cannot tell apart. The
    full-resolution test of s3 against the placed stations its link does not join decides:
    the right pose alone is placed (clean, and seen); with the turned one as well, the right
    one where the test refutes the turned one's placement, and nothing where it refutes
    neither or cannot see s3, or without the test, or when the picked link is a doorway's
    (a slide along a wall is what neither tells)."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    turned = (
        invert(P["s2"]) @ P["s3"] @ make_transform(rotation_about_axis([0, 0, 1], 0.17), [0, 0, 0])
    )

    def run(full, with_turned=True):
        right = _picked(P, "s1", "s3")
        found = [right]
        if with_turned:
            found.append(_picked(P, "s2", "s3"))
            found[1].T_target_source = turned
        sol = solve_graph(sorted(P), [*base, *found], SurveyConfig(), reference="s0",
                          judge=_blind, full=full)  # fmt: skip
        return sol, found

    sol, (right,) = run(_Full(P), with_turned=False)
    assert "s3" in sol.groups[0] and sol.confidence["s3"] == "uncertain"
    assert right.status == "accepted" and right.map_joined
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    full = _Full(P)
    sol, (right, wrong) = run(full)
    assert "s3" in sol.groups[0] and full.asked >= 2
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert right.status == "accepted" and wrong.status == "rejected"
    assert wrong.loop_error_deg > 5
    for unsure in (_Full(P, wrong=0.0), _Full(P, seen=0.001), None):
        sol, _ = run(unsure)
        assert "s3" not in sol.groups[0]
    sol, _ = run(_Full(P, seen=0.001), with_turned=False)
    assert "s3" not in sol.groups[0]
    # a doorway link (doubted for its small overlap) may slide along a wall, which neither
    # the positions nor the test tell: its picked pose alone places nothing
    door = _picked(P, "s1", "s3")
    door.reasons = [{"code": "low_overlap", "message": "the scans share little"}]
    sol = solve_graph(sorted(P), [*base, door], SurveyConfig(), reference="s0", judge=_blind,
                      full=_Full(P))  # fmt: skip
    assert "s3" not in sol.groups[0]


def test_a_loop_of_windowed_links_outranks_a_lone_confident_link_a_bay_off():
    """s3 placed by two links confident inside rough positions' windows that agree around
    the loop (right), and by one confident on its own but a bay (6 m) off: the placement the
    loop confirms wins, however many lone trusted answers the other has (the held-out
    warehouse 6007 with rough positions placed five stations a bay off the other way); the
    bay-off link is rejected with its loop error."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    loop = [_windowed(P, "s2", "s3"), _windowed(P, "s1", "s3")]
    bay = _link(P, "s0", "s3", T=_moved(P, "s0", "s3", [6.0, 0, 0]))
    sol = solve_graph(sorted(P), [*base, *loop, bay], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0] and all(e.status == "accepted" for e in loop)
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert bay.status == "rejected"
    # the lone confident link alone still places it, unchecked
    sol = solve_graph(sorted(P), [*base, bay], SurveyConfig(), reference="s0")
    assert "s3" in sol.groups[0]


def test_a_block_hanging_from_one_link_is_single_and_the_frame_is_the_largest_block():
    """Two blocks that loops of confident links hold together (a triangle s0-s2, a square
    with a diagonal s3-s6) joined by one confident link s2-s3: it closes no loop, so one
    registration fixes where each block lies from the other (a bay or a wall's thickness off
    in it moves the whole block, every station of it still two links deep). Without a
    reference given, the frame is the larger block's (its first station): its stations are
    ``confident``, the triangle's ``single``, resting on s2 <- s3; a reference given in the
    triangle makes the square ``single`` instead."""
    from flexreg.survey.graph import single_link

    P = _poses(7)
    tri = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    square = [_link(P, "s3", "s4"), _link(P, "s4", "s5"), _link(P, "s5", "s6"),
              _link(P, "s3", "s6"), _link(P, "s3", "s5")]  # fmt: skip
    links = [*tri, _link(P, "s2", "s3"), *square]
    sol = solve_graph(sorted(P), links, SurveyConfig())
    assert sorted(sol.groups[0]) == sorted(P) and all(e.status == "accepted" for e in links)
    assert sol.reference == "s3"
    np.testing.assert_allclose(sol.poses["s0"], invert(P["s3"]) @ P["s0"], atol=1e-6)
    assert sol.confidence == {**dict.fromkeys(["s0", "s1", "s2"], "single"),
                              **dict.fromkeys(["s3", "s4", "s5", "s6"], "confident")}  # fmt: skip
    assert single_link("s0", sol.reference, links) == "one confident link alone fixes it (s2 <- s3)"
    sol = solve_graph(sorted(P), links, SurveyConfig(), reference="s1")
    assert sol.reference == "s1"
    assert sol.confidence == {**dict.fromkeys(["s0", "s1", "s2"], "confident"),
                              **dict.fromkeys(["s3", "s4", "s5", "s6"], "single")}  # fmt: skip
    assert single_link("s6", "s1", links) == "one confident link alone fixes it (s2 <- s3)"


def test_a_station_one_confident_link_fixes_is_single():
    """s3 hangs on one confident link s2-s3; an uncertain link s1-s3 agrees with it (a view
    that repeats bay by bay aliases every link alike, so it adds no independent check): s3 is
    ``single``; the triangle's stations, two confident links each, are ``confident``."""
    P = _poses(4)
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2"),
             _link(P, "s2", "s3"), _link(P, "s1", "s3", "uncertain")]  # fmt: skip
    sol = solve_graph(sorted(P), links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == sorted(P) and all(e.status == "accepted" for e in links)
    assert sol.confidence == {"s0": "confident", "s1": "confident", "s2": "confident",
                              "s3": "single"}  # fmt: skip


def test_a_twin_closing_a_loop_with_a_bay_shifted_confident_link_confirms_nothing():
    """A hall of identical 6 m bays: s3 seen from s0 by a confident link one bay off, and
    from s2 by an uncertain link two bays off whose twin (one bay along) closes the triangle
    with it. A twin is no independent route (one of them agrees with any answer a whole
    number of bays off): s3 is not confirmed by that loop, and the map, knowing the truth,
    leaves it unplaced."""
    P = _poses(4)
    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    bay = np.array([6.0, 0.0, 0.0])

    def shifted(a, k):
        return invert(P[a]) @ make_transform(np.eye(3), k * bay) @ P["s3"]

    def links():
        wrong = _link(P, "s0", "s3", T=shifted("s0", 1))
        seq = _link(P, "s2", "s3", "uncertain", T=shifted("s2", 2))
        seq.alternatives = [Alternative(shifted("s2", 1), "twin", 0.9)]
        return wrong, seq

    wrong, seq = links()
    solve_graph(sorted(P), [*base, wrong, seq], SurveyConfig(), reference="s0")
    assert not wrong.confirmed_by_loop  # placed alone: the map did not check it here
    wrong, seq = links()
    sol = solve_graph(sorted(P), [*base, wrong, seq], SurveyConfig(), reference="s0",
                      judge=_Judge(P))  # fmt: skip
    assert "s3" not in sol.groups[0] and wrong.status == "rejected"
    # the same twin beside a right confident link: s3 placed (the twin is picked inside)
    right = _link(P, "s0", "s3")
    seq = _link(P, "s2", "s3", "uncertain", T=shifted("s2", 1))
    seq.alternatives = [Alternative(shifted("s2", 0), "twin", 0.9)]
    sol = solve_graph(sorted(P), [*base, right, seq], SurveyConfig(), reference="s0",
                      judge=_Judge(P))  # fmt: skip
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert seq.status == "accepted" and "twin" in (seq.picked or "")


class _Fit:
    """Where all the overlap of two groups fits, knowing the truth: from a start whose
    stations lie within ``basin`` metres of their true places, the true placement; from
    anywhere else, the start (a minimum of its own). Records what it was given."""

    def __init__(self, P, basin=0.3):
        self.P, self.basin, self.calls = P, basin, []

    def __call__(self, target, source, X):
        self.calls.append((sorted(target), sorted(source)))
        a, A = next(iter(target.items()))
        b, B = next(iter(source.items()))
        true = invert(self.P[a] @ invert(A)) @ self.P[b] @ invert(B)
        far = max(np.linalg.norm((X @ S)[:3, 3] - (true @ S)[:3, 3]) for S in source.values())
        return true if far <= self.basin else X


def test_a_doorway_link_slid_along_a_wall_reaches_the_right_one_fitted_on_all_overlap():
    """s3 seen through two doorways, from s1 and from s2, each link uncertain only for its
    small overlap, the one from s1 slid 14 cm along a wall (where its few shared points
    fit the wall's two faces). Fitted on all the overlap between the two groups, from
    either link's placement, s3 comes to one place, where s2's link puts it: s3 is placed
    there through s2's link, and s1's, off it, is rejected with its loop error. Two links
    that both slid (the fit comes to a place neither gives), or a second one a room (3 m)
    off (beyond the fit's reach: it is not even fitted), place nothing; nor, without the
    map's judge, does the slide."""
    P = _poses(4)

    def slid(a, offset):
        return _plain(P, a, "s3", _moved(P, a, "s3", offset))

    base = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    right, off = _plain(P, "s2", "s3"), slid("s1", [0.14, 0, 0])
    fit = _Fit(P)
    sol = solve_graph(sorted(P), [*base, right, off], SurveyConfig(), reference="s0",
                      judge=_Judge(P), fit=fit)  # fmt: skip
    assert "s3" in sol.groups[0] and sol.confidence["s3"] == "uncertain"
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)
    assert right.status == "accepted" and off.status == "rejected"
    assert off.loop_error_m is not None and 0.13 < off.loop_error_m < 0.15
    assert (off.why or "").startswith("slid")
    assert all(s == ["s3"] and {"s1", "s2"} <= set(t) for t, s in fit.calls)
    both = [slid("s2", [0, 0.1, 0]), slid("s1", [0.14, 0, 0])]
    sol = solve_graph(sorted(P), [*base, *both], SurveyConfig(), reference="s0",
                      judge=_Judge(P), fit=_Fit(P))  # fmt: skip
    assert "s3" not in sol.groups[0]
    fit = _Fit(P)
    room = [_plain(P, "s2", "s3"), slid("s1", [3.0, 0, 0])]  # the map cannot tell them apart
    sol = solve_graph(sorted(P), [*base, *room], SurveyConfig(), reference="s0",
                      judge=_Judge(P, wrong=0.02), fit=fit)  # fmt: skip
    assert "s3" not in sol.groups[0] and fit.calls == []
    right, off = _plain(P, "s2", "s3"), slid("s1", [0.14, 0, 0])
    sol = solve_graph(sorted(P), [*base, right, off], SurveyConfig(), reference="s0",
                      fit=_Fit(P))  # fmt: skip
    assert "s3" not in sol.groups[0]


def test_a_runner_up_that_explains_almost_nothing_at_full_resolution_is_no_alternative():
    """A street's plan turned half round scores well on the samples at long range (their
    tolerance grows with the range) yet explains almost nothing of the scans at full
    resolution: it is no pose the graph or the map may pick. Runner-ups not compared at
    full resolution, and those that explain a fair share there, stay alternatives."""
    from flexreg.core.results import Hypothesis
    from flexreg.registration.config import TWIN_MIN_RATIO, JudgeConfig
    from flexreg.survey.links import alternatives_of

    turned = make_transform(rotation_about_axis([0, 0, 1], np.pi), [6.1, -21.6, 0.0])
    bay = make_transform(np.eye(3), [5.9, 0.0, 0.0])
    near = make_transform(np.eye(3), [0.0, 3.0, 0.0])
    ups = [
        Hypothesis(turned, 0.64, 180.0, 48.4, "alias"),
        Hypothesis(bay, 0.9, 0.0, 5.9, "plan"),
        Hypothesis(near, 0.7, 0.0, 3.0, "descriptors"),
    ]
    duels = [{"full_support": 0.009}, {"full_support": TWIN_MIN_RATIO}, {}]
    kept = alternatives_of(np.eye(4), ups, None, JudgeConfig(), duels)
    assert [a.support for a in kept] == [0.9, 0.7]
    assert np.allclose(kept[0].T_target_source, bay)
    assert len(alternatives_of(np.eye(4), ups, None, JudgeConfig())) == 3  # nothing measured


def test_rough_positions_refute_a_station_placed_a_bay_off_by_links_aliased_alike():
    """Four stations in a row held by confident links, and a fifth whose two doorway links
    (uncertain only for their small overlap) both put it a bay (5.65 m) across from where it
    stood, the way a station's own look-alike bay aliases all its links alike: they agree
    around their loop, and without positions they place it. Rough positions of all five
    (0.5 m off, sigma 1 m) refute that placement: the row's fit to its positions puts the
    fifth 5 m from its own; the same links at the true pose place it."""
    from flexreg.survey.positions import Position

    P = {f"s{i}": make_transform(np.eye(3), [8.0 * i, 0.0, 0.0]) for i in range(4)}
    P["s4"] = make_transform(np.eye(3), [12.0, 7.0, 0.0])
    rng = np.random.default_rng(5)
    pos = {}
    for s, T in P.items():
        turn = rng.uniform(0, 2 * np.pi)
        off = 0.5 * np.array([np.cos(turn), np.sin(turn), 0.0])
        pos[s] = Position(T[:3, 3] + off, False, np.radians(rng.choice([-10.0, 10.0])), 1.0)
    row = [_link(P, f"s{i}", f"s{i + 1}") for i in range(3)] + [_link(P, "s0", "s2")]

    def doorways(offset):
        return [_plain(P, a, "s4", _moved(P, a, "s4", offset)) for a in ("s1", "s2")]

    sol = solve_graph(sorted(P), [*row, *doorways([0.0, 5.65, 0.0])], SurveyConfig())
    assert "s4" in sol.groups[0]  # aliased alike, the loop cannot tell
    sol = solve_graph(sorted(P), [*row, *doorways([0.0, 5.65, 0.0])], SurveyConfig(), positions=pos)
    assert "s4" not in sol.groups[0] and all(s in sol.groups[0] for s in ("s0", "s1", "s2"))
    sol = solve_graph(sorted(P), [*row, *doorways([0.0, 0.0, 0.0])], SurveyConfig(), positions=pos)
    assert "s4" in sol.groups[0]
    np.testing.assert_allclose(sol.poses["s4"], invert(P[sol.reference]) @ P["s4"], atol=1e-6)


def test_the_loop_errors_of_every_hypothesis_at_once_are_each_ones_own():
    """``_sets`` scores every hypothesis between two groups against each placement at once;
    each error is the one :func:`loop_error` gives that hypothesis alone (the stations'
    poses in their groups' frames, either station of a link in the second group)."""
    from flexreg.survey.consensus import Placement, _fit, _Fits

    rng = np.random.default_rng(7)

    def pose():
        return make_transform(
            rotation_about_axis(rng.normal(size=3), rng.uniform(-np.pi, np.pi)),
            rng.uniform(-20, 20, size=3),
        )

    stems = [f"s{i}" for i in range(6)]
    root = {s: ("s0" if i < 3 else "s3") for i, s in enumerate(stems)}
    place = Placement(root, {s: pose() for s in stems})
    links = [_link(None, a, b, T=pose()) for a, b in [("s0", "s3"), ("s4", "s1"), ("s2", "s5")]]
    hyps = [h for e in links for h in hypotheses_of(e)]
    hyps[1].refit = pose()  # a refitted pose is scored by its fit
    fits = _Fits(hyps, place, "s3")
    Xs = [pose(), np.eye(4), invert(place.pose["s3"]) @ place.pose["s0"]]
    degs, ms = fits.many(np.stack(Xs))
    assert degs.shape == ms.shape == (3, len(hyps))
    for X, deg, m in zip(Xs, degs, ms, strict=True):
        np.testing.assert_allclose(fits(X), (deg, m), rtol=0, atol=1e-9)
        for h, d, t in zip(hyps, deg, m, strict=True):
            want = _fit(h, place, X, "s3")
            assert abs(d - want[0]) < 1e-5 and abs(t - want[1]) < 1e-9
