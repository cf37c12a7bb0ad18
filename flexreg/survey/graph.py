"""The station graph: which links to keep, where each station is, which groups exist.

Each registered link carries its transform, its verdict, its alternatives and its
information matrix. A wrong link must not place a station:

1. **Hypotheses and groups** (:mod:`flexreg.survey.consensus`): one mechanism, pairwise
   consistency maximisation between groups of stations, picks each link's pose among its
   hypotheses and merges groups where loops of trusted links (or the surveyor, or the map)
   confirm them; every other link of a group keeps the pose that agrees with the group, or
   is rejected with its loop error.
2. **Robust pose-graph optimisation** per group (Open3D's ``PoseGraph`` with its line
   process over every kept link): a link it switches off, or one that still disagrees with
   the optimised poses, is rejected and the optimisation rerun.
3. **Groups**: connected components of the kept links, never fused. Group 0 holds the
   reference (the given station, or the first by name of the largest group).
4. **Residuals**: a link can agree with its loops within the loop tolerance and still be a
   few centimetres off, pulling the optimised poses. The accepted link that fits the
   optimised poses worst is dropped when it is beyond ``residual_factor`` times the median
   residual of the accepted links (at least ``residual_floor_m`` / ``residual_floor_deg``),
   and everything is solved again without it, until every link fits.
5. **Vetoes** from the map check (:mod:`flexreg.survey.mapcheck`): two placed stations
   whose scans contradict each other at their solved relative pose (linked or not) mean a
   wrong link between them; the links of a path between them that no loop confirms are cut
   (when loops confirm them all, the most doubtful one: the highest free-space conflict ratio
   of its own check) and everything solved again.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.errors import InputError
from flexreg.survey.c2c import CAPTURE_VOXELS
from flexreg.survey.config import MAP_DOUBT_MARGIN, PRUNE_THRESHOLD, SurveyConfig
from flexreg.survey.consensus import Placement, merge_groups
from flexreg.survey.hypotheses import Hypothesis, LoopTolerance, cycle_votes, hypotheses_of
from flexreg.survey.links import (
    FullJudge,
    GraphSolution,
    GroupFit,
    Judge,
    Link,
    Matrix,
    Veto,
    bridges,
    loop_error,
    reached,
    walk,
)
from flexreg.survey.positions import Position

log = logging.getLogger(__name__)


# ------------------------------------------------------------------------------ steps


def _reject(e: Link, why: str, err: tuple[float, float] | None = None) -> None:
    e.status, e.why, e.in_tree = "rejected", why, False
    if err is not None:
        e.loop_error_deg, e.loop_error_m = float(err[0]), float(err[1])


def tolerance(config: SurveyConfig) -> LoopTolerance:
    """The survey's loop tolerance."""
    return LoopTolerance(config.loop_max_deg, config.loop_max_m, config.loop_per_link_m)


def _consistent(err: tuple[float, float], hops: int, config: SurveyConfig) -> bool:
    return tolerance(config).agrees(err, hops)


