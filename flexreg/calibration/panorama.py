"""The scan as a picture to pick points on: its range image (native grid or an equirectangular
panorama of an unstructured cloud), the Flexion image on that grid, and correspondence files
whose ``row,col`` columns refer to it."""

from __future__ import annotations

import math
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.camera import SphericalCamera
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan
from flexreg.errors import InputError
from flexreg.io.correspondences import read_pairs
from flexreg.stages import feature_images as images
from flexreg.stages import projection
from flexreg.stages.correspondences import lift
from flexreg.stages.projection import auto_spherical_camera, fill_holes, project

__all__ = [
    "normalized_fill",
    "panorama_camera",
    "panorama_flexion",
    "read_correspondences",
    "scan_range_image",
]


def panorama_camera(points: ArrayLike) -> SphericalCamera:
    """Equirectangular camera for an unstructured lidar cloud, one pixel per point spacing.

    A spinning lidar samples azimuth much more finely than elevation (e.g. 0.17 deg between
    firings, 0.4 deg between rings). The azimuth pitch is the median angular distance of each
    point to its nearest neighbour; the polar pitch makes the pixel count match the points
    over the covered directions, as :func:`flexreg.stages.projection.auto_spherical_camera` does
    (whose isotropic pitch this is for a scanner with square sampling). When that function
    recognises evenly spaced rings (one row per ring), its camera is used as it is.
    """
    from scipy.spatial import cKDTree  # heavy: ~0.1 s at import; the CLI imports this package

    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    base = auto_spherical_camera(P)
    if not math.isclose(base.dphi, base.dtheta, rel_tol=1e-6):
        return base  # evenly spaced rings recognised: one row per ring already
    r = np.linalg.norm(P, axis=1)
    dirs = P[r > 0] / r[r > 0, None]
    if len(dirs) < 100:
        return base
    rng = np.random.default_rng(0)  # deterministic subsample for the spacing statistic
    probe = dirs[rng.choice(len(dirs), min(len(dirs), 20000), replace=False)]
    d, _ = cKDTree(dirs).query(probe, k=2)
    s0 = base.dphi
    a = float(np.clip(np.median(d[:, 1]), s0 / 4, s0))
    b = s0 * s0 / a
    H = max(1, math.floor((base.theta_max - base.theta_min) / b + 0.5))
    th_hi = min(np.pi, base.theta_min + H * b)
    span = base.phi_max - base.phi_min
    W = max(1, math.ceil(span / a - 1e-9))
    return SphericalCamera(W, H, base.phi_min, base.phi_max, base.theta_min, th_hi)


def _nearest_fill(image: RangeImage, max_px: float) -> RangeImage:
    """Give every no-return pixel within ``max_px`` of a return that nearest return (the real
    point, its index and intensity)."""
    from scipy import ndimage  # heavy: ~0.1 s at import; the CLI imports this package

    v = image.valid
    if v.all() or not v.any():
        return image
    dist, (ri, ci) = ndimage.distance_transform_edt(~v, return_indices=True)
    fill = ~v & (dist <= max_px)
    xyz = image.xyz.copy()
    index = image.index.copy()
    xyz[fill] = image.xyz[ri[fill], ci[fill]]
    index[fill] = image.index[ri[fill], ci[fill]]
    inten = None
    if image.intensity is not None:
        inten = image.intensity.copy()
        inten[fill] = image.intensity[ri[fill], ci[fill]]
    return RangeImage(xyz=xyz, valid=v | fill, index=index, camera=image.camera, intensity=inten)


def normalized_fill(
    values: NDArray[np.float64], mask: NDArray[np.bool_], sigmas: tuple[float, ...]
) -> NDArray[np.float64]:
    """Fill an image from its valid samples by normalised convolution, coarse scales only where
    the fine ones found too little support (Knutsson & Westin's normalised averaging).

    Parameters
    ----------
    values : (H, W) float64
    mask : (H, W) bool
        The valid samples.
    sigmas : tuple of float, pixels
        Gaussian scales, fine to coarse.

    Returns
    -------
    (H, W) float64
        NaN where no scale found a Gaussian weight of valid samples above 0.1.
    """
    import cv2  # heavy: OpenCV loads only with the calibration functions that blur

    out = np.full(values.shape, np.nan)
    v = np.where(mask, values, 0.0)
    m = mask.astype(np.float64)
    for s in sigmas:
        num = cv2.GaussianBlur(v, (0, 0), s)
        den = cv2.GaussianBlur(m, (0, 0), s)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = num / den
        fill = np.isnan(out) & (den > 0.1)
        out[fill] = r[fill]
    return out


