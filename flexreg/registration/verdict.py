"""Whether a registration can be trusted: the evidence (:func:`gather`) and the decision
(:func:`decide`).

The evidence is measured on the final transform with inputs the registration has already
prepared: each scan's view (range image, what it measured, range slack, normals) and each
scan's even sample. It answers, in numbers with units in their keys:

* ``overlap``: how much of each scan the other explains (both directions);
* ``free_space``: how much of each lies where the other scanner saw through empty space;
* ``inliers``: how many feature matches agree and how they spread in 3D;
* ``axis_strength``: how firmly the overlap's surfaces fix each of the six pose parameters
  (a corridor fixes nothing along its axis);
* ``runner_up``: the best clearly different candidate pose and its score against the winner;
* ``residual``: how closely the surfaces meet; ``refinement``: whether ICP was kept.

:func:`decide` turns the evidence into a :class:`~flexreg.core.results.Verdict` with one
:class:`~flexreg.core.results.Reason` per failed test; its thresholds are the ``verdict_*``
fields of :class:`~flexreg.registration.config.RegistrationConfig`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.results import Hypothesis, Reason, Verdict
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.registration.candidates import Check, Judged
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.fullres import FullPair, pose_masks
from flexreg.stages.verification import AXES, axis_strength, plane_information, soft_score, spread

#: most runner-up poses listed
MAX_RUNNER_UPS = 3

#: most other candidate poses the answer duels (:func:`rivals`)
MAX_RIVALS = 8

#: relative range tolerance of the fine checks (fraction of the range)
FINE_REL = 0.002

#: free space is judged at this many inlier thresholds plus this fraction of the range (the
#: tolerance at which the candidates compete)
FREE_SPACE_TOLERANCE, FREE_SPACE_REL = 2.5, 0.01


@dataclass(eq=False)
class TwoWay:
    """Checks of a transform in both directions: the source's sample in the target's view
    (``forward``) and the target's sample in the source's view (``backward``)."""

    forward: Check
    backward: Check

    def score(self, T: NDArray[np.float64], tol: float) -> Scored:
        """:func:`~flexreg.stages.verification.soft_score` of both directions at ``tol``
        (metres, plus 0.2% of the range)."""
        f = soft_score(*self._args(self.forward, T, tol))
        b = soft_score(*self._args(self.backward, invert(T), tol))
        return Scored(T, tol, f, b)

    @staticmethod
    def _args(c: Check, T: NDArray[np.float64], tol: float) -> tuple[Any, ...]:
        return c.view, c.sample, T, tol, FINE_REL, c.slack, c.measured


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


def _frac(mask: NDArray[np.bool_]) -> float:
    return float(mask.mean()) if len(mask) else 0.0


def _r(x: float, nd: int = 4) -> float:
    return round(float(x), nd)


def _vec(v: NDArray[np.float64], nd: int = 4) -> list[float]:
    return [round(float(x), nd) for x in v]


def runner_ups(
    judged: Sequence[Judged],
    T: NDArray[np.float64],
    top: float,
    *,
    distinct_deg: float,
    distinct_m: float,
    ratio: float,
    limit: int = MAX_RUNNER_UPS,
) -> list[Hypothesis]:
    """The best candidates clearly different from ``T`` (more than ``distinct_deg`` or
    ``distinct_m`` away, and from each other), best first: always the best one, then any
    others whose score is at least ``ratio`` of the winner's ``top`` (at most ``limit``)."""

    def far(A: NDArray[np.float64], B: NDArray[np.float64]) -> bool:
        return rotation_error_deg(A, B) > distinct_deg or translation_error_m(A, B) > distinct_m

    out: list[Hypothesis] = []
    for j in sorted(judged, key=lambda j: -j.score):
        if not far(j.T_target_source, T) or any(
            not far(j.T_target_source, h.T_target_source) for h in out
        ):
            continue
        rel = j.score / top if top > 1e-9 else (1.0 if j.score >= top else 0.0)
        if out and rel < ratio:
            break
        out.append(
            Hypothesis(
                np.array(j.T_target_source, dtype=np.float64),
                _r(rel),
                _r(rotation_error_deg(j.T_target_source, T), 3),
                _r(translation_error_m(j.T_target_source, T), 3),
                j.origin,
            )
        )
        if len(out) >= limit:
            break
    return out


