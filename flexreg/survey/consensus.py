"""Which pose of each link the survey keeps: the hypotheses that agree around cycles.

Every registered link offers hypotheses: its answer and, when its verdict is uncertain, the
clearly different poses that fit almost as well (its runner-ups, its twins one bay or room
along; :class:`~flexreg.survey.links.Alternative`). A confident verdict has decided between
its poses on the dense check, and a link the surveyor vouched for (``--link``, rough
positions) offers its one pose. One mechanism chooses among them for the whole project:
pairwise consistency maximisation (PCM, Mangelson et al., ICRA 2018) applied between groups
of stations, the way PCM merges the maps of several robots.

1. **Cycle votes** (:mod:`flexreg.survey.hypotheses`). Every short cycle, and every longer
   one through the spanning forest of the trusted answers, is composed for every
   combination of its links' hypotheses; one that closes within the loop tolerance votes
   for each of them (a *firm* vote when the rest of the cycle is trusted answers), and a
   cycle of trusted answers that does not close contradicts each of them.
2. **Merges** (:func:`merge_groups`). Starting from single stations, the hypotheses of the
   links between two groups form consistent sets: two are consistent when the cycle they
   close through the groups' own poses meets (PCM's test, the groups' poses in the role of
   odometry). Sets rank by whether a loop of confident answers confirms them (below), then
   by trusted answers, their firm votes, links, all votes, the surveyor's word and weight:
   a placement two registrations confirm around a loop outranks one that a lone trusted
   answer gives. A placement rough positions refute (either group's fit to its positions
   puts a station of the other beyond three sigma of its own,
   :func:`~flexreg.survey.positions.refutes`) is no hypothesis: all of a station's links
   aliased alike a bay along agree around every loop, and only the positions tell. The
   best set of the whole project merges its groups when a loop of confident answers
   confirms it (two of them in it, each trusted, confident inside
   rough positions' windows, or an uncertain link's pose the positions picked, or a firm
   vote of a link's answer: a twin or runner-up closing a cycle is no independent route)
   and no distinct placement of the same groups is as well supported; then everything is
   looked at again.
   Uncertain links confirm each other only when rough positions picked their poses (the
   positions say which bay or room each means) or when nothing but their small overlap, or
   open space their even samples find and full resolution clears, doubts them
   (:attr:`~flexreg.survey.links.Link.plain`: two doorway links of different
   pairs of scans, each finding one pose and nothing against it, that agree to the loop
   tolerance, or that reach one placement once fitted on all the overlap of the two
   groups: a doorway link may slide along a wall, :func:`_refit`; the map then tests what
   they place at full resolution): in look-alike rooms
   and bays several uncertain links are wrong the same way, for the twins, rivals or open
   space that made them uncertain. Nor do they settle a dispute between trusted answers: one
   that a cycle of trusted answers contradicts and none confirms is *disputed* (one link of
   that cycle is wrong, and nothing says it is not this one), and a cycle through it is no
   firm vote; where two distinct placements of the same groups each hold a trusted answer
   and the best is contradicted, only the map decides. (A room that looks the same turned
   half round aliases every link of its station alike: a confident answer and the uncertain
   links of that station then agree on the turn.) Where distinct placements compete, the map's
   free-space check may pick the one under which the groups' nearest stations see each
   other without contradiction, every other contradicting decisively more. Once no such
   merge is left, a lone trusted answer (or the surveyor's word) places its stations
   unchecked unless the map check refutes it; one that a cycle of trusted answers
   contradicts, only where the map sees the groups at ease. A pose the rough positions
   picked alone places what it joins where the map's full-resolution test confirms it:
   the groups' nearest stations see each other there with nothing in open space, and every
   other distinct placement such a pose proposes puts their points where the others saw
   through (:func:`_sited`; the positions chose the bay, the test the turn their 30-degree
   window leaves open). When nothing else is left the map may name the wrong link of a
   cycle of trusted answers that does not close (:func:`_blame`).
3. **Inside a group**, every other link keeps the hypothesis that agrees with the group's
   poses (a loop picks an alias pair's right pose), or is rejected with its loop error.

Two separate sites are never fused: a merge needs a loop of trusted answers, the
surveyor's word or the map between them. The mechanism has no setting of its own: the loop
tolerances (the scanner's noise), the registration's ``judge.ambiguity_ratio`` (what a close
rival is) and ``judge.decisive_ratio`` (what a decisive win is), and the map check's
thresholds decide.
"""

