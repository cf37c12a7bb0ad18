"""Verification: how well a transform explains the target's view of the source.

The dense free-space check of :func:`overlap_score`: source points mapped into the target frame
are looked up in the target's range image; a point is consistent when the target saw a
surface at its range and in conflict when it lies clearly in front of what the target saw.
:func:`classify_points` is its core on points already sampled (the registration samples each
scan once and checks many candidates), :func:`range_slack` the per-pixel range tolerance and
:func:`measured_image` what the camera measures per pixel.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import RangeImage
from flexreg.errors import ConfigError
from flexreg.stages.sampling import area_sample


def measured_image(image: RangeImage) -> NDArray[np.float32]:
    """What the camera model measures per pixel: depth z (pinhole) or range, NaN where invalid."""
    return image.depth_z() if isinstance(image.camera, PinholeCamera) else image.range


def range_slack(
    image: RangeImage, measured: NDArray[np.float32] | None = None
) -> NDArray[np.float32]:
    """(H, W) largest range (or depth) change from each pixel to its 4 neighbours, metres (0
    where unknown): how much range one pixel spans on an oblique surface. ``measured`` is the
    image's range (depth for pinhole cameras), when already at hand."""
    ref = measured_image(image) if measured is None else measured
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
    _, ok, bad = classify_points(target, ps, T_target_source, tolerance_m, tolerance_rel, slack)
    return (float(ok.mean()), float(bad.mean())) if len(ok) else (0.0, 0.0)


def classify_points(
    target: RangeImage,
    ps: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    tolerance_m: float,
    tolerance_rel: float,
    slack: NDArray[np.float32] | None = None,
    ref: NDArray[np.float32] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Source points checked against the target's view: the core of :func:`overlap_score`.

    Parameters
    ----------
    target : RangeImage
        The target's view (with a camera model; without one, nearest-neighbour distances and no
        conflicts).
    ps : (N, 3) float64, metres
        Source points, already sampled (e.g. :func:`flexreg.stages.sampling.area_sample`).
    T_target_source : (4, 4) float64
    tolerance_m, tolerance_rel : float
        Range tolerance: metres plus a fraction of the range.
    slack : (H, W) float32, optional
        :func:`range_slack` of the target, when at hand.
    ref : (H, W) float32, optional
        :func:`measured_image` of the target, when at hand.

    Returns
    -------
    q : (N, 3) float64
        The points in the target frame.
    consistent, conflicting : (N,) bool
    """
    if len(ps) == 0:
        return np.zeros((0, 3)), np.zeros(0, bool), np.zeros(0, bool)
    T = np.asarray(T_target_source, dtype=np.float64)
    q = ps @ T[:3, :3].T + T[:3, 3]
    cam = target.camera
    if cam is None:
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
        ref = measured_image(target)
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


__all__ = ["classify_points", "measured_image", "overlap_score", "range_slack"]
