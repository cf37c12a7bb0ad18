"""The map check: placed stations that contradict each other cut the most doubtful link."""

from __future__ import annotations

import numpy as np

from flexreg.core.transforms import invert, make_transform, rotation_about_axis
from flexreg.survey.config import SurveyConfig
from flexreg.survey.graph import Link, Veto, solve_graph
from flexreg.survey.mapcheck import PairLook, assemble, pairs_to_check, plan_looks

INFO = np.diag([2e5, 2e5, 2e5, 1e4, 1e4, 1e4])


def _poses() -> dict[str, np.ndarray]:
    """Five stations 5 m apart along x, each turned a little about z."""
    return {
        f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.3 * i), [5.0 * i, 0.0, 0.0])
        for i in range(5)
    }


def _link(P, a, b, *, doubt, T=None, verdict="confident"):
    T = invert(P[a]) @ P[b] if T is None else T
    return Link(a, b, T, INFO, verdict, overlap_target=0.5, overlap_source=0.5, doubt=doubt)


def _chain_with_an_aliased_station():
    """s0-s1-s2-s3 correct (and s0-s2, s1-s3 closing loops); s4 linked to s3 and s2 by two
    links that agree with each other but put it 10 m off (an identical room elsewhere)."""
    P = _poses()
    wrong = make_transform(np.eye(3), [10.0, 0, 0]) @ P["s4"]  # where the aliases put s4
    links = [
        _link(P, "s0", "s1", doubt=0.05),
        _link(P, "s1", "s2", doubt=0.04),
        _link(P, "s2", "s3", doubt=0.06),
        _link(P, "s0", "s2", doubt=0.05),
        _link(P, "s1", "s3", doubt=0.03),
        _link(P, "s3", "s4", doubt=0.35, T=invert(P["s3"]) @ wrong),
        _link(P, "s2", "s4", doubt=0.30, T=invert(P["s2"]) @ wrong),
    ]
    return P, wrong, links


def test_without_a_veto_agreeing_aliased_links_place_a_station_wrongly():
    P, wrong, links = _chain_with_an_aliased_station()
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    assert "s4" in sol.groups[0]
    np.testing.assert_allclose(sol.poses["s4"][:3, 3], (invert(P["s0"]) @ wrong)[:3, 3], atol=1e-6)


def test_a_veto_cuts_the_most_doubtful_links_until_the_station_is_unplaced():
    P, _wrong, links = _chain_with_an_aliased_station()
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    veto = Veto("s1", "s4", invert(sol.poses["s1"]) @ sol.poses["s4"], "s4 in s1's free space")
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", vetoes=[veto])
    assert "s4" not in sol.groups[0]
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2", "s3"]
    cut = [e for e in links if e.why and "cut by the map check" in e.why]
    assert [(e.target, e.source) for e in cut] == [("s2", "s4")]
    assert "s4 in s1's free space" in cut[0].why
    # then s3 -> s4 alone places s4, unconfirmed and far more doubtful than the confirmed
    assert links[5].status == "rejected" and "may be a wrong match" in links[5].why
    for e in links[:5]:  # the correct links all stay
        assert e.status == "accepted"


def test_a_veto_no_longer_matching_the_solution_cuts_nothing():
    P, _, links = _chain_with_an_aliased_station()
    elsewhere = make_transform(np.eye(3), [0, 30.0, 0])  # a configuration the graph never had
    veto = Veto("s1", "s4", elsewhere, "an older configuration")
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", vetoes=[veto])
    assert "s4" in sol.groups[0]
    assert not any(e.why and "map check" in e.why for e in links)


def test_when_no_link_stands_out_every_similarly_doubtful_one_on_the_path_is_cut():
    P = _poses()
    links = [_link(P, "s0", "s1", doubt=0.10), _link(P, "s1", "s2", doubt=0.08)]
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0")
    veto = Veto("s0", "s2", invert(sol.poses["s0"]) @ sol.poses["s2"], "contradiction")
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0", vetoes=[veto])
    assert all(e.status == "rejected" for e in links)  # 0.08 * 1.5 >= 0.10: both cut
    assert sol.poses == {}


