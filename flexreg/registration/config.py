"""Every knob of :func:`flexreg.registration.register`, validated in one place."""

from __future__ import annotations

import logging
import math
import typing
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, Field, field_validator, model_validator

from flexreg.config import Config, OddSize, Positive, Seed, ThresholdM, VoxelM, one_of
from flexreg.core.transforms import rotation_error_deg, translation_error_m
from flexreg.errors import ConfigError
from flexreg.stages.feature_images import KINDS
from flexreg.stages.keypoints import METHODS
from flexreg.stages.refinement.icp import IcpMethod

#: feature images :func:`register` accepts: every kind of :data:`KINDS`, or the scan's intensity
IMAGES: tuple[str, ...] = (*KINDS, "intensity")
ICP_METHODS: tuple[str, ...] = typing.get_args(IcpMethod)
STRETCHES: tuple[str, ...] = ("clahe", "percentile")
MEDIANS: tuple[int, ...] = (0, 3, 5)
UPRIGHT: tuple[str, ...] = ("auto", "on", "off")

#: where :func:`~flexreg.registration.register` takes its hypotheses from
REGISTRATION_METHODS: tuple[str, ...] = ("auto", "flexion", "geometric", "init")

log = logging.getLogger(__name__)

# Bounds of the knobs that set sizes, steps, cells and counts: each keeps a run's time and
# memory within what the stage was measured with, and is no finer than anything resolves.
#: Most keypoints kept per image: the SIFT descriptors (512 bytes each) of 200 000 take 0.1 GB
#: an image, and matching them takes time quadratic in their number.
MAX_FEATURES = 200_000
#: Range images (pixels) the image stages take: at least 128 x 128 (below it no detector finds
#: enough keypoints), at most 50 megapixels (a 10 000 x 5 000 panorama: its points alone, at
#: 24 bytes a pixel, take 1.2 GB).
MIN_IMAGE_PIXELS, MAX_IMAGE_PIXELS = 128 * 128, 50_000_000
#: RANSAC iteration cap: a million triplets take seconds; the adaptive stop ends runs with
#: 10 % inliers after about 9 200 at the default confidence (0.9999).
MAX_RANSAC_ITERATIONS = 1_000_000
#: Plan-view cell, metres: the fine plan has cells a quarter of it over a 20 m reach and the
#: coarse one covers 40 m, so 10 cm cells already make 1 600 x 1 600 fine cells; finer ones
#: draw the levelling error (about 7 cm at 40 m for 0.1 degrees of tilt), not the walls.
#: 2 m cells leave 40 cells across the coarse plan.
MIN_PLAN_CELL_M, MAX_PLAN_CELL_M = 0.1, 2.0
#: Plan overlays tried, each a guided matching and a dense check.
MAX_PLAN_HYPOTHESES = 50


#: The registration's own checks, each of which can be left out (``judge.checks``):
#: ``polish`` judges each candidate after a quick local ICP on small subsets of the scans;
#: ``aliases`` also tries the twins of the best prior in repeating structure (each symmetry of
#: either plan view, :func:`~flexreg.registration.candidates.alias_candidates`), so that the
#: truth one bay beside a wrong answer competes; ``settle`` settles near-ties at full
#: resolution (:mod:`flexreg.registration.settle`: candidates slid along a weak axis or a
#: repeat duel on every pixel); ``full`` checks a confident answer at full resolution also
#: where the settling did not compare the scans there (0.3-0.6 s a pair at 1024 x 512);
#: ``twins`` slides a confident answer of two levelled scans along the target's wall
#: directions and checks where else it fits (:mod:`flexreg.registration.twins`); ``guard``
#: keeps the ICP refinement only when the two-way dense check scores it at least as well as
#: the coarse transform (:data:`GUARD_MARGIN`); ``open3d`` (not by default) also states
#: Open3D's ``evaluate_registration`` fitness and inlier RMSE beside the overlap (it loads
#: Open3D, 0.2 GB and 0.6 s, into a call that has no other use for it).
CHECKS: tuple[str, ...] = ("polish", "aliases", "settle", "full", "twins", "guard", "open3d")
#: The checks that run unless ``judge.checks`` says otherwise (every one but ``open3d``).
DEFAULT_CHECKS: tuple[str, ...] = CHECKS[:-1]

