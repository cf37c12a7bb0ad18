"""What :class:`~flexreg.registration.pipeline.Registration` computes of one scan alone,
before any pair: the working range image, the feature image, keypoints and their 3D points,
the plan views, and the inputs of the checks and of the refinement (:class:`ScanView`,
:class:`PreparedScan`). :func:`~flexreg.registration.pipeline.register` runs the same
functions for its two scans.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, replace
from pathlib import Path, PurePath
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import fft

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan, as_points
from flexreg.errors import DegenerateGeometryError, FlexregError
from flexreg.registration.candidates import Keypoints3D
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.fullres import full_pair_of
from flexreg.stages import feature_images
from flexreg.stages.correspondences import lift
from flexreg.stages.keypoints import Features, detect_and_describe, strip_rows
from flexreg.stages.levelling import Levelling
from flexreg.stages.normals import grid_normals
from flexreg.stages.overlap import keep_overlap_inputs
from flexreg.stages.priors import PlanView, TopView, plan_view
from flexreg.stages.projection import fill_holes, sampling_gaps, with_camera, working_image
from flexreg.stages.refinement import PROJECTIVE_ICP_POINTS, uses_projective
from flexreg.stages.sampling import area_sample_cell, area_sample_image
from flexreg.stages.verification import measured_image, range_slack
from flexreg.stages.viewpoint import hidden_share

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
    gaps : bool
        A cloud without a native grid whose image has
        :func:`~flexreg.stages.projection.sampling_gaps` (projected at its own density: a
        rosette, a fused fragment): its empty pixels are directions never sampled (the
        full-resolution open-space test, :func:`~flexreg.registration.fullres.full_view`),
        and the refinement pairs nearest points instead of pixels. A native grid's empty
        pixels are rays that returned nothing, whatever their pattern.
    hidden : float or None
        The share of a cloud's points that lie behind its own from its origin
        (:func:`~flexreg.stages.viewpoint.hidden_share`); None for a grid (one viewpoint by
        construction) or a scan not at hand. Beyond
        :data:`~flexreg.stages.viewpoint.MAX_HIDDEN_SHARE` the cloud was not taken from one
        point, and nothing is known to be open space in its view.
    """

    image: RangeImage
    measured: NDArray[np.float32] | None = None
    slack: NDArray[np.float32] | None = None
    normals: NDArray[np.float32] | None = None
    sample: NDArray[np.float64] | None = None
    polish_sample: NDArray[np.float64] | None = None
    refine_sample: tuple[float, NDArray[np.float64]] | None = None
    gaps: bool = False
    hidden: float | None = None


@dataclass(eq=False)
class PreparedScan:
    """One scan prepared for :meth:`Registration.align` (numpy arrays only: picklable for
    Dask, and stored as plain data by :func:`prepared_to_arrays`).

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
    symmetries : list of (4, 4) float64, or None
        The poses that overlay the plan view onto itself
        (:func:`~flexreg.registration.candidates.self_symmetries`), when the judge looks for
        aliases and the scan has a plan view: one scan's, found once with it rather than in
        each of its links (about a second at 1024 x 512).
    """

    scan: Scan | RangeImage
    image: RangeImage
    keypoints: Keypoints3D
    plan: PlanView | str | None
    view: ScanView
    config: RegistrationConfig
    timings_s: dict[str, float] = field(default_factory=dict)
    symmetries: list[NDArray[np.float64]] | None = None


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
        prior = config.prior
        return plan_view(image, max_tilt_rad=prior.max_tilt_rad, plan_cell_m=prior.plan_cell_m)
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
    # a native grid (no camera of its own: its pixels are the scanner's rays) has no gaps
    v.gaps = image.camera is not None and sampling_gaps(image.valid, image.wraps)
    projective = config.refine and uses_projective(config.icp, config.voxel_m) and not v.gaps
    # both roles: the verdict checks the transform in both directions
    v.measured = measured_image(v.image)
    v.slack = range_slack(v.image, v.measured)
    if target or (source and projective):
        v.normals = grid_normals(v.image)
    v.sample = area_sample_image(image.xyz, image.valid, CHECK_POINTS)  # no copy of the points
    if source:
        v.polish_sample = area_sample_image(image.xyz, image.valid, POLISH_POINTS)
    if scan is not None and not v.gaps:
        v.refine_sample = refinement_sample(scan, config)
    if isinstance(scan, Scan) and not scan.has_grid and len(scan):
        v.hidden = hidden_share(scan.points)
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
        if config.judge.runs("full"):
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


# ------------------------------------------------------------------------------ as plain data

#: the classes a prepared scan is made of, by name (nothing else is rebuilt from a file)
_PLAIN_TYPES: dict[str, Any] = {
    c.__name__: c
    for c in (
        PreparedScan,
        ScanView,
        RangeImage,
        Scan,
        Keypoints3D,
        Features,
        PlanView,
        TopView,
        Levelling,
        PinholeCamera,
        SphericalCamera,
    )
}


