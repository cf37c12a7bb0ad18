"""ICP refinement with Open3D, seeded by a coarse transform, parameters from the scan resolution."""

from __future__ import annotations

import logging
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ConfigError, RegistrationError
from flexreg.stages.refinement.result import IcpResult
from flexreg.stages.sampling import median_spacing, thin_random, to_open3d

log = logging.getLogger(__name__)

IcpMethod = Literal["point-to-plane", "gicp", "point-to-point"]

#: clouds above this many points are randomly thinned (fixed seed) before voxel downsampling
_PRE_THIN = 1_000_000

#: smallest ICP correspondence distance, in voxels
_FLOOR = 0.5


def refine_icp(
    target: NDArray[np.float64],
    source: NDArray[np.float64],
    T_init: NDArray[np.float64],
    *,
    method: IcpMethod = "point-to-plane",
    voxel_m: float | None = None,
    max_distance_m: float | None = None,
    max_iterations: int = 30,
    max_target_points: int = 150_000,
    max_source_points: int = 40_000,
    initial_error_m: float = 0.0,
) -> IcpResult:
    """Refine ``T_target_source`` with Open3D ICP on downsampled clouds, coarse to fine.

    The target is voxel-downsampled (its normals or covariances come from that cloud), the
    source is downsampled with the same voxel and then thinned to ``max_source_points`` evenly
    spread points: the source only supplies residuals, and a few tens of thousands of them pin
    a rigid transform far below the noise. ICP runs three times with a shrinking
    correspondence distance (``max_distance_m``, a third of it, a tenth of it but at least
    half a voxel), so a start a few centimetres off converges without letting the final
    iterations pair points across surfaces.

    Parameters
    ----------
    target, source : (N, 3) float64, metres
        Points in their own scanner frames.
    T_init : (4, 4) float64
        Initial ``T_target_source`` (e.g. from RANSAC on feature matches).
    method : {"point-to-plane", "gicp", "point-to-point"}
    voxel_m : float, optional
        Downsampling voxel; default twice the target's median point spacing, enlarged until
        the target keeps at most ``max_target_points`` points.
    max_distance_m : float, optional
        First correspondence distance; default 5 voxels or ``initial_error_m``, whichever is
        larger.
    max_iterations : int
        Per distance level.
    max_target_points, max_source_points : int
        Point budgets (speed on large scans).
    initial_error_m : float, metres
        How far off ``T_init`` may be.

    Raises
    ------
    RegistrationError
        ICP found no correspondences at all (no overlap at the initial pose).
    """
    import open3d as o3d  # heavy: loaded only when an Open3D refinement runs

    reg = o3d.pipelines.registration
    # very large scans: a random thinning first (voxels of the sizes used here hold many
    # points, so the voxel grid hardly changes, and the downsampling gets much cheaper)
    target = thin_random(np.asarray(target), _PRE_THIN)
    source = thin_random(np.asarray(source), _PRE_THIN)
    auto_voxel = voxel_m is None
    if voxel_m is None:
        voxel_m = 2.0 * median_spacing(target, tree_points=200_000)
    elif not voxel_m > 0:
        raise ConfigError(f"voxel must be positive, got {voxel_m}")
    tgt = to_open3d(target).voxel_down_sample(voxel_m)
    for _ in range(6 if auto_voxel else 0):  # point count falls with the square of the voxel
        if len(tgt.points) <= max_target_points:
            break
        voxel_m *= 1.1 * float(np.sqrt(len(tgt.points) / max_target_points))
        tgt = tgt.voxel_down_sample(voxel_m)  # re-binning the smaller cloud is cheap
    if max_distance_m is None:
        max_distance_m = max(5.0 * voxel_m, initial_error_m)
    if not max_distance_m > 0:
        raise ConfigError(f"ICP distance must be positive, got {max_distance_m}")
    src = to_open3d(source).voxel_down_sample(voxel_m)
    if len(src.points) > max_source_points:
        src = src.uniform_down_sample(int(np.ceil(len(src.points) / max_source_points)))
    search = o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel_m, max_nn=20)
    crit = reg.ICPConvergenceCriteria(
        relative_fitness=1e-8, relative_rmse=1e-8, max_iteration=max_iterations
    )
    T = np.asarray(T_init, dtype=np.float64)
    levels: list[float] = []
    # Open3D's multi-threaded reductions sum in varying order; one thread keeps the result
    # bit-identical from run to run (flexreg's determinism contract).
    _prepare(tgt, src, method, search)  # per point: the same with any number of threads
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        for shrink in (1.0, 3.0, 10.0):
            # below half a voxel, or below the typical gap between the two clouds' samples
            # (sparse lidar rings), two samplings of one surface would lose each other
            dist = max(max_distance_m / shrink, _FLOOR * voxel_m)
            if shrink == 10.0:
                dist = max(dist, _sample_gap(tgt, src, T, levels[-1]))
            levels.append(dist)
            res = _icp(reg, tgt, src, T, method, crit, dist)
            if len(res.correspondence_set) == 0:
                raise RegistrationError(
                    f"ICP found no correspondences within {dist:.3g} m of the initial pose"
                )
            T = np.array(res.transformation, dtype=np.float64)
        info = np.asarray(reg.get_information_matrix_from_point_clouds(src, tgt, levels[-1], T))
    finally:
        o3d.utility.set_max_threads(threads)
    log.info(
        "ICP on %d target / %d source points, voxel %.3g m: fitness %.3f, rmse %.3g m",
        len(tgt.points),
        len(src.points),
        voxel_m,
        res.fitness,
        res.inlier_rmse,
    )
    return IcpResult(
        T_target_source=T,
        fitness=float(res.fitness),
        inlier_rmse_m=float(res.inlier_rmse),
        information=info,
        voxel_m=float(voxel_m),
        max_distance_m=float(levels[-1]),
        source_points=len(src.points),
    )


def _sample_gap(tgt: Any, src: Any, T: NDArray[np.float64], within: float) -> float:
    """Median distance from the source points (placed by ``T``) to their nearest target point,
    among those closer than ``within``, metres."""
    q = np.asarray(src.points) @ T[:3, :3].T + T[:3, 3]
    from scipy.spatial import cKDTree  # heavy (0.1 s): the CLI imports this module at start-up

    d, _ = cKDTree(np.asarray(tgt.points)).query(q, distance_upper_bound=within)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else 0.0


def _prepare(tgt: Any, src: Any, method: str, search: Any) -> None:
    if method == "point-to-plane":
        tgt.estimate_normals(search)
    elif method == "gicp":
        # Open3D builds regularised covariances itself (its own 20-neighbour normals); raw
        # covariances of planar patches are near-singular and can give NaN transforms
        pass
    elif method != "point-to-point":
        raise ConfigError(f"unknown ICP method {method!r}")


def _icp(reg: Any, tgt: Any, src: Any, T0: Any, method: str, crit: Any, dist: float) -> Any:
    if method == "point-to-plane":
        est: Any = reg.TransformationEstimationPointToPlane()
        return reg.registration_icp(src, tgt, dist, T0, est, crit)
    if method == "gicp":
        est = reg.TransformationEstimationForGeneralizedICP()
        return reg.registration_generalized_icp(src, tgt, dist, T0, est, crit)
    est = reg.TransformationEstimationPointToPoint()
    return reg.registration_icp(src, tgt, dist, T0, est, crit)