# Fixed parts of the judge, each measured on the synthetic and real pairs of the verdict and
# survey benchmarks (docs/benchmarks.md, "Verdict" and "Survey", say on which).
#: How much lower (share of the sampled points) the refinement may score than the coarse
#: transform and still be kept (``guard``): the check resolves the tolerance, not the
#: millimetres ICP adds.
GUARD_MARGIN = 0.01
#: Sweep of a weak axis or a repeat (:mod:`flexreg.registration.settle`): how far either way
#: and in which steps, metres.
SWEEP_RANGE_M, SWEEP_STEP_M = 20.0, 0.5
#: Slide of a confident answer along the walls (:mod:`flexreg.registration.twins`), metres.
TWIN_RANGE_M, TWIN_STEP_M = 15.0, 0.25
#: Smallest lead of a decisive duel on the samples, as a share of both samples; at full
#: resolution as a share of all points checked, or as a count of points (a small cue holds a
#: fixed number of pixels whatever the scans' size: a forklift two bays away leads by 13-53
#: points of 850 000 at 1024 x 512, while the duels of empty tunnels, arcades and rooms
#: leave 0-2 points either way).
DECISIVE_SHARE, FULL_DECISIVE_SHARE, FULL_DECISIVE_POINTS = 0.005, 1e-4, 10
#: Smallest second principal spread of the agreeing feature matches, as a fraction of the
#: overlap's (``clustered_inliers``).
MIN_INLIER_SPREAD = 0.05
#: Largest final inlier RMSE, in inlier thresholds (``high_residual``).
MAX_RMSE_RATIO = 1.0
#: A fitting twin makes the answer ambiguous from this share of what the answer explains;
#: under the strong share it must also survive a duel on every pixel.
TWIN_MIN_RATIO, TWIN_STRONG_RATIO = 0.2, 0.4

#: ``judge.open_share`` at which the open-space limits below were measured; each scales with
#: it (the ratios are the measurements').
OPEN_SHARE = 0.005
#: ``judge.min_axis_strength`` at which :data:`SWEEP_AXIS_STRENGTH` was measured.
MIN_AXIS_STRENGTH = 0.01
#: A translation direction weaker than this (per point) is swept, at the default
#: ``judge.min_axis_strength`` (three times it).
SWEEP_AXIS_STRENGTH = 0.03


class PriorConfig(Config):
    """The levelled-scanner prior: plan views overlaid to guide matching
    (:mod:`flexreg.stages.priors`).

    Attributes
    ----------
    upright : {"auto", "on", "off"}
        Levelled-scanner prior: overlay the scans' plan views to guide matching (``"auto"``:
        when both look levelled; ``"on"``: required). Each scan's vertical is estimated, the
        plan views overlaid (:mod:`flexreg.stages.priors`) and the best overlays guide
        matching. ``"auto"`` uses it when both scans are panoramas or native grids that look
        levelled.
    max_tilt_rad : float, radians
        Largest tilt of a scan still treated as levelled, in [0, pi/2) (default 25°). The
        vertical is estimated reliably up to about that
        (:data:`flexreg.stages.priors.MAX_TILT_RAD`). A scan tilted more gets no plan-view
        prior; the reason, with its measured tilt, is in the error message when registration
        fails (and ``upright="on"`` fails with it).
    plan_cell_m : float, metres
        Plan-view cell size, in [0.1, 2] m (:data:`MIN_PLAN_CELL_M`, :data:`MAX_PLAN_CELL_M`).
    plan_hypotheses : int
        Plan overlays tried (best first), in [1, :data:`MAX_PLAN_HYPOTHESES`] (50).
    guided_radius_m : float, metres
        Guided matching search radius around a prior's prediction, in (0, 5] (a window wider
        than the largest inlier distance guides nothing).
    guided_radius_per_m : float, metres per metre of range
        Guided matching search radius added per metre of range, in [0, 1] (1: a cone of 45
        degrees).
    """

    upright: Annotated[str, one_of(UPRIGHT)] = "auto"
    max_tilt_rad: float = Field(math.radians(25.0), ge=0, lt=math.pi / 2)
    plan_cell_m: float = Field(0.25, ge=MIN_PLAN_CELL_M, le=MAX_PLAN_CELL_M, allow_inf_nan=False)
    plan_hypotheses: int = Field(3, ge=1, le=MAX_PLAN_HYPOTHESES)
    guided_radius_m: ThresholdM = 0.25
    guided_radius_per_m: float = Field(0.02, ge=0, le=1, allow_inf_nan=False)


