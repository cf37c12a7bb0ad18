"""Near-ties settled: candidates along a weak axis or a repeat, and a tournament of the close
candidates decided by duels at full resolution (:mod:`flexreg.registration.fullres`).

In a tunnel nothing but a niche fixes the position along the axis; in an arcade of identical
bays nothing but a parked forklift tells one bay from the next; and a half turn maps both onto
themselves. The priors then land anywhere along the axis, and the true pose is often not among
the candidates at all. When the winning pose has a weak translation axis (the point-to-plane
information of its overlap, :func:`weak_direction`) or the target's plan view repeats (a shift
among its symmetries), :func:`sweep_candidates` slides the winner, and its turns by the plan's
self-overlays, along that axis over ``SWEEP_RANGE_M`` in steps of ``SWEEP_STEP_M``; each slid
pose is scored on the source's points at full resolution (a cue near the stations covers many
of them), the best local maxima are placed on the surfaces facing the axis and polished by the quick
projective ICP, and they join the candidates. :func:`tournament` then duels every clearly
different candidate that scores close to the best (:func:`~flexreg.registration.check.duel`
on :func:`~flexreg.registration.fullres.pose_masks`): one that beats every other decisively
(:func:`decisive_full`) is the answer; without one the near-tie stays and the verdict says so.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert, rotation_error_deg
from flexreg.registration.candidates import Aliases, Coarse, Keypoints3D, at_pose
from flexreg.registration.check import TOLERANCE, Check, Judged, Masks, decisive_full, duel
from flexreg.registration.config import SWEEP_RANGE_M, SWEEP_STEP_M, JudgeConfig
from flexreg.registration.fullres import (
    FullPair,
    FullView,
    full_masks,
    full_score,
    full_scores,
    pose_masks,
)
from flexreg.stages.verification import plane_information

log = logging.getLogger(__name__)

#: most source points scored per slid pose (every k-th point of its full view)
SWEEP_POINTS = 40_000

#: most source points facing the axis scored per slid pose (a tunnel at 1024 x 512 has about
#: 11 000, a niche's sides a few hundred of them)
FACING_POINTS = 10_000

#: local maxima of each sweep refined, polished and judged
SWEEP_PEAKS = 3

#: most candidates in a :func:`tournament`
TOURNAMENT_SIZE = 10

#: most candidates :func:`screen`-ed for a tournament (best scores first)
SCREENED = 30

#: a turn of the plan's self-overlays is a half turn or so when it turns more than this
TURN_DEG = 90.0


def weak_direction(
    check: Check,
    normals: NDArray[np.float32],
    T: NDArray[np.float64],
    threshold_m: float,
    min_strength: float,
) -> NDArray[np.float64] | None:
    """The translation direction the overlap of pose ``T`` fixes least, when weaker than
    ``min_strength`` (per point, as :func:`~flexreg.stages.verification.axis_strength`).

    The translation block of the point-to-plane information of the source's sample points
    the target explains, once the rotations may adjust (its Schur complement), divided by
    their number; its weakest eigenvector is the direction (a corridor's axis).

    Parameters
    ----------
    check : Check
        The target's view and the source's even sample.
    normals : (H, W, 3) float32
        The target's grid normals.
    T : (4, 4) float64
        The pose.
    threshold_m : float, metres
        The inlier threshold (points within half of it count).
    min_strength : float

    Returns
    -------
    (3,) float64 or None
        Unit direction in the target frame, or None when every direction is firm.
    """
    q, ok, _ = check.classify(T, *TOLERANCE.fine(threshold_m))
    info, _, n = plane_information(check.view, normals, q[ok])
    if n < 6:
        return None
    H = info / n
    rr, rt, tt = H[:3, :3], H[:3, 3:], H[3:, 3:]
    schur = tt - rt.T @ np.linalg.pinv(rr) @ rt
    lam, V = np.linalg.eigh((schur + schur.T) / 2)
    if lam[0] >= min_strength:
        return None
    return np.asarray(V[:, 0], dtype=np.float64)


def repeat_direction(aliases: Aliases | None) -> NDArray[np.float64] | None:
    """The direction of the first pure shift among the target's plan symmetries (a row of
    bays or modules), unit, target frame; None without one."""
    for S in aliases.target if aliases is not None else ():
        t = S[:3, 3]
        if rotation_error_deg(S, np.eye(4)) < 1.0 and np.linalg.norm(t) >= 1.0:
            return np.asarray(t / np.linalg.norm(t), dtype=np.float64)
    return None


def half_turn(
    W: NDArray[np.float64], up: NDArray[np.float64], pivot: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``W`` turned by 180 degrees about the vertical ``up`` through ``pivot`` (target frame).

    >>> T = half_turn(np.eye(4), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    >>> T[:3, 3].round(6).tolist(), T[0, 0].round(6)
    ([2.0, 0.0, 0.0], -1.0)
    """
    u = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    R = 2.0 * np.outer(u, u) - np.eye(3)  # rotation by pi about u
    F = np.eye(4)
    F[:3, :3] = R
    F[:3, 3] = pivot - R @ pivot
    return F @ W


