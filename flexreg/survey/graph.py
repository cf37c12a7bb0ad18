"""The station graph: which links to keep, where each station is, which groups exist.

Each registered link carries its transform, its verdict and its information matrix. A wrong
link must not place a station, so the graph is built in steps that each trust less:

1. **Spanning tree of the confident links**, most trusted first (Kruskal; trust = overlap,
   lowered by the link's doubt: the share of one scan its own check put in the other's free
   space, relative to what it explains).
2. **Loop closure**: every other confident link closes a cycle with the tree; it agrees with
   the cycle when the composed transforms meet within ``loop_max_deg`` and ``loop_max_m``
   (+ ``loop_per_link_m`` per link of the cycle). A disagreeing cycle blames the tree links
   on it, an agreeing one supports them; when one link of the disagreeing cycle is far more
   doubtful than the others (``loop_doubt_ratio``, at least ``loop_doubt_min``), only that
   one is blamed (or rejected, when it is the closing link). A tree link blamed more than
   supported is dropped and the tree rebuilt without it; when the blame is tied (one
   triangle, nobody can tell which link is wrong) every link of that cycle is dropped. What
   is left disagreeing is rejected, with its loop error. Given a *judge* (the map check's
   dense scores, :class:`flexreg.survey.mapcheck.PairJudge`), a disagreeing cycle is first
   put to it: for each link, the rest of the cycle places that link's two stations, and the
   judge says how much of what each sees lands in the other's free space. When one link's
   hypothesis is clean and every other contradicts ``map_judge_ratio`` times as much (and
   at least ``map_min_conflict`` of a scan), that link alone is blamed (identical rooms:
   the link that overlays two twins is the one whose removal leaves a consistent map).
3. **Uncertain links** never place a station alone: one inside a group is kept when it agrees
   with the group's poses; between groups they are rejected, unless ``uncertain_joins`` lets
   two or more that agree on the same relative pose (a loop through both) join the groups,
   or the map allows no other placement of a group (``Link.map_joined``, set by
   :mod:`flexreg.survey.groupjoin`).
4. **Robust pose-graph optimisation** per group (Open3D's ``PoseGraph`` with its line
   process): tree links are trusted edges, the others loop-closure edges the line process
   may switch off; a pruned edge, or one that still disagrees with the optimised poses, is
   rejected and the optimisation rerun.
5. **Groups**: connected components of the kept links, never fused. Group 0 holds the
   reference (the given station, or the first by name of the largest group).
6. **Residuals**: a link can agree with its loops within the loop tolerance and still be a
   few centimetres off, pulling the optimised poses. The accepted link that fits the
   optimised poses worst is dropped when it is beyond ``residual_factor`` times the median
   residual of the accepted links (at least ``residual_floor_m`` / ``residual_floor_deg``),
   and everything is solved again without it, until every link fits.
7. **Vetoes** from the map check (:mod:`flexreg.survey.mapcheck`): two placed stations
   whose scans contradict each other at their solved relative pose (linked or not) mean a
   wrong link between them; the most doubtful one on a path between them (the highest
   free-space conflict ratio of its own check) is cut and everything solved again.
8. **Lone links in repeating structure** (:mod:`flexreg.survey.lone`): a separate group held
   only by unconfirmed tree links, one of whose stations has a whole-bay ambiguous link,
   poses nothing; its links are cut and everything solved again.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence

import numpy as np

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.errors import InputError
from flexreg.survey.config import SurveyConfig
from flexreg.survey.links import (
    GraphSolution,
    Judge,
    Link,
    Matrix,
    Veto,
    bridges,
    judged_culprit,
    loop_error,
)
from flexreg.survey.lone import lone_cuts, lone_suspect

log = logging.getLogger(__name__)


# ------------------------------------------------------------------------------ helpers


class _Forest:
    """Spanning forest of a set of links with the poses it implies."""

    def __init__(self, stems: list[str], tree: list[Link]) -> None:
        self.adj: dict[str, list[tuple[str, Link]]] = {s: [] for s in stems}
        for e in tree:
            self.adj[e.target].append((e.source, e))
            self.adj[e.source].append((e.target, e))
        self.parent: dict[str, tuple[str, Link] | None] = {}
        self.depth: dict[str, int] = {}
        self.root: dict[str, str] = {}
        self.pose: dict[str, Matrix] = {}
        for s in stems:
            if s not in self.parent:
                self._walk(s)

    def _walk(self, root: str) -> None:
        self.parent[root], self.depth[root], self.root[root] = None, 0, root
        self.pose[root] = np.eye(4)
        queue = deque([root])
        while queue:
            a = queue.popleft()
            for b, e in self.adj[a]:
                if b in self.parent:
                    continue
                T = np.asarray(e.T_target_source)
                self.pose[b] = self.pose[a] @ (T if e.target == a else invert(T))
                self.parent[b], self.depth[b], self.root[b] = (a, e), self.depth[a] + 1, root
                queue.append(b)

    def path(self, a: str, b: str) -> list[Link]:
        """The tree links between two stations of one tree."""
        out: list[Link] = []
        while a != b:
            if self.depth[a] >= self.depth[b]:
                pa = self.parent[a]
                assert pa is not None
                out.append(pa[1])
                a = pa[0]
            else:
                pb = self.parent[b]
                assert pb is not None
                out.append(pb[1])
                b = pb[0]
        return out

    def components(self) -> dict[str, list[str]]:
        out: dict[str, list[str]] = {}
        for s, r in self.root.items():
            out.setdefault(r, []).append(s)
        return out


def _trust(e: Link) -> float:
    """How much a link is trusted to place a station: its overlap, less for a link whose own
    check put much of one scan in the other's free space (its doubt)."""
    return e.overlap * max(0.05, 1.0 - 2.0 * float(e.doubt or 0.0))


