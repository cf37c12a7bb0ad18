"""The records of a survey's graph: links, vetoes and the solution (see
:mod:`flexreg.survey.consensus` and :mod:`flexreg.survey.graph` for how they are decided)."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.registration.check import decisive_full
from flexreg.registration.config import TWIN_MIN_RATIO, JudgeConfig
from flexreg.survey.config import MIN_EXPLAINED

Matrix = NDArray[np.float64]
E = TypeVar("E")


@dataclass(frozen=True, eq=False)
class Alternative:
    """A pose a link could have instead of its answer.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    kind : {"runner_up", "twin", "answer"}
        A clearly different candidate of the registration that scored close to the answer,
        the answer slid along the target's walls to where it fits again, or the
        registration's own answer where a prior picked another of its poses.
    support : float
        How well it fits against the answer: a runner-up's score ratio, a twin's share of
        what the answer explains (1: as well).
    """

    T_target_source: Matrix
    kind: str
    support: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "T_target_source": np.asarray(self.T_target_source, dtype=np.float64).tolist(),
            "kind": self.kind,
            "support": round(float(self.support), 4),
        }

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> Alternative:
        """From :meth:`to_dict`'s JSON (a cached link's)."""
        return cls(np.asarray(d["T_target_source"], dtype=np.float64), d["kind"], d["support"])


#: Most alternatives a link keeps, the best supported first.
MAX_ALTERNATIVES = 6


def alternatives_of(
    T: Matrix,
    runner_ups: Sequence[Any],
    twins: Mapping[str, Any] | None,
    judge: JudgeConfig,
    duels: Sequence[Mapping[str, Any]] = (),
) -> list[Alternative]:
    """A link's alternatives: the registration's runner-ups (each a
    :class:`~flexreg.core.results.Hypothesis`; ``duels`` are their entries of the evidence's
    ``runner_ups``, in the same order: one that explains less than
    :data:`~flexreg.registration.config.TWIN_MIN_RATIO` of what the answer explains at full
    resolution, ``full_support``, is no pose the scans fit, whatever the samples scored it)
    and the twins of its answer ``T`` that fit by
    the verdict's own measure (the ``twins`` section of its evidence; the answer moved by
    each twin's ``offset_m``, target frame): at least
    :data:`~flexreg.registration.config.TWIN_MIN_RATIO` of what the answer explains, no more
    open space than ``judge.twin_fit_open`` (or twice the answer's), not beaten decisively on
    every pixel. Without duplicates (within ``judge.distinct_deg`` / ``distinct_m`` of a
    better one or of the answer), best first, at most :data:`MAX_ALTERNATIVES`.

    >>> T = np.eye(4)
    >>> twins = {"answer": {"explained_share": 0.5, "open_share": 0.0},
    ...          "twins": [{"offset_m": [5.9, 0, 0], "explained_share": 0.45, "open_share": 0.0},
    ...                    {"offset_m": [-5.9, 0, 0], "explained_share": 0.05, "open_share": 0.0}]}
    >>> [(a.kind, a.support, float(a.T_target_source[0, 3]))
    ...  for a in alternatives_of(T, [], twins, JudgeConfig())]
    [('twin', 0.9, 5.9)]
    """
    weak = {
        i
        for i, d in enumerate(duels)
        if d.get("full_support") is not None and d["full_support"] < TWIN_MIN_RATIO
    }
    found: list[Alternative] = [
        Alternative(np.asarray(h.T_target_source, dtype=np.float64), "runner_up", h.score_ratio)
        for i, h in enumerate(runner_ups)
        if i not in weak
    ]
    answer = (twins or {}).get("answer") or {}
    explained = float(answer.get("explained_share") or 0.0)
    most_open = max(judge.twin_fit_open, 2.0 * float(answer.get("open_share") or 0.0))
    for t in (twins or {}).get("twins", ()) if explained > 0 else ():
        support = float(t["explained_share"]) / explained
        beaten = decisive_full(
            t.get("full_refuted_share", 0.0),
            t.get("full_refuting_share", 0.0),
            judge,
            points=t.get("full_points", 0),
        )
        if support < TWIN_MIN_RATIO or t["open_share"] > most_open or beaten:
            continue
        Tt = np.array(T, dtype=np.float64)
        Tt[:3, 3] += np.asarray(t["offset_m"], dtype=np.float64)
        found.append(Alternative(Tt, "twin", support))
    found.sort(key=lambda a: -a.support)
    kept: list[Alternative] = []
    for a in found:
        if all(
            judge.distinct(a.T_target_source, b) for b in [T, *(k.T_target_source for k in kept)]
        ):
            kept.append(a)
    return kept[:MAX_ALTERNATIVES]


@dataclass(eq=False)
class Link:
    """One attempted link and what the graph made of it (see poses.json in
    :mod:`flexreg.survey`).

    Attributes
    ----------
    target, source : str
    T_target_source : (4, 4) float64 or None
        None when the registration failed.
    information : (6, 6) float64 or None
        Information matrix, (rx, ry, rz, tx, ty, tz) as Open3D orders it.
    overlap_share, open3d_fitness, open3d_inlier_rmse_m : float or None
        The overlap of ``register`` and ``compare`` (:mod:`flexreg.stages.overlap`; written
        as ``overlap`` with ``overlap_of``, its denominator) and Open3D's figures beside it.
        ``overlap_target`` / ``overlap_source`` are the verdict's view-consistency shares,
        which order the links.
    verdict : {"confident", "uncertain"} or None
    repeat : bool
        The verdict called the pair ambiguous because the answer moved along the hall fits
        too (its evidence holds ``twins`` and it is uncertain: the twin test runs only on
        answers otherwise confident, :mod:`flexreg.registration.twins`): the two stations
        stand in repeating structure.
    doubt : float or None
        The verdict's larger free-space conflict ratio (share of a scan's sample in the other's
        free space over the share the other explains): which link of a conflicting pair's
        path the map check cuts first.
    map_joined : bool
        It joined two groups where the map's free-space check allowed only its placement
        of all those their links propose (:mod:`flexreg.survey.consensus`).
    status : {"pending", "accepted", "rejected", "failed"}
    vouched : str
        Why the link is trusted beyond its verdict: ``"hand"`` (given by the surveyor,
        ``--link``), ``"positions"`` (the one of its poses the rough positions pick,
        :mod:`flexreg.survey.positions`); empty for none. A vouched link places stations
        on its own where no loop reaches them (a hand link; a pose the positions picked only
        where the map's full-resolution test confirms it: positions pick a pose, they do
        not confirm its centimetres), and loops still check it.
    picked : str
        What picked one of its alternatives over its answer (the answer is then among the
        alternatives), in words; empty when it keeps its answer.
    refused : str
        Why something outside the pair refused every pose of the link (rough positions that
        disagree with all of them); empty for none. A refused link stays rejected.
    undecided : str
        Why rough positions given for both stations left the link as it was (several of its
        poses agree with them, or none is near); empty otherwise.
    windowed : bool
        Registered only inside the window of two rough positions
        (:func:`flexreg.survey.positions.window_of`): its verdict is then partly theirs (they
        ruled out every pose beyond the window), so even a confident one needs a loop.
    open_clear : bool or None
        Its answer, checked at full resolution, puts no more in open space than the verdict
        allows there (:func:`flexreg.registration.verdict.full_open_clear`); None when not
        checked there. A ``free_space`` reason of such a link is the even sample's alone.
    alternatives : list of Alternative
        The clearly different poses the registration found fitting almost as well (its
        runner-ups) or the answer moved a whole bay or room that fits too (its twins):
        what the link could be instead of its answer (:func:`alternatives_of`).
    """

    target: str
    source: str
    T_target_source: Matrix | None = None
    information: Matrix | None = None
    verdict: str | None = None
    reasons: list[dict[str, str]] = field(default_factory=list)
    overlap_target: float | None = None
    overlap_source: float | None = None
    matches: int | None = None
    inliers: int | None = None
    rmse_m: float | None = None
    fitness: float | None = None
    strength: dict[str, float] = field(default_factory=dict)
    origin: str = ""
    place_score: float | None = None
    seconds: float | None = None
    status: str = "pending"
    why: str | None = None
    in_tree: bool = False
    confirmed_by_loop: bool = False
    loop_error_deg: float | None = None
    loop_error_m: float | None = None
    cached: bool = False
    overlap_share: float | None = None
    overlap_of: str | None = None
    open3d_fitness: float | None = None
    open3d_inlier_rmse_m: float | None = None
    map_joined: bool = False
    doubt: float | None = None
    repeat: bool = False
    alternatives: list[Alternative] = field(default_factory=list)
    vouched: str = ""
    picked: str = ""
    refused: str = ""
    undecided: str = ""
    windowed: bool = False
    open_clear: bool | None = None
    # the answer and alternatives as registered, before the first take or keep_only
    registered: tuple[Matrix, list[Alternative]] | None = field(default=None, repr=False)

    @property
    def overlap(self) -> float:
        """The smaller overlap of both directions (0 when unknown)."""
        vals = [v for v in (self.overlap_target, self.overlap_source) if v is not None]
        return float(min(vals)) if vals else 0.0

    @property
    def poses(self) -> list[Matrix]:
        """Its answer, then its alternatives' poses (the same arrays)."""
        return [np.asarray(self.T_target_source), *(a.T_target_source for a in self.alternatives)]

    def take(self, alternative: Alternative, why: str) -> None:
        """Let one of its alternatives be the link's pose (something outside the pair picked
        it: a loop, the map, rough positions); the answer becomes an alternative."""
        self._remember()
        self.alternatives = [
            Alternative(np.asarray(self.T_target_source), "answer", 1.0),
            *(a for a in self.alternatives if a is not alternative),
        ]
        self.T_target_source = np.asarray(alternative.T_target_source, dtype=np.float64)
        self.picked = f"{why} picked its {alternative.kind.replace('_', '-')}, not its answer"

    def keep_only(self, alternatives: list[Alternative]) -> None:
        """Only these of its alternatives stay its hypotheses (:meth:`untake` brings the
        others back)."""
        if len(alternatives) < len(self.alternatives):
            self._remember()
            self.alternatives = list(alternatives)

    def _remember(self) -> None:
        if self.registered is None:
            self.registered = (np.asarray(self.T_target_source), list(self.alternatives))

    def untake(self) -> None:
        """Its answer and alternatives as registered again (every :meth:`take` and
        :meth:`keep_only` undone)."""
        if self.registered is not None:
            self.T_target_source, alternatives = self.registered
            self.alternatives, self.registered, self.picked = list(alternatives), None, ""

    def agreeing_alternative(
        self, P_target: Matrix, P_source: Matrix, agrees: Callable[[tuple[float, float]], bool]
    ) -> tuple[Alternative, tuple[float, float]] | None:
        """The one alternative whose loop error against the stations' poses ``agrees``, with
        that error; None when none does, or more than one."""
        fits = [
            (a, err)
            for a in self.alternatives
            if agrees(err := loop_error(np.asarray(a.T_target_source), P_target, P_source))
        ]
        return fits[0] if len(fits) == 1 else None

    @property
    def confident(self) -> bool:
        """Its own registration calls it confident (inside rough positions' window too), or
        the surveyor gave it: two such links that agree around a loop are two independent
        registrations (:mod:`flexreg.survey.consensus`)."""
        return self.verdict == "confident" or self.vouched == "hand"

    @property
    def trusted(self) -> bool:
        """Whether its pose may place stations: confident, or given by the surveyor. Rough
        positions pick which of an uncertain link's poses is meant, not its centimetres (a
        pose 0.4 m off fits a 1 m sigma), and a link registered only inside their window is
        confident partly by their doing (a doorway pair 14 cm off, confident inside its
        window, on the held-out building 131): such links still need a loop."""
        return (self.verdict == "confident" and not self.windowed) or self.vouched == "hand"

    @property
    def fits(self) -> bool:
        """Whether its poses fit its scans: confident, or uncertain only because several
        clearly different poses fit (``ambiguous``): what a loop or rough positions choose
        between. A link also uncertain for its overlap, open space or a weak axis fits none
        of them well."""
        return all(r.get("code") == "ambiguous" for r in self.reasons)

    def _doubted_only_for(self, *codes: str) -> bool:
        """Whether every reason of its verdict is one of ``codes``, or open space only its
        even sample finds where full resolution clears the answer (:attr:`open_clear`)."""
        fit = set(codes) | ({"free_space"} if self.open_clear else set())
        return all(r.get("code") in fit for r in self.reasons)

    @property
    def aliased(self) -> bool:
        """Whether all that doubts it is the look-alike poses that fit as well
        (``ambiguous``; with open space only its even sample finds, where full resolution
        clears the answer, :attr:`open_clear`): what rough positions settle, unlike a small
        overlap (``low_overlap``: a doorway link may slide along a wall, which they cannot
        tell) (:func:`flexreg.survey.consensus.merge_groups`)."""
        return self.verdict == "uncertain" and self._doubted_only_for("ambiguous")

    @property
    def fits_where_seen(self) -> bool:
        """Whether its poses fit what both scans see: it :attr:`fits`, or it is uncertain
        also (or only) because the scans share little (``low_overlap``: a doorway's worth),
        not because its answer contradicts them (a weak axis, a high residual, open space
        at full resolution). Open space only the even sample finds (its stray returns) does
        not count where full resolution clears the answer (:attr:`open_clear`). Rough
        positions may pick the pose of such a link
        (:func:`flexreg.survey.positions.apply_positions`)."""
        return self._doubted_only_for("ambiguous", "low_overlap")

    @property
    def plain(self) -> bool:
        """Whether it is uncertain only because the scans share little (``low_overlap``: a
        doorway's worth) or because its even sample puts points in open space that full
        resolution clears (:attr:`open_clear`: stray returns among racks): its registration
        found no rival pose, no twin, no weak axis and nothing in open space at full
        resolution. Two such answers of different pairs of scans that agree around a loop
        confirm each other (:mod:`flexreg.survey.consensus`), and the stations they place
        are tested at full resolution like a lone link's
        (:func:`flexreg.survey.mapcheck.unconfirmed_pairs`)."""
        uncertain = self.verdict == "uncertain" and bool(self.reasons)
        return uncertain and self._doubted_only_for("low_overlap")

    @property
    def usable(self) -> bool:
        return self.T_target_source is not None and self.status != "failed"

    def to_dict(self) -> dict[str, Any]:
        def m(a: Matrix | None) -> Any:
            return None if a is None else np.asarray(a, dtype=np.float64).tolist()

        return {
            "target": self.target,
            "source": self.source,
            "origin": self.origin,
            "place_score": self.place_score,
            "status": self.status,
            "why": self.why,
            "T_target_source": m(self.T_target_source),
            "verdict": self.verdict,
            "reasons": list(self.reasons),
            "overlap": self.overlap_share if self.T_target_source is not None else None,
            "overlap_of": self.overlap_of,
            "open3d_fitness": self.open3d_fitness,
            "open3d_inlier_rmse_m": self.open3d_inlier_rmse_m,
            "overlap_target": self.overlap_target,
            "overlap_source": self.overlap_source,
            "matches": self.matches,
            "inliers": self.inliers,
            "rmse_m": self.rmse_m,
            "fitness": self.fitness,
            "strength": dict(self.strength),
            "free_space_conflict_ratio": self.doubt,
            "information": m(self.information),
            "in_tree": self.in_tree,
            "confirmed_by_loop": self.confirmed_by_loop,
            "map_joined": self.map_joined,
            "repeat": self.repeat,
            "loop_error_deg": self.loop_error_deg,
            "loop_error_m": self.loop_error_m,
            "seconds": self.seconds,
            "cached": self.cached,
            "alternatives": [a.to_dict() for a in self.alternatives],
            "vouched": self.vouched or None,
            "picked": self.picked or None,
            "refused": self.refused or None,
            "windowed": self.windowed,
            "open_space_clear_at_full_resolution": self.open_clear,
        }