def scan_range_image(scan: Scan) -> RangeImage:
    """The range image whose ``(row, col)`` a correspondence file refers to.

    A scan with a native grid (PTX, gridded E57, organised PCD, ...) keeps it
    (``flexreg.range_image``) with isolated no-returns filled
    (:func:`flexreg.stages.projection.fill_holes`). An unstructured cloud (KITTI ``.bin``, most
    ``.pcd``) is z-buffered into :func:`panorama_camera`, and each empty pixel within 2 pixels
    of a return shows the nearest return, so every pixel holds a real lidar point. This is the
    grid of the ``panorama.png`` :func:`flexreg.calibration.picking_views` draws.
    """
    if scan.has_grid:
        return fill_holes(projection.range_image(scan))
    return _nearest_fill(project(scan, panorama_camera(scan.points)), 2.0)


def panorama_flexion(scan: Scan, *, n: int = 3) -> NDArray[np.float32]:
    """Flexion n x n image (paper eq. 11-13) on the grid of :func:`scan_range_image`.

    Native grids are converted directly. For a projected panorama the range is densified
    first (normalised convolution of the returns' ranges, back-projected along each pixel's
    ray with eq. 7-8), so the sparse rows of a spinning lidar give a readable image.
    """
    if scan.has_grid:
        return images.flexion(fill_holes(projection.range_image(scan)), n=n)
    cam = panorama_camera(scan.points)
    ri = project(scan, cam)
    r = normalized_fill(ri.range.astype(np.float64), ri.valid, (1.0, 2.0))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    return images.flexion(cam.backproject(u, v, r), n=n, wrap=cam.wraps)


def read_correspondences(
    path: str | PathLike[str],
    *,
    scan: Scan | None = None,
    range_image: RangeImage | None = None,
) -> Correspondences2D3D:
    """Read 2D-3D correspondences from a CSV file.

    The first non-comment line is a header naming the columns (case-insensitive, any order,
    extra columns ignored): ``u,v`` (camera pixel) and either ``X,Y,Z`` (lidar frame, metres)
    or ``row,col`` (pixel of the scan's range image, see :func:`scan_range_image`; fractional
    values are interpolated bilinearly). Blank lines and lines starting with ``#`` are skipped
    (:func:`flexreg.io.correspondences.read_pairs` reads the file).

    Parameters
    ----------
    path : path-like
    scan : Scan, optional
        Needed for ``row,col`` files (lifted on :func:`scan_range_image`).
    range_image : RangeImage, optional
        Lift ``row,col`` on this image instead.

    Returns
    -------
    Correspondences2D3D

    Raises
    ------
    InputError
        Missing file, bad header, or a malformed line (named by its line number): wrong
        number of fields, a value that is not a finite number, a ``row,col`` outside the range
        image or on a pixel without a lidar return.
    """
    table = read_pairs(path)
    p = table.path
    if table.xyz is not None:
        return Correspondences2D3D(table.pixels, table.xyz, table.lines, str(p))
    assert table.rowcol is not None
    if range_image is None:
        if scan is None:
            raise InputError(p, "row,col correspondences need the scan they refer to")
        range_image = scan_range_image(scan)
    points = _lift_grid(range_image, table.rowcol, table.lines, p)
    return Correspondences2D3D(table.pixels, points, table.lines, str(p))


def _lift_grid(
    image: RangeImage, rowcol: NDArray[np.float64], lines: NDArray[np.int64], p: Path
) -> NDArray[np.float64]:
    """3D points of ``(row, col)`` range-image pixels; integer ones exactly, others bilinearly."""
    H, W = image.shape
    out = np.empty((len(rowcol), 3))
    for k, (r, c) in enumerate(rowcol):
        if not (-0.5 <= r <= H - 0.5 and -0.5 <= c <= W - 0.5):
            raise InputError(
                p,
                f"line {lines[k]}: row {r:g}, col {c:g} lies outside the scan's {W}x{H} range "
                "image (see --export-views)",
            )
        ri, ci = round(r), round(c)
        if abs(r - ri) < 1e-9 and abs(c - ci) < 1e-9:
            if not image.valid[ri, ci]:
                raise InputError(
                    p, f"line {lines[k]}: range-image pixel row {ri}, col {ci} has no lidar return"
                )
            out[k] = image.xyz[ri, ci]
            continue
        pts, ok = lift(image, np.array([[c, r]]))
        if not ok[0]:
            raise InputError(
                p,
                f"line {lines[k]}: row {r:g}, col {c:g} is not between four lidar returns on one "
                "surface; use whole pixel coordinates",
            )
        out[k] = pts[0]
    return out
