"""The range image: an organised view of a scan, every pixel holding the scanner's own point.

:class:`RangeImage` is the central data structure: ``xyz`` keeps the 3D point of every pixel
(never a resampled one), ``index`` maps each pixel back to the scan's point, ``valid`` marks
returns, and ``camera`` (when known) relates pixels and rays (paper eq. 1-8). The builders here
need no algorithm: a native grid, a depth image with its camera, a pixel -> point index map.
The z-buffer projection of unstructured clouds is a stage (:mod:`flexreg.stages.projection`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import Camera, DepthKind, PinholeCamera, SphericalCamera
from flexreg.core.scan import Scan
from flexreg.errors import InputError

__all__ = [
    "RangeImage",
    "downsample_image",
    "float_xyz",
    "from_depth",
    "from_grid",
    "from_index",
    "to_scan",
]


@dataclass(eq=False)
class RangeImage:
    """An organised view of a scan.

    Attributes
    ----------
    xyz : (H, W, 3) float32 or float64, metres
        Scanner-frame point of each pixel; NaN where invalid. Float32 when made from a float32
        scan (the scanner-frame readers' points): the stages read it as it is and do their
        sums and solves in float64.
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

    xyz: NDArray[np.floating]
    valid: NDArray[np.bool_]
    index: NDArray[np.int64]
    camera: Camera | None = None
    intensity: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        H, W = self.valid.shape
        if self.xyz.shape != (H, W, 3) or self.index.shape != (H, W):
            raise InputError("range image", "xyz, valid and index shapes disagree")

    def __getstate__(self) -> dict[str, Any]:
        """Pickled as it is, except an ``index`` that is one value repeated (a working image
        that keeps no point numbers: a read-only broadcast view), which is stored as that
        value and unpickled as the same view (no pixel-sized array in what travels between
        processes or in the memory of the process that loads it; the survey's cache stores it
        the same way, as data)."""
        state = dict(self.__dict__)
        ix = self.index
        if ix.size and not any(ix.strides):
            state["index"] = ("broadcast", ix.dtype.str, ix.flat[0].item(), ix.shape)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        ix = state["index"]
        if isinstance(ix, tuple):
            _, dtype, value, shape = ix
            state = {**state, "index": np.broadcast_to(np.array(value, dtype=dtype), shape)}
        self.__dict__.update(state)

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


def working_stride(height: int, width: int, max_pixels: int) -> int:
    """Every how many rows and columns a grid of ``height`` x ``width`` is kept so that its
    working image has at most about ``max_pixels`` pixels (1: the whole grid).

    >>> working_stride(1024, 2048, 2_500_000), working_stride(4096, 8192, 2_500_000)
    (1, 4)
    """
    return max(1, math.ceil(math.sqrt(height * width / max(1, max_pixels))))


def float_xyz(a: NDArray[np.generic]) -> NDArray[np.floating]:
    """``a`` as a C-contiguous float32 array when it is float32, float64 otherwise (no copy
    when it already is one): what the compiled stages take, so that a float32 image is never
    copied to float64 whole."""
    a = np.asarray(a)
    return np.ascontiguousarray(a, dtype=np.float32 if a.dtype == np.float32 else np.float64)


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
    s = max(1, int(stride))
    # only the kept rows and columns: no full-size index (or point-number array) first
    index = _grid_index(scan.grid_index, (H + s - 1) // s, (W + s - 1) // s, s)
    camera = scan.camera if s == 1 else subsampled_camera(scan.camera, H, W, s)
    return from_index(scan, index, camera)


@numba.njit(cache=True, nogil=True)
def _grid_index(grid_index, h, w, s):  # pragma: no cover - compiled
    """(h, w) int64 index of the points on every ``s``-th row and column of their grid
    (``grid_index`` (N, 2) row, column); -1 where none. A later point wins a shared cell."""
    index = np.full((h, w), -1, dtype=np.int64)
    for i in range(grid_index.shape[0]):
        r = grid_index[i, 0]
        c = grid_index[i, 1]
        if r % s == 0 and c % s == 0:
            index[r // s, c // s] = i
    return index


def from_index(scan: Scan, index: NDArray[np.int64], camera: Camera | None) -> RangeImage:
    """Range image whose pixels show ``scan.points[index]`` (``index`` (H, W) int64, -1 where
    there is no return), with the scan's intensities; ``xyz`` has the points' type."""
    valid = index >= 0
    xyz = np.empty((*index.shape, 3), dtype=scan.points.dtype)
    intensity = None if scan.intensity is None else np.empty(index.shape, dtype=np.float32)
    _gather(scan.points, scan.intensity, index, xyz, intensity)
    return RangeImage(xyz=xyz, valid=valid, index=index, camera=camera, intensity=intensity)


def _gather(
    points: NDArray[np.floating],
    intensity: NDArray[np.float32] | None,
    index: NDArray[np.int64],
    xyz: NDArray[np.floating],
    out_intensity: NDArray[np.float32] | None,
) -> None:
    """``xyz`` and ``out_intensity`` (when not None) of the pixels of ``index``, NaN where it
    is -1, without point-sized temporaries."""
    _gather_points(points, index, xyz)
    if out_intensity is not None:
        _gather_values(intensity, index, out_intensity)


@numba.njit(cache=True, nogil=True)
def _gather_points(points, index, xyz):  # pragma: no cover - compiled
    H, W = index.shape
    for i in range(H):
        for j in range(W):
            k = index[i, j]
            for c in range(3):
                xyz[i, j, c] = points[k, c] if k >= 0 else np.nan


@numba.njit(cache=True, nogil=True)
def _gather_values(values, index, out):  # pragma: no cover - compiled
    H, W = index.shape
    for i in range(H):
        for j in range(W):
            k = index[i, j]
            out[i, j] = values[k] if k >= 0 else np.nan


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


def subsampled_camera(camera: Camera | None, H: int, W: int, f: int) -> Camera | None:
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
        camera=subsampled_camera(image.camera, image.height, image.width, f),
        intensity=None if image.intensity is None else image.intensity[::f, ::f].copy(),
    )


def to_scan(image: RangeImage, **kwargs: Any) -> Scan:
    """The valid pixels of a range image as a gridded :class:`Scan` (row-major point order)."""
    return Scan.from_organized(
        image.xyz, image.valid, intensity=image.intensity, camera=image.camera, **kwargs
    )
