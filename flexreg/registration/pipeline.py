"""``register(target, source, config)``: the whole chain from two scans to ``T_target_source``.

Stages (each public and usable alone): range image (:mod:`flexreg.stages.projection`) -> feature
image
(:func:`feature_image`) -> keypoints and descriptors
(:func:`flexreg.stages.keypoints.detect_and_describe`)
-> matches (:func:`flexreg.stages.matching.match`) -> 3D correspondences
(:func:`flexreg.stages.correspondences.lift`) -> consistency pruning and RANSAC
(:mod:`flexreg.stages.alignment`) -> ICP refinement
(:func:`flexreg.stages.refinement.icp.refine_icp`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan
from flexreg.core.transforms import (
    invert,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import ConfigError, DegenerateGeometryError, RegistrationError
from flexreg.registration.config import RegistrationConfig
from flexreg.stages.alignment import consistent_subset, ransac_rigid, squared_residuals
from flexreg.stages.correspondences import lift
from flexreg.stages.keypoints import Features, detect_and_describe
from flexreg.stages.matching import match
from flexreg.stages.projection import range_image
from flexreg.stages.refinement.icp import IcpResult
from flexreg.stages.refinement.projective import grid_normals, point_information

log = logging.getLogger(__name__)


@dataclass(eq=False)
class RegistrationResult:
    """What :func:`register` found.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        Final transform (refined when ``config.refine``).
    T_coarse : (4, 4) float64
        The RANSAC transform before refinement.
    matches : int
        Putative 2D matches lifted to 3D.
    inliers : int
        RANSAC inliers among them.
    inlier_rmse_m : float
        RMSE of the final stage's inliers (ICP when refined, else RANSAC), metres.
    fitness : float
        Final-stage overlap: ICP fitness (fraction of downsampled source points with a target
        point within the ICP distance) or, unrefined, inliers / matches.
    fitness_denominator : str
        What ``fitness`` divides by.
    information : (6, 6) float64
        Information matrix (rotation, translation) for pose graphs.
    timings_s : dict
        Seconds per stage. The plan views and the preparation of the checks run in background
        threads beside the feature stages, so the stages add up to more than ``wall_s``.
    threshold_m : float
        RANSAC inlier threshold used.
    config : RegistrationConfig
    correspondences : (Q, 2, 3) float64
        Lifted ``[target point, source point]`` pairs (RANSAC input).
    inlier_mask : (Q,) bool
    keypoints : tuple of (K, 2) arrays
        Target and source keypoint positions of the lifted matches (for drawing).
    prior : str
        Which prior led to the estimate: ``"plan"`` (plan-view overlay) or ``"descriptors"``
        (global descriptor matching).
    wall_s : float
        Seconds the whole call took.
    """

    T_target_source: NDArray[np.float64]
    T_coarse: NDArray[np.float64]
    matches: int
    inliers: int
    inlier_rmse_m: float
    fitness: float
    fitness_denominator: str
    information: NDArray[np.float64]
    timings_s: dict[str, float]
    threshold_m: float
    config: RegistrationConfig
    correspondences: NDArray[np.float64] = field(repr=False)
    inlier_mask: NDArray[np.bool_] = field(repr=False)
    keypoints: tuple[NDArray[np.float64], NDArray[np.float64]] = field(repr=False)
    prior: str = "descriptors"
    wall_s: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-match arrays)."""
        return {
            "T_target_source": self.T_target_source.tolist(),
            "T_coarse": self.T_coarse.tolist(),
            "matches": self.matches,
            "inliers": self.inliers,
            "inlier_rmse_m": self.inlier_rmse_m,
            "fitness": self.fitness,
            "fitness_denominator": self.fitness_denominator,
            "information": self.information.tolist(),
            "threshold_m": self.threshold_m,
            "timings_s": self.timings_s,
            "wall_s": self.wall_s,
            "prior": self.prior,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
        }


# ------------------------------------------------------------------------------ stages