def _standout(loop: list[Link], config: SurveyConfig) -> Link | None:
    """The link of a disagreeing loop whose doubt stands out: at least ``loop_doubt_min``
    and ``loop_doubt_ratio`` times every other link's doubt of the loop; else None."""
    ranked = sorted(loop, key=lambda e: -float(e.doubt or 0.0))
    top = float(ranked[0].doubt or 0.0)
    second = float(ranked[1].doubt or 0.0) if len(ranked) > 1 else 0.0
    if top >= config.loop_doubt_min and top >= config.loop_doubt_ratio * second:
        return ranked[0]
    return None


def _kruskal(stems: list[str], links: list[Link]) -> tuple[list[Link], list[Link]]:
    """Tree links (most trusted first, joining separate trees) and the rest."""
    up = {s: s for s in stems}

    def find(x: str) -> str:
        while up[x] != x:
            up[x] = up[up[x]]
            x = up[x]
        return x

    tree, rest = [], []
    for e in sorted(links, key=lambda e: -_trust(e)):
        a, b = find(e.target), find(e.source)
        if a != b:
            up[a] = b
            tree.append(e)
        else:
            rest.append(e)
    return tree, rest


def _consistent(err: tuple[float, float], hops: int, config: SurveyConfig) -> bool:
    tol_m = config.loop_max_m + config.loop_per_link_m * hops
    return err[0] <= config.loop_max_deg and err[1] <= tol_m


def _reject(e: Link, why: str, err: tuple[float, float] | None = None) -> None:
    e.status, e.why, e.in_tree = "rejected", why, False
    if err is not None:
        e.loop_error_deg, e.loop_error_m = float(err[0]), float(err[1])


# ------------------------------------------------------------------------------ steps