def test_a_pair_conflicts_when_contradiction_outweighs_explanation_in_one_direction():
    cfg = SurveyConfig()  # map_min_conflict 0.03, map_conflict_ratio 1.0
    T = make_transform(np.eye(3), [5.0, 0.0, 0.0])  # 5 m apart: two viewpoints
    assert PairLook("a", "b", T, (0.04, 0.02), (0.08, 0.05), (100, 100)).conflicts(cfg)
    assert PairLook("a", "b", T, (0.50, 0.02), (0.08, 0.03), (100, 100)).conflicts(cfg)
    # correct but barely overlapping: little explained, less contradicted
    assert not PairLook("a", "b", T, (0.05, 0.04), (0.02, 0.01), (100, 100)).conflicts(cfg)
    # moving objects on a well-overlapping pair: more explained than contradicted
    assert not PairLook("a", "b", T, (0.30, 0.25), (0.09, 0.08), (100, 100)).conflicts(cfg)
    # tiny shares are not evidence
    assert not PairLook("a", "b", T, (0.0, 0.0), (0.02, 0.0), (100, 100)).conflicts(cfg)
    look = PairLook("a", "b", T, (0.04, 0.02), (0.08, 0.05), (100, 100))
    assert (
        look.describe() == "8.0% of b's points lie where a saw open space and 4.0% on its surfaces"
    )


def test_pairs_within_the_radius_of_one_group_are_checked_both_ways():
    P = _poses()
    pairs = pairs_to_check([["s0", "s1", "s2"], ["s3", "s4"]], P, radius_m=7.0)
    assert pairs == [("s0", "s1"), ("s1", "s2"), ("s3", "s4")]
    glances = {s: f"{s}.glance.npz" for s in P}
    todo = plan_looks(pairs, P, glances)
    assert [b for b, _, _ in todo["s1"]] == ["s0", "s2"]
    _b, g, T = todo["s1"][1]
    assert g == "s2.glance.npz"
    np.testing.assert_allclose(T, invert(P["s1"]) @ P["s2"])
    seen = {
        "s0": {"s1": (0.5, 0.01, 10)},
        "s1": {"s0": (0.4, 0.02, 12), "s2": (0.3, 0.0, 10)},
        "s2": {"s1": (0.2, 0.06, 11)},
    }
    looks = assemble(pairs, P, seen)  # s3-s4 had no results: left out
    assert [(x.a, x.b) for x in looks] == [("s0", "s1"), ("s1", "s2")]
    assert looks[1].explained == (0.3, 0.2) and looks[1].conflicting == (0.0, 0.06)
    assert looks[1].samples == (10, 11)


def test_a_station_placed_in_the_wrong_spot_contradicts_its_neighbour(tmp_path):
    """Real prepared stations of a synthetic room, at fixed poses (seeded placement depends
    on ray-cast ties that differ across CPUs). At the true relative pose one station's sample
    lies on the other's surfaces, bar the noise and edge returns; turned half a turn and
    dropped 1 m, its floor and walls cut through the other's free space. The margins are
    ratios of the two shares, which the geometry sets (not one machine's output): at the
    truth the explained share is above 4x the conflicting one (about 17x here), at the wrong
    pose the conflicting share is above 3x the explained one (about 7x here)."""
    from flexreg.registration.pipeline import Registration
    from flexreg.survey.mapcheck import PairJudge, look_from, write_glance
    from flexreg.survey.stations import save_prepared
    from flexreg.synth import TLSConfig, make_scene, scan_tls

    scene = make_scene("room", 1)  # a furnished room of about 14.5 x 13 m, floor at z = 0
    W = {
        "station_00": make_transform(np.eye(3), [6.5, 6.4, 1.5]),
        "station_01": make_transform(rotation_about_axis([0, 0, 1], 0.8), [8.5, 7.6, 1.4]),
    }
    reg = Registration()
    files = {}
    for k, (name, pose) in enumerate(W.items()):
        scan = scan_tls(scene, pose, config=TLSConfig(width=512, height=256), rng=k)
        f = tmp_path / f"{name}.prepared.npz"
        save_prepared(reg.prepare(scan), f)
        files[name] = str(f)
    glances = {n: write_glance(f) for n, f in files.items()}
    assert all(g is not None and g.endswith(".glance.npz") for g in glances.values())
    assert write_glance(files["station_00"]) == glances["station_00"]  # written once
    T = invert(W["station_00"]) @ W["station_01"]
    moved = make_transform(rotation_about_axis([0, 0, 1], np.pi), [0.0, 0.0, -1.0]) @ T
    res = look_from(
        files["station_00"],
        glances["station_00"],
        [("station_01", glances["station_01"], T), ("station_01", glances["station_01"], moved)],
    )
    (_, ok_true, bad_true, n), (_, ok_moved, bad_moved, _) = res
    assert n > 1000
    assert ok_true > 4 * bad_true and ok_true > 0.1
    assert bad_moved > 3 * ok_moved and bad_moved > bad_true and ok_moved < ok_true
    # the graph's judge scores the same pair the same way, both directions at once, and
    # calls the wrong pose a conflict with the survey's own thresholds, the true one not
    cfg = SurveyConfig()
    judge = PairJudge(files, glances, cfg, keep=1)
    look = judge.look("station_00", "station_01", T)
    assert look is not None and look.explained[0] == ok_true and look.conflicting[0] == bad_true
    assert not look.conflicts(cfg)
    wrong = judge.look("station_00", "station_01", moved)
    assert wrong is not None and wrong.conflicts(cfg)
    r_true, _ = judge("station_00", "station_01", T)
    r_moved, c_moved = judge("station_00", "station_01", moved)
    assert r_true < 0.2 < 0.5 < r_moved and c_moved >= bad_moved
    assert judge("station_00", "nowhere", T) is None