def _choose(
    stems: list[str],
    links: list[Link],
    config: SurveyConfig,
    judge: Judge | None,
    fit: GroupFit | None = None,
    positions: Mapping[str, Position] | None = None,
    full: FullJudge | None = None,
) -> Placement:
    """Steps 1-3 (:mod:`flexreg.survey.consensus`): the hypothesis of every pending link,
    the groups they make and their poses; links left out are rejected with why."""
    tol = tolerance(config)
    pending = [e for e in links if e.status == "pending"]
    hyps: dict[frozenset[str], list[Hypothesis]] = {}
    for e in pending:
        hyps.setdefault(frozenset((e.target, e.source)), []).extend(hypotheses_of(e))
    broken = cycle_votes(hyps, tol)
    place, chosen = merge_groups(
        stems,
        hyps,
        tol,
        (config.registration.judge.ambiguity_ratio, config.registration.judge.decisive_ratio),
        (judge, config.map_min_conflict, config.map_conflict_ratio, config.map_radius_m)
        if judge is not None
        else None,
        broken,
        (fit, 2 * CAPTURE_VOXELS * config.refine_voxel_m) if fit is not None else None,
        positions,
        (full, config.registration.judge.settle_open_share, config.map_min_conflict)
        if full is not None
        else None,
    )
    for e in pending:
        c = chosen.get(id(e))
        if c is not None and c.how == "fit":
            P_t, P_s = place.pose[e.target], place.pose[e.source]
            _reject(e, SLID, loop_error(np.asarray(e.T_target_source), P_t, P_s))
            continue
        if c is not None:
            if c.hypothesis.alternative is not None:
                e.take(c.hypothesis.alternative, "the map" if c.how == "map" else "the loop")
            e.in_tree, e.confirmed_by_loop = c.centre, c.by_loop
            e.map_joined = c.how in ("map", "full")
            continue
        if place.root[e.target] != place.root[e.source]:
            _reject(e, _unconfirmed(e, hyps))
            continue
        P_t, P_s = place.pose[e.target], place.pose[e.source]
        err = loop_error(np.asarray(e.T_target_source), P_t, P_s)
        pick = (
            e.agreeing_alternative(P_t, P_s, lambda x: tol.agrees(x, 2))
            if not tol.agrees(err, 2) and not e.trusted
            else None
        )
        if pick is not None:  # an alias pair: the loop picks the right one of its poses
            e.take(pick[0], "the loop")
            err = pick[1]
        if tol.agrees(err, 2):
            e.confirmed_by_loop = True
            e.loop_error_deg, e.loop_error_m = err
        else:
            _reject(
                e,
                "disagrees with the loop it closes"
                if e.trusted
                else "uncertain, and the group's other links place its stations elsewhere",
                err,
            )
    return place


#: Why a doorway link is left out when fitted on all the overlap it joins another's placement.
SLID = (
    "slid (along a wall, where its few shared points fit too): fitted on all the overlap of "
    "the two groups it joins, it comes to where another doorway link places them, and its "
    "own pose is off that by its loop error"
)

#: Why a confident link between two groups placed nothing when confident links disagree.
CONTESTED = (
    "a loop of confident links through it does not close: it or another of them is wrong, "
    "and no other loop nor the map tells which"
)


def _by_positions(e: Link) -> bool:
    """Whether what the link offers rests on the rough positions: not trusted, and the pose
    they picked, or confident only inside their window (such a link needs a loop:
    :mod:`flexreg.survey.consensus`)."""
    windowed = e.windowed and e.verdict == "confident"
    return not e.trusted and (e.vouched == "positions" or windowed)


def _unconfirmed(e: Link, hyps: dict[frozenset[str], list[Hypothesis]]) -> str:
    """Why a link between two groups placed nothing, in words."""
    n = 1 + len(e.alternatives)
    if _by_positions(e):
        how = (
            "confident inside the rough positions' window"
            if e.verdict == "confident"
            else f"the rough positions pick one of the {n} poses it fits"
            if n > 1
            else "the rough positions vouch for its pose"
        )
        return (
            f"{how}, and no loop confirms it (positions tell a bay or a room apart, not the "
            "centimetres: a pose found within them may be slid), nor does the map at full "
            "resolution (it must see the station clean from its placed neighbours and refute "
            "every other pose the positions picked)"
        )
    if n > 1 and not e.trusted and e.fits:
        return (
            f"fits {n} poses (look-alike rooms or bays), and no loop or rough position tells "
            "which is right"
        )
    if e.trusted and any(h.against for h in hyps[frozenset((e.target, e.source))]):
        return CONTESTED
    if e.trusted:
        return "no loop checks it: a single link places no station on its own"
    return "uncertain (see the link's reasons), and no loop confirms it"