def _confident_tree(
    stems: list[str], links: list[Link], config: SurveyConfig, judge: Judge | None = None
) -> _Forest:
    """Steps 1 and 2: the tree of confident links after the loop checks."""
    active = [e for e in links if e.trusted and e.status == "pending"]
    while True:
        tree, rest = _kruskal(stems, active)
        forest = _Forest(stems, tree)
        blame: dict[int, int] = {}
        support: dict[int, int] = {}
        judged: dict[int, bool] = {}
        bad: list[tuple[Link, list[Link], tuple[float, float]]] = []
        agreeing: list[Link] = []
        for e in rest:
            p = forest.path(e.target, e.source)
            err = loop_error(
                np.asarray(e.T_target_source), forest.pose[e.target], forest.pose[e.source]
            )
            if _consistent(err, len(p) + 1, config):
                e.confirmed_by_loop = True
                e.loop_error_deg, e.loop_error_m = err
                agreeing.append(e)
                for t in p:
                    support[id(t)] = support.get(id(t), 0) + 1
                    t.confirmed_by_loop = True
            else:
                suspect = judged_culprit(
                    [e, *p], judge, config.map_judge_ratio, config.map_min_conflict
                )
                if suspect is not None:
                    judged[id(suspect)] = True
                    if suspect is e:
                        _reject(e, _MAP_BLAMES, err)
                        continue
                else:
                    suspect = _standout([e, *p], config)
                    if suspect is e:  # the closer alone is far more doubtful than the loop
                        _reject(
                            e,
                            "disagrees with the loop it closes, and is that loop's least "
                            "trustworthy link (its scans clash most: open space against surface)",
                            err,
                        )
                        continue
                bad.append((e, p, err))
                for t in [suspect] if suspect is not None else p:
                    blame[id(t)] = blame.get(id(t), 0) + 1
        if any(e.status == "rejected" for e in rest):
            active = [e for e in active if e.status != "rejected"]
            if not bad:
                continue
        if not bad:
            confirmed = agreeing + [t for t in tree if support.get(id(t), 0) > 0]
            lone = lone_suspect(forest, tree, support, confirmed, links, config)
            if not lone:
                break
            for t, why in lone:
                _reject(t, why)
            active = [e for e in active if e.status != "rejected"]
            continue
        net = {id(t): blame.get(id(t), 0) - support.get(id(t), 0) for t in tree}
        worst = max(net.values(), default=0)
        if worst <= 0:  # every blamed tree link is better supported: the closers are wrong
            for e, _, err in bad:
                _reject(e, "disagrees with the loop it closes", err)
            active = [e for e in active if e.status != "rejected"]
            continue
        culprits = [t for t in tree if net[id(t)] == worst]
        for t in culprits:
            _reject(
                t,
                _MAP_BLAMES
                if judged.get(id(t))
                else f"{blame.get(id(t), 0)} disagreeing loop(s) run through it, no agreeing one",
            )
        for e, p, err in bad:
            if len(culprits) > 1 and any(t in culprits for t in p):
                _reject(e, "closes a loop whose links disagree; nothing tells which is wrong", err)
        active = [e for e in active if e.status != "rejected"]
    for e in tree:
        e.in_tree = True
    return forest


_MAP_BLAMES = (
    "disagrees with a loop, and the map blames it: without this link the loop's stations land "
    "where their scans agree; with it, one scan lies where another saw open space"
)


