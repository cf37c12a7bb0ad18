"""Scan -> :class:`RangeImage`: native grid, z-buffer projection, or depth image + camera.

The range image keeps the 3D point of every pixel (``xyz``), so the image conversions need no
camera at all, and the pixel -> point index map, so 2D features can be lifted back to the scan.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from .camera import Camera, DepthKind, PinholeCamera, SphericalCamera
from .errors import InputError
from .images import _col
from .scan import Scan

log = logging.getLogger(__name__)


@dataclass(eq=False)
class RangeImage:
    """An organised view of a scan.

    Attributes
    ----------
    xyz : (H, W, 3) float64, metres
        Scanner-frame point of each pixel; NaN where invalid.
    valid : (H, W) bool
        Pixels that hold a return.
    index : (H, W) int64
        Index into the source scan's ``points`` of the point each pixel shows; -1 where invalid
        (or where the image was not made from a scan).
    camera : PinholeCamera or SphericalCamera or None
        Model relating pixels and rays; ``None`` for a native scanner grid whose geometry is only
        implied by its points.
    intensity : (H, W) float32 or None
        Per-pixel intensity, NaN where invalid.
    """

    xyz: NDArray[np.float64]
    valid: NDArray[np.bool_]
    index: NDArray[np.int64]
    camera: Camera | None = None
    intensity: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        H, W = self.valid.shape
        if self.xyz.shape != (H, W, 3) or self.index.shape != (H, W):
            raise InputError("range image", "xyz, valid and index shapes disagree")

    def __repr__(self) -> str:
        cam = type(self.camera).__name__ if self.camera is not None else "native grid"
        return f"RangeImage({self.height}x{self.width}, {self.n_valid} valid, {cam})"

    @property
    def height(self) -> int:
        return int(self.valid.shape[0])

    @property
    def width(self) -> int:
        return int(self.valid.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``."""
        return (self.height, self.width)

    @property
    def n_valid(self) -> int:
        return int(np.count_nonzero(self.valid))

    @property
    def wraps(self) -> bool:
        """True for a full-turn equirectangular image (columns wrap around)."""
        return isinstance(self.camera, SphericalCamera) and self.camera.wraps

    @property
    def range(self) -> NDArray[np.float32]:
        """(H, W) float32 Euclidean range in metres, NaN where invalid."""
        with np.errstate(invalid="ignore"):
            r = np.sqrt(np.einsum("ijk,ijk->ij", self.xyz, self.xyz)).astype(np.float32)
        r[~self.valid] = np.nan
        return r

    def depth_z(self) -> NDArray[np.float32]:
        """(H, W) float32 orthographic depth ``Z`` in metres (pinhole images), NaN where invalid."""
        z = self.xyz[..., 2].astype(np.float32)
        z[~self.valid] = np.nan
        return z

    def gather(self, values: NDArray[np.generic], fill: float = np.nan) -> NDArray[np.generic]:
        """Per-point values of the source scan laid out on the image, ``fill`` where invalid."""
        values = np.asarray(values)
        out = np.full(self.shape + values.shape[1:], fill, dtype=np.result_type(values, type(fill)))
        m = self.index >= 0
        out[m] = values[self.index[m]]
        return out


# ------------------------------------------------------------------------------ builders


def from_grid(scan: Scan, *, stride: int = 1) -> RangeImage:
    """Range image on the scan's native grid, without resampling.

    Parameters
    ----------
    scan : Scan
        Must carry ``grid_shape`` and ``grid_index`` (PTX, gridded E57, organised PCD, 3DTK,
        depth images, synthetic stations).
    stride : int
        Keep every ``stride``-th row and column (as :func:`downsample_image`, without building
        the full-size image first).
    """
    if scan.grid_shape is None or scan.grid_index is None:
        raise InputError(scan.path or scan.name, "scan has no native grid; project it instead")
    H, W = scan.grid_shape
    r, c = scan.grid_index[:, 0], scan.grid_index[:, 1]
    index = np.full((H, W), -1, dtype=np.int64)
    index[r, c] = np.arange(len(scan), dtype=np.int64)
    if stride == 1:
        return _from_index(scan, index, scan.camera)
    return _from_index(
        scan,
        np.ascontiguousarray(index[::stride, ::stride]),
        _subsampled_camera(scan.camera, H, W, stride),
    )