def _strength(
    target: RangeImage, normals: NDArray[np.float32] | None, q: NDArray[np.float64]
) -> dict[str, Any]:
    """Per-axis constraint strength of the overlap's points ``q`` (target frame)."""
    if normals is None or len(q) < 6:
        return {a: 0.0 for a in AXES} | {"points": len(q)}
    info, c, n = plane_information(target, normals, q)
    d2 = (q - c) ** 2
    # lever arm of each rotation: RMS distance of the points from that axis
    lever = np.sqrt(np.mean(d2.sum(axis=1)[:, None] - d2, axis=0))
    s, weakest, d = axis_strength(info, n, lever)
    kind = "translation" if np.linalg.norm(d[3:]) >= np.linalg.norm(d[:3]) else "rotation"
    part = d[3:] if kind == "translation" else d[:3]
    part = part / (np.linalg.norm(part) or 1.0)
    if part[int(np.argmax(np.abs(part)))] < 0:
        part = -part
    return {a: _r(v) for a, v in zip(AXES, s, strict=True)} | {
        "points": int(n),
        "lever_arm_m": _vec(lever, 3),
        "weakest": {
            "strength": _r(weakest),
            "kind": kind,
            "direction_target": _vec(part, 3),
        },
    }


def gather(
    two: TwoWay,
    final: Scored,
    *,
    target_normals: NDArray[np.float32] | None,
    inlier_points: NDArray[np.float64],
    matches: int,
    fit_to_matches: bool,
    runner_up: Sequence[Hypothesis],
    candidates: int,
    inlier_rmse_m: float,
    fitness: float,
    threshold_m: float,
    residual_kind: str = "point-to-plane",
    refinement: dict[str, Any] | None,
    rivals: Sequence[Hypothesis] = (),
    full: FullPair | None = None,
    full_ratio: float = 0.6,
    sweep: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The evidence of a registration (JSON-ready, units in the keys).

    Parameters
    ----------
    two : TwoWay
        Both scans' views and samples.
    final : Scored
        The final transform scored in both directions (:meth:`TwoWay.score`).
    target_normals : (H, W, 3) float32 or None
        The target's grid normals (for the per-axis strength).
    inlier_points : (K, 3) float64, metres
        The inlier feature matches' target points.
    matches : int
        Feature matches tested.
    fit_to_matches : bool
        Whether the coarse transform was fitted to the matches (not so for a plan overlay
        alone: then the matches do not carry the pose and their count is not tested).
    runner_up : sequence of Hypothesis
        From :func:`runner_ups`.
    candidates : int
        How many candidate poses were judged.
    inlier_rmse_m, fitness, threshold_m : float
        The final stage's residual and overlap, and the inlier threshold.
    residual_kind : {"point-to-plane", "keypoints", "open3d"}
        What ``inlier_rmse_m`` measures: point-to-plane residuals (projective refinement),
        keypoint residuals (no refinement kept), or Open3D's distances between voxel samples
        of the two clouds (GICP, point-to-point: they grow with the voxel, not with the misfit,
        so the residual test skips them).
    refinement : dict or None
        Whether the refinement was kept and the scores (None: not refined).
    rivals : sequence of Hypothesis
        Every other clearly different candidate worth a duel (:func:`runner_ups` without a
        score limit, at most :data:`MAX_RIVALS`): under ``"rivals"`` the answer's
        :func:`duel` against each, whatever its overall score. A rival that explains what
        the answer puts in open space refutes it, even when it overlaps less (the true pose
        of two stations that barely see each other, against a wrong pose that overlays two
        identical rooms).
    full : FullPair, optional
        Both scans at full resolution: the answer's own open-space share there is recorded
        (:func:`full_evidence`), and each runner-up scoring at least ``full_ratio`` of the
        answer also duels it there (``full_refuted_share``, ``full_refuting_share``, shares of
        ``full_points``; :mod:`flexreg.registration.fullres`).
    full_ratio : float
    sweep : dict, optional
        What the sweep along a weak axis or a repeat did
        (:class:`~flexreg.registration.settle.Settlement`), with ``settled``: the answer
        beat every close slid pose at full resolution.
    """
    _, qf, okf, _ = final.forward
    _, _, okb, _ = final.backward
    # free space at the candidates' coarse tolerance: a surface clearly in front of what the
    # other scanner saw, not range noise
    free_tol = FREE_SPACE_TOLERANCE * threshold_m
    answer = duel_masks(two, final.T, threshold_m)
    (_, badf), (_, badb) = answer
    sf, sb = _frac(okf), _frac(okb)
    overlap_q = qf[okf]
    std_xyz, std_pc = spread(inlier_points)
    _, overlap_pc = spread(overlap_q)
    ev: dict[str, Any] = {
        "overlap": {
            "source_explained": _r(_frac(okf)),
            "target_explained": _r(_frac(okb)),
            "tolerance_m": _r(final.tolerance_m),
            "tolerance_rel": FINE_REL,
            "samples": [len(okf), len(okb)],
        },
        "free_space": {
            "source_conflicting": _r(_frac(badf)),
            "target_conflicting": _r(_frac(badb)),
            # contradicted as a fraction of explained, per direction
            "source_conflict_ratio": _r(_frac(badf) / sf) if sf > 0 else None,
            "target_conflict_ratio": _r(_frac(badb) / sb) if sb > 0 else None,
            "tolerance_m": _r(free_tol),
            "tolerance_rel": FREE_SPACE_REL,
        },
        "inliers": {
            "count": len(inlier_points),
            "matches": int(matches),
            "fit_to_matches": bool(fit_to_matches),
            "std_xyz_m": _vec(std_xyz, 3),
            "std_principal_m": _vec(std_pc, 3),
            "overlap_std_principal_m": _vec(overlap_pc, 3),
            "spread_ratio": _r(std_pc[1] / overlap_pc[1]) if overlap_pc[1] > 0 else 0.0,
        },
        "axis_strength": _strength(two.forward.view, target_normals, overlap_q),
        "runner_up": None,
        "candidates": int(candidates),
        "residual": {
            "inlier_rmse_m": _r(inlier_rmse_m, 5),
            "fitness": _r(fitness),
            "threshold_m": _r(threshold_m, 5),
            "rmse_over_threshold": _r(inlier_rmse_m / threshold_m) if threshold_m > 0 else None,
            "kind": residual_kind,
        },
        "refinement": refinement,
    }
    c = overlap_q.mean(axis=0) if len(overlap_q) else np.zeros(3)
    # whenever the settling made both scans' full views (a repeating plan, a weak axis or a
    # close rival) the answer's own open-space share there decides ``free_space`` (decide)
    full_answer = None if full is None else full_evidence(ev, full, final.T, threshold_m)
    if sweep is not None:
        ev["sweep"] = dict(sweep)
    ups = []
    for h in runner_up:
        D = np.asarray(h.T_target_source) @ invert(final.T)
        won, lost = duel(answer, duel_masks(two, h.T_target_source, threshold_m))
        ups.append(
            {
                "score_ratio": h.score_ratio,
                "rotation_deg": h.rotation_deg,
                "translation_m": h.translation_m,
                "offset_m": _vec(D[:3, :3] @ c + D[:3, 3] - c, 3),
                "origin": h.origin,
                "refuted_share": _r(won),
                "refuting_share": _r(lost),
            }
            | _full_duel(full, full_answer, h, threshold_m, full_ratio)
        )
    if ups:
        ev["runner_up"] = ups[0]
        ev["runner_ups"] = ups
    ev["rivals"] = [_rival(two, answer, h, threshold_m) for h in rivals]
    return ev


def full_evidence(
    ev: dict[str, Any],
    full: FullPair,
    T: NDArray[np.float64],
    threshold_m: float,
    why: str = "settling",
) -> Masks:
    """Record under ``ev["full_resolution"]`` how many points of both scans ``full`` checks,
    the share of them the pose ``T`` puts in the other's open space, and ``why`` they were
    compared (``"settling"``: a repeat, a weak axis or a close rival, where a twin beside the
    truth is likely; ``"check"``: a confident answer checked anyway); its masks
    (:func:`~flexreg.registration.fullres.pose_masks`)."""
    masks = pose_masks(full, T, threshold_m)
    bad = sum(int(b.sum()) for _, b in masks)
    ev["full_resolution"] = {
        "points": full.points,
        "open_space_share": round(bad / full.points, 7) if full.points else 0.0,
        "why": why,
    }
    return masks


def _full_duel(
    full: FullPair | None,
    answer: Masks | None,
    h: Hypothesis,
    threshold_m: float,
    ratio: float,
) -> dict[str, Any]:
    """The answer's full-resolution duel against a close runner-up (empty when not held)."""
    if full is None or answer is None or h.score_ratio < ratio:
        return {}
    won, lost = duel(answer, pose_masks(full, h.T_target_source, threshold_m))
    return {
        "full_refuted_share": round(won, 6),
        "full_refuting_share": round(lost, 6),
        "full_points": full.points,
    }


def _rival(two: TwoWay, answer: Masks, h: Hypothesis, threshold_m: float) -> dict[str, Any]:
    won, lost = duel(answer, duel_masks(two, h.T_target_source, threshold_m))
    return {
        "score_ratio": h.score_ratio,
        "rotation_deg": h.rotation_deg,
        "translation_m": h.translation_m,
        "origin": h.origin,
        "refuted_share": _r(won),
        "refuting_share": _r(lost),
    }


Masks = tuple[tuple[NDArray[np.bool_], NDArray[np.bool_]], ...]


def duel_masks(two: TwoWay, T: NDArray[np.float64], threshold_m: float) -> Masks:
    """Per direction (source in the target's view, target in the source's), which sampled
    points a pose explains (fine tolerance: half an inlier threshold plus 0.2 %) and which it
    puts in the other scanner's free space (:data:`FREE_SPACE_TOLERANCE` inlier thresholds
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
    (:data:`FREE_SPACE_TOLERANCE` inlier thresholds plus 1 %); (N,) bool each."""
    explained = check.classify(T, threshold_m / 2, FINE_REL)[1]
    free = check.classify(T, FREE_SPACE_TOLERANCE * threshold_m, FREE_SPACE_REL)[2]
    return explained, free


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


# ---------------------------------------------------------------------------- decision


def _along(v: Sequence[float]) -> str:
    """``"x"`` when one axis carries most of a direction, else the direction's components."""
    a = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(a))
    if n <= 0:
        return "an unknown direction"
    k = int(np.argmax(np.abs(a)))
    if abs(a[k]) >= 0.9 * n:
        return "xyz"[k]
    return "({:.2f}, {:.2f}, {:.2f}) of the target frame".format(*(a / n))


