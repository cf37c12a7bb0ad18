"""Every knob of frame-to-frame odometry, validated in one place."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from flexreg.errors import ConfigError

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
METHODS: tuple[str, ...] = ("essential", "svd")
#: ``cv2.recoverPose`` counts a triangulated point as in front of both cameras only up to this
#: many baselines away (OpenCV's default is 50). Depth-camera motion between frames is often
#: millimetres while the scene is metres away -- thousands of baselines -- and with the default
#: every point would fail the check and the four pose candidates could not be told apart.


def _l(items: tuple[str, ...]) -> str:
    return ", ".join(items)


@dataclass(frozen=True)
class OdometryConfig:
    """Every knob of :func:`odometry`; saved with each result.

    Attributes
    ----------
    image : str
        Feature image: ``flexion``, ``flexion-normalized``, ``flexion-angle``,
        ``bearing-{horizontal,vertical,diagonal,antidiagonal}`` or ``color``.
    n : int
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
        Keep only the strongest keypoints (None: the detector's own default/limit).
    border_px : int, pixels
        Detect only this far from pixels without a value (0: anywhere on valid pixels).
    support : float
        Also drop keypoints closer to a pixel without a value than this times their diameter
        (0: keep them; see :func:`flexreg.stages.keypoints.detect_and_describe`).
    ratio : float
        Lowe's ratio-test threshold on the two nearest neighbours.
    mutual : bool
        Also require mutual nearest neighbours (not in the paper).
    method : {"essential", "svd"}
        Pose solver, see the module docstring.
    ransac_threshold_px : float, pixels
        Epipolar RANSAC threshold of ``cv2.findEssentialMat`` (OpenCV's default 1 px).
    ransac_confidence : float
        RANSAC confidence (``findEssentialMat``'s ``prob``; also used for the SVD solver).
    threshold_m : float or None, metres
        Inlier distance of the SVD solver; None: ``max(0.01, 0.015 * median range)`` of the
        pair's matched points.
    min_inliers : int
        A pair with fewer inliers counts as failed.
    max_jump : float
        Keypoints whose four neighbouring depth pixels differ by more than this fraction of
        their range are not lifted to 3D (depth discontinuities).
    seed : int
        Seed of all randomness (RANSAC sampling).
    """

    image: str = "flexion"
    n: int = 5
    median: int = 3
    fill_holes: bool = True
    stretch: str | None = None
    features: str = "orb"
    max_features: int | None = None
    border_px: int = 0
    support: float = 0.0
    ratio: float = 0.8
    mutual: bool = False
    method: str = "essential"
    ransac_threshold_px: float = 1.0
    ransac_confidence: float = 0.999
    threshold_m: float | None = None
    min_inliers: int = 12
    max_jump: float = 0.03
    seed: int = 0

    def __post_init__(self) -> None:
        from flexreg.stages.keypoints import METHODS as FEATURES

        if self.image not in IMAGES:
            raise ConfigError(f"image: unknown feature image {self.image!r}; known: {_l(IMAGES)}")
        if isinstance(self.n, bool) or not isinstance(self.n, int) or self.n < 3 or self.n % 2 == 0:
            raise ConfigError(f"n: must be an odd grid size 3, 5, 7, ..., got {self.n!r}")
        if self.median not in (0, 3, 5) or isinstance(self.median, bool):
            raise ConfigError(f"median: must be 0 (off), 3 or 5, got {self.median!r}")
        if self.stretch not in (None, "clahe", "percentile"):
            raise ConfigError(
                f"stretch: must be None, 'clahe' or 'percentile', got {self.stretch!r}"
            )
        if self.features not in FEATURES:
            raise ConfigError(f"features: unknown method {self.features!r}; known: {_l(FEATURES)}")
        if self.method not in METHODS:
            raise ConfigError(f"method: unknown solver {self.method!r}; known: {_l(METHODS)}")
        if self.max_features is not None and self.max_features < 8:
            raise ConfigError(f"max_features: must be at least 8, got {self.max_features}")
        if self.border_px < 0 or not self.support >= 0:
            raise ConfigError(
                f"border_px and support must be non-negative, got {self.border_px}, {self.support}"
            )
        if not 0 < self.ratio <= 1:
            raise ConfigError(f"ratio: must be in (0, 1], got {self.ratio}")
        if not (math.isfinite(self.ransac_threshold_px) and self.ransac_threshold_px > 0):
            raise ConfigError(
                f"ransac_threshold_px: must be a positive number of pixels, "
                f"got {self.ransac_threshold_px}"
            )
        if not 0 < self.ransac_confidence < 1:
            raise ConfigError(f"ransac_confidence: must be in (0, 1), got {self.ransac_confidence}")
        if self.threshold_m is not None and not (
            math.isfinite(self.threshold_m) and self.threshold_m > 0
        ):
            raise ConfigError(
                f"threshold_m: must be a positive number of metres, got {self.threshold_m}"
            )
        if self.min_inliers < 5:
            raise ConfigError(f"min_inliers: must be at least 5, got {self.min_inliers}")
        if not self.max_jump > 0:
            raise ConfigError(f"max_jump: must be positive, got {self.max_jump}")
        if self.seed < 0:
            raise ConfigError(f"seed: must be a non-negative integer, got {self.seed}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