def feature_image(
    image: RangeImage, config: RegistrationConfig = RegistrationConfig()
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image features are detected on, and its valid mask.

    Flexion (or another conversion) of the range image, contrast-normalised as configured;
    ``"intensity"`` uses the scan's intensity instead.
    """
    from flexreg.stages import feature_images as images

    if config.image == "intensity":
        if image.intensity is None:
            raise RegistrationError("the scan has no intensity for an intensity feature image")
        val = image.intensity.astype(np.float64)
        lo, hi = np.nanpercentile(val, [1, 99])
        f = ((val - lo) / max(hi - lo, 1e-12)).astype(np.float32)
        f[~image.valid] = np.nan
    else:
        f = images.convert(image, config.image, n=config.n, median=config.median)
    mask = np.isfinite(f)
    q, qmask = images.quantize(
        f,
        bits=8,
        value_range=images.value_range(config.image, f) if config.image != "intensity" else (0, 1),
        stretch=config.stretch,  # type: ignore[arg-type]
    )
    return np.asarray(q, dtype=np.uint8), mask & np.asarray(qmask, dtype=bool)


def pixel_footprint(image: RangeImage) -> NDArray[np.float32]:
    """(H, W) metric size of each pixel: the smaller of its horizontal and vertical
    neighbour distances (NaN where unknown). Used to derive thresholds from resolution."""
    rows, cols = np.indices(image.shape).reshape(2, -1)
    return _footprint_at(image, rows, cols).reshape(image.shape)


def _footprint_at(
    image: RangeImage, rows: NDArray[np.int64], cols: NDArray[np.int64]
) -> NDArray[np.float32]:
    """:func:`pixel_footprint` at the given pixels only ((N,) float32)."""
    xyz = image.xyz
    p = xyz[rows, cols]
    right = cols + 1
    if image.wraps:
        right = np.where(right == image.width, 0, right)
    nan = np.full(3, np.nan)
    ph = np.where(
        (right < image.width)[:, None], xyz[rows, np.minimum(right, image.width - 1)], nan
    )
    below = rows + 1
    pv = np.where(
        (below < image.height)[:, None], xyz[np.minimum(below, image.height - 1), cols], nan
    )
    with np.errstate(invalid="ignore"):
        dh = np.linalg.norm(ph - p, axis=1).astype(np.float32)
        return np.fmin(dh, np.linalg.norm(pv - p, axis=1).astype(np.float32))


@contextmanager
def _timed(timings: dict[str, float], name: str) -> Iterator[None]:
    t = time.perf_counter()
    yield
    timings[name] = timings.get(name, 0.0) + time.perf_counter() - t


#: the plan views are drawn from at most about this many pixels per scan (every k-th row and
#: column of larger images); 300 k at 1024 x 512 already lost the far structure that places a
#: distant station
PLAN_PIXELS = 1_000_000

#: points of the projective refinement, half from each scan (spread evenly over its surfaces)
PROJECTIVE_ICP_POINTS = 30_000

#: target points of the area-weighted scale of the Open3D refinement (GICP, point-to-point;
#: see :func:`area_cell`)
AREA_ICP_POINTS = 10_000
#: the finest ICP scale is kept unless the dense check scores it this much lower (fraction of
#: the sampled source points) than the area-weighted scale
FINE_ICP_SLACK = 0.01


def _as_image(x: Scan | RangeImage) -> RangeImage:
    return x if isinstance(x, RangeImage) else range_image(x)


def _polisher(
    target: RangeImage, normals: NDArray[np.float32], sample: NDArray[np.float64], thr: float
) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """A quick local ICP of a small even sample of the source (``sample``, about 5000 points)
    against the target's range image (projective,
    :func:`flexreg.stages.refinement.projective.projective_icp`),
    for judging candidates.

    ``target`` must have a camera model; ``normals`` are its :func:`grid_normals`."""
    from flexreg.stages.refinement.projective import projective_icp

    def polish(T: NDArray[np.float64]) -> NDArray[np.float64]:
        try:
            r = projective_icp(
                target,
                sample,
                T,
                max_distance_m=3 * thr,
                normals=normals,
                max_iterations=15,
                tolerance=1e-4,
            )
        except RegistrationError:
            return T
        return r.T_target_source

    return polish


def _with_camera(image: RangeImage) -> RangeImage:
    """The image itself when it has a camera model; otherwise its points re-projected through
    an equirectangular camera fitted to them, so that free-space checks can look pixels up."""
    from flexreg.stages.projection import auto_spherical_camera, project

    if image.camera is not None:
        return image
    pts = image.xyz[image.valid]
    return project(Scan(points=pts), auto_spherical_camera(pts))


def _working_image(x: Scan | RangeImage, max_pixels: int) -> RangeImage:
    """The range image the image stages work on: at most ``max_pixels`` (every k-th row and
    column of larger grids)."""
    from flexreg.core.range_image import downsample_image, from_grid

    def factor(h: int, w: int) -> int:
        return max(1, math.ceil(math.sqrt(h * w / max(1, max_pixels))))

    if isinstance(x, Scan) and x.has_grid and x.grid_shape is not None:
        return from_grid(x, stride=factor(*x.grid_shape))
    img = _as_image(x)
    return downsample_image(img, factor(img.height, img.width))


def _points(x: Scan | RangeImage) -> NDArray[np.float64]:
    return x.points if isinstance(x, Scan) else x.xyz[x.valid]


def derive_threshold(
    target: RangeImage,
    source: RangeImage,
    xy_target: NDArray[np.float64],
    xy_source: NDArray[np.float64],
    *,
    threshold_px: float = 3.0,
) -> float:
    """Inlier distance from the scans' resolution: ``threshold_px`` times the median metric
    footprint of the pixels under the keypoints (at least 5 mm), metres."""
    f = []
    for img, xy in ((target, xy_target), (source, xy_source)):
        if len(xy) == 0:
            continue
        c = np.clip(np.rint(xy).astype(np.int64), 0, [img.width - 1, img.height - 1])
        f.append(_footprint_at(img, c[:, 1], c[:, 0]))
    fa = np.concatenate(f) if f else np.zeros(0)
    thr = float(threshold_px * np.nanmedian(fa)) if np.isfinite(fa).any() else 0.05
    return max(thr, 0.005)


def upright_priors(
    target: RangeImage, source: RangeImage, config: RegistrationConfig = RegistrationConfig()
) -> list[NDArray[np.float64]]:
    """``T_target_source`` candidates of two levelled scans from their plan views, best first.

    Each scan's vertical is estimated from its surfaces, the plans of the levelled scans are
    overlaid by FFT correlation over yaw and the height offset is read from their horizontal
    surfaces (:mod:`flexreg.stages.priors`). Accurate to about a plan cell and a degree: a prior for
    guided matching, not a result.

    Raises
    ------
    DegenerateGeometryError
        A scan is not levelled (tilt above ``config.max_tilt_rad``) or shows too little
        horizontal or vertical surface.
    """
    from flexreg.stages import priors as topview

    views = []
    for img in (target, source):
        stride = max(1, math.ceil(math.sqrt(img.height * img.width / PLAN_PIXELS)))
        pts, nrm, area = topview.surface_normals(img, k=2, stride=stride, compact=False)
        lev = topview.estimate_up(nrm, area, max_tilt_rad=config.max_tilt_rad)
        coarse, fine = topview.top_views(
            pts, nrm, area, lev, [(config.plan_cell_m, 40.0), (config.plan_cell_m / 4, 20.0)]
        )
        views.append((lev, coarse, fine))
    (lt, vt, vtf), (ls, vs, vsf) = views
    plans = topview.match_top_views(
        vt, vs, yaw_step_rad=math.radians(2.0), top_k=config.plan_hypotheses, coarse_candidates=6
    )
    plans = topview.refine_plan_matches(vtf, vsf, plans, yaw_range_rad=math.radians(1.0))
    dz = topview.height_offset(vt, vs)
    out = []
    for m in plans:
        M = np.eye(4)
        M[:3, :3] = rotation_about_axis([0.0, 0.0, 1.0], m.yaw_rad)
        M[:3, 3] = (m.t_xy[0], m.t_xy[1], dz)
        Lt, Ls = np.eye(4), np.eye(4)
        Lt[:3, :3], Ls[:3, :3] = lt.R_level, ls.R_level
        out.append(invert(Lt) @ M @ Ls)
    log.info(
        "plan overlays: %s (tilts %.2f / %.2f deg, dz %.3f m)",
        ", ".join(f"{math.degrees(m.yaw_rad):.1f} deg score {m.score:.0f}" for m in plans),
        math.degrees(lt.tilt_rad),
        math.degrees(ls.tilt_rad),
        dz,
    )
    return out


def _measured(image: RangeImage) -> NDArray[np.float32]:
    """What the camera model measures per pixel: depth z (pinhole) or range, NaN where invalid."""
    return image.depth_z() if isinstance(image.camera, PinholeCamera) else image.range


def range_slack(
    image: RangeImage, measured: NDArray[np.float32] | None = None
) -> NDArray[np.float32]:
    """(H, W) largest range (or depth) change from each pixel to its 4 neighbours, metres (0
    where unknown): how much range one pixel spans on an oblique surface. ``measured`` is the
    image's range (depth for pinhole cameras), when already at hand."""
    ref = _measured(image) if measured is None else measured
    out = np.zeros(image.shape, dtype=np.float32)
    if image.wraps:  # the seam columns are neighbours
        ref = np.concatenate([ref, ref[:, :1]], axis=1)
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            d = np.abs(np.diff(ref, axis=axis))
            d = np.nan_to_num(d, nan=0.0)
            W = out.shape[1]
            if axis == 0:
                out[1:] = np.maximum(out[1:], d[:, :W])
                out[:-1] = np.maximum(out[:-1], d[:, :W])
            else:
                out[:, 1:] = np.maximum(out[:, 1:], d[:, : W - 1])
                out[:, :-1] = np.maximum(out[:, :-1], d[:, : W - 1])
                if image.wraps:
                    out[:, -1] = np.maximum(out[:, -1], d[:, -1])
                    out[:, 0] = np.maximum(out[:, 0], d[:, -1])
    return out


