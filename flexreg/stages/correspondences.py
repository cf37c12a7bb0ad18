"""Lift 2D keypoints to 3D points on the range image they were detected in; the metric pixel
footprint and the inlier threshold it gives."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage


def lift(
    image: RangeImage,
    xy: NDArray[np.floating],
    *,
    max_jump: float = 0.03,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """3D points of sub-pixel keypoints by bilinear interpolation of the xyz grid.

    A keypoint is dropped (``ok = False``) when one of its four neighbouring pixels is invalid
    or when their ranges differ by more than ``max_jump`` times their mean (a depth
    discontinuity, where interpolation would invent a point in mid-air). On a full-turn
    panorama the neighbours wrap around the seam.

    Parameters
    ----------
    image : RangeImage
    xy : (K, 2) float, pixels
        ``(u, v)`` keypoint positions.
    max_jump : float
        Largest relative range spread of the 4 neighbours.

    Returns
    -------
    points : (K, 3) float64, metres
        NaN where not ok.
    ok : (K,) bool
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    H, W = image.shape
    finite = np.isfinite(xy).all(axis=1)
    u = np.where(finite, xy[:, 0], -1.0)
    v = np.where(finite, xy[:, 1], -1.0)
    u0 = np.floor(u).astype(np.int64)
    v0 = np.floor(v).astype(np.int64)
    u1, v1 = u0 + 1, v0 + 1
    if image.wraps:
        u0, u1 = np.mod(u0, W), np.mod(u1, W)
        inside = (v0 >= 0) & (v1 < H)
    else:
        inside = (u0 >= 0) & (u1 < W) & (v0 >= 0) & (v1 < H)
    ok = inside & finite
    pts = np.full((len(xy), 3), np.nan)
    if not ok.any():
        return pts, ok
    a = np.flatnonzero(ok)
    U0, U1, V0, V1 = u0[a], u1[a], v0[a], v1[a]
    corners = [image.xyz[V0, U0], image.xyz[V0, U1], image.xyz[V1, U0], image.xyz[V1, U1]]
    valid = image.valid[V0, U0] & image.valid[V0, U1] & image.valid[V1, U0] & image.valid[V1, U1]
    r = np.stack([np.linalg.norm(c, axis=1) for c in corners], axis=1)
    with np.errstate(invalid="ignore"):
        smooth = (r.max(1) - r.min(1)) <= max_jump * r.mean(1)
    good = valid & smooth
    fa = (u - np.floor(u))[a, None]
    fb = (v - np.floor(v))[a, None]
    p = (
        corners[0] * (1 - fa) * (1 - fb)
        + corners[1] * fa * (1 - fb)
        + corners[2] * (1 - fa) * fb
        + corners[3] * fa * fb
    )
    ok[a] = good
    pts[a[good]] = p[good]
    return pts, ok


def pixel_footprint(image: RangeImage) -> NDArray[np.float32]:
    """(H, W) metric size of each pixel: the smaller of its horizontal and vertical
    neighbour distances (NaN where unknown). Used to derive thresholds from resolution."""
    rows, cols = np.indices(image.shape).reshape(2, -1)
    return _footprint_at(image, rows, cols).reshape(image.shape)


def _footprint_at(
    image: RangeImage, rows: NDArray[np.int64], cols: NDArray[np.int64]
) -> NDArray[np.float32]:
    """:func:`pixel_footprint` at the given pixels only ((N,) float32)."""
    xyz = image.xyz
    p = xyz[rows, cols]
    right = cols + 1
    if image.wraps:
        right = np.where(right == image.width, 0, right)
    nan = np.full(3, np.nan)
    ph = np.where(
        (right < image.width)[:, None], xyz[rows, np.minimum(right, image.width - 1)], nan
    )
    below = rows + 1
    pv = np.where(
        (below < image.height)[:, None], xyz[np.minimum(below, image.height - 1), cols], nan
    )
    with np.errstate(invalid="ignore"):
        dh = np.linalg.norm(ph - p, axis=1).astype(np.float32)
        return np.fmin(dh, np.linalg.norm(pv - p, axis=1).astype(np.float32))


def derive_threshold(
    target: RangeImage,
    source: RangeImage,
    xy_target: NDArray[np.float64],
    xy_source: NDArray[np.float64],
    *,
    threshold_px: float = 3.0,
) -> float:
    """Inlier distance from the scans' resolution: ``threshold_px`` times the median metric
    footprint of the pixels under the keypoints (at least 5 mm), metres."""
    f = []
    for img, xy in ((target, xy_target), (source, xy_source)):
        if len(xy) == 0:
            continue
        c = np.clip(np.rint(xy).astype(np.int64), 0, [img.width - 1, img.height - 1])
        f.append(_footprint_at(img, c[:, 1], c[:, 0]))
    fa = np.concatenate(f) if f else np.zeros(0)
    thr = float(threshold_px * np.nanmedian(fa)) if np.isfinite(fa).any() else 0.05
    return max(thr, 0.005)
