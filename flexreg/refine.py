"""ICP refinement with Open3D, seeded by a coarse transform, parameters from the scan resolution."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .errors import ConfigError, RegistrationError

log = logging.getLogger(__name__)

IcpMethod = Literal["point-to-plane", "gicp", "point-to-point"]


@dataclass(frozen=True)
class IcpResult:
    """Outcome of :func:`refine_icp`.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    fitness : float
        Fraction of the *downsampled source* points with a target point within
        ``max_distance_m`` (Open3D's definition; denominator stated by the name).
    inlier_rmse_m : float
    information : (6, 6) float64
        Open3D's information matrix of the correspondences (rotation first, then translation).
    voxel_m, max_distance_m : float
        Parameters used.
    """

    T_target_source: NDArray[np.float64]
    fitness: float
    inlier_rmse_m: float
    information: NDArray[np.float64]
    voxel_m: float
    max_distance_m: float


def median_spacing(points: NDArray[np.float64], *, sample: int = 5000, seed: int = 0) -> float:
    """Median nearest-neighbour distance of a point cloud (metres), from a fixed subsample."""
    from scipy.spatial import cKDTree

    P = np.asarray(points, dtype=np.float64)
    if len(P) < 2:
        raise RegistrationError("cannot estimate point spacing from fewer than 2 points")
    tree = cKDTree(P)
    idx = np.random.default_rng(seed).choice(len(P), min(sample, len(P)), replace=False)
    d, _ = tree.query(P[idx], k=2)
    return float(np.median(d[:, 1]))


def _cloud(points: NDArray[np.float64]) -> Any:
    import open3d as o3d

    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    return pc


def refine_icp(
    target: NDArray[np.float64],
    source: NDArray[np.float64],
    T_init: NDArray[np.float64],
    *,
    method: IcpMethod = "point-to-plane",
    voxel_m: float | None = None,
    max_distance_m: float | None = None,
    max_iterations: int = 60,
) -> IcpResult:
    """Refine ``T_target_source`` with Open3D ICP on voxel-downsampled clouds.

    Parameters
    ----------
    target, source : (N, 3) float64, metres
        Points in their own scanner frames.
    T_init : (4, 4) float64
        Initial ``T_target_source`` (e.g. from RANSAC on feature matches).
    method : {"point-to-plane", "gicp", "point-to-point"}
    voxel_m : float, optional
        Downsampling voxel; default 2x the median point spacing of the target (at least 5 mm).
    max_distance_m : float, optional
        Correspondence distance; default 3 voxels.
    max_iterations : int

    Raises
    ------
    RegistrationError
        ICP found no correspondences at all (no overlap at the initial pose).
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    if voxel_m is None:
        voxel_m = max(0.005, 2.0 * median_spacing(target))
    if max_distance_m is None:
        max_distance_m = 3.0 * voxel_m
    if not (voxel_m > 0 and max_distance_m > 0):
        raise ConfigError(f"voxel and distance must be positive: {voxel_m}, {max_distance_m}")
    tgt = _cloud(target).voxel_down_sample(voxel_m)
    src = _cloud(source).voxel_down_sample(voxel_m)
    search = o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel_m, max_nn=30)
    crit = reg.ICPConvergenceCriteria(
        relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=max_iterations
    )
    T0 = np.asarray(T_init, dtype=np.float64)
    # Open3D's multi-threaded reductions sum in varying order; one thread keeps the result
    # bit-identical from run to run (flexreg's determinism contract).
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        res, tgt, src = _icp(reg, tgt, src, T0, method, search, crit, max_distance_m)
        info = np.asarray(
            reg.get_information_matrix_from_point_clouds(
                src, tgt, max_distance_m, np.asarray(res.transformation)
            )
        )
    finally:
        o3d.utility.set_max_threads(threads)
    if len(res.correspondence_set) == 0:
        raise RegistrationError(
            f"ICP found no correspondences within {max_distance_m:.3g} m of the initial pose"
        )
    return IcpResult(
        T_target_source=np.array(res.transformation, dtype=np.float64),
        fitness=float(res.fitness),
        inlier_rmse_m=float(res.inlier_rmse),
        information=info,
        voxel_m=float(voxel_m),
        max_distance_m=float(max_distance_m),
    )


def _icp(
    reg: Any, tgt: Any, src: Any, T0: Any, method: str, search: Any, crit: Any, dist: float
) -> Any:
    if method == "point-to-plane":
        tgt.estimate_normals(search)
        est: Any = reg.TransformationEstimationPointToPlane()
        res = reg.registration_icp(src, tgt, dist, T0, est, crit)
    elif method == "gicp":
        tgt.estimate_covariances(search)
        src.estimate_covariances(search)
        est = reg.TransformationEstimationForGeneralizedICP()
        res = reg.registration_generalized_icp(src, tgt, dist, T0, est, crit)
    elif method == "point-to-point":
        est = reg.TransformationEstimationPointToPoint()
        res = reg.registration_icp(src, tgt, dist, T0, est, crit)
    else:
        raise ConfigError(f"unknown ICP method {method!r}")
    return res, tgt, src