def _bridge(stems: list[str], forest: _Forest, links: list[Link], config: SurveyConfig) -> None:
    """Step 3: uncertain links join groups only in agreeing pairs; inside a group they are
    kept when they agree with its poses."""
    uncertain = sorted(
        (e for e in links if not e.trusted and e.status == "pending"),
        key=lambda e: -e.overlap,
    )
    comp = forest.root
    tol_m = config.loop_max_m + 2 * config.loop_per_link_m
    changed = config.uncertain_joins or any(e.map_joined for e in uncertain)
    while changed:
        changed = False
        between: dict[tuple[str, str], list[tuple[Link, Matrix]]] = {}
        for e in uncertain:
            ct, cs = comp[e.target], comp[e.source]
            if ct == cs:
                continue
            # pose of the source's group frame in the target's group frame, by this link
            rel = (
                forest.pose[e.target]
                @ np.asarray(e.T_target_source)
                @ invert(forest.pose[e.source])
            )
            if ct < cs:
                between.setdefault((ct, cs), []).append((e, rel))
            else:
                between.setdefault((cs, ct), []).append((e, invert(rel)))
        for (ct, cs), items in sorted(between.items()):
            best: list[tuple[Link, Matrix]] = []
            for _, r0 in items:
                agree = [
                    (e, r)
                    for e, r in items
                    if rotation_error_deg(r, r0) <= config.loop_max_deg
                    and translation_error_m(r, r0) <= tol_m
                ]
                if (any(e.map_joined for e, _ in agree), len(agree)) > (
                    any(e.map_joined for e, _ in best),
                    len(best),
                ):
                    best = agree
            if not any(e.map_joined for e, _ in best) and (
                len(best) < 2 or not config.uncertain_joins
            ):
                continue
            rel = best[0][1]
            for s in stems:
                if comp[s] == cs:
                    forest.pose[s] = rel @ forest.pose[s]
                    comp[s] = ct
            best.sort(key=lambda x: not x[0].map_joined)  # the map's link is the tree link
            for i, (e, _) in enumerate(best):
                e.confirmed_by_loop = e.confirmed_by_loop or len(best) > 1
                e.in_tree = i == 0
            changed = True
            break
    for e in uncertain:
        if e.in_tree:
            continue
        if comp[e.target] != comp[e.source]:
            why = (
                "uncertain, and no second link confirms it"
                if config.uncertain_joins
                else "uncertain (see the link's reasons), and one uncertain link never joins groups"
            )
            _reject(e, why)
            continue
        err = loop_error(
            np.asarray(e.T_target_source), forest.pose[e.target], forest.pose[e.source]
        )
        pick = (
            None
            if _consistent(err, 2, config)
            else e.agreeing_alternative(
                forest.pose[e.target], forest.pose[e.source], lambda x: _consistent(x, 2, config)
            )
        )
        if pick is not None:  # an alias pair: the loop picks the right one of its poses
            e.take(pick[0], "the loop")
            err = pick[1]
        if _consistent(err, 2, config):
            e.confirmed_by_loop = True
            e.loop_error_deg, e.loop_error_m = err
        else:
            _reject(e, "uncertain, and the group's other links place its stations elsewhere", err)


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
                uncertain=not e.in_tree,
            )
        )
    if not edges:
        return dict(poses), []
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=config.loop_max_m,
        edge_prune_threshold=config.prune_threshold,
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


def _confidence(group: list[str], ref: str, links: list[Link]) -> dict[str, str]:
    """``confident`` when joined to ``ref`` by confident accepted links alone."""
    adj: dict[str, list[str]] = {s: [] for s in group}
    for e in links:
        if e.status == "accepted" and e.trusted and e.target in adj:
            adj[e.target].append(e.source)
            adj[e.source].append(e.target)
    seen, queue = {ref}, deque([ref])
    while queue:
        for b in adj[queue.popleft()]:
            if b not in seen:
                seen.add(b)
                queue.append(b)
    return {s: "confident" if s in seen else "uncertain" for s in group}


