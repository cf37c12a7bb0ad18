"""The survey's station graph on hand-built graphs, and its candidate pairs."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.core.transforms import (
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import InputError
from flexreg.survey.config import SurveyConfig
from flexreg.survey.graph import Link, solve_graph
from flexreg.survey.links import Alternative, GraphSolution
from flexreg.survey.pairs import (
    auto_pairs,
    chain_pairs,
    hypothesis_pairs,
    later_pairs,
    place_score,
    read_pairs_csv,
    sequential_order,
    sequential_pairs,
)
from flexreg.survey.stations import GlobalDescriptor

INFO = np.diag([2e5, 2e5, 2e5, 1e4, 1e4, 1e4])


def _grid(n_side: int, spacing: float = 5.0, seed: int = 0) -> dict[str, np.ndarray]:
    """World poses of stations on a grid, each turned about z and a little tilted."""
    rng = np.random.default_rng(seed)
    poses = {}
    for i in range(n_side * n_side):
        R = rotation_about_axis([rng.normal(0, 0.02), rng.normal(0, 0.02), 1], rng.uniform(-3, 3))
        t = [spacing * (i % n_side), spacing * (i // n_side), rng.uniform(-0.1, 0.1)]
        poses[f"s{i:02d}"] = make_transform(R, t)
    return poses


def _link(P, a, b, verdict="confident", *, T=None, overlap=0.5, noise=0.0, rng=None):
    T_true = invert(P[a]) @ P[b]
    if T is None:
        T = T_true
        if noise:
            dR = rotation_about_axis(rng.normal(size=3), np.radians(noise * 2))
            T = make_transform(dR, rng.normal(0, noise, 3)) @ T_true
    return Link(a, b, T, INFO, verdict, overlap_target=overlap, overlap_source=overlap)


def _grid_links(P, n_side, **kw):
    names = sorted(P)
    links = []
    for i in range(n_side * n_side):
        if i % n_side < n_side - 1:
            links.append(_link(P, names[i], names[i + 1], **kw))
        if i + n_side < n_side * n_side:
            links.append(_link(P, names[i], names[i + n_side], **kw))
    return links


def _errors(sol, P):
    ref = sol.reference
    out = {}
    for s, T in sol.poses.items():
        if s in sol.groups[0]:
            truth = invert(P[ref]) @ P[s]
            out[s] = (rotation_error_deg(T, truth), translation_error_m(T, truth))
    return out


def test_a_planted_wrong_link_is_rejected_with_its_loop_error():
    P = _grid(3)
    links = _grid_links(P, 3)
    # the strongest link of all, 30 degrees and 3 m wrong: it enters the first tree
    wrong = make_transform(rotation_about_axis([0, 0, 1], np.radians(30)), [3, 0, 0])
    bad = _link(P, "s00", "s04", T=wrong @ invert(P["s00"]) @ P["s04"], overlap=0.9)
    links.append(bad)
    sol = solve_graph(sorted(P), links, SurveyConfig())
    assert bad.status == "rejected"
    assert bad.loop_error_deg == pytest.approx(30.0, abs=0.5)
    assert bad.loop_error_m > 1.0
    assert all(e.status == "accepted" for e in links if e is not bad)
    assert sorted(sol.groups[0]) == sorted(P)
    assert all(r < 1e-6 and t < 1e-9 for r, t in _errors(sol, P).values())
    assert sol.stats["max_link_error_m"] < 1e-9


def test_a_wrong_link_closing_a_loop_is_rejected_and_the_rest_kept():
    P = _grid(3, seed=1)
    links = _grid_links(P, 3)
    wrong = make_transform(rotation_about_axis([0, 0, 1], np.radians(2)), [0.5, 0.2, 0])
    bad = _link(P, "s01", "s05", T=wrong @ invert(P["s01"]) @ P["s05"], overlap=0.1)
    links.append(bad)
    solve_graph(sorted(P), links)
    assert bad.status == "rejected" and "loop" in (bad.why or "")
    assert bad.loop_error_deg == pytest.approx(2.0, abs=0.05)


def test_noisy_links_are_optimised_into_consistent_poses():
    rng = np.random.default_rng(3)
    P = _grid(3, seed=2)
    links = _grid_links(P, 3, noise=0.002, rng=rng)
    sol = solve_graph(sorted(P), links, reference="s04")
    assert sol.reference == "s04"
    assert all(e.status == "accepted" for e in links)
    errs = _errors(sol, P)
    assert len(errs) == 9
    assert max(t for _, t in errs.values()) < 0.02
    assert max(r for r, _ in errs.values()) < 0.2
    # the optimised poses spread the noise: every link's residual is within the loop limits
    assert sol.stats["max_link_error_m"] < 0.02


def test_one_triangle_cannot_tell_which_link_is_wrong_so_nothing_is_placed_wrongly():
    P = _grid(2, seed=4)
    names = ["s00", "s01", "s02"]
    wrong = make_transform(rotation_about_axis([0, 0, 1], np.radians(20)), [1, 0, 0])
    links = [
        _link(P, "s00", "s01", T=wrong @ invert(P["s00"]) @ P["s01"], overlap=0.9),
        _link(P, "s01", "s02", overlap=0.6),
        _link(P, "s00", "s02", overlap=0.5),
    ]
    sol = solve_graph(names, links)
    for s, (r, t) in _errors(sol, P).items():
        assert r < 1e-6 and t < 1e-9, s  # placed only where right
    assert links[0].status == "rejected"


def test_uncertain_links_alone_place_nothing_even_two_that_agree():
    P = _grid(2, seed=5)
    names = sorted(P)
    base = [_link(P, "s00", "s01"), _link(P, "s01", "s02"), _link(P, "s00", "s02")]
    lone = _link(P, "s02", "s03", verdict="uncertain")
    sol = solve_graph(names, [*base, lone])
    assert "s03" not in sol.groups[0]
    assert lone.status == "rejected" and "uncertain" in lone.why
    assert "separate" not in sol.reasons["s03"]
    second = _link(P, "s01", "s03", verdict="uncertain")
    lone = _link(P, "s02", "s03", verdict="uncertain")
    sol = solve_graph(names, [*base, lone, second])  # a loop, of uncertain links only
    assert "s03" not in sol.groups[0] and lone.status == second.status == "rejected"
    # look-alike rooms make uncertain links wrong in the same way: a loop of trusted links
    # confirms a pose, a loop of uncertain ones does not (the map may pick among placements)


def test_two_uncertain_links_that_disagree_place_nothing():
    P = _grid(2, seed=6)
    names = sorted(P)
    base = [_link(P, "s00", "s01"), _link(P, "s01", "s02"), _link(P, "s00", "s02")]
    off = make_transform(np.eye(3), [2.0, 0, 0])
    a = _link(P, "s02", "s03", verdict="uncertain")
    b = _link(P, "s01", "s03", verdict="uncertain", T=off @ invert(P["s01"]) @ P["s03"])
    sol = solve_graph(names, [*base, a, b])
    assert "s03" not in sol.groups[0]
    assert a.status == b.status == "rejected"


def test_separate_groups_are_reported_never_fused():
    P = _grid(3, seed=7)
    names = sorted(P)
    links = [
        _link(P, "s00", "s01"),
        _link(P, "s01", "s02"),
        _link(P, "s00", "s02"),
        _link(P, "s06", "s07"),
        _link(P, "s07", "s08"),
        _link(P, "s06", "s08"),
    ]
    sol = solve_graph(names, links)
    assert sorted(sol.groups[0]) == ["s00", "s01", "s02"]
    assert sorted(sol.groups[1]) == ["s06", "s07", "s08"]
    assert "separate group of 3" in sol.reasons["s07"]
    # the second group is solved in its own frame, correctly
    g1 = sol.group_reference[1]
    T = sol.poses["s08"] if g1 != "s08" else sol.poses["s06"]
    other = "s08" if g1 != "s08" else "s06"
    truth = invert(P[g1]) @ P[other]
    assert translation_error_m(T, truth) < 1e-9
    for single in ("s03", "s04", "s05"):
        assert "no link was tried" in sol.reasons[single]


def test_failed_links_and_an_unknown_reference():
    P = _grid(2)
    names = sorted(P)
    failed = Link("s00", "s03", why="only 2 inliers")
    links = [_link(P, "s00", "s01"), failed]
    sol = solve_graph(names, links)
    assert failed.status == "failed"
    assert "failed" in sol.reasons["s03"]
    with pytest.raises(InputError, match="not one of the stations"):
        solve_graph(names, links, reference="nope")


def test_candidate_pairs():
    stems = [f"scan_{i}" for i in (10, 2, 1)]
    assert sequential_order(stems) == ["scan_1", "scan_2", "scan_10"]
    assert sequential_order(["a1", "b2"]) is None
    seq = sequential_pairs(["s1", "s2", "s3"], 1)
    assert [(c.target, c.source) for c in seq] == [("s1", "s2"), ("s2", "s3")]
    # 64 stations, every pair scored: at most 6 N links, about linear in N
    stems = [f"st{i:02d}" for i in range(64)]
    rng = np.random.default_rng(0)
    scores = {
        frozenset((a, b)): int(rng.integers(0, 40))
        for i, a in enumerate(stems)
        for b in stems[i + 1 :]
    }
    cands = auto_pairs(stems, scores, neighbours=1, place_candidates=3, max_links=6 * 64)
    assert 63 <= len(cands) <= 4 * 64
    assert len({c.key for c in cands}) == len(cands)


def test_pairs_csv(tmp_path):
    f = tmp_path / "pairs.csv"
    f.write_text("target,source\na,b\nb.ptx,c\n")
    got = read_pairs_csv(f, ["a", "b", "c"])
    assert [(c.target, c.source, c.origin) for c in got] == [("a", "b", "file"), ("b", "c", "file")]
    f.write_text("a,x\n")
    with pytest.raises(InputError, match="'x' is not one of the stations"):
        read_pairs_csv(f, ["a", "b"])


def test_place_score_is_invariant_to_the_station_pose():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-10, 10, (200, 3))
    desc = rng.normal(size=(200, 32)).astype(np.float32)
    a = GlobalDescriptor(desc, pts, False)
    T = make_transform(rotation_about_axis([0, 0, 1], 2.0), [4, -3, 0.2])
    moved = (pts - T[:3, 3]) @ T[:3, :3]  # the same points seen from another station
    order = rng.permutation(200)
    b = GlobalDescriptor(
        desc[order] + rng.normal(0, 0.01, desc.shape).astype(np.float32), moved[order], False
    )
    other = GlobalDescriptor(rng.normal(size=(200, 32)).astype(np.float32), pts, False)
    assert place_score(a, b) >= 150
    assert place_score(a, other) <= 3


def test_a_link_within_the_loop_tolerance_but_centimetres_off_is_dropped():
    P = _grid(3, seed=8)
    links = _grid_links(P, 3)
    off = make_transform(np.eye(3), [0.06, 0.0, 0.0])  # inside 3 cm + 1 cm per link of 3+
    bad = _link(P, "s04", "s05", T=off @ invert(P["s04"]) @ P["s05"], overlap=0.05)
    links.append(_link(P, "s00", "s04"))
    links.remove(next(e for e in links if (e.target, e.source) == ("s04", "s05")))
    links.append(bad)
    sol = solve_graph(sorted(P), links)
    assert bad.status == "rejected" and "adjust" in bad.why  # pruned, or its residual
    assert all(e.status == "accepted" for e in links if e is not bad)
    # the optimisation without it converges back onto the exact poses
    assert all(r < 1e-3 and t < 1e-4 for r, t in _errors(sol, P).values())


# ------------------------------------------------------------------ reasons in plain words

#: phrases of the earlier reasons a surveyor could not read (and words for the machinery)
JARGON = (
    "confirmed by no loop",
    "confirmed by none",
    "more doubtful",
    "most doubtful",
    "uncertain links never do",
    "undecidable",
    "switched off",
    "optimised poses",
    "pose-graph",
    "line process",
    "tree link",
    "as well as the answer",
)
RATIO = "free-space conflict ratio"


def _assert_plain(text: str, *, link: bool = True) -> None:
    """No jargon; in a link's reason, the free-space conflict ratio only in the closing
    parenthesis (a station's reason quotes its links' reasons)."""
    assert not [w for w in JARGON if w in text], text
    if link and RATIO in text:
        assert text.endswith(")") and text.rindex("(") < text.index(RATIO), text


def _lone_doubtful():
    """s0-s1-s2 a loop; s3 hangs on s2 by an uncertain link whose scans overlap most, and on
    s1 by another uncertain link two metres off."""
    P = {f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.3 * i), [5.0 * i, 0, 0])
         for i in range(4)}  # fmt: skip
    off = make_transform(np.eye(3), [2.0, 0, 0])
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2"),
             _link(P, "s2", "s3", "uncertain", overlap=0.6),
             _link(P, "s1", "s3", "uncertain", T=off @ invert(P["s1"]) @ P["s3"])]  # fmt: skip
    return sorted(P), links, SurveyConfig()


def test_an_unplaced_station_says_what_is_wrong_and_what_to_do():
    """The reasons, and the pair worth aligning by hand: the one whose scans overlap most
    (s2, not s1, the first by name)."""
    names, links, config = _lone_doubtful()
    sol = solve_graph(names, links, config, reference="s0")
    assert "s3" not in sol.groups[0]
    for e in links[3:]:
        assert e.why == "uncertain (see the link's reasons), and no loop confirms it"
    reason = sol.reasons["s3"]
    assert reason.startswith("no link places it (2 tried: 2 uncertain with no loop to confirm")
    assert reason.endswith(
        "; to place it: --link s2 s3 T.txt (a transform from flexreg register s2 s3), rough "
        "positions (--positions) to confirm a link, or a scan between it and s2"
    )
    _assert_plain(reason, link=False)
    for e in links[3:]:
        _assert_plain(e.why)


def test_a_station_whose_pose_only_the_rough_positions_picked_says_so():
    """s0-s1-s2 a loop; s3 hangs on s2 by one uncertain link that fits two poses a bay apart,
    of which the rough positions picked the right one. A pose the positions picked needs a
    second registration around a loop: s3 stays unplaced, and neither its link nor the
    station asks for the positions the surveyor already gave. The pair it names to align by
    hand is the one whose pose the positions picked, not s1's, whose scans overlap more but
    whose link is off."""
    P = {f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.3 * i), [5.0 * i, 0, 0])
         for i in range(4)}  # fmt: skip
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    lone = _link(P, "s2", "s3", "uncertain")
    lone.alternatives = [Alternative(_bay(P, "s2", "s3", [6.0, 0, 0]), "twin", 0.9)]
    lone.vouched = "positions"
    off = _link(P, "s1", "s3", "uncertain", overlap=0.8, T=_bay(P, "s1", "s3", [2.0, 0, 0]))
    sol = solve_graph(sorted(P), [*links, lone, off], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    assert lone.why == (
        "the rough positions pick one of the 2 poses it fits, and no loop confirms it "
        "(positions tell a bay or a room apart, not the centimetres: a pose found within them "
        "may be slid), nor does the map at full resolution (it must see the station clean from "
        "its placed neighbours and refute every other pose the positions picked)"
    )
    reason = sol.reasons["s3"]
    assert "--positions" not in reason and "would pick one" not in reason, reason
    assert reason.endswith(
        "; the rough positions pick its links' poses, and no second registration confirms "
        "one: --link s2 s3 T.txt (the pose they picked is in poses.json's links; check it, or "
        "align the pair in flexreg register s2 s3), or a scan between it and s2"
    ), reason
    _assert_plain(reason, link=False)
    _assert_plain(lone.why)


def test_a_link_that_fits_none_of_its_poses_does_not_say_it_fits_several():
    """s3 hangs on s2 by one uncertain link with two poses, uncertain for its overlap as
    well: it does not "fit 2 poses (look-alike rooms or bays)" (which a loop or positions would
    pick from); its reasons are what stands in the way, and the station is not told that
    rough positions would pick one of them."""
    P = {f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.3 * i), [5.0 * i, 0, 0])
         for i in range(4)}  # fmt: skip
    links = [_link(P, "s0", "s1"), _link(P, "s1", "s2"), _link(P, "s0", "s2")]
    lone = _link(P, "s2", "s3", "uncertain", overlap=0.08)
    lone.reasons = [{"code": "low_overlap", "message": "only 8% ..."},
                    {"code": "ambiguous", "message": "two poses ..."}]  # fmt: skip
    lone.alternatives = [Alternative(_bay(P, "s2", "s3", [6.0, 0, 0]), "runner_up", 0.9)]
    sol = solve_graph(sorted(P), [*links, lone], SurveyConfig(), reference="s0")
    assert "s3" not in sol.groups[0]
    assert lone.why == "uncertain (see the link's reasons), and no loop confirms it"
    assert "would pick one" not in sol.reasons["s3"], sol.reasons["s3"]
    lone.reasons = lone.reasons[1:]  # ambiguous only: it fits both, and a loop or positions pick
    solve_graph(sorted(P), [*links, lone], SurveyConfig(), reference="s0")
    assert lone.why.startswith("fits 2 poses (look-alike rooms or bays)")


def _wrong_in_a_loop():
    P = _grid(3, seed=1)
    wrong = make_transform(rotation_about_axis([0, 0, 1], np.radians(2)), [0.5, 0.2, 0])
    bad = _link(P, "s01", "s05", T=wrong @ invert(P["s01"]) @ P["s05"], overlap=0.1)
    return sorted(P), [*_grid_links(P, 3), bad], SurveyConfig()


def _triangle():
    P = _grid(2, seed=4)
    wrong = make_transform(rotation_about_axis([0, 0, 1], np.radians(20)), [1, 0, 0])
    links = [
        _link(P, "s00", "s01", T=wrong @ invert(P["s00"]) @ P["s01"], overlap=0.9),
        _link(P, "s01", "s02", overlap=0.6),
        _link(P, "s00", "s02", overlap=0.5),
    ]
    return sorted(P), links, SurveyConfig()


def _uncertain_pair():
    def build():
        P = _grid(2, seed=6)
        off = make_transform(np.eye(3), [2.0, 0, 0])
        links = [
            _link(P, "s00", "s01"),
            _link(P, "s01", "s02"),
            _link(P, "s02", "s03", verdict="uncertain"),
            _link(P, "s01", "s03", verdict="uncertain", T=off @ invert(P["s01"]) @ P["s03"]),
        ]
        return sorted(P), links, SurveyConfig()

    return build


def _groups_and_failures():
    P = _grid(3, seed=7)
    links = [_link(P, "s00", "s01"), _link(P, "s01", "s02"), _link(P, "s00", "s02"),
             _link(P, "s06", "s07"), _link(P, "s07", "s08"),
             Link("s00", "s03", why="only 2 inliers")]  # fmt: skip
    return sorted(P), links, SurveyConfig()


def _centimetres_off():
    P = _grid(3, seed=8)
    links = [e for e in _grid_links(P, 3) if (e.target, e.source) != ("s04", "s05")]
    off = make_transform(np.eye(3), [0.06, 0.0, 0.0])
    bad = _link(P, "s04", "s05", T=off @ invert(P["s04"]) @ P["s05"], overlap=0.05)
    return sorted(P), [*links, _link(P, "s00", "s04"), bad], SurveyConfig()


@pytest.mark.parametrize(
    "build",
    [
        _lone_doubtful,
        _wrong_in_a_loop,
        _triangle,
        _uncertain_pair(),
        _groups_and_failures,
        _centimetres_off,
    ],
)
def test_no_reason_is_in_jargon(build):
    names, links, config = build()
    sol = solve_graph(names, links, config)
    assert any(e.why for e in links)
    for e in links:
        _assert_plain(e.why or "")
    for text in sol.reasons.values():
        _assert_plain(text, link=False)


# ------------------------------------------------------------------ hypotheses of a link


def _bay(P, a, b, offset):
    """The pose of ``a <- b`` moved by ``offset`` metres in ``a``'s frame (a look-alike bay)."""
    T = invert(P[a]) @ P[b]
    W = T.copy()
    W[:3, 3] += np.asarray(offset, dtype=np.float64)
    return W


