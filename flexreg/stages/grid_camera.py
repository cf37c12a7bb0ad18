"""A camera model for a scanner's native grid (PTX, E57, organised PCD, 3DTK): so that a range
image written from the grid (``flexreg project``) gets its camera sidecar and can be read back.

A gridded scan keeps the scanner's own rows and columns and no camera model. Most grids are
regular: a terrestrial scanner's is equirectangular (each column one azimuth, each row one polar
angle), an organised depth-camera cloud's is a pinhole image. :func:`fit_grid_camera` fits both
models to the grid's points by least squares and returns the one that puts every point back on
its own pixel (95th percentile of the distance at most ``max_error_px``), or None.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import Camera, PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage
from flexreg.errors import InputError

__all__ = ["MAX_GRID_ERROR_PX", "fit_grid_camera", "grid_camera_error", "grid_with_camera"]

log = logging.getLogger(__name__)

#: a fitted camera must put 95 % of the grid's points within this many pixels of their own
MAX_GRID_ERROR_PX = 1.0
_SAMPLES = 200_000
_TWO_PI = 2.0 * math.pi


def _sample(
    image: RangeImage,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(u, v, points) of at most ``_SAMPLES`` valid pixels, evenly spread (deterministic)."""
    v, u = np.nonzero(image.valid)
    step = max(1, math.ceil(len(u) / _SAMPLES))
    v, u = v[::step], u[::step]
    return u.astype(np.float64), v.astype(np.float64), image.xyz[v, u].astype(np.float64)


def grid_camera_error(image: RangeImage, camera: Camera) -> float:
    """95th percentile of the pixel distance between each valid pixel and the projection of
    its point through ``camera`` (pixels; ``inf`` when none projects)."""
    u, v, P = _sample(image)
    pu, pv, _ = camera.project(P)
    du = pu - u
    if isinstance(camera, SphericalCamera) and camera.wraps:
        du = (du + camera.width / 2) % camera.width - camera.width / 2
    d = np.hypot(du, pv - v)
    d = d[np.isfinite(d)]
    return float(np.percentile(d, 95)) if len(d) and len(d) == len(u) else math.inf


def _spherical(image: RangeImage) -> SphericalCamera | None:
    u, v, P = _sample(image)
    r = np.linalg.norm(P, axis=1)
    ok = r > 0
    u, v, P, r = u[ok], v[ok], P[ok], r[ok]
    if len(u) < 10 or np.ptp(u) < 1 or np.ptp(v) < 1:
        return None
    theta = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0))
    dtheta, theta0 = np.polyfit(v, theta, 1)
    phi = np.arctan2(P[:, 1], P[:, 0])
    # azimuth step: from pairs of samples in one row, the wrapped difference over the columns
    order = np.lexsort((u, v))
    same = (np.diff(v[order]) == 0) & (np.diff(u[order]) > 0)
    if not same.any():
        return None
    dphi_pairs = np.angle(np.exp(1j * np.diff(phi[order])))[same] / np.diff(u[order])[same]
    dphi = float(np.median(dphi_pairs))
    if not (dtheta > 0 and dphi > 0):
        return None
    phi0 = float(np.angle(np.mean(np.exp(1j * (phi - u * dphi)))))
    width, height = image.width, image.height
    span = width * dphi
    if span > _TWO_PI * 1.01:
        return None
    span = min(span, _TWO_PI)
    if abs(span - _TWO_PI) < 0.01 * _TWO_PI:  # a full turn within 1 %: make it wrap exactly
        dphi, span = _TWO_PI / width, _TWO_PI
        phi0 = float(np.angle(np.mean(np.exp(1j * (phi - u * dphi)))))
    if -0.01 * dtheta < theta0 < 0:  # the pole row: zero within a hundredth of a pixel
        theta0 = 0.0
    theta_max = theta0 + height * dtheta
    if math.pi < theta_max < math.pi + 0.01 * dtheta:
        theta_max = math.pi
    if theta0 < 0 or theta_max > math.pi + 1e-9:
        return None
    try:
        return SphericalCamera(width, height, phi0, phi0 + span, float(theta0), float(theta_max))
    except InputError:
        return None


