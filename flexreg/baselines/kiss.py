"""KISS-ICP (the ``kiss-icp`` pip package) on one static scan pair.

KISS-ICP is a lidar odometry: it registers each new frame to a voxel map of the previous ones,
starting from a constant-velocity prediction. A pair of static scans is fed to it as a
two-frame sequence, exactly as follows:

1. ``KISSConfig()`` with ``data.deskew = False`` (static scans: no motion within a scan),
   ``data.min_range = 0``, ``data.max_range`` = 1.01 x the largest range of any point of
   either scan (no point is cut), ``mapping.voxel_size`` = ``voxel_m`` if given, else
   KISS-ICP's own rule ``max_range / 100`` (the voxel "from the data"); everything else keeps
   KISS-ICP's defaults (``max_points_per_voxel`` 20, adaptive threshold with
   ``initial_threshold`` 2.0 m and ``min_motion_th`` 0.1 m, ``max_num_iterations`` 500,
   ``convergence_criterion`` 1e-4), except ``registration.max_num_threads = 1``: with more
   threads its reductions sum in varying order and the result changes from run to run.
2. ``KissICP(config).register_frame(target, timestamps)``: the first frame has an empty map,
   so its pose stays the identity and it becomes the map (the target frame is the world).
3. ``register_frame(source, timestamps)``: the initial guess is ``last_pose @ last_delta`` =
   the identity, the correspondence distance ``3 sigma`` with ``sigma`` = the initial
   threshold (no motion has been observed yet); the estimated pose ``last_pose`` is
   ``T_target_source``.

So KISS-ICP **starts from the identity**. A given ``T_init`` is honoured by feeding the source
points already moved by it and composing the result with it (``T = T_kiss @ T_init``).
Timestamps are all zero (unused without deskewing).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from flexreg.baselines._common import (
    BaselineConfig,
    initial_transform,
    make_result,
)
from flexreg.core.results import PairResult
from flexreg.core.scan import as_points
from flexreg.core.transforms import apply, invert
from flexreg.errors import ConfigError, RegistrationError
from flexreg.stages.sampling import to_open3d

#: max_range = this x the largest point range of the pair ("covering the scan")
RANGE_MARGIN = 1.01
#: KISS-ICP's own default voxel rule: max_range / 100
VOXELS_PER_RANGE = 100.0


def kiss_icp(
    target: Any,
    source: Any,
    *,
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    seed: int = 0,
) -> PairResult:
    """Register ``source`` onto ``target`` with KISS-ICP (see the module notes for how).

    Parameters
    ----------
    target, source : Scan, RangeImage or (N, 3) float array, metres
        Points in their scanner frames (ranges are measured from the origin).
    T_init : (4, 4) float, optional
        Initial ``T_target_source`` (the source is pre-moved by it); identity by default.
    voxel_m : float, optional, metres
        KISS-ICP map voxel; default ``max_range / 100`` (KISS-ICP's rule).
    seed : int
        Unused (KISS-ICP is deterministic); recorded in the configuration.

    Returns
    -------
    PairResult
        ``T_coarse`` is the start; ``matches`` = the source points KISS-ICP registered (its
        ``1.5 x voxel`` subsample), ``inliers`` / ``fitness`` / ``inlier_rmse_m`` = those with
        a map point within ``3 sigma`` (the distance KISS-ICP used), evaluated by Open3D.

    Raises
    ------
    RegistrationError
        The map or the registered source ended up empty.
    """
    import open3d as o3d
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pt = as_points(target, name="target")
    ps = as_points(source, name="source")
    T0, start = initial_transform(T_init)
    ps_moved = apply(T0, ps) if start != "identity" else ps
    r_max = max(float(np.sqrt((pt * pt).sum(1).max())), float(np.sqrt((ps * ps).sum(1).max())))
    max_range = RANGE_MARGIN * r_max
    if voxel_m is None:
        voxel, how = max_range / VOXELS_PER_RANGE, f"max_range / {VOXELS_PER_RANGE:g} (KISS-ICP)"
    elif np.isfinite(voxel_m) and voxel_m > 0:
        voxel, how = float(voxel_m), "given"
    else:
        raise ConfigError(f"voxel must be a positive number of metres, got {voxel_m}")
    config = KISSConfig()
    config.data.deskew = False
    config.data.min_range = 0.0
    config.data.max_range = max_range
    config.mapping.voxel_size = voxel
    config.registration.max_num_threads = 1
    kiss = KissICP(config)
    sigma = float(kiss.adaptive_threshold.get_threshold())
    timings["setup"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    kiss.register_frame(pt, np.zeros(len(pt)))
    timings["map"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    _, used = kiss.register_frame(ps_moved, np.zeros(len(ps_moved)))
    timings["registration"] = time.perf_counter() - t2
    T_kiss = np.asarray(kiss.last_pose, dtype=np.float64)
    T = T_kiss @ T0
    t3 = time.perf_counter()
    used = np.asarray(used, dtype=np.float64).reshape(-1, 3)
    map_points = np.asarray(kiss.local_map.point_cloud(), dtype=np.float64).reshape(-1, 3)
    if len(used) == 0 or len(map_points) == 0:
        raise RegistrationError(
            f"KISS-ICP kept {len(map_points)} map / {len(used)} source points "
            f"(voxel {voxel:.3g} m, max range {max_range:.3g} m)"
        )
    reg: Any = o3d.pipelines.registration
    dist = 3.0 * sigma
    # `used` is in the frame of the points fed (the source moved by T0), so evaluate with T_kiss
    src, tgt = to_open3d(used), to_open3d(map_points)
    ev = reg.evaluate_registration(src, tgt, dist, T_kiss)
    info = np.asarray(reg.get_information_matrix_from_point_clouds(src, tgt, dist, T_kiss))
    corr = np.asarray(ev.correspondence_set, dtype=np.int64).reshape(-1, 2)
    pairs = np.stack([map_points[corr[:, 1]], apply(invert(T0), used[corr[:, 0]])], axis=1)
    timings["evaluation"] = time.perf_counter() - t3
    cfg = BaselineConfig(
        method="kiss-icp",
        voxel_m=voxel,
        voxel_source=how,
        start=start,
        seed=seed,
        parameters={
            "kiss_config": config.model_dump(),
            "frames": "target first (the map, pose = identity), then source",
            "initial_guess": "identity" if start == "identity" else "source pre-moved by T_init",
            "correspondence_distance_m": dist,
        },
    )
    return make_result(
        T=T,
        T_coarse=T0,
        matches=len(used),
        inliers=len(corr),
        inlier_rmse_m=float(ev.inlier_rmse),
        fitness=float(ev.fitness),
        fitness_denominator=(
            f"{len(used)} source points registered by KISS-ICP ({1.5 * voxel:.3g} m voxels) "
            f"with a map point within {dist:.3g} m"
        ),
        information=info,
        timings_s=timings,
        threshold_m=dist,
        config=cfg,
        correspondences=pairs,
        prior=start,
    )