def test_an_alias_pair_whose_right_pose_is_its_runner_up_is_resolved_by_a_loop():
    """Three stations in a hall of 6 m bays: two confident links place them, the third pair
    registered one bay off (uncertain: its twin fits too). The loop picks the twin, which
    becomes the link's pose; the answer stays as an alternative."""
    from flexreg.survey.links import Alternative

    P = _grid(2)
    links = [_link(P, "s00", "s01"), _link(P, "s01", "s03")]
    truth = invert(P["s00"]) @ P["s03"]
    alias = _link(P, "s00", "s03", "uncertain", T=_bay(P, "s00", "s03", [6.0, 0, 0]))
    alias.alternatives = [
        Alternative(_bay(P, "s00", "s03", [12.0, 0, 0]), "twin", 0.7),
        Alternative(truth, "twin", 0.9),
    ]
    sol = solve_graph(["s00", "s01", "s03"], [*links, alias], SurveyConfig())
    assert alias.status == "accepted" and alias.confirmed_by_loop
    assert translation_error_m(alias.T_target_source, truth) < 1e-9
    assert alias.alternatives[0].kind == "answer"
    assert alias.picked == "the loop picked its twin, not its answer"
    assert max(e[1] for e in _errors(sol, P).values()) < 1e-6


def test_planted_wrong_hypotheses_among_right_ones_are_left_out():
    """A 3 x 3 grid of confident links, and uncertain links whose answers are whole bays
    off with the truth among their alternatives (or not at all): every station lands on the
    truth, each alias link either takes its right alternative or is rejected; none of the
    wrong poses is accepted."""
    from flexreg.survey.links import Alternative

    P = _grid(3)
    links = _grid_links(P, 3)
    names = sorted(P)
    rng = np.random.default_rng(5)
    planted = []
    for a, b in [
        (names[0], names[4]),
        (names[2], names[4]),
        (names[4], names[8]),
        (names[6], names[2]),
    ]:
        shift = [6.0 * rng.choice([-2, -1, 1, 2]), 0.0, 0.0]
        e = _link(P, a, b, "uncertain", T=_bay(P, a, b, shift))
        right = Alternative(invert(P[a]) @ P[b], "runner_up", 0.8)
        wrong = Alternative(_bay(P, a, b, [0.0, 6.0, 0.0]), "twin", 0.9)
        e.alternatives = [wrong, right] if len(planted) % 2 == 0 else [wrong]
        planted.append(e)
    sol = solve_graph(names, [*links, *planted], SurveyConfig())
    assert set(sol.groups[0]) == set(names)
    assert max(err[1] for err in _errors(sol, P).values()) < 1e-6
    for i, e in enumerate(planted):
        truth = invert(P[e.target]) @ P[e.source]
        if e.status == "accepted":
            assert translation_error_m(e.T_target_source, truth) < 1e-9, i
        else:
            assert e.status == "rejected" and i % 2 == 1