def _sweep_settled(ev: dict[str, Any]) -> bool:
    """Whether a sweep along the weak axis found every other position refuted at full
    resolution (:mod:`flexreg.registration.settle`)."""
    sw = ev.get("sweep") or {}
    return bool(sw.get("kind") == "weak_axis" and sw.get("settled"))


def _overlap_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    o = ev.get("overlap")
    if not o:
        return None
    s, t = o["source_explained"], o["target_explained"]
    if min(s, t) >= cfg.verdict_min_overlap:
        return None
    return Reason(
        "low_overlap",
        f"only {100 * s:.0f}% of the source and {100 * t:.0f}% of the target are explained by "
        f"the other scan (need {100 * cfg.verdict_min_overlap:.0f}% of each): the scans may "
        "hardly overlap",
    )


def _free_space_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    f = ev.get("free_space")
    if not f:
        return None
    worst = max(f["source_conflicting"], f["target_conflicting"])
    ratio = max(f.get("source_conflict_ratio") or 0.0, f.get("target_conflict_ratio") or 0.0)
    if worst > cfg.verdict_max_conflict:
        return Reason(
            "free_space",
            f"{100 * worst:.0f}% of one scan lands where the other scanner saw through empty "
            f"space (allowed {100 * cfg.verdict_max_conflict:.0f}%): the pose puts surfaces in "
            "open space",
        )
    if ratio > cfg.verdict_max_conflict_ratio:
        return Reason(
            "free_space",
            f"for every 100 points of one scan the other explains, {100 * ratio:.0f} land where "
            f"the other scanner saw through empty space (allowed "
            f"{100 * cfg.verdict_max_conflict_ratio:.0f}): the pose contradicts much of what it "
            "fits",
        )
    return None