class JudgeConfig(Config):
    """The judge of a registration: which checks run and the thresholds of the verdict
    (:mod:`flexreg.registration.verdict`). Shares are of a scan's even sample, except
    ``open_share`` (of all points of both scans, at full resolution).

    The other limits are fixed (the module constants above) or follow these fields: the
    full-resolution open-space limits scale with ``open_share`` (:attr:`settle_open_share`,
    :attr:`full_max_open_check`, :attr:`full_max_conflict`, :attr:`twin_fit_open`), the
    sweep's axis strength with ``min_axis_strength`` (:attr:`sweep_axis_strength`).

    Attributes
    ----------
    checks : list of str
        The checks that run, any of :data:`CHECKS`: ``polish``, ``aliases``, ``settle``,
        ``full``, ``twins``, ``guard`` (default: all of them), and ``open3d`` (not by default).
    min_overlap : float
        Share of each scan the other must explain at the fine tolerance, in [0, 1]; less
        gives the reason ``low_overlap``.
    max_free_space : float
        Largest share of either scan that may lie in the other's free space, in [0, 1]
        (``free_space``).
    max_free_space_ratio : float
        Largest share of either scan in the other's free space as a fraction of the share the
        other explains (``free_space``): a pose that contradicts half as much as it explains
        is not a fit, whatever the absolute shares.
    open_share : float
        Largest share of all points of both scans an answer may put in the other's open space
        at full resolution, where the settling compared the scans there (a repeating plan, a
        weak axis or a close rival), in [0, 1] (``free_space``). Right poses put 0.00-0.24 %
        there on every placed pair of the synthetic survey projects, wrong ones in repeating
        halls 0.4-17 %. A confident answer checked anyway (``full``) may put 4 times as much
        there (things that moved between the scans add to it).
    min_axis_strength : float
        Smallest per-point strength of each pose parameter, 0-1 (``weak_axis``).
    ambiguity_ratio : float
        A clearly different pose scoring at least this fraction of the winner's score makes
        the answer ``ambiguous`` unless the answer beats it decisively.
    decisive_ratio : float
        Smallest factor by which the answer's lead over a runner-up in their duel (the points
        it explains and the runner-up puts in free space) must outnumber the reverse to be
        decisive; the lead must also reach :data:`DECISIVE_SHARE` of both samples.
    distinct_deg : float, degrees
        How far a candidate must be turned from the answer to count as a different pose.
    distinct_m : float, metres
        How far a candidate must be moved from the answer to count as a different pose.
    """

    checks: tuple[Annotated[str, one_of(CHECKS, "check")], ...] = DEFAULT_CHECKS
    min_overlap: float = Field(0.2, ge=0, le=1)
    max_free_space: float = Field(0.2, ge=0, le=1)
    max_free_space_ratio: Positive = 0.45
    open_share: float = Field(OPEN_SHARE, ge=0, le=1)
    min_axis_strength: float = Field(MIN_AXIS_STRENGTH, ge=0, le=1)
    ambiguity_ratio: float = Field(0.6, gt=0, allow_inf_nan=False)
    decisive_ratio: Positive = 3.0
    distinct_deg: Positive = 3.0
    distinct_m: Positive = 0.5

    @field_validator("checks")
    @classmethod
    def _unique(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(v)) != len(v):
            raise ValueError("names a check twice")
        return v

    def distinct(self, A: NDArray[np.float64], B: NDArray[np.float64]) -> bool:
        """Whether two poses (4 x 4 ``T_target_source``) are clearly different: more than
        ``distinct_deg`` turned or ``distinct_m`` moved from each other. The one definition
        the candidates, the settling and the evidence share."""
        return (
            rotation_error_deg(A, B) > self.distinct_deg
            or translation_error_m(A, B) > self.distinct_m
        )

    def runs(self, check: str) -> bool:
        """Whether ``check`` (one of :data:`CHECKS`) runs."""
        return check in self.checks

    def _scaled(self, at_default: float) -> float:
        """An open-space limit measured at :data:`OPEN_SHARE`, at this ``open_share``."""
        return at_default * (self.open_share / OPEN_SHARE)

    @property
    def settle_open_share(self) -> float:
        """Share of both scans' points in the other's open space, at full resolution, from
        which a pose in a repeating plan with no close rival is still swept along the repeat
        (0.003 at the default ``open_share``: a warehouse pair one bay off leaves 1.1 %)."""
        return self._scaled(0.003)

    @property
    def full_max_open_check(self) -> float:
        """Largest open-space share of a confident answer checked at full resolution where
        the settling did not compare the scans (``full``; 0.02 at the default: two identical
        rooms overlaid nine metres off put 4-8 % there, right poses of real pairs
        0.2-0.35 %)."""
        return self._scaled(0.02)

    @property
    def full_max_conflict(self) -> float:
        """Largest open-space share of an answer whose full-resolution lead counts as
        decisive (1e-4 at the default: a right pose puts almost none there)."""
        return self._scaled(1e-4)

    @property
    def twin_fit_open(self) -> float:
        """Largest open-space share (or twice the answer's) of a twin that fits (1e-3 at the
        default: no right answer of the accuracy set has such a twin, 91 of the 93 confident
        answers whole bays off on the 64-station warehouse have one)."""
        return self._scaled(1e-3)

    @property
    def sweep_axis_strength(self) -> float:
        """A translation direction weaker than this (per point) is swept
        (:data:`SWEEP_AXIS_STRENGTH` at the default ``min_axis_strength``)."""
        return SWEEP_AXIS_STRENGTH * (self.min_axis_strength / MIN_AXIS_STRENGTH)


