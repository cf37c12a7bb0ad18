"""A link's hypotheses, and the cycles that vote for them: step 1 of the survey's choice of
which pose of each link to keep (:mod:`flexreg.survey.consensus`).

Every registered link offers hypotheses (:func:`hypotheses_of`): its answer and, when its
verdict is uncertain, the clearly different poses that fit almost as well (its runner-ups,
its twins one bay or room along; :class:`~flexreg.survey.links.Alternative`). A confident
verdict has decided between its poses on the dense check, and a link the surveyor vouched
for (``--link``, rough positions) offers its one pose.

Every cycle of three or four stations, and every longer cycle through the spanning forest of
the trusted answers (confident or vouched), is composed for every combination of its links'
hypotheses (:func:`cycle_votes`). A combination that closes within the loop tolerance
(``loop_max_deg``; ``loop_max_m`` plus ``loop_per_link_m`` per link) is an independent route,
and each of its hypotheses gets a vote: a *firm* vote when the rest of the cycle is trusted
answers. A cycle of trusted answers that does not close contradicts each of them
(:attr:`Hypothesis.against`).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from flexreg.core.transforms import invert
from flexreg.survey.links import Alternative, Link, Matrix, walk

log = logging.getLogger(__name__)

#: A hypothesis's weight: a trusted answer counts whole, an uncertain answer half, an
#: alternative half its support (a runner-up's score ratio, a twin's share of the answer's).
UNCERTAIN_WEIGHT = 0.5


@dataclass(frozen=True)
class LoopTolerance:
    """How far a cycle of links may be from closing: ``max_deg`` degrees, and ``max_m``
    plus ``per_link_m`` per link metres (errors add up along a path)."""

    max_deg: float
    max_m: float
    per_link_m: float

    def metres(self, hops: int) -> float:
        return self.max_m + self.per_link_m * hops

    def agrees(self, err: tuple[float, float], hops: int) -> bool:
        """Whether a loop error (degrees, metres) over ``hops`` links is within it."""
        return err[0] <= self.max_deg and err[1] <= self.metres(hops)


@dataclass(eq=False)
class Hypothesis:
    """One pose a link may have.

    Attributes
    ----------
    link : Link
    T : (4, 4) float64
        ``T_target_source`` of the hypothesis.
    alternative : Alternative or None
        None for the link's answer.
    votes : int
        Cycles it closes (within the loop tolerance).
    firm_votes : int
        Those of them whose other links are all trusted answers (confident, or vouched for)
        and none of them disputed: a trusted answer that a cycle of trusted answers
        contradicts and none confirms may be the wrong one of that cycle, and confirms
        nothing (:func:`cycle_votes`).
    misfit : float
        Over those cycles, how far each closes at best, as a share of the tolerance
        (rotation and translation added): which of equally voted hypotheses fits tightest.
    against : int
        Cycles of trusted answers through it (it one of them) that do not close.
    blamed : bool
        The map named it the wrong link of such a cycle
        (:func:`flexreg.survey.consensus.merge_groups`): it places nothing.
    refit : (4, 4) float64 or None
        Its link's pose where all the overlap of the two groups it joins fits, when that is
        off its own beyond the loop tolerance (a doorway link slid along a wall): it joins
        sets through it but places nothing itself (:mod:`flexreg.survey.consensus`).
    """

    link: Link
    T: Matrix
    alternative: Alternative | None = None
    votes: int = 0
    firm_votes: int = 0
    misfit: float = 0.0
    against: int = 0
    blamed: bool = False
    rests: list[tuple[Hypothesis, ...]] = field(default_factory=list)  # of its firm votes
    refit: Matrix | None = None
    _inverse: Matrix | None = field(default=None, init=False, repr=False)

    @property
    def vouched(self) -> bool:
        return self.alternative is None and self.link.vouched == "hand"

    @property
    def firm(self) -> bool:
        """A trusted answer: confident, or vouched for."""
        return self.alternative is None and self.link.trusted

    @property
    def confident(self) -> bool:
        """A confident link's answer (:attr:`~flexreg.survey.links.Link.confident`)."""
        return self.alternative is None and self.link.confident

    @property
    def sited(self) -> bool:
        """The pose of the link the surveyor's rough positions picked, alone of its fitting
        poses within their window (:func:`flexreg.survey.positions.choose`)."""
        return self.alternative is None and self.link.vouched == "positions"

    @property
    def plain(self) -> bool:
        """The answer of a link uncertain only for its small overlap
        (:attr:`~flexreg.survey.links.Link.plain`)."""
        return self.alternative is None and self.link.plain and not self.link.vouched

    @property
    def weight(self) -> float:
        if self.alternative is not None:
            return UNCERTAIN_WEIGHT * float(self.alternative.support)
        return 1.0 if self.link.trusted else UNCERTAIN_WEIGHT

    def oriented(self, a: str) -> Matrix:
        """The pose as ``T_a_other`` (``a`` one of the link's stations)."""
        if self.link.target == a:
            return self.T
        if self._inverse is None:  # asked for in every cycle through it
            self._inverse = invert(self.T)
        return self._inverse


