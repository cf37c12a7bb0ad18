"""Separate groups held by lone links in repeating structure pose nothing.

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

from flexreg.survey.links import GraphSolution, Link

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
        lone = all(e.in_tree and not e.confirmed_by_loop and not e.map_joined for e in inside)
        repeats = any(e.repeat and (e.target in members or e.source in members) for e in links)
        if inside and lone and repeats:
            cuts += [(e, WHY) for e in inside]
    return cuts


__all__ = ["WHY", "lone_cuts"]
