"""Calibration from given pairs: checked correspondences, the PnP stage, a
:class:`CalibrationResult`."""

from __future__ import annotations

from numpy.typing import ArrayLike

from flexreg.calibration.config import CalibrationConfig
from flexreg.calibration.types import CalibrationResult, check_correspondences
from flexreg.calibration.verdict import calibration_verdict, require_determined
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.transforms import as_transform
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages import camera_pose

__all__ = ["solve_pnp"]


def solve_pnp(
    correspondences: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    *,
    config: CalibrationConfig = CalibrationConfig(),
    T_init: ArrayLike | None = None,
    threshold_px: float | None = None,
) -> CalibrationResult:
    """``T_camera_lidar`` from 2D-3D pairs: PnP in MAGSAC++ RANSAC, then Levenberg-Marquardt.

    The pairs are checked (:func:`check_correspondences`), then solved by
    :func:`flexreg.stages.camera_pose.solve_pnp` with the RANSAC and refinement settings of
    ``config``: a pair is an inlier when its point lies in front of the camera and reprojects
    within ``threshold_px``.

    Parameters
    ----------
    correspondences : Correspondences2D3D
    intrinsics : CameraIntrinsics
        Pixels are distorted image coordinates; the distortion is modelled, not removed.
    config : CalibrationConfig
    T_init : (4, 4) float, optional
        Initial guess, used for the checks of :func:`check_correspondences` only.
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
        See :func:`check_correspondences`.
    CalibrationError
        RANSAC finds no pose with at least
        :data:`flexreg.stages.camera_pose.MIN_CORRESPONDENCES` inliers in front of the camera;
        the pairs' (or the inliers') lidar points lie on one line, which leaves the pose
        undetermined (:func:`flexreg.calibration.verdict.require_determined`).
    """
    check_correspondences(correspondences, intrinsics, T_init=T_init)
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
    verdict = calibration_verdict(
        correspondences, pnp.inlier_mask, intrinsics, pnp.T_camera_lidar, config=config
    )
    return CalibrationResult(
        T_camera_lidar=pnp.T_camera_lidar,
        correspondences=correspondences,
        inlier_mask=pnp.inlier_mask,
        residuals_px=pnp.residuals_px,
        threshold_px=pnp.threshold_px,
        intrinsics=intrinsics,
        method="pairs",
        config=config,
        timings_s=pnp.timings_s,
        T_init=None if T_init is None else as_transform(T_init, name="initial guess"),
        verdict=verdict,
    )