class RegistrationConfig(Config):
    """Every knob of :func:`register`; saved with each result. The front end's knobs (the
    paper's: images, features, matching, RANSAC, ICP) are plain fields; the levelled-scanner
    prior and the judge are the tables ``prior`` and ``judge``.

    Keys of the flat layout before the tables (``upright``, ``verdict_min_overlap``,
    ``polish``, ...) are still read, with a deprecation warning, for one release
    (:data:`RENAMED`, :data:`AS_CHECKS`, :data:`RETIRED`).

    Attributes
    ----------
    method : {"auto", "flexion", "geometric", "init"}
        Where the hypotheses come from: ``"flexion"`` the feature images (and the plan
        views of levelled scanners); ``"geometric"`` FPFH descriptors of the clouds, made
        consistent and solved by RANSAC (:mod:`flexreg.stages.geometric`); ``"auto"`` the
        feature images alone for two panoramic stations (read with their grids) on which
        they find a prior, both routes judged together on every other pair (an object
        scanned from outside, a narrow-field lidar frame, a fragment, a depth image, or a
        station the feature images find nothing on); ``"init"`` the given initial transform only
        (``register(..., init=T)``, refined by ICP: no search; the ``icp_only`` switch of
        earlier releases). Every hypothesis is judged by the same dense check and verdict.
    image : str
        Feature image kind, one of :data:`flexreg.stages.feature_images.KINDS` or
        ``"intensity"``.
    n : int, pixels
        Flexion / Bearing Angle neighbourhood size (odd, >= 3).
    median : {0, 3, 5}
        Median pre-filter window (0: off).
    stretch : {"clahe", "percentile"} or None
        Contrast normalisation before detection (None: none).
    features : str
        Detector/descriptor: sift, orb, akaze, kaze, brisk (surf on nonfree OpenCV).
    max_features : int
        Strongest keypoints kept per image, in [8, :data:`MAX_FEATURES`] (200 000).
    feature_strip_pixels : int, pixels
        SIFT on a larger image runs in horizontal strips of about this many pixels each (0:
        always the whole image). Plus margins
        (:func:`flexreg.stages.keypoints.detect_and_describe` ``strip_rows``), so only
        one strip's scale space is in memory: 0.18 GB instead of 0.47 GB for a 2048 x 1024
        image, for about 40 % more detection time. Pixels, at most
        :data:`MAX_IMAGE_PIXELS` (strips are at least 64 rows high whatever the value).
    feature_tile_pixels : int, pixels
        When above 0, SIFT runs in square tiles of at most this many pixels each instead of
        strips. Plus margins (:func:`flexreg.stages.keypoints.tiles`): 196 608 keeps about 0.045 GB
        of scale space for a 2048 x 1024 image (0.2 GB less than the strips) and finds 98 % of
        its keypoints. Not the default: it changes the keypoints of 1024 x 512 images too,
        and the survey and verdict benchmarks were measured with the strips. Pixels, at most
        :data:`MAX_IMAGE_PIXELS` (tiles are at least 64 pixels a side whatever the value).
    ratio : float
        Lowe's ratio-test threshold, in (0, 1].
    mutual : bool
        Mutual nearest-neighbour check.
    threshold_m : float or None, metres
        RANSAC inlier distance; derived from the scans' pixel footprint when None.
    threshold_px : float, pixel footprints
        RANSAC inlier distance when ``threshold_m`` is None (keypoint localisation error).
    consistency : bool
        Prune correspondences by pairwise-distance consistency before RANSAC.
    min_inliers : int
        Fewer RANSAC inliers raise :class:`RegistrationError` (>= 3).
    confidence : float
        RANSAC stopping confidence, in (0, 1).
    max_iterations : int
        RANSAC iteration cap, a count of sampled triplets, in
        [1, :data:`MAX_RANSAC_ITERATIONS`] (1 000 000).
    refine : bool
        Refine with ICP.
    icp : {"point-to-plane", "gicp", "point-to-point"}
        ICP variant.
    voxel_m : float or None, metres
        ICP voxel; derived from point spacing when None.
    seed : int
        Randomness (RANSAC sampling); same seed, same transform.
    fill_holes : bool
        Fill isolated no-return pixels before the conversion
        (:func:`flexreg.stages.projection.fill_holes`).
    min_overlap : float
        Smallest share of the source's points the result must explain, in [0, 1]; less raises
        :class:`RegistrationError` (no overlap). See :func:`overlap_score`.
    max_image_pixels : int, pixels
        Larger range images are subsampled (every k-th row and column) before the image
        stages. ICP still uses every point. Pixels, in [16 384, 50 000 000]
        (:data:`MIN_IMAGE_PIXELS`, :data:`MAX_IMAGE_PIXELS`).
    prior : PriorConfig
        The levelled-scanner prior.
    judge : JudgeConfig
        Which checks run and the verdict's thresholds.
    """

    method: Annotated[str, one_of(REGISTRATION_METHODS, "method")] = "auto"
    image: Annotated[str, one_of(IMAGES, "feature image")] = "flexion"
    n: OddSize = 5
    median: Annotated[int, one_of(MEDIANS)] = 3
    stretch: Annotated[str, one_of(STRETCHES)] | None = "clahe"
    features: Annotated[str, one_of(METHODS, "method")] = "sift"
    max_features: int = Field(8000, ge=8, le=MAX_FEATURES)
    feature_strip_pixels: int = Field(524_288, ge=0, le=MAX_IMAGE_PIXELS)
    feature_tile_pixels: int = Field(0, ge=0, le=MAX_IMAGE_PIXELS)
    ratio: float = Field(0.85, gt=0, le=1)
    mutual: bool = True
    threshold_m: ThresholdM | None = None
    threshold_px: Positive = 3.0
    consistency: bool = True
    min_inliers: int = Field(10, ge=3)
    confidence: float = Field(0.9999, gt=0, lt=1)
    max_iterations: int = Field(50_000, ge=1, le=MAX_RANSAC_ITERATIONS)
    refine: bool = True
    icp: Annotated[str, one_of(ICP_METHODS, "method")] = "point-to-plane"
    voxel_m: VoxelM | None = None
    seed: Seed = 0
    fill_holes: bool = True
    min_overlap: float = Field(0.1, ge=0, le=1)
    max_image_pixels: int = Field(2_500_000, ge=MIN_IMAGE_PIXELS, le=MAX_IMAGE_PIXELS)
    prior: PriorConfig = PriorConfig()
    judge: JudgeConfig = JudgeConfig()

    @model_validator(mode="before")
    @classmethod
    def _flat_keys(cls, data: Any) -> Any:
        return nest_flat_keys(data) if isinstance(data, dict) else data

    @property
    def icp_only(self) -> bool:
        """Whether the given initial transform is the only hypothesis (``method="init"``)."""
        return self.method == "init"