@dataclass(eq=False)
class Veto:
    """Two stations that must not stay in one configuration (the map check found them
    contradicting each other there; :mod:`flexreg.survey.mapcheck`).

    Attributes
    ----------
    a, b : str
    T_a_b : (4, 4) float64
        The refuted relative pose (maps ``b``'s points into ``a``'s frame).
    why : str
        What contradicts what, in words.
    held : frozenset of str
        Stations the map check holds placed right (confirmed by loops, or seen clean against
        such stations at full resolution): the wrong link lies between the other end and the
        nearest of them on a path between the two (empty: anywhere on the path).
    """

    a: str
    b: str
    T_a_b: Matrix
    why: str
    held: frozenset[str] = frozenset()


@dataclass(eq=False)
class GraphSolution:
    """Where each station is and which groups exist.

    Attributes
    ----------
    reference : str
        The station of group 0 whose frame the poses are given in.
    poses : dict of str -> (4, 4) float64
        ``T_groupref_station`` of every station in a group of two or more, in its group's
        frame (group 0: the reference frame).
    groups : list of list of str
        Stations per group, group 0 first (the reference's), then by size; single stations
        form their own groups.
    group_reference : list of str
    confidence : dict of str -> str
        ``confident`` or ``uncertain`` (placed only through loop-confirmed uncertain links).
    reasons : dict of str -> str
        Why a station is not in the reference's group.
    stats : dict
        Bundle error (RMS), mean and max link residuals, degrees and metres.
    """

    reference: str
    poses: dict[str, Matrix]
    groups: list[list[str]]
    group_reference: list[str]
    confidence: dict[str, str]
    reasons: dict[str, str]
    stats: dict[str, float | None]

    def group_of(self, stem: str) -> int:
        for i, g in enumerate(self.groups):
            if stem in g:
                return i
        raise KeyError(stem)


