"""The one result type of every ICP refinement (Open3D nearest-neighbour and projective)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class IcpResult:
    """Outcome of an ICP refinement (:func:`flexreg.stages.refinement.refine`,
    :func:`~flexreg.stages.refinement.icp.refine_icp`,
    :func:`~flexreg.stages.refinement.projective.projective_icp`).

    Attributes
    ----------
    T_target_source : (4, 4) float64
    fitness : float
        Nearest-neighbour ICP: fraction of the *downsampled source* points with a target point
        within ``max_distance_m`` (Open3D's definition). Projective ICP: share of the sampled
        points paired at the final correspondence distance. ``source_points`` is the
        denominator.
    inlier_rmse_m : float
        RMS residual of the paired points (point-to-plane for projective ICP), metres.
    information : (6, 6) float64
        Information matrix of the correspondences (Open3D's convention: rotation first, then
        translation).
    voxel_m : float
        Downsampling voxel used, metres (projective: the cell of the source's even sampling,
        NaN when :func:`~flexreg.stages.refinement.projective.projective_icp` is called
        directly).
    max_distance_m : float
        Correspondence distance of the final ICP level (``fitness`` and ``inlier_rmse_m``
        refer to it), metres.
    source_points : int
        Downsampled source points (the denominator of ``fitness``); projective and symmetric:
        the sampled points of both scans.
    association : {"nearest", "projective"}
        How source points found their target partners: nearest neighbour (Open3D ICP) or the
        pixel hit by their ray in the target's range image (projective ICP).
    iterations : int
        Iterations over all distance levels (projective ICP; 0 when not counted).
    """

    T_target_source: NDArray[np.float64]
    fitness: float
    inlier_rmse_m: float
    information: NDArray[np.float64]
    voxel_m: float
    max_distance_m: float
    source_points: int = 0
    association: str = "nearest"
    iterations: int = 0


__all__ = ["IcpResult"]
