"""Calibration from given pairs: checked correspondences, the PnP stage, a
:class:`CalibrationResult`."""

from __future__ import annotations

import logging

from numpy.typing import ArrayLike

from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.types import (
    CalibrationResult,
    DroppedPair,
    describe_dropped,
    usable_correspondences,
)
from flexreg.calibration.verdict import calibration_verdict, require_determined
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.transforms import as_transform
from flexreg.errors import InputError
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages import camera_pose

log = logging.getLogger(__name__)

__all__ = ["solve_pnp"]


def _usable(
    c: Correspondences2D3D, intrinsics: CameraIntrinsics, T_init: ArrayLike | None
) -> tuple[Correspondences2D3D, tuple[DroppedPair, ...]]:
    """The pairs to solve (:func:`usable_correspondences`); at least
    :data:`~flexreg.stages.camera_pose.MIN_CORRESPONDENCES` of them, or an error that names
    the dropped ones."""
    kept, dropped = usable_correspondences(c, intrinsics, T_camera_lidar=T_init)
    n = camera_pose.MIN_CORRESPONDENCES
    if len(kept) < n:
        why = f" ({len(dropped)} left out: {describe_dropped(dropped)})" if dropped else ""
        raise InputError(
            c.source or "correspondences",
            f"only {len(kept)} usable correspondence(s){why}; camera-lidar calibration needs "
            f"at least {n}",
        )
    if dropped:
        log.info("%s: left out %s", c.source or "correspondences", describe_dropped(dropped))
    return kept, dropped


def solve_pnp(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    config: CalibrationConfig = CalibrationConfig(),
    T_init: ArrayLike | None = None,
    threshold_px: float | None = None,
) -> CalibrationResult:
    """``T_camera_lidar`` from 2D-3D pairs: PnP in MAGSAC++ RANSAC, then Levenberg-Marquardt.

    Pairs whose pixel lies outside the image or whose point lies behind the camera of
    ``T_init`` are left out (:func:`~flexreg.calibration.types.usable_correspondences`); the
    rest are solved by :func:`flexreg.stages.camera_pose.solve_pnp` with the RANSAC and
    refinement settings of ``config``: a pair is an inlier when its point lies in front of the
    camera and reprojects within ``threshold_px``. Pairs whose point lies behind the camera
    under the solution are left out of the result too. Every pair left out is listed in
    ``result.dropped`` with its line and reason.

    Parameters
    ----------
    correspondences : Correspondences2D3D
    intrinsics : CameraIntrinsics
        Pixels are distorted image coordinates; the distortion is modelled, not removed.
    config : CalibrationConfig
    T_init : (4, 4) float, optional
        Initial guess, used only to leave out points behind its camera.
    threshold_px : float, optional
        Inlier threshold, default ``config.threshold_px``.

    Returns
    -------
    CalibrationResult
        ``method="pairs"``, with the verdict on the inliers' geometry
        (:func:`flexreg.calibration.verdict.calibration_verdict`).

    Raises
    ------
    InputError
        Fewer than :data:`flexreg.stages.camera_pose.MIN_CORRESPONDENCES` usable pairs (the
        message names the ones left out).
    CalibrationError
        RANSAC finds no pose with at least
        :data:`flexreg.stages.camera_pose.MIN_CORRESPONDENCES` inliers in front of the camera;
        the pairs' (or the inliers') lidar points lie on one line, which leaves the pose
        undetermined (:func:`flexreg.calibration.verdict.require_determined`).
    """
    correspondences, dropped = _usable(correspondences, intrinsics, T_init)
    require_determined(correspondences, config=config)
    pnp = camera_pose.solve_pnp(
        correspondences,
        intrinsics,
        threshold_px=float(config.threshold_px if threshold_px is None else threshold_px),
        confidence=config.confidence,
        max_iterations=config.max_iterations,
        seed=config.seed,
        refine=config.refine,
    )
    # behind the camera under the solution: never inliers (so the pose is the same without
    # them), left out of the result and named
    behind, more = usable_correspondences(
        correspondences, intrinsics, T_camera_lidar=pnp.T_camera_lidar, pose="solution"
    )
    T = pnp.T_camera_lidar
    keep = correspondences.points @ T[2, :3] + T[2, 3] > 0
    if more:
        log.info("%s: left out %s", correspondences.source, describe_dropped(more))
        correspondences = behind
    verdict = calibration_verdict(
        correspondences, pnp.inlier_mask[keep], intrinsics, pnp.T_camera_lidar, config=config
    )
    return CalibrationResult(
        T_camera_lidar=pnp.T_camera_lidar,
        correspondences=correspondences,
        inlier_mask=pnp.inlier_mask[keep],
        residuals_px=pnp.residuals_px[keep],
        threshold_px=pnp.threshold_px,
        intrinsics=intrinsics,
        method="pairs",
        config=config,
        timings_s=pnp.timings_s,
        T_init=None if T_init is None else as_transform(T_init, name="initial guess"),
        verdict=verdict,
        dropped=tuple(sorted(dropped + more, key=lambda d: d.line)),  # file order
    )