from __future__ import annotations

import logging
from collections.abc import Container, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from flexreg.core.transforms import invert
from flexreg.survey.hypotheses import Cycle, Hypothesis, LoopTolerance
from flexreg.survey.links import (
    FullJudge,
    GroupFit,
    Judge,
    Matrix,
    loop_error,
    map_refutes,
    map_sees,
)
from flexreg.survey.positions import Position, refutes

log = logging.getLogger(__name__)

#: Most distinct placements of two groups the map's free-space check looks at: where more
#: remain, the groups stay apart (a periodic hall offers one per bay).
MAP_PLACEMENTS = 6
#: Pairs of stations, one of each group, the map's check scores per placement: the nearest.
MAP_PAIRS = 8
#: Of those, the pairs its full-resolution test looks at per placement (:func:`_sited`): a
#: quarter of a second each, in the graph's own process.
FULL_PAIRS = 4


# ------------------------------------------------------------------ step 2: merges


@dataclass
class Placement:
    """Groups and the poses of their stations in each group's frame.

    Attributes
    ----------
    root : dict of str -> str
        The group (its first station) of every station.
    pose : dict of str -> (4, 4) float64
        ``T_group_station``.
    """

    root: dict[str, str]
    pose: dict[str, Matrix]

    def members(self, r: str) -> list[str]:
        return [s for s, g in self.root.items() if g == r]


@dataclass(frozen=True, eq=False)
class Chosen:
    """What a merge gave a link: its hypothesis, whether it is the merge's own link (the
    others of its set close loops with it), what decided (``"loop"``, ``"map"``; ``"fit"``
    for a link whose own pose is off the placement its fitted pose joined, :func:`_refit`)
    and whether a loop confirms it."""

    hypothesis: Hypothesis
    centre: bool
    how: str
    by_loop: bool


@dataclass(eq=False)
class _Set:
    """A consistent set of hypotheses between two groups, one per link."""

    centre: Hypothesis
    X: Matrix  # T_g1_g2 the centre proposes
    members: list[Hypothesis]

    @property
    def rank(self) -> tuple[int, int, int, int, int, float]:
        """Trusted answers, their cycles, links, all cycles, the surveyor's word, weight."""
        return (
            sum(h.firm for h in self.members),
            sum(h.firm_votes for h in self.members),
            len(self.members),
            sum(h.votes for h in self.members),
            sum(h.vouched for h in self.members),
            sum(h.weight for h in self.members),
        )

    @property
    def standing(self) -> tuple[bool, int, bool, int, int, int, int]:
        """Whether a loop with a confident registration confirms it, its trusted answers,
        whether a loop confirms it at all, then the rest of its rank without the weight: a
        placement two registrations confirm around a loop outranks one a lone trusted
        answer gives, however many (a bay-off answer confident on its own against two
        confident inside rough positions' windows that agree, on a warehouse); one that
        only poses the positions picked confirm does not outrank a confident answer (two
        doorway links slid alike by a wall's thickness agree with each other, not with
        the confident link of the right placement)."""
        r = self.rank
        how = self.confirmed_by
        return (how == "registration", r[0], bool(how), r[1], r[2], r[3], r[4])

    @property
    def misfit(self) -> float:
        """Mean cycle misfit of its voted members (0 without votes)."""
        votes = sum(h.votes for h in self.members)
        return sum(h.misfit for h in self.members) / votes if votes else 0.0

    @property
    def firmly_confirmed(self) -> bool:
        """A loop of confident answers closes through it: two of its links are (trusted, or
        confident inside rough positions' windows: each registered on its own scans, they
        agree to the loop tolerance, which a pose slid or a bay off in one of them does not),
        or a cycle of trusted answers closes through one of its links' answers. An
        alternative closing such a cycle is no independent route: an uncertain link's twins
        offer its pose one bay along each way, so in a hall of identical bays one of them
        agrees with any trusted answer a whole number of bays off. A pose rough positions
        picked of an uncertain link counts as one too: the positions decided which bay or
        room that link means (none other of its poses lay within their window), and the
        loop holds it to the centimetre, with a confident registration or with a second
        picked pose of another pair of scans (two doorway links of a room, each uncertain
        for the little the scans share, that agree to the loop tolerance: a slide of either
        opens the loop). One picked pose alone does not: positions pick a bay, not
        centimetres. Two answers of links uncertain only for their small overlap
        (:attr:`Hypothesis.plain`) count as picked poses do: each registration found one pose
        and nothing against it, and a slide of either opens the loop."""
        return bool(self.confirmed_by)

    @property
    def confirmed_by(self) -> str:
        """What confirms it around a loop (:attr:`firmly_confirmed`): ``"registration"``
        when a confident answer is among the two, or a cycle of trusted answers closes
        through one of its answers; ``"positions"`` when only poses the positions picked
        do, with or without plain answers (:attr:`Hypothesis.plain`); ``"overlap"`` when
        only plain answers do; empty when nothing does."""
        confident = sum(h.confident for h in self.members)
        sited = sum(h.sited and not h.confident for h in self.members)
        plain = sum(h.plain for h in self.members)
        if any(h.firm_votes for h in self.members if h.alternative is None) or (
            confident and confident + sited + plain >= 2
        ):
            return "registration"
        if sited + plain >= 2:
            return "positions" if sited else "overlap"
        return ""


