"""From a coarse result to the answer and its verdict: the refinement (kept when it scores
better, :func:`conclude`), the evidence and the one decision on it, and the second look an
answer refuted in open space gets (:func:`slid_answer`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.results import Verdict
from flexreg.core.scan import Scan
from flexreg.registration.candidates import Coarse, Keypoints3D, at_pose, dense_prior
from flexreg.registration.check import TOLERANCE, Check, Scored, TwoWay, decisive_full, duel
from flexreg.registration.config import GUARD_MARGIN, RegistrationConfig
from flexreg.registration.evidence import MAX_RIVALS, full_evidence, gather, runner_ups
from flexreg.registration.fullres import FullPair, pose_masks
from flexreg.registration.preparation import Run, ScanView
from flexreg.registration.settle import Settlement, pin_along
from flexreg.registration.twins import find_twins, slide_refuted
from flexreg.registration.verdict import decide, reasons
from flexreg.stages.refinement import refine
from flexreg.stages.refinement.projective import point_information

log = logging.getLogger(__name__)


def _icp_denominator(icp: Any) -> str:
    if icp.association == "projective":
        return (
            f"{icp.source_points} points of both scans spread evenly over their surfaces (one "
            f"per {icp.voxel_m:.3g} m cell) within {icp.max_distance_m:.3g} m of the other "
            "scan's surface on their ray"
        )
    return (
        f"{icp.source_points} source points ({icp.voxel_m:.3g} m voxels, thinned) "
        f"with a target point within {icp.max_distance_m:.3g} m"
    )


def _refine(
    scans: list[Scan | RangeImage],
    views: list[ScanView],
    T: NDArray[np.float64],
    thr: float,
    check: Check,
    config: RegistrationConfig,
    run: Run,
) -> Any:
    """ICP refinement of the coarse transform (:func:`~flexreg.stages.refinement.refine`),
    pairing from two plan cells: a coarse pose may be that far off (a plan overlay's cell, or
    a doorway link slid by a wall's thickness, which pairs within three inlier thresholds
    hold: only pairs seen from the same side reach across it)."""
    vt, vs = views
    samples = None
    if vs.refine_sample is not None and vt.refine_sample is not None:
        samples = (vs.refine_sample[0], vs.refine_sample[1], vt.refine_sample[1])
    with run.stage("refinement"):
        return refine(
            scans[0],
            scans[1],
            T,
            threshold_m=thr,
            method=config.icp,
            voxel_m=config.voxel_m,
            projective=not (vt.gaps or vs.gaps),
            check=lambda T_: check.judge(T_, *TOLERANCE.fine(thr))[0],
            target_image=vt.image,
            target_normals=vt.normals,
            source_image=vs.image,
            source_normals=vs.normals,
            samples=samples,
            reach_m=2 * config.prior.plan_cell_m,
        )


def _verdict(
    c: Coarse,
    scored: Scored,
    two: TwoWay,
    vt: ScanView,
    stage: tuple[float, float, str],
    thr: float,
    refinement: dict[str, Any] | None,
    config: RegistrationConfig,
    settled: Settlement,
    full_pair: Callable[[], FullPair],
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    up: NDArray[np.float64] | None,
) -> Verdict:
    """The evidence on the final transform (:mod:`.evidence`), measured once, and the one
    decision on it (:mod:`.verdict`). An answer no test doubts on the samples is also
    checked at full resolution (when the settling did not compare the scans there) and, for
    two levelled scans (``up``: the target's vertical), has its twins along the target's
    walls measured (:mod:`.twins`)."""
    ups = runner_ups(
        c.judged,
        scored.T,
        c.score,
        config.judge,
        ratio=config.judge.ambiguity_ratio,
    )
    rivals = runner_ups(
        c.judged,
        scored.T,
        c.score,
        config.judge,
        ratio=-np.inf,
        limit=MAX_RIVALS,
    )
    ev = gather(
        two,
        scored,
        target_normals=vt.normals,
        inlier_points=c.target_points[c.inliers],
        matches=len(c.pairs),
        fit_to_matches="keypoints" in c.origin or not dense_prior(c.origin),
        runner_up=ups,
        candidates=len(c.judged),
        inlier_rmse_m=stage[0],
        fitness=stage[1],
        residual_kind=stage[2],
        threshold_m=thr,
        refinement=refinement,
        rivals=rivals,
        full=settled.pair,
        full_ratio=config.judge.ambiguity_ratio,
        sweep=None if settled.sweep is None else settled.sweep | {"settled": settled.won},
    )
    judge = config.judge
    # measured further only where the answer still stands on what is measured so far
    if not reasons(ev, judge) and settled.pair is None and judge.runs("full"):
        ev = replace(ev, full_resolution=full_evidence(full_pair(), scored.T, thr, "check")[0])
    if not reasons(ev, judge) and up is not None and judge.runs("twins"):
        pair = settled.pair if settled.pair is not None else full_pair()
        ev = replace(ev, twins=find_twins(pair, scored.T, up, polish, thr, judge, settled.axis))
    return decide(ev, ups, judge)


@dataclass(frozen=True)
class Judging:
    """What turns a coarse result into an answer and its verdict (:func:`_conclude`)."""

    scans: list[Scan | RangeImage]
    views: list[ScanView]
    check: Check
    two: TwoWay
    thr: float
    config: RegistrationConfig
    run: Run
    pair: Callable[[], FullPair]
    polish: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None
    up: NDArray[np.float64] | None


@dataclass(frozen=True)
class Concluded:
    T: NDArray[np.float64]
    T_coarse: NDArray[np.float64]
    rmse: float
    fitness: float
    denom: str
    info: NDArray[np.float64]
    verdict: Verdict


def conclude(c: Coarse, settled: Settlement, j: Judging) -> Concluded:
    """The coarse result ``c`` refined (kept when it scores better) and judged."""
    T, inl, thr, judge = c.T_target_source, c.inliers, j.thr, j.config.judge
    T_coarse = T.copy()
    rmse = float(np.sqrt(c.residuals2[inl].mean())) if inl.any() else float("nan")
    fine_tol, fine_rel = TOLERANCE.fine(thr)
    q, cons, _ = j.check.classify(T, fine_tol, fine_rel)
    fitness = float(cons.mean())
    assert j.views[1].sample is not None
    denom = (
        f"{len(j.views[1].sample)} source points spread evenly over its surfaces, within "
        f"{fine_tol:.3g} m + 0.2% of range of what the target saw"
    )
    info = point_information(q[cons])
    refinement = None
    icp = _refine(j.scans, j.views, T, thr, j.check, j.config, j.run) if j.config.refine else None
    if icp is not None and settled.axis is not None:  # the cue, not ICP, fixes the axis
        icp = replace(icp, T_target_source=pin_along(settled, icp.T_target_source, T))
    with j.run.stage("verdict"):
        scored = coarse = j.two.score(T_coarse, fine_tol)
        kind = "keypoints"
        if icp is not None:
            refined = j.two.score(icp.T_target_source, fine_tol)
            kept = not judge.runs("guard") or refined.value >= coarse.value - GUARD_MARGIN
            duelled = None
            if not kept and judge.runs("full"):
                # the sample counts a wall's far face laid on its near face as explained; at
                # full resolution a point seen from behind explains nothing
                pair = j.pair()
                won, lost = duel(
                    pose_masks(pair, icp.T_target_source, thr), pose_masks(pair, T_coarse, thr)
                )
                if decisive_full(won, lost, judge, points=pair.points):
                    kept, duelled = True, [round(won, 6), round(lost, 6)]
                    log.info("the refinement wins at full resolution (%.5f / %.5f)", won, lost)
            refinement = {
                "kept": kept,
                "score_coarse": round(coarse.value, 6),
                "score_refined": round(refined.value, 6),
                "guard": judge.runs("guard"),
                "margin": GUARD_MARGIN,
                "method": j.config.icp,
            }
            if duelled is not None:
                refinement["full_duel"] = duelled
            if kept:
                T, rmse, fitness = icp.T_target_source, icp.inlier_rmse_m, icp.fitness
                info, denom, scored = icp.information, _icp_denominator(icp), refined
                kind = "point-to-plane" if icp.association == "projective" else "open3d"
            else:
                log.info("refinement discarded: %.4f -> %.4f", coarse.value, refined.value)
        stage = (rmse, fitness, kind)
        verdict = _verdict(
            c, scored, j.two, j.views[0], stage, thr, refinement, j.config, settled, j.pair,
            j.polish, j.up,
        )  # fmt: skip
    return Concluded(T, T_coarse, rmse, fitness, denom, info, verdict)


def slid_answer(
    c: Coarse, done: Concluded, kps: tuple[Keypoints3D, Keypoints3D], j: Judging
) -> Coarse | None:
    """For an answer the verdict refutes in open space (two levelled scans), the coarse
    result at the pose slid along the walls that replaces it
    (:func:`~flexreg.registration.twins.slide_refuted`), or None."""
    judge = j.config.judge
    refuted = any(r.code == "free_space" for r in done.verdict.reasons)
    if not refuted or j.up is None or not judge.runs("settle") or j.config.icp_only:
        return None
    with j.run.stage("settling"):
        won = slide_refuted(j.pair(), done.T, j.up, j.polish, j.check, j.thr, judge)
    if won is None:
        return None
    log.info("the answer is refuted in open space; slid along the walls, it fits")
    return at_pose(won.origin, won.T_target_source, *kps, j.thr, c.judged, c.score)


__all__ = ["Concluded", "Judging", "conclude", "slid_answer"]