def _pinhole(image: RangeImage) -> PinholeCamera | None:
    u, v, P = _sample(image)
    ok = P[:, 2] > 0
    if ok.sum() < 10 or not ok.all():
        return None
    x, y = P[:, 0] / P[:, 2], P[:, 1] / P[:, 2]
    fx, cx = np.polyfit(x, u, 1)
    fy, cy = np.polyfit(y, v, 1)
    try:
        return PinholeCamera(float(fx), float(fy), float(cx), float(cy), image.width, image.height)
    except InputError:
        return None


def fit_grid_camera(
    image: RangeImage, *, max_error_px: float = MAX_GRID_ERROR_PX
) -> tuple[Camera | None, float]:
    """The equirectangular or pinhole camera of a native grid, when one fits it.

    Parameters
    ----------
    image : RangeImage
        A scan's native grid (points in the scanner frame).
    max_error_px : float, pixels
        Largest 95th percentile of the distance between a pixel and its point's projection.

    Returns
    -------
    camera : SphericalCamera, PinholeCamera or None
        The better fitting model, or None when neither fits within ``max_error_px`` (the
        grid is not regular, or not in a layout those models describe: azimuth along the
        rows, mirrored columns).
    error_px : float, pixels
        The 95th percentile of the best model (``inf`` when no model could be fitted).

    Examples
    --------
    >>> from flexreg.core.scan import Scan
    >>> from flexreg.stages.projection import project
    >>> cam = SphericalCamera(360, 90, -math.pi, math.pi, 0.5, 2.0)
    >>> img = project(Scan(points=cam.rays().reshape(-1, 3) * 5.0), cam)
    >>> fitted, err = fit_grid_camera(RangeImage(img.xyz, img.valid, img.index))
    >>> type(fitted).__name__, err < 1e-6
    ('SphericalCamera', True)
    """
    best: tuple[Camera | None, float] = (None, math.inf)
    for fit in (_spherical, _pinhole):
        cam = fit(image)
        if cam is None:
            continue
        err = grid_camera_error(image, cam)
        if err < best[1]:
            best = (cam, err)
    if best[0] is None or best[1] > max_error_px:
        log.info("no camera model fits the grid (95th percentile %.3g px)", best[1])
        return None, best[1]
    return best


def _flipped(image: RangeImage, rows: bool, cols: bool) -> RangeImage:
    sl = (slice(None, None, -1 if rows else 1), slice(None, None, -1 if cols else 1))
    return RangeImage(
        xyz=np.ascontiguousarray(image.xyz[sl]),
        valid=np.ascontiguousarray(image.valid[sl]),
        index=np.ascontiguousarray(image.index[sl]),
        camera=None,
        intensity=None if image.intensity is None else np.ascontiguousarray(image.intensity[sl]),
    )


def grid_with_camera(
    image: RangeImage, *, max_error_px: float = MAX_GRID_ERROR_PX
) -> tuple[RangeImage, float]:
    """A native grid with the camera that fits it (:func:`fit_grid_camera`), its rows and/or
    columns reversed when the scanner stored them bottom-up or mirrored; the image itself
    (without camera) and the best error when none fits. An image with a camera is returned
    as it is, with error 0."""
    if image.camera is not None:
        return image, 0.0
    best: tuple[RangeImage, float] = (image, math.inf)
    for rows, cols in ((False, False), (True, False), (False, True), (True, True)):
        candidate = _flipped(image, rows, cols) if rows or cols else image
        cam, err = fit_grid_camera(candidate, max_error_px=max_error_px)
        if cam is not None and err < best[1]:
            best = (replace(candidate, camera=cam), err)
        elif cam is None and best[0].camera is None:
            best = (image, min(best[1], err))
        if best[0].camera is not None and err == 0.0:
            break
    return best
