"""Open3D global registration: FPFH features + RANSAC, then point-to-plane ICP.

The configuration of Open3D's global-registration tutorial, every size from one voxel ``v``
(the 1:2:5 voxel:normal:FPFH radius rule):

- both clouds voxel-downsampled at ``v`` (clouds above 2 million points thinned to every k-th
  point first);
- normals within ``2 v`` (at most 30 neighbours), FPFH within ``5 v`` (at most 100
  neighbours), :func:`open3d.pipelines.registration.compute_fpfh_feature`;
- :func:`open3d.pipelines.registration.registration_ransac_based_on_feature_matching` with the
  mutual filter, inlier distance ``1.5 v``, point-to-point estimation on 3 correspondences, the
  edge-length (0.9) and distance (``1.5 v``) checkers, and
  ``RANSACConvergenceCriteria(max_iteration=100000, confidence=0.999)``, seeded with
  :func:`open3d.utility.random.seed`;
- refinement: the coarse-to-fine point-to-plane ICP of :mod:`flexreg.baselines.open3d_icp`
  (voxels v, v / 2, v / 4) started from the RANSAC transform, as Open3D's tutorial refines
  the global result on finer clouds than the features.

Features use all cores (per point, so the same with any thread count). RANSAC runs on one
thread by default (``ransac_threads=1``): Open3D's parallel RANSAC draws its hypotheses in
thread order, and with more threads the result changes from run to run even with a fixed seed
(observed on the bunny pair: 1 run in 3 differed by 1° before refinement). The comparison
benchmark runs it with all cores, as Open3D does by default (see
:func:`flexreg.bench.compare.run_method`). The ICP runs on one thread.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from flexreg.baselines._common import (
    DEFAULT_MAX_POINTS,
    BaselineConfig,
    correspondence_pairs,
    make_result,
    open3d_threads,
    resolve_voxel,
)
from flexreg.baselines.open3d_icp import ICP_LEVELS, THIN_POINTS, run_levels
from flexreg.core.results import PairResult
from flexreg.core.scan import as_points
from flexreg.errors import RegistrationError
from flexreg.stages.sampling import thin, to_open3d

#: the 1:2:5 rule: normal and FPFH radii in voxels, with their neighbour caps
NORMAL_RADIUS_VOXELS, NORMAL_MAX_NN = 2.0, 30
FPFH_RADIUS_VOXELS, FPFH_MAX_NN = 5.0, 100
#: RANSAC inlier distance in voxels, edge-length similarity, iterations and confidence
RANSAC_DISTANCE_VOXELS = 1.5
EDGE_LENGTH_SIMILARITY = 0.9
RANSAC_MAX_ITERATIONS = 100_000
RANSAC_CONFIDENCE = 0.999


def fpfh_ransac(
    target: Any,
    source: Any,
    *,
    voxel_m: float | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
    seed: int = 0,
    refine: bool = True,
    ransac_threads: int | None = 1,
    T_init: Any = None,
) -> PairResult:
    """FPFH + RANSAC global registration (no initial guess), then point-to-plane ICP.

    Parameters
    ----------
    target, source : Scan, RangeImage or (N, 3) float array, metres
    voxel_m : float, optional, metres
        The scale ``v``; default from the scan resolution (see
        :func:`~flexreg.baselines._common.default_voxel`).
    max_points : int
        Point budget of the default voxel.
    seed : int
        RANSAC seed.
    refine : bool
        Run the point-to-plane ICP after RANSAC.
    ransac_threads : int or None
        Threads of the RANSAC. 1 (default) makes the result depend on ``seed`` alone; with more
        (None: Open3D's default, all cores) Open3D's hypotheses are drawn in thread order and
        the result can change from run to run even with the same seed.
    T_init : ignored
        Accepted for a uniform signature; a global method needs no start.

    Returns
    -------
    PairResult
        ``T_coarse`` = the RANSAC transform; ``matches`` = downsampled source points, each with
        its nearest FPFH neighbour in the target (before the mutual filter); ``inliers`` =
        RANSAC inliers within ``1.5 v``. With refinement, ``inlier_rmse_m``, ``fitness`` and
        ``correspondences`` are those of the final ICP level.

    Raises
    ------
    RegistrationError
        RANSAC found no consistent correspondence set, or the ICP no overlap.
    """
    import open3d as o3d

    reg: Any = o3d.pipelines.registration
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pt = as_points(target, name="target")
    ps = as_points(source, name="source")
    v, how = resolve_voxel(voxel_m, pt, max_points)
    tgt_full, src_full = to_open3d(thin(pt, THIN_POINTS)), to_open3d(thin(ps, THIN_POINTS))
    tgt, src = tgt_full.voxel_down_sample(v), src_full.voxel_down_sample(v)
    t1 = time.perf_counter()
    timings["downsampling"] = t1 - t0
    feats = [fpfh_features(pc, v) for pc in (tgt, src)]
    t2 = time.perf_counter()
    timings["features"] = t2 - t1
    dist = RANSAC_DISTANCE_VOXELS * v
    coarse = ransac_on_features(tgt, src, feats[0], feats[1], dist, int(seed), ransac_threads)
    timings["ransac"] = time.perf_counter() - t2
    n_inl = len(coarse.correspondence_set)
    if n_inl < 3:
        raise RegistrationError(
            f"FPFH + RANSAC found {n_inl} consistent correspondences among {len(src.points)} "
            f"source / {len(tgt.points)} target points ({v:.3g} m voxels)"
        )
    T_coarse = np.array(coarse.transformation, dtype=np.float64)
    T, res, final_dist = T_coarse, coarse, dist
    tl, sl = tgt, src
    if refine:
        T, res, levels, (tl, sl) = run_levels(
            tgt_full, src_full, T_coarse, v, "point-to-plane", timings
        )
        final_dist = levels[-1]
    t3 = time.perf_counter()
    info = np.asarray(reg.get_information_matrix_from_point_clouds(sl, tl, final_dist, T))
    timings["information"] = time.perf_counter() - t3
    config = _settings(v, how, int(seed), dist, ransac_threads, refine)
    n_src = len(sl.points)
    return make_result(
        T=T,
        T_coarse=T_coarse,
        matches=len(src.points),
        inliers=n_inl,
        inlier_rmse_m=float(res.inlier_rmse),
        fitness=float(res.fitness),
        fitness_denominator=(
            f"{n_src} source points ({v:.3g} m voxels) with a target point within "
            f"{final_dist:.3g} m"
        ),
        information=info,
        timings_s=timings,
        threshold_m=final_dist,
        config=config,
        correspondences=correspondence_pairs(tl, sl, res.correspondence_set),
        prior="fpfh-ransac",
    )


def fpfh_features(cloud: Any, v: float) -> Any:
    """Normals (within ``2 v``, at most 30 neighbours, set on ``cloud``) and FPFH features
    (within ``5 v``, at most 100 neighbours) of a voxel-downsampled Open3D cloud.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud
        Downsampled at ``v``; its normals are (re)estimated in place.
    v : float, metres
        The scale voxel.

    Returns
    -------
    open3d.pipelines.registration.Feature
        (33, N) FPFH histograms, one column per point.
    """
    import open3d as o3d  # heavy: loaded only when the baseline runs

    reg: Any = o3d.pipelines.registration
    cloud.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(radius=NORMAL_RADIUS_VOXELS * v, max_nn=NORMAL_MAX_NN)
    )
    return reg.compute_fpfh_feature(
        cloud,
        o3d.geometry.KDTreeSearchParamHybrid(radius=FPFH_RADIUS_VOXELS * v, max_nn=FPFH_MAX_NN),
    )


def ransac_on_features(
    tgt: Any,
    src: Any,
    tgt_feature: Any,
    src_feature: Any,
    dist: float,
    seed: int,
    ransac_threads: int | None,
) -> Any:
    """Open3D's RANSAC on mutual FPFH matches (the tutorial's checkers and criteria), seeded
    with :func:`open3d.utility.random.seed`; ``dist`` is the inlier distance (metres).
    Returns Open3D's ``RegistrationResult`` (its transformation maps ``src`` into ``tgt``)."""
    import open3d as o3d  # heavy: loaded only when the baseline runs

    reg: Any = o3d.pipelines.registration
    o3d.utility.random.seed(seed)
    with open3d_threads(ransac_threads):
        return reg.registration_ransac_based_on_feature_matching(
            src,
            tgt,
            src_feature,
            tgt_feature,
            True,
            dist,
            reg.TransformationEstimationPointToPoint(False),
            3,
            [
                reg.CorrespondenceCheckerBasedOnEdgeLength(EDGE_LENGTH_SIMILARITY),
                reg.CorrespondenceCheckerBasedOnDistance(dist),
            ],
            reg.RANSACConvergenceCriteria(RANSAC_MAX_ITERATIONS, RANSAC_CONFIDENCE),
        )


