"""Joining a separate group to the reference's when the map allows one placement only.

Uncertain links never join groups on their own (:mod:`flexreg.survey.graph`, step 3): a link
through a doorway is often uncertain because the two scans share little, and an uncertain
link is as likely to overlay two identical rooms. What decides is the rest of the project.
Every link between a separate group and the reference's group (confident or uncertain, not
failed) proposes a placement of the whole group by its answer and one by each of its
alternatives (its runner-ups and the twins of its answer, :func:`flexreg.survey.links.
alternatives_of`); proposals of the same placement (within 1° and 0.1 m) are one
hypothesis. Each hypothesis is scored with the map check's
dense scores (:class:`~flexreg.survey.mapcheck.PairJudge`) on every pair of one station of
each group within ``map_radius_m``:

* **clean**: no pair puts ``map_min_conflict`` (3 %) or more of a station's sample in the
  other's free space, and at least one pair explains ``map_join_min_explained`` (10 %) of
  both stations' samples (the groups do see each other there);
* **refuted**: some pair puts at least ``map_min_conflict`` of a sample in the other's free
  space.

The group is joined by the clean hypothesis's best link (with the pose of it that proposes
the placement: an alternative replaces the answer) only when it is the *only* clean one and
every other hypothesis is refuted: then every other placement puts one station's walls
where another station saw through, and this one contradicts nothing while the groups see
each other. The joining link stays ``uncertain``, so the stations it places are
``"confidence": "uncertain"`` and the survey exits 3 (placed, but say which to check).
"""

from __future__ import annotations

import logging

import numpy as np

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.survey.config import SurveyConfig
from flexreg.survey.links import GraphSolution, Link, Matrix
from flexreg.survey.mapcheck import PairJudge

log = logging.getLogger(__name__)


def _placements(
    P: dict[str, Matrix], links: list[Link], members: set[str], main: set[str]
) -> list[tuple[Matrix, list[tuple[Link, Matrix]]]]:
    """Placements ``T_ref_group`` of a group proposed by the links between it and the main
    group, by their answers and their alternatives (each link's pose that proposes it kept
    beside it); proposals within 1° / 0.1 m merged; links in file order."""
    out: list[tuple[Matrix, list[tuple[Link, Matrix]]]] = []
    for e in links:
        if e.T_target_source is None or e.status == "failed":
            continue
        for T in e.poses:
            if e.target in main and e.source in members:
                R = P[e.target] @ T @ invert(P[e.source])
            elif e.source in main and e.target in members:
                R = P[e.source] @ invert(T) @ invert(P[e.target])
            else:
                break
            for R0, same in out:
                if rotation_error_deg(R, R0) <= 1.0 and translation_error_m(R, R0) <= 0.1:
                    same.append((e, T))
                    break
            else:
                out.append((R, [(e, T)]))
    return out


def _score(
    R: Matrix,
    P: dict[str, Matrix],
    members: list[str],
    main: list[str],
    judge: PairJudge,
    config: SurveyConfig,
) -> tuple[float, float]:
    """The largest free-space share and the largest explained share (the smaller of the
    pair's two) over the cross pairs of a placement within ``map_radius_m``."""
    worst, support = 0.0, 0.0
    for y in members:
        Py = R @ P[y]
        for x in main:
            Px = P[x]
            if np.linalg.norm(Px[:3, 3] - Py[:3, 3]) > config.map_radius_m:
                continue
            look = judge.look(x, y, invert(Px) @ Py)
            if look is None:
                continue
            worst = max(worst, *look.conflicting)
            support = max(support, min(look.explained))
    return worst, support


def join_by_map(
    sol: GraphSolution, links: list[Link], judge: PairJudge, config: SurveyConfig
) -> list[tuple[Link, str]]:
    """The links that join a separate group to the reference's group (at most one per
    group), each with the reason; [] when no group has a single placement the map allows.

    Parameters
    ----------
    sol : GraphSolution
        The current solution: group 0 in the reference frame, each other group in its own.
    links : list of Link
        Every attempted link (statuses as the solution left them).
    judge : PairJudge
        Dense scores of a pair of stations at any relative pose.
    config : SurveyConfig
        ``map_radius_m``, ``map_min_conflict``, ``map_join_min_explained``.
    """
    main = [s for s in sol.groups[0] if s in sol.poses]
    P = dict(sol.poses)
    for g in sol.groups[1:]:
        if len(g) == 1:  # a single station is its own frame
            P[g[0]] = np.eye(4)
    out: list[tuple[Link, str]] = []
    for group in sol.groups[1:]:
        members = [s for s in group if s in P]
        if not members or not main:
            continue
        hypotheses = _placements(P, links, set(members), set(main))
        scored = [(_score(R, P, members, main, judge, config), same) for R, same in hypotheses]
        clean = [
            (s, same)
            for s, same in scored
            if s[0] < config.map_min_conflict and s[1] >= config.map_join_min_explained
        ]
        refuted = [s for s, _ in scored if s[0] >= config.map_min_conflict]
        if len(clean) != 1 or len(refuted) != len(scored) - 1:
            continue
        (worst, support), same = clean[0]
        uncertain = [(e, T) for e, T in same if not e.trusted]
        if not uncertain:  # confident links there were rejected for their own reasons
            continue
        best, T = max(uncertain, key=lambda x: x[0].overlap)
        picked = [a for a in best.alternatives if a.T_target_source is T]
        if picked:  # the placement is one of its alternatives'
            best.take(picked[0], "the map")
        why = (
            f"joins {', '.join(members)} to the reference's group: of the {len(scored)} "
            "placements the links propose, only this one puts no scan where another saw open "
            f"space, every other does (this one: at most {100 * worst:.1f}% of a scan in "
            f"another's free space, {100 * support:.0f}% explained)"
        )
        log.info("map join: %s <- %s %s", best.target, best.source, why)
        out.append((best, why))
    return out


__all__ = ["join_by_map"]