def _optimise(
    group: list[str], ref: str, poses: dict[str, Matrix], links: list[Link], config: SurveyConfig
) -> tuple[dict[str, Matrix], list[Link]]:
    """Step 4 for one group: Open3D's robust pose-graph optimisation; returns the poses and
    the loop-closure links its line process switched off."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    idx = {s: i for i, s in enumerate(group)}
    graph = reg.PoseGraph()
    for s in group:
        graph.nodes.append(reg.PoseGraphNode(np.asarray(poses[s], dtype=np.float64)))
    edges = [e for e in links if e.status == "pending" and e.target in idx and e.source in idx]
    for e in edges:
        info = np.asarray(e.information, dtype=np.float64) if e.information is not None else None
        if info is None or info.shape != (6, 6) or not np.all(np.isfinite(info)):
            info = np.eye(6)
        graph.edges.append(
            reg.PoseGraphEdge(
                idx[e.source],
                idx[e.target],
                np.asarray(e.T_target_source, dtype=np.float64),
                info,
                uncertain=True,
            )
        )
    if not edges:
        return dict(poses), []
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=config.loop_max_m,
        edge_prune_threshold=PRUNE_THRESHOLD,
        preference_loop_closure=1.0,
        reference_node=idx[ref],
    )
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            graph,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )
    kept = {(int(e.source_node_id), int(e.target_node_id)) for e in graph.edges}
    pruned = [e for e in edges if (idx[e.source], idx[e.target]) not in kept]
    out = {s: np.asarray(graph.nodes[idx[s]].pose, dtype=np.float64) for s in group}
    ref_inv = invert(out[ref])  # the reference node stays fixed; guard against drift anyway
    return {s: ref_inv @ P for s, P in out.items()}, pruned


def _reference(
    stems: list[str], comp: dict[str, str], links: list[Link], reference: str | None
) -> str:
    if reference is not None:
        if reference not in comp:
            raise InputError("--reference", f"{reference!r} is not one of the stations")
        return reference
    size: dict[str, int] = {}  # the first station by name of the largest group: the same
    for s in stems:  # reference whatever the links' strengths (deterministic across runs)
        size[comp[s]] = size.get(comp[s], 0) + 1
    return max(stems, key=lambda s: (size[comp[s]], -stems.index(s)))


def _firm_edges(
    links: list[Link], group: list[str] | None = None
) -> tuple[list[tuple[str, str]], set[int]]:
    """The confident accepted links (inside ``group``, when given) as station pairs (a link
    confident inside rough positions' window counts once accepted: a loop of confident links
    confirmed it), and the indices of those among them that close no loop (bridges)."""
    members = None if group is None else set(group)
    edges = [
        (e.target, e.source)
        for e in links
        if e.status == "accepted"
        and e.confident
        and (members is None or (e.target in members and e.source in members))
    ]
    return edges, bridges(edges)


def _looped(firm: tuple[list[tuple[str, str]], set[int]]) -> list[tuple[str, str]]:
    """The confident accepted links that close a loop of them (``firm``:
    :func:`_firm_edges`): each has a second route of confident links that agrees with it."""
    edges, alone = firm
    return [x for i, x in enumerate(edges) if i not in alone]


def _confidence(
    group: list[str], ref: str, firm: tuple[list[tuple[str, str]], set[int]]
) -> dict[str, str]:
    """``confident`` when joined to ``ref`` by confident accepted links that each close a
    loop of them (one 2-edge-connected block with ``ref``): no single registration decides
    where the station lies from ``ref``; ``single`` when joined by confident links but
    through one that closes no loop (a bridge: the station alone at the end of one link, or a
    block of stations hanging from the rest by one link): that registration fixes it, and the
    uncertain links that agree with it may be wrong the same way (a view that repeats bay by
    bay aliases every link alike); else ``uncertain``. ``firm``: :func:`_firm_edges` of the
    group."""
    joined = reached(ref, firm[0])
    held = reached(ref, _looped(firm))
    return {
        s: "uncertain" if s not in joined else "confident" if s in held else "single" for s in group
    }


def _firm_reference(group: list[str], firm: tuple[list[tuple[str, str]], set[int]]) -> str:
    """The first station by name of the largest block of ``group`` that confident links
    closing loops hold together (:func:`_confidence`; ``firm``: :func:`_firm_edges` of the
    group): the frame every confirmed pose is given in, so that a block hanging from one link
    is the one reported as such."""
    kept = _looped(firm)
    best: tuple[int, str] | None = None
    done: set[str] = set()
    for s in group:  # in name order: the first of each block
        if s in done:
            continue
        block = reached(s, kept)
        done |= block
        if best is None or len(block) > best[0]:
            best = (len(block), s)
    return group[0] if best is None else best[1]


def single_link(stem: str, ref: str, links: list[Link]) -> str:
    """What a ``single`` station's pose from ``ref`` rests on, in words: the confident
    accepted links on the way from the station to ``ref`` that close no loop (its own link
    when it hangs alone; the one its block hangs from), as ``target <- source``, nearest the
    station first."""
    edges, alone = _firm_edges(links)
    adj: dict[str, list[tuple[str, int]]] = {}
    for i, (a, b) in enumerate(edges):
        adj.setdefault(a, []).append((b, i))
        adj.setdefault(b, []).append((a, i))
    named = [" <- ".join(edges[i]) for _, i in walk(adj, stem, ref) or [] if i in alone]
    if len(named) == 1:
        return f"one confident link alone fixes it ({named[0]})"
    what = ", ".join(named) if named else "its links"
    return f"confident links that no loop checks fix it, one after the other ({what})"


def uncertain_via(stem: str, ref: str, links: list[Link]) -> list[str]:
    """The uncertain accepted links on a shortest walk of accepted links from ``stem`` to
    ``ref``, as ``target <- source``, nearest the station first: what places a station of
    confidence ``uncertain`` (each confirmed by a loop of other uncertain links)."""
    path = _accepted_path(links, ref, stem)  # from the station to ref
    return [f"{e.target} <- {e.source}" for e in path if not e.confident]


#: A link's outcome in a few words (a piece of its ``why``, and the words for it), for the
#: count in an unplaced station's reason: each link's own reason, with its figures, stays on
#: the link (poses.json, the report's link table).
_OUTCOMES = (
    ("uncertain (see the link's reasons)", "uncertain with no loop to confirm them"),
    ("fits ", "fit several poses (look-alike rooms or bays)"),
    ("the group's other links place", "uncertain and at odds with their group's other links"),
    ("slid (along a wall", "slid along a wall (another doorway link places them)"),
    ("no loop checks it", "confident but alone (a single link places no station on its own)"),
    (CONTESTED, "confident in a loop that does not close"),
    ("cut by the map check", "cut by the map check"),
    ("off the adjusted poses", "far off the adjusted poses"),
    ("disagrees with the loop", "at odds with the loop they close"),
    ("rough positions", "picked by the rough positions with no loop to confirm them"),
)


def _tally(links: list[Link]) -> str:
    """The outcomes of a station's links counted, most frequent first: ``"9 failed to
    register, 4 uncertain with no loop to confirm them, 1 cut by the map check"``."""
    counts: dict[str, int] = {}
    for e in links:
        why = e.why or e.status
        words = (
            "failed to register"
            if e.status == "failed"
            else "accepted"
            if e.status == "accepted"
            else next((w for key, w in _OUTCOMES if key in why), why)
        )
        counts[words] = counts.get(words, 0) + 1
    order = sorted(counts.items(), key=lambda kv: -kv[1])  # stable: first seen first on ties
    return ", ".join(f"{n} {words}" for words, n in order)