def reached(start: str, edges: Sequence[tuple[str, str]]) -> set[str]:
    """The stations ``edges`` (station pairs) join to ``start``, ``start`` included.

    >>> sorted(reached("a", [("a", "b"), ("c", "d")]))
    ['a', 'b']
    """
    adj: dict[str, list[str]] = {}
    for x, y in edges:
        adj.setdefault(x, []).append(y)
        adj.setdefault(y, []).append(x)
    seen, queue = {start}, deque([start])
    while queue:
        for y in adj.get(queue.popleft(), []):
            if y not in seen:
                seen.add(y)
                queue.append(y)
    return seen


def bridges(edges: list[tuple[str, str]]) -> set[int]:
    """Indices of the edges that close no loop: removing one disconnects its two stations
    (a link between two stations linked twice closes a loop of two).

    >>> sorted(bridges([("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")]))
    [3]
    """
    return {
        i
        for i, (a, b) in enumerate(edges)
        if b not in reached(a, [x for j, x in enumerate(edges) if j != i])
    }


def walk(
    adj: Mapping[str, Sequence[tuple[str, E]]], start: str, end: str
) -> list[tuple[str, E]] | None:
    """A shortest walk from ``start`` to ``end`` over ``adj`` (station -> (neighbour, edge);
    fewest steps, ties in adjacency order): its (next station, edge) steps, [] when they are
    one station, None when no walk joins them.

    >>> walk({"a": [("b", 1)], "b": [("a", 1), ("c", 2)], "c": [("b", 2)]}, "a", "c")
    [('b', 1), ('c', 2)]
    """
    back: dict[str, tuple[str, E] | None] = {end: None}
    queue = deque([end])
    while queue and start not in back:
        x = queue.popleft()
        for y, e in adj.get(x, ()):
            if y not in back:
                back[y] = (x, e)
                queue.append(y)
    if start not in back:
        return None
    steps: list[tuple[str, E]] = []
    x = start
    while (step := back[x]) is not None:
        steps.append(step)
        x = step[0]
    return steps


