"""Choosing the coarse transform: every prior and its keypoint refinement compete on the dense
free-space check.

Priors come from global descriptor matching and from plan-view overlays. Each is refined by
guided matching (:func:`flexreg.stages.alignment.guided_fit`); the candidates are judged, after
a quick local ICP (:func:`polisher`), by the share of the source's even sample that the target's
view confirms minus three times the share it contradicts
(:func:`flexreg.stages.verification.classify_points`): first the best prior family at a coarse
tolerance (a wrong model puts the source in the target's free space), then its most precise
member at a fine tolerance.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import fft, ndimage

from flexreg.core.kept import Kept, digest
from flexreg.core.range_image import RangeImage
from flexreg.core.transforms import (
    invert,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import DegenerateGeometryError, RegistrationError
from flexreg.registration.check import TOLERANCE, Check, Judged
from flexreg.registration.config import JudgeConfig, RegistrationConfig
from flexreg.stages.alignment import (
    COLLINEAR_RATIO,
    Window,
    guided_fit,
    spread_ratio,
    squared_residuals,
)
from flexreg.stages.keypoints import Features
from flexreg.stages.matching import match_guided
from flexreg.stages.priors import PlanView, TopView, match_top_views
from flexreg.stages.refinement.projective import projective_icp

log = logging.getLogger(__name__)

#: a candidate: (origin, T_target_source); origin is "plan", "descriptors" or "init" (a
#: given T_target_source), with "+keypoints" when refined by guided matching
Candidate = tuple[str, NDArray[np.float64]]

#: priors that stay candidates themselves (judged by the dense check alone, not needing
#: keypoint inliers): plan-view overlays, a given initial transform and the aliases of the
#: best prior (:func:`alias_candidates`), and the poses slid along a weak axis or a repeat
#: (:mod:`flexreg.registration.settle`) or slid along the walls from an answer refuted in
#: open space (:func:`flexreg.registration.twins.slide_refuted`), and the geometric route's
#: FPFH hypotheses (:mod:`flexreg.registration.geometric`)
DENSE_PRIORS = ("plan", "window-plan", "init", "alias", "sweep", "slide", "geometric")

#: the prior polished from afar (:func:`polisher`, ``wide``): a plan overlay inside a rough
#: prior's window, which a look-alike elsewhere did not outscore
WIDE_PRIOR = "window-plan"

#: most turns and most shifts of a plan view kept as its symmetries (:func:`self_symmetries`),
#: and the smallest share of the identity's overlay score they must reach
SYMMETRIES, SYMMETRY_SHARE = 3, 0.5

#: ... and of a pure shift (a corridor or a row of bays overlays itself shifted along its
#: length wherever it is seen, so a shift's share decays with the distance)
SHIFT_SHARE = 0.3

#: distinct judged candidates whose offset from the winner is tried the other way round
ALIAS_OFFSETS = 1


def require_inliers(c: Coarse, thr: float, min_inliers: int, counts: str) -> None:
    """A coarse transform fitted to keypoints needs at least ``max(3, min_inliers)`` inliers
    within ``thr`` metres, not on one line (a dense prior carries its pose without them).

    Raises
    ------
    RegistrationError
        Too few or collinear inliers; ``counts`` (keypoints and matches) is in the message.
    """
    if dense_prior(c.origin):
        return
    inl = c.inliers
    if inl.sum() < max(3, min_inliers):
        raise RegistrationError(
            f"only {int(inl.sum())} inliers within {thr:.3g} m (need "
            f"{max(3, min_inliers)}); {counts}"
        )
    if spread_ratio(c.source_points[inl]) < COLLINEAR_RATIO:
        raise RegistrationError(f"the {int(inl.sum())} inliers are collinear")


def dense_prior(origin: str) -> bool:
    """Whether a candidate's origin is a :data:`DENSE_PRIORS` prior (refined or not)."""
    return origin.split("+")[0] in DENSE_PRIORS


@dataclass(eq=False)
class Keypoints3D:
    """Keypoints and descriptors of one scan and their lifted 3D points.

    Attributes
    ----------
    features : Features
    points : (K, 3) float64, metres
        NaN where a keypoint could not be lifted.
    lifted : (K,) bool
    """

    features: Features
    points: NDArray[np.float64]
    lifted: NDArray[np.bool_]