def _full_open_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    """The answer puts more than ``verdict_full_max_open`` (where the settling compared the
    scans: a twin beside the truth is likely) or ``verdict_full_max_open_check`` (a confident
    answer checked anyway) of both scans' points in the other's open space at full
    resolution: one bay, aisle or room beside the right pose, which the samples' checks
    cannot tell."""
    f = ev.get("full_resolution")
    if not f:
        return None
    allowed = (
        cfg.verdict_full_max_open_check if f.get("why") == "check" else cfg.verdict_full_max_open
    )
    if f["open_space_share"] <= allowed:
        return None
    return Reason(
        "free_space",
        f"at full resolution {100 * f['open_space_share']:.2f}% of both scans' points land where "
        f"the other scanner saw through empty space (allowed {100 * allowed:.1f}%): the pose is "
        "contradicted, perhaps a bay or room beside the right one",
    )


def _inlier_reasons(ev: dict[str, Any], cfg: RegistrationConfig) -> list[Reason]:
    i = ev.get("inliers")
    if not i or not i.get("fit_to_matches", True):
        return []
    if i["count"] < cfg.verdict_min_inliers:
        return [
            Reason(
                "few_inliers",
                f"only {i['count']} of {i['matches']} feature matches agree with the pose (need "
                f"{cfg.verdict_min_inliers}): it rests on the surfaces alone",
            )
        ]
    if i["count"] >= 3 and i["spread_ratio"] < cfg.verdict_min_inlier_spread:
        return [
            Reason(
                "clustered_inliers",
                f"the {i['count']} agreeing feature matches lie in a narrow patch (spread "
                f"{i['std_principal_m'][1]:.2f} m across, the overlap "
                f"{i['overlap_std_principal_m'][1]:.2f} m): the pose may tilt about them",
            )
        ]
    return []


