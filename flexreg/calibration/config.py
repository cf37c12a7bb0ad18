"""Every knob of camera-lidar calibration, validated in one place."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from flexreg.config import Config, OddSize, Positive, Seed, odd


class CalibrationConfig(Config):
    """Settings of :func:`calibrate` (saved with every result).

    Attributes
    ----------
    threshold_px : float, pixels
        RANSAC inlier threshold on the reprojection error (full-resolution pixels).
    confidence : float
        RANSAC confidence in (0, 1).
    max_iterations : int
        RANSAC iteration cap (>= 1).
    refine : bool
        Levenberg-Marquardt refinement on the inliers after RANSAC.
    seed : int
        Seed of OpenCV's USAC random generator (same seed, same result).
    init_rotation_deg : float, degrees
        Automatic mode: how far the initial guess's rotation may be off. Sets the first search
        radius, and corrections beyond twice this are not accepted.
    init_translation_m : float, metres
        Automatic mode: how far the initial guess's translation may be off. Sets the first
        search radius, and corrections beyond twice this are not accepted.
    auto_scale : float or None
        Automatic mode: scale of the working images relative to the camera image, in (0, 1]
        (None: from the lidar's angular density). None picks about 1.75 pixels per lidar
        point spacing.
    auto_rounds : int
        Automatic mode: match-and-solve rounds, each with a smaller search radius.
    patch_px : int, working pixels
        Automatic mode: side of the matched patches (odd, >= 7).
    max_keypoints : int
        Automatic mode: patches per round (strongest corners of the Flexion view).
    min_ncc : float
        Automatic mode: lowest normalised cross-correlation of a kept match, in (-1, 1).
    min_inliers : int
        Automatic mode: fewest PnP inliers for a round's result to be considered.
    max_spread_deg : float, degrees
        Automatic mode: largest median rotation between the chosen pose and the other rounds'
        poses (rounds 2, 3, ...); beyond it the matches are judged unreliable and the mode
        refuses.
    flexion_n : int, pixels
        Grid size n of the Flexion n x n images (odd, >= 3).
    verdict_min_inliers : int
        Fewer agreeing pairs make the result uncertain (``few_inliers``).
    verdict_planar_ratio : float
        Inlier lidar points thinner than this share of their extent (third over first
        principal spread) lie on one plane: uncertain (``coplanar_points``); up to five times
        thicker, only when a mirrored pose fits them at least half as well.
    verdict_line_ratio : float
        Narrower than this share (second over first principal spread): near one line,
        uncertain (``collinear_points``).
    collinear_ratio : float
        Narrower than this share: on one line, the pose is not determined and calibration
        fails (at most ``verdict_line_ratio``).
    verdict_min_image_coverage : float
        Share of the camera image the inlier pixels' convex hull must cover, in [0, 1]
        (``clustered_pixels`` below it).
    verdict_max_rotation_std_deg : float, degrees
        Largest standard deviation of the rotation about any camera axis for a confident
        result (``weak_axis`` beyond). From the reprojection's information matrix.
    verdict_max_translation_std_m : float, metres
        Largest standard deviation of the translation along any camera axis for a confident
        result (``weak_axis`` beyond). From the reprojection's information matrix.
    """

    threshold_px: Positive = 3.0
    confidence: float = Field(0.9999, gt=0, lt=1)
    max_iterations: int = Field(10000, ge=1)
    refine: bool = True
    seed: Seed = 0
    init_rotation_deg: Positive = 2.0
    init_translation_m: Positive = 0.10
    auto_scale: Annotated[float, Field(gt=0, le=1)] | None = None
    auto_rounds: int = Field(6, ge=1)
    patch_px: Annotated[int, odd(7)] = 21
    max_keypoints: int = Field(800, ge=1)
    min_ncc: float = Field(0.3, gt=-1, lt=1)
    min_inliers: int = Field(12, ge=1)
    max_spread_deg: Positive = 1.0
    flexion_n: OddSize = 3
    verdict_min_inliers: int = Field(10, ge=4)
    verdict_planar_ratio: float = Field(0.01, ge=0, lt=1)
    verdict_line_ratio: float = Field(0.05, ge=0, lt=1)
    collinear_ratio: float = Field(0.01, ge=0, lt=1)
    verdict_min_image_coverage: float = Field(0.05, ge=0, le=1)
    verdict_max_rotation_std_deg: Positive = 0.5
    verdict_max_translation_std_m: Positive = 0.05

    @model_validator(mode="after")
    def _line_ratios(self) -> CalibrationConfig:
        if self.collinear_ratio > self.verdict_line_ratio:
            raise ValueError(
                f"collinear_ratio ({self.collinear_ratio}) must be at most verdict_line_ratio "
                f"({self.verdict_line_ratio})"
            )
        return self
