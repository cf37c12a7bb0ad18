"""Every knob of camera-lidar calibration, validated in one place."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from flexreg.errors import ConfigError


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of :func:`calibrate` (saved with every result).

    Attributes
    ----------
    threshold_px : float, pixels
        RANSAC inlier threshold on the reprojection error (full-resolution pixels).
    confidence : float
        RANSAC confidence in (0, 1).
    max_iterations : int
        RANSAC iteration cap.
    refine : bool
        Levenberg-Marquardt refinement on the inliers after RANSAC.
    seed : int
        Seed of OpenCV's USAC random generator (same seed, same result).
    init_rotation_deg, init_translation_m : float
        Automatic mode: how far the initial guess may be off (degrees, metres); sets the
        first search radius, and corrections beyond twice these are not accepted.
    auto_scale : float or None
        Automatic mode: scale of the working images relative to the camera image; None picks
        it from the lidar's angular density (about 1.75 pixels per lidar point spacing).
    auto_rounds : int
        Automatic mode: match-and-solve rounds, each with a smaller search radius.
    patch_px : int
        Automatic mode: side of the matched patches in working pixels (odd).
    max_keypoints : int
        Automatic mode: patches per round (strongest corners of the Flexion view).
    min_ncc : float
        Automatic mode: lowest normalised cross-correlation of a kept match.
    min_inliers : int
        Automatic mode: fewest PnP inliers for a round's result to be considered.
    max_spread_deg : float
        Automatic mode: largest median rotation between the chosen pose and the other rounds'
        poses (rounds 2, 3, ...); beyond it the matches are judged unreliable and the mode
        refuses.
    flexion_n : int
        Grid size n of the Flexion n x n images (odd, >= 3).
    """

    threshold_px: float = 3.0
    confidence: float = 0.9999
    max_iterations: int = 10000
    refine: bool = True
    seed: int = 0
    init_rotation_deg: float = 2.0
    init_translation_m: float = 0.10
    auto_scale: float | None = None
    auto_rounds: int = 6
    patch_px: int = 21
    max_keypoints: int = 800
    min_ncc: float = 0.3
    min_inliers: int = 12
    max_spread_deg: float = 1.0
    flexion_n: int = 3

    def __post_init__(self) -> None:
        def positive(name: str, value: float) -> None:
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number, got {value!r}")

        positive("threshold_px", self.threshold_px)
        positive("init_rotation_deg", self.init_rotation_deg)
        positive("init_translation_m", self.init_translation_m)
        positive("max_spread_deg", self.max_spread_deg)
        if not 0 < self.confidence < 1:
            raise ConfigError(f"confidence must be in (0, 1), got {self.confidence!r}")
        for name in ("max_iterations", "auto_rounds", "max_keypoints", "min_inliers"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        if self.auto_scale is not None and not (0 < self.auto_scale <= 1):
            raise ConfigError(f"auto_scale must be in (0, 1], got {self.auto_scale!r}")
        if self.patch_px < 7 or self.patch_px % 2 == 0:
            raise ConfigError(f"patch_px must be an odd size >= 7, got {self.patch_px!r}")
        if not -1 < self.min_ncc < 1:
            raise ConfigError(f"min_ncc must be in (-1, 1), got {self.min_ncc!r}")
        if self.flexion_n < 3 or self.flexion_n % 2 == 0:
            raise ConfigError(f"flexion_n must be an odd grid size >= 3, got {self.flexion_n!r}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of all fields."""
        return asdict(self)