def test_an_unplaced_stations_reason_counts_its_links_outcomes():
    """Each link's own reason stays on the link; the station's reason counts them, most
    frequent first, so that a station with many links still reads in one line."""
    names, links, config = _lone_doubtful()
    failed = Link("s0", "s3", None, None, None, why="no overlap: the best transform explains 2%")
    sol = solve_graph(names, [*links, failed], config, reference="s0")
    reason = sol.reasons["s3"]
    assert reason.startswith(
        "no link places it (3 tried: 2 uncertain with no loop to confirm them, 1 failed to "
        "register); "
    )
    assert "2%" not in reason and failed.why.startswith("no overlap")


def test_a_separate_group_no_loop_checks_is_not_posed():
    """Apart from the reference's group, two stations joined by one confident link form no
    group: nothing checks that link (a look-alike answer would pose them wrongly in their own
    frame), so each is listed alone, saying a single link places nothing; a separate
    triangle is posed."""
    P = _grid(3, seed=7)
    names = sorted(P)
    tri = [_link(P, "s00", "s01"), _link(P, "s01", "s02"), _link(P, "s00", "s02")]
    lone = _link(P, "s06", "s07")
    sol = solve_graph(names, [*tri, lone])
    assert sorted(sol.groups[0]) == ["s00", "s01", "s02"]
    assert all(len(g) == 1 for g in sol.groups[1:])
    assert "s06" not in sol.poses and "s07" not in sol.poses
    assert lone.status == "rejected" and "single link" in lone.why
    assert "single link places no station" in sol.reasons["s07"]
    sol = solve_graph(
        names,
        [*tri, *(_link(P, a, b) for a, b in (("s06", "s07"), ("s07", "s08"), ("s06", "s08")))],
    )
    assert sorted(sol.groups[1]) == ["s06", "s07", "s08"]


