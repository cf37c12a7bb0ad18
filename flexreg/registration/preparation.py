"""What :class:`~flexreg.registration.pipeline.Registration` computes of one scan alone,
before any pair: the working range image, the feature image, keypoints and their 3D points,
the plan views, and the inputs of the checks and of the refinement (:class:`ScanView`,
:class:`PreparedScan`). :func:`~flexreg.registration.pipeline.register` runs the same
functions for its two scans.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import fft

from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan, as_points
from flexreg.errors import DegenerateGeometryError, FlexregError
from flexreg.registration.candidates import Keypoints3D
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.fullres import full_pair_of
from flexreg.stages import feature_images
from flexreg.stages.correspondences import lift
from flexreg.stages.keypoints import detect_and_describe, strip_rows
from flexreg.stages.normals import grid_normals
from flexreg.stages.overlap import keep_overlap_inputs
from flexreg.stages.priors import PlanView, plan_view
from flexreg.stages.projection import fill_holes, with_camera, working_image
from flexreg.stages.refinement import PROJECTIVE_ICP_POINTS, uses_projective
from flexreg.stages.sampling import area_sample_cell, area_sample_image
from flexreg.stages.verification import measured_image, range_slack

log = logging.getLogger(__name__)

#: points of the dense check (the source's even sample) and of the quick local ICP
CHECK_POINTS, POLISH_POINTS = 20_000, 5_000

Progress = Callable[[str], None] | None


def feature_image(
    image: RangeImage, config: RegistrationConfig = RegistrationConfig()
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image :func:`register` detects features on, and its valid mask:
    :func:`flexreg.stages.feature_images.feature_image` with the configured kind, ``n``,
    ``median`` and ``stretch`` (holes are filled earlier, on the range image)."""
    return feature_images.feature_image(
        image,
        kind=config.image,
        n=config.n,
        median=config.median,
        stretch=config.stretch,  # type: ignore[arg-type]
    )


# ------------------------------------------------------------------------------ per scan


@dataclass(eq=False)
class ScanView:
    """What the checks and the refinement need of one scan alone.

    Attributes
    ----------
    image : RangeImage
        The working range image with a camera model (re-projected when it had none).
    measured, slack : (H, W) float32 or None
        :func:`~flexreg.stages.verification.measured_image` and
        :func:`~flexreg.stages.verification.range_slack` of ``image`` (the dense checks; the
        verdict checks in both directions).
    normals : (H, W, 3) float32 or None
        :func:`~flexreg.stages.normals.grid_normals` of ``image`` (as target; as source for
        the projective refinement).
    sample : (N, 3) float64 or None
        Even sample of the working image for the dense checks (as source; as target for the
        verdict's check in the other direction).
    polish_sample : (N, 3) float64 or None
        As source: even sample for the quick ICP.
    refine_sample : (float, (M, 3) float64) or None
        The projective refinement's even sample of the whole scan and its cell, metres.
    """

    image: RangeImage
    measured: NDArray[np.float32] | None = None
    slack: NDArray[np.float32] | None = None
    normals: NDArray[np.float32] | None = None
    sample: NDArray[np.float64] | None = None
    polish_sample: NDArray[np.float64] | None = None
    refine_sample: tuple[float, NDArray[np.float64]] | None = None


@dataclass(eq=False)
class PreparedScan:
    """One scan prepared for :meth:`Registration.align` (numpy arrays only, picklable).

    Attributes
    ----------
    scan : Scan or RangeImage
        The scan as given (the Open3D refinements use all its points).
    image : RangeImage
        The working range image (holes filled when configured).
    keypoints : Keypoints3D
        Keypoints, descriptors and their 3D points.
    plan : PlanView, str or None
        The plan views, the reason there are none (the scan is not levelled, ...), or None
        when not computed (a pinhole scan without ``upright="on"``).
    view : ScanView
    config : RegistrationConfig
        The configuration it was prepared with (:meth:`Registration.align` needs the same).
    timings_s : dict
        Seconds per stage.
    """

    scan: Scan | RangeImage
    image: RangeImage
    keypoints: Keypoints3D
    plan: PlanView | str | None
    view: ScanView
    config: RegistrationConfig
    timings_s: dict[str, float] = field(default_factory=dict)


@contextmanager
def timed_stage(timings: dict[str, float], name: str) -> Iterator[None]:
    t = time.perf_counter()
    yield
    timings[name] = timings.get(name, 0.0) + time.perf_counter() - t


@dataclass(eq=False)
class Run:
    """Timings and progress of one call."""

    progress: Progress
    timings: dict[str, float] = field(default_factory=dict)
    start: float = field(default_factory=time.perf_counter)

    def stage(self, name: str) -> Any:
        self.wait(name)
        return timed_stage(self.timings, name)

    def wait(self, name: str) -> None:
        if self.progress is not None:
            self.progress(name)

    def background(self, name: str, fn: Callable[..., Any], *args: Any) -> Callable[[], Any]:
        """``fn(*args)`` for a background thread: single-threaded in numba (the threads fill
        the cores together instead of competing for them), timed as ``name``."""

        def job() -> Any:
            numba.set_num_threads(1)
            with timed_stage(self.timings, name), fft.set_workers(-1):
                return fn(*args)

        return job


