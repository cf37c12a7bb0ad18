"""Every knob of frame-to-frame odometry and of trajectory evaluation, validated in one place."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from flexreg.config import Config, Finite, OddSize, Positive, Seed, ThresholdM, one_of
from flexreg.stages.keypoints import METHODS as FEATURES

#: units of the RPE interval ``delta``
DELTA_UNITS = ("frames", "seconds", "metres")
#: RPE error compositions (see :func:`flexreg.odometry.evaluation.rpe`)
RPE_CONVENTIONS = ("tools", "paper")

#: feature images odometry can run on
IMAGES: tuple[str, ...] = (
    "flexion",
    "flexion-normalized",
    "flexion-angle",
    "bearing-horizontal",
    "bearing-vertical",
    "bearing-diagonal",
    "bearing-antidiagonal",
    "color",
)
#: pose solvers
METHODS: tuple[str, ...] = ("essential", "svd")
#: trajectory file formats of ``flexreg evaluate`` (auto: by the number of values per line)
TRAJECTORY_FORMATS: tuple[str, ...] = ("auto", "tum", "kitti")


class OdometryConfig(Config):
    """Every knob of :func:`odometry`; saved with each result.

    Attributes
    ----------
    image : str
        Feature image: ``flexion``, ``flexion-normalized``, ``flexion-angle``,
        ``bearing-{horizontal,vertical,diagonal,antidiagonal}`` or ``color``.
    n : int, pixels
        Odd neighbourhood size of the conversion (Flexion n x n; 3 is the paper's Bearing
        Angle between adjacent pixels).
    median : {0, 3, 5}
        Median pre-filter window on the depth before the conversion (paper sec. III-B-1).
    fill_holes : bool
        Fill isolated no-reading pixels first (:func:`flexreg.stages.projection.fill_holes`).
    stretch : {None, "clahe", "percentile"}
        Contrast normalisation after the 8-bit mapping (None: the paper's plain eq. 10 scaling).
    features : str
        Detector/descriptor: ``akaze``, ``orb``, ``sift``, ``kaze``, ``brisk`` (``surf`` on a
        nonfree OpenCV), with OpenCV's default parameters as in the paper.
    max_features : int or None
        Keep only the strongest keypoints (>= 8; None: the detector's own default/limit).
    border_px : int, pixels
        Detect only this far from pixels without a value (0: anywhere on valid pixels).
    support : float
        Also drop keypoints closer to a pixel without a value than this times their diameter
        (0: keep them; see :func:`flexreg.stages.keypoints.detect_and_describe`).
    ratio : float
        Lowe's ratio-test threshold on the two nearest neighbours, in (0, 1].
    mutual : bool
        Also require mutual nearest neighbours (not in the paper).
    method : {"svd", "essential"}
        Pose solver: ``"svd"`` (3D-3D) or ``"essential"`` (the paper's 2D-2D; see
        :mod:`flexreg.odometry.track`). Default ``"svd"`` (3D-3D): 2-2.6x
        lower ATE than the paper's ``"essential"`` on the measured sequences
        (docs/odometry.md), and it also runs on panoramic (lidar, TLS) frames.
    ransac_threshold_px : float, pixels
        Epipolar RANSAC threshold of ``cv2.findEssentialMat`` (OpenCV's default 1 px).
    ransac_confidence : float
        RANSAC confidence in (0, 1) (``findEssentialMat``'s ``prob``; also used for the SVD
        solver).
    threshold_m : float or None, metres
        Inlier distance of the SVD solver; None: ``max(0.01, 0.015 * median range)`` of the
        pair's matched points.
    min_inliers : int
        A pair with fewer inliers counts as failed (>= 5).
    max_jump : float
        Keypoints whose four neighbouring depth pixels differ by more than this fraction of
        their range are not lifted to 3D (depth discontinuities).
    seed : int
        Seed of all randomness (RANSAC sampling).
    """

    image: Annotated[str, one_of(IMAGES, "feature image")] = "flexion"
    n: OddSize = 5
    median: Annotated[int, one_of((0, 3, 5))] = 3
    fill_holes: bool = True
    stretch: Annotated[str, one_of(("clahe", "percentile"))] | None = None
    features: Annotated[str, one_of(FEATURES, "method")] = "orb"
    max_features: Annotated[int, Field(ge=8)] | None = None
    border_px: int = Field(0, ge=0)
    support: float = Field(0.0, ge=0, allow_inf_nan=False)
    ratio: float = Field(0.8, gt=0, le=1)
    mutual: bool = False
    method: Annotated[str, one_of(METHODS)] = "svd"
    ransac_threshold_px: Positive = 1.0
    ransac_confidence: float = Field(0.999, gt=0, lt=1)
    threshold_m: ThresholdM | None = None
    min_inliers: int = Field(12, ge=5)
    max_jump: Positive = 0.03
    seed: Seed = 0


class EvaluationConfig(Config):
    """Settings of :func:`flexreg.odometry.evaluation.evaluate` as ``flexreg evaluate`` runs
    it; saved with each result.

    Attributes
    ----------
    format : {"auto", "tum", "kitti"}
        Trajectory file format (auto: 8 values per line TUM, 12 KITTI).
    delta_unit : {"frames", "seconds", "metres"}
        Unit of the RPE interval.
    delta : float
        RPE interval in ``delta_unit`` (> 0; a whole number of frames).
    convention : {"tools", "paper"}
        RPE error composition (see :func:`flexreg.odometry.evaluation.rpe`).
    scale : bool
        Also estimate a scale in the ATE alignment (monocular estimates).
    max_dt_s : float or None, seconds
        Largest time difference of matched poses (None: each TUM tool's own rule).
    offset_s : float, seconds
        Time offset added to the estimate.
    """

    format: Annotated[str, one_of(TRAJECTORY_FORMATS)] = "auto"
    delta_unit: Annotated[str, one_of(DELTA_UNITS)] = "frames"
    delta: Positive = 1.0
    convention: Annotated[str, one_of(RPE_CONVENTIONS)] = "tools"
    scale: bool = False
    max_dt_s: Positive | None = None
    offset_s: Finite = 0.0

    @field_validator("delta")
    @classmethod
    def _whole_frames(cls, delta: float, info: ValidationInfo) -> float:
        if info.data.get("delta_unit") == "frames" and delta != int(delta):
            raise PydanticCustomError("whole_frames", "must be a whole number of frames")
        return delta