def _turned(x: float, y: float, yaw: float) -> np.ndarray:
    return make_transform(rotation_about_axis([0, 0, 1], yaw), [x, y, 0.0])


def _hypothesis_project():
    """Three stations placed in a row 10 m apart (a0, a1, a2) and one more (b) that a link
    from a1 places 7 m beside a1 (right) or, as its runner-up, one 10 m bay along (beside a2)."""
    P = {
        "a0": _turned(0, 0, 0.3),
        "a1": _turned(10, 0, -1.0),
        "a2": _turned(20, 0, 2.0),
        "b": _turned(10, 7, 0.7),
    }
    links = [_link(P, "a0", "a1"), _link(P, "a1", "a2"), _link(P, "a0", "a2")]
    bay = invert(P["a1"]) @ _turned(20, 7, 0.7)
    hop = _link(P, "a1", "b", "uncertain")
    hop.alternatives = [Alternative(bay, "runner_up", 0.95)]
    sol = solve_graph(sorted(P), [*links, hop], SurveyConfig())
    return P, [*links, hop], sol


def test_each_hypothesis_brings_the_pair_that_would_test_it():
    P, links, sol = _hypothesis_project()
    assert sol.group_of("b") != sol.group_of("a0")  # the uncertain link alone places nothing
    order = {s: i for i, s in enumerate(sorted(P))}
    tried = {frozenset((e.target, e.source)) for e in links}

    # the answer puts b 12.2 m from a0 and from a2 (a0 first in file order); the runner-up
    # puts it 7 m from a2: each pose's nearest untried pair, nearest first
    def nearest(reach_m, tried):
        return [o[0][1:3] for o in hypothesis_pairs(sol, links, tried, reach_m, order)]

    assert nearest(15.0, tried) == [("a2", "b"), ("a0", "b")]
    assert nearest(10.0, tried) == [("a2", "b")]
    # with a2 - b tried, the answer's next pair; the runner-up brings none other within reach
    assert nearest(15.0, tried | {frozenset(("a2", "b"))}) == [("a0", "b")]
    _, a, b, T = hypothesis_pairs(sol, links, tried, 15.0, order)[1][0]
    np.testing.assert_allclose(T, invert(P[a]) @ P[b], atol=1e-9)  # the answer is right
    links[-1].verdict = None  # a failed registration's pose is no hypothesis
    assert hypothesis_pairs(sol, links, tried, 15.0, order) == []