def range_images_of(scans: list[Scan | RangeImage], config: RegistrationConfig) -> list[RangeImage]:
    """The working images: no stage maps their pixels back to point numbers, so their
    ``index`` is not kept (a read-only -1 view: 8 bytes per pixel less, 16 MB per
    2048 x 1024 image), nor their intensity unless the feature image reads it."""
    images = [working_image(x, max_pixels=config.max_image_pixels) for x in scans]
    images = [
        replace(
            i,
            index=np.broadcast_to(np.int64(-1), i.shape),
            intensity=i.intensity if config.image == "intensity" else None,
        )
        for i in images
    ]
    return [fill_holes(i) for i in images] if config.fill_holes else images


def keypoints_of(
    images: list[RangeImage], config: RegistrationConfig, run: Run
) -> list[Keypoints3D]:
    """Feature images, keypoints and descriptors, and their 3D points, stage by stage."""
    with run.stage("feature images"):
        converted = [feature_image(img, config) for img in images]
    with run.stage("features"):
        feats = [
            detect_and_describe(
                f,
                config.features,
                m,
                max_features=config.max_features,
                wrap=img.wraps,
                strip_rows=strip_rows(f.shape, config.feature_strip_pixels),
                tile_pixels=config.feature_tile_pixels or None,
            )
            for (f, m), img in zip(converted, images, strict=True)
        ]
    with run.stage("lifting"):
        lifted = [lift(img, f.xy) for img, f in zip(images, feats, strict=True)]
    return [Keypoints3D(f, x, ok) for f, (x, ok) in zip(feats, lifted, strict=True)]


def _plan_view(image: RangeImage, config: RegistrationConfig) -> PlanView | str:
    try:
        return plan_view(image, max_tilt_rad=config.max_tilt_rad, plan_cell_m=config.plan_cell_m)
    except DegenerateGeometryError as e:
        return str(e)


def plans_of(images: list[RangeImage], config: RegistrationConfig) -> list[PlanView | str]:
    return [_plan_view(img, config) for img in images]


def refinement_sample(
    scan: Scan | RangeImage, config: RegistrationConfig
) -> tuple[float, NDArray[np.float64]] | None:
    """The projective refinement's even sample of the whole scan and its cell (None when the
    refinement does not use one): the only part of a :class:`ScanView` that reads the scan's
    own points rather than its working image."""
    if not (config.refine and uses_projective(config.icp, config.voxel_m)):
        return None
    points = as_points(scan, name="scan", keep_float32=True)
    return area_sample_cell(points, PROJECTIVE_ICP_POINTS // 2)


def _scan_view(
    scan: Scan | RangeImage | None,
    image: RangeImage,
    config: RegistrationConfig,
    *,
    target: bool,
    source: bool,
) -> ScanView:
    """The parts of :class:`ScanView` the scan's roles need (the refinement's sample only
    with ``scan``: the caller computed it otherwise)."""
    v = ScanView(with_camera(image))
    projective = config.refine and uses_projective(config.icp, config.voxel_m)
    # both roles: the verdict checks the transform in both directions
    v.measured = measured_image(v.image)
    v.slack = range_slack(v.image, v.measured)
    if target or (source and projective):
        v.normals = grid_normals(v.image)
    v.sample = area_sample_image(image.xyz, image.valid, CHECK_POINTS)  # no copy of the points
    if source:
        v.polish_sample = area_sample_image(image.xyz, image.valid, POLISH_POINTS)
    if scan is not None:
        v.refine_sample = refinement_sample(scan, config)
    return v


def scan_views(
    scans: list[Scan | RangeImage] | list[None],
    images: list[RangeImage],
    config: RegistrationConfig,
    roles: list[tuple[bool, bool]],
) -> list[ScanView]:
    views = [
        _scan_view(x, img, config, target=t, source=s)
        for x, img, (t, s) in zip(scans, images, roles, strict=True)
    ]
    if roles == [(True, False), (False, True)] and None not in scans:  # register's pair
        _keep_overlap_inputs(scans)  # type: ignore[arg-type]
        if config.verdict_full_check:
            # the full-resolution views the verdict's check of a confident answer reads,
            # made here beside the feature stages instead of at the end of the call (kept
            # with these views: :func:`~flexreg.registration.fullres.full_pair_of`)
            full_pair_of(views)()
    return views


def _keep_overlap_inputs(scans: list[Scan | RangeImage]) -> None:
    """The overlap's inputs of a pair that do not depend on the transform (the target's scale
    voxel, both clouds' voxel centroids, the target's k-d tree), computed here, beside the
    feature stages, and kept by content for the overlap stage at the end of the call
    (:func:`~flexreg.stages.overlap.keep_overlap_inputs`: the figure is the same). A scan the
    overlap stage would refuse is left to it to refuse."""
    try:
        keep_overlap_inputs(
            as_points(scans[0], keep_float32=True), as_points(scans[1], keep_float32=True)
        )
    except FlexregError as e:
        log.debug("overlap inputs not computed ahead: %s", e)