def hypotheses_of(link: Link) -> list[Hypothesis]:
    """A link's hypotheses: its answer, then, for an uncertain link, its alternatives (a
    confident verdict has decided between its poses on the dense check; the surveyor or rough
    positions vouch for one pose)."""
    out = [Hypothesis(link, np.asarray(link.T_target_source, dtype=np.float64))]
    if not link.trusted and not link.vouched:
        out += [Hypothesis(link, np.asarray(a.T_target_source), a) for a in link.alternatives]
    return out


# ------------------------------------------------------------------ step 1: cycle votes


@dataclass(frozen=True)
class Cycle:
    """A cycle of stations and the trusted answer of each link around it (``links[i]``
    joins ``stations[i]`` and ``stations[i + 1]``, the last the first)."""

    stations: tuple[str, ...]
    links: list[Hypothesis]

    def rest(self, i: int) -> Matrix:
        """``T_{stations[i], stations[i + 1]}`` composed along the other links."""
        n = len(self.stations)
        P = np.eye(4)  # T_{v[i+1], x} along v[i+1] -> v[i+2] -> ... -> v[i]
        for j in range(1, n):
            x = self.stations[(i + j) % n]
            P = P @ self.links[(i + j) % n].oriented(x)
        return invert(P)


def _angles_deg(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Geodesic angles between the rotation blocks of two stacks of 4x4 (broadcast)."""
    c = (np.einsum("...ji,...ji->...", A[..., :3, :3], B[..., :3, :3]) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _cycles(adj: dict[str, set[str]]) -> Iterator[tuple[str, ...]]:
    """Every simple cycle of three or four stations once (its smallest station first)."""
    for a in sorted(adj):
        for b, c in itertools.combinations(sorted(x for x in adj[a] if x > a), 2):
            if c in adj[b]:
                yield (a, b, c)
    for a in sorted(adj):
        for c in sorted(x for x in adj if x > a):
            common = sorted(x for x in adj[a] & adj[c] if x > a)
            for b, d in itertools.combinations(common, 2):
                yield (a, b, c, d)


def cycle_votes(hyps: dict[frozenset[str], list[Hypothesis]], tol: LoopTolerance) -> list[Cycle]:
    """Step 1: each hypothesis's :attr:`~Hypothesis.votes` and :attr:`~Hypothesis.against`
    (set in place). ``hyps``: the hypotheses per pair of stations. Returns the cycles of
    three or four trusted answers that do not close (the map may blame one of its links:
    :func:`flexreg.survey.consensus.merge_groups`)."""
    adj: dict[str, set[str]] = {}
    for pair in hyps:
        a, b = sorted(pair)
        adj.setdefault(a, set()).add(b)
        adj.setdefault(b, set()).add(a)

    def stack(x: str, y: str) -> tuple[list[Hypothesis], np.ndarray]:
        hs = hyps[frozenset((x, y))]
        return hs, np.stack([h.oriented(x) for h in hs])

    n = 0
    broken: list[Cycle] = []
    for cyc in _cycles(adj):
        n += 1
        if len(cyc) == 3:  # T_ab T_bc against T_ac
            a, b, c = cyc
            left = [stack(a, b), stack(b, c)]
            right = [stack(a, c)]
        else:  # a-b-c-d: T_ab T_bc against T_ad T_dc
            a, b, c, d = cyc
            left = [stack(a, b), stack(b, c)]
            right = [stack(a, d), stack(d, c)]
        A = np.einsum("iab,jbc->ijac", left[0][1], left[1][1])
        B = right[0][1] if len(right) == 1 else np.einsum("iab,jbc->ijac", right[0][1], right[1][1])
        A = A.reshape(-1, 4, 4)
        B = B.reshape(-1, 4, 4)
        deg = _angles_deg(A[:, None], B[None, :])
        m = np.linalg.norm(A[:, None, :3, 3] - B[None, :, :3, 3], axis=-1)
        closes = (deg <= tol.max_deg) & (m <= tol.metres(len(cyc)))
        if _contradict(closes, left, right):
            edges = [hyps[frozenset((x, cyc[(i + 1) % len(cyc)]))] for i, x in enumerate(cyc)]
            firm = [[h for h in e if h.firm] for e in edges]
            if all(len(f) == 1 for f in firm):
                broken.append(Cycle(cyc, [f[0] for f in firm]))
        closing = np.argwhere(closes)
        if not len(closing):
            continue
        misfit = deg / tol.max_deg + m / tol.metres(len(cyc))
        fit: dict[int, tuple[float, Hypothesis, tuple[Hypothesis, ...] | None]] = {}
        nl1 = len(left[1][0])
        nr1 = len(right[1][0]) if len(right) == 2 else 1
        for i, k in closing:
            members = [left[0][0][i // nl1], left[1][0][i % nl1]]
            members += (
                [right[0][0][k]]
                if len(right) == 1
                else [right[0][0][k // nr1], right[1][0][k % nr1]]
            )
            for h in members:
                f = float(misfit[i, k])
                rest = tuple(o for o in members if o is not h)
                backed = rest if all(o.firm for o in rest) else None
                was = fit.get(id(h))
                if was is None or (backed is not None, -f) > (was[2] is not None, -was[0]):
                    fit[id(h)] = (f, h, backed)
        for f, h, backed in fit.values():
            _vote(h, f, backed)
    closed = _tree_votes(hyps, tol)
    log.debug("%d short cycles, %d longer ones closed", n, closed)
    _settle_firm_votes(hyps)
    return broken


def _settle_firm_votes(hyps: dict[frozenset[str], list[Hypothesis]]) -> None:
    """Firm votes only through undisputed trusted answers. A trusted answer is disputed when
    a cycle of trusted answers through it does not close and none closes: one link of that
    cycle is wrong and nothing says it is not this one (a confident answer into a look-alike
    room, agreeing with the alias of every other link of the same station). One confirmed by
    a closing cycle of trusted answers stays undisputed: the broken cycle's wrong link is
    another."""
    every = [h for hs in hyps.values() for h in hs]
    disputed = {id(h) for h in every if h.firm and h.against and not h.rests}
    for h in every:
        h.firm_votes = sum(all(id(o) not in disputed for o in rest) for rest in h.rests)


def _contradict(closes: np.ndarray, *sides: list[tuple[list[Hypothesis], np.ndarray]]) -> bool:
    """A cycle whose links all have a trusted answer, and whose trusted answers do not
    close: each of them is contradicted (:attr:`Hypothesis.against`; returns True).
    ``closes``: which combinations of the left side's (rows) and the right side's (columns)
    close."""
    firm = []
    for side in sides:
        hs = [x[0] for x in side]
        combos = np.ones(1, dtype=bool)
        for lst in hs:
            combos = np.outer(combos, [h.firm for h in lst]).ravel()
        firm.append(combos)
    if not (firm[0].any() and firm[1].any()) or closes[np.ix_(firm[0], firm[1])].any():
        return False
    for side in sides:
        for lst in (x[0] for x in side):
            for h in lst:
                h.against += h.firm
    return True


def _vote(h: Hypothesis, misfit: float, firm: tuple[Hypothesis, ...] | None) -> None:
    """One closing cycle for ``h``; ``firm``: the rest of the cycle when it is all trusted
    answers (a firm vote, counted by :func:`_settle_firm_votes`), else None."""
    h.votes += 1
    h.misfit += misfit
    if firm is not None:
        h.rests.append(firm)


def _tree_votes(hyps: dict[frozenset[str], list[Hypothesis]], tol: LoopTolerance) -> int:
    """Votes of the longer cycles: the trusted answers' spanning forest (best overlap first,
    Kruskal), and every other hypothesis closing a cycle of five or more links through it;
    returns how many such cycles closed."""
    up: dict[str, str] = {}

    def find(x: str) -> str:
        while up.setdefault(x, x) != x:
            up[x] = up[up[x]]
            x = up[x]
        return x

    firm = [h for hs in hyps.values() for h in hs if h.firm]
    adj: dict[str, list[tuple[str, Hypothesis]]] = {}
    in_tree: set[int] = set()
    for h in sorted(firm, key=lambda h: -h.link.overlap):
        a, b = find(h.link.target), find(h.link.source)
        if a != b:
            up[a] = b
            in_tree.add(id(h))
            adj.setdefault(h.link.target, []).append((h.link.source, h))
            adj.setdefault(h.link.source, []).append((h.link.target, h))
    closed = 0
    for hs in hyps.values():
        for h in hs:
            if id(h) in in_tree:
                continue
            path = walk(adj, h.link.target, h.link.source)
            if path is None or len(path) + 1 <= 4:
                continue  # another tree, or a short cycle (counted already)
            T = np.eye(4)  # T_target_source along the tree
            x = h.link.target
            for y, e in path:
                T = T @ e.oriented(x)
                x = y
            err = (float(_angles_deg(T, h.T)), float(np.linalg.norm(T[:3, 3] - h.T[:3, 3])))
            if tol.agrees(err, len(path) + 1):
                closed += 1
                f = err[0] / tol.max_deg + err[1] / tol.metres(len(path) + 1)
                edges = [e for _, e in path]
                _vote(h, f, tuple(edges))  # the rest of its cycle: the forest's trusted answers
                for e in edges:
                    rest = tuple(o for o in [h, *edges] if o is not e)
                    _vote(e, f, rest if h.firm else None)
            elif h.firm:  # a cycle of trusted answers that does not close
                for k in [h, *(e for _, e in path)]:
                    k.against += 1
    return closed


__all__ = [
    "UNCERTAIN_WEIGHT",
    "Cycle",
    "Hypothesis",
    "LoopTolerance",
    "cycle_votes",
    "hypotheses_of",
]
