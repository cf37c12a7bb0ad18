"""Every knob of :func:`flexreg.registration.register`, validated in one place."""

from __future__ import annotations

import math
import typing
from typing import Annotated

from pydantic import Field

from flexreg.config import Config, OddSize, Positive, Seed, ThresholdM, VoxelM, one_of
from flexreg.stages.feature_images import KINDS
from flexreg.stages.keypoints import METHODS
from flexreg.stages.refinement.icp import IcpMethod

#: feature images :func:`register` accepts: every kind of :data:`KINDS`, or the scan's intensity
IMAGES: tuple[str, ...] = (*KINDS, "intensity")
ICP_METHODS: tuple[str, ...] = typing.get_args(IcpMethod)
STRETCHES: tuple[str, ...] = ("clahe", "percentile")
MEDIANS: tuple[int, ...] = (0, 3, 5)
UPRIGHT: tuple[str, ...] = ("auto", "on", "off")

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
#: Sweep and twin slides, metres: a step finer than 5 cm moves the pose by less than the
#: dense check's tolerance (2.5 inlier thresholds) and the polishing ICP that follow capture,
#: so finer steps only judge the same pose again; a range beyond 50 m leaves the plan views'
#: 40 m reach, where no overlap is left to judge.
MIN_SLIDE_STEP_M, MAX_SLIDE_STEP_M, MAX_SLIDE_RANGE_M = 0.05, 5.0, 50.0


