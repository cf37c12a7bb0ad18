"""Candidate links of a survey: which station pairs to register.

Registering every pair costs ``N (N - 1) / 2`` links (19,900 for 200 stations) although a
station overlaps only its few neighbours. The candidates come from two cheap cues:

* **file order**: stations named ``prefix + number`` (``station_07``, ``Scan 12``) are usually
  scanned one after the other, each beside the previous one; each station is linked to its
  ``neighbours`` next ones in that order;
* **place recognition**: each station keeps its few hundred strongest keypoints with their 3D
  points (:func:`flexreg.survey.stations.global_descriptor`). Two stations score by how many
  of their mutual ratio-test matches are *geometrically consistent* (the largest set whose
  pairwise 3D distances agree, :func:`flexreg.stages.alignment.consistent_subset`): distances
  between points do not change with the scanner's position or heading, so the score is
  invariant to yaw (and any rotation) and counts only structure both stations really see.
  Each station's best ``place_candidates`` partners are tried.

The total is capped at ``max_links_per_station * N``; the file-order links come first, then
the place-recognition links by score. Later rounds (:func:`later_pairs`) add pairs whose
solved positions are close, then the pairs that would close a loop through a chain of confident
links between groups (:func:`chain_pairs`), then the pairs that would test each pose a link
between two groups may have (:func:`hypothesis_pairs`), then the unplaced stations' next place
partners; the map's free-space check keeps only the pairs that would see each other at the pose
that suggests them.

A surveyor can add pairs (a CSV, :func:`read_pairs_csv`) and links given by hand with their
``T_target_source`` (:func:`hand_links`, e.g. from ``flexreg register --init`` or a point-pair
alignment); :func:`merge_candidates` puts them in place of the automatic candidates of the
same pairs (one link per pair).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import combinations
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.transforms import as_transform, invert
from flexreg.errors import InputError
from flexreg.io.transform_io import read_pair_transform
from flexreg.stages.alignment import consistent_subset
from flexreg.survey.links import GraphSolution, Judge, Link, map_refutes, map_sees
from flexreg.survey.stations import GlobalDescriptor

#: Lowe's ratio of the place-recognition matches
PLACE_RATIO = 0.85
#: distance tolerance of the consistency check, metres, plus this share of the distance
PLACE_TOLERANCE_M, PLACE_RELATIVE = 0.15, 0.02
#: a place-recognition score under this many consistent matches proposes no link
MIN_PLACE_MATCHES = 4
#: most pairs the map looks at for one hypothesis of a link before giving it up (as many as
#: the graph scores for one placement of two groups)
HYPOTHESIS_LOOKS = 8

_NUMBERED = re.compile(r"^(.*?)(\d+)$")


@dataclass(frozen=True)
class Candidate:
    """A pair to register.

    Attributes
    ----------
    target, source : str
        Station stems (``T_target_source`` maps the source into the target).
    origin : str
        Why: ``sequential``, ``place``, ``proximity``, ``all``, ``file`` (a pairs CSV) or
        ``hand`` (a link given with its transform).
    place_score : float or None
        Consistent place-recognition matches (None: not ranked).
    T_target_source : (4, 4) float64 or None
        The pose a ``hand`` link is given: it seeds the registration (refined and checked
        like any other answer, :func:`flexreg.survey.execute.align_link`); None otherwise.
    window : (float, float) or None
        When the seed is rough (two stations' rough positions): how far off it may be, a
        shift in metres and a turn in radians; the registration then searches only there
        (:func:`flexreg.registration.pipeline.register`, ``window``).
    """

    target: str
    source: str
    origin: str
    place_score: float | None = None
    T_target_source: NDArray[np.float64] | None = field(default=None, compare=False, repr=False)
    window: tuple[float, float] | None = field(default=None, compare=False)

    @property
    def key(self) -> frozenset[str]:
        return frozenset((self.target, self.source))


def sequential_order(stems: list[str]) -> list[str] | None:
    """The stems in scanning order when every name is ``prefix + number`` with one prefix,
    else None."""
    parts = [_NUMBERED.match(s) for s in stems]
    if not stems or any(p is None for p in parts):
        return None
    prefixes = {p.group(1) for p in parts if p is not None}
    if len(prefixes) != 1:
        return None
    return sorted(stems, key=lambda s: int(_NUMBERED.match(s).group(2)))  # type: ignore[union-attr]


def _knn(a: Any, b: Any, binary: bool) -> Any:
    import cv2

    matcher = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2)
    return matcher.knnMatch(a, b, k=2)


def _ratio_best(knn: Any) -> dict[int, int]:
    out: dict[int, int] = {}
    for m in knn:
        if len(m) == 2 and m[0].distance < PLACE_RATIO * m[1].distance:
            out[m[0].queryIdx] = m[0].trainIdx
        elif len(m) == 1:
            out[m[0].queryIdx] = m[0].trainIdx
    return out


def place_score(a: GlobalDescriptor, b: GlobalDescriptor) -> int:
    """Geometrically consistent mutual matches between two stations' global descriptors.

    Parameters
    ----------
    a, b : GlobalDescriptor

    Returns
    -------
    int
        Size of the largest set of mutual ratio-test matches whose 3D distances agree
        (0 when fewer than 3 match).
    """
    if len(a.descriptors) < 2 or len(b.descriptors) < 2 or a.binary != b.binary:
        return 0
    ab = _ratio_best(_knn(a.descriptors, b.descriptors, a.binary))
    ba = _ratio_best(_knn(b.descriptors, a.descriptors, a.binary))
    pairs = np.array([(i, j) for i, j in sorted(ab.items()) if ba.get(j) == i], dtype=np.int64)
    if len(pairs) < 3:
        return int(len(pairs) > 0)
    keep = consistent_subset(
        a.points[pairs[:, 0]],
        b.points[pairs[:, 1]],
        threshold_m=PLACE_TOLERANCE_M,
        relative=PLACE_RELATIVE,
    )
    return len(keep)


def place_scores(descriptors: dict[str, GlobalDescriptor]) -> dict[frozenset[str], int]:
    """:func:`place_score` of every station pair (a few milliseconds each)."""
    stems = list(descriptors)
    return {
        frozenset((a, b)): place_score(descriptors[a], descriptors[b])
        for a, b in combinations(stems, 2)
    }


def _ordered(a: str, b: str, order: dict[str, int]) -> tuple[str, str]:
    return (a, b) if order[a] < order[b] else (b, a)


def sequential_pairs(stems: list[str], neighbours: int) -> list[Candidate]:
    """Each station with its ``neighbours`` next ones in scanning order (file order when the
    names are not numbered)."""
    seq = sequential_order(stems) or stems
    return [
        Candidate(seq[i], seq[j], "sequential")
        for i in range(len(seq))
        for j in range(i + 1, min(len(seq), i + 1 + neighbours))
    ]


def all_pairs(stems: list[str]) -> list[Candidate]:
    """Every pair, in file order."""
    return [Candidate(a, b, "all") for a, b in combinations(stems, 2)]


def ranked_partners(
    stem: str, stems: list[str], scores: dict[frozenset[str], int]
) -> list[tuple[str, int]]:
    """The other stations by place-recognition score, best first (ties by file order)."""
    others = [(o, scores.get(frozenset((stem, o)), 0)) for o in stems if o != stem]
    return sorted(others, key=lambda t: -t[1])


def auto_pairs(
    stems: list[str],
    scores: dict[frozenset[str], int],
    *,
    neighbours: int,
    place_candidates: int,
    max_links: int,
) -> list[Candidate]:
    """File-order neighbours (when the names are numbered) plus each station's best
    ``place_candidates`` partners, at most ``max_links`` in all."""
    order = {s: i for i, s in enumerate(stems)}
    chosen: dict[frozenset[str], Candidate] = {}
    if sequential_order(stems) is not None:
        for c in sequential_pairs(stems, neighbours):
            chosen[c.key] = Candidate(c.target, c.source, c.origin, scores.get(c.key))
    ranked: list[Candidate] = []
    for s in stems:
        for o, sc in ranked_partners(s, stems, scores)[:place_candidates]:
            if sc >= MIN_PLACE_MATCHES:
                t, src = _ordered(s, o, order)
                ranked.append(Candidate(t, src, "place", float(sc)))
    ranked.sort(key=lambda c: (-(c.place_score or 0.0), order[c.target], order[c.source]))
    for c in ranked:
        if len(chosen) >= max_links:
            break
        chosen.setdefault(c.key, c)
    return list(chosen.values())[:max_links]


def station_stem(name: str, stems: Sequence[str]) -> str | None:
    """The station ``name`` means: a stem as it is, else the stem of a file name or path
    (``site/station_07.ptx`` -> ``station_07``); None when it names none of ``stems``.

    >>> station_stem("site/station_07.ptx", ["station_07", "station_08"])
    'station_07'
    """
    if name in stems:
        return name
    stem = Path(name).stem
    return stem if stem in stems else None


def read_pairs_csv(path: Path, stems: list[str]) -> list[Candidate]:
    """Pairs from a CSV file of ``target,source`` station stems (a header row is allowed).

    Raises
    ------
    InputError
        Unreadable file, a row without two names, an unknown station, a pair with itself, or
        no pair at all.
    """
    known = set(stems)
    try:
        with path.open(newline="") as f:
            rows = [r for r in csv.reader(f) if r and any(x.strip() for x in r)]
    except OSError as e:
        raise InputError(path, f"cannot read: {e.strerror or e}") from None
    if rows and [x.strip().lower() for x in rows[0][:2]] == ["target", "source"]:
        rows = rows[1:]
    out: dict[frozenset[str], Candidate] = {}
    for n, row in enumerate(rows, 1):
        if len(row) < 2:
            raise InputError(path, f"row {n}: expected target,source")
        t, s = (station_stem(x.strip(), stems) or Path(x.strip()).stem for x in row[:2])
        for name in (t, s):
            if name not in known:
                raise InputError(path, f"row {n}: {name!r} is not one of the stations")
        if t == s:
            raise InputError(path, f"row {n}: a station cannot be linked to itself")
        out.setdefault(frozenset((t, s)), Candidate(t, s, "file"))
    if not out:
        raise InputError(path, "no pairs in the file")
    return list(out.values())


#: a link given by hand: target, source and its ``T_target_source`` (a 4x4 matrix, or a
#: transform file read by :func:`~flexreg.io.transform_io.read_pair_transform`)
HandLink = tuple[str, str, ArrayLike | str | PathLike[str]]


def hand_links(links: Iterable[HandLink], stems: Sequence[str]) -> list[Candidate]:
    """Links given by hand, as ``hand`` candidates carrying their ``T_target_source``.

    Parameters
    ----------
    links : iterable of (str, str, array_like or path-like)
        ``(target, source, T_target_source)``: two stations (stems, or file names whose stem
        is a station) and the pose that maps the source into the target, as a 4x4 matrix or
        a transform file (a 4x4 text matrix, a JSON with ``T_target_source``, a ``flexreg
        synth`` gt.json).
    stems : sequence of str
        The stations.

    Returns
    -------
    list of Candidate
        In the order given.

    Raises
    ------
    InputError
        An unknown station, a station linked to itself or a pair given twice (naming
        ``--link``), or a transform that is not a 4x4 rigid matrix (naming its file);
        checked link by link, the names before the matrix.
    """
    out: dict[frozenset[str], Candidate] = {}
    for target, source, T in links:
        names = []
        for name in (target, source):
            stem = station_stem(str(name), stems)
            if stem is None:
                raise InputError(
                    f"--link {target} {source}", f"{str(name)!r} is not one of the stations"
                )
            names.append(stem)
        t, s = names
        if t == s:
            raise InputError(f"--link {target} {source}", "a station cannot be linked to itself")
        if frozenset((t, s)) in out:
            raise InputError(f"--link {target} {source}", f"the pair {t} / {s} is given twice")
        if isinstance(T, str | PathLike):
            M = read_pair_transform(T, t, s)
        else:
            M = as_transform(T, name=f"--link {target} {source}")
        out[frozenset((t, s))] = Candidate(t, s, "hand", T_target_source=M)
    return list(out.values())


def merge_candidates(
    candidates: Iterable[Candidate], given: Iterable[Candidate]
) -> list[Candidate]:
    """``candidates`` with ``given`` ones in place of those of the same pair (either
    direction; a given pair the candidates lack comes after them): one link per pair, the
    surveyor's word first.

    >>> auto = [Candidate("a", "b", "sequential"), Candidate("b", "c", "sequential")]
    >>> got = merge_candidates(auto, [Candidate("c", "b", "file")])
    >>> [(c.target, c.source, c.origin) for c in got]
    [('a', 'b', 'sequential'), ('c', 'b', 'file')]
    """
    chosen: dict[frozenset[str], Candidate] = {c.key: c for c in candidates}
    for c in given:
        chosen[c.key] = c
    return list(chosen.values())


def later_pairs(
    stems: list[str],
    sol: GraphSolution,
    links: Sequence[Link],
    tried: set[frozenset[str]],
    scores: dict[frozenset[str], int],
    *,
    reach_m: float,
    place_candidates: int,
    budget: int,
    judge: tuple[Judge, float, float] | None = None,
) -> list[Candidate]:
    """The pairs a solution suggests, at most ``budget``: stations of one group whose solved
    positions are within ``reach_m`` (loops), then stations of different groups that a chain
    of trusted answers between the groups brings within ``reach_m`` (:func:`chain_pairs`:
    the loop that would check them), then the pairs each hypothesis of a link between two
    groups brings within ``reach_m`` (:func:`hypothesis_pairs`: the loops that would test
    it), then the unplaced stations' next ``place_candidates`` place-recognition partners,
    every station's first before any station's second (a cut budget reaches every station):
    whatever they score, as the last way left to an unplaced station.

    With the map's free-space check (``judge``: the judge, ``map_min_conflict`` and
    ``map_conflict_ratio``), a pair is proposed only where the stations would see each other
    at the pose that suggests it (:func:`~flexreg.survey.links.map_sees`): a registration
    can confirm a pose only where the two scans share surfaces there. A hypothesis the map
    refutes (:func:`~flexreg.survey.links.map_refutes`, at the nearest pairs it looks at)
    needs no loop to refute it, and a pair that sees nothing of the other at the pose that
    suggests it would only fail."""
    order = {s: i for i, s in enumerate(stems)}
    near: list[_Pose] = []
    for g in sol.groups:
        for i, a in enumerate(g):
            for b in g[i + 1 :]:
                if frozenset((a, b)) in tried or a not in sol.poses or b not in sol.poses:
                    continue
                d = float(np.linalg.norm(sol.poses[a][:3, 3] - sol.poses[b][:3, 3]))
                if d <= reach_m:
                    near.append((d, a, b, invert(sol.poses[a]) @ sol.poses[b]))
    near.sort(key=lambda t: (t[0], order[t[1]], order[t[2]]))
    out: list[Candidate] = []
    keys: set[frozenset[str]] = set()
    for options in [
        *([x] for x in near),  # each near pair alone: the group's placement is given
        *chain_pairs(sol, links, tried, reach_m, order),
        *hypothesis_pairs(sol, links, tried, reach_m, order),
    ]:
        if len(out) >= budget:  # the map looks no further than the budget reaches
            break
        pair = _first_seen(options, judge)
        if pair is not None and frozenset(pair) not in keys:
            keys.add(frozenset(pair))
            out.append(Candidate(*_ordered(*pair, order), "proximity", _score(scores, *pair)))
    unplaced = [s for g in sol.groups[1:] for s in g] if len(sol.groups[0]) > 1 else list(stems)
    extra = [
        [
            (o, sc)
            for o, sc in ranked_partners(s, stems, scores)
            if frozenset((s, o)) not in tried and sc > 0
        ][:place_candidates]
        for s in unplaced
    ]
    for k in range(place_candidates):  # every station's next partner, then the second...
        out += [
            Candidate(*_ordered(s, x[k][0], order), "place", float(x[k][1]))
            for s, x in zip(unplaced, extra, strict=True)
            if k < len(x)
        ]
    seen: set[frozenset[str]] = set()
    unique = []
    for c in out:
        if c.key not in seen:
            seen.add(c.key)
            unique.append(c)
    return unique[: max(0, budget)]


_Pose = tuple[float, str, str, "NDArray[np.float64]"]
"""A pair a pose suggests: distance (metres), stations ``a`` and ``b``, ``T_a_b``."""


def _first_seen(
    options: list[_Pose], judge: tuple[Judge, float, float] | None
) -> tuple[str, str] | None:
    """Of the pairs one placement brings near (nearest first), the first the map (``judge``:
    the judge, ``map_min_conflict``, ``map_conflict_ratio``) finds seeing each other there,
    looking at no more than :data:`HYPOTHESIS_LOOKS`; None when the map refutes the
    placement at one of them first, or none of them sees the other. Without a map, the
    nearest pair. The judge remembers each pair and pose it looked at."""
    if judge is None:
        return (options[0][1], options[0][2]) if options else None
    for _, a, b, T in options[:HYPOTHESIS_LOOKS]:
        said = judge[0](a, b, T)
        if map_refutes(said, judge[1], judge[2]):
            return None
        if map_sees(said):
            return a, b
    return None


def _cross(
    sol: GraphSolution,
    groups: tuple[int, int],
    X: NDArray[np.float64],
    tried: set[frozenset[str]],
    reach_m: float,
    order: dict[str, int],
) -> list[_Pose]:
    """The untried pairs, one station of each group, that ``X`` (``T_g1_g2`` of the groups'
    frames) brings within ``reach_m``, nearest first, with their relative poses."""
    eye = np.eye(4)
    A, B = sol.groups[groups[0]], sol.groups[groups[1]]
    pa = np.array([sol.poses.get(a, eye)[:3, 3] for a in A])
    pb = np.array([sol.poses.get(b, eye)[:3, 3] for b in B]) @ X[:3, :3].T + X[:3, 3]
    d = np.linalg.norm(pa[:, None, :] - pb[None], axis=2)
    out: list[_Pose] = []
    for i, j in np.argwhere(d <= reach_m):
        a, b = A[i], B[j]
        if frozenset((a, b)) not in tried:
            T = invert(sol.poses.get(a, eye)) @ X @ sol.poses.get(b, eye)
            out.append((float(d[i, j]), a, b, T))
    out.sort(key=lambda t: (t[0], order[t[1]], order[t[2]]))
    return out


def _between(group: dict[str, int], e: Link) -> tuple[int, int] | None:
    """The groups of a link's target and source when they differ (else None)."""
    gt, gs = group.get(e.target), group.get(e.source)
    return None if gt is None or gs is None or gt == gs else (gt, gs)