def test_in_a_disagreeing_triangle_a_link_far_more_doubtful_than_the_others_is_the_one_dropped():
    P = _poses()
    off = make_transform(rotation_about_axis([0, 0, 1], np.pi / 2), [4.0, 1.0, 0.0])
    links = [
        _link(P, "s0", "s1", doubt=0.01),
        _link(P, "s0", "s2", doubt=0.08),
        _link(P, "s1", "s2", doubt=0.28, T=off @ invert(P["s1"]) @ P["s2"]),  # wrong
    ]
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert [e.status for e in links] == ["accepted", "accepted", "rejected"]
    # without the doubts nobody can tell which link of the lone triangle is wrong
    for e in links:
        e.doubt = None
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) < 3


def _ambiguous(link: Link) -> Link:
    link.verdict = "uncertain"
    link.reasons = [{"code": "ambiguous", "message": "a clearly different pose fits as well"}]
    return link


def test_a_lone_link_is_not_trusted_where_an_ambiguous_link_agrees_with_it():
    """s3 hangs on one confident link (no loop confirms it); an ambiguous link from s1 puts
    it in the same place: the configuration is one of twins, so s3 stays unplaced."""
    P = _poses()
    twin = make_transform(rotation_about_axis([0, 0, 1], np.pi), [6.0, 0, 0]) @ P["s3"]
    links = [
        _link(P, "s0", "s1", doubt=0.02),
        _link(P, "s1", "s2", doubt=0.03),
        _link(P, "s0", "s2", doubt=0.02),
        _link(P, "s2", "s3", doubt=0.05, T=invert(P["s2"]) @ twin),
        _ambiguous(_link(P, "s1", "s3", doubt=0.04, T=invert(P["s1"]) @ twin)),
    ]
    names = ["s0", "s1", "s2", "s3"]
    sol = solve_graph(names, links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert links[3].status == "rejected" and "another pose fits about as well" in links[3].why
    # an ambiguous link that disagrees with the lone link says nothing about it
    links[4].T_target_source = invert(P["s1"]) @ P["s3"]
    sol = solve_graph(names, links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == names
    # and the rule can be switched off
    links[4].T_target_source = invert(P["s1"]) @ twin
    sol = solve_graph(names, links, SurveyConfig(trust_lone_links=True), reference="s0")
    assert sorted(sol.groups[0]) == names


def test_a_lone_link_more_doubtful_than_every_confirmed_link_places_nothing():
    P = _poses()
    names = ["s0", "s1", "s2", "s3"]

    def links(lone_doubt):
        return [
            _link(P, "s0", "s1", doubt=0.05),
            _link(P, "s1", "s2", doubt=0.12),
            _link(P, "s0", "s2", doubt=0.04),
            _link(P, "s2", "s3", doubt=lone_doubt),  # no loop confirms it
        ]

    ls = links(0.40)
    sol = solve_graph(names, ls, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert ls[3].status == "rejected"
    assert "so it may be a wrong match (free-space conflict ratio 0.40" in ls[3].why
    assert "checked links at most 0.15)" in ls[3].why  # their 0.12, floored at loop_doubt_min
    for d in (0.14, None):  # under the floor, or unknown: trusted like the confirmed links
        sol = solve_graph(names, links(d), SurveyConfig(), reference="s0")
        assert sorted(sol.groups[0]) == names
    sol = solve_graph(names, links(0.40), SurveyConfig(trust_lone_links=True), reference="s0")
    assert sorted(sol.groups[0]) == names


def test_the_lone_link_ceiling_comes_from_the_loops_where_it_attaches():
    """A region folded onto itself (a separate group here) has its wrong links confirmed by
    loops of wrong links, at a doubt of 0.45: that says nothing about a lone link attaching
    a station to the reference's part, whose loops carry 0.05."""
    P = _poses() | {f"t{i}": make_transform(np.eye(3), [2.0 * i, 30.0, 0.0]) for i in range(3)}
    links = [
        _link(P, "s0", "s1", doubt=0.05),
        _link(P, "s1", "s2", doubt=0.05),
        _link(P, "s0", "s2", doubt=0.04),
        _link(P, "s2", "s3", doubt=0.30),  # lone: the only link placing s3
        _link(P, "t0", "t1", doubt=0.45),
        _link(P, "t1", "t2", doubt=0.45),
        _link(P, "t0", "t2", doubt=0.45),
    ]
    names = ["s0", "s1", "s2", "s3", "t0", "t1", "t2"]
    sol = solve_graph(names, links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert links[3].status == "rejected" and "at most 0.15)" in links[3].why
    assert sorted(sol.groups[1]) == ["t0", "t1", "t2"]


def test_an_ambiguous_link_blames_the_most_doubtful_tree_link_of_its_twin_placement():
    """s0-s1-s2 confirmed; s2-s3 right but lone; s3-s4 and s3-s5 put s4 and s5 into the twin
    room (doubt 0.35), and s4-s5 between the twins confirms them by a loop. The ambiguous
    link s2 <- s4 agrees with the twin placement: the wrong links go, not s2-s3."""
    P = _poses() | {"s5": make_transform(np.eye(3), [22.0, 3.0, 0.0])}
    twin = make_transform(rotation_about_axis([0, 0, 1], np.pi), [40.0, 0.0, 0.0])
    Q = {**P, "s4": twin @ P["s4"], "s5": twin @ P["s5"]}  # where the twin links put them
    links = [
        _link(P, "s0", "s1", doubt=0.40),  # a hall: right links carry 0.4 (no ceiling rule)
        _link(P, "s1", "s2", doubt=0.40),
        _link(P, "s0", "s2", doubt=0.40),
        _link(P, "s2", "s3", doubt=0.10),
        _link(Q, "s3", "s4", doubt=0.35),
        _link(Q, "s3", "s5", doubt=0.34),
        _link(P, "s4", "s5", doubt=0.05),
        _ambiguous(_link(Q, "s2", "s4", doubt=0.30)),
    ]
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2", "s3"]
    assert links[3].status == "accepted"
    assert links[4].status == links[5].status == "rejected"
    assert any("the least trustworthy" in (e.why or "") for e in links[4:6])
    np.testing.assert_allclose(sol.poses["s3"], invert(P["s0"]) @ P["s3"], atol=1e-6)


def _truth_judge(P, *, noise=0.01, wrong=0.08):
    """A judge that knows the truth: two stations placed within 1 m of their true relative
    pose contradict each other by ``noise``, anywhere else by ``wrong``."""
    calls = []

    def judge(a, b, T):
        calls.append((a, b))
        true = invert(P[a]) @ P[b]
        r = noise if np.linalg.norm(T[:3, 3] - true[:3, 3]) < 1.0 else wrong
        return r, r

    return judge, calls


def _twin_triangle():
    """s0-s1 and s1-s2 right; s0-s2 overlays two identical rooms (wrong), equally doubtful."""
    P = _poses()
    twin = make_transform(rotation_about_axis([0, 0, 1], np.pi), [3.0, 2.0, 0.0])
    links = [
        _link(P, "s0", "s1", doubt=0.05),
        _link(P, "s1", "s2", doubt=0.05),
        _link(P, "s0", "s2", doubt=0.05, T=twin @ invert(P["s0"]) @ P["s2"]),
    ]
    return P, links


def test_the_map_blames_the_link_whose_removal_leaves_the_loop_consistent():
    P, links = _twin_triangle()
    # no doubt stands out: without a judge the whole triangle is dropped
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) < 3
    judge, calls = _truth_judge(P)
    sol = solve_graph(list(P)[:3], links, SurveyConfig(), reference="s0", judge=judge)
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    assert [e.status for e in links] == ["accepted", "accepted", "rejected"]
    assert "the map blames it" in links[2].why
    np.testing.assert_allclose(sol.poses["s2"], invert(P["s0"]) @ P["s2"], atol=1e-6)
    assert {frozenset(c) for c in calls} == {frozenset(("s0", "s1")), frozenset(("s1", "s2")),
                                              frozenset(("s0", "s2"))}  # fmt: skip


def test_the_map_decides_nothing_when_the_others_do_not_contradict_clearly_more():
    P, links = _twin_triangle()
    config = SurveyConfig()
    for wrong in (0.025, 0.02):  # 2.5x the clean hypothesis; then below map_min_conflict
        judge, _ = _truth_judge(P, noise=0.01, wrong=wrong)
        sol = solve_graph(list(P)[:3], links, config, reference="s0", judge=judge)
        assert len(sol.groups[0]) < 3
        assert not any(e.why and "map blames" in e.why for e in links)
    # two hypotheses equally clean (the judge cannot tell the pair apart): nothing decided
    sol = solve_graph(list(P)[:3], links, config, reference="s0", judge=lambda *_: (0.01, 0.01))
    assert len(sol.groups[0]) < 3
    # a pair the judge cannot score: nothing decided either
    sol = solve_graph(list(P)[:3], links, config, reference="s0", judge=lambda *_: None)
    assert len(sol.groups[0]) < 3


def test_judged_culprit_on_a_hand_scored_loop():
    from flexreg.survey.links import implied_pose, judged_culprit

    P, links = _twin_triangle()
    # the rest of the loop places s0 and s2 at their true relative pose
    np.testing.assert_allclose(implied_pose(links, links[2]), invert(P["s0"]) @ P["s2"], atol=1e-9)
    scores = {("s0", "s1"): (0.09, 0.06), ("s1", "s2"): (0.04, 0.04), ("s0", "s2"): (0.01, 0.01)}

    def judge(a, b, T):
        return scores[(a, b)]

    assert judged_culprit(links, judge, 3.0, 0.03) is links[2]
    assert judged_culprit(links, judge, 5.0, 0.03) is None  # 0.04 is only 4x 0.01
    assert judged_culprit(links, judge, 3.0, 0.05) is None  # s1-s2 conflicts only 0.04
    assert judged_culprit(links, None, 3.0, 0.03) is None


def test_two_stations_placed_at_one_spot_must_see_the_same_scene():
    """A warehouse folded onto itself puts stations of different aisles at one spot: their
    scans agree on the racks (60 % explained) but not on the far walls."""
    config = SurveyConfig()
    near = make_transform(np.eye(3), [0.3, 0.0, 0.0])
    folded = PairLook("a", "b", near, (0.6, 0.62), (0.1, 0.08), (100, 100))
    assert folded.distance_m == 0.3
    assert folded.coincident(config) and folded.conflicts(config)
    assert "they cannot both stand there" in folded.describe(config)
    repeated_setup = PairLook("a", "b", near, (0.93, 0.95), (0.01, 0.01), (100, 100))
    assert not repeated_setup.conflicts(config)
    apart = PairLook("a", "b", make_transform(np.eye(3), [3.0, 0, 0]), (0.6, 0.62),
                     (0.1, 0.08), (100, 100))  # fmt: skip
    assert not apart.conflicts(config)
    assert not folded.conflicts(SurveyConfig(map_coincident_m=0.0))