def _placed(place: Placement, X: Matrix, g2: str, s: str) -> Matrix:
    return X @ place.pose[s] if place.root[s] == g2 else place.pose[s]


def _fit(h: Hypothesis, place: Placement, X: Matrix, g2: str) -> tuple[float, float]:
    """Loop error (degrees, metres) of hypothesis ``h`` (its :attr:`~Hypothesis.refit` when
    it has one) where ``X`` (``T_g1_g2``) places group ``g2``."""
    T = h.T if h.refit is None else h.refit
    return loop_error(T, _placed(place, X, g2, h.link.target), _placed(place, X, g2, h.link.source))


#: Placements :meth:`_Fits.many` scores at once.
_FITS_BLOCK = 32


class _Fits:
    """:func:`_fit` of every hypothesis of ``items`` at once, for any placement ``X``
    (``T_g1_g2``) of group ``g2``: each link joins the two groups, so its loop closes as
    ``inv(P_target) X P_source`` (source in ``g2``) or ``inv(P_target) inv(X) P_source``
    (target in ``g2``), with the stations' poses in their groups' frames."""

    def __init__(self, items: Sequence[Hypothesis], place: Placement, g2: str) -> None:
        T = [h.T if h.refit is None else h.refit for h in items]
        self.T = np.stack(T) if T else np.zeros((0, 4, 4))
        self.left = np.stack([invert(place.pose[h.link.target]) for h in items] or [np.eye(4)])
        self.right = np.stack([place.pose[h.link.source] for h in items] or [np.eye(4)])
        self.flip = np.asarray([place.root[h.link.target] == g2 for h in items], dtype=bool)

    def __call__(self, X: Matrix) -> tuple[np.ndarray, np.ndarray]:
        """Loop errors (degrees, metres), one per hypothesis, where ``X`` places ``g2``."""
        deg, m = self.many(np.asarray(X, dtype=np.float64)[None])
        return deg[0], m[0]

    def many(self, Xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Loop errors (degrees, metres), (K, N): of every hypothesis where each of ``Xs``
        ((K, 4, 4) placements of ``g2``) places it."""
        k, n = len(Xs), len(self.T)
        deg, m = np.zeros((k, n)), np.zeros((k, n))
        for i in range(0, k, _FITS_BLOCK):  # a few MB at a time
            X = Xs[i : i + _FITS_BLOCK]
            inv = np.stack([invert(x) for x in X])
            mid = np.where(self.flip[None, :, None, None], inv[:, None], X[:, None])
            rel = self.left[None] @ mid @ self.right[None]
            c = (np.einsum("nij,knij->kn", self.T[:, :3, :3], rel[..., :3, :3]) - 1.0) / 2.0
            gap = self.T[None, :, :3, 3] - rel[..., :3, 3]
            deg[i : i + _FITS_BLOCK] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
            m[i : i + _FITS_BLOCK] = np.linalg.norm(gap, axis=-1)
        return deg, m


def _sets(
    place: Placement,
    g1: str,
    g2: str,
    items: list[Hypothesis],
    tol: LoopTolerance,
    positions: Mapping[str, Position] | None = None,
) -> list[_Set]:
    """The consistent sets between groups ``g1`` and ``g2``, best first: one per hypothesis
    as its centre, with the best-fitting hypothesis of every other link that agrees with
    the placement it proposes (the cycle through both and the groups' poses closes); none
    whose placement rough ``positions`` refute (:func:`~flexreg.survey.positions.refutes`)."""
    out = []
    first = {s: place.pose[s] for s in place.members(g1)}
    centres = [c for c in items if c.refit is None]  # a refitted one places nothing itself
    Xs = [_proposal(c, place, g1) for c in centres]
    degs, ms = _Fits(items, place, g2).many(np.stack(Xs) if Xs else np.zeros((0, 4, 4)))
    for c, X, deg, m in zip(centres, Xs, degs, ms, strict=True):
        if positions and refutes(
            positions, first, {s: X @ place.pose[s] for s in place.members(g2)}
        ):
            continue
        best: dict[int, tuple[float, Hypothesis]] = {id(c.link): (0.0, c)}
        ok = (deg <= tol.max_deg) & (m <= tol.metres(4))
        for i in np.flatnonzero(ok):
            h = items[i]
            if h.link is c.link:
                continue
            score = float(m[i]) + float(deg[i]) * 0.01
            if id(h.link) not in best or score < best[id(h.link)][0]:
                best[id(h.link)] = (score, h)
        out.append(_Set(c, X, [h for _, h in best.values()]))
    out.sort(key=lambda s: (s.standing, s.rank[5]), reverse=True)
    return out


def _proposal(h: Hypothesis, place: Placement, g1: str) -> Matrix:
    """``T_g1_g2``: where hypothesis ``h`` (of a link between groups ``g1`` and ``g2``)
    places the second group."""
    a = h.link.target if place.root[h.link.target] == g1 else h.link.source
    b = h.link.source if a == h.link.target else h.link.target
    return place.pose[a] @ h.oriented(a) @ invert(place.pose[b])


def _medoid(s: _Set, place: Placement, g1: str, g2: str) -> _Set:
    """The set with its best-agreeing member as its centre: the one whose placement the
    others fit best (the merge's own link; the others close loops with it)."""
    if len(s.members) < 3:
        return s
    best: tuple[float, Hypothesis, Matrix] | None = None
    for c in s.members:
        if c.refit is not None:
            continue
        X = _proposal(c, place, g1)
        cost = sum(_fit(h, place, X, g2)[1] for h in s.members)
        if best is None or cost < best[0]:
            best = (cost, c, X)
    assert best is not None
    return _Set(best[1], best[2], s.members)


def _rival(
    sets: list[_Set], top: _Set, place: Placement, g2: str, tol: LoopTolerance
) -> _Set | None:
    """The best set proposing a placement distinct from ``top``'s."""
    for s in sets[1:]:
        if not tol.agrees(_fit(s.centre, place, top.X, g2), 4):
            return s
    return None


def _contradiction(
    s: _Set, place: Placement, g2: str, judge: Judge, radius_m: float
) -> tuple[float, float, float] | None:
    """What the map's check says of the two groups' stations where the set places the
    second: over the :data:`MAP_PAIRS` nearest pairs of stations (one of each group) within
    ``radius_m``, the worst contradiction and conflict and the best explained share of the
    judge's. The set's own links' pairs are no witnesses (their registrations fitted them,
    and their verdicts judged them already); None when the map cannot tell for any pair."""
    said = [judge(a, b, T) for a, b, T in _judged_pairs(s, place, g2, radius_m)]
    seen = [x for x in said if x is not None]
    if not seen:
        return None
    return max(x[0] for x in seen), max(x[1] for x in seen), max(x[2] for x in seen)


def _judged_pairs(
    s: _Set, place: Placement, g2: str, radius_m: float
) -> list[tuple[str, str, Matrix]]:
    """The pairs of stations the map looks at where set ``s`` places group ``g2``: the
    :data:`MAP_PAIRS` nearest (one of each group) within ``radius_m``, nearest first, but
    the set's own links' pairs, each with its relative pose ``T_a_b``."""
    c = s.centre.link
    g1 = place.root[c.target] if place.root[c.target] != g2 else place.root[c.source]
    own = {frozenset((h.link.target, h.link.source)) for h in s.members}
    at, pairs = _nearest(place, s.X, (g1, g2), radius_m, own)
    return [(a, b, invert(at[a]) @ at[b]) for a, b in pairs]


def _distinct(sets: list[_Set], place: Placement, g2: str, tol: LoopTolerance) -> list[_Set]:
    """Of ``sets`` (best supported first), the first of each distinct placement of ``g2``."""
    out: list[_Set] = []
    fits = _Fits([s.centre for s in sets], place, g2)
    seen = np.zeros(len(sets), dtype=bool)  # agrees with a placement kept already
    for i, s in enumerate(sets):
        if not seen[i]:
            out.append(s)
            deg, m = fits(s.X)
            seen |= (deg <= tol.max_deg) & (m <= tol.metres(4))
    return out


def _nearest(
    place: Placement,
    X: Matrix,
    groups: tuple[str, str],
    radius_m: float,
    skip: Container[frozenset[str]] = (),
) -> tuple[dict[str, Matrix], list[tuple[str, str]]]:
    """The stations of both groups where ``X`` (``T_g1_g2``) places the second, and the
    :data:`MAP_PAIRS` nearest pairs of stations (one of each) within ``radius_m``, but those
    of ``skip``."""
    g1, g2 = groups
    at = {x: _placed(place, X, g2, x) for x in place.members(g1) + place.members(g2)}
    pairs = sorted(
        (float(np.linalg.norm(at[a][:3, 3] - at[b][:3, 3])), a, b)
        for a in place.members(g1)
        for b in place.members(g2)
        if frozenset((a, b)) not in skip
    )
    return at, [(a, b) for d, a, b in pairs[:MAP_PAIRS] if d <= radius_m]


def _refit(
    items: list[Hypothesis],
    place: Placement,
    groups: tuple[str, str],
    fit: tuple[GroupFit, float],
    radius_m: float,
    tol: LoopTolerance,
) -> bool:
    """Where all the overlap of two groups fits, from each placement a plain answer
    (:attr:`Hypothesis.plain`) of a link between them gives, when another link's plain answer
    places them within ``fit``'s reach (metres, at the stations: translation plus the turn
    over ``radius_m``) of it. A doorway link may slide along a wall where its few shared
    points fit as well (the wall's two faces, one seen by each scan): fitted on the
    overlap of every near pair of the groups' stations (``fit``, with its normal-side rule),
    it comes to where the right one is. An answer whose own pose is off the fitted placement
    (beyond the loop tolerance) gets that pose as its :attr:`Hypothesis.refit`: it joins a
    set through it (two links of different pairs of scans that reach one placement confirm
    it, as two that agree do) but places nothing itself. Returns whether one got one."""
    g1, g2 = groups
    plain = [h for h in items if h.plain]
    starts = {id(h): _proposal(h, place, g1) for h in plain}
    todo = []
    for h in plain:
        errs = (_fit(f, place, starts[id(h)], g2) for f in plain if f.link is not h.link)
        if any(m + np.radians(d) * radius_m <= fit[1] for d, m in errs):
            todo.append(h)
    for h in todo:
        _, pairs = _nearest(place, starts[id(h)], groups, radius_m)
        near = {h.link.target, h.link.source}.union(*pairs)
        sides = [{x: place.pose[x] for x in sorted(near) if place.root[x] == g} for g in groups]
        X = fit[0](sides[0], sides[1], starts[id(h)])
        if X is None or tol.agrees(err := _fit(h, place, X, g2), 2):
            continue
        log.debug("%s <- %s fitted on its groups' overlap: its own pose %.3f deg / %.3f m off",
                  h.link.target, h.link.source, *err)  # fmt: skip
        h.refit = invert(_placed(place, X, g2, h.link.target)) @ _placed(
            place, X, g2, h.link.source
        )
    return any(h.refit is not None for h in todo)


@dataclass(frozen=True)
class _Pick:
    """What merges two groups: the set, what chose it, and how much the map finds the
    groups' stations contradicting each other there (0 when it was not asked)."""

    set: _Set
    how: str
    contradiction: float = 0.0


#: What decides a merge: the placement, the loop tolerance, the registration's ambiguity and
#: decisive ratios, the map's check with its thresholds and radius, and its full-resolution
#: test with the settle limit and the share that sees (:func:`merge_groups`).
Decide = tuple[
    Placement,
    LoopTolerance,
    tuple[float, float],
    "tuple[Judge, float, float, float] | None",
    "tuple[FullJudge, float, float] | None",
]


def _decide(sets: list[_Set], g2: str, decide: Decide, alone: bool) -> _Pick | None:
    """The set that merges two groups, or None. What chooses it (:attr:`_Pick.how`):
    ``"loop"``, a loop of trusted answers; ``"map"``, the map's check among distinct
    placements; ``"hand"``, the surveyor's word; ``"alone"``, one trusted answer no loop
    checks; ``"full"``, a pose the rough positions picked that the full-resolution test
    confirms (:func:`_sited`, with ``full``). The last three only when ``alone`` (once no set
    a loop confirms is left) where a cycle of trusted answers contradicts them."""
    place, tol, ratios, judge, full = decide
    pick = _decide_sets(sets, place, g2, tol, ratios, judge, alone)
    if pick is None and alone and judge is not None and full is not None:
        return _sited(sets, place, g2, tol, judge[3], full)
    return pick


def _decide_sets(
    sets: list[_Set],
    place: Placement,
    g2: str,
    tol: LoopTolerance,
    ratios: tuple[float, float],
    judge: tuple[Judge, float, float, float] | None,
    alone: bool,
) -> _Pick | None:
    """:func:`_decide` by loops, the map's sample check, the surveyor's word or a lone
    trusted answer."""
    if not sets:  # every hypothesis between them refitted elsewhere
        return None
    rival_ratio, decisive = ratios
    top = sets[0]
    rival = _rival(sets, top, place, g2, tol)
    clear = (
        rival is None
        or top.standing > rival.standing
        or (top.standing == rival.standing and rival.rank[5] < rival_ratio * top.rank[5])
    )
    if clear and top.firmly_confirmed:
        return _Pick(top, "loop")
    vouched = any(h.vouched for h in top.members)
    contradicted = any(h.against for h in top.members)
    # two trusted answers that place the groups apart, a cycle of trusted answers through
    # one broken: one of them is wrong, and only the map may tell which
    disputed = contradicted and rival is not None and rival.rank[0] > 0 and not vouched
    if (
        clear
        and (vouched or (top.rank[0] and alone))
        and (alone or not contradicted)
        and not disputed
    ):
        # placed unchecked (the map check and the final alignment's pairs check it later),
        # unless the map check refutes it; where a cycle of trusted answers contradicts it,
        # only where the groups see each other, the least contradicted first
        said = _contradiction(top, place, g2, judge[0], judge[3]) if judge else None
        log.debug("%s <- %s alone: the map says %s", top.centre.link.target,
                  top.centre.link.source, said)  # fmt: skip
        if judge is not None and map_refutes(said, judge[1], judge[2]):
            return None
        if contradicted and not map_sees(said):
            return None
        return _Pick(top, "hand" if vouched else "alone", said[0] if said else 0.0)
    if judge is None or rival is None:
        return None
    distinct = _distinct(sets, place, g2, tol)
    if len(distinct) > MAP_PLACEMENTS:
        return None
    judged = [_contradiction(s, place, g2, judge[0], judge[3]) for s in distinct]
    best = _decisive(judged, judge, decisive)
    if best is None:
        return None
    return _Pick(distinct[best], "map", min(x[0] for x in judged if x is not None))


def _sited(
    sets: list[_Set],
    place: Placement,
    g2: str,
    tol: LoopTolerance,
    radius_m: float,
    full: tuple[FullJudge, float, float],
) -> _Pick | None:
    """The placement of two groups that a pose the rough positions picked proposes
    (:attr:`Hypothesis.sited`, no trusted answer in its set) of a link doubted only for its
    look-alike poses (:attr:`~flexreg.survey.links.Link.aliased`: not a doorway link, which
    may slide along a wall), once nothing else merges them: the positions chose the pose
    among the link's (none other of its poses lay within their window), and the
    full-resolution test of the groups' nearest stations (``full``: the
    test, ``judge.settle_open_share`` and ``map_min_conflict``) stands for the loop no
    registration closes. It must find that placement clean (no pair puts the limit or more
    of both stations' points in the other's open space, and one pair sees the other's at
    least ``map_min_conflict`` explained) and refute every other such pose's distinct
    placement. A pose a few degrees off (the positions' window allows 30) puts walls and
    racks where the neighbours saw through; the sample's check cannot tell, for the stray
    returns at depth edges it counts at every pose (docs/benchmarks.md)."""
    picked = [s for s in sets if s.centre.sited and not s.rank[0] and s.centre.link.aliased]
    distinct = _distinct(picked, place, g2, tol)
    if len(distinct) > MAP_PLACEMENTS:
        return None
    clean: _Set | None = None
    for s in distinct:  # tested until the answer is known
        said = _at_full(s, place, g2, full, radius_m)
        if said == "refuted":
            continue
        if said == "unseen" or clean is not None:
            return None
        clean = s
    return _Pick(clean, "full") if clean is not None else None


def _at_full(
    s: _Set,
    place: Placement,
    g2: str,
    full: tuple[FullJudge, float, float],
    radius_m: float,
) -> str:
    """What the full-resolution test says of the :data:`FULL_PAIRS` nearest pairs of the two
    groups' stations within ``radius_m`` where the set places the second (its own links'
    pairs left out: their registrations fitted them), nearest first: ``"refuted"`` at the
    first pair with the limit or more of both stations' points in the other's open space,
    else ``"clean"`` when a pair sees the other's points explained at least
    ``map_min_conflict``, else ``"unseen"``."""
    test, limit, min_seen = full
    seen = False
    for a, b, T in _judged_pairs(s, place, g2, radius_m)[:FULL_PAIRS]:
        said = test(a, b, T)
        if said is None:
            continue
        if said[0] >= limit:
            return "refuted"
        seen = seen or said[1] >= min_seen
    return "clean" if seen else "unseen"


def _decisive(
    said: Sequence[tuple[float, float, float] | None],
    judge: tuple[Judge, float, float, float],
    decisive: float,
) -> int | None:
    """Of several hypotheses the map scored, the one it finds clean (the stations see each
    other, the map check does not refute them) while every other contradicts ``decisive``
    times as much and puts ``map_min_conflict`` of a scan in the other's free space; None
    when there is no such one, or the map cannot tell for one of them."""
    if any(x is None for x in said):
        return None
    scores = [x for x in said if x is not None]
    best = min(range(len(scores)), key=lambda i: scores[i][0])
    low = scores[best][0]
    if not map_sees(scores[best]) or map_refutes(scores[best], judge[1], judge[2]):
        return None
    others = (x for i, x in enumerate(scores) if i != best)
    if all(x[0] >= decisive * low and x[0] > low and x[1] >= judge[1] for x in others):
        return best
    return None


def _blame(
    cycles: Sequence[Cycle], judge: tuple[Judge, float, float, float], decisive: float
) -> bool:
    """For the first cycle of trusted answers that does not close and that the map can
    decide: each of its links in turn is the hypothesis "this one is wrong and the rest is
    right"; the rest then places that link's two stations, and the map's check scores them
    there. The link whose hypothesis the map finds clean (they see each other, it does not
    refute them) while every other contradicts ``decisive`` times as much is blamed
    (:attr:`Hypothesis.blamed`), and the cycle no longer contradicts the others. Returns
    whether one was blamed."""
    for cyc in cycles:
        if any(h.blamed for h in cyc.links) or not all(h.against for h in cyc.links):
            continue
        n = len(cyc.stations)
        said = [judge[0](cyc.stations[i], cyc.stations[(i + 1) % n], cyc.rest(i)) for i in range(n)]
        best = _decisive(said, judge, decisive)
        if best is not None:
            cyc.links[best].blamed = True
            for h in cyc.links:
                h.against -= 1
            return True
    return False


def _best(
    memo: dict[tuple[str, str], tuple[list[_Set], dict[bool, _Pick | None]]],
    decide: Decide,
    alone: bool,
) -> tuple[tuple[float, ...], str, str, _Pick] | None:
    """The best merge of the project (:func:`_decide` per pair of groups, remembered in
    ``memo``); ``decide``: what decides (:data:`Decide`)."""
    best: tuple[tuple[float, ...], str, str, _Pick] | None = None
    for (g1, g2), (found, decided) in sorted(memo.items()):
        if alone not in decided:
            decided[alone] = _decide(found, g2, decide, alone)
        pick = decided[alone]
        if pick is None:
            continue
        p = pick.set
        overlap = sum(h.link.overlap for h in p.members)
        rank = (*p.rank[:5], -pick.contradiction, -p.misfit, p.rank[5], overlap)
        if best is None or rank > best[0]:
            best = (rank, g1, g2, pick)
    return best


def merge_groups(
    stems: list[str],
    hyps: dict[frozenset[str], list[Hypothesis]],
    tol: LoopTolerance,
    ratios: tuple[float, float],
    judge: tuple[Judge, float, float, float] | None = None,
    broken: Sequence[Cycle] = (),
    fit: tuple[GroupFit, float] | None = None,
    positions: Mapping[str, Position] | None = None,
    full: tuple[FullJudge, float, float] | None = None,
) -> tuple[Placement, dict[int, Chosen]]:
    """Step 2: the groups, and what each link that merged groups was given (by link id).

    Parameters
    ----------
    stems : list of str
    hyps : dict
        The hypotheses per pair of stations.
    tol : LoopTolerance
    ratios : (float, float)
        The registration's ``judge.ambiguity_ratio`` and ``judge.decisive_ratio``: a
        distinct placement as well supported in trusted answers, votes and links whose
        weight is at least the first share of the best's is a rival, and the groups stay
        apart unless the map decides: the one placement under which the groups see each
        other and the map check does not refute them, every other contradicting at least
        the second times as much.
    judge : (Judge, float, float, float), optional
        The map's free-space check, and its ``map_min_conflict``, ``map_conflict_ratio`` and
        ``map_radius_m``.
    broken : sequence of Cycle
        The cycles of trusted answers that do not close (:func:`cycle_votes`): when no merge
        is left, the map may name the wrong link of one (:func:`_blame`), and merging goes
        on without it.
    fit : (GroupFit, float), optional
        Where all the overlap of two groups fits, and how far apart (metres) two starts may
        be for it to bring them together: when nothing a loop confirms is left, plain answers
        are fitted on it (:func:`_refit`; with ``judge`` only).
    positions : dict of str -> Position, optional
        Rough positions: a placement of two groups they refute
        (:func:`~flexreg.survey.positions.refutes`) is no hypothesis.
    full : (FullJudge, float, float), optional
        The map's full-resolution test, ``judge.settle_open_share`` and ``map_min_conflict``:
        when nothing else is left, a pose the rough positions picked places what it joins
        where the test confirms it (:func:`_sited`; with ``judge`` only).
    """
    place = Placement({s: s for s in stems}, {s: np.eye(4) for s in stems})
    chosen: dict[int, Chosen] = {}
    # per pair of groups, its sets and what decides them (without, with lone links): a
    # merge changes only the pairs of the two groups it joins, a blame every pair
    memo: dict[tuple[str, str], tuple[list[_Set], dict[bool, _Pick | None]]] = {}
    refitted: set[tuple[str, str]] = set()
    while True:
        between: dict[tuple[str, str], list[Hypothesis]] = {}
        for pair, hs in hyps.items():
            a, b = sorted(pair)
            ra, rb = place.root[a], place.root[b]
            if ra != rb:
                key = (ra, rb) if ra < rb else (rb, ra)
                between.setdefault(key, []).extend(
                    h for h in hs if id(h.link) not in chosen and not h.blamed
                )
        for k, items in sorted(between.items()):
            if items and k not in memo:
                for h in items:
                    h.refit = None
                memo[k] = (_sets(place, *k, items, tol, positions), {})
        decide = (place, tol, ratios, judge, full)
        best = _best(memo, decide, False)  # what a loop confirms first
        if best is None and fit is not None and judge is not None:  # then slid doorway links
            for k in sorted(memo.keys() - refitted):
                refitted.add(k)
                if _refit(between[k], place, k, fit, judge[3], tol):
                    memo[k] = (_sets(place, *k, between[k], tol, positions), {})
            best = _best(memo, decide, False)
        best = best or _best(memo, decide, True)  # then lone trusted links
        if best is None:
            if judge is not None and _blame(broken, judge, ratios[1]):
                memo.clear()
                refitted.clear()
                continue
            return place, chosen
        _, g1, g2, picked = best
        memo = {k: v for k, v in memo.items() if g1 not in k and g2 not in k}
        refitted = {k for k in refitted if g1 not in k and g2 not in k}
        how, med = picked.how, _medoid(picked.set, place, g1, g2)
        for s in place.members(g2):
            place.pose[s] = med.X @ place.pose[s]
            place.root[s] = g1
        for h in med.members:
            if h.refit is not None:  # its own pose is off the placement: it is rejected
                chosen[id(h.link)] = Chosen(h, False, "fit", False)
                continue
            # an uncertain pose agreeing with the merge closes a loop with its own link: the
            # loop confirms it (though, no independent route, it confirms nothing else)
            loop = med.firmly_confirmed or (h is not med.centre and not h.firm)
            chosen[id(h.link)] = Chosen(h, h is med.centre, how, loop)


__all__ = ["FULL_PAIRS", "MAP_PAIRS", "MAP_PLACEMENTS", "Chosen", "Placement", "merge_groups"]