@dataclass(eq=False)
class Coarse:
    """The chosen coarse transform and its final guided matches.

    Attributes
    ----------
    origin : str
    T_target_source : (4, 4) float64
    pairs : (Q, 2) int64
        Final guided matches (target, source keypoint).
    target_points, source_points : (Q, 3) float64
        Their lifted points.
    residuals2 : (Q,) float64
        Squared residuals under ``T_target_source``, square metres.
    inliers : (Q,) bool
        Within the inlier threshold.
    judged : list of Judged
        Every candidate as the dense check judged it (the runner-ups come from here).
    score : float
        The winner's score in that check.
    """

    origin: str
    T_target_source: NDArray[np.float64]
    pairs: NDArray[np.int64]
    target_points: NDArray[np.float64]
    source_points: NDArray[np.float64]
    residuals2: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    judged: list[Judged] = field(default_factory=list)
    score: float = float("nan")


def polisher(
    target: RangeImage,
    normals: NDArray[np.float32],
    sample: NDArray[np.float64],
    thr: float,
    wide_m: float = 0.5,
) -> Callable[..., NDArray[np.float64]]:
    """A quick local ICP of a small even sample of the source (``sample``, about 5000 points)
    against the target's range image (projective,
    :func:`flexreg.stages.refinement.projective.projective_icp`), for judging candidates.

    ``polish(T)`` associates within ``3 thr``; ``polish(T, wide=True)`` first within
    ``wide_m`` and then half as far each round down to it, for a candidate known only to
    that accuracy (a plan overlay inside a rough prior's window: about a plan cell, so
    ``wide_m`` is two plan cells).

    ``target`` must have a camera model; ``normals`` are its
    :func:`~flexreg.stages.normals.grid_normals`."""

    def icp(T: NDArray[np.float64], d: float) -> NDArray[np.float64]:
        try:
            r = projective_icp(
                target,
                sample,
                T,
                max_distance_m=d,
                normals=normals,
                max_iterations=15,
                tolerance=1e-4,
            )
        except RegistrationError:
            return T
        return r.T_target_source

    def polish(T: NDArray[np.float64], wide: bool = False) -> NDArray[np.float64]:
        d = wide_m if wide else 3 * thr
        while d > 3 * thr:
            T = icp(T, d)
            d /= 2
        return icp(T, 3 * thr)

    return polish


def _guided(
    kt: Keypoints3D,
    ks: Keypoints3D,
    T0: NDArray[np.float64],
    thr: float,
    config: RegistrationConfig,
) -> tuple[NDArray[np.float64], int] | None:
    """:func:`~flexreg.stages.alignment.guided_fit` around ``T0``: its transform and inliers;
    None when there is none, or when its matches are degenerate (three collinear inliers of
    a tunnel against an arcade at 2048 x 1024 ended the whole registration there)."""
    try:
        fit = guided_fit(
            kt.features,
            ks.features,
            kt.points,
            ks.points,
            T0,
            threshold_m=thr,
            radius_m=config.prior.guided_radius_m,
            radius_per_m=config.prior.guided_radius_per_m,
        )
    except DegenerateGeometryError as e:
        log.debug("guided fit around a prior skipped: %s", e)
        return None
    return None if fit is None else (fit.T_target_source, int(fit.inliers.sum()))


def families(
    priors: list[Candidate],
    kt: Keypoints3D,
    ks: Keypoints3D,
    thr: float,
    config: RegistrationConfig,
) -> list[list[Candidate]]:
    """Each prior with its keypoint-refined version (plan and init priors stay candidates
    themselves; a descriptor prior only through its refinement)."""
    out = []
    for origin, T0 in priors:
        fam = [(origin, T0)] if dense_prior(origin) else []
        est = _guided(kt, ks, T0, thr, config)
        if est is not None and est[1] >= max(3, config.min_inliers):
            fam.append((f"{origin}+keypoints", est[0]))
        if fam:
            out.append(fam)
    return out


