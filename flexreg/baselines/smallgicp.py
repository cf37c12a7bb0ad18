"""small_gicp (the optional ``small_gicp`` pip package) as a fast GICP reference.

Only available when ``small_gicp`` is importable (flexreg does not depend on it). With the
scale voxel ``v`` (same default as the Open3D baselines):
``small_gicp.preprocess_points(points, downsampling_resolution=v / 2, num_neighbors=10)`` for
both clouds (voxel grid + covariances from 10 neighbours, small_gicp's default), then
``small_gicp.align(target, source, target_tree, init_T_target_source=T_init,
registration_type="GICP", max_correspondence_distance=2 v, max_iterations=20)``: small_gicp's
own default ratio of correspondence distance to downsampling resolution (1.0 m : 0.25 m). One
thread, so that the result is identical from run to run.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from flexreg.baselines._common import (
    DEFAULT_MAX_POINTS,
    BaselineConfig,
    initial_transform,
    make_result,
    resolve_voxel,
)
from flexreg.core.results import PairResult
from flexreg.core.scan import as_points
from flexreg.core.transforms import apply
from flexreg.errors import RegistrationError

#: downsampling resolution in scale voxels, and the correspondence distance in downsampling
#: resolutions (small_gicp's default 1.0 m / 0.25 m)
RESOLUTION_VOXELS = 0.5
DISTANCE_RESOLUTIONS = 4.0
NUM_NEIGHBORS = 10
MAX_ITERATIONS = 20


def small_gicp_align(
    target: Any,
    source: Any,
    *,
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
    seed: int = 0,
) -> PairResult:
    """GICP with small_gicp from the identity or ``T_init`` (see the module notes).

    Parameters
    ----------
    target, source : Scan, RangeImage or (N, 3) float array, metres
    T_init : (4, 4) float, optional
        Initial ``T_target_source``; identity by default.
    voxel_m : float, optional, metres
        Downsampling resolution ``v``; default from the scan resolution.
    max_points : int
        Point budget of the default voxel.
    seed : int
        Unused (deterministic); recorded in the configuration.

    Returns
    -------
    PairResult
        ``matches`` = downsampled source points, ``inliers`` = small_gicp's ``num_inliers``
        (within ``2 v``), ``fitness`` = their share, ``inlier_rmse_m`` over them,
        ``information`` = small_gicp's Hessian ``H`` (rotation first, like Open3D's).

    Raises
    ------
    RegistrationError
        No inlier at the end (no overlap from the start).
    """
    import small_gicp

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pt = as_points(target, name="target")
    ps = as_points(source, name="source")
    T0, start = initial_transform(T_init)
    v, how = resolve_voxel(voxel_m, pt, max_points)
    res_m = RESOLUTION_VOXELS * v
    tgt, tree = small_gicp.preprocess_points(
        pt, downsampling_resolution=res_m, num_neighbors=NUM_NEIGHBORS, num_threads=1
    )
    src, _ = small_gicp.preprocess_points(
        ps, downsampling_resolution=res_m, num_neighbors=NUM_NEIGHBORS, num_threads=1
    )
    t1 = time.perf_counter()
    timings["preprocessing"] = t1 - t0
    dist = DISTANCE_RESOLUTIONS * res_m
    res = small_gicp.align(
        tgt,
        src,
        tree,
        init_T_target_source=T0,
        registration_type="GICP",
        max_correspondence_distance=dist,
        num_threads=1,
        max_iterations=MAX_ITERATIONS,
    )
    timings["registration"] = time.perf_counter() - t1
    T = np.asarray(res.T_target_source, dtype=np.float64)
    n_src = int(src.size())
    n_inl = int(res.num_inliers)
    if n_inl == 0:
        raise RegistrationError(
            f"small_gicp found no correspondence within {dist:.3g} m of its start: no overlap"
        )
    # residuals of the source points that have a target point within the distance
    ts = np.asarray(tgt.points())[:, :3]
    ss = np.asarray(src.points())[:, :3]
    d, idx = cKDTree(ts).query(apply(T, ss), distance_upper_bound=dist)
    ok = np.isfinite(d)
    rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan")
    corr = np.stack([ts[idx[ok]], ss[ok]], axis=1)
    config = BaselineConfig(
        method="small-gicp",
        voxel_m=v,
        voxel_source=how,
        start=start,
        seed=seed,
        parameters={
            "registration_type": "GICP",
            "downsampling_resolution_m": res_m,
            "num_neighbors": NUM_NEIGHBORS,
            "max_correspondence_distance_m": dist,
            "max_iterations": MAX_ITERATIONS,
            "num_threads": 1,
            "converged": bool(res.converged),
            "iterations": int(res.iterations),
        },
    )
    return make_result(
        T=T,
        T_coarse=T0,
        matches=n_src,
        inliers=n_inl,
        inlier_rmse_m=rmse,
        fitness=n_inl / n_src if n_src else 0.0,
        fitness_denominator=(
            f"{n_src} source points ({res_m:.3g} m voxels) with a target point within {dist:.3g} m"
        ),
        information=np.asarray(res.H, dtype=np.float64),
        timings_s=timings,
        threshold_m=dist,
        config=config,
        correspondences=corr,
        prior=start,
    )
