"""Scan -> :class:`RangeImage`: native grid, z-buffer projection, or depth image + camera.

The range image keeps the 3D point of every pixel (``xyz``), so the image conversions need no
camera at all, and the pixel -> point index map, so 2D features can be lifted back to the scan.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.budget import check_memory
from flexreg.core.camera import ANGLE_CHUNK, Camera, SphericalCamera, azimuth_polar_extent
from flexreg.core.grid import wrap_col
from flexreg.core.range_image import (
    RangeImage,
    downsample_image,
    float_xyz,
    from_grid,
    from_index,
    subsampled_camera,
    working_stride,
)
from flexreg.core.scan import GRID_CELL_BYTES, Scan
from flexreg.errors import DegenerateGeometryError, InputError
from flexreg.stages.grid_camera import fit_grid_camera

log = logging.getLogger(__name__)


# ------------------------------------------------------------------------------ builders


@numba.njit(cache=True, nogil=True)
def _zbuffer(
    lin: NDArray[np.int64], depth: NDArray[np.float64], n_pixels: int
) -> NDArray[np.int64]:
    best = np.full(n_pixels, np.inf)
    index = np.full(n_pixels, -1, dtype=np.int64)
    for i in range(lin.shape[0]):
        p = lin[i]
        if p >= 0 and depth[i] < best[p]:  # strict: the first of equal ranges wins
            best[p] = depth[i]
            index[p] = i
    return index


def project(scan: Scan, camera: Camera, *, stride: int = 1) -> RangeImage:
    """Z-buffer projection of a scan through a camera: the nearest return wins each pixel.

    Parameters
    ----------
    scan : Scan
        Points in the camera/scanner frame.
    camera : PinholeCamera or SphericalCamera
        Pixel ``[v, u]`` receives the points whose coordinates round to ``(u, v)``.
    stride : int
        Keep every ``stride``-th row and column of the image only: exactly
        ``downsample_image(project(scan, camera), stride)``, without the full-size image or a
        full-size pixel list (the points off the kept pixels are dropped chunk by chunk).

    Returns
    -------
    RangeImage
        The pixel holds the *original* point (not a resampled one), so nothing is lost to
        quantisation; ``index`` points back into ``scan.points``.

    Raises
    ------
    MemoryBudgetError
        The image would not fit the memory budget (:mod:`flexreg.core.budget`).
    """
    H, W = camera.shape
    s = max(1, int(stride))
    h, w = -(-H // s), -(-W // s)
    check_memory(
        h * w * GRID_CELL_BYTES,
        f"a {h} x {w} range image",
        source=scan.path if scan.path is not None else (scan.name or "scan"),
    )
    n = len(scan.points)
    if s == 1:
        lin = np.empty(n, dtype=np.int64)
        d = np.empty(n, dtype=np.float64)
        for a in range(0, n, _PROJECT_CHUNK):  # elementwise: chunks bound the temporaries
            b = min(n, a + _PROJECT_CHUNK)
            lin[a:b], d[a:b] = _pixels(scan.points[a:b], camera)
        index = _zbuffer(lin, d, H * W).reshape(H, W)
        del lin, d
        return from_index(scan, index, camera)
    kept: list[tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]] = []
    for a in range(0, n, _PROJECT_CHUNK):
        lin, d = _pixels(scan.points[a : a + _PROJECT_CHUNK], camera)
        v, u = np.divmod(lin, W)
        on = np.flatnonzero((lin >= 0) & (v % s == 0) & (u % s == 0))
        kept.append(((v[on] // s) * w + u[on] // s, d[on], on + a))
    small = np.concatenate([k[0] for k in kept])
    depth = np.concatenate([k[1] for k in kept])
    ids = np.concatenate([k[2] for k in kept])
    del kept
    winner = _zbuffer(small, depth, h * w)  # the points in order: ties as in one pass
    index = np.where(winner >= 0, ids[np.maximum(winner, 0)], -1).reshape(h, w)
    return from_index(scan, index, subsampled_camera(camera, H, W, s))


#: points projected at a time by :func:`project` (a multiple of every SIMD width, so each
#: element is computed exactly as in one pass over all points)
_PROJECT_CHUNK = 1 << 18


def _pixels(
    points: NDArray[np.floating], camera: Camera
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Linear pixel index (-1 outside the image or behind the camera) and depth of points."""
    H, W = camera.shape
    u, v, d = camera.project(points)
    with np.errstate(invalid="ignore"):
        iu = np.floor(u + 0.5)
        iv = np.floor(v + 0.5)
    if isinstance(camera, SphericalCamera) and camera.wraps:
        iu = np.where(iu >= W, iu - W, iu)
    ok = np.isfinite(iu) & np.isfinite(iv) & (iu >= 0) & (iu < W) & (iv >= 0) & (iv < H) & (d > 0)
    return np.where(ok, iv * W + iu, -1).astype(np.int64), d


