"""Pieces shared by the baselines: the scale parameter, the start, Open3D threads, results."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.results import PairResult
from flexreg.core.transforms import as_transform
from flexreg.errors import ConfigError
from flexreg.stages.overlap import SCALE_MAX_POINTS, scale_voxel

#: default point budget of the scale parameter: the voxel is enlarged until the voxel-downsampled
#: target keeps at most this many points (FPFH + RANSAC cost grows quickly with the count)
DEFAULT_MAX_POINTS = SCALE_MAX_POINTS


@dataclass(frozen=True)
class BaselineConfig:
    """How a baseline was run; stored in its :class:`~flexreg.core.results.PairResult`
    (``seed`` and ``to_dict()`` are what the result uses).

    Attributes
    ----------
    method : str
        Registry name (``"icp-plane"``, ``"fpfh-ransac"``, ...).
    voxel_m : float, metres
        The scale parameter every size of the method derives from.
    voxel_source : str
        ``"given"`` or how the default was derived from the scan resolution.
    start : str
        ``"identity"``, ``"initial guess"`` or ``"global"`` (no start needed).
    seed : int
        Seed of the method's randomness (RANSAC); same seed, same result.
    parameters : dict
        Every other setting, with its value (distances in metres).
    """

    method: str
    voxel_m: float
    voxel_source: str
    start: str
    seed: int = 0
    parameters: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "voxel_m": self.voxel_m,
            "voxel_source": self.voxel_source,
            "start": self.start,
            "seed": self.seed,
            "parameters": dict(self.parameters),
        }


def initial_transform(T_init: ArrayLike | None) -> tuple[NDArray[np.float64], str]:
    """``(T, start)``: the validated initial guess, or the identity."""
    if T_init is None:
        return np.eye(4), "identity"
    return as_transform(T_init, name="T_init"), "initial guess"


def default_voxel(
    target: NDArray[np.float64], *, max_points: int = DEFAULT_MAX_POINTS
) -> tuple[float, str]:
    """The baselines' scale parameter ``(voxel_m, how)``: the rule of the overlap figure of
    every result, :func:`flexreg.stages.overlap.scale_voxel` (parameters and returns there)."""
    return scale_voxel(target, max_points=max_points)


def resolve_voxel(
    voxel_m: float | None, target: NDArray[np.float64], max_points: int
) -> tuple[float, str]:
    """The given voxel (validated) or :func:`default_voxel`."""
    if voxel_m is None:
        return default_voxel(target, max_points=max_points)
    if not (math.isfinite(voxel_m) and voxel_m > 0):
        raise ConfigError(f"voxel must be a positive number of metres, got {voxel_m}")
    return float(voxel_m), "given"


@contextmanager
def open3d_threads(n: int | None) -> Iterator[None]:
    """Run Open3D with at most ``n`` threads inside the block (``None``: unchanged)."""
    import open3d as o3d

    if n is None:
        yield
        return
    old = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(int(n))
    try:
        yield
    finally:
        o3d.utility.set_max_threads(old)


def make_result(
    *,
    T: NDArray[np.float64],
    T_coarse: NDArray[np.float64],
    matches: int,
    inliers: int,
    inlier_rmse_m: float,
    fitness: float,
    fitness_denominator: str,
    information: NDArray[np.float64],
    timings_s: dict[str, float],
    threshold_m: float,
    config: BaselineConfig,
    correspondences: NDArray[np.float64] | None = None,
    prior: str,
) -> PairResult:
    """A :class:`~flexreg.core.results.PairResult` for a baseline.

    ``keypoints`` are empty (no image features).
    """
    corr = np.zeros((0, 2, 3)) if correspondences is None else correspondences
    return PairResult(
        T_target_source=np.asarray(T, dtype=np.float64),
        T_coarse=np.asarray(T_coarse, dtype=np.float64),
        matches=int(matches),
        inliers=int(inliers),
        inlier_rmse_m=float(inlier_rmse_m),
        fitness=float(fitness),
        fitness_denominator=fitness_denominator,
        information=np.asarray(information, dtype=np.float64),
        timings_s=timings_s,
        threshold_m=float(threshold_m),
        config=config,
        correspondences=corr,
        inlier_mask=np.ones(len(corr), dtype=bool),
        keypoints=(np.zeros((0, 2)), np.zeros((0, 2))),
        prior=prior,
        wall_s=float(sum(timings_s.values())),  # the baselines' stages run one after another
    )


def correspondence_pairs(target: Any, source: Any, correspondence_set: Any) -> NDArray[np.float64]:
    """(Q, 2, 3) ``[target point, source point]`` pairs (scanner frames) of an Open3D
    correspondence set ``(source index, target index)``."""
    c = np.asarray(correspondence_set, dtype=np.int64).reshape(-1, 2)
    if len(c) == 0:
        return np.zeros((0, 2, 3))
    pt = np.asarray(target.points)[c[:, 1]]
    ps = np.asarray(source.points)[c[:, 0]]
    return np.stack([pt, ps], axis=1)
