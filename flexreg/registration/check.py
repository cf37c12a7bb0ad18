"""The dense check: one instrument, one tolerance model.

A :class:`Check` holds one scan's view (its range image, what it measured, its range slack)
and the other scan's even sample, and classifies the sample under a pose
(:func:`~flexreg.stages.verification.classify_points`): *explained* where it lies on the
view's surfaces, *conflicting* where it lies clearly in front of what the scanner saw, in its
free space. :class:`TwoWay` holds both directions. Every judge of a registration (the
candidates, the settling, the refinement's guard, the evidence, the survey's map check)
measures with it, at the tolerances of one :class:`Tolerance`:

* the *fine* tolerance (half an inlier threshold plus 0.2 % of the range): what a pose
  explains;
* the *free-space* tolerance (2.5 inlier thresholds plus 1 % of the range): what it puts in
  open space, and the tolerance at which the candidates compete.

:func:`duel` compares two poses on their masks, of the samples (:func:`duel_masks`) or at
full resolution (:func:`~flexreg.registration.fullres.pose_masks`); :func:`decisive` and
:func:`decisive_full` say when a duel settles them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.transforms import invert
from flexreg.registration.config import (
    DECISIVE_SHARE,
    FULL_DECISIVE_POINTS,
    FULL_DECISIVE_SHARE,
    JudgeConfig,
)
from flexreg.stages.verification import classify_points, classify_points_at, soft_score
from flexreg.stages.viewpoint import one_viewpoint


@dataclass(frozen=True)
class Tolerance:
    """The tolerances of the dense check, in inlier thresholds and fractions of the range.

    Attributes
    ----------
    fine_rel : float
        Relative range tolerance of the fine check (fraction of the range); its absolute
        part is half an inlier threshold.
    free_k : float
        The free-space tolerance in inlier thresholds.
    free_rel : float
        Its relative range part (fraction of the range).

    Examples
    --------
    >>> TOLERANCE.fine(0.04), TOLERANCE.free(0.04)
    ((0.02, 0.002), (0.1, 0.01))
    """

    fine_rel: float = 0.002
    free_k: float = 2.5
    free_rel: float = 0.01

    def fine(self, threshold_m: float) -> tuple[float, float]:
        """The fine tolerance at inlier threshold ``threshold_m``: (metres, fraction of the
        range)."""
        return threshold_m / 2, self.fine_rel

    def free(self, threshold_m: float) -> tuple[float, float]:
        """The free-space tolerance at inlier threshold ``threshold_m``: (metres, fraction of
        the range)."""
        return self.free_k * threshold_m, self.free_rel


#: the tolerances every dense check of flexreg uses
TOLERANCE = Tolerance()

#: per direction (source in the target's view, target in the source's), which points a pose
#: explains and which it puts in the other scanner's free space: (N,) bool each
Masks = tuple[tuple[NDArray[np.bool_], NDArray[np.bool_]], ...]


@dataclass(frozen=True)
class Judged:
    """One candidate as the dense check at the coarse tolerance judged it.

    Attributes
    ----------
    origin : str
    T_target_source : (4, 4) float64
        The candidate after the quick local ICP (as given without polishing).
    score : float
        ``consistent - 3 conflicting`` (see :meth:`Check.judge`).
    consistent, conflicting : float
        Fractions of the source's sample.
    """

    origin: str
    T_target_source: NDArray[np.float64]
    score: float
    consistent: float
    conflicting: float


@dataclass(eq=False)
class Check:
    """The dense check of candidates: the target's view and the source's even sample.

    Attributes
    ----------
    view : RangeImage
        The target's range image with a camera model.
    measured, slack : (H, W) float32
        Its :func:`~flexreg.stages.verification.measured_image` and
        :func:`~flexreg.stages.verification.range_slack`.
    sample : (N, 3) float64
        The source's points spread evenly over its surfaces.
    hidden : float or None
        The share of the target cloud's points hidden behind its own from its origin
        (:func:`~flexreg.stages.viewpoint.hidden_share`; None: a grid). A cloud not taken
        from one point (:func:`~flexreg.stages.viewpoint.one_viewpoint`) tells no open space:
        no sampled point conflicts with its view.
    witnesses : (H, W) bool or None
        The pixels whose footprint's range is bounded: :func:`check_masks` judges only the
        points that fall on them (:func:`~flexreg.stages.verification.open_space_witnesses`;
        None: every pixel). The map check sets them; a registration's own checks do not.
    """

    view: RangeImage
    measured: NDArray[np.float32]
    slack: NDArray[np.float32]
    sample: NDArray[np.float64]
    hidden: float | None = None
    witnesses: NDArray[np.bool_] | None = None

    @property
    def free_space(self) -> bool:
        """Whether the view's open space is known (the target was taken from one point)."""
        return one_viewpoint(self.hidden)

    def classify(
        self, T: NDArray[np.float64], tol: float, rel: float
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
        """The sample in the target frame, and which points are consistent / conflicting."""
        q, ok, bad = classify_points(self.view, self.sample, T, tol, rel, self.slack, self.measured)
        return q, ok, bad if self.free_space else np.zeros_like(bad)

    def judge(self, T: NDArray[np.float64], tol: float, rel: float) -> tuple[float, float, float]:
        """``consistent - 3 conflicting`` (conflicts are strong evidence), and both."""
        _, ok_, bad_ = self.classify(T, tol, rel)
        ok, bad = float(ok_.mean()), float(bad_.mean())
        return ok - 3 * bad, ok, bad


@dataclass(eq=False)
class TwoWay:
    """Checks of a transform in both directions: the source's sample in the target's view
    (``forward``) and the target's sample in the source's view (``backward``)."""

    forward: Check
    backward: Check

    def score(self, T: NDArray[np.float64], tol: float) -> Scored:
        """:func:`~flexreg.stages.verification.soft_score` of both directions at ``tol``
        (metres, plus 0.2% of the range)."""
        f = self._soft(self.forward, T, tol)
        return Scored(T, tol, f, self._soft(self.backward, invert(T), tol))

    @staticmethod
    def _soft(c: Check, T: NDArray[np.float64], tol: float) -> Any:
        return soft_score(
            c.view,
            c.sample,
            T,
            tol,
            TOLERANCE.fine_rel,
            c.slack,
            c.measured,
            open_space=c.free_space,
        )


@dataclass(eq=False)
class Scored:
    """A transform scored in both directions (see :meth:`TwoWay.score`)."""

    T: NDArray[np.float64]
    tolerance_m: float
    forward: tuple[float, NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]
    backward: tuple[float, NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]

    @property
    def value(self) -> float:
        """The mean score of both directions."""
        return 0.5 * (self.forward[0] + self.backward[0])


def duel_masks(two: TwoWay, T: NDArray[np.float64], threshold_m: float) -> Masks:
    """Per direction (source in the target's view, target in the source's), which sampled
    points a pose explains (fine tolerance: half an inlier threshold plus 0.2 %) and which it
    puts in the other scanner's free space (:meth:`Tolerance.free`: 2.5 inlier thresholds
    plus 1 %): the inputs of :func:`duel`.

    Parameters
    ----------
    two : TwoWay
    T : (4, 4) float64
        A ``T_target_source``.
    threshold_m : float, metres
        The registration's inlier threshold.

    Returns
    -------
    ((explained, conflicting), (explained, conflicting))
        (N,) bool masks of the forward and the backward sample.
    """
    return tuple(
        check_masks(check, TT, threshold_m)
        for check, TT in ((two.forward, T), (two.backward, invert(T)))
    )


def check_masks(
    check: Check, T: NDArray[np.float64], threshold_m: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """One direction of :func:`duel_masks`: which of the check's sample ``T`` puts on the
    view's surfaces (half an inlier threshold plus 0.2 %) and which in its free space
    (:meth:`Tolerance.free`: 2.5 inlier thresholds plus 1 %); (N,) bool each. With the
    check's ``witnesses``, points at other pixels are neither."""
    (explained, _), (_, free) = classify_points_at(
        check.view,
        check.sample,
        T,
        [TOLERANCE.fine(threshold_m), TOLERANCE.free(threshold_m)],
        check.slack,
        check.measured,
        check.witnesses,
    )
    return explained, free if check.free_space else np.zeros_like(free)


def duel(A: Masks, B: Masks) -> tuple[float, float]:
    """Direct evidence between two poses of the same pair (their :func:`duel_masks`): the
    share of both scans' samples that ``A`` explains and ``B`` puts in the other scanner's
    free space, and the reverse.

    A symmetric room or repeating bays give both poses the same surfaces to fit, so overall
    scores tie; a unique object (a cue) fits under the right pose and lands in open space
    under the other.

    Returns
    -------
    won, lost : float
        Shares (of all sampled points of both directions) that favour ``A`` and ``B``.
    """
    won = sum(int((okA & badB).sum()) for (okA, _), (_, badB) in zip(A, B, strict=True))
    lost = sum(int((okB & badA).sum()) for (_, badA), (okB, _) in zip(A, B, strict=True))
    n = sum(len(ok) for ok, _ in A)
    return (won / n, lost / n) if n else (0.0, 0.0)


def decisive(won: float, lost: float, judge: JudgeConfig) -> bool:
    """Whether :func:`duel` shares ``won`` against ``lost`` settle two poses (see
    :data:`~flexreg.registration.config.DECISIVE_SHARE` and ``judge.decisive_ratio``)."""
    return won - lost >= DECISIVE_SHARE and won >= judge.decisive_ratio * lost


def decisive_full(won: float, lost: float, judge: JudgeConfig, *, points: int = 0) -> bool:
    """Whether full-resolution :func:`duel` shares (:mod:`flexreg.registration.fullres`)
    settle two poses: ``won >= judge.decisive_ratio * lost`` and a lead ``won - lost`` of
    at least ``FULL_DECISIVE_SHARE`` of the points, or, given the number of
    ``points`` checked, of at least ``FULL_DECISIVE_POINTS`` points.

    The share scales with the scans; a small cue does not (a forklift seen two bays away
    leads by 13-53 points of 850 000 at 1024 x 512, less than the share's 85), while the
    duels of empty tunnels, arcades and rooms leave 0-2 points either way: a count floor
    between them with the ratio settles the cue and leaves the empty scenes open.

    >>> judge = JudgeConfig()
    >>> decisive_full(0.0005, 0.0, judge), decisive_full(0.00005, 0.0, judge)
    (True, False)
    >>> decisive_full(0.0006, 0.0003, judge)
    False
    >>> n = 850_000  # 17 points against none, and 17 against 6 (not 3 : 1)
    >>> decisive_full(17 / n, 0.0, judge, points=n), decisive_full(17 / n, 6 / n, judge, points=n)
    (True, False)
    >>> decisive_full(2 / n, 0.0, judge, points=n)
    False
    """
    if won < judge.decisive_ratio * lost:
        return False
    lead = won - lost
    if lead >= FULL_DECISIVE_SHARE:
        return True
    floor = FULL_DECISIVE_POINTS
    return points > 0 and floor > 0 and lead * points >= floor - 1e-6


__all__ = [
    "TOLERANCE",
    "Check",
    "Judged",
    "Masks",
    "Scored",
    "Tolerance",
    "TwoWay",
    "check_masks",
    "decisive",
    "decisive_full",
    "duel",
    "duel_masks",
]