def _lidar_rings(points: NDArray[np.floating]) -> tuple[int, float, float] | None:
    """``(rings, ring_spacing_rad, azimuth_pitch_rad)`` when the cloud is a spinning lidar's:
    its polar angles fall into a few narrow, about evenly spaced bands (one per beam); else None.

    The azimuth pitch is measured along the rings (consecutive azimuths of one beam), never
    derived from the number of points: a sweep that loses returns to the sky, windows, glass
    or range limits keeps its firing pitch, and a few rays more or less (another CPU's ray
    caster, another dropout draw) cannot move it.
    """
    if len(points) < 1000:
        return None
    if _polar_runs(points, math.radians(0.2)) < 4:
        return None  # fewer than 4 bands: the sort below would find fewer than 4 rings
    P = np.asarray(points, dtype=np.float64)
    th_all = _polar(P)
    order = np.argsort(th_all, kind="stable")
    th = th_all[order]
    gaps = np.diff(th)
    sep = gaps > math.radians(0.2)
    n = int(sep.sum()) + 1
    if not (4 <= n <= 256) or n * 50 > len(P):
        return None
    spacing = float(np.median(gaps[sep]))
    # rings about evenly spaced, and each band much narrower than the spacing
    if not np.all((gaps[sep] > 0.5 * spacing) & (gaps[sep] < 2.5 * spacing)):
        return None
    starts = np.r_[0, np.flatnonzero(sep) + 1]
    ends = np.r_[np.flatnonzero(sep), len(th) - 1]
    if np.max(th[ends] - th[starts]) > 0.25 * spacing:
        return None
    pitch = _ring_azimuth_pitch(P[order], np.r_[0, np.cumsum(sep)])
    if pitch is None:
        return None
    return n, spacing, pitch