def _group_pose(sol: GraphSolution, e: Link, T: NDArray[np.float64]) -> NDArray[np.float64]:
    """``T_grouptarget_groupsource`` of the groups' frames when ``e`` has pose ``T``."""
    eye = np.eye(4)
    return sol.poses.get(e.target, eye) @ T @ invert(sol.poses.get(e.source, eye))


def chain_pairs(
    sol: GraphSolution,
    links: Sequence[Link],
    tried: set[frozenset[str]],
    reach_m: float,
    order: dict[str, int],
) -> list[list[_Pose]]:
    """The untried pairs of stations of different groups that chains of trusted answers
    between groups (confident links no loop has checked yet, nor any contradicts) bring
    within ``reach_m``: each the link that would close a loop through the chain and so
    confirm its links or refute one of them (a single station joined by confident links to
    the stations on either side is placed only once such a loop closes). One list per pair
    of groups a chain joins, nearest pair first; the groups' frames are joined along a
    spanning tree of those answers, in the links' order."""
    frame: dict[int, NDArray[np.float64]] = {}  # T_tree_group of the groups chains reach
    tree: dict[int, int] = {}
    group = {s: i for i, g in enumerate(sol.groups) for s in g}
    adj: dict[int, list[tuple[int, NDArray[np.float64]]]] = {}
    for e in links:
        ends = _between(group, e)
        if ends is None or e.T_target_source is None or not e.trusted or e.loop_error_m is not None:
            continue
        X = _group_pose(sol, e, np.asarray(e.T_target_source))
        adj.setdefault(ends[0], []).append((ends[1], X))
        adj.setdefault(ends[1], []).append((ends[0], invert(X)))
    for root in sorted(adj):
        if root in frame:
            continue
        frame[root], tree[root] = np.eye(4), root
        todo = [root]
        while todo:
            g = todo.pop(0)
            for h, X in adj[g]:
                if h not in frame:
                    frame[h], tree[h] = frame[g] @ X, root
                    todo.append(h)
    out = []
    members = sorted(frame)
    for i, g1 in enumerate(members):
        for g2 in members[i + 1 :]:
            if tree[g1] != tree[g2]:
                continue
            X = invert(frame[g1]) @ frame[g2]
            options = _cross(sol, (g1, g2), X, tried, reach_m, order)
            if options:
                out.append(options)
    out.sort(key=lambda o: o[0][0])
    return out