def loop_error(T_link: Matrix, P_target: Matrix, P_source: Matrix) -> tuple[float, float]:
    """How far a link is from the relative pose of two solved stations: degrees, metres."""
    rel = invert(P_target) @ P_source
    return rotation_error_deg(T_link, rel), translation_error_m(T_link, rel)


Judge = Callable[[str, str, Matrix], "tuple[float, float, float] | None"]
"""How much two stations contradict each other at a relative pose ``T_a_b`` (maps ``b``'s
points into ``a``'s frame): ``(contradiction, conflict, explained)`` — the larger share, over
both directions, of what one station sees that lands in the other's free space among what
lands on its surfaces or in its free space; the larger share of a station's sample in the
other's free space; the smaller share of a station's sample on the other's surfaces — or
None when the two hardly see each other there."""

FullJudge = Callable[[str, str, Matrix], "tuple[float, float, int] | None"]
"""Two stations at one relative pose at full resolution: ``full(a, b, T_a_b)`` gives the
share of both stations' points in the other's open space, the share the other explains and
how many points were tested (:func:`flexreg.survey.mapcheck.open_space_at_full`); None when
it cannot tell."""

GroupFit = Callable[[dict[str, Matrix], dict[str, Matrix], Matrix], "Matrix | None"]
"""Where all the overlap of two groups of stations fits: ``fit(target, source, X)``, each
group given as its stations' poses in its own frame (``{stem: T_group_station}``) and ``X``
the start (``T_target_source`` of the groups' frames); the fitted ``T_target_source``, or None
when too little overlaps."""


def map_refutes(said: tuple[float, float, float] | None, min_conflict: float, ratio: float) -> bool:
    """The map check's own test of a :data:`Judge`'s answer
    (:meth:`~flexreg.survey.mapcheck.PairLook.conflicts`): at least ``min_conflict`` of a scan
    in the other's free space, and ``ratio`` times what it explains there."""
    return said is not None and said[1] >= min_conflict and said[0] >= ratio / (1.0 + ratio)


def map_sees(said: tuple[float, float, float] | None) -> bool:
    """Two stations see each other at the pose a :data:`Judge` scored: each explains
    :data:`~flexreg.survey.config.MIN_EXPLAINED` of the other's sample."""
    return said is not None and said[2] >= MIN_EXPLAINED


__all__ = [
    "MAX_ALTERNATIVES",
    "Alternative",
    "FullJudge",
    "GraphSolution",
    "GroupFit",
    "Judge",
    "Link",
    "Matrix",
    "Veto",
    "alternatives_of",
    "bridges",
    "loop_error",
    "map_refutes",
    "map_sees",
    "reached",
    "walk",
]