def _best_family(
    fams: list[list[Candidate]],
    check: Check,
    polish: Callable[..., NDArray[np.float64]] | None,
    thr: float,
    window: Window | None = None,
) -> tuple[int, tuple[float, float], NDArray[np.float64] | None, list[Judged], float]:
    """Index of the winning family (-1 when none), its (consistent, conflicting) fractions,
    its polished transform (None without polishing), every candidate as judged, and the
    winner's score. With a rough prior's ``window`` only a candidate that ends inside it can
    win; every one is judged (the verdict duels the answer against them all)."""
    judged = []  # (score, moved, family, consistent, conflicting, polished T)
    seen = []
    for i, fam in enumerate(fams):
        for origin, T in fam:
            # judged after a quick local ICP: a right but rough candidate improves, a wrong one
            # stays wrong
            Tj = polish(T, wide=origin == WIDE_PRIOR) if polish is not None else T
            score, ok, bad = check.judge(Tj, *TOLERANCE.free(thr))
            moved = translation_error_m(Tj, T) / thr + rotation_error_deg(Tj, T)
            log.info("%s: overlap %.3f, conflict %.3f, moved %.2f", origin, ok, bad, moved)
            judged.append((score, moved, i, ok, bad, Tj))
            seen.append(Judged(origin, Tj, score, ok, bad))
    if window is not None:
        judged = [j for j in judged if window.contains(j[5])[0]]
    if not judged:
        return -1, (0.0, 0.0), None, seen, float("nan")
    top = max(j[0] for j in judged)
    # candidates that end in the same place score alike: take the one that was already there
    # (moved least under the quick ICP)
    _, _, best, ok, bad, Tj = min((j for j in judged if j[0] >= top - 0.01), key=lambda j: j[1])
    return best, (ok, bad), Tj if polish is not None else None, seen, top


def _shifts(
    plan: TopView, count: int, min_share: float, min_shift_m: float
) -> list[tuple[float, float]]:
    """The best horizontal shifts (metres) that overlay a plan onto itself: peaks of its
    autocorrelation at least ``min_share`` of the centre's and ``min_shift_m`` away from it."""
    c = plan.cells - plan.cells.min(axis=0)
    h, w = int(c[:, 1].max()) + 1, int(c[:, 0].max()) + 1
    shape = (fft.next_fast_len(2 * h, real=True), fft.next_fast_len(2 * w, real=True))
    grid = np.zeros(shape)
    np.add.at(grid, (c[:, 1], c[:, 0]), plan.values)
    f = fft.rfft2(grid)
    auto = fft.fftshift(fft.irfft2(f * np.conj(f), s=shape))
    centre = np.array(shape) // 2
    top = float(auto[tuple(centre)])
    if top <= 0:
        return []
    iy, ix = np.mgrid[0 : shape[0], 0 : shape[1]]
    dist = np.hypot(iy - centre[0], ix - centre[1]) * plan.cell_m
    peak = (auto == ndimage.maximum_filter(auto, size=5)) & (auto >= min_share * top)
    peak &= dist >= min_shift_m
    ys, xs = np.nonzero(peak)
    order = np.argsort(-auto[ys, xs], kind="stable")[:count]
    return [
        (float(xs[k] - centre[1]) * plan.cell_m, float(ys[k] - centre[0]) * plan.cell_m)
        for k in order
    ]


def self_symmetries(
    plan: PlanView | str | None,
    *,
    count: int = SYMMETRIES,
    min_share: float = SYMMETRY_SHARE,
    min_shift_share: float = SHIFT_SHARE,
) -> list[NDArray[np.float64]]:
    """Poses other than the identity that overlay a levelled scan's plan view onto itself
    (identical rooms, repeating bays, a symmetric hall), in the scan's frame.

    A pose ``T`` that puts the source into one of two identical parts of the target's view
    has a twin ``S @ T`` for each such symmetry ``S`` of the target (and ``T @ S'`` for a
    symmetry ``S'`` of the source): :func:`alias_candidates` tries them. Turns come from
    overlaying the plan onto itself over yaw (:func:`~flexreg.stages.priors.match_top_views`),
    shifts from the peaks of its autocorrelation; only those overlaying at least
    ``min_share`` (shifts: ``min_shift_share``) of what the identity overlays count (an
    ordinary room has none). The last :data:`KEEP_SYMMETRIES` plan views' are kept by
    content (a survey station takes part in a dozen links): later calls return the same
    read-only arrays.

    Parameters
    ----------
    plan : PlanView, str or None
        :func:`~flexreg.stages.priors.plan_view` of the scan (a str or None: no plan view,
        no symmetries).
    count : int
        Most turns and most shifts returned (each).
    min_share, min_shift_share : float
        Smallest overlay score of a turn and of a pure shift, as a fraction of the
        identity's.

    Returns
    -------
    list of (4, 4) float64
        ``T_scan_scan`` transforms (rotation about the vertical and a horizontal shift in the
        levelled frame, expressed in the scanner frame): the turns, then the shifts.
    """
    if not isinstance(plan, PlanView):
        return []
    key = (_plan_key(plan), count, min_share, min_shift_share)
    return list(
        _SYMMETRIES.get(
            key, lambda: _frozen(_self_symmetries(plan, count, min_share, min_shift_share))
        )
    )