def _axis_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    a = ev.get("axis_strength")
    if not a:
        return None
    weak = [k for k in AXES if a.get(k, 1.0) < cfg.verdict_min_axis_strength]
    if not weak:
        return None
    limit = f"strength {min(a[k] for k in weak):.3f}, need {cfg.verdict_min_axis_strength:g}"
    w = a.get("weakest", {})
    direction = _along(w.get("direction_target", ()))
    if any(k in ("x", "y", "z") for k in weak) and w.get("kind", "translation") == "translation":
        if _sweep_settled(ev):
            return None
        return Reason(
            "weak_axis",
            f"the scans constrain almost nothing along {direction} ({limit}; a corridor or "
            "tunnel?): the position along it is a guess",
        )
    return Reason(
        "weak_axis",
        f"the scans constrain almost no rotation about {direction} ({limit}; a round room or "
        "a single surface?): the angle about it is a guess",
    )


def decisive(won: float, lost: float, cfg: RegistrationConfig) -> bool:
    """Whether :func:`duel` shares ``won`` against ``lost`` settle two poses (see
    ``verdict_decisive_share`` and ``verdict_decisive_ratio`` of the config)."""
    return won - lost >= cfg.verdict_decisive_share and won >= cfg.verdict_decisive_ratio * lost


def decisive_full(won: float, lost: float, cfg: RegistrationConfig, *, points: int = 0) -> bool:
    """Whether full-resolution :func:`duel` shares (:mod:`flexreg.registration.fullres`)
    settle two poses: ``won >= verdict_decisive_ratio * lost`` and a lead ``won - lost`` of
    at least ``verdict_full_decisive_share`` of the points, or, given the number of
    ``points`` checked, of at least ``verdict_full_decisive_points`` points.

    The share scales with the scans; a small cue does not (a forklift seen two bays away
    leads by 13-53 points of 850 000 at 1024 x 512, less than the share's 85), while the
    duels of empty tunnels, arcades and rooms leave 0-2 points either way: a count floor
    between them with the ratio settles the cue and leaves the empty scenes open.

    >>> cfg = RegistrationConfig()
    >>> decisive_full(0.0005, 0.0, cfg), decisive_full(0.00005, 0.0, cfg)
    (True, False)
    >>> decisive_full(0.0006, 0.0003, cfg)
    False
    >>> n = 850_000  # 17 points against none, and 17 against 6 (not 3 : 1)
    >>> decisive_full(17 / n, 0.0, cfg, points=n), decisive_full(17 / n, 6 / n, cfg, points=n)
    (True, False)
    >>> decisive_full(2 / n, 0.0, cfg, points=n)
    False
    """
    if won < cfg.verdict_decisive_ratio * lost:
        return False
    lead = won - lost
    if lead >= cfg.verdict_full_decisive_share:
        return True
    floor = cfg.verdict_full_decisive_points
    return points > 0 and floor > 0 and lead * points >= floor - 1e-6