def _turns(
    aliases: Aliases | None, W: NDArray[np.float64], pivot: NDArray[np.float64]
) -> list[NDArray[np.float64]]:
    """``W`` turned half about the target's vertical through ``pivot`` (the overlap's
    centroid: on the axis of a symmetric cross-section when the surfaces are sampled by
    area), when the vertical is known."""
    if aliases is None or aliases.up is None:
        return []
    return [half_turn(W, aliases.up, pivot)]


#: how far (metres) and in what steps a turned pose is slid across the axis to fit the walls
ACROSS_M, ACROSS_STEP_M = 2.0, 0.1


def _across(
    T: NDArray[np.float64],
    direction: NDArray[np.float64],
    up: NDArray[np.float64],
    score: _Scorer,
) -> NDArray[np.float64]:
    """``T`` slid horizontally across ``direction`` to where ``score`` peaks, within
    :data:`ACROSS_M` in :data:`ACROSS_STEP_M` steps. The overlap's centroid misses the axis
    of a tunnel's cross-section when one station stands near a wall (by half a metre on the
    cue tunnels of the verdict benchmark, docs/benchmarks.md: the half turn about it then
    stands beside the walls and no slide along the axis fits); across the axis the walls
    fix the position."""
    v = np.cross(np.asarray(up, dtype=np.float64), direction)
    norm = float(np.linalg.norm(v))
    if norm < 1e-6:
        return T
    v /= norm
    k = round(ACROSS_M / ACROSS_STEP_M)
    offsets = np.arange(-k, k + 1) * ACROSS_STEP_M
    s = score.shifted(T, offsets[:, None] * v)
    return _shifted(T, float(offsets[int(np.argmax(s))]) * v)


