"""Every knob of :func:`flexreg.registration.register`, validated in one place."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class RegistrationConfig:
    """Every knob of :func:`register`; saved with each result.

    Attributes
    ----------
    image : str
        Feature image kind (see :data:`flexreg.stages.feature_images.KINDS`), or ``"intensity"``.
    n : int
        Flexion / Bearing Angle neighbourhood size (odd).
    median : int
        Median pre-filter window (0, 3 or 5).
    stretch : str or None
        Contrast normalisation before detection: ``"clahe"``, ``"percentile"`` or None.
    features : str
        Detector/descriptor: sift, orb, akaze, kaze, brisk (surf on nonfree OpenCV).
    max_features : int
        Strongest keypoints kept per image.
    ratio : float
        Lowe's ratio-test threshold.
    mutual : bool
        Mutual nearest-neighbour check.
    threshold_m : float or None
        RANSAC inlier distance; derived from the scans' pixel footprint when None.
    threshold_px : float
        Derived threshold in pixel footprints (keypoint localisation error).
    consistency : bool
        Prune correspondences by pairwise-distance consistency before RANSAC.
    min_inliers : int
        Fewer RANSAC inliers raise :class:`RegistrationError`.
    confidence, max_iterations : float, int
        RANSAC stopping.
    refine : bool
        Refine with ICP.
    icp : str
        ``"point-to-plane"``, ``"gicp"`` or ``"point-to-point"``.
    voxel_m : float or None
        ICP voxel; derived from point spacing when None.
    seed : int
        Randomness (RANSAC sampling); same seed, same transform.
    fill_holes : bool
        Fill isolated no-return pixels before the conversion
        (:func:`flexreg.stages.projection.fill_holes`).
    upright : {"auto", "on", "off"}
        Levelled-scanner prior: estimate each scan's vertical, overlay their plan views
        (:mod:`flexreg.stages.priors`) and use the best overlays to guide matching. ``"auto"`` uses
        it
        when both scans are panoramas or native grids that look levelled, ``"on"`` requires it.
    max_tilt_rad : float, radians
        Largest tilt of a scan still treated as levelled.
    plan_cell_m : float, metres
        Plan-view cell size.
    plan_hypotheses : int
        Plan overlays tried (best first).
    guided_radius_m, guided_radius_per_m : float
        Guided matching search radius around a prior's prediction: metres plus metres per
        metre of range.
    max_image_pixels : int
        Larger range images are subsampled (every k-th row and column) before the image
        stages; ICP still uses every point.
    polish : bool
        Judge each candidate after a quick local ICP on small subsets of the scans.
    min_overlap : float
        Smallest share of the source's points the result must explain (see
        :func:`overlap_score`); less raises :class:`RegistrationError` (no overlap).
    """

    image: str = "flexion"
    n: int = 5
    median: int = 3
    stretch: str | None = "clahe"
    features: str = "sift"
    max_features: int = 8000
    ratio: float = 0.85
    mutual: bool = True
    threshold_m: float | None = None
    threshold_px: float = 3.0
    consistency: bool = True
    min_inliers: int = 10
    confidence: float = 0.9999
    max_iterations: int = 50_000
    refine: bool = True
    icp: str = "point-to-plane"
    voxel_m: float | None = None
    seed: int = 0
    fill_holes: bool = True
    upright: str = "auto"
    max_tilt_rad: float = math.radians(10.0)
    plan_cell_m: float = 0.25
    plan_hypotheses: int = 3
    guided_radius_m: float = 0.25
    guided_radius_per_m: float = 0.02
    min_overlap: float = 0.1
    max_image_pixels: int = 2_500_000
    polish: bool = True

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