class RegistrationConfig(Config):
    """Every knob of :func:`register`; saved with each result.

    Attributes
    ----------
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
    icp_only : bool
        Refine the given initial transform (``register(..., init=T)``) only: no descriptor
        or plan-view search. Requires ``init``.
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
    min_overlap : float
        Smallest share of the source's points the result must explain, in [0, 1]; less raises
        :class:`RegistrationError` (no overlap). See :func:`overlap_score`.
    max_image_pixels : int, pixels
        Larger range images are subsampled (every k-th row and column) before the image
        stages. ICP still uses every point. Pixels, in [16 384, 50 000 000]
        (:data:`MIN_IMAGE_PIXELS`, :data:`MAX_IMAGE_PIXELS`).
    open3d_overlap_check : bool
        Also state Open3D's ``evaluate_registration`` fitness and inlier RMSE beside the
        overlap. The same figures computed independently (:mod:`flexreg.stages.overlap`).
        Off by default: it loads Open3D (0.2 GB and 0.6 s) into a call that has no other use
        for it; ``open3d_fitness`` and ``open3d_inlier_rmse_m`` are then null.
    polish : bool
        Judge each candidate after a quick local ICP on small subsets of the scans.
    aliases : bool
        Also try the twins of the best prior in repeating structure, so that the truth one
        bay or module beside a wrong answer competes. Twins: the pose moved by each
        symmetry of either scan's plan view, and by the offsets to the best other candidates
        the other way round (:func:`~flexreg.registration.candidates.alias_candidates`); the
        verdict duels the answer against every such twin.
    settle : bool
        Settle near-ties at full resolution (:mod:`flexreg.registration.settle`). When the
        winning pose has a weak translation axis or the target's plan repeats, candidates slid
        along that axis (and turned by the plan's self-overlays) join; clearly different
        candidates scoring close to the best then duel on every pixel of both scans, and one
        that beats all others decisively is the answer. Costs nothing on pairs without a weak
        axis, a repeat or a close rival.
    settle_open_share : float
        Share of both scans' points in the other's open space, at full resolution, from which
        a pose in a repeating plan with no close rival is still swept along the repeat. The
        plan repeats when the target's plan view overlays itself shifted by a bay; the pose
        explains at least ``verdict_min_overlap`` of the source's sample. Right poses
        leave 0.00-0.24 % there (every placed pair of the synthetic survey projects), a
        warehouse pair one bay off 1.1 %.
    sweep_axis_strength : float
        A translation direction weaker than this (per point, 0-1) is swept.
    sweep_range_m : float, metres
        How far either way the sweep slides the pose, in (0, 50]
        (:data:`MAX_SLIDE_RANGE_M`).
    sweep_step_m : float, metres
        Steps in which the sweep slides the pose, in [0.05, 5] (:data:`MIN_SLIDE_STEP_M`,
        :data:`MAX_SLIDE_STEP_M`).
    refine_guard : bool
        Keep the ICP refinement only when it scores at least as well as the coarse transform
        in the two-way dense check, less ``refine_guard_margin``; else keep the coarse
        transform. See :func:`~flexreg.stages.verification.soft_score` and
        docs/registration.md.
    refine_guard_margin : float
        How much lower (fraction of the sampled points) the refinement may score and still be
        kept. The check resolves the tolerance, not the millimetres ICP adds.
    verdict_min_overlap : float
        Share of each scan the other must explain at the fine tolerance, in [0, 1]; less
        gives the reason ``low_overlap``.
    verdict_max_conflict : float
        Largest share of either scan that may lie in the other's free space, in [0, 1]
        (``free_space``).
    verdict_max_conflict_ratio : float
        Largest share of either scan in the other's free space as a fraction of the share the
        other explains (``free_space``). A pose that contradicts half as much as it explains
        is not a fit, whatever the absolute shares.
    verdict_min_inliers : int
        Fewest agreeing feature matches (``few_inliers``; 0: not tested). Plan-view poses
        often rest on a handful of matches and the dense checks.
    verdict_min_inlier_spread : float
        Smallest second principal spread of the agreeing matches, as a fraction of the
        overlap's (``clustered_inliers``).
    verdict_min_axis_strength : float
        Smallest per-point strength of each pose parameter, 0-1 (``weak_axis``).
    verdict_ambiguity_ratio : float
        A clearly different pose scoring at least this fraction of the winner's score makes
        the answer ``ambiguous`` unless the answer beats it decisively
        (``verdict_decisive_share``).
    verdict_decisive_share : float
        Smallest lead, as a share of both scans' samples, by which the answer beats a
        runner-up decisively. The lead: the points the answer explains and the runner-up puts
        in free space, less the reverse; it must also be ``verdict_decisive_ratio`` times
        the reverse. One unique object (a cue) settles what the symmetric rest leaves open.
    verdict_decisive_ratio : float
        Smallest factor by which the answer's lead over a runner-up must outnumber the
        reverse to be decisive (see ``verdict_decisive_share``).
    verdict_full_decisive_share : float
        Smallest decisive lead at full resolution, as a share of all points of both scans
        checked, at the ratio ``verdict_decisive_ratio``. See
        :mod:`flexreg.registration.fullres`. A runner-up beaten so is no ambiguity, and a weak
        axis along which every slid pose was beaten so is settled.
    verdict_full_decisive_points : int
        Smallest decisive lead at full resolution in points, at the same ratio (0: off); the
        alternative to ``verdict_full_decisive_share``. A small cue
        holds a fixed number of pixels whatever the scans' size: a forklift two bays away
        leads by 13-53 points of 850 000 (1024 x 512), below the share, while the duels of
        empty tunnels, arcades and rooms leave 0-2 points either way.
    verdict_full_max_conflict : float
        Largest share of all points of both scans the answer itself may put in open space at
        full resolution for its full-resolution lead to count as decisive. A right pose puts
        almost none there; a wrong one puts the cue there, and beating other wrong poses does
        not make it right.
    verdict_full_max_open : float
        Largest share of all points of both scans an answer may put in the other's open space
        at full resolution before ``free_space``. Checked where the settling compared the
        scans there: a repeating plan, a weak axis or a close rival. Right poses put 0.00-0.24 %
        there on every placed pair of the synthetic survey projects; wrong ones in repeating
        halls 0.4-17 %.
    verdict_full_check : bool
        Check a confident answer at full resolution also where the settling did not compare
        the scans there. Costs both scans' full views once (about 0.3-0.6 s a pair at
        1024 x 512).
    verdict_full_max_open_check : float
        Largest share of both scans' points a confident answer may put in open space in the
        check of ``verdict_full_check``. Two identical rooms overlaid by a pose nine metres
        off put 4-8 % there while the samples' checks pass; right poses of real pairs
        0.2-0.35 % (3DTK, Velodyne, the bunny), and things that moved between the scans add
        to it.
    verdict_twins : bool
        Also slide a confident answer of two levelled scans along the target's wall
        directions and check where else it fits (:mod:`flexreg.registration.twins`). In a
        hall of identical bays an answer whole bays off fits as well as the truth, and only
        its twins give it away. Costs 0.1-0.2 s a pair at 1024 x 512.
    verdict_twin_min_ratio : float
        Share of what the answer explains from which a fitting twin makes the answer
        ``ambiguous``.
    verdict_twin_fit_open : float
        Largest share of both scans' points a twin may put in open space (or twice the
        answer's share) and still fit. The answer is ``ambiguous`` when a twin puts at most
        ``verdict_twin_fit_open`` of both scans' points in open space and explains at least
        ``verdict_twin_min_ratio`` of what the answer explains. On the synthetic survey
        projects no right answer of the accuracy set has such a twin (the best fitting one
        explains 0-8 % of what the answer does), while 91 of the 93 confident answers whole
        bays off on the 64-station warehouse have one (docs/benchmarks.md, Survey).
    verdict_twin_strong_ratio : float
        Share of what the answer explains under which a fitting twin also duels the answer on
        every pixel, and does not count when the answer beats it decisively. Decisively: by
        a forklift, a niche (:func:`~flexreg.registration.verdict.decisive_full`). A
        stronger twin counts whatever its duel: a neighbouring bay seen almost as well as
        the answer's, which the answer may beat by a hundred points of clutter while the
        truth lies bays further (warehouse 36, station_10 <- station_27). The wall direction
        the settling swept and won a tournament along is not slid at all.
    twin_range_m : float, metres
        How far either way the answer is slid to find its twins, in (0, 50], as for the sweep.
    twin_step_m : float, metres
        Steps in which the answer is slid to find its twins, in [0.05, 5], as for the sweep.
    verdict_distinct_deg : float, degrees
        How far a candidate must be turned from the answer to count as a different pose.
    verdict_distinct_m : float, metres
        How far a candidate must be moved from the answer to count as a different pose.
    verdict_max_rmse_ratio : float, inlier thresholds
        Largest final inlier RMSE (``high_residual``).
    """

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
    icp_only: bool = False
    upright: Annotated[str, one_of(UPRIGHT)] = "auto"
    max_tilt_rad: float = Field(math.radians(25.0), ge=0, lt=math.pi / 2)
    plan_cell_m: float = Field(0.25, ge=MIN_PLAN_CELL_M, le=MAX_PLAN_CELL_M, allow_inf_nan=False)
    plan_hypotheses: int = Field(3, ge=1, le=MAX_PLAN_HYPOTHESES)
    guided_radius_m: ThresholdM = 0.25
    guided_radius_per_m: float = Field(0.02, ge=0, le=1, allow_inf_nan=False)
    min_overlap: float = Field(0.1, ge=0, le=1)
    max_image_pixels: int = Field(2_500_000, ge=MIN_IMAGE_PIXELS, le=MAX_IMAGE_PIXELS)
    open3d_overlap_check: bool = False
    polish: bool = True
    aliases: bool = True
    settle: bool = True
    settle_open_share: float = Field(0.003, gt=0, le=1)
    sweep_axis_strength: float = Field(0.03, ge=0, le=1)
    sweep_range_m: float = Field(20.0, gt=0, le=MAX_SLIDE_RANGE_M, allow_inf_nan=False)
    sweep_step_m: float = Field(0.5, ge=MIN_SLIDE_STEP_M, le=MAX_SLIDE_STEP_M, allow_inf_nan=False)
    refine_guard: bool = True
    refine_guard_margin: float = Field(0.01, ge=0, le=1)
    verdict_min_overlap: float = Field(0.2, ge=0, le=1)
    verdict_max_conflict: float = Field(0.2, ge=0, le=1)
    verdict_max_conflict_ratio: Positive = 0.45
    verdict_min_inliers: int = Field(0, ge=0)
    verdict_min_inlier_spread: float = Field(0.05, ge=0, le=1)
    verdict_min_axis_strength: float = Field(0.01, ge=0, le=1)
    verdict_ambiguity_ratio: float = Field(0.6, gt=0, allow_inf_nan=False)
    verdict_decisive_share: float = Field(0.005, ge=0, le=1)
    verdict_decisive_ratio: Positive = 3.0
    verdict_full_decisive_share: float = Field(1e-4, ge=0, le=1)
    verdict_full_decisive_points: int = Field(10, ge=0)
    verdict_full_max_conflict: float = Field(1e-4, ge=0, le=1)
    verdict_full_max_open: float = Field(0.005, ge=0, le=1)
    verdict_full_check: bool = True
    verdict_full_max_open_check: float = Field(0.02, ge=0, le=1)
    verdict_twins: bool = True
    verdict_twin_min_ratio: float = Field(0.2, gt=0, le=1)
    verdict_twin_fit_open: float = Field(1e-3, ge=0, le=1)
    verdict_twin_strong_ratio: float = Field(0.4, gt=0, le=1)
    twin_range_m: float = Field(15.0, gt=0, le=MAX_SLIDE_RANGE_M, allow_inf_nan=False)
    twin_step_m: float = Field(0.25, ge=MIN_SLIDE_STEP_M, le=MAX_SLIDE_STEP_M, allow_inf_nan=False)
    verdict_distinct_deg: Positive = 3.0
    verdict_distinct_m: Positive = 0.5
    verdict_max_rmse_ratio: Positive = 1.0