def _settled(u: dict[str, Any], ev: dict[str, Any], cfg: RegistrationConfig) -> bool:
    """Whether the answer beats a runner-up decisively, on the samples or at full
    resolution (there only when the answer itself puts almost nothing in open space, or
    when the runner-up puts ``settle_open_share`` of the points in open space, ten times
    what the answer does and what it refutes of the runner-up's)."""
    if "refuted_share" in u and decisive(u["refuted_share"], u["refuting_share"], cfg):
        return True
    full = ev.get("full_resolution") or {}
    own = full.get("open_space_share", 1.0)
    if (  # a runner-up full resolution refutes outright (a bay off in a repeating hall)
        u.get("full_refuted_share", 0.0) >= cfg.settle_open_share
        and own <= cfg.settle_open_share / 3
        and u["full_refuted_share"] >= 10 * max(u["full_refuting_share"], own)
    ):
        return True
    if own > cfg.verdict_full_max_conflict:
        return False
    return "full_refuted_share" in u and decisive_full(
        u["full_refuted_share"], u["full_refuting_share"], cfg, points=u.get("full_points", 0)
    )


def _ambiguity_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    rivals = [
        u
        for u in ev.get("runner_ups") or ([ev["runner_up"]] if ev.get("runner_up") else [])
        if u["score_ratio"] >= cfg.verdict_ambiguity_ratio and not _settled(u, ev, cfg)
    ]
    if not rivals:
        return None
    r = rivals[0]
    if r["rotation_deg"] > 10:
        what = f"turned {r['rotation_deg']:.0f}° from each other"
        cause = "symmetric structure"
    else:
        what = f"{r['translation_m']:.1f} m apart along {_along(r.get('offset_m', ()))}"
        cause = "repeating structure"
    return Reason(
        "ambiguous",
        f"two poses {what} fit almost equally well (the other scores {100 * r['score_ratio']:.0f}"
        f"% of the answer): {cause}",
    )


def _refuted_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    """A rival pose beats the answer :func:`decisive`-ly in their duel, whatever the scores."""
    beaten = [
        u for u in ev.get("rivals") or () if decisive(u["refuting_share"], u["refuted_share"], cfg)
    ]
    if not beaten:
        return None
    r = max(beaten, key=lambda u: u["refuting_share"] - u["refuted_share"])
    return Reason(
        "ambiguous",
        f"another pose {r['rotation_deg']:.0f}° / {r['translation_m']:.1f} m away explains "
        f"{100 * r['refuting_share']:.1f}% of the scans where this one puts surfaces in open "
        f"space (the reverse: {100 * r['refuted_share']:.1f}%): this pose is contradicted, "
        "perhaps an identical room or bay beside the right one",
    )


def _twin_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    """A twin of the answer fits (:mod:`flexreg.registration.twins`, ``verdict_twin_*``)."""
    a = (ev.get("twins") or {}).get("answer")
    if not a:
        return None
    limit = max(cfg.verdict_twin_fit_open, 2 * a["open_share"])
    least = max(cfg.verdict_twin_min_ratio * a["explained_share"], 1e-9)
    won, lost = "full_refuted_share", "full_refuting_share"
    fits = [  # a weak twin the answer beats on every pixel does not count
        t
        for t in ev["twins"].get("twins", ())
        if t["open_share"] <= limit
        and t["explained_share"] >= least
        and not decisive_full(
            t.get(won, 0.0), t.get(lost, 0.0), cfg, points=t.get("full_points", 0)
        )
    ]
    if not fits:
        return None
    t = max(fits, key=lambda t: t["explained_share"])
    return Reason(
        "ambiguous",
        f"the answer moved {t['shift_m']:.1f} m along {_along(t['offset_m'])} fits too: it "
        f"explains {100 * t['explained_share']:.0f}% of both scans (the answer "
        f"{100 * a['explained_share']:.0f}%) and contradicts nothing more: repeating "
        "structure (identical bays or rooms) these two scans alone cannot tell apart",
    )


def _residual_reason(ev: dict[str, Any], cfg: RegistrationConfig) -> Reason | None:
    r = ev.get("residual")
    if not r or r.get("rmse_over_threshold") is None or r.get("kind") == "open3d":
        return None
    if r["rmse_over_threshold"] <= cfg.verdict_max_rmse_ratio:
        return None
    return Reason(
        "high_residual",
        f"the surfaces still differ by {100 * r['inlier_rmse_m']:.1f} cm RMS (allowed "
        f"{100 * cfg.verdict_max_rmse_ratio * r['threshold_m']:.1f} cm): they do not meet closely",
    )