def test_later_pairs_try_loops_then_hypotheses_then_place_partners():
    P, links, sol = _hypothesis_project()
    stems = sorted(P)
    tried = {frozenset((e.target, e.source)) for e in links}
    scores = {frozenset(("a0", "b")): 9, frozenset(("a1", "b")): 12}
    got = later_pairs(stems, sol, links, tried, scores, reach_m=15.0, place_candidates=3, budget=10)
    assert [(c.target, c.source, c.origin) for c in got] == [
        ("a2", "b", "proximity"),
        ("a0", "b", "proximity"),
    ]
    assert got[1].place_score == 9.0
    short = later_pairs(
        stems, sol, links, tried, scores, reach_m=15.0, place_candidates=3, budget=1
    )
    assert [c.key for c in short] == [frozenset(("a2", "b"))]


def test_later_pairs_give_every_unplaced_station_its_next_partner_first():
    P, links, _ = _hypothesis_project()
    P["c"] = _turned(30, 7, 0.2)  # unplaced, no link yet
    sol = solve_graph(sorted(P), links, SurveyConfig())
    stems = sorted(P)
    tried = {frozenset((e.target, e.source)) for e in links}
    scores = {
        frozenset(("a1", "c")): 6,
        frozenset(("a0", "c")): 7,
        frozenset(("a0", "b")): 9,
        frozenset(("a2", "b")): 5,
    }
    kw = {"reach_m": 5.0, "place_candidates": 2}  # no pose of b's link brings a pair that near
    got = later_pairs(stems, sol, links, tried, scores, budget=3, **kw)
    # each unplaced station's best partner before any station's second
    assert {(c.target, c.source) for c in got[:2]} == {("a0", "b"), ("a0", "c")}
    assert len(got) == 3 and got[2].key in (frozenset(("a2", "b")), frozenset(("a1", "c")))
    got = later_pairs(stems, sol, links, tried, scores, budget=10, **kw)
    assert {c.key for c in got} == {
        frozenset(p) for p in [("a0", "b"), ("a0", "c"), ("a2", "b"), ("a1", "c")]
    }
    assert all(c.origin == "place" for c in got)