def _outward(e: Link, members: set[str]) -> tuple[str, str]:
    """A link's two stations, the one outside ``members`` first."""
    return (e.target, e.source) if e.target not in members else (e.source, e.target)


def _why_unplaced(stem: str, group: list[str], links: list[Link], placed: set[str]) -> str:
    """Why a station is not placed, and the one thing that would place it."""
    members = set(group)
    mine = [e for e in links if (e.target in members) != (e.source in members)]
    mine = mine if len(group) > 1 else [e for e in links if stem in (e.target, e.source)]
    toward = [e for e in mine if (e.target in placed) or (e.source in placed)]
    near = sorted({x for e in toward or mine for x in (e.target, e.source)} - members)
    other = near[0] if near else "STATION"
    side = next(iter(sorted(members & {x for e in toward for x in (e.target, e.source)})), stem)
    seen = [e for e in toward if e.usable and e.overlap > 0]
    if seen:  # the pair whose scans see most of each other: the one worth aligning by hand
        other, side = _outward(max(seen, key=lambda e: e.overlap), members)
    hand = f"--link {other} {side} T.txt (a transform from flexreg register {other} {side})"
    rivals = [e for e in toward if e.why == CONTESTED]
    what = (
        f"confident links place it apart ({', '.join(f'{e.target} <- {e.source}' for e in rivals)}"
        "): one of them is wrong"
        + (f" (in a separate group of {len(group)} stations)" if len(group) > 1 else "")
        if len(rivals) > 1
        else f"in a separate group of {len(group)} stations: no confident link, nor one a loop "
        "confirms, joins it to the reference's group"
        if len(group) > 1
        else "no link was tried (no other scan seemed to see the same place)"
        if not mine
        else f"all {len(mine)} link(s) failed to register"
        if all(e.status == "failed" for e in mine)
        else f"no link places it ({len(mine)} tried: {_tally(mine)})"
    )
    many = max(
        (e for e in toward if e.usable and e.fits), key=lambda e: len(e.alternatives), default=None
    )
    n, alias = 1, other
    if many is not None:  # the link that fits most poses, and its station outside the group
        n, alias = 1 + len(many.alternatives), ({many.target, many.source} - members).pop()
    sited = [e for e in toward or mine if _by_positions(e)]
    if sited:  # they decided; nothing confirms: the pair whose pose they picked, to check
        other, side = _outward(max(sited, key=lambda e: e.overlap), members)
        return (
            f"{what}; the rough positions pick its links' poses, and no second registration "
            f"confirms one: --link {other} {side} T.txt (the pose they picked is in poses.json's "
            f"links; check it, or align the pair in flexreg register {other} {side}), or a scan "
            f"between it and {other}"
        )
    said = next((e.undecided for e in toward if e.undecided), "")
    if said:
        return f"{what}; the rough positions cannot place it ({said}): {hand}"
    if len(rivals) > 1:
        pairs = " or ".join(f"--link {e.target} {e.source} T.txt" for e in rivals[:2])
        return (
            f"{what}; rough positions (--positions) would tell which, or {pairs} with the "
            "transform you check to be right (flexreg register TARGET SOURCE gives it)"
        )
    if n > 1:
        return (
            f"{what}; its link with {alias} fits {n} poses (look-alike "
            f"rooms or bays): rough positions of both (--positions) would pick one, or {hand}"
        )
    return (
        f"{what}; to place it: {hand}, rough positions (--positions) to confirm a link, or a "
        f"scan between it and {other}"
    )