def _settings(
    v: float, how: str, seed: int, dist: float, ransac_threads: int | None, refine: bool
) -> BaselineConfig:
    """The record of how the baseline ran: every size from the voxel ``v``."""
    return BaselineConfig(
        method="fpfh-ransac",
        voxel_m=v,
        voxel_source=how,
        start="global",
        seed=seed,
        parameters={
            "normal_radius_m": NORMAL_RADIUS_VOXELS * v,
            "normal_max_nn": NORMAL_MAX_NN,
            "fpfh_radius_m": FPFH_RADIUS_VOXELS * v,
            "fpfh_max_nn": FPFH_MAX_NN,
            "mutual_filter": True,
            "ransac_distance_m": dist,
            "ransac_n": 3,
            "edge_length_similarity": EDGE_LENGTH_SIMILARITY,
            "ransac_max_iterations": RANSAC_MAX_ITERATIONS,
            "ransac_confidence": RANSAC_CONFIDENCE,
            "ransac_threads": "all (Open3D default)" if ransac_threads is None else ransac_threads,
            "refinement": (
                {
                    "variant": "point-to-plane",
                    "levels": [
                        {"voxel_m": f * v, "max_distance_m": d * v, "max_iterations": it}
                        for f, d, it in ICP_LEVELS
                    ],
                    "threads": 1,
                }
                if refine
                else None
            ),
            "thin_above_points": THIN_POINTS,
        },
    )