def _polar(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """Polar angle of points (N, 3) float64, radians (pi / 2 at the origin)."""
    r = np.linalg.norm(P, axis=1)
    return np.arccos(np.clip(P[:, 2] / np.where(r > 0, r, 1.0), -1.0, 1.0))


def _angles(
    points: NDArray[np.floating], phi0: float, th0: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Azimuth from ``phi0`` (0 to 2 pi) and polar angle less ``th0`` of points, radians."""
    P = np.asarray(points, dtype=np.float64)
    return np.mod(np.arctan2(P[:, 1], P[:, 0]) - phi0, 2 * np.pi), _polar(P) - th0


def _polar_runs(points: NDArray[np.floating], gap_rad: float) -> int:
    """An upper bound of the number of bands of the points' polar angles separated by more
    than ``gap_rad`` (what :func:`_lidar_rings` counts after sorting), in one pass over the
    points in chunks: the runs of occupied bins a third of ``gap_rad`` wide. Two sorted
    neighbours more than ``gap_rad`` apart are more than two bins apart, so an empty bin
    lies between them and they fall into different runs."""
    w = gap_rad / 3.0
    occupied = np.zeros(int(np.pi / w) + 2, dtype=bool)
    for a in range(0, len(points), ANGLE_CHUNK):
        th = _polar(np.asarray(points[a : a + ANGLE_CHUNK], dtype=np.float64))
        occupied[(th[np.isfinite(th)] / w).astype(np.int64)] = True
    return int(np.count_nonzero(occupied[1:] & ~occupied[:-1])) + int(occupied[0])


def _ring_azimuth_pitch(P: NDArray[np.float64], ring: NDArray[np.int64]) -> float | None:
    """Firing pitch (radians) of a spinning lidar: the typical azimuth step between
    consecutive returns of one beam.

    Missing returns make some steps whole multiples of the pitch and dual returns make
    zero steps; both are outliers here. The estimate is the median of the non-zero steps,
    then the mean of the steps within 25 % of it (the single-pitch steps), so it stays at
    the firing pitch while at least about a third of each turn returns.
    """
    phi = np.arctan2(P[:, 1], P[:, 0])
    o = np.lexsort((phi, ring))
    phi, ring = phi[o], ring[o]
    step = np.diff(phi)
    same = ring[1:] == ring[:-1]
    step = step[same & (step > 1e-7)]
    if len(step) < 100:
        return None
    first = float(np.median(step))
    near = step[np.abs(step - first) <= 0.25 * first]
    return float(near.mean()) if len(near) else first


def auto_spherical_camera(
    points: NDArray[np.floating], *, angular_resolution_rad: float | None = None
) -> SphericalCamera:
    """Choose an equirectangular camera that fits an unstructured cloud.

    The azimuth/polar extent comes from the data (a full turn when there is no gap wider than
    5 degrees). A spinning lidar's cloud (polar angles in a few narrow, evenly spaced bands)
    gets one row per beam. Otherwise, unless ``angular_resolution_rad`` is given, the pixel
    pitch makes the number of pixels over the covered part of the (phi, theta) domain equal
    to the number of points, so a scan at its native density fills the image without holes
    or overdraw.
    """
    phi_min, phi_max, th_min, th_max, full = azimuth_polar_extent(points)
    if not full and phi_max - phi_min < 1e-6 and th_max - th_min < 1e-6:
        raise DegenerateGeometryError(
            "the points lie on one ray from the scanner (they cover no angle): no image can "
            "be made of them"
        )
    span_phi, span_th = max(phi_max - phi_min, 1e-6), max(th_max - th_min, 1e-6)
    rings = _lidar_rings(points) if angular_resolution_rad is None else None
    if rings is not None:  # spinning lidar: one row per beam, azimuth at the ring density
        _, spacing, dphi = rings
        H = math.floor(span_th / spacing + 0.5) + 1
        th_lo = th_min
        th_hi = min(np.pi, th_lo + H * spacing)
        if full:  # a whole number of firings per turn
            return SphericalCamera(max(1, round(2 * np.pi / dphi)), H, -np.pi, np.pi, th_lo, th_hi)
        W = math.floor(span_phi / dphi + 0.5) + 1
        return SphericalCamera(W, H, phi_min, phi_min + W * dphi, th_lo, th_hi)
    if angular_resolution_rad is None:
        n = len(points)
        step = math.sqrt(span_phi * span_th / max(n, 1))
        # occupancy of the domain on a grid 8x coarser than the first guess (in chunks)
        cell = 8 * step
        nx, ny = max(1, int(span_phi / cell) + 1), max(1, int(span_th / cell) + 1)
        occ = np.zeros((ny, nx), dtype=bool)
        for a in range(0, n, ANGLE_CHUNK):
            ph, th = _angles(points[a : a + ANGLE_CHUNK], phi_min, th_min)
            occ[
                np.clip((th / cell).astype(int), 0, ny - 1),
                np.clip((ph / cell).astype(int), 0, nx - 1),
            ] = True
        frac = occ.mean()
        step = math.sqrt(frac * span_phi * span_th / max(n, 1))
    else:
        step = float(angular_resolution_rad)
        if not step > 0:
            raise InputError("angular_resolution_rad", f"must be positive, got {step}")
    H = math.floor(span_th / step + 0.5) + 1
    th_lo = th_min
    if th_lo + H * step > np.pi:  # keep the polar range inside [0, pi]
        th_lo = max(0.0, np.pi - H * step)
    th_hi = min(np.pi, th_lo + H * step)
    if full:
        W = max(1, math.ceil(2 * np.pi / step))
        return SphericalCamera(W, H, -np.pi, np.pi, th_lo, th_hi)
    # pixel 0 is centred on the first azimuth, the last pixel on (or just past) the last one
    W = math.floor(span_phi / step + 0.5) + 1
    return SphericalCamera(W, H, phi_min, phi_min + W * step, th_lo, th_hi)


def range_image(
    scan: Scan,
    camera: Camera | None = None,
    *,
    angular_resolution_rad: float | None = None,
) -> RangeImage:
    """The one call: native grid when the scan has one, otherwise a z-buffer projection.

    Parameters
    ----------
    scan : Scan
    camera : PinholeCamera or SphericalCamera, optional
        Forces a projection through this camera even if the scan has a grid.
    angular_resolution_rad : float, optional
        Pixel pitch of the automatic equirectangular camera (unstructured scans only).
    """
    if camera is None and scan.has_grid:
        return from_grid(scan)
    if len(scan) == 0:
        raise InputError(scan.path or scan.name, "scan has no points to project")
    if camera is None:
        camera = auto_spherical_camera(scan.points, angular_resolution_rad=angular_resolution_rad)
        log.info(
            "projecting %d points into %dx%d equirectangular image",
            len(scan),
            camera.width,
            camera.height,
        )
    return project(scan, camera)


def fill_holes(image: RangeImage, *, min_neighbours: int = 5, max_jump: float = 0.03) -> RangeImage:
    """Fill isolated no-return pixels with the mean of their valid 3x3 neighbours.

    A scanner drops single returns on dark or shiny spots; each such hole would punch an
    invalid square of side ``n`` into an n x n conversion, and feature detectors love those
    squares. A hole is filled only when at least ``min_neighbours`` of its 8 neighbours are
    valid and their ranges agree within ``max_jump`` (relative): holes at depth
    discontinuities and larger gaps stay empty.

    Parameters
    ----------
    image : RangeImage
    min_neighbours : int
        Valid neighbours (of 8) a hole needs to be filled.
    max_jump : float
        Largest relative range spread of those neighbours.

    Returns
    -------
    RangeImage
        A new image; filled pixels are valid with ``index`` -1 (they are no scan points) and
        NaN intensity.
    """
    v = image.valid
    if v.all() or not v.any():
        return image
    xyz, hole, filled = _fill_holes(
        float_xyz(image.xyz),
        np.ascontiguousarray(v),
        int(min_neighbours),
        float(max_jump),
        image.wraps,
    )
    if filled == 0:
        return image
    log.debug("filled %d isolated no-return pixels", filled)
    return RangeImage(
        xyz=xyz,
        valid=v | hole,
        index=image.index,
        camera=image.camera,
        intensity=image.intensity,
    )


#: an image whose returns have an empty pixel beside them this often (of its returns) is a
#: cloud projected at its own density, its empty pixels directions never sampled. A sensor's
#: grid has its no-returns in regions (sky, glass, beyond range): beside 1.4-2.3 % of the
#: returns of the synthetic stations, 2.6-5 % of the PCL Kinect and room scans, 12-17 % of the
#: Ouster and Velodyne frames, 20-22 % of the organised foreign stations. Clouds projected at
#: their density: 42-61 % of fused fragments (synthetic and 3DMatch), 53-60 % of the bunny
#: range grids, 95 % of a rosette frame (a cloud of evenly spread points: 97 %)
SAMPLING_GAPS_SHARE = 0.3

#: rows (about) of a large image whose returns :func:`sampling_gaps` looks at
GAPS_ROWS = 256


def sampling_gaps(seen: NDArray[np.bool_], wraps: bool = False) -> bool:
    """Whether an image's empty pixels are gaps between a cloud's returns rather than rays
    that returned nothing: at least :data:`SAMPLING_GAPS_SHARE` of its returns have an empty
    pixel among their 8 neighbours (counted on every k-th row of an image of more than
    :data:`GAPS_ROWS` rows). Such an image is no sensor's grid: its empty pixels
    bound no open space, and its pixels pair no points for a projective ICP.

    Parameters
    ----------
    seen : (H, W) bool
        Pixels that hold a return.
    wraps : bool
        Columns wrap around (a full turn).

    Returns
    -------
    bool

    Examples
    --------
    >>> grid = np.ones((6, 6), dtype=bool); grid[:2] = False  # a sky band
    >>> sparse = np.zeros((6, 6), dtype=bool); sparse[::2, ::2] = True
    >>> sampling_gaps(grid), sampling_gaps(sparse)
    (False, True)
    """
    H = seen.shape[0]
    rows = np.arange(0, H, max(1, H // GAPS_ROWS))  # every k-th row of a large image
    block = seen[np.clip(rows[:, None] + np.arange(-1, 2), 0, H - 1)]  # (R, 3, W) row trios
    mid = block[:, 1]
    if not mid.any():
        return False
    full = block.all(axis=1)  # columns whose three rows hold returns
    left = np.roll(full, 1, axis=1) if wraps else np.pad(full, ((0, 0), (1, 0)), "edge")[:, :-1]
    right = np.roll(full, -1, axis=1) if wraps else np.pad(full, ((0, 0), (0, 1)), "edge")[:, 1:]
    beside = mid & ~(full & left & right)
    return float(beside.sum()) >= SAMPLING_GAPS_SHARE * float(mid.sum())


#: range images larger than this are subsampled (every k-th row and column) for the image stages
MAX_IMAGE_PIXELS = 2_500_000


def working_image(x: Scan | RangeImage, *, max_pixels: int = MAX_IMAGE_PIXELS) -> RangeImage:
    """The range image the image stages work on: at most ``max_pixels`` (every k-th row and
    column of larger grids). A gridded scan keeps its native grid (:func:`range_image`)."""

    def factor(h: int, w: int) -> int:
        return working_stride(h, w, max_pixels)

    if isinstance(x, Scan) and x.has_grid and x.grid_shape is not None:
        return from_grid(x, stride=factor(*x.grid_shape))
    if isinstance(x, Scan) and len(x):  # projected straight into the kept pixels
        camera = auto_spherical_camera(x.points)
        k = factor(*camera.shape)
        log.info(
            "projecting %d points into every %d-th pixel of %dx%d", len(x), k, *camera.shape[::-1]
        )
        return project(x, camera, stride=k)
    img = x if isinstance(x, RangeImage) else range_image(x)
    return downsample_image(img, factor(img.height, img.width))


#: a native grid is its own camera image when a fitted camera puts 95 % of its points within
#: this many pixels of their own pixel (:func:`with_camera`): they round to it
GRID_CAMERA_MAX_ERROR_PX = 0.5


def with_camera(image: RangeImage) -> RangeImage:
    """The image with a camera model, so that checks can look pixels up.

    The image itself when it has one; a native grid that is regular (a terrestrial scanner's
    equirectangular grid, an organised depth camera's pinhole image) gets the camera fitted to
    it (:func:`flexreg.stages.grid_camera.fit_grid_camera`, 95 % of its points within
    :data:`GRID_CAMERA_MAX_ERROR_PX` of their own pixel) and keeps its pixels; otherwise its
    points are re-projected through an equirectangular camera fitted to them
    (:func:`auto_spherical_camera`)."""
    if image.camera is not None:
        return image
    camera, _ = fit_grid_camera(image, max_error_px=GRID_CAMERA_MAX_ERROR_PX)
    if camera is not None:
        return replace(image, camera=camera)
    pts = image.xyz[image.valid]
    return project(Scan(points=pts), auto_spherical_camera(pts))


def camera_image(x: Scan | RangeImage, *, max_pixels: int = MAX_IMAGE_PIXELS) -> RangeImage:
    """The range image a scan is checked against and refined on: :func:`working_image`, holes
    filled (:func:`fill_holes`), with a camera model (:func:`with_camera`)."""
    return with_camera(fill_holes(working_image(x, max_pixels=max_pixels)))


@numba.njit(cache=True, nogil=True)
def _fill_holes(xyz, valid, min_neighbours, max_jump, wrap):  # pragma: no cover - compiled
    """:func:`fill_holes` on the arrays: a copy of ``xyz`` with the fillable holes set to the
    mean of their valid 3x3 neighbours (columns wrap when ``wrap``), their mask, and how
    many."""
    H, W = valid.shape
    out = xyz.copy()
    hole = np.zeros((H, W), dtype=np.bool_)
    filled = 0
    for i in range(H):
        for j in range(W):
            if valid[i, j]:
                continue
            cnt = 0
            rmin = np.inf
            rmax = -np.inf
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for di in range(-1, 2):
                ii = i + di
                if ii < 0 or ii >= H:
                    continue
                for dj in range(-1, 2):
                    jj = wrap_col(j + dj, W, wrap)
                    if jj < 0 or not valid[ii, jj]:
                        continue
                    x, y, z = xyz[ii, jj, 0], xyz[ii, jj, 1], xyz[ii, jj, 2]
                    r = math.sqrt(x * x + y * y + z * z)
                    rmin = min(rmin, r)
                    rmax = max(rmax, r)
                    sx += x
                    sy += y
                    sz += z
                    cnt += 1
            if cnt >= min_neighbours and rmax - rmin <= max_jump * rmax:
                out[i, j, 0] = sx / cnt
                out[i, j, 1] = sy / cnt
                out[i, j, 2] = sz / cnt
                hole[i, j] = True
                filled += 1
    return out, hole, filled