def _stats(links: list[Link]) -> dict[str, float | None]:
    acc = [e for e in links if e.status == "accepted" and e.loop_error_m is not None]
    if not acc:
        return dict.fromkeys(
            (
                "bundle_error_m",
                "bundle_error_deg",
                "mean_link_error_m",
                "max_link_error_m",
                "mean_link_error_deg",
                "max_link_error_deg",
            ),
        )
    m = np.array([e.loop_error_m for e in acc], dtype=np.float64)  # links that close loops
    d = np.array([e.loop_error_deg for e in acc], dtype=np.float64)
    return {
        "bundle_error_m": float(np.sqrt(np.mean(m**2))),
        "bundle_error_deg": float(np.sqrt(np.mean(d**2))),
        "mean_link_error_m": float(m.mean()),
        "max_link_error_m": float(m.max()),
        "mean_link_error_deg": float(d.mean()),
        "max_link_error_deg": float(d.max()),
    }


def solve_graph(
    stations: list[str],
    links: list[Link],
    config: SurveyConfig | None = None,
    *,
    reference: str | None = None,
    vetoes: Sequence[Veto] = (),
    judge: Judge | None = None,
    fit: GroupFit | None = None,
    positions: Mapping[str, Position] | None = None,
    full: FullJudge | None = None,
) -> GraphSolution:
    """Steps 1-5 of this module: statuses of ``links`` (set in place), poses and groups.

    Parameters
    ----------
    stations : list of str
        Station stems, in file order (ties are broken by it).
    links : list of Link
        Attempted links; those without a transform are ``failed``. Statuses, loop errors,
        ``in_tree`` and ``confirmed_by_loop`` are written into them.
    config : SurveyConfig, optional
        Loop tolerances and the line process's prune threshold (default: defaults).
    reference : str, optional
        The station whose frame group 0 is solved in (default: the first station by name of
        the largest group).
    vetoes : sequence of Veto
        Pairs of stations the map check found contradicting each other: while a solution
        keeps one in its refuted configuration, the links between them no loop confirms are
        cut (step 5) and the graph solved again.
    judge : callable, optional
        ``judge(a, b, T_a_b)``: how much stations ``a`` and ``b`` contradict each other at
        that relative pose (:data:`~flexreg.survey.links.Judge`); it decides between
        distinct placements of two groups and names the wrong link of a cycle of confident
        links that does not close (step 1). Default: no judge.
    fit : callable, optional
        ``fit(target, source, X)``: where all the overlap of two groups of stations fits
        (:data:`~flexreg.survey.links.GroupFit`); with ``judge``, doorway links that slid
        along a wall are fitted on it (:func:`flexreg.survey.consensus.merge_groups`).
    positions : dict of str -> Position, optional
        Rough positions (:mod:`flexreg.survey.positions`): a placement of two groups they
        refute (:func:`~flexreg.survey.positions.refutes`) joins nothing.
    full : callable, optional
        ``full(a, b, T_a_b)``: the map's full-resolution test of two stations
        (:data:`~flexreg.survey.links.FullJudge`); with ``judge``, a pose the rough
        positions picked places what no other link does where it confirms it
        (:func:`flexreg.survey.consensus.merge_groups`).

    Returns
    -------
    GraphSolution

    Raises
    ------
    InputError
        ``reference`` is not one of ``stations``.
    """
    config = config if config is not None else SurveyConfig()
    dropped: dict[int, str] = {}
    maps = (judge, fit, positions or {}, full)
    sol = _solve_once(stations, links, config, reference, dropped, maps)
    for _ in range(len(links)):
        worst = _worst_residual(links, config)
        cuts = [worst] if worst is not None else _veto_cuts(sol, links, vetoes, config)
        if not cuts:
            break
        for e, why in cuts:
            dropped[id(e)] = why
        sol = _solve_once(stations, links, config, reference, dropped, maps)
    return sol


