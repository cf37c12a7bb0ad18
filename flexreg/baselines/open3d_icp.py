"""Open3D ICP baselines: point-to-point, point-to-plane and generalized ICP, coarse to fine.

Every size comes from one scale parameter, the voxel ``v`` (default from the scan resolution,
:func:`~flexreg.baselines._common.default_voxel`: the voxel that leaves at most 20,000 target
points, the size FPFH + RANSAC works at). Very large clouds are first thinned to every k-th
point (at most 2 million), then ICP runs three levels (:data:`ICP_LEVELS`), each on both
clouds voxel-downsampled at its voxel:

=====  ==========  ===========================  ==============
level  voxel       max correspondence distance  max iterations
=====  ==========  ===========================  ==============
1      v           5 v                          50
2      v / 2       2 v                          30
3      v / 4       0.75 v                       30
=====  ==========  ===========================  ==============

A level voxel never goes below the median point spacing ``s`` of the finest cloud (it would
downsample nothing and leave the normal neighbourhoods nearly empty), nor a distance below
``2 s``; this only matters for small, dense clouds whose default voxel is ``2 s``.

Point-to-plane ICP estimates the target's normals on each level within ``2 x`` the level voxel,
at most 30 neighbours (the 1:2 voxel:normal rule of Open3D's tutorials). GICP is given no
normals or covariances: Open3D then builds them as in the GICP paper (normals from the 20
nearest neighbours, plane-shaped covariances ``diag(1e-3, 1, 1)``). Covariances computed
beforehand with ``estimate_covariances`` would be used raw, which makes GICP's weights
singular (NaN transforms on the Velodyne pair), and normals from the 1:2 radius rule leave the
sparse far rings of a lidar scan without neighbours. The start is the identity or a given
``T_init``. Open3D's ICP iterations run on one thread: its multi-threaded reductions sum in
varying order, and one thread keeps the result bit-identical from run to run (the same rule as
:func:`flexreg.stages.refinement.icp.refine_icp`).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.baselines._common import (
    DEFAULT_MAX_POINTS,
    BaselineConfig,
    correspondence_pairs,
    initial_transform,
    make_result,
    open3d_threads,
    resolve_voxel,
)
from flexreg.core.results import PairResult
from flexreg.core.scan import as_points
from flexreg.errors import ConfigError, RegistrationError
from flexreg.stages.sampling import median_spacing, thin, to_open3d

log = logging.getLogger(__name__)

IcpVariant = Literal["point-to-point", "point-to-plane", "gicp"]
VARIANTS: tuple[str, ...] = ("point-to-point", "point-to-plane", "gicp")

#: (voxel, max correspondence distance) in units of the scale voxel v, and max iterations
ICP_LEVELS: tuple[tuple[float, float, int], ...] = (
    (1.0, 5.0, 50),
    (0.5, 2.0, 30),
    (0.25, 0.75, 30),
)
#: normal / covariance radius in level voxels, and neighbour cap
NORMAL_RADIUS_VOXELS = 2.0
NORMAL_MAX_NN = 30
#: clouds above this many points are thinned (every k-th point) before voxel downsampling
THIN_POINTS = 2_000_000


def icp(
    target: Any,
    source: Any,
    *,
    variant: IcpVariant = "point-to-plane",
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
    seed: int = 0,
    name: str | None = None,
) -> PairResult:
    """Coarse-to-fine Open3D ICP from the identity or from ``T_init``.

    Parameters
    ----------
    target, source : Scan, RangeImage or (N, 3) float array, metres
        Points in their own scanner frames.
    variant : {"point-to-point", "point-to-plane", "gicp"}
    T_init : (4, 4) float, optional
        Initial ``T_target_source``; the identity when not given.
    voxel_m : float, optional, metres
        The scale parameter ``v``; default from the scan resolution (2 median spacings of the
        target, enlarged until at most ``max_points`` target points remain).
    max_points : int
        Point budget of the default voxel.
    seed : int
        Unused (ICP is deterministic); recorded in the configuration.
    name : str, optional
        Registry name recorded in the configuration (default ``"icp-" + variant``).

    Returns
    -------
    PairResult
        ``T_coarse`` is the start; ``matches`` = downsampled source points searched at the
        finest level, ``inliers`` = those with a target point within its distance (``2 v``);
        ``fitness`` = inliers / matches; ``correspondences`` = those pairs.

    Raises
    ------
    RegistrationError
        A level found no correspondence at all (no overlap at the start).
    ConfigError
        Unknown variant or invalid voxel.
    """
    import open3d as o3d

    if variant not in VARIANTS:
        raise ConfigError(f"unknown ICP variant {variant!r}; known: {', '.join(VARIANTS)}")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pt = as_points(target, name="target")
    ps = as_points(source, name="source")
    T0, start = initial_transform(T_init)
    v, how = resolve_voxel(voxel_m, pt, max_points)
    tgt = to_open3d(thin(pt, THIN_POINTS))
    src = to_open3d(thin(ps, THIN_POINTS))
    timings["downsampling"] = time.perf_counter() - t0
    T, res, levels, (tl, sl) = run_levels(tgt, src, T0, v, variant, timings)
    reg: Any = o3d.pipelines.registration
    t1 = time.perf_counter()
    info = np.asarray(reg.get_information_matrix_from_point_clouds(sl, tl, levels[-1], T))
    timings["information"] = time.perf_counter() - t1
    config = BaselineConfig(
        method=name or f"icp-{variant}",
        voxel_m=v,
        voxel_source=how,
        start=start,
        seed=seed,
        parameters={
            "variant": variant,
            "levels": [
                {"voxel_m": f * v, "max_distance_m": d * v, "max_iterations": it}
                for f, d, it in ICP_LEVELS
            ],
            "normals": (
                {
                    "radius_m": [NORMAL_RADIUS_VOXELS * f * v for f, _, _ in ICP_LEVELS],
                    "max_nn": NORMAL_MAX_NN,
                }
                if variant == "point-to-plane"
                else (
                    "Open3D's own: 20 nearest neighbours, covariances diag(1e-3, 1, 1)"
                    if variant == "gicp"
                    else None
                )
            ),
            "level_floor": "median point spacing of the finest cloud",
            "threads": 1,
            "thin_above_points": THIN_POINTS,
        },
    )
    n_src = len(sl.points)
    return make_result(
        T=T,
        T_coarse=T0,
        matches=n_src,
        inliers=len(res.correspondence_set),
        inlier_rmse_m=float(res.inlier_rmse),
        fitness=float(res.fitness),
        fitness_denominator=(
            f"{n_src} source points ({v:.3g} m voxels) with a target point within "
            f"{levels[-1]:.3g} m"
        ),
        information=info,
        timings_s=timings,
        threshold_m=levels[-1],
        config=config,
        correspondences=correspondence_pairs(tl, sl, res.correspondence_set),
        prior=start,
    )


def run_levels(
    tgt: Any,
    src: Any,
    T0: NDArray[np.float64],
    v: float,
    variant: str,
    timings: dict[str, float],
) -> tuple[NDArray[np.float64], Any, list[float], tuple[Any, Any]]:
    """ICP over :data:`ICP_LEVELS` on two Open3D clouds (full resolution or thinned).

    Both clouds are voxel-downsampled at the finest level's voxel once; the coarser levels are
    re-binned from that (cheap). Returns ``(T, last Open3D result, distances per level,
    (target, source) of the last level)``; seconds are added to ``timings`` (``downsampling``,
    ``normals``, ``icp``).
    """
    import open3d as o3d

    reg: Any = o3d.pipelines.registration
    T = np.asarray(T0, dtype=np.float64)
    levels: list[float] = []
    res: Any = None
    tl = sl = None
    t0 = time.perf_counter()
    finest = min(f for f, _, _ in ICP_LEVELS)
    tf, sf = tgt.voxel_down_sample(finest * v), src.voxel_down_sample(finest * v)
    # a level voxel below the point spacing downsamples nothing and leaves the normal
    # neighbourhood nearly empty: voxels, normal radii and distances never go below it
    spacing = level_floor(tf)
    timings["downsampling"] = timings.get("downsampling", 0.0) + time.perf_counter() - t0
    for factor, dist_f, iters in ICP_LEVELS:
        t0 = time.perf_counter()
        lv = max(factor * v, spacing)
        tl = tf if factor == finest else tf.voxel_down_sample(lv)
        sl = sf if factor == finest else sf.voxel_down_sample(lv)
        search = o3d.geometry.KDTreeSearchParamHybrid(
            radius=NORMAL_RADIUS_VOXELS * lv, max_nn=NORMAL_MAX_NN
        )
        if variant == "point-to-plane":
            tl.estimate_normals(search)
        t1 = time.perf_counter()
        timings["normals"] = timings.get("normals", 0.0) + t1 - t0
        dist = max(dist_f * v, NORMAL_RADIUS_VOXELS * spacing)
        levels.append(dist)
        crit = reg.ICPConvergenceCriteria(
            relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=iters
        )
        with open3d_threads(1):
            if variant == "point-to-plane":
                est: Any = reg.TransformationEstimationPointToPlane()
                res = reg.registration_icp(sl, tl, dist, T, est, crit)
            elif variant == "gicp":
                est = reg.TransformationEstimationForGeneralizedICP()
                res = reg.registration_generalized_icp(sl, tl, dist, T, est, crit)
            else:
                est = reg.TransformationEstimationPointToPoint()
                res = reg.registration_icp(sl, tl, dist, T, est, crit)
        timings["icp"] = timings.get("icp", 0.0) + time.perf_counter() - t1
        if len(res.correspondence_set) == 0:
            raise RegistrationError(
                f"ICP ({variant}) found no correspondence within {dist:.3g} m of its start "
                f"(level voxel {lv:.3g} m): no overlap there"
            )
        T = np.array(res.transformation, dtype=np.float64)
        if not np.isfinite(T).all():
            raise RegistrationError(f"ICP ({variant}) diverged: the transform holds NaN or Inf")
        log.debug(
            "%s level %.3g m: fitness %.3f, rmse %.3g m",
            variant,
            dist,
            res.fitness,
            res.inlier_rmse,
        )
    return T, res, levels, (tl, sl)


def level_floor(cloud_: Any) -> float:
    """Median nearest-neighbour spacing of an Open3D cloud (metres; 0 for < 2 points)."""
    pts = np.asarray(cloud_.points)
    return median_spacing(pts, sample=2000) if len(pts) >= 2 else 0.0


def icp_point_to_point(target: Any, source: Any, **options: Any) -> PairResult:
    """``icp(..., variant="point-to-point")`` (registry name ``icp-point``)."""
    return icp(target, source, variant="point-to-point", name="icp-point", **options)


def icp_point_to_plane(target: Any, source: Any, **options: Any) -> PairResult:
    """``icp(..., variant="point-to-plane")`` (registry name ``icp-plane``)."""
    return icp(target, source, variant="point-to-plane", name="icp-plane", **options)


def generalized_icp(target: Any, source: Any, **options: Any) -> PairResult:
    """``icp(..., variant="gicp")`` (registry name ``gicp``)."""
    return icp(target, source, variant="gicp", name="gicp", **options)
