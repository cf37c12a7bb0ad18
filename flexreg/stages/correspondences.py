"""Lift 2D keypoints to 3D points on the range image they were detected in."""

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
