"""What the picker shows: the camera image, the lidar views (the scan's panorama as Flexion,
range or intensity image, and a perspective Flexion view), the lidar points projected on the
camera image, and where a click on a lidar view lands (the nearest real return).

Pixel coordinates follow :mod:`flexreg.core.camera`: integer ``(x, y)`` is the centre of pixel
``[y, x]``. Lidar-view coordinates are those of the view's own grid: ``(col, row)`` of the
panorama (:func:`flexreg.calibration.scan_range_image`, the grid of ``u,v,row,col`` files) or
the working pixels of the perspective view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.calibration.auto import FlexionView, render_flexion_view
from flexreg.calibration.panorama import panorama_flexion, scan_range_image
from flexreg.core.camera import SphericalCamera
from flexreg.core.scan import Scan
from flexreg.core.transforms import apply
from flexreg.errors import InputError
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages import feature_images as images
from flexreg.stages.camera_pose import project_points
from flexreg.viz.draw import as_bgr, range_colours

__all__ = [
    "OVERLAY_DOT_PX",
    "OVERLAY_SPACING_PX",
    "PANORAMA_MODES",
    "LidarViews",
    "Snap",
    "encode_png",
    "overlay_rgba",
    "preview",
]

#: lidar views on the panorama grid
PANORAMA_MODES = ("flexion", "range", "intensity")
#: farthest a click may be from a return and still snap to it, view pixels
SNAP_RADIUS_PX = 48
#: projected lidar points on the camera image: dot size and least spacing, screen pixels
OVERLAY_DOT_PX = 4
OVERLAY_SPACING_PX = 10


def encode_png(image: NDArray[np.uint8]) -> bytes:
    """PNG bytes of a grey, BGR or BGRA image."""
    import cv2  # heavy: OpenCV loads only when drawing

    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise InputError("image", "cannot encode PNG")
    return bytes(buf.tobytes())


def preview(image: NDArray[np.uint8], max_px: int) -> NDArray[np.uint8]:
    """``image`` shrunk (area average) so that its longer side is at most ``max_px``."""
    import cv2  # heavy: OpenCV loads only when drawing

    h, w = image.shape[:2]
    s = max_px / max(h, w)
    if s >= 1:
        return image
    size = (max(1, round(w * s)), max(1, round(h * s)))
    return np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)


def _disc(radius: int) -> NDArray[np.int64]:
    """(K, 2) integer offsets within ``radius`` pixels of a pixel (the pixel itself for 0)."""
    d = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(d, d)
    inside = dx * dx + dy * dy <= radius * radius + radius  # rounder discs for small radii
    return np.column_stack([dx[inside], dy[inside]])


def _nearest_per_cell(xy: NDArray[np.float64], cell: float) -> NDArray[np.int64]:
    """Indices of the first point (in the given order) in each ``cell`` x ``cell`` square."""
    key = np.floor(xy / cell).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


def overlay_rgba(
    points: ArrayLike,
    intrinsics: CameraIntrinsics,
    T_camera_lidar: ArrayLike,
    size: tuple[int, int],
    *,
    max_range_m: float | None = None,
    zoom: float = 1.0,
) -> NDArray[np.uint8]:
    """Lidar points projected into the camera image as a transparent layer, coloured by range.

    The dots keep one look on screen whatever the zoom and the scan's density: each is
    :data:`OVERLAY_DOT_PX` screen pixels across with a dark rim one screen pixel wide (seen on
    light and dark images alike), in the bright part of the colour map, and at most one dot
    (the nearest return) is drawn per square of :data:`OVERLAY_SPACING_PX` screen pixels, so
    that a dense TLS scan seen whole shows a lattice of dots instead of a haze; zooming in
    shows more of them.

    Parameters
    ----------
    points : (N, 3) float, metres, lidar frame
    intrinsics : CameraIntrinsics
        With the image size known (lens distortion is applied).
    T_camera_lidar : (4, 4) float
    size : (w, h) int
        Size of the layer (the image as served: full size or a preview of it).
    max_range_m : float, optional
        Far end of the colour map (default: 95th percentile of the visible points' ranges).
    zoom : float
        Screen pixels per layer pixel where the page shows the layer (> 0).

    Returns
    -------
    (h, w, 4) uint8
        BGRA, alpha 255 on the dots (near ones drawn last), 0 elsewhere.
    """
    if intrinsics.size is None:
        raise InputError(intrinsics.source, "image size unknown")
    if not (math.isfinite(zoom) and zoom > 0):
        raise InputError("zoom", f"must be a positive number, got {zoom!r}")
    W, H = intrinsics.size
    w, h = size
    out = np.zeros((h, w, 4), dtype=np.uint8)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    uv, z = project_points(P, intrinsics, T_camera_lidar)
    vis = (z > 0) & np.isfinite(uv).all(axis=1)
    vis &= (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    if not vis.any():
        return out
    r = np.linalg.norm(P[vis], axis=1)
    far = max(float(np.percentile(r, 95)) if max_range_m is None else float(max_range_m), 1e-3)
    xy = (uv[vis] + 0.5) * [w / W, h / H] - 0.5
    near_first = np.argsort(r, kind="stable")
    cell = OVERLAY_SPACING_PX / zoom
    keep = near_first[_nearest_per_cell(xy[near_first], cell)] if cell > 1 else near_first
    order = keep[np.argsort(-r[keep], kind="stable")]  # far to near: near ones on top
    # the colour map's bright middle (10 % to 90 %): its dark ends vanish on dark images
    colours = range_colours(far * (0.1 + 0.8 * np.minimum(r[order] / far, 1.0)), far)
    ix = np.rint(xy[order]).astype(np.int64)
    radius = max(0, round(OVERLAY_DOT_PX / 2 / zoom - 0.5))
    rim = radius + max(1, round(1 / zoom))
    for offsets, fill in ((_disc(rim), None), (_disc(radius), colours)):
        for dx, dy in offsets:
            x, y = ix[:, 0] + dx, ix[:, 1] + dy
            ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
            out[y[ok], x[ok], :3] = 24 if fill is None else fill[ok]
            out[y[ok], x[ok], 3] = 255
    return out


@dataclass(frozen=True)
class Snap:
    """Where a click on a lidar view lands: the nearest pixel holding a real return.

    Attributes
    ----------
    x, y : float
        The snapped pixel's centre in the view.
    index : int
        The scan point there.
    point : (3,) float64, metres, lidar frame
    """

    x: float
    y: float
    index: int
    point: NDArray[np.float64]

    @property
    def range_m(self) -> float:
        """Distance of the point from the lidar, metres."""
        return float(np.linalg.norm(self.point))


def _nearest_valid(valid: NDArray[np.bool_], x: float, y: float) -> tuple[int, int] | None:
    """``(row, col)`` of the valid pixel nearest ``(x, y)`` within :data:`SNAP_RADIUS_PX`."""
    H, W = valid.shape
    cx, cy = math.floor(x + 0.5), math.floor(y + 0.5)
    r = SNAP_RADIUS_PX
    r0, r1, c0, c1 = max(0, cy - r), min(H, cy + r + 1), max(0, cx - r), min(W, cx + r + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    rows, cols = np.nonzero(valid[r0:r1, c0:c1])
    if rows.size == 0:
        return None
    d = (rows + r0 - y) ** 2 + (cols + c0 - x) ** 2
    k = int(np.argmin(d))
    return int(rows[k] + r0), int(cols[k] + c0)


def _turns_counter_clockwise(xyz: NDArray[np.floating], valid: NDArray[np.bool_]) -> bool:
    """Whether a grid's columns turn counter-clockwise about +Z (azimuth ``atan2(y, x)``
    growing with the column, median over neighbouring returns of about 64 rows). Seen from
    the scanner with +Z up, such a panorama is mirrored next to a camera image."""
    rows = slice(None, None, max(1, xyz.shape[0] // 64))
    P, v = xyz[rows], valid[rows]
    phi = np.arctan2(P[..., 1], P[..., 0]).astype(np.float64)
    d = np.mod(phi[:, 1:] - phi[:, :-1] + np.pi, 2 * np.pi) - np.pi
    d = d[v[:, 1:] & v[:, :-1]]
    return bool(d.size > 0 and np.median(d) > 0)


class LidarViews:
    """The scan's pictures for picking, the grids they share, and snapping on them.

    Parameters
    ----------
    scan : Scan
    intrinsics : CameraIntrinsics
        With the image size known (for the perspective view).
    T_init : (4, 4) float, optional
        Pose of the perspective Flexion view (without it there is none).
    n : int
        Flexion grid size.
    """

    def __init__(
        self,
        scan: Scan,
        intrinsics: CameraIntrinsics,
        T_init: ArrayLike | None = None,
        *,
        n: int = 3,
    ) -> None:
        self.scan = scan
        self.n = n
        self.range_image = scan_range_image(scan)
        ri = self.range_image
        cam = ri.camera
        # spinning lidars sample elevation more coarsely than azimuth: show angles to scale
        self.aspect = (
            float(np.clip(cam.dtheta / cam.dphi, 1.0, 8.0))
            if isinstance(cam, SphericalCamera)
            else 1.0
        )
        self.mirror = _turns_counter_clockwise(ri.xyz, ri.valid)
        self._pixel_of = np.full(len(scan), -1, dtype=np.int64)  # scan point -> panorama pixel
        flat = np.flatnonzero((ri.valid & (ri.index >= 0)).ravel())
        self._pixel_of[ri.index.ravel()[flat][::-1]] = flat[::-1]  # first pixel wins
        self.perspective: FlexionView | None = None
        if T_init is not None:
            self.perspective = render_flexion_view(scan, intrinsics, T_init, n=n)
        self._pictures: dict[str, NDArray[np.uint8]] = {}
        self._tree: Any = None  # scipy cKDTree of the scan's points, built on first use

    @property
    def modes(self) -> list[str]:
        """The views this scan has: ``flexion``, ``range``, ``intensity`` (when the scan has
        intensities), ``perspective`` (with an initial guess)."""
        m = ["flexion", "range"]
        m += ["intensity"] if self.range_image.intensity is not None else []
        m += ["perspective"] if self.perspective is not None else []
        return m

    def check_mode(self, mode: str) -> str:
        """``mode`` itself, or an error naming the available ones."""
        if mode not in self.modes:
            raise InputError("view", f"unknown lidar view {mode!r}; this scan has {self.modes}")
        return mode

    def grid(self, mode: str) -> str:
        """``"panorama"`` or ``"perspective"``: the pixel grid a view's coordinates refer to."""
        return "perspective" if self.check_mode(mode) == "perspective" else "panorama"

    def size(self, mode: str) -> tuple[int, int]:
        """``(width, height)`` of a view, pixels."""
        if self.grid(mode) == "perspective":
            assert self.perspective is not None
            h, w = self.perspective.flexion.shape
            return w, h
        return self.range_image.width, self.range_image.height

    def picture(self, mode: str) -> NDArray[np.uint8]:
        """(h, w, 3) uint8 BGR picture of a view (computed once)."""
        mode = self.check_mode(mode)
        if mode not in self._pictures:
            self._pictures[mode] = self._draw(mode)
        return self._pictures[mode]

    def _draw(self, mode: str) -> NDArray[np.uint8]:
        ri = self.range_image
        if mode == "flexion":
            F = panorama_flexion(self.scan, n=self.n)
            q, _ = images.quantize(F, 8, stretch="percentile", percentiles=(1.0, 99.0))
            return as_bgr(np.asarray(q, dtype=np.uint8))
        if mode == "perspective":
            assert self.perspective is not None
            q, _ = images.quantize(self.perspective.flexion, 8)
            return as_bgr(np.asarray(q, dtype=np.uint8))
        if mode == "range":
            r = ri.range.astype(np.float64)
            far = float(np.percentile(r[ri.valid], 95)) if ri.valid.any() else 1.0
            out = np.zeros((*ri.shape, 3), dtype=np.uint8)
            out[ri.valid] = range_colours(r[ri.valid], max(far, 1e-3))
            return out
        assert ri.intensity is not None
        q, _ = images.quantize(
            np.where(ri.valid, ri.intensity, np.nan), 8, stretch="percentile", percentiles=(1, 99)
        )
        return as_bgr(np.asarray(q, dtype=np.uint8))

    def snap(self, mode: str, x: float, y: float) -> Snap:
        """The real return nearest ``(x, y)`` on a view.

        Raises
        ------
        InputError
            ``(x, y)`` outside the view, or no return within :data:`SNAP_RADIUS_PX`.
        """
        W, H = self.size(mode)
        if not (-0.5 <= x <= W - 0.5 and -0.5 <= y <= H - 0.5):
            raise InputError("lidar click", f"({x:g}, {y:g}) lies outside the {W}x{H} {mode} view")
        if self.grid(mode) == "perspective":
            assert self.perspective is not None
            index_map = self.perspective.index
        else:
            # filled holes (index -1) hold no scan point: never snapped to
            index_map = np.where(self.range_image.valid, self.range_image.index, -1)
        hit = _nearest_valid(index_map >= 0, x, y)
        if hit is None:
            raise InputError("lidar click", f"no lidar return near ({x:.0f}, {y:.0f})")
        row, col = hit
        idx = int(index_map[row, col])
        return Snap(float(col), float(row), idx, np.array(self.scan.points[idx], dtype=np.float64))

    def index_of(self, points: ArrayLike) -> NDArray[np.int64]:
        """(N,) int64 the scan point nearest each of ``points`` (k-d tree, built once)."""
        from scipy.spatial import cKDTree  # heavy: ~0.1 s at import

        if self._tree is None:
            self._tree = cKDTree(self.scan.points)
        _, k = self._tree.query(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        return np.asarray(k, dtype=np.int64)

    def locate(self, points: ArrayLike, index: ArrayLike, grid: str) -> NDArray[np.float64]:
        """(N, 2) float64 position of points on a grid (NaN where it does not show them).

        On the panorama: the pixel of scan point ``index`` (-1: not on it). On the
        perspective view: the point's projection with the view's camera and pose.
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full((len(P), 2), np.nan)
        if grid == "perspective":
            if self.perspective is None or not len(P):
                return out
            v = self.perspective
            pc = apply(v.T_camera_lidar, P)
            front = pc[:, 2] > 0
            c = v.camera
            z = np.where(front, pc[:, 2], 1.0)
            x = c.fx * pc[:, 0] / z + c.skew * pc[:, 1] / z + c.cx
            y = c.fy * pc[:, 1] / z + c.cy
            ok = front & (x >= -0.5) & (x <= c.width - 0.5) & (y >= -0.5) & (y <= c.height - 0.5)
            out[ok] = np.column_stack([x, y])[ok]
            return out
        idx = np.asarray(index, dtype=np.int64).reshape(-1)
        ok = (idx >= 0) & (idx < len(self._pixel_of))
        pix = np.full(len(idx), -1, dtype=np.int64)
        pix[ok] = self._pixel_of[idx[ok]]
        has = pix >= 0
        W = self.range_image.width
        out[has, 0] = pix[has] % W
        out[has, 1] = pix[has] // W
        return out
