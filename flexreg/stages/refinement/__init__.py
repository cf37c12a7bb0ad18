"""ICP refinement of a coarse ``T_target_source``: :func:`refine` chooses the method.

- :mod:`.projective` — symmetric projective point-to-plane ICP on both range images (the
  default: constant-time association through each scan's camera model, full resolution).
- :mod:`.icp` — Open3D nearest-neighbour ICP (GICP, point-to-point, point-to-plane at a fixed
  voxel) on voxel-downsampled clouds, coarse to fine.

Both return one :class:`IcpResult`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan, as_points
from flexreg.stages.projection import camera_image
from flexreg.stages.refinement.icp import IcpMethod, refine_icp
from flexreg.stages.refinement.projective import projective_icp
from flexreg.stages.refinement.result import IcpResult
from flexreg.stages.sampling import area_cell, area_sample, area_sample_cell
from flexreg.stages.verification import classify_points, measured_image, range_slack

log = logging.getLogger(__name__)

#: points of the projective refinement, half from each scan (spread evenly over its surfaces)
PROJECTIVE_ICP_POINTS = 30_000


#: target points of the area-weighted scale of the Open3D refinement (GICP, point-to-point;
#: see :func:`area_cell`)
AREA_ICP_POINTS = 10_000

#: most correspondence levels of a refinement from ``reach_m``: enough that the distance,
#: shrinking by thirds, meets four robust standard deviations of the residuals first (0.5 m
#: reaches 0.2 mm after eight)
REACH_LEVELS = 8

#: the finest ICP scale is kept unless the dense check scores it this much lower (fraction of
#: the sampled source points) than the area-weighted scale
FINE_ICP_SLACK = 0.01


def refine(
    target: Scan | RangeImage,
    source: Scan | RangeImage,
    T_init: NDArray[np.float64],
    *,
    threshold_m: float,
    method: str = "point-to-plane",
    voxel_m: float | None = None,
    projective: bool = True,
    check: Callable[[NDArray[np.float64]], float] | None = None,
    target_image: RangeImage | None = None,
    target_normals: NDArray[np.float32] | None = None,
    source_image: RangeImage | None = None,
    source_normals: NDArray[np.float32] | None = None,
    samples: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None,
    reach_m: float | None = None,
) -> IcpResult:
    """ICP refinement of a coarse ``T_target_source``.

    **Point-to-plane (default): symmetric projective ICP on both range images**
    (:func:`~flexreg.stages.refinement.projective.projective_icp`). About
    :data:`PROJECTIVE_ICP_POINTS` points, half from each scan, spread evenly over its surfaces
    (:func:`~flexreg.stages.sampling.area_sample`), are paired with the other scan's pixel
    their rays hit, whose plane comes from that image's grid; both scans keep their full image
    resolution. Sampling by area keeps the dense, noisy or self-similar near field of a scanner
    (a corridor's walls fit any shift along it) from outweighing the far structure that fixes
    the pose; pairing in both directions keeps either scan's viewpoint and normals alone from
    deciding it.

    **GICP, point-to-point, a fixed voxel, or clouds that are no sensor's grid: Open3D**
    nearest-neighbour ICP at two scales.
    First on voxels sized so that the target keeps about :data:`AREA_ICP_POINTS`
    (:func:`~flexreg.stages.sampling.area_cell`, area-weighted as above), then at the finest
    voxels the point budget allows (:func:`~flexreg.stages.refinement.icp.refine_icp`), started
    from the first; the fine result is kept unless the dense free-space check scores it more
    than :data:`FINE_ICP_SLACK` lower. With ``voxel_m``, one coarse-to-fine ICP at that voxel.

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
    projective : bool
        False when either scan's image is no sensor's grid but a cloud projected with gaps
        between its returns (:func:`~flexreg.stages.projection.sampling_gaps`: a rosette, a
        fused fragment): a pixel then pairs a point with whichever return fell nearest its
        ray, or none, so point-to-plane pairs nearest points (Open3D) instead.
    check : callable, optional
        Open3D path: ``check(T) -> score`` (higher is better); default the consistent minus
        three times the conflicting fraction of
        :func:`~flexreg.stages.verification.overlap_score` at ``threshold_m / 2``.
    target_image : RangeImage, optional
        The target's range image with a camera model, when already at hand (projective path).
    target_normals : (H, W, 3) float32, optional
        Its :func:`flexreg.stages.normals.grid_normals`, when already at hand.
    source_image : RangeImage, optional
        The source's range image with a camera model, when already at hand.
    source_normals : (H, W, 3) float32, optional
        Its :func:`flexreg.stages.normals.grid_normals`, when already at hand.
    samples : (float, (N, 3) float64, (M, 3) float64), optional
        The projective path's area samples (source cell size, source and target points), when
        already at hand.
    reach_m : float, optional
        Projective path: the first correspondence distance, when ``T_init`` may be further
        off than three inlier thresholds (a pose slid by a wall's thickness: only pairs
        seen from the same side reach across it); the distance then shrinks by thirds until
        it meets four robust standard deviations of the residuals (the scans' noise), not
        after a set number of levels. Default: from three inlier thresholds, three levels.

    Returns
    -------
    IcpResult
    """
    kind: Any = method
    if projective and uses_projective(method, voxel_m):
        vt = target_image if target_image is not None else camera_image(target)
        vs = source_image if source_image is not None else camera_image(source)
        cell_s, src_sample, tgt_sample = (
            samples if samples is not None else refine_samples(target, source)
        )
        r = projective_icp(
            vt,
            src_sample,
            T_init,
            max_distance_m=max(3 * threshold_m, reach_m or 0.0),
            levels=3 if reach_m is None else REACH_LEVELS,
            normals=target_normals if target_image is not None else None,
            source=vs,
            target_points=tgt_sample,
            source_normals=source_normals if source_image is not None else None,
            facing=True,
        )
        return replace(r, voxel_m=cell_s, source_points=len(src_sample) + len(tgt_sample))
    sp = as_points(source, name="source")
    tp = as_points(target, name="target")
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
        vt = camera_image(target)
        ref = measured_image(vt)
        slack = range_slack(vt, ref)
        sample = area_sample(sp, 20000)

        def check(T: NDArray[np.float64]) -> float:
            _, ok, bad = classify_points(vt, sample, T, threshold_m / 2, 0.002, slack, ref)
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


def uses_projective(method: str, voxel_m: float | None) -> bool:
    """Whether :func:`refine` takes the projective path (point-to-plane without a fixed voxel)."""
    return method == "point-to-plane" and voxel_m is None


def refine_samples(
    target: Scan | RangeImage, source: Scan | RangeImage
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """The projective refinement's area samples: source cell size, source and target points."""
    n = PROJECTIVE_ICP_POINTS // 2
    cell_s, src = area_sample_cell(as_points(source, name="source", keep_float32=True), n)
    tgt = area_sample_cell(as_points(target, name="target", keep_float32=True), n)[1]
    return cell_s, src, tgt


__all__ = [
    "AREA_ICP_POINTS",
    "FINE_ICP_SLACK",
    "PROJECTIVE_ICP_POINTS",
    "IcpMethod",
    "IcpResult",
    "refine",
    "refine_samples",
    "uses_projective",
]