def _accepted_path(links: list[Link], a: str, b: str) -> list[Link]:
    """The accepted links of a shortest path from ``a`` to ``b`` (fewest links; ties in link
    order), or [] when there is none."""
    adj: dict[str, list[tuple[str, Link]]] = {}
    for e in links:
        if e.status == "accepted":
            adj.setdefault(e.target, []).append((e.source, e))
            adj.setdefault(e.source, []).append((e.target, e))
    steps = walk(adj, b, a)
    return [e for _, e in steps] if steps else []


def _nearest_held(unconfirmed: list[Link], path: list[Link], v: Veto) -> list[Link]:
    """The links of ``unconfirmed`` between the end of ``v`` that it does not hold right and
    the nearest station of :attr:`Veto.held` on ``path`` (from ``v.b`` to ``v.a``): where the
    map check saw every station up to it placed right, the wrong link lies beyond. All of
    ``unconfirmed`` when the veto holds no station, or both ends."""
    if not v.held or (v.a in v.held) == (v.b in v.held):
        return unconfirmed
    x, steps = (v.b, path) if v.a in v.held else (v.a, path[::-1])
    segment = []
    for e in steps:
        segment.append(e)
        x = e.source if e.target == x else e.target
        if x in v.held:
            break
    near = [e for e in unconfirmed if any(e is f for f in segment)]
    return near or unconfirmed