def _why_unplaced(stem: str, group: list[str], links: list[Link], placed: set[str]) -> str:
    """Why a station is not placed, and the one thing that would place it."""
    members = set(group)
    mine = [e for e in links if (e.target in members) != (e.source in members)]
    mine = mine if len(group) > 1 else [e for e in links if stem in (e.target, e.source)]
    toward = [e for e in mine if (e.target in placed) or (e.source in placed)]
    near = sorted({x for e in toward or mine for x in (e.target, e.source)} - members)
    other = near[0] if near else "STATION"
    side = next(iter(sorted(members & {x for e in toward for x in (e.target, e.source)})), stem)
    hand = f"--link {other} {side} T.txt (a transform from flexreg register {other} {side})"
    what = (
        f"in a separate group of {len(group)} stations: no confident link, nor one a loop "
        "confirms, joins it to the reference's group"
        if len(group) > 1
        else "no link was tried (no other scan seemed to see the same place)"
        if not mine
        else f"all {len(mine)} link(s) failed to register"
        if all(e.status == "failed" for e in mine)
        else f"no link places it ({len(mine)} tried: "
        + "; ".join(sorted({e.why or e.status for e in mine if e.status != "accepted"}))
        + ")"
    )
    n = max((1 + len(e.alternatives) for e in toward if e.usable), default=1)
    said = next((e.undecided for e in toward if e.undecided), "")
    if said:
        return f"{what}; the rough positions cannot place it ({said}): {hand}"
    if n > 1:
        return (
            f"{what}; its link with {other} fits {n} poses (look-alike rooms or bays): rough "
            f"positions of both (--positions) would pick one, or {hand}"
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
) -> GraphSolution:
    """Steps 1-6 of this module: statuses of ``links`` (set in place), poses and groups.

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
        keeps one in its refuted configuration, the most doubtful link between them is cut
        (step 7) and the graph solved again.
    judge : callable, optional
        ``judge(a, b, T_a_b)``: whether stations ``a`` and ``b`` contradict each other at
        that relative pose (True / False / None when it cannot tell); it decides which link
        of a disagreeing loop to blame where it can (step 2). Default: no judge.

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
    sol = _solve_once(stations, links, config, reference, dropped, judge)
    for _ in range(len(links)):
        worst = _worst_residual(links, config)
        cuts = [worst] if worst is not None else _veto_cuts(sol, links, vetoes, config)
        cuts = cuts or lone_cuts(sol, links)  # step 8: lone links in repeating structure
        if not cuts:
            break
        for e, why in cuts:
            dropped[id(e)] = why
        sol = _solve_once(stations, links, config, reference, dropped, judge)
    return sol


def _accepted_path(links: list[Link], a: str, b: str) -> list[Link]:
    """The accepted links of a shortest path from ``a`` to ``b`` (fewest links; ties in link
    order), or [] when there is none."""
    adj: dict[str, list[tuple[str, Link]]] = {}
    for e in links:
        if e.status == "accepted":
            adj.setdefault(e.target, []).append((e.source, e))
            adj.setdefault(e.source, []).append((e.target, e))
    back: dict[str, tuple[str, Link] | None] = {a: None}
    queue = deque([a])
    while queue and b not in back:
        x = queue.popleft()
        for y, e in adj.get(x, []):
            if y not in back:
                back[y] = (x, e)
                queue.append(y)
    if b not in back:
        return []
    path, x = [], b
    while (step := back[x]) is not None:
        x, e = step
        path.append(e)
    return path


def _veto_cuts(
    sol: GraphSolution, links: list[Link], vetoes: Sequence[Veto], config: SurveyConfig
) -> list[tuple[Link, str]]:
    """The links to cut for the first veto the solution still violates: both stations in one
    group at (about) the refuted relative pose. The most doubtful accepted link of a path
    between them is cut, with every link of the path whose doubt is within
    ``map_doubt_margin`` of it; [] when no veto is violated."""
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
        doubt = [max(float(e.doubt or 0.0), 1e-6) for e in path]
        top = max(doubt)
        cut = [e for e, d in zip(path, doubt, strict=True) if d * config.map_doubt_margin >= top]
        return [
            (
                e,
                f"cut by the map check: {v.a} and {v.b} contradict each other where the "
                f"links place them ({v.why}); of the {len(path)} link(s) between them this one "
                f"is the least trustworthy (free-space conflict ratio {d:.2f})",
            )
            for e, d in zip(path, doubt, strict=True)
            if e in cut
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


def _solve_once(
    stations: list[str],
    links: list[Link],
    config: SurveyConfig,
    reference: str | None,
    dropped: dict[int, str],
    judge: Judge | None = None,
) -> GraphSolution:
    """Steps 1-5 with the links of ``dropped`` rejected beforehand."""
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
    forest = _confident_tree(stations, links, config, judge)
    _bridge(stations, forest, links, config)
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
        poses.update(start)
        kept = [e for e in links if e.status == "pending" and e.target in start]
        alone = bridges([(e.target, e.source) for e in kept])  # they close no loop: unchecked
        for i, e in enumerate(kept):
            e.status = "accepted"
            if i not in alone:
                e.loop_error_deg, e.loop_error_m = loop_error(
                    np.asarray(e.T_target_source), start[e.target], start[e.source]
                )
        confidence.update(_confidence(g, gref, links))
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
    placed = set(ordered[0]) if len(ordered[0]) > 1 else set()
    reasons = {s: _why_unplaced(s, g, links, placed) for g in ordered[1:] for s in g}
    if len(ordered[0]) < 2:
        reasons[ordered[0][0]] = _why_unplaced(ordered[0][0], ordered[0], links, placed)
    return GraphSolution(ref, poses, ordered, grefs, confidence, reasons, _stats(links))


__all__ = ["GraphSolution", "Judge", "Link", "Veto", "loop_error", "solve_graph"]