def _from_index(scan: Scan, index: NDArray[np.int64], camera: Camera | None) -> RangeImage:
    valid = index >= 0
    xyz = np.full((*index.shape, 3), np.nan)
    xyz[valid] = scan.points[index[valid]]
    intensity = None
    if scan.intensity is not None:
        intensity = np.full(index.shape, np.nan, dtype=np.float32)
        intensity[valid] = scan.intensity[index[valid]]
    return RangeImage(xyz=xyz, valid=valid, index=index, camera=camera, intensity=intensity)


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


def project(scan: Scan, camera: Camera) -> RangeImage:
    """Z-buffer projection of a scan through a camera: the nearest return wins each pixel.

    Parameters
    ----------
    scan : Scan
        Points in the camera/scanner frame.
    camera : PinholeCamera or SphericalCamera
        Pixel ``[v, u]`` receives the points whose coordinates round to ``(u, v)``.

    Returns
    -------
    RangeImage
        The pixel holds the *original* point (not a resampled one), so nothing is lost to
        quantisation; ``index`` points back into ``scan.points``.
    """
    u, v, d = camera.project(scan.points)
    H, W = camera.shape
    with np.errstate(invalid="ignore"):
        iu = np.floor(u + 0.5)
        iv = np.floor(v + 0.5)
    if isinstance(camera, SphericalCamera) and camera.wraps:
        iu = np.where(iu >= W, iu - W, iu)
    ok = np.isfinite(iu) & np.isfinite(iv) & (iu >= 0) & (iu < W) & (iv >= 0) & (iv < H) & (d > 0)
    lin = np.where(ok, iv * W + iu, -1).astype(np.int64)
    index = _zbuffer(lin, d, H * W).reshape(H, W)
    return _from_index(scan, index, camera)


def azimuth_polar_extent(points: NDArray[np.float64]) -> tuple[float, float, float, float, bool]:
    """Angular extent of points seen from the origin.

    Returns
    -------
    phi_min, phi_max, theta_min, theta_max : float, radians
        ``phi_max`` may exceed pi when the covered azimuth interval crosses the -pi/pi cut.
    full_turn : bool
        True when no azimuth gap wider than 5 degrees exists.
    """
    P = np.asarray(points, dtype=np.float64)
    if len(P) == 0:
        raise InputError("points", "no points")
    r = np.linalg.norm(P, axis=1)
    P = P[r > 0]
    r = r[r > 0]
    phi = np.sort(np.arctan2(P[:, 1], P[:, 0]))
    theta = np.arccos(np.clip(P[:, 2] / r, -1.0, 1.0))
    gaps = np.diff(np.concatenate([phi, [phi[0] + 2 * np.pi]]))
    k = int(np.argmax(gaps))
    full = bool(gaps[k] < np.radians(5.0))
    if full:
        phi_min, phi_max = -np.pi, np.pi
    else:  # the covered interval starts after the widest gap
        phi_min = float(phi[(k + 1) % len(phi)])
        phi_max = float(phi[k])
        if phi_max < phi_min:
            phi_max += 2 * np.pi
    return float(phi_min), float(phi_max), float(theta.min()), float(theta.max()), full