def _veto_cuts(
    sol: GraphSolution, links: list[Link], vetoes: Sequence[Veto], config: SurveyConfig
) -> list[tuple[Link, str]]:
    """The links to cut for the first veto the solution still violates: both stations in one
    group at (about) the refuted relative pose; [] when no veto is violated.

    One link of a path between them is wrong. A confident link that closes a loop of
    confident links has a second route that agrees with it; one that does not (a bridge, or
    an uncertain link) has nothing but its own registration, and in a hall that repeats bay
    by bay a wrong answer explains the scans as well as a right one (its free-space conflict
    ratio is no guide there). So every link of the path that no loop confirms is cut: the
    map says one of them is wrong and nothing says which. Only when a loop confirms every
    link of the path is the most doubtful one cut, with every link whose doubt is within
    ``MAP_DOUBT_MARGIN`` of it."""
    for v in vetoes:
        if v.a not in sol.poses or v.b not in sol.poses:
            continue
        if sol.group_of(v.a) != sol.group_of(v.b):
            continue
        rel = invert(sol.poses[v.a]) @ sol.poses[v.b]
        if rotation_error_deg(rel, v.T_a_b) > 1.0 or translation_error_m(rel, v.T_a_b) > 0.1:
            continue  # the configuration changed: the next map check looks at it again
        path = _accepted_path(links, v.a, v.b)
        if not path:
            continue
        said = (
            f"cut by the map check: {v.a} and {v.b} contradict each other where the links "
            f"place them ({v.why}); "
        )
        held = {frozenset(x) for x in _looped(_firm_edges(links))}
        loose = [e for e in path if frozenset((e.target, e.source)) not in held]
        unconfirmed = _nearest_held(loose, path, v)
        if unconfirmed:
            n = len(unconfirmed)
            which = (
                "one of those is wrong, and nothing tells which"
                if n == len(loose)
                else "the map saw the stations on the other side of it placed right"
            )
            return [
                (e, said + f"no loop confirms this one ({n} of the {len(path)} link(s) between "
                 f"them; {which})")
                for e in unconfirmed
            ]  # fmt: skip
        doubt = [max(float(e.doubt or 0.0), 1e-6) for e in path]
        top = max(doubt)
        return [
            (
                e,
                said + f"loops confirm each of the {len(path)} link(s) between them; this one "
                f"is the least trustworthy (free-space conflict ratio {d:.2f})",
            )
            for e, d in zip(path, doubt, strict=True)
            if d * MAP_DOUBT_MARGIN >= top
        ]
    return []


def _worst_residual(links: list[Link], config: SurveyConfig) -> tuple[Link, str] | None:
    """Step 6: the accepted link that fits the optimised poses worst, when it is beyond
    ``residual_factor`` times the median link residual (at least the floors), else None."""
    acc = [e for e in links if e.status == "accepted" and e.loop_error_m is not None]
    if len(acc) < 3:
        return None
    med_m = float(np.median([e.loop_error_m for e in acc]))
    med_d = float(np.median([e.loop_error_deg for e in acc]))
    thr_m = max(config.residual_floor_m, config.residual_factor * med_m)
    thr_d = max(config.residual_floor_deg, config.residual_factor * med_d)
    worst = max(acc, key=lambda e: max(e.loop_error_m / thr_m, e.loop_error_deg / thr_d))  # type: ignore[operator]
    m, d = float(worst.loop_error_m), float(worst.loop_error_deg)  # type: ignore[arg-type]
    if m <= thr_m and d <= thr_d:
        return None
    return worst, (
        f"is {1000 * m:.1f} mm / {d:.3f}° off the adjusted poses, far more than the other links "
        f"(limit {1000 * thr_m:.1f} mm / {thr_d:.3f}°: {config.residual_factor:g} x the median "
        "link's)"
    )


def _unchecked_groups_apart(
    ordered: list[list[str]],
    grefs: list[str],
    links: list[Link],
    poses: dict[str, Matrix],
    confidence: dict[str, str],
) -> tuple[list[list[str]], list[str]]:
    """A separate group (not the reference's) whose accepted links close no loop is given no
    pose: nothing checks it, and one confident look-alike answer would pose it wrongly in its
    own frame (the 64-station warehouse: two stations four bays apart). Its links are
    rejected and its stations listed alone, each saying what would place it."""
    keep_g, keep_r, apart = [ordered[0]], [grefs[0]], []
    for g, r in zip(ordered[1:], grefs[1:], strict=True):
        members = set(g)
        kept = [e for e in links if e.status == "accepted" and e.target in members]
        if len(g) > 1 and len(bridges([(e.target, e.source) for e in kept])) == len(kept):
            for e in kept:
                _reject(e, "no loop checks it: a single link places no station on its own")
            for x in g:
                poses.pop(x, None)
                confidence.pop(x, None)
            apart += [[x] for x in g]
            continue
        keep_g.append(g)
        keep_r.append(r)
    return keep_g + apart, keep_r + [g[0] for g in apart]


