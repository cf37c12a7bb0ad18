"""Lone links: a tree link no loop checks (:func:`lone_suspect`, step 2 of
:mod:`flexreg.survey.graph`), and separate groups such links hold (:func:`lone_cuts`).

Separate groups held by lone links in repeating structure pose nothing.

A group that no link joins to the reference's is still solved in its own frame
(``T_group_station``). When it is held together only by tree links that no loop confirms and
the map did not join, each relative pose in it rests on one pairwise answer. In a hall of
identical bays such an answer can be whole bays off while no twin of it fits (the bays one
either way put the racks' ends or a wall in open space, the truth several bays away overlaps
too little to count): the 64-station synthetic warehouse paired station_35 and station_38
4 bays (22.6 m) off this way, every other link of station_38 being whole-bay ambiguous
(:attr:`~flexreg.survey.links.Link.repeat`). So when any station of such a group has a link
the verdict called ambiguous for its whole-bay twins, the group's links are cut and its
stations stay single (unplaced, as before, now without a relative pose). A group with a
confirming loop, or one outside repeating structure (a lone link between two rooms of an
annex), keeps its poses.
"""

from __future__ import annotations

from collections import deque
from typing import Protocol

import numpy as np

from flexreg.survey.config import SurveyConfig
from flexreg.survey.links import GraphSolution, Link, Matrix, loop_error

#: why a cut link places nothing
WHY = (
    "a lone link among look-alike bays (its stations' other links fit a whole bay off as "
    "well) and no loop checks it, so it places nothing; add a scan that closes a loop"
)


def lone_cuts(sol: GraphSolution, links: list[Link]) -> list[tuple[Link, str]]:
    """The accepted links of every separate group (not the reference's) of two or more
    stations that only unconfirmed tree links hold together, when one of its stations has a
    :attr:`~flexreg.survey.links.Link.repeat` link; each with :data:`WHY`.

    Parameters
    ----------
    sol : GraphSolution
        The graph's solution.
    links : list of Link
        Its links, statuses set.

    Returns
    -------
    list of (Link, str)
    """
    cuts: list[tuple[Link, str]] = []
    for group in sol.groups[1:]:
        if len(group) < 2:
            continue
        members = set(group)
        inside = [
            e
            for e in links
            if e.status == "accepted" and e.target in members and e.source in members
        ]
        lone = all(
            e.in_tree and not e.confirmed_by_loop and not e.map_joined and not e.vouched
            for e in inside
        )
        repeats = any(e.repeat and (e.target in members or e.source in members) for e in links)
        if inside and lone and repeats:
            cuts += [(e, WHY) for e in inside]
    return cuts


class Tree(Protocol):
    """The graph's spanning tree as :func:`lone_suspect` reads it."""

    adj: dict[str, list[tuple[str, Link]]]
    pose: dict[str, Matrix]

    def path(self, a: str, b: str) -> list[Link]: ...


def _beyond(adj: dict[str, list[tuple[str, Link]]], cut: Link, start: str) -> set[str]:
    """Stations reachable from ``start`` over the tree without the link ``cut``."""
    seen, queue = {start}, deque([start])
    while queue:
        for y, e in adj[queue.popleft()]:
            if e is not cut and y not in seen:
                seen.add(y)
                queue.append(y)
    return seen


def lone_suspect(
    forest: Tree,
    tree: list[Link],
    support: dict[int, int],
    confirmed: list[Link],
    links: list[Link],
    config: SurveyConfig,
) -> list[tuple[Link, str]]:
    """A tree link that alone places stations and that nothing vouches for, or [].

    A tree link that no loop confirms is the only evidence for where the stations beyond it
    are (the smaller side of the tree it splits). It is rejected (better unplaced than wrong)
    when

    * an *ambiguous* link across the same cut (its verdict found a clearly different pose
      that fits about as well: a symmetric room, repeating bays) agrees with that placement:
      the placement is one of twins and nothing checks which (an ambiguous link that
      disagrees says nothing about it). The tree links between the ambiguous link's stations
      make the twin placement; the most doubtful of them is rejected (this one unless another
      is more doubtful, even one a loop of links wrong in the same way confirms); or
    * it is more doubtful (free-space conflict ratio) than every link a loop confirmed among
      the stations it attaches to (the larger side; the whole project's when no loop
      confirms a link there), and than ``loop_doubt_min``: the loops show how much conflict
      that part's right links carry, and this one carries more, unchecked. (Another part of
      the project may be a region folded onto itself, its wrong links confirmed by loops of
      wrong links: their doubt says nothing about this one.)

    One at a time, the most doubtful first: a wrongly placed station's own ambiguous links
    agree with whatever placed it, and would make its neighbours' tree links look alike. Off
    with ``trust_lone_links``."""
    if config.trust_lone_links:
        return []
    ambiguous = [
        e
        for e in links
        if e.T_target_source is not None
        and e.status != "failed"
        and any(r.get("code") == "ambiguous" for r in e.reasons)
    ]
    vouched = [(e, float(e.doubt)) for e in confirmed if e.doubt is not None]
    overall = max([config.loop_doubt_min, *(d for _, d in vouched)]) if vouched else None
    adj = forest.adj  # the tree's links per station
    out: list[tuple[float, int, Link, str]] = []
    for t in tree:
        if support.get(id(t), 0) > 0 or t.vouched == "hand":  # positions pick a pose, not cm
            continue
        a, b = _beyond(adj, t, t.source), _beyond(adj, t, t.target)
        side = a if len(a) <= len(b) else b
        rest = b if side is a else a
        placing = f"the only link placing {', '.join(sorted(side))}, and no loop checks it"
        doubt = float(t.doubt or 0.0)
        there = [d for e, d in vouched if e.target in rest and e.source in rest]
        ceiling = max([config.loop_doubt_min, *there]) if there else overall
        if ceiling is not None and doubt > ceiling:
            why = (
                f"{placing}: more of one scan lies where the other saw open space than on any "
                "link a loop checked, so it may be a wrong match (free-space conflict ratio "
                f"{doubt:.2f}, checked links at most {ceiling:.2f})"
            )
            out.append((doubt, -len(side), t, why))
            continue
        for e in ambiguous:
            if not (
                (e.target in side and e.source in rest) or (e.source in side and e.target in rest)
            ):
                continue
            err = loop_error(
                np.asarray(e.T_target_source), forest.pose[e.target], forest.pose[e.source]
            )
            if err[0] <= 1.0 and err[1] <= 0.1:
                # the twin placement is made by the tree links between the ambiguous link's
                # stations: the most doubtful of them goes (this one, unless another is worse)
                worst = max(forest.path(e.target, e.source), key=lambda x: float(x.doubt or 0))
                why = (
                    f"{placing}; link {e.target} <- {e.source} agrees with it, but there another "
                    "pose fits about as well (look-alike rooms or bays): it may be the wrong one"
                )
                if worst is not t:
                    why = (
                        f"link {e.target} <- {e.source} agrees with where the links place "
                        f"{e.target} and {e.source}, but there another pose fits about as well "
                        "(look-alike rooms or bays); of the links between them this one is the "
                        "least trustworthy, its scans clashing most (free-space conflict ratio "
                        f"{float(worst.doubt or 0):.2f})"
                    )
                out.append((float(worst.doubt or 0), -len(side), worst, why))
                break
    if not out:
        return []
    _, _, t, why = max(out, key=lambda x: (x[0], x[1]))
    return [(t, why)]


__all__ = ["WHY", "Tree", "lone_cuts", "lone_suspect"]