def _lidar_rings(points: NDArray[np.float64]) -> tuple[int, float, float] | None:
    """``(rings, ring_spacing_rad, azimuth_pitch_rad)`` when the cloud is a spinning lidar's:
    its polar angles fall into a few narrow, about evenly spaced bands (one per beam); else None.

    The azimuth pitch is measured along the rings (consecutive azimuths of one beam), never
    derived from the number of points: a sweep that loses returns to the sky, windows, glass
    or range limits keeps its firing pitch, and a few rays more or less (another CPU's ray
    caster, another dropout draw) cannot move it.
    """
    P = np.asarray(points, dtype=np.float64)
    if len(P) < 1000:
        return None
    r = np.linalg.norm(P, axis=1)
    th_all = np.arccos(np.clip(P[:, 2] / np.where(r > 0, r, 1.0), -1.0, 1.0))
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
    points: NDArray[np.float64], *, angular_resolution_rad: float | None = None
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
    span_phi, span_th = phi_max - phi_min, max(th_max - th_min, 1e-6)
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
        # occupancy of the domain on a grid 8x coarser than the first guess
        P = np.asarray(points, dtype=np.float64)
        r = np.linalg.norm(P, axis=1)
        ph = np.mod(np.arctan2(P[:, 1], P[:, 0]) - phi_min, 2 * np.pi)
        th = np.arccos(np.clip(P[:, 2] / np.where(r > 0, r, 1.0), -1.0, 1.0)) - th_min
        cell = 8 * step
        nx, ny = max(1, int(span_phi / cell) + 1), max(1, int(span_th / cell) + 1)
        occ = np.zeros((ny, nx), dtype=bool)
        occ[
            np.clip((th / cell).astype(int), 0, ny - 1), np.clip((ph / cell).astype(int), 0, nx - 1)
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


def from_depth(
    depth_m: NDArray[np.floating], camera: Camera, *, depth_kind: DepthKind | None = None
) -> RangeImage:
    """Range image from a depth or range map and its camera (eq. 2 or eq. 7-8).

    Parameters
    ----------
    depth_m : (H, W) float, metres
        0, negative or NaN mark no return.
    camera : PinholeCamera or SphericalCamera
        Its size must match the image.
    depth_kind : {"z", "range"}, optional
        Orthographic depth or Euclidean range; default ``"z"`` for pinhole, ``"range"`` for
        spherical (a spherical camera only accepts ``"range"``).
    """
    d = np.asarray(depth_m, dtype=np.float64)
    if d.shape != camera.shape:
        raise InputError(
            "depth image",
            f"size {d.shape[1]}x{d.shape[0]} does not match the camera's "
            f"{camera.width}x{camera.height}",
        )
    valid = np.isfinite(d) & (d > 0)
    v, u = np.mgrid[0 : d.shape[0], 0 : d.shape[1]].astype(np.float64)
    if isinstance(camera, PinholeCamera):
        xyz = camera.backproject(u, v, np.where(valid, d, np.nan), depth_kind=depth_kind or "z")
    else:
        if depth_kind not in (None, "range"):
            raise InputError("depth_kind", "an equirectangular image stores range, not z")
        xyz = camera.backproject(u, v, np.where(valid, d, np.nan))
    index = np.full(d.shape, -1, dtype=np.int64)
    index[valid] = np.arange(int(valid.sum()), dtype=np.int64)
    return RangeImage(xyz=xyz, valid=valid, index=index, camera=camera)


def _subsampled_camera(camera: Camera | None, H: int, W: int, f: int) -> Camera | None:
    """The camera of every ``f``-th row and column of an H x W image (pixel ``(u', v')`` is the
    original ``(f u', f v')``), or None when the size is not a multiple of ``f``."""
    c = camera
    if c is None or H % f or W % f:
        return None
    if isinstance(c, SphericalCamera):
        return SphericalCamera(W // f, H // f, c.phi_min, c.phi_max, c.theta_min, c.theta_max)
    if isinstance(c, PinholeCamera):
        return PinholeCamera(
            c.fx / f, c.fy / f, c.cx / f, c.cy / f, W // f, H // f, skew=c.skew / f
        )
    return None


def downsample_image(image: RangeImage, factor: int) -> RangeImage:
    """Every ``factor``-th row and column of a range image (points kept, not averaged).

    The camera is scaled to match when the image size is a multiple of ``factor`` (pixel
    ``(u', v')`` is the original ``(factor u', factor v')``); otherwise the result is a native
    grid without a camera model.
    """
    f = int(factor)
    if f < 1:
        raise InputError("factor", f"must be a positive integer, got {factor}")
    if f == 1:
        return image
    return RangeImage(
        xyz=np.ascontiguousarray(image.xyz[::f, ::f]),
        valid=np.ascontiguousarray(image.valid[::f, ::f]),
        index=np.ascontiguousarray(image.index[::f, ::f]),
        camera=_subsampled_camera(image.camera, image.height, image.width, f),
        intensity=None if image.intensity is None else image.intensity[::f, ::f].copy(),
    )


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
        np.ascontiguousarray(image.xyz, dtype=np.float64),
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
                    jj = _col(j + dj, W, wrap)
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


def to_scan(image: RangeImage, **kwargs: Any) -> Scan:
    """The valid pixels of a range image as a gridded :class:`Scan` (row-major point order)."""
    return Scan.from_organized(
        image.xyz, image.valid, intensity=image.intensity, camera=image.camera, **kwargs
    )
