"""A separate group joins the reference's only where the map allows a single placement."""

from __future__ import annotations

import numpy as np

from flexreg.core.transforms import invert, make_transform, rotation_about_axis
from flexreg.survey.config import SurveyConfig
from flexreg.survey.graph import Link, solve_graph
from flexreg.survey.groupjoin import join_by_map
from flexreg.survey.mapcheck import PairLook

INFO = np.diag([2e5, 2e5, 2e5, 1e4, 1e4, 1e4])


def _poses():
    return {
        f"s{i}": make_transform(rotation_about_axis([0, 0, 1], 0.2 * i), [4.0 * i, 1.0 * i, 0])
        for i in range(5)
    }


def _link(P, a, b, verdict="confident", T=None):
    T = invert(P[a]) @ P[b] if T is None else T
    return Link(a, b, T, INFO, verdict, overlap_target=0.4, overlap_source=0.4, doubt=0.05)


class _Judge:
    """Scores a pair as the map check would, knowing the truth: at the true relative pose
    ``clean`` conflict, anywhere else ``wrong``; ``explained`` either way."""

    def __init__(self, P, *, clean=0.01, wrong=0.12, explained=0.3):
        self.P, self.clean, self.wrong, self.explained = P, clean, wrong, explained

    def look(self, a, b, T):
        true = invert(self.P[a]) @ self.P[b]
        c = self.clean if np.linalg.norm(T[:3, 3] - true[:3, 3]) < 0.5 else self.wrong
        return PairLook(a, b, T, (self.explained,) * 2, (c, c), (1000, 1000))


def _two_groups():
    """s0-s1-s2 and s3-s4 each confidently linked; between them only uncertain links: s2-s3
    right (a doorway), s1-s3 wrong (an identical room 6 m off)."""
    P = _poses()
    twin = make_transform(np.eye(3), [6.0, 0, 0])
    links = [
        _link(P, "s0", "s1"),
        _link(P, "s1", "s2"),
        _link(P, "s0", "s2"),
        _link(P, "s3", "s4"),
        _link(P, "s2", "s3", "uncertain"),
        _link(P, "s1", "s3", "uncertain", T=twin @ invert(P["s1"]) @ P["s3"]),
    ]
    return P, links


def test_the_only_placement_no_station_contradicts_joins_the_group():
    P, links = _two_groups()
    config = SurveyConfig()
    sol = solve_graph(list(P), links, config, reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2"] and sorted(sol.groups[1]) == ["s3", "s4"]
    joins = join_by_map(sol, links, _Judge(P), config)
    assert [(e.target, e.source) for e, _ in joins] == [("s2", "s3")]
    assert "only this one puts no scan where another saw open space" in joins[0][1]
    joins[0][0].map_joined = True
    sol = solve_graph(list(P), links, config, reference="s0")
    assert sorted(sol.groups[0]) == ["s0", "s1", "s2", "s3", "s4"]
    for s in ("s3", "s4"):
        np.testing.assert_allclose(sol.poses[s], invert(P["s0"]) @ P[s], atol=1e-6)
        assert sol.confidence[s] == "uncertain"  # joined through an uncertain link
    assert links[4].status == "accepted" and links[5].status == "rejected"


def test_no_join_when_two_placements_are_clean_or_the_groups_barely_see_each_other():
    P, links = _two_groups()
    config = SurveyConfig()
    sol = solve_graph(list(P), links, config, reference="s0")
    # nothing contradicts the twin either: both placements are possible
    assert join_by_map(sol, links, _Judge(P, wrong=0.02), config) == []
    # the right placement is clean but explains almost nothing: no evidence either way
    assert join_by_map(sol, links, _Judge(P, explained=0.05), config) == []
    # without any uncertain link proposing it, the clean placement is not taken
    links[4].verdict = "confident"
    links[4].status = "rejected"
    assert join_by_map(sol, links, _Judge(P), config) == []


def test_two_separate_sites_are_never_joined_when_every_placement_contradicts():
    P, links = _two_groups()
    config = SurveyConfig()
    sol = solve_graph(list(P), links, config, reference="s0")
    assert join_by_map(sol, links, _Judge(P, clean=0.12), config) == []