def _truthful_judge(P, seen_m=float("inf")):
    """A map that finds two stations seeing each other, clean, at their true relative pose
    when they are within ``seen_m`` (None beyond: they hardly see each other), and
    contradicting each other anywhere 0.5 m or more off it."""

    def judge(a, b, T_a_b):
        truth = invert(P[a]) @ P[b]
        if np.linalg.norm(truth[:3, 3]) > seen_m:
            return None
        if translation_error_m(T_a_b, truth) >= 0.5:
            return (0.9, 0.3, 0.05)
        return (0.01, 0.002, 0.6)

    return judge


def test_a_hypothesis_the_map_refutes_brings_no_pair_and_unseen_pairs_give_way():
    P, links, sol = _hypothesis_project()
    stems = sorted(P)
    tried = {frozenset((e.target, e.source)) for e in links}
    kw = {"reach_m": 15.0, "place_candidates": 0, "budget": 10}
    # without a map: the runner-up's pair (b beside a2) first, then the answer's
    got = later_pairs(stems, sol, links, tried, {}, **kw)
    assert [c.key for c in got] == [frozenset(("a2", "b")), frozenset(("a0", "b"))]
    # the map refutes the runner-up where it puts b: only the answer's nearest pair is left
    got = later_pairs(stems, sol, links, tried, {}, judge=(_truthful_judge(P), 0.03, 1.0), **kw)
    assert [(c.target, c.source) for c in got] == [("a0", "b")]
    # b sees nothing of a0 or a2 from 12.2 m: no pair tests the answer either
    judge = (_truthful_judge(P, seen_m=11.0), 0.03, 1.0)
    assert later_pairs(stems, sol, links, tried, {}, judge=judge, **kw) == []