def decide(
    evidence: dict[str, Any],
    runner_up: Sequence[Hypothesis] = (),
    config: RegistrationConfig = RegistrationConfig(),
) -> Verdict:
    """The verdict on a registration's evidence: ``"uncertain"`` with one reason per failed
    test, else ``"confident"``.

    Tests (thresholds: ``config.verdict_*``; a test whose evidence is missing passes):
    ``low_overlap`` (either scan explained less than ``verdict_min_overlap``),
    ``free_space`` (either conflicting more than ``verdict_max_conflict``, or more than
    ``verdict_max_conflict_ratio`` of what the other explains of it, or, where the scans were
    compared at full resolution, more than ``verdict_full_max_open`` of all their points in
    the other's open space),
    ``few_inliers`` (fewer than ``verdict_min_inliers``) or ``clustered_inliers`` (their
    second principal spread below ``verdict_min_inlier_spread`` of the overlap's),
    ``weak_axis`` (a pose parameter's strength below ``verdict_min_axis_strength``),
    ``ambiguous`` (a clearly different pose scores at least ``verdict_ambiguity_ratio`` of
    the winner and the answer does not beat it :func:`decisive`-ly, or any rival pose beats
    the answer :func:`decisive`-ly in their duel, or the answer moved a whole bay fits
    too: :func:`_twin_reason`), ``high_residual``
    (inlier RMSE above ``verdict_max_rmse_ratio`` inlier thresholds). A rejected refinement
    is a note, not a reason.

    Parameters
    ----------
    evidence : dict
        As :func:`gather` makes it.
    runner_up : sequence of Hypothesis
    config : RegistrationConfig

    Returns
    -------
    Verdict

    Examples
    --------
    >>> v = decide({"overlap": {"source_explained": 0.05, "target_explained": 0.6}})
    >>> v.status, [r.code for r in v.reasons]
    ('uncertain', ['low_overlap'])
    >>> decide({"overlap": {"source_explained": 0.7, "target_explained": 0.6}}).status
    'confident'
    """
    reasons: list[Reason] = []
    for test in (_overlap_reason, _free_space_reason, _axis_reason, _ambiguity_reason):
        r = test(evidence, config)
        if r is not None:
            reasons.append(r)
    if not any(x.code == "free_space" for x in reasons):
        r = _full_open_reason(evidence, config)
        if r is not None:
            reasons.append(r)
    for extra in (_refuted_reason, _twin_reason):
        if not any(x.code == "ambiguous" for x in reasons):
            r = extra(evidence, config)
            if r is not None:
                reasons.append(r)
    reasons += _inlier_reasons(evidence, config)
    r = _residual_reason(evidence, config)
    if r is not None:
        reasons.append(r)
    notes: list[Reason] = []
    if _sweep_settled(evidence) and _axis_reason(evidence, config) is None:
        a = evidence.get("axis_strength") or {}
        if any(a.get(k, 1.0) < config.verdict_min_axis_strength for k in ("x", "y", "z")):
            sw = evidence["sweep"]
            notes.append(
                Reason(
                    "weak_axis_settled",
                    f"the surfaces constrain almost nothing along {_along(sw['direction_target'])}"
                    f", but of {sw['poses']} positions tried along it within "
                    f"{sw['range_m']:g} m every other one puts surfaces in open space where this "
                    "one fits them (a unique object decides)",
                )
            )
    ref = evidence.get("refinement")
    if ref and not ref.get("kept", True):
        notes.append(
            Reason(
                "refinement_rejected",
                f"the ICP refinement was discarded: it scored {ref['score_refined']:.4f} "
                f"against {ref['score_coarse']:.4f} before it (the coarse transform is kept)",
            )
        )
    status: Literal["confident", "uncertain"] = "uncertain" if reasons else "confident"
    return Verdict(status, tuple(reasons), evidence, tuple(runner_up), tuple(notes))


__all__ = [
    "FINE_REL",
    "FREE_SPACE_REL",
    "FREE_SPACE_TOLERANCE",
    "MAX_RIVALS",
    "MAX_RUNNER_UPS",
    "Scored",
    "TwoWay",
    "check_masks",
    "decide",
    "decisive",
    "decisive_full",
    "duel",
    "duel_masks",
    "full_evidence",
    "gather",
    "runner_ups",
]
