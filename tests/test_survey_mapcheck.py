"""The map check: placed stations that contradict each other cut the links between them that no
loop confirms (else the most doubtful one)."""

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
    # s2 -> s4 first (the more doubtful of the path s1-s2-s4); then s3 -> s4 alone still
    # places s4 where the map refuted it, and goes too
    assert [(e.target, e.source) for e in cut] == [("s3", "s4"), ("s2", "s4")]
    assert all("s4 in s1's free space" in e.why for e in cut)
    for e in links[:5]:  # the correct links all stay
        assert e.status == "accepted"


def test_a_veto_cuts_the_links_no_loop_confirms_however_doubtful_the_confirmed_ones():
    """A hall that repeats bay by bay: the right links among s0, s1, s2 close a loop but
    show more free-space conflict (racks seen through racks) than the two wrong links that
    hang s3 and s4 from s2 a bay off. The map refutes s0 against s4: the cut falls on the
    links no loop confirms, not on the loop's most doubtful link."""
    P = _poses()
    bay = make_transform(np.eye(3), [0.0, 6.0, 0.0])  # one bay across
    W3, W4 = bay @ P["s3"], bay @ P["s4"]
    links = [
        _link(P, "s0", "s1", doubt=0.40),
        _link(P, "s1", "s2", doubt=0.42),
        _link(P, "s0", "s2", doubt=0.44),
        _link(P, "s2", "s3", doubt=0.12, T=invert(P["s2"]) @ W3),  # wrong, a bridge
        _link(P, "s3", "s4", doubt=0.20, T=invert(W3) @ W4),  # right relative to s3
    ]
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) == 5  # nothing yet says s3 and s4 are a bay off
    veto = Veto("s0", "s4", invert(sol.poses["s0"]) @ sol.poses["s4"], "s4 in s0's free space")
    sol = solve_graph(list(P), links, SurveyConfig(), reference="s0", vetoes=[veto])
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"]
    cut = [e for e in links if "cut by the map check" in (e.why or "")]
    assert [(e.target, e.source) for e in cut] == [("s2", "s3"), ("s3", "s4")]
    assert all("no loop confirms this one (2 of the 3 link(s)" in e.why for e in cut)
    for e in links[:3]:  # the loop stays, whatever its free-space conflict ratios
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
    links = [_link(P, "s0", "s1", doubt=0.10), _link(P, "s1", "s2", doubt=0.08),
             _link(P, "s2", "s3", doubt=0.02), _link(P, "s0", "s3", doubt=0.02)]  # fmt: skip
    sol = solve_graph(list(P)[:4], links, SurveyConfig(), reference="s0")
    assert len(sol.groups[0]) == 4
    veto = Veto("s0", "s2", invert(sol.poses["s0"]) @ sol.poses["s2"], "contradiction")
    sol = solve_graph(list(P)[:4], links, SurveyConfig(), reference="s0", vetoes=[veto])
    cut = [e for e in links if "cut by the map check" in (e.why or "")]
    assert links[0] in cut and links[1] in cut  # 0.08 * 1.5 >= 0.10: both cut at once
    assert "s1" not in sol.poses


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
    judge = PairJudge(files, glances, cfg, keep_bytes=1)  # one view at a time
    look = judge.look("station_00", "station_01", T)
    assert look is not None and look.explained[0] == ok_true and look.conflicting[0] == bad_true
    assert not look.conflicts(cfg)
    wrong = judge.look("station_00", "station_01", moved)
    assert wrong is not None and wrong.conflicts(cfg)
    r_true, _, x_true = judge("station_00", "station_01", T)
    r_moved, c_moved, _ = judge("station_00", "station_01", moved)
    assert x_true > 0.1  # the right pose explains much of both
    assert r_true < 0.2 < 0.5 < r_moved and c_moved >= bad_moved
    assert judge("station_00", "nowhere", T) is None
    # kept for a later run: a new judge answers the same from the cache, without a view
    judge.keep()
    later = PairJudge(files, glances, cfg)
    again = later.look("station_00", "station_01", T)
    assert again is not None and (again.explained, again.conflicting, again.samples) == (
        look.explained, look.conflicting, look.samples)  # fmt: skip
    assert later("station_00", "station_01", moved) == judge("station_00", "station_01", moved)
    assert later._views == {}  # nothing was scored again
    other = make_transform(np.eye(3), [0.0, 0.0, 0.5]) @ T  # a new placement: kept alone
    assert later.look("station_00", "station_01", other) is not None
    later.keep()
    with np.load(later.kept_path()) as z:
        assert len(z["keys"]) == 3  # the two it recalled and the new one
    last = PairJudge(files, glances, cfg)
    last.look("station_00", "station_01", other)
    last._new = 1  # as if it had scored something: only what it asked for is kept
    last.keep()
    with np.load(last.kept_path()) as z:
        assert len(z["keys"]) == 1
    with open(later.kept_path(), "wb") as f:  # damaged: scored again, with a warning
        f.write(b"not looks")
    third = PairJudge(files, glances, cfg)
    assert third.look("station_00", "station_01", T).explained == look.explained
    assert third._views != {}
    # the map check scores on the workers only what no judge has scored at the same pose,
    # and keeps it: a second round (or run) at the same poses recalls it
    from flexreg.survey.mapcheck import pair_looks

    calls = []

    def run(fn, items):
        calls.append(len(items))
        return [fn(*item) for item in items]

    T2 = make_transform(np.eye(3), [0.01, 0.0, 0.0]) @ T
    poses, pair = {"station_00": np.eye(4), "station_01": T2}, [("station_00", "station_01")]
    first = pair_looks(pair, poses, (files, glances), later, run)
    again = pair_looks(pair, poses, (files, glances), later, run)
    assert calls == [2, 0]  # each station's view once, then nothing
    assert [(x.explained, x.conflicting, x.samples) for x in again] == [
        (x.explained, x.conflicting, x.samples) for x in first]  # fmt: skip
    own = PairJudge(files, glances, cfg).look("station_00", "station_01", T2)  # in process
    assert own is not None and own.explained == first[0].explained
    assert own.conflicting == first[0].conflicting


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