#: Flat keys of the layout before the ``prior`` and ``judge`` tables -> where they are now.
RENAMED: dict[str, str] = {
    **{k: f"prior.{k}" for k in PriorConfig.model_fields},
    "verdict_min_overlap": "judge.min_overlap",
    "verdict_max_conflict": "judge.max_free_space",
    "verdict_max_conflict_ratio": "judge.max_free_space_ratio",
    "verdict_full_max_open": "judge.open_share",
    "verdict_min_axis_strength": "judge.min_axis_strength",
    "verdict_ambiguity_ratio": "judge.ambiguity_ratio",
    "verdict_decisive_ratio": "judge.decisive_ratio",
    "verdict_distinct_deg": "judge.distinct_deg",
    "verdict_distinct_m": "judge.distinct_m",
}
#: Flat switches of the old layout -> the check of ``judge.checks`` they turn on or off.
AS_CHECKS: dict[str, str] = {
    "polish": "polish",
    "aliases": "aliases",
    "settle": "settle",
    "verdict_full_check": "full",
    "verdict_twins": "twins",
    "refine_guard": "guard",
    "open3d_overlap_check": "open3d",
}
#: Thresholds of the old layout that are fixed or follow another field now: their value
#: then, and what holds it now. Read at that value (it changes nothing); refused otherwise.
RETIRED: dict[str, tuple[float, str]] = {
    "verdict_min_inliers": (0, "min_inliers holds the feature matches' minimum"),
    "verdict_min_inlier_spread": (MIN_INLIER_SPREAD, "fixed"),
    "verdict_decisive_share": (DECISIVE_SHARE, "fixed"),
    "verdict_full_decisive_share": (FULL_DECISIVE_SHARE, "fixed"),
    "verdict_full_decisive_points": (FULL_DECISIVE_POINTS, "fixed"),
    "verdict_full_max_conflict": (1e-4, "follows judge.open_share: 1/50 of it"),
    "verdict_full_max_open_check": (0.02, "follows judge.open_share: 4 times it"),
    "settle_open_share": (0.003, "follows judge.open_share: 0.6 times it"),
    "verdict_twin_fit_open": (1e-3, "follows judge.open_share: 1/5 of it"),
    "verdict_twin_min_ratio": (TWIN_MIN_RATIO, "fixed"),
    "verdict_twin_strong_ratio": (TWIN_STRONG_RATIO, "fixed"),
    "sweep_axis_strength": (SWEEP_AXIS_STRENGTH, "follows judge.min_axis_strength: 3 times it"),
    "sweep_range_m": (SWEEP_RANGE_M, "fixed"),
    "sweep_step_m": (SWEEP_STEP_M, "fixed"),
    "twin_range_m": (TWIN_RANGE_M, "fixed"),
    "twin_step_m": (TWIN_STEP_M, "fixed"),
    "refine_guard_margin": (GUARD_MARGIN, "fixed"),
    "verdict_max_rmse_ratio": (MAX_RMSE_RATIO, "fixed"),
}