def _frozen(moves: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    for S in moves:
        S.flags.writeable = False  # shared by every pair of this scan
    return moves


#: plan views whose :func:`self_symmetries` are kept (by content: a survey worker loads a
#: station again for each of its dozen links, each of which asked for them anew, a third of
#: a typical link's time)
KEEP_SYMMETRIES = 256
_SYMMETRIES: Kept[list[NDArray[np.float64]]] = Kept(KEEP_SYMMETRIES)


def _plan_key(plan: PlanView) -> bytes:
    """A digest of everything :func:`self_symmetries` reads of a plan view."""
    c = plan.coarse
    return digest(
        c.cells, c.values, c.xy, c.heights, plan.levelling.R_level, [c.cell_m, c.z0_m, c.dz_m]
    )


def _self_symmetries(
    plan: PlanView, count: int, min_share: float, min_shift_share: float
) -> list[NDArray[np.float64]]:
    matches = match_top_views(
        plan.coarse,
        plan.coarse,
        yaw_step_rad=math.radians(2.0),
        top_k=count + 1,
        coarse_candidates=6,
    )
    top = max((m.score for m in matches), default=0.0)
    moves = [
        (m.yaw_rad, m.t_xy)
        for m in matches
        if m.score >= min_share * top
        and not (abs(m.yaw_rad) < math.radians(5.0) and math.hypot(*m.t_xy) < 1.0)
    ][:count]
    moves += [(0.0, t) for t in _shifts(plan.coarse, count, min_shift_share, 1.0)]
    L = np.eye(4)
    L[:3, :3] = plan.levelling.R_level
    out = []
    for yaw, (tx, ty) in moves:
        M = np.eye(4)
        M[:3, :3] = rotation_about_axis([0.0, 0.0, 1.0], yaw)
        M[:3, 3] = (tx, ty, 0.0)
        out.append(invert(L) @ M @ L)
    return out


@dataclass(frozen=True)
class Aliases:
    """Symmetries of both scans' plan views (:func:`self_symmetries`).

    Attributes
    ----------
    target, source : list of (4, 4) float64
        ``T_target_target`` and ``T_source_source`` self-overlays.
    up : (3,) float64 or None
        The target's vertical (unit, target frame) from its plan view's levelling.
    """

    target: list[NDArray[np.float64]] = field(default_factory=list)
    source: list[NDArray[np.float64]] = field(default_factory=list)
    up: NDArray[np.float64] | None = None


def alias_candidates(
    W: NDArray[np.float64],
    judged: list[Judged],
    aliases: Aliases | None,
    judge: JudgeConfig,
) -> list[Candidate]:
    """The twins of the winning pose ``W`` in repeating structure: ``W`` moved by each
    symmetry of the target's view (``S @ W``) and of the source's (``W @ S'``), and by the
    offset from ``W`` to each of the :data:`ALIAS_OFFSETS` best clearly different candidates,
    the other way round (``inv(D) @ W`` with ``D = J @ inv(W)``): when the best prior fell one
    bay or module beside the truth and another one bay beyond it, the truth is among them.

    Parameters
    ----------
    W : (4, 4) float64
        The winning ``T_target_source``.
    judged : list of Judged
        Every candidate as judged.
    aliases : Aliases or None
    judge : JudgeConfig
        What counts as a different pose (:meth:`JudgeConfig.distinct`).

    Returns
    -------
    list of Candidate
        Origin ``"alias"``.
    """
    out: list[Candidate] = []
    if aliases is not None:
        out += [("alias", S @ W) for S in aliases.target]
        out += [("alias", W @ S) for S in aliases.source]
    far = [
        j for j in sorted(judged, key=lambda j: -j.score) if judge.distinct(j.T_target_source, W)
    ]
    for j in far[:ALIAS_OFFSETS]:
        D = j.T_target_source @ invert(W)
        out.append(("alias", invert(D) @ W))
    return out


def choose(
    priors: list[Candidate],
    kt: Keypoints3D,
    ks: Keypoints3D,
    check: Check,
    polish: Callable[..., NDArray[np.float64]] | None,
    thr: float,
    config: RegistrationConfig,
    counts: str,
    notes: list[str],
    aliases: Aliases | None = None,
    window: Window | None = None,
) -> Coarse:
    """The coarse transform: the best prior family at a coarse tolerance, then its most
    precise member (with the keypoint estimate around the polished winner) at ``thr / 2``.

    ``counts`` (keypoints and descriptor matches) and ``notes`` (why a route gave no prior)
    end the error messages. The twins of the best prior in repeating structure
    (:func:`alias_candidates` of ``aliases``) then compete too: one that scores better takes
    its place, and all are judged (the verdict duels the answer against them). With a rough
    prior's ``window`` only a candidate inside it can be the answer; all are judged.

    Raises
    ------
    RegistrationError
        No candidate, or the best explains less than ``config.min_overlap`` of the source's
        sample or contradicts more than half of what it explains.
    """
    fams = families(priors, kt, ks, thr, config)
    best, (ok, bad), polished, judged, top = _best_family(fams, check, polish, thr, window)
    if best < 0:
        raise RegistrationError(
            f"no transform found: {counts}, {len(priors)} priors"
            + (f"; {'; '.join(notes)}" if notes else "")
        )
    if config.judge.runs("aliases") and not config.icp_only:
        W = polished if polished is not None else fams[best][0][1]
        twins = alias_candidates(
            W,
            judged,
            aliases,
            config.judge,
        )
        b2, okbad2, pol2, judged2, top2 = _best_family(
            [[c] for c in twins], check, polish, thr, window
        )
        judged = judged + judged2
        if b2 >= 0 and top2 > top + 0.01:
            log.info("an alias of the best prior scores better: %.3f > %.3f", top2, top)
            fams.append([twins[b2]])
            best, (ok, bad), polished, top = len(fams) - 1, okbad2, pol2, top2
    if ok < config.min_overlap or bad > 0.5 * ok:
        raise RegistrationError(
            f"no overlap: the best transform explains {100 * ok:.1f}% of the source's sampled "
            f"points and contradicts {100 * bad:.1f}% (need {100 * config.min_overlap:.0f}%); "
            f"{counts}" + (f"; {'; '.join(notes)}" if notes else "")
        )
    finalists = list(fams[best])
    if polished is not None and fams[best][0][0] == WIDE_PRIOR:
        # polished from afar, it is the candidate: the plan overlay itself is a cell off
        finalists.append((WIDE_PRIOR, polished))
    if polished is not None:
        # the keypoint estimate around the polished winner: a candidate that was far off but
        # converged under the quick ICP still gets a feature-based coarse transform
        est = _guided(kt, ks, polished, thr, config)
        if est is not None and est[1] >= 3:
            finalists.append((f"{finalists[0][0].split('+')[0]}+keypoints", est[0]))
    origin, T = max(finalists, key=lambda c: check.judge(c[1], *TOLERANCE.fine(thr))[0])
    return at_pose(origin, T, kt, ks, thr, judged, top)


def at_pose(
    origin: str,
    T: NDArray[np.float64],
    kt: Keypoints3D,
    ks: Keypoints3D,
    thr: float,
    judged: list[Judged],
    score: float,
) -> Coarse:
    """The :class:`Coarse` result at pose ``T``: its final guided matches (within twice the
    inlier threshold plus 0.2 % of range), their residuals and inliers."""
    fin = match_guided(
        kt.features, ks.features, kt.points, ks.points, T, radius_m=2 * thr, radius_per_m=0.002
    )
    pt, ps = kt.points[fin[:, 0]], ks.points[fin[:, 1]]
    d2 = squared_residuals(T, pt, ps)
    return Coarse(origin, T, fin, pt, ps, d2, d2 < thr * thr, judged, score)


__all__ = [
    "ALIAS_OFFSETS",
    "KEEP_SYMMETRIES",
    "SHIFT_SHARE",
    "SYMMETRIES",
    "SYMMETRY_SHARE",
    "Aliases",
    "Candidate",
    "Coarse",
    "Keypoints3D",
    "alias_candidates",
    "at_pose",
    "choose",
    "dense_prior",
    "families",
    "polisher",
    "self_symmetries",
]