def prepared_to_arrays(prepared: PreparedScan) -> tuple[Any, dict[str, NDArray[Any]]]:
    """A prepared scan as plain data: a JSON-ready tree and the numpy arrays it names.

    The tree holds the scalars, strings, the configuration (as
    :meth:`~flexreg.config.Config.to_dict`) and the class of each part, by name; every array
    is one entry of the dict (``a0``, ``a1``, ...). An array or part shared by several fields
    is stored once and shared again on reading; an array that is one value repeated (a
    working image's ``index``: a read-only broadcast view) is stored as that value.
    :func:`prepared_from_arrays` rebuilds the same scan, bit for bit, without unpickling
    anything.

    Raises
    ------
    TypeError
        A part of a type this layout does not know (an object array, a foreign class).
    """
    arrays: dict[str, NDArray[Any]] = {}
    memo: dict[int, Any] = {}
    keep: list[Any] = []  # the parts seen, alive while their ids are the memo's keys
    count = [0]  # parts numbered in the order they start

    def enc(x: Any) -> Any:
        if x is None or isinstance(x, bool | int | str):
            return x
        if isinstance(x, float):
            return x if math.isfinite(x) else {"float": repr(x)}
        if isinstance(x, tuple):
            return {"tuple": [enc(v) for v in x]}
        if isinstance(x, list):
            return {"list": [enc(v) for v in x]}
        if isinstance(x, dict) and all(isinstance(k, str) for k in x):
            return {"dict": {k: enc(v) for k, v in x.items()}}
        if isinstance(x, PurePath):
            return {"path": str(x)}
        if isinstance(x, RegistrationConfig):
            return {"config": x.to_dict()}
        if isinstance(x, np.generic):
            return {"scalar": enc(np.asarray(x))["array"]}
        if id(x) in memo:
            return memo[id(x)]
        keep.append(x)
        if isinstance(x, np.ndarray):
            if x.dtype.hasobject:
                raise TypeError("an object array cannot be stored as plain data")
            key = f"a{len(arrays)}"
            if x.size and not any(x.strides):  # one value repeated: a broadcast view
                arrays[key] = np.array(x.flat[0], dtype=x.dtype)
                memo[id(x)] = {"broadcast": key, "shape": list(x.shape)}
            else:
                arrays[key] = x
                memo[id(x)] = {"array": key}
            return memo[id(x)]
        name = type(x).__name__
        if _PLAIN_TYPES.get(name) is not type(x):
            raise TypeError(f"{type(x).__qualname__} cannot be stored as plain data")
        kinds: Any = type(x)  # one of the dataclasses above
        extra = set(vars(x)) - {f.name for f in fields(kinds)}
        if extra:
            raise TypeError(f"{name} holds more than its fields ({', '.join(sorted(extra))})")
        ref = count[0]
        count[0] += 1
        tree = {
            "type": name,
            "id": ref,
            "fields": {f.name: enc(getattr(x, f.name)) for f in fields(kinds)},
        }
        memo[id(x)] = {"ref": ref}
        return tree

    return enc(prepared), arrays


def prepared_from_arrays(tree: Any, arrays: dict[str, NDArray[Any]]) -> PreparedScan:
    """The prepared scan :func:`prepared_to_arrays` made ``tree`` and ``arrays`` of.

    Only the classes of a prepared scan are rebuilt, through their own constructors (which
    check shapes); nothing in the data names code to run.

    Raises
    ------
    ValueError
        The tree is not such a layout (an unknown class or tag, a missing array or part, a
        part that its class refuses).
    """
    parts: dict[int, Any] = {}

    def dec(x: Any) -> Any:
        if x is None or isinstance(x, bool | int | float | str):
            return x
        if not isinstance(x, dict) or len(x) not in (1, 2, 3):
            raise ValueError(f"not a stored value: {str(x)[:60]}")
        if "type" in x:
            cls = _PLAIN_TYPES.get(x["type"]) if isinstance(x["type"], str) else None
            given = x.get("fields")
            if cls is None or not isinstance(given, dict):
                raise ValueError(f"not a part of a prepared scan: {str(x['type'])[:60]}")
            names = {f.name for f in fields(cls)}
            if set(given) != names:
                raise ValueError(
                    f"{cls.__name__}: fields {sorted(given)}, expected {sorted(names)}"
                )
            try:
                obj = cls(**{k: dec(v) for k, v in given.items()})
            except (TypeError, FlexregError) as e:
                raise ValueError(f"{cls.__name__}: {e}") from None
            parts[int(x["id"])] = obj
            return obj
        ((tag, v),) = list(x.items())[:1]
        if tag == "ref":
            return parts[int(v)]
        if tag == "array":
            return arrays[v]
        if tag == "broadcast":
            return np.broadcast_to(arrays[v], tuple(int(n) for n in x["shape"]))
        if tag == "scalar":
            return arrays[v][()]
        if tag == "float":
            return float(v)
        if tag == "tuple":
            return tuple(dec(e) for e in v)
        if tag == "list":
            return [dec(e) for e in v]
        if tag == "dict":
            return {str(k): dec(e) for k, e in v.items()}
        if tag == "path":
            return Path(v)
        if tag == "config":
            return RegistrationConfig(**v)
        raise ValueError(f"unknown tag {tag!r}")

    try:
        out = dec(tree)
    except (KeyError, TypeError, AttributeError, RecursionError, FlexregError) as e:
        raise ValueError(f"not a stored prepared scan ({type(e).__name__}: {e})") from None
    if not isinstance(out, PreparedScan) or not (
        isinstance(out.image, RangeImage)
        and isinstance(out.scan, Scan | RangeImage)
        and isinstance(out.keypoints, Keypoints3D)
        and isinstance(out.view, ScanView)
        and isinstance(out.config, RegistrationConfig)
    ):
        raise ValueError("not a stored prepared scan")
    return out