def nest_flat_keys(data: dict[str, Any]) -> dict[str, Any]:
    """A registration configuration's mapping with the old flat keys in their tables.

    Each old key logs one deprecation warning naming its new place. A retired threshold
    (:data:`RETIRED`) given at its old value is dropped; at another value it is refused.

    >>> nest_flat_keys({"n": 7, "verdict_min_overlap": 0.3})
    {'n': 7, 'judge': {'min_overlap': 0.3}}
    >>> nest_flat_keys({"icp_only": True})
    {'method': 'init'}
    >>> nest_flat_keys({"verdict_twins": False})["judge"]["checks"]
    ('polish', 'aliases', 'settle', 'full', 'guard')
    """
    if "icp_only" in data:  # a switch of earlier releases: the method "init" now
        value = data["icp_only"]
        data = {k: v for k, v in data.items() if k != "icp_only"}
        if value if isinstance(value, bool) else str(value).lower() in ("true", "1", "yes"):
            data["method"] = "init"
        log.warning('setting icp_only is deprecated: it is method = "init" now')
    old = [k for k in data if k in RENAMED or k in AS_CHECKS or k in RETIRED]
    if not old:
        return data
    out = {k: v for k, v in data.items() if k not in old}
    tables = {t: dict(out.get(t) or {}) for t in ("prior", "judge")}
    for key in old:
        value = data[key]
        if key in RENAMED:
            table, _, field = RENAMED[key].partition(".")
            tables[table][field] = value
            log.warning("setting %s is deprecated: it is %s now", key, RENAMED[key])
        elif key in AS_CHECKS:
            checks = list(tables["judge"].get("checks", DEFAULT_CHECKS))
            name = AS_CHECKS[key]
            on = value if isinstance(value, bool) else str(value).lower() in ("true", "1", "yes")
            checks = [c for c in checks if c != name] + ([name] if on else [])
            tables["judge"]["checks"] = tuple(c for c in CHECKS if c in checks)
            log.warning(
                "setting %s is deprecated: it is %r %s judge.checks now",
                key,
                name,
                "in" if on else "left out of",
            )
        else:
            was, now = RETIRED[key]
            try:
                same = float(value) == float(was)
            except (TypeError, ValueError):
                same = False
            if not same:
                raise ConfigError(
                    f"{key}: no longer a setting ({now}; it was {was:g}): cannot be {_shown(value)}"
                )
            log.warning("setting %s is deprecated: no longer a setting (%s)", key, now)
    out.update({t: v for t, v in tables.items() if v})
    return out


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def leaf_fields(cls: type[BaseModel]) -> list[str]:
    """Every field of a configuration, its tables' fields as ``table.field`` (what a user
    may set).

    >>> len(leaf_fields(PriorConfig))
    6
    """
    out: list[str] = []
    for name, f in cls.model_fields.items():
        inner = f.annotation
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            out += [f"{name}.{x}" for x in leaf_fields(inner)]
        else:
            out.append(name)
    return out


__all__ = [
    "AS_CHECKS",
    "CHECKS",
    "DECISIVE_SHARE",
    "DEFAULT_CHECKS",
    "FULL_DECISIVE_POINTS",
    "FULL_DECISIVE_SHARE",
    "GUARD_MARGIN",
    "ICP_METHODS",
    "IMAGES",
    "MAX_IMAGE_PIXELS",
    "MAX_PLAN_CELL_M",
    "MAX_PLAN_HYPOTHESES",
    "MAX_RMSE_RATIO",
    "MEDIANS",
    "MIN_IMAGE_PIXELS",
    "MIN_INLIER_SPREAD",
    "MIN_PLAN_CELL_M",
    "RENAMED",
    "RETIRED",
    "STRETCHES",
    "SWEEP_AXIS_STRENGTH",
    "SWEEP_RANGE_M",
    "SWEEP_STEP_M",
    "TWIN_MIN_RATIO",
    "TWIN_RANGE_M",
    "TWIN_STEP_M",
    "TWIN_STRONG_RATIO",
    "UPRIGHT",
    "JudgeConfig",
    "PriorConfig",
    "RegistrationConfig",
    "leaf_fields",
    "nest_flat_keys",
]
