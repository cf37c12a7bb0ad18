"""Pictures of a calibration: the verification overlay and the views for picking pairs by hand
(drawn with :mod:`flexreg.viz.draw`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.auto import render_flexion_view
from flexreg.calibration.panorama import panorama_flexion
from flexreg.calibration.types import CalibrationResult
from flexreg.core.scan import Scan
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages import feature_images as images
from flexreg.stages.camera_pose import project_points
from flexreg.viz.draw import as_bgr, colour_bar, draw_grid, range_colours

__all__ = ["overlay_image", "picking_views"]


def overlay_image(
    image: NDArray[np.uint8],
    points: ArrayLike,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: ArrayLike,
    *,
    result: CalibrationResult | None = None,
    max_range_m: float | None = None,
    radius_px: int | None = None,
) -> NDArray[np.uint8]:
    """Lidar points projected into the camera image, coloured by range (verification picture).

    Parameters
    ----------
    image : (H, W[, 3]) uint8
        Camera image (BGR or grey).
    points : (N, 3) float, metres, lidar frame
    intrinsics : CameraIntrinsics
    T_camera_lidar : (4, 4) float
    result : CalibrationResult, optional
        Also draw its correspondences: a line from each pixel to its point's projection, green
        for inliers, magenta for outliers.
    max_range_m : float, optional
        Range of the far end of the colour map (default: 95th percentile of the visible
        points' ranges).
    radius_px : int, optional
        Dot radius (default from the image size).

    Returns
    -------
    (H, W, 3) uint8
        BGR image, with a colour bar (metres) in the lower right corner.
    """
    import cv2  # heavy: OpenCV loads only when drawing

    out = as_bgr(image)
    H, W = out.shape[:2]
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    uv, z = project_points(P, intrinsics, T_camera_lidar)
    vis = (z > 0) & np.isfinite(uv).all(axis=1)
    vis &= (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    r = np.linalg.norm(P, axis=1)
    if max_range_m is None:
        max_range_m = float(np.percentile(r[vis], 95)) if vis.any() else 1.0
    max_range_m = max(float(max_range_m), 1e-3)
    rad = radius_px if radius_px is not None else max(1, round(max(W, H) / 1600))
    idx = np.flatnonzero(vis)
    idx = idx[np.argsort(-r[idx], kind="stable")]  # far first, near on top
    colours = range_colours(r[idx], max_range_m)
    pts = np.rint(uv[idx]).astype(np.int32)
    for (x, y), c in zip(pts, colours.tolist(), strict=True):
        cv2.circle(out, (int(x), int(y)), rad, c, -1, cv2.LINE_8)
    if result is not None:
        corr = result.correspondences
        proj, _ = project_points(corr.points, intrinsics, T_camera_lidar)
        for i in range(len(corr)):
            colour = (0, 255, 0) if result.inlier_mask[i] else (255, 0, 255)
            a = tuple(int(x) for x in np.rint(corr.pixels[i]))
            cv2.drawMarker(out, a, colour, cv2.MARKER_CROSS, 4 * rad + 6, 1, cv2.LINE_AA)
            if np.isfinite(proj[i]).all():
                b = tuple(int(x) for x in np.rint(proj[i]))
                cv2.line(out, a, b, colour, 1, cv2.LINE_AA)
    colour_bar(out, max_range_m)
    return out


def picking_views(
    image: NDArray[np.uint8],
    scan: Scan,
    *,
    intrinsics: CameraIntrinsics | None = None,
    T_init: ArrayLike | None = None,
    n: int = 3,
) -> dict[str, NDArray[np.uint8]]:
    """Pictures for reading correspondences by hand, each at its own native pixel grid.

    * ``"camera"``: the camera image with a pixel grid (``u`` along the width, ``v`` down);
      an image viewer's cursor position is ``(u, v)`` directly.
    * ``"panorama"``: the Flexion n x n image of the scan's range image
      (:func:`flexreg.calibration.scan_range_image`) with a grid; the cursor position
      ``(x, y)`` is ``(col, row)`` for a ``u,v,row,col`` file.
    * ``"flexion-view"`` (with ``intrinsics`` and ``T_init``): the scan rendered as a Flexion
      image from the initial guess (:func:`flexreg.calibration.render_flexion_view`), resized
      to the camera image and gridded the same way, to find the same structures in both (it
      holds no lidar coordinates; read those from the panorama).

    Returns
    -------
    dict of str to (h, w, 3) uint8 BGR images
    """
    import cv2  # heavy: OpenCV loads only when drawing

    cam = as_bgr(image)
    H, W = cam.shape[:2]
    major = 100 if max(W, H) >= 800 else 50
    draw_grid(cam, major // 5, major, top="u", left="v")
    views = {"camera": cam}
    F = panorama_flexion(scan, n=n)
    q, _ = images.quantize(F, 8, stretch="percentile", percentiles=(1.0, 99.0))
    pano = as_bgr(np.asarray(q, dtype=np.uint8))
    draw_grid(pano, 10, 50, top="col", left="row")
    views["panorama"] = pano
    if intrinsics is not None and T_init is not None:
        intr = intrinsics.for_image(W, H)
        view = render_flexion_view(scan, intr, T_init, n=n)
        q, _ = images.quantize(view.flexion, 8)
        fv = as_bgr(
            np.asarray(
                cv2.resize(np.asarray(q, np.uint8), (W, H), interpolation=cv2.INTER_NEAREST),
                dtype=np.uint8,
            )
        )
        draw_grid(fv, major // 5, major, top="u", left="v")
        views["flexion-view"] = fv
    return views