def hypothesis_pairs(
    sol: GraphSolution,
    links: Sequence[Link],
    tried: set[frozenset[str]],
    reach_m: float,
    order: dict[str, int],
) -> list[list[_Pose]]:
    """For each pose a registered link between two groups may have (its answer and its
    alternatives), the untried pairs of stations, one of each group, that pose brings within
    ``reach_m``, nearest first, with their relative poses there: each the link that would
    close a loop through the hypothesis and so confirm or refute it. The poses by their
    nearest pair."""
    group = {s: i for i, g in enumerate(sol.groups) for s in g}
    out = []
    for e in links:
        ends = _between(group, e)
        if ends is None or e.T_target_source is None or e.verdict is None:
            continue
        for T in e.poses:
            options = _cross(sol, ends, _group_pose(sol, e, T), tried, reach_m, order)
            if options:
                out.append(options)
    out.sort(key=lambda o: (o[0][0], order[o[0][1]], order[o[0][2]]))
    return out


def _score(scores: dict[frozenset[str], int], a: str, b: str) -> float | None:
    v = scores.get(frozenset((a, b)))
    return None if v is None else float(v)


__all__ = [
    "HYPOTHESIS_LOOKS",
    "MIN_PLACE_MATCHES",
    "Candidate",
    "HandLink",
    "all_pairs",
    "auto_pairs",
    "chain_pairs",
    "hand_links",
    "hypothesis_pairs",
    "later_pairs",
    "merge_candidates",
    "place_score",
    "place_scores",
    "ranked_partners",
    "read_pairs_csv",
    "sequential_order",
    "sequential_pairs",
    "station_stem",
]