def test_a_chain_of_confident_links_brings_the_pair_that_would_close_its_loop():
    P = {"s0": _turned(0, 0, 0.2), "s1": _turned(3, 0, 1.1), "s2": _turned(6, 0.5, -2.0)}
    chain = [_link(P, "s0", "s1"), _link(P, "s1", "s2")]
    stems = sorted(P)
    # the three apart, as where the map kept each lone link from placing its stations
    sol = GraphSolution("s0", {}, [["s0"], ["s1"], ["s2"]], ["s0", "s1", "s2"], {}, {}, {})
    order = {s: i for i, s in enumerate(stems)}
    tried = {frozenset((e.target, e.source)) for e in chain}
    got = chain_pairs(sol, chain, tried, 12.0, order)
    assert [[(a, b) for _, a, b, _ in options] for options in got] == [[("s0", "s2")]]
    d, _, _, T = got[0][0]
    truth = invert(P["s0"]) @ P["s2"]
    assert translation_error_m(T, truth) < 1e-9 and d == pytest.approx(np.linalg.norm(truth[:3, 3]))
    assert chain_pairs(sol, chain, tried, 5.0, order) == []  # 6 m apart
    got = later_pairs(stems, sol, chain, tried, {}, reach_m=12.0, place_candidates=0, budget=5)
    assert [(c.target, c.source, c.origin) for c in got] == [("s0", "s2", "proximity")]
    # an uncertain link, or a confident one a loop contradicts, chains nothing
    chain[1].loop_error_m, chain[1].loop_error_deg = 0.4, 2.0
    assert chain_pairs(sol, chain, tried, 12.0, order) == []
    chain[1].loop_error_m = chain[1].loop_error_deg = None
    chain[0].verdict = "uncertain"
    assert chain_pairs(sol, chain, tried, 12.0, order) == []