def _solve_once(
    stations: list[str],
    links: list[Link],
    config: SurveyConfig,
    reference: str | None,
    dropped: dict[int, str],
    maps: tuple[Judge | None, GroupFit | None, Mapping[str, Position], FullJudge | None] = (
        None,
        None,
        {},
        None,
    ),
) -> GraphSolution:
    """Steps 1-3 with the links of ``dropped`` rejected beforehand; ``maps``: the judge, the
    group fit, the rough positions and the full-resolution test."""
    for e in links:
        e.status, e.in_tree, e.confirmed_by_loop = "pending", False, False
        e.loop_error_deg = e.loop_error_m = None
        if e.T_target_source is None:
            e.status = "failed"
            e.why = e.why or "registration failed"
        else:  # a reason from an earlier solve would stay on a link accepted now
            e.why = dropped.get(id(e)) or e.refused or None
            if e.why is not None:
                e.status = "rejected"
    forest = _choose(stations, links, config, *maps)
    comp = forest.root
    ref = _reference(stations, comp, links, reference)
    members: dict[str, list[str]] = {}
    for s in stations:
        members.setdefault(comp[s], []).append(s)
    ordered = sorted(
        members.values(),
        key=lambda g: (ref not in g, -len(g), stations.index(g[0])),
    )
    poses: dict[str, Matrix] = {}
    grefs: list[str] = []
    confidence: dict[str, str] = {}
    for g in ordered:
        gref = ref if ref in g else _reference(g, comp, links, None)
        grefs.append(gref)
        if len(g) < 2:
            continue
        inv = invert(forest.pose[gref])
        start = {s: inv @ forest.pose[s] for s in g}
        for _ in range(3):
            solved, pruned = _optimise(g, gref, start, links, config)
            late = []
            for e in links:
                if e.status != "pending" or e.target not in solved or e.in_tree:
                    continue
                err = loop_error(np.asarray(e.T_target_source), solved[e.target], solved[e.source])
                if e in pruned:
                    _reject(e, "disagrees with the other links: the adjustment left it out", err)
                    late.append(e)
                elif not _consistent(err, 2, config):
                    _reject(e, "disagrees with the optimised poses", err)
                    late.append(e)
            start = solved
            if not late:
                break
        kept = [e for e in links if e.status == "pending" and e.target in start]
        alone = bridges([(e.target, e.source) for e in kept])  # they close no loop: unchecked
        for i, e in enumerate(kept):
            e.status = "accepted"
            if i not in alone:
                e.loop_error_deg, e.loop_error_m = loop_error(
                    np.asarray(e.T_target_source), start[e.target], start[e.source]
                )
        firm = _firm_edges(links, g)
        if gref != reference:  # not the surveyor's: the frame of the largest confirmed block
            frame = _firm_reference(g, firm)
            inv = invert(start[frame])
            start = {s: inv @ P for s, P in start.items()}
            if gref == ref:
                ref = frame
            gref = grefs[-1] = frame
        poses.update(start)
        confidence.update(_confidence(g, gref, firm))
    for e in links:  # anything left (between groups) was never confirmed
        if e.status == "pending":
            _reject(e, "joins two groups with no confirming loop")
        if (
            e.status == "rejected"
            and e.loop_error_m is None
            and e.target in poses
            and e.source in poses
            and comp[e.target] == comp[e.source]
        ):  # a dropped tree link: how far it is from the final poses
            e.loop_error_deg, e.loop_error_m = loop_error(
                np.asarray(e.T_target_source), poses[e.target], poses[e.source]
            )
    ordered, grefs = _unchecked_groups_apart(ordered, grefs, links, poses, confidence)
    placed = set(ordered[0]) if len(ordered[0]) > 1 else set()
    reasons = {s: _why_unplaced(s, g, links, placed) for g in ordered[1:] for s in g}
    if len(ordered[0]) < 2:
        reasons[ordered[0][0]] = _why_unplaced(ordered[0][0], ordered[0], links, placed)
    return GraphSolution(ref, poses, ordered, grefs, confidence, reasons, _stats(links))


__all__ = [
    "GraphSolution",
    "Judge",
    "Link",
    "Veto",
    "loop_error",
    "single_link",
    "solve_graph",
    "uncertain_via",
]
