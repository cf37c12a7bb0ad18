"""Whole-shift twins: would the answer, moved along the hall, fit as well?

In a hall of identical bays (a warehouse's racks, an arcade, a car park) a pairwise answer
several bays off overlays identical structure: at full resolution it explains most points and
puts none in open space, exactly as the truth does, which lies a few bays away where the two
scans overlap less (docs/survey.md, "halls of identical bays"). No test of the answer alone
can refuse it; what gives it away is that the answer *moved by a bay* fits too.

:func:`find_twins` looks for such moves without knowing the bay. The source's points, placed
by the answer, are slid along the target's two horizontal wall directions
(:func:`horizontal_axes`) within ``range_m`` in ``step_m`` steps and checked at full
resolution on a sample (:func:`~flexreg.registration.fullres.full_scores`, coarse): the
slid poses that put least in open space nearby and explain most, at least
:data:`MIN_SHIFT_M` away, are polished by the quick ICP and checked on both scans
(explained and open-space shares of a sample each way,
:func:`~flexreg.registration.fullres.full_masks`). The verdict
(:func:`flexreg.registration.verdict.decide`, ``ambiguous``) then calls the answer ambiguous
when a twin *fits* (it puts at most ``judge.twin_fit_open`` of the points in open space, or
twice what the answer does) and explains at least ``TWIN_MIN_RATIO`` of what the
answer explains: two poses a whole bay apart that both fit are two answers, and the larger
overlap of one is no evidence for it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from flexreg.core.transforms import invert
from flexreg.registration.check import TOLERANCE, Check, Judged, Masks, duel
from flexreg.registration.config import (
    SWEEP_RANGE_M,
    TWIN_MIN_RATIO,
    TWIN_RANGE_M,
    TWIN_STEP_M,
    TWIN_STRONG_RATIO,
    JudgeConfig,
)
from flexreg.registration.fullres import (
    FullPair,
    FullView,
    full_masks,
    full_scores,
    pose_masks,
)
from flexreg.registration.settle import rescue

log = logging.getLogger(__name__)

#: source points scored per slid pose (every k-th point of its full view)
SWEEP_POINTS = 8_000

#: points of each scan checked per twin (every k-th point of its full view)
CHECK_POINTS = 20_000

#: best local maxima of each axis's sweep that are polished and checked
PEAKS = 4

#: a twin is at least this far from the answer, metres (nearer: the same pose, polished)
MIN_SHIFT_M = 1.0

#: a wall direction within this many degrees of the settling's swept axis is not slid
SETTLED_DEG = 15.0

#: normals used to find the wall directions (every k-th of the view's)
AXIS_NORMALS = 50_000


def horizontal_axes(view: FullView, up: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """The two horizontal directions of a scan's walls (unit, the scan's frame).

    The horizontal parts of the normals of its vertical surfaces (normals within about 25
    degrees of horizontal) vote for an orientation modulo 90 degrees (the mean of
    ``exp(4i angle)``): the first direction is the dominant wall normal, the second is
    square to it and to ``up``. Racks, aisles and corridors run along one of them.

    Parameters
    ----------
    view : FullView
    up : (3,) float64
        The vertical, the scan's frame.

    Returns
    -------
    list of two (3,) float64, or [] when the scan shows no vertical surface

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> n = np.array([[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)
    >>> a, b = horizontal_axes(SimpleNamespace(normals=n), np.array([0.0, 0.0, 1.0]))
    >>> np.round(np.abs(a), 3).tolist(), round(float(abs(a @ b)), 6)
    ([0.6, 0.8, 0.0], 0.0)
    """
    u = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    n = np.asarray(view.normals, dtype=np.float64)
    n = n[:: max(1, -(-len(n) // AXIS_NORMALS))]
    n = n[np.isfinite(n).all(axis=1)]
    h = n - np.outer(n @ u, u)
    w = np.linalg.norm(h, axis=1)
    h = h[w > 0.9] / w[w > 0.9, None]
    if len(h) == 0:
        return []
    e1 = np.cross(u, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 0.1:
        e1 = np.cross(u, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    angle = np.angle(np.exp(4j * np.arctan2(h @ e2, h @ e1)).mean()) / 4
    a = math.cos(angle) * e1 + math.sin(angle) * e2
    return [a, np.cross(u, a)]


def _every(n: int, most: int) -> int:
    return max(1, -(-n // most))


def shares(pair: FullPair, T: NDArray[np.float64], threshold_m: float) -> tuple[float, float]:
    """The shares of both scans' points (every k-th, :data:`CHECK_POINTS` each way) that the
    pose ``T`` explains and puts in open space
    (:func:`~flexreg.registration.fullres.full_masks`)."""
    s, t = pair.source, pair.target
    ks, kt = _every(len(s.points), CHECK_POINTS), _every(len(t.points), CHECK_POINTS)
    ps, pss, psn = s.take(np.s_[::ks])
    pt, pts, ptn = t.take(np.s_[::kt])
    fe, fo = full_masks(t, ps, pss, T, threshold_m, normals=psn)
    be, bo = full_masks(s, pt, pts, invert(T), threshold_m, normals=ptn)
    n = len(fe) + len(be)
    if n == 0:
        return 0.0, 0.0
    return (int(fe.sum()) + int(be.sum())) / n, (int(fo.sum()) + int(bo.sum())) / n


#: an unpolished slid pose is a candidate when it puts at most this share of the sampled
#: points in open space (a whole bay off, a step from the truth, the uprights' faces stand
#: up to half a step in front of what the other scanner saw)
SWEEP_OPEN = 0.01


def _candidates(
    explained: NDArray[np.float64],
    opens: NDArray[np.float64],
    offsets: NDArray[np.float64],
    answer_factor: float = 2.0,
) -> list[int]:
    """Indices of the slid poses worth polishing: the local minima of the open-space share
    (over two steps either way) at most :data:`SWEEP_OPEN` (or ``answer_factor`` times the
    answer's, at offset 0) and at
    least :data:`MIN_SHIFT_M` from the answer, the :data:`PEAKS` that explain most, each
    more than two steps from a better one. Along a hall the explained share falls steadily
    with the distance from the answer (the scans overlap less), so its peaks miss the bays;
    the open space drops to nothing at each bay, where the uprights fit again."""
    centre = int(np.argmin(np.abs(offsets)))
    limit = max(SWEEP_OPEN, answer_factor * float(opens[centre]))
    low = opens == ndimage.minimum_filter1d(opens, size=5, mode="nearest")
    idx = np.flatnonzero(low & (opens <= limit) & (np.abs(offsets) >= MIN_SHIFT_M))
    out: list[int] = []
    for i in sorted(idx.tolist(), key=lambda i: (-explained[i], i)):
        if all(abs(i - k) > 2 for k in out):
            out.append(i)
        if len(out) >= PEAKS:
            break
    return out


def _slides(
    pair: FullPair,
    T: NDArray[np.float64],
    axes: list[NDArray[np.float64]],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    threshold_m: float,
    offsets: NDArray[np.float64],
    answer_factor: float,
) -> Iterator[NDArray[np.float64]]:
    """``T`` slid by ``offsets`` (metres) along each of ``axes`` (target frame), scored on a
    sample of the source at full resolution: the :func:`_candidates` (open-space share at
    most :data:`SWEEP_OPEN`, or ``answer_factor`` times ``T``'s) polished, those that stay at least
    :data:`MIN_SHIFT_M` from ``T``."""
    s = pair.source
    k = _every(len(s.points), SWEEP_POINTS)
    pts, slack, normals = s.take(np.s_[::k])
    m = max(1, len(pts))
    for a in axes:
        opens = np.zeros(len(offsets), dtype=np.int64)
        scores = full_scores(
            pair.target, pts, slack, T, offsets[:, None] * a, threshold_m, coarse=True,
            normals=normals, open_counts=opens,
        )  # fmt: skip
        for i in _candidates((scores + 3.0 * opens) / m, opens / m, offsets, answer_factor):
            Tk = T.copy()
            Tk[:3, 3] += offsets[i] * a
            Tk = polish(Tk) if polish is not None else Tk
            if float(np.linalg.norm(Tk[:3, 3] - T[:3, 3])) >= MIN_SHIFT_M:
                yield Tk  # else polished back onto the answer


def find_twins(
    pair: FullPair,
    T: NDArray[np.float64],
    up: NDArray[np.float64],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    threshold_m: float,
    judge: JudgeConfig,
    settled_axis: NDArray[np.float64] | None = None,
    *,
    range_m: float = TWIN_RANGE_M,
    step_m: float = TWIN_STEP_M,
) -> dict[str, Any]:
    """The answer ``T`` slid along the target's wall directions: where else it fits.

    Parameters
    ----------
    pair : FullPair
        Both scans at full resolution.
    T : (4, 4) float64
        The answer, ``T_target_source``.
    up : (3,) float64
        The target's vertical (its frame).
    polish : callable or None
        The quick local ICP (:func:`~flexreg.registration.candidates.polisher`).
    threshold_m : float, metres
        The inlier threshold.
    judge : JudgeConfig
        A twin that fits (:attr:`~flexreg.registration.config.JudgeConfig.twin_fit_open`)
        and explains between :data:`~flexreg.registration.config.TWIN_MIN_RATIO` and
        :data:`~flexreg.registration.config.TWIN_STRONG_RATIO` of what the answer explains
        also duels the answer on every pixel of both scans
        (:func:`~flexreg.registration.check.duel`).
    settled_axis : (3,) float64, optional
        The direction (target frame) along which the settling swept the answer and placed
        it by a tournament it won at full resolution
        (:attr:`~flexreg.registration.settle.Settlement.axis`): every pose slid along it
        within 20 m, the truth's included, has lost a duel against the answer there (a niche
        in a tunnel, a forklift among identical bays), so the wall direction within
        :data:`SETTLED_DEG` of it is not slid again.
    range_m, step_m : float, metres
        How far either way and in which steps the answer is slid
        (:data:`~flexreg.registration.config.TWIN_RANGE_M`, ``TWIN_STEP_M``).

    Returns
    -------
    dict
        JSON-ready: ``axes_target`` (the two directions), ``range_m``, ``step_m``,
        ``answer`` and each of ``twins`` with ``explained_share`` and ``open_share`` (of both
        scans' checked points), each twin with its ``offset_m`` from the answer (target
        frame) and ``shift_m`` (its length), a dueled one also ``full_refuted_share`` and
        ``full_refuting_share`` (shares of ``full_points``); ``settled_axes_target``: the
        wall directions left out as settled.
    """
    axes: list[NDArray[np.float64]] = []
    settled: list[NDArray[np.float64]] = []
    for a in horizontal_axes(pair.target, up):
        along = settled_axis is not None and abs(float(a @ settled_axis)) >= math.cos(
            math.radians(SETTLED_DEG)
        ) * float(np.linalg.norm(settled_axis))
        (settled if along else axes).append(a)
    x0, o0 = shares(pair, T, threshold_m)
    n = math.floor(range_m / step_m)
    offsets: NDArray[np.float64] = np.arange(-n, n + 1, dtype=np.float64) * step_m
    twins: list[dict[str, Any]] = []
    limit = max(judge.twin_fit_open, 2.0 * o0)
    weak = (TWIN_MIN_RATIO * x0, TWIN_STRONG_RATIO * x0)
    answer: list[Masks] = []  # the answer's full-resolution masks, once a twin needs them
    for Tk in _slides(pair, T, axes, polish, threshold_m, offsets, 2.0):
        d = Tk[:3, 3] - T[:3, 3]
        x, o = shares(pair, Tk, threshold_m)
        twin: dict[str, Any] = {
            "offset_m": [round(float(v), 3) for v in d],
            "shift_m": round(float(np.linalg.norm(d)), 3),
            "explained_share": round(x, 5),
            "open_share": round(o, 6),
        }
        if o <= limit and weak[0] <= x < weak[1]:
            answer = answer or [pose_masks(pair, T, threshold_m)]
            won, lost = duel(answer[0], pose_masks(pair, Tk, threshold_m))
            twin |= {
                "full_refuted_share": round(won, 7),
                "full_refuting_share": round(lost, 7),
                "full_points": pair.points,
            }
        twins.append(twin)
    log.debug("twins of the answer: %s", twins)
    return {
        "axes_target": [[round(float(v), 4) for v in a] for a in axes],
        "settled_axes_target": [[round(float(v), 4) for v in a] for a in settled],
        "range_m": range_m,
        "step_m": step_m,
        "answer": {"explained_share": round(x0, 5), "open_share": round(o0, 6)},
        "twins": twins,
    }


def slide_refuted(
    pair: FullPair,
    W: NDArray[np.float64],
    up: NDArray[np.float64],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    check: Check,
    threshold_m: float,
    judge: JudgeConfig,
) -> Judged | None:
    """A pose for an answer ``W`` the verdict refutes in open space, or None.

    In a hall of identical bays a pairwise answer a bay or more off the truth overlays the
    racks of the wrong bays, and where the scans see different ends of the hall, it puts
    what one scanner saw where the other saw through (the truth, a bay or two away, puts
    nothing there). The answer is slid along the target's two wall directions
    (:func:`horizontal_axes`) over :data:`~flexreg.registration.config.SWEEP_RANGE_M`
    either way in :data:`~flexreg.registration.config.TWIN_STEP_M` steps; the slid poses
    where the open space drops to a local minimum of at most :data:`SWEEP_OPEN` are
    polished, those that explain less than half as much as the answer (slid out of the hall,
    clean only by seeing less) are dropped, and
    :func:`~flexreg.registration.settle.rescue` keeps the one that puts
    (almost) nothing in open space, beats the answer decisively at full resolution,
    explains at least half as much and leaves no other clean pose unbeaten. It is then
    judged as any answer is.

    Parameters
    ----------
    pair : FullPair
    W : (4, 4) float64
        The refuted answer, ``T_target_source``.
    up : (3,) float64
        The target's vertical (its frame).
    polish : callable or None
        The quick local ICP.
    check : Check
        The dense check (scores each slid pose as the candidates are scored).
    threshold_m : float, metres
    judge : JudgeConfig

    Returns
    -------
    Judged or None
        Origin ``"slide"``.
    """
    axes = horizontal_axes(pair.target, up)
    n = math.floor(SWEEP_RANGE_M / TWIN_STEP_M)
    offsets = np.arange(-n, n + 1, dtype=np.float64) * TWIN_STEP_M
    free = TOLERANCE.free(threshold_m)
    least = 0.5 * shares(pair, W, threshold_m)[0]
    slid = [
        Judged("slide", Tk, *check.judge(Tk, *free))
        for Tk in _slides(pair, W, axes, polish, threshold_m, offsets, 0.0)
        if shares(pair, Tk, threshold_m)[0] >= least  # not clean merely by seeing less
    ]
    if not slid:
        return None
    return rescue(pose_masks(pair, W, threshold_m), slid, W, pair, threshold_m, judge)


__all__ = [
    "AXIS_NORMALS",
    "CHECK_POINTS",
    "MIN_SHIFT_M",
    "PEAKS",
    "SETTLED_DEG",
    "SWEEP_OPEN",
    "SWEEP_POINTS",
    "find_twins",
    "horizontal_axes",
    "shares",
    "slide_refuted",
]