def overlap_score(
    target: RangeImage,
    source: RangeImage,
    T_target_source: NDArray[np.float64],
    *,
    tolerance_m: float = 0.05,
    tolerance_rel: float = 0.01,
    samples: int = 20000,
    slack: NDArray[np.float32] | None = None,
    sampling: str = "area",
) -> tuple[float, float]:
    """How well a transform explains the target's view of the source: a dense check.

    A regular sample of the source's points is mapped into the target frame and looked up in
    the target's range image. A point is *consistent* when the target saw a surface at the
    same range (within ``tolerance_m + tolerance_rel * range``) and *in conflict* when it
    lies clearly in front of what the target saw: the target looked through the place where
    the transform puts it, so a wrong transform collects conflicts while a right one only
    collects consistent and occluded points. Each pixel's tolerance also grows by the range
    change to its neighbours (``slack``, see :func:`range_slack`), since a pixel on a surface
    seen at grazing incidence spans a long stretch of range. Native grids without a camera
    model fall back to nearest-neighbour distances (no conflicts).

    With ``sampling="area"`` (default) the sample is spread evenly over the source's surfaces
    (one point per cell of a voxel grid sized to give about ``samples`` points,
    :func:`area_sample`), so fractions are fractions of surface area; ``"pixels"`` takes every
    k-th valid pixel instead, which weights surfaces near the scanner by their many pixels. Area
    matters where the near field is self-similar: in a corridor the walls beside the scanner
    fill most pixels and fit any shift along it, while the far structure that fixes the shift
    has few pixels but most of the area.

    Returns
    -------
    consistent, conflicting : float
        Fractions of the sampled source points.
    """
    if sampling not in ("area", "pixels"):
        raise ConfigError(f"sampling must be 'area' or 'pixels', got {sampling!r}")
    ps = source.xyz[source.valid]
    ps = area_sample(ps, samples) if sampling == "area" else ps[:: max(1, len(ps) // samples)]
    _, ok, bad = _overlap(target, ps, T_target_source, tolerance_m, tolerance_rel, slack)
    return (float(ok.mean()), float(bad.mean())) if len(ok) else (0.0, 0.0)


def area_sample(points: NDArray[np.float64], samples: int) -> NDArray[np.float64]:
    """About ``samples`` points spread evenly over the surfaces of a cloud.

    One point (the first in input order) per occupied cell of the voxel grid of
    :func:`area_cell`; deterministic.

    Parameters
    ----------
    points : (N, 3) float64
        Metres.
    samples : int
        Wanted number of points (the result has about 0.7 to 1.4 times that, or all N points
        when N is smaller).

    Returns
    -------
    (M, 3) float64
        A subset of ``points`` in input order.
    """
    return _area_sample_cell(points, samples)[1]


def _area_sample_cell(
    points: NDArray[np.float64], samples: int
) -> tuple[float, NDArray[np.float64]]:
    """:func:`area_cell` and :func:`area_sample` at once."""
    p = np.asarray(points, dtype=np.float64)
    cell, first = _area_cells(p, samples)
    return cell, p if len(p) <= samples else p[first]


def area_cell(points: NDArray[np.float64], samples: int) -> float:
    """Voxel size at which about ``samples`` voxels of a cloud's surfaces are occupied, metres.

    Downsampling with it weights every part of a scene by its surface area rather than by its
    number of points (a scanner samples the surfaces near it far more densely).

    Parameters
    ----------
    points : (N, 3) float64
        Metres.
    samples : int
        Wanted number of occupied voxels.
    """
    return _area_cells(np.asarray(points, dtype=np.float64), samples)[0]


def _area_cells(p: NDArray[np.float64], samples: int) -> tuple[float, NDArray[np.int64]]:
    """Cell size and the index of the first point in each occupied cell, ascending (of a
    thinned copy of ``p`` when it is large: indices then refer to ``p`` itself)."""
    step = max(1, len(p) // (20 * samples))  # enough points to fill the cells
    q = np.ascontiguousarray(p[::step])
    if len(q) == 0:
        return 1e-9, np.zeros(0, dtype=np.int64)
    lo, hi = _bounds(q)
    span = float(np.max(hi - lo))
    cell = max(span, 1e-9) / math.sqrt(samples)  # surfaces: cells grow with 1 / cell^2
    first = np.arange(len(q))
    table = np.empty(1 << max(4, int(2 * len(q) - 1).bit_length()), dtype=np.int64)
    for _ in range(8):
        first = _first_in_cells(q, lo, cell, table)
        ratio = len(first) / samples
        if 0.7 < ratio < 1.4:
            break
        cell *= math.sqrt(ratio)
    return cell, first * step


@numba.njit(cache=True, nogil=True)
def _bounds(q):  # pragma: no cover - compiled
    """Per-axis minimum and maximum of (N, 3) points (N >= 1)."""
    lo = q[0].copy()
    hi = q[0].copy()
    for i in range(1, q.shape[0]):
        for c in range(3):
            x = q[i, c]
            if x < lo[c]:
                lo[c] = x
            elif x > hi[c]:
                hi[c] = x
    return lo, hi


@numba.njit(cache=True, nogil=True)
def _first_in_cells(q, lo, cell, table):  # pragma: no cover - compiled
    """Indices (ascending) of the first point of each occupied cell of side ``cell`` anchored
    at ``lo``: an open-addressing hash set of the integer cell coordinates; ``table`` is
    scratch space of a power-of-two size at least twice the number of points."""
    mask = table.shape[0] - 1
    table[:] = -1
    out = np.empty(q.shape[0], dtype=np.int64)
    n = 0
    for i in range(q.shape[0]):
        kx = np.int64(np.floor((q[i, 0] - lo[0]) / cell))
        ky = np.int64(np.floor((q[i, 1] - lo[1]) / cell))
        kz = np.int64(np.floor((q[i, 2] - lo[2]) / cell))
        h = (kx * 73856093) ^ (ky * 19349663) ^ (kz * 83492791)
        slot = h & mask
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = i
                out[n] = i
                n += 1
                break
            if (
                np.int64(np.floor((q[j, 0] - lo[0]) / cell)) == kx
                and np.int64(np.floor((q[j, 1] - lo[1]) / cell)) == ky
                and np.int64(np.floor((q[j, 2] - lo[2]) / cell)) == kz
            ):
                break
            slot = (slot + 1) & mask
    return out[:n]


def _overlap(
    target: RangeImage,
    ps: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    tolerance_m: float,
    tolerance_rel: float,
    slack: NDArray[np.float32] | None = None,
    ref: NDArray[np.float32] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Source points ``ps`` (already sampled) checked against the target's view (``ref``: its
    :func:`_measured` image, when at hand)."""
    if len(ps) == 0:
        return np.zeros((0, 3)), np.zeros(0, bool), np.zeros(0, bool)
    T = np.asarray(T_target_source, dtype=np.float64)
    q = ps @ T[:3, :3].T + T[:3, 3]
    cam = target.camera
    if cam is None:
        from scipy.spatial import cKDTree

        pt = target.xyz[target.valid]
        pt = pt[:: max(1, len(pt) // 200_000)]
        d, _ = cKDTree(pt).query(q, distance_upper_bound=4 * tolerance_m)
        ok = d < tolerance_m + tolerance_rel * np.linalg.norm(q, axis=1)
        return q, ok, np.zeros(len(q), dtype=bool)
    u, v, d = cam.project(q)
    with np.errstate(invalid="ignore"):
        iu = np.floor(u + 0.5)
        iv = np.floor(v + 0.5)
        if target.wraps:
            iu = np.where(iu >= target.width, iu - target.width, iu)
        inside = np.isfinite(iu) & np.isfinite(iv) & (d > 0)
        inside &= (iu >= 0) & (iu < target.width) & (iv >= 0) & (iv < target.height)
    if ref is None:
        ref = _measured(target)
    if slack is None:
        slack = range_slack(target, ref)
    r = np.full(len(q), np.nan)
    extra = np.zeros(len(q))
    pix = (iv[inside].astype(np.int64), iu[inside].astype(np.int64))
    r[inside] = ref[pix]
    extra[inside] = slack[pix]
    tol = tolerance_m + tolerance_rel * np.abs(d) + extra
    with np.errstate(invalid="ignore"):
        consistent = np.abs(d - r) < tol
        conflict = d < r - tol
    return q, consistent, conflict


@dataclass(eq=False)
class _Estimate:
    T: NDArray[np.float64]
    pairs: NDArray[np.int64]
    inliers: NDArray[np.bool_]
    origin: str


def _guided_estimate(
    ft: Features,
    fs: Features,
    xt: NDArray[np.float64],
    xs: NDArray[np.float64],
    T0: NDArray[np.float64],
    thr: float,
    config: RegistrationConfig,
    origin: str,
) -> _Estimate | None:
    """Guided matching around a prior, then least squares with a shrinking inlier radius.

    The prior is trusted to within the guided search radius; starting from it, correspondences
    within the current radius are fitted (Kabsch) and the radius halves down to ``thr``, so
    the estimate cannot jump to an unrelated model the way RANSAC on the same matches can.
    A second, tight guided round around the result collects the final matches.
    """
    from flexreg.stages.alignment import COLLINEAR_RATIO, kabsch, spread_ratio
    from flexreg.stages.matching import match_guided

    def shrink(T: NDArray[np.float64], pairs: NDArray[np.int64], r0: float) -> Any:
        pt, ps = xt[pairs[:, 0]], xs[pairs[:, 1]]
        rng_s = np.linalg.norm(ps, axis=1)
        # radii r0, r0/2, ... down to thr (the range-proportional part shrinking alike),
        # then two more fits at thr
        radii = [r0]
        while radii[-1] > thr:
            radii.append(max(radii[-1] / 2, thr))
        for radius in [*radii, thr, thr]:
            extra = config.guided_radius_per_m * rng_s * (radius / r0) if radius > thr else 0.0
            inl = squared_residuals(T, pt, ps) < (radius + extra) ** 2
            if inl.sum() < 3 or spread_ratio(ps[inl]) < COLLINEAR_RATIO:
                return None, inl
            T = kabsch(pt[inl], ps[inl])
        return T, squared_residuals(T, pt, ps) < thr * thr

    r0 = max(config.guided_radius_m, 2 * thr)
    pairs = match_guided(ft, fs, xt, xs, T0, radius_m=r0, radius_per_m=config.guided_radius_per_m)
    if len(pairs) < 3:
        return None
    T, _ = shrink(T0, pairs, r0)
    if T is None:
        return None
    pairs = match_guided(ft, fs, xt, xs, T, radius_m=2 * thr, radius_per_m=0.002)
    if len(pairs) < 3:
        return None
    T, inl = shrink(T, pairs, 2 * thr)
    if T is None:
        return None
    return _Estimate(T, pairs, inl, origin)


def refine(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    T_init: NDArray[np.float64],
    *,
    threshold_m: float,
    method: str = "point-to-plane",
    voxel_m: float | None = None,
    check: Callable[[NDArray[np.float64]], float] | None = None,
    target_image: RangeImage | None = None,
    target_normals: NDArray[np.float32] | None = None,
    source_image: RangeImage | None = None,
    source_normals: NDArray[np.float32] | None = None,
    samples: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> IcpResult:
    """ICP refinement of a coarse ``T_target_source``.

    **Point-to-plane (default): symmetric projective ICP on both range images**
    (:func:`flexreg.stages.refinement.projective.projective_icp`). About
    :data:`PROJECTIVE_ICP_POINTS` points,
    half from each scan, spread evenly over its surfaces (:func:`area_sample`), are paired with
    the other scan's pixel their rays hit, whose plane comes from that image's grid; both scans
    keep their full image resolution. Sampling by area keeps the dense, noisy or self-similar
    near field of a scanner (a corridor's walls fit any shift along it) from outweighing the far
    structure that fixes the pose; pairing in both directions keeps either scan's viewpoint and
    normals alone from deciding it.

    **GICP, point-to-point, or a fixed voxel: Open3D** nearest-neighbour ICP at two scales.
    First on voxels sized so that the target keeps about :data:`AREA_ICP_POINTS`
    (:func:`area_cell`, area-weighted as above), then at the finest voxels the point budget
    allows (:func:`refine.refine_icp`), started from the first; the fine result is kept unless
    the dense free-space check scores it more than :data:`FINE_ICP_SLACK` lower. With
    ``voxel_m``, one coarse-to-fine ICP at that voxel.

    Parameters
    ----------
    target, source : Scan or RangeImage
    T_init : (4, 4) float64
        Coarse transform.
    threshold_m : float
        Inlier threshold of the coarse stage (how far off ``T_init`` may be), metres.
    method : {"point-to-plane", "gicp", "point-to-point"}
    voxel_m : float, optional
        A fixed voxel: Open3D ICP at that voxel, no second scale.
    check : callable, optional
        Open3D path: ``check(T) -> score`` (higher is better); default the consistent minus
        three times the conflicting fraction of :func:`overlap_score` at ``threshold_m / 2``.
    target_image : RangeImage, optional
        The target's range image with a camera model, when already at hand (projective path).
    target_normals : (H, W, 3) float32, optional
        Its :func:`flexreg.stages.refinement.projective.grid_normals`, when already at hand.
    source_image : RangeImage, optional
        The source's range image with a camera model, when already at hand.
    source_normals : (H, W, 3) float32, optional
        Its :func:`flexreg.stages.refinement.projective.grid_normals`, when already at hand.
    samples : (float, (N, 3) float64, (M, 3) float64), optional
        The projective path's area samples (source cell size, source and target points), when
        already at hand.

    Returns
    -------
    IcpResult
    """
    from flexreg.stages.refinement.icp import refine_icp

    sp = _points(source)
    kind: Any = method
    if _projective_refinement(method, voxel_m):
        from flexreg.stages.refinement.projective import projective_icp

        vt = target_image if target_image is not None else _camera_image(target)
        vs = source_image if source_image is not None else _camera_image(source)
        cell_s, src_sample, tgt_sample = (
            samples if samples is not None else _refine_samples(target, source)
        )
        r = projective_icp(
            vt,
            src_sample,
            T_init,
            max_distance_m=3 * threshold_m,
            normals=target_normals if target_image is not None else None,
            source=vs,
            target_points=tgt_sample,
            source_normals=source_normals if source_image is not None else None,
        )
        return IcpResult(
            T_target_source=r.T_target_source,
            fitness=r.fitness,
            inlier_rmse_m=r.inlier_rmse_m,
            information=r.information,
            voxel_m=cell_s,
            max_distance_m=r.max_distance_m,
            source_points=len(src_sample) + len(tgt_sample),
            association="projective",
        )
    tp = _points(target)
    if voxel_m is not None:
        return refine_icp(
            tp, sp, T_init, method=kind, voxel_m=voxel_m, initial_error_m=3 * threshold_m
        )
    broad = refine_icp(
        tp,
        sp,
        T_init,
        method=kind,
        voxel_m=area_cell(tp, AREA_ICP_POINTS),
        initial_error_m=3 * threshold_m,
    )
    fine = refine_icp(tp, sp, broad.T_target_source, method=kind, initial_error_m=3 * threshold_m)
    if check is None:
        vt = _camera_image(target)
        ref = _measured(vt)
        slack = range_slack(vt, ref)
        sample = area_sample(sp, 20000)

        def check(T: NDArray[np.float64]) -> float:
            _, ok, bad = _overlap(vt, sample, T, threshold_m / 2, 0.002, slack, ref)
            return float(ok.mean() - 3 * bad.mean())

    s_broad, s_fine = check(broad.T_target_source), check(fine.T_target_source)
    best = fine if s_fine >= s_broad - FINE_ICP_SLACK else broad
    log.info(
        "ICP at %.3g m voxels: check %.3f; at %.3g m: %.3f -> %.3g m kept",
        broad.voxel_m,
        s_broad,
        fine.voxel_m,
        s_fine,
        best.voxel_m,
    )
    return best


def _projective_refinement(method: str, voxel_m: float | None) -> bool:
    """Whether :func:`refine` takes the projective path (point-to-plane without a fixed voxel)."""
    return method == "point-to-plane" and voxel_m is None


def _camera_image(target: Scan | RangeImage) -> RangeImage:
    """The range image (with a camera model, holes filled) that :func:`register` checks
    against and refines on."""
    from flexreg.stages.projection import fill_holes

    return _with_camera(fill_holes(_working_image(target, RegistrationConfig().max_image_pixels)))


@dataclass(eq=False)
class _Prepared:
    """What the checks and the refinement of :func:`register` need of the scans alone, made
    while the feature and plan stages run (see :func:`_prepare`)."""

    vt: RangeImage
    ref: NDArray[np.float32]
    slack: NDArray[np.float32]
    normals: NDArray[np.float32]
    sample: NDArray[np.float64]
    polish_sample: NDArray[np.float64]
    vs: RangeImage
    source_normals: NDArray[np.float32] | None
    refine_samples: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None


def _prepare(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    ti: RangeImage,
    si: RangeImage,
    config: RegistrationConfig,
) -> _Prepared:
    """The target's view for the dense checks (range, slack, normals), the source's samples,
    and what the default refinement uses (source normals, area samples of both scans)."""
    vt = _with_camera(ti)
    ref = _measured(vt)
    vs = _with_camera(si)
    pts_s = si.xyz[si.valid]
    projective = config.refine and _projective_refinement(config.icp, config.voxel_m)
    return _Prepared(
        vt=vt,
        ref=ref,
        slack=range_slack(vt, ref),
        normals=grid_normals(vt),
        sample=area_sample(pts_s, 20000),
        polish_sample=area_sample(pts_s, 5000),
        vs=vs,
        source_normals=grid_normals(vs) if projective else None,
        refine_samples=_refine_samples(target, source) if projective else None,
    )


def _refine_samples(
    target: Scan | RangeImage, source: Scan | RangeImage
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """The projective refinement's area samples: source cell size, source and target points."""
    n = PROJECTIVE_ICP_POINTS // 2
    cell_s, src = _area_sample_cell(_points(source), n)
    return cell_s, src, _area_sample_cell(_points(target), n)[1]


@dataclass(eq=False)
class _Matched:
    """What the feature stages of :func:`register` found (see :func:`_global_matching`)."""

    ft: Features
    fs: Features
    xt: NDArray[np.float64]
    xs: NDArray[np.float64]
    thr: float
    pairs: NDArray[np.int64]
    priors: list[tuple[str, NDArray[np.float64]]]
    notes: list[str]


def _global_matching(
    ti: RangeImage,
    si: RangeImage,
    config: RegistrationConfig,
    stage: Callable[[str], Any],
) -> _Matched:
    """The feature stages of :func:`register`: feature images, keypoints and descriptors,
    lifting, the inlier threshold, descriptor matching and RANSAC (the descriptor prior)."""
    with stage("feature images"):
        fti, mt = feature_image(ti, config)
        fsi, ms = feature_image(si, config)
    with stage("features"):
        ft = detect_and_describe(
            fti, config.features, mt, max_features=config.max_features, wrap=ti.wraps
        )
        fs = detect_and_describe(
            fsi, config.features, ms, max_features=config.max_features, wrap=si.wraps
        )
    with stage("lifting"):
        xt, lt_ok = lift(ti, ft.xy)
        xs, ls_ok = lift(si, fs.xy)
    n_lt, n_ls = int(lt_ok.sum()), int(ls_ok.sum())
    log.info("%d/%d keypoints, %d/%d lifted", len(ft), len(fs), n_lt, n_ls)
    if n_lt < 3 or n_ls < 3:
        raise RegistrationError(
            f"too few keypoints on valid surface: {n_lt} target / {n_ls} source "
            f"(of {len(ft)} / {len(fs)} detected)"
        )
    thr = (
        float(config.threshold_m)
        if config.threshold_m is not None
        else derive_threshold(
            ti,
            si,
            ft.xy[lt_ok],
            fs.xy[ls_ok],
            threshold_px=config.threshold_px,
        )
    )
    priors: list[tuple[str, NDArray[np.float64]]] = []
    notes: list[str] = []
    with stage("matching"):  # descriptors, then the global model (consistency, RANSAC)
        pairs = match(ft, fs, ratio=config.ratio, mutual=config.mutual)
        pairs = pairs[lt_ok[pairs[:, 0]] & ls_ok[pairs[:, 1]]]
        if len(pairs) >= 3:
            pt, ps = xt[pairs[:, 0]], xs[pairs[:, 1]]
            idx = np.arange(len(pairs))
            if config.consistency:
                idx = consistent_subset(pt, ps, threshold_m=2 * thr, relative=0.01)
            try:
                rr = ransac_rigid(
                    pt[idx],
                    ps[idx],
                    threshold_m=thr,
                    confidence=config.confidence,
                    max_iterations=config.max_iterations,
                    min_inliers=3,
                    rng=config.seed,
                )
                priors.append(("descriptors", rr.T_target_source))
            except DegenerateGeometryError as e:
                notes.append(f"global matching: {e}")
        else:
            notes.append(f"global matching: {len(pairs)} matches")
    return _Matched(ft, fs, xt, xs, thr, pairs, priors, notes)


def register(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    config: RegistrationConfig = RegistrationConfig(),
    *,
    progress: Callable[[str], None] | None = None,
) -> RegistrationResult:
    """Register ``source`` onto ``target``: returns ``T_target_source``.

    Priors come from two independent routes: global descriptor matching (ratio test, mutual
    check, pairwise-consistency pruning, RANSAC) and, for levelled scanners, plan-view overlays
    (:func:`upright_priors`). Each prior guides a second matching of all keypoints near its
    predictions (:func:`flexreg.stages.matching.match_guided`) and a least-squares fit with a
    shrinking inlier radius. The candidates are judged, after a quick local ICP, by the dense
    free-space check :func:`overlap_score`; the winner is the coarse transform, refined by ICP.

    Parameters
    ----------
    target, source : Scan or RangeImage
        Scans in their own scanner frames (a gridded scan keeps its native grid).
    config : RegistrationConfig
    progress : callable, optional
        Called with the name of each stage as it starts; for the stages that run in background
        threads (plan views, preparation), when the call starts waiting for them.

    Raises
    ------
    RegistrationError
        Too few matches or inliers, degenerate (collinear) inliers, or ICP without overlap;
        the message gives the counts. No transform is returned then.
    """
    from flexreg.stages.alignment import COLLINEAR_RATIO, spread_ratio
    from flexreg.stages.matching import match_guided
    from flexreg.stages.projection import fill_holes

    if config.upright not in ("auto", "on", "off"):
        raise ConfigError(f"upright must be 'auto', 'on' or 'off', got {config.upright!r}")
    timings: dict[str, float] = {}
    t_start = time.perf_counter()

    def stage(name: str) -> Any:
        if progress is not None:
            progress(name)
        return _timed(timings, name)

    with stage("range images"):
        ti, si = (_working_image(x, config.max_image_pixels) for x in (target, source))
        if config.fill_holes:
            ti, si = fill_holes(ti), fill_holes(si)
    panoramic = not isinstance(ti.camera, PinholeCamera) and not isinstance(
        si.camera, PinholeCamera
    )
    use_plan = config.upright == "on" or (config.upright == "auto" and panoramic)

    # the plan views and the preparation of the checks need only the range images: they run in
    # two background threads beside the feature stages, every thread single-threaded in numba
    # so that together they fill the cores instead of competing for them
    def plan_views() -> list[NDArray[np.float64]]:
        from scipy import fft

        numba.set_num_threads(1)
        with _timed(timings, "plan views"), fft.set_workers(-1):
            return upright_priors(ti, si, config)

    def prepare() -> _Prepared:
        numba.set_num_threads(1)
        with _timed(timings, "preparation"):
            return _prepare(target, source, ti, si, config)

    pool = ThreadPoolExecutor(max_workers=2)
    plan_job = pool.submit(plan_views) if use_plan else None
    prep_job = pool.submit(prepare)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        m = _global_matching(ti, si, config, stage)
        ft, fs, xt, xs, thr, pairs, notes = m.ft, m.fs, m.xt, m.xs, m.thr, m.pairs, m.notes
        priors: list[tuple[str, NDArray[np.float64]]] = []
        if plan_job is not None:
            if progress is not None:
                progress("plan views")
            try:
                priors += [("plan", T) for T in plan_job.result()]
            except DegenerateGeometryError as e:
                if config.upright == "on":
                    raise RegistrationError(f"upright prior impossible: {e}") from None
                notes.append(f"no plan prior ({e})")
                log.info("no plan prior: %s", e)
        if progress is not None:
            progress("preparation")
        prep = prep_job.result()
    finally:
        numba.set_num_threads(threads)
        pool.shutdown(wait=True, cancel_futures=True)
    priors += m.priors
    with stage("estimation"):
        # every prior and its keypoint-refined version compete on the dense overlap check:
        # first the best prior family at a coarse tolerance (a wrong model puts the source
        # in the target's free space), then the more precise member at a fine tolerance
        families: list[list[tuple[str, NDArray[np.float64]]]] = []
        for origin, T0 in priors:
            fam = [(origin, T0)] if origin == "plan" else []
            est = _guided_estimate(ft, fs, xt, xs, T0, thr, config, origin)
            if est is not None and est.inliers.sum() >= max(3, config.min_inliers):
                fam.append((f"{origin}+keypoints", est.T))
            if fam:
                families.append(fam)
        vt, ref, slack, sample, normals = prep.vt, prep.ref, prep.slack, prep.sample, prep.normals
        polish = _polisher(vt, normals, prep.polish_sample, thr) if config.polish else None

        def judge(T: NDArray[np.float64], tol: float, rel: float) -> tuple[float, float, float]:
            """``consistent - 3 conflicting`` (conflicts are strong evidence), and both."""
            _, ok_, bad_ = _overlap(vt, sample, T, tol, rel, slack, ref)
            ok, bad = float(ok_.mean()), float(bad_.mean())
            return ok - 3 * bad, ok, bad

        judged = []  # (score, moved, family, consistent, conflicting, polished T)
        for i, fam in enumerate(families):
            for origin, T in fam:
                # judged after a quick local ICP: a right but rough candidate improves, a
                # wrong one stays wrong
                Tj = polish(T) if polish is not None else T
                score, ok, bad = judge(Tj, 2.5 * thr, 0.01)
                moved = translation_error_m(Tj, T) / thr + rotation_error_deg(Tj, T)
                log.info("%s: overlap %.3f, conflict %.3f, moved %.2f", origin, ok, bad, moved)
                judged.append((score, moved, i, ok, bad, Tj))
        best_fam, best_fit, best_polished = -1, (0.0, 0.0), None
        if judged:
            top = max(j[0] for j in judged)
            # candidates that end in the same place score alike: take the one that was
            # already there (moved least under the quick ICP)
            _, _, best_fam, ok, bad, Tj = min(
                (j for j in judged if j[0] >= top - 0.01), key=lambda j: j[1]
            )
            best_fit = (ok, bad)
            best_polished = Tj if polish is not None else None
        if best_fam < 0:
            raise RegistrationError(
                f"no transform found: {len(ft)}/{len(fs)} keypoints, {len(pairs)} descriptor "
                f"matches, {len(priors)} priors" + (f"; {'; '.join(notes)}" if notes else "")
            )
        if best_fit[0] < config.min_overlap or best_fit[1] > 0.5 * best_fit[0]:
            raise RegistrationError(
                f"no overlap: the best transform explains {100 * best_fit[0]:.1f}% of the "
                f"source's sampled points and contradicts {100 * best_fit[1]:.1f}% (need "
                f"{100 * config.min_overlap:.0f}%); {len(ft)}/{len(fs)} keypoints, "
                f"{len(pairs)} descriptor matches"
            )
        fine_tol = thr / 2
        finalists = list(families[best_fam])
        if best_polished is not None:
            # the keypoint estimate around the polished winner: a candidate that was far off
            # but converged under the quick ICP still gets a feature-based coarse transform
            est = _guided_estimate(
                ft, fs, xt, xs, best_polished, thr, config, finalists[0][0].split("+")[0]
            )
            if est is not None and est.inliers.sum() >= 3:
                finalists.append((f"{est.origin}+keypoints", est.T))
        origin, T = max(finalists, key=lambda c: judge(c[1], fine_tol, 0.002)[0])
        fin = match_guided(ft, fs, xt, xs, T, radius_m=2 * thr, radius_per_m=0.002)
        pt, ps = xt[fin[:, 0]], xs[fin[:, 1]]
        d2 = squared_residuals(T, pt, ps)
        inl = d2 < thr * thr
    log.info("coarse estimate from %s: %d/%d keypoint inliers", origin, inl.sum(), len(inl))
    if "plan" not in origin:
        if inl.sum() < max(3, config.min_inliers):
            raise RegistrationError(
                f"only {int(inl.sum())} inliers within {thr:.3g} m (need "
                f"{max(3, config.min_inliers)}); {len(ft)}/{len(fs)} keypoints, "
                f"{len(pairs)} descriptor matches"
            )
        if spread_ratio(ps[inl]) < COLLINEAR_RATIO:
            raise RegistrationError(f"the {int(inl.sum())} inliers are collinear")
    T_coarse = T.copy()
    rmse = float(np.sqrt(d2[inl].mean())) if inl.any() else float("nan")
    q, cons, _ = _overlap(vt, sample, T, fine_tol, 0.002, slack, ref)
    fitness = float(cons.mean())
    denom = (
        f"{len(sample)} source points spread evenly over its surfaces, within {fine_tol:.3g} m "
        "+ 0.2% of range of what the target saw"
    )
    info = point_information(q[cons])
    if config.refine:
        with stage("refinement"):
            icp = refine(
                target,
                source,
                T,
                threshold_m=thr,
                method=config.icp,
                voxel_m=config.voxel_m,
                check=lambda T_: judge(T_, fine_tol, 0.002)[0],
                target_image=vt,
                target_normals=normals,
                source_image=prep.vs,
                source_normals=prep.source_normals,
                samples=prep.refine_samples,
            )
        T, rmse, fitness, info = (
            icp.T_target_source,
            icp.inlier_rmse_m,
            icp.fitness,
            icp.information,
        )
        denom = (
            f"{icp.source_points} points of both scans spread evenly over their surfaces (one "
            f"per {icp.voxel_m:.3g} m cell) within {icp.max_distance_m:.3g} m of the other "
            "scan's surface on their ray"
            if icp.association == "projective"
            else f"{icp.source_points} source points ({icp.voxel_m:.3g} m voxels, thinned) "
            f"with a target point within {icp.max_distance_m:.3g} m"
        )
    return RegistrationResult(
        T_target_source=T,
        T_coarse=T_coarse,
        matches=len(fin),
        inliers=int(inl.sum()),
        inlier_rmse_m=rmse,
        fitness=fitness,
        fitness_denominator=denom,
        information=info,
        timings_s=timings,
        threshold_m=thr,
        config=config,
        correspondences=np.stack([pt, ps], axis=1),
        inlier_mask=inl,
        keypoints=(ft.xy[fin[:, 0]], fs.xy[fin[:, 1]]),
        prior=origin,
        wall_s=time.perf_counter() - t_start,
    )


__all__ = [
    "Features",
    "RegistrationConfig",
    "RegistrationResult",
    "area_cell",
    "area_sample",
    "feature_image",
    "overlap_score",
    "pixel_footprint",
    "range_slack",
    "refine",
    "register",
    "upright_priors",
]