def _shifted(T: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    out = T.copy()
    out[:3, 3] += v
    return out


@dataclass(eq=False)
class _Scorer:
    """Scores a pose on a strided subset of the source's full view
    (:func:`~flexreg.registration.fullres.full_score`)."""

    target: FullView
    points: NDArray[np.floating[Any]]
    slack: NDArray[np.floating[Any]]
    normals: NDArray[np.floating[Any]]
    threshold_m: float

    @classmethod
    def of(cls, pair: FullPair, threshold_m: float, points: int = SWEEP_POINTS) -> _Scorer:
        s = pair.source
        k = max(1, -(-len(s.points) // points))
        return cls(pair.target, *s.take(np.s_[::k]), threshold_m)

    def __call__(self, T: NDArray[np.float64]) -> float:
        return full_score(
            self.target, self.points, self.slack, T, self.threshold_m, coarse=True,
            normals=self.normals,
        )  # fmt: skip

    def shifted(self, T: NDArray[np.float64], shifts: NDArray[np.float64]) -> NDArray[np.float64]:
        """The scores of ``T`` moved by each of ``shifts`` ((K, 3), target frame) at once."""
        return full_scores(
            self.target, self.points, self.slack, T, shifts, self.threshold_m, coarse=True,
            normals=self.normals,
        )  # fmt: skip


def _facing(
    pair: FullPair, R: NDArray[np.float64], direction: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """The source's points whose normal, turned by ``R`` into the target frame, lies within
    60 degrees of ``direction`` either way: the only surfaces a slide along it moves across
    themselves (a tunnel's niche and its cabinets, a forklift's front and back)."""
    # the direction turned into the source frame, against the normals in float64 (a float32
    # array times a float64 matrix takes numpy's slow mixed-type loop: 60 ms for 360 000)
    v = np.asarray(R, dtype=np.float64).T @ np.asarray(direction, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.asarray(np.abs(pair.source.normals.astype(np.float64) @ v) >= 0.5)


@dataclass(eq=False)
class _FacingScorer(_Scorer):
    """Scores a pose on the source's points facing the sweep's direction only (at most
    :data:`FACING_POINTS`, every k-th), with the open-space tolerance (coarse). Along a
    tunnel the other surfaces change their score with the grazing angles and the reach of
    the other scanner far more than a small cue does (on all points the truth can score a
    percent below a pose metres away: docs/benchmarks.md, Verdict); on the facing points it
    peaks at the cue."""

    @classmethod
    def facing(
        cls, pair: FullPair, base: NDArray[np.float64], direction: NDArray[np.float64], thr: float
    ) -> _FacingScorer:
        s = pair.source
        idx = np.flatnonzero(_facing(pair, base[:3, :3], direction))
        idx = idx[:: max(1, -(-len(idx) // FACING_POINTS))]
        return cls(pair.target, *s.take(idx), thr)


def _peaks(scores: NDArray[np.float64], count: int, skip: int | None, away: int = 0) -> list[int]:
    """Indices of the best local maxima of a 1-D score (not ``skip``), each more than
    ``away`` indices from every better one kept."""
    s = np.asarray(scores)
    left = np.concatenate([[-np.inf], s[:-1]])
    right = np.concatenate([s[1:], [-np.inf]])
    idx = [int(i) for i in np.flatnonzero((s >= left) & (s >= right)) if i != skip]
    out: list[int] = []
    for i in sorted(idx, key=lambda i: -s[i]):
        if all(abs(i - k) > away for k in out):
            out.append(i)
        if len(out) >= count:
            break
    return out


def sweep_candidates(
    W: NDArray[np.float64],
    direction: NDArray[np.float64],
    aliases: Aliases | None,
    pair: FullPair,
    threshold_m: float,
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    *,
    pivot: NDArray[np.float64],
    range_m: float,
    step_m: float,
) -> list[NDArray[np.float64]]:
    """Poses slid along ``direction``: the winner ``W`` and its half turn, each moved by every
    multiple of ``step_m`` within ``range_m`` along ``direction`` (target frame), scored on
    a subset of the source's full view (:data:`SWEEP_POINTS`), and in half steps on the
    source's points facing the direction only (a cue's surfaces); the :data:`SWEEP_PEAKS` best
    local maxima of each score (those of the second at least ``step_m`` from the first's)
    polished and then placed along the direction on the surfaces facing it
    (:func:`place_along`; a polish afterwards may slide it off again).

    Parameters
    ----------
    W : (4, 4) float64
        The winning ``T_target_source``.
    direction : (3,) float64
        Unit direction, target frame.
    aliases : Aliases or None
        Gives the target's vertical (``up``) for the half turn.
    pair : FullPair
    threshold_m : float, metres
    polish : callable or None
        The quick local ICP.
    pivot : (3,) float64, metres
        Where the vertical axis of the half turn passes (target frame).
    range_m, step_m : float, metres

    Returns
    -------
    list of (4, 4) float64
    """
    score = _Scorer.of(pair, threshold_m)
    n = int(np.floor(range_m / step_m))
    offsets = np.arange(-n, n + 1) * step_m
    fine = np.arange(-2 * n, 2 * n + 1) * (step_m / 2)
    out = []
    for b, base in enumerate([W, *_turns(aliases, W, pivot)]):
        if b > 0 and aliases is not None and aliases.up is not None:
            base = _across(base, direction, aliases.up, score)
        u = _axis(base, direction, polish, range_m / 2)
        s = score.shifted(base, offsets[:, None] * u)
        found = [float(offsets[i]) for i in _peaks(s, SWEEP_PEAKS, n if b == 0 else None)]
        # the surfaces facing the axis in half steps: where the cue fits, whatever the rest
        facing = _FacingScorer.facing(pair, base, u, threshold_m)
        f = facing.shifted(base, fine[:, None] * u)
        for i in _peaks(f, SWEEP_PEAKS, 2 * n if b == 0 else None, away=2):
            if all(abs(fine[i] - d) >= step_m for d in found):
                found.append(float(fine[i]))
        log.debug("sweep base %d: offsets %s", b, found)
        for d in found:
            T = _shifted(base, d * u)
            T = polish(T) if polish is not None else T
            out.append(place_along(T, u, pair, threshold_m, span_m=step_m))
    log.info("sweep along %s: %d poses", np.round(direction, 3), len(out))
    return out


def _axis(
    base: NDArray[np.float64],
    direction: NDArray[np.float64],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    reach_m: float,
) -> NDArray[np.float64]:
    """The sweep's direction through ``base``, corrected by polishing ``base`` slid
    ``reach_m`` either way: a direction estimated a third of a degree off puts a pose slid
    15 m along it 8 cm beside the surfaces, which grazing floors and walls turn into range
    residuals of decimetres; the polished ends lie on the true axis."""
    if polish is None:
        return direction
    ends = [polish(_shifted(base, s * reach_m * direction))[:3, 3] for s in (1.0, -1.0)]
    v = ends[0] - ends[1]
    n = float(np.linalg.norm(v))
    if n < reach_m or float(v @ direction) <= 0:  # the polish ran off: keep the estimate
        return direction
    return np.asarray(v / n, dtype=np.float64)


def place_along(
    T: NDArray[np.float64],
    direction: NDArray[np.float64],
    pair: FullPair,
    threshold_m: float,
    *,
    span_m: float,
) -> NDArray[np.float64]:
    """``T`` moved along ``direction`` (target frame) to where the full-resolution soft
    score (:func:`~flexreg.registration.fullres.full_score`) of the source's points facing
    that direction (normal within 60 degrees of it, either way) peaks, within ``span_m``
    either way: first in tenths of the span, then in hundredths around the best. On an axis
    that only a cue fixes, ICP has almost nothing to pull on (the cue's surfaces are beyond
    its reach) and the other points only add noise; the surfaces facing the axis decide.

    Returns
    -------
    (4, 4) float64
    """
    s = pair.source
    facing = _facing(pair, T[:3, :3], direction)
    pts, slack, normals = s.take(facing)
    if len(pts) == 0:
        return T
    best = 0.0
    for step in (span_m / 10, span_m / 100):
        offsets = best + np.arange(-10, 11) * step
        scores = full_scores(
            pair.target, pts, slack, T, offsets[:, None] * direction, threshold_m,
            normals=normals,
        )  # fmt: skip
        best = float(offsets[int(np.argmax(scores))])
    return _shifted(T, best * direction)


def contenders(
    judged: Sequence[Judged],
    judge: JudgeConfig,
    *,
    floor: float | None = None,
    size: int = TOURNAMENT_SIZE,
) -> list[Judged]:
    """The clearly different candidates, best first, each the best of its neighbourhood:
    those scoring at least ``judge.ambiguity_ratio`` of the best (``floor`` None), or at
    least ``floor``; at most ``size``."""
    ranked = sorted(judged, key=lambda j: -j.score)
    if not ranked:
        return []
    top = ranked[0].score
    low = judge.ambiguity_ratio * top if floor is None else floor
    out: list[Judged] = []
    for j in ranked:
        if j.score < low:
            break
        if all(judge.distinct(j.T_target_source, o.T_target_source) for o in out):
            out.append(j)
        if len(out) >= size:
            break
    return out


def screen(
    players: Sequence[Judged], pair: FullPair, threshold_m: float, size: int = TOURNAMENT_SIZE
) -> list[Judged]:
    """The first player and the ``size - 1`` others that put the fewest of every k-th point
    of both scans in open space (:data:`SWEEP_POINTS` each way; ties: the better score
    first). The samples' scores differ by a percent or two between poses of a tunnel or an
    arcade, so the best scores are not the right pose's company (a pose slid onto the cue can
    rank in the middle of twenty: docs/benchmarks.md, Verdict); at full resolution it is the
    one pose that contradicts nothing, and the poses that contradict little are those that
    can win or refute a winner."""
    if len(players) <= size:
        return list(players)
    s, t = pair.source, pair.target
    ks = max(1, -(-len(s.points) // SWEEP_POINTS))
    kt = max(1, -(-len(t.points) // SWEEP_POINTS))

    def conflicts(T: NDArray[np.float64]) -> int:
        fwd = full_masks(t, s.points[::ks], s.point_slack[::ks], T, threshold_m)[1]
        bwd = full_masks(s, t.points[::kt], t.point_slack[::kt], invert(T), threshold_m)[1]
        return int(fwd.sum()) + int(bwd.sum())

    rest = sorted(players[1:], key=lambda j: (conflicts(j.T_target_source), -j.score))
    return [players[0], *rest[: size - 1]]


#: an answer that puts more than this share of both scans' points in open space at full
#: resolution is not a bay or an aisle beside the truth but plainly wrong (low overlap, the
#: wrong room): no rescue sweep for it (two sweeps cost 30-90 s on such building pairs); a
#: warehouse pair one bay off puts 1.1 % there
RESCUE_MAX_OPEN = 0.02


def _other_row(u: NDArray[np.float64], aliases: Aliases | None) -> NDArray[np.float64]:
    """The horizontal direction across ``u`` (unit, target frame)."""
    up = aliases.up if aliases is not None and aliases.up is not None else np.array([0, 0, 1.0])
    v = np.cross(np.asarray(up, dtype=np.float64), u)
    return np.asarray(v / (np.linalg.norm(v) or 1.0), dtype=np.float64)


def rescue(
    contradicted: Masks,
    judged: Sequence[Judged],
    W: NDArray[np.float64],
    pair: FullPair,
    threshold_m: float,
    judge: JudgeConfig,
) -> Judged | None:
    """The candidate that replaces an answer full resolution contradicts, or None.

    The answer ``W`` puts at least ``judge.settle_open_share`` of both scans in open space (one bay
    or aisle off in a repeating hall: the cue is where the other scanner saw through). Its
    twins and the swept poses are screened (:func:`screen`); the one that puts the fewest
    points in open space wins when that is under a third of ``judge.settle_open_share``, it beats
    the answer :func:`~flexreg.registration.check.decisive_full`-ly, explains at least half
    as many points (not clean merely by seeing less of the other scan), and no other clearly
    different clean candidate (within twice its open share) is left unbeaten."""
    answer = Judged("answer", W, 0.0, 0.0, 0.0)
    others = [j for j in judged if judge.distinct(j.T_target_source, W)]
    ranked = screen([answer, *others], pair, threshold_m, size=TOURNAMENT_SIZE)[1:]
    n = pair.points
    scored = []
    for j in ranked:
        m = pose_masks(pair, j.T_target_source, threshold_m)
        scored.append((open_share(m), j, m))
    scored.sort(key=lambda x: x[0])
    if not scored or scored[0][0] > judge.settle_open_share / 3:
        return None
    share, best, masks = scored[0]
    if not decisive_full(*duel(masks, contradicted), judge, points=n):
        return None
    if explained_share(masks) < 0.5 * explained_share(contradicted):  # clean only by seeing less
        return None
    for other_share, j, m in scored[1:]:
        if other_share <= 2 * max(share, 1.0 / n) and judge.distinct(
            j.T_target_source, best.T_target_source
        ):
            if not decisive_full(*duel(masks, m), judge, points=n):
                return None
    log.info("full resolution contradicts the answer; %s puts %.3f%% in open space", best.origin,
             100 * share)  # fmt: skip
    return best


def _share(masks: Masks, which: int) -> float:
    """Share of all points of both scans set in mask ``which`` (0 explained, 1 open space)."""
    n = sum(len(m[which]) for m in masks)
    return sum(int(m[which].sum()) for m in masks) / n if n else 0.0


def explained_share(masks: Masks) -> float:
    """Share of all points of both scans that a pose explains (its
    :func:`~flexreg.registration.fullres.pose_masks`)."""
    return _share(masks, 0)


def open_share(masks: Masks) -> float:
    """Share of all points of both scans that a pose puts in open space (its
    :func:`~flexreg.registration.fullres.pose_masks`)."""
    return _share(masks, 1)


def tournament(
    players: Sequence[Judged], pair: FullPair, threshold_m: float, judge: JudgeConfig
) -> Judged | None:
    """The one candidate that settles a near-tie at full resolution, or None.

    A player is *close* when it scores at least ``judge.ambiguity_ratio`` of the best, and
    *passes* when it puts at most ``judge.full_max_conflict`` of all points in open space
    itself (a pose that puts the cue where the other scanner saw through is refuted by its
    own contradictions). The winner is close and passes, no player beats it
    :func:`~flexreg.registration.check.decisive_full`-ly, and it beats every other close
    player decisively (there is at least one). A single inconclusive duel (a pose far along
    a tunnel where neither scan sees the other's cue) leaves the near-tie open: nothing is
    settled that the data do not settle.

    Parameters
    ----------
    players : sequence of Judged
        Clearly different candidates (:func:`contenders`).
    pair : FullPair
    threshold_m : float, metres
    judge : JudgeConfig

    Returns
    -------
    Judged or None
        None without a single such player (or with fewer than two players).
    """
    if len(players) < 2:
        return None
    masks = [pose_masks(pair, p.T_target_source, threshold_m) for p in players]
    n = pair.points
    passing = [open_share(m) <= judge.full_max_conflict for m in masks]
    top = max(p.score for p in players)
    close = [k for k, p in enumerate(players) if p.score >= judge.ambiguity_ratio * top]
    winners = []
    for i, p in enumerate(players):
        if not passing[i] or i not in close:
            continue
        duels = {k: duel(masks[i], masks[k]) for k in range(len(players)) if k != i}
        if any(decisive_full(lost, won, judge, points=n) for won, lost in duels.values()):
            continue
        if all(decisive_full(*duels[k], judge, points=n) for k in close if k != i):
            winners.append(p)
    for i, p in enumerate(players):
        log.debug(
            "player %d %s score %.3f open %.0f t %s duels %s",
            *(
                i,
                p.origin,
                p.score,
                open_share(masks[i]) * n,
                np.round(p.T_target_source[:3, 3], 2),
            ),
            [
                tuple(round(x * n) for x in duel(masks[i], masks[k]))
                for k in range(len(players))
                if k != i
            ],
        )
    if len(winners) != 1:
        return None
    log.info("tournament of %d: %s settles it", len(players), winners[0].origin)
    return winners[0]


@dataclass(eq=False)
class Settlement:
    """What :func:`settle` did.

    Attributes
    ----------
    coarse : Coarse
        The coarse result, at the tournament's winner when that is another pose; its
        ``judged`` include the slid poses.
    pair : FullPair or None
        Both scans at full resolution, when a sweep, a tournament or the open-space test of
        a repeating plan needed them (the verdict then reads the answer's share there).
    sweep : dict or None
        JSON-ready: ``kind`` (``"weak_axis"`` or ``"repeat"``), ``direction_target``,
        ``range_m``, ``step_m``, ``poses`` (slid poses judged).
    players : int
        Clearly different candidates in the tournament (0 or 1: none was held).
    won : bool
        Whether one player beat every other decisively (it is the answer).
    axis : (3,) float64 or None
        The swept direction (target frame) when the winner was placed along it: the cue
        alone fixes the position there (:func:`pin_along`).
    """

    coarse: Coarse
    pair: FullPair | None = None
    sweep: dict[str, object] | None = None
    players: int = 0
    won: bool = False
    axis: NDArray[np.float64] | None = None


def pin_along(
    settled: Settlement, T: NDArray[np.float64], T_placed: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``T`` (a refined pose) moved along the axis the settlement placed its winner on, so
    that its position along it is ``T_placed``'s again; ``T`` itself without such an axis.
    The cue fixes that one coordinate; ICP, with nothing but grazing floors and walls to pull
    on along a tunnel, slides by a decimetre or more while the two-way soft score that the
    guard reads barely moves (docs/benchmarks.md, Verdict). ICP keeps the other five degrees
    of freedom. Only a weak axis is pinned: along a repeat (a row of bays, the axis not weak)
    the overlap's own structure holds ICP, finer than the cue's placement."""
    if settled.axis is None or (settled.sweep or {}).get("kind") != "weak_axis":
        return T
    u = settled.axis / np.linalg.norm(settled.axis)
    out = np.array(T, dtype=np.float64, copy=True)
    out[:3, 3] -= float((out[:3, 3] - T_placed[:3, 3]) @ u) * u
    return out


def settle(
    c: Coarse,
    full_pair: Callable[[], FullPair],
    check: Check,
    normals: NDArray[np.float32],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    threshold_m: float,
    aliases: Aliases | None,
    keypoints: tuple[Keypoints3D, Keypoints3D],
    judge: JudgeConfig,
) -> Settlement:
    """Sweep along a weak axis or a repeat, then hold a tournament of the close candidates.

    Parameters
    ----------
    c : Coarse
        :func:`~flexreg.registration.candidates.choose`'s result.
    full_pair : callable
        Makes the :class:`~flexreg.registration.fullres.FullPair` of the scans (called only
        when needed: not on a pair without a weak axis, a repeat or a close rival).
    check : Check
        The dense check (the source's sample in the target's view).
    normals : (H, W, 3) float32
        The target's grid normals.
    polish : callable or None
        The quick local ICP.
    threshold_m : float, metres
    aliases : Aliases or None
        The plans' symmetries.
    keypoints : (Keypoints3D, Keypoints3D)
        Target and source keypoints (the final guided matches of a new winner).
    judge : JudgeConfig

    Returns
    -------
    Settlement
    """
    W, thr = c.T_target_source, threshold_m
    rivals = len(contenders(c.judged, judge)) >= 2
    kind, u = "weak_axis", weak_direction(check, normals, W, thr, judge.sweep_axis_strength)
    if u is None and rivals:  # a repeat matters only when a pose beside the answer competes
        kind, u = "repeat", repeat_direction(aliases)
    pair, contradicted, classified = None, None, None
    if u is None and not rivals:  # ... or when full resolution contradicts the answer
        u = repeat_direction(aliases)
        classified = check.classify(W, *TOLERANCE.fine(thr)) if u is not None else None
        if classified is None or classified[1].mean() < judge.min_overlap:
            return Settlement(c)  # too little overlap to be confident anyway: nothing to rescue
        pair = full_pair()
        contradicted = pose_masks(pair, W, thr)
        share = open_share(contradicted)
        if not judge.settle_open_share <= share < RESCUE_MAX_OPEN:
            return Settlement(c, pair)  # the verdict reads the answer's share
        kind = "repeat"
        log.debug("answer puts %.2f%% in open space at full resolution: sweep", 100 * share)
    pair = pair if pair is not None else full_pair()
    judged = list(c.judged)
    sweep = None
    if u is not None:
        q, ok, _ = classified if classified is not None else check.classify(W, *TOLERANCE.fine(thr))
        pivot = q[ok].mean(axis=0) if ok.any() else W[:3, 3]
        # a contradicted answer in a repeating hall may be off along either of its rows
        axes = [u] if contradicted is None else [u, _other_row(u, aliases)]
        poses = [
            T
            for a in axes
            for T in sweep_candidates(
                W,
                a,
                aliases,
                pair,
                thr,
                polish,
                pivot=pivot,
                range_m=SWEEP_RANGE_M,
                step_m=SWEEP_STEP_M,
            )
        ]
        for T in poses:
            judged.append(Judged("sweep", T, *check.judge(T, *TOLERANCE.free(thr))))
            log.debug("sweep pose at %s: %.3f", np.round(T[:3, 3], 2), judged[-1].score)
        sweep = {
            "kind": kind,
            "direction_target": [round(float(x), 3) for x in u],
            "range_m": SWEEP_RANGE_M,
            "step_m": SWEEP_STEP_M,
            "poses": len(poses),
        }
    answer = Judged(c.origin, W, *check.judge(W, *TOLERANCE.free(thr)))
    others = contenders(judged, judge, floor=0.0, size=SCREENED)
    players = [answer] + [j for j in others if judge.distinct(j.T_target_source, W)]
    players = screen(players, pair, thr)
    winner = tournament(players, pair, thr, judge)
    if winner is None and contradicted is not None:
        winner = rescue(contradicted, judged, W, pair, thr, judge)
    out = Coarse(
        c.origin,
        W,
        c.pairs,
        c.target_points,
        c.source_points,
        c.residuals2,
        c.inliers,
        judged,
        c.score,
    )
    if winner is not None and u is not None:
        # the cue alone fixes the position along the axis: place the winner on it
        T = place_along(winner.T_target_source, u, pair, thr, span_m=SWEEP_STEP_M)
        winner = Judged(winner.origin, T, *check.judge(T, *TOLERANCE.free(thr)))
    if winner is not None and (u is not None or judge.distinct(winner.T_target_source, W)):
        log.info("the tournament's winner (%s) is the answer", winner.origin)
        kt, ks = keypoints
        out = at_pose(winner.origin, winner.T_target_source, kt, ks, thr, judged, c.score)
    axis = u if winner is not None else None
    return Settlement(out, pair, sweep, len(players), winner is not None, axis)


__all__ = [
    "ACROSS_M",
    "ACROSS_STEP_M",
    "FACING_POINTS",
    "RESCUE_MAX_OPEN",
    "SCREENED",
    "SWEEP_PEAKS",
    "SWEEP_POINTS",
    "TOURNAMENT_SIZE",
    "TURN_DEG",
    "Settlement",
    "contenders",
    "explained_share",
    "half_turn",
    "open_share",
    "pin_along",
    "place_along",
    "repeat_direction",
    "rescue",
    "screen",
    "settle",
    "sweep_candidates",
    "tournament",
    "weak_direction",
]
