"""Depth conversions of the paper's section III: organised 3D points -> 2D feature images.

Every conversion works on an organised ``(H, W, 3)`` grid of 3D points (a spherical or pinhole
range image, or a scanner's native grid): it only needs the points of neighbouring pixels, never
a camera model. A point is *invalid* if any coordinate is NaN or infinite, or if it is exactly
the origin ``(0, 0, 0)`` (a "no return" stored as zero depth).

=========================  ===============================================  ==================
kind                       what the pixel holds                             paper
=========================  ===============================================  ==================
``flexion``                Flexion n x n, ``|n1 . n2|`` in [0, 1]           eq. 11-13
``flexion-normalized``     ``|n1 . n2| / (|n1| |n2|)`` in [0, 1]            sec. III-B-4
``flexion-angle``          ``1 - angle(n1, n2) / pi`` in [0, 1]             eq. 14
``bearing-horizontal``     Bearing Angle to the left neighbour, radians     eq. 9 (Harati)
``bearing-vertical``       ... to the neighbour above, radians              eq. 9
``bearing-diagonal``       ... to the upper-left neighbour, radians         eq. 9
``bearing-antidiagonal``   ... to the lower-left neighbour, radians         eq. 9
``range``                  Euclidean distance to the sensor, metres         eq. 4
``curvature-gaussian``     Gaussian curvature ``K``, 1/m^2                  Fig. 5a baseline
``curvature-mean``         mean curvature ``H``, 1/m                        Fig. 5b baseline
``curvature-max``          principal curvature of largest magnitude, 1/m    Fig. 5c baseline
=========================  ===============================================  ==================

Neighbourhoods. ``n`` is the paper's grid size (Flexion n x n); the neighbours are at the pixel
offset ``k = (n - 1) / 2`` horizontally, vertically and diagonally (the authors' code passes
``k`` itself as "n"). A pixel is valid only if its own point and every neighbour it uses are
valid; everything else is NaN in the float images and 0 (with ``valid = False``) after
:func:`quantize`. For a full-turn equirectangular image (``wrap=True``) the columns wrap around,
so the seam columns use the neighbours on the other side instead of being a dead border.

The kernels are numba functions parallel over (blocks of) rows; they read float32 or float64
points, compute in float64 and allocate only their float32 output plus per-thread scratch (the
Flexion kernel's ring buffer of ``2k + 1`` rows, a few hundred kB).

Examples
--------
>>> import numpy as np
>>> v, u = np.mgrid[0:5, 0:5].astype(float)
>>> plane = np.stack([u, v, np.full_like(u, 10.0)], axis=-1)   # a plane facing the sensor
>>> f = flexion(plane)
>>> round(float(f[2, 2]), 6), bool(np.isnan(f[0, 0]))
(1.0, True)
>>> img, valid = quantize(f, bits=8)
>>> int(img[2, 2]), int(img[0, 0]), bool(valid[0, 0])
(255, 0, False)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal, Union

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.config import MAX_GRID_SIZE
from flexreg.core.range_image import RangeImage
from flexreg.errors import ConfigError, InputError, RegistrationError
from flexreg.stages._image_kernels import (
    bearing_kernel,
    curvature_kernel,
    flexion_kernel,
    median_kernel,
    quantize_kernel,
    range_kernel,
)
from flexreg.stages.projection import fill_holes as fill_image_holes

__all__ = [
    "BEARING_DIRECTIONS",
    "CURVATURE_KINDS",
    "KINDS",
    "bearing_angle",
    "convert",
    "curvature",
    "feature_image",
    "flexion",
    "flexion_angle",
    "flexion_normalized",
    "median_prefilter",
    "quantize",
    "range_values",
    "value_range",
]

BearingDirection = Literal["horizontal", "vertical", "diagonal", "antidiagonal"]
CurvatureKind = Literal["gaussian", "mean", "max"]
Stretch = Literal["percentile", "clahe"]
PointsLike = Union[ArrayLike, "RangeImage"]

#: Offset ``(d_row, d_col)`` of the "previous" neighbour of each Bearing Angle direction
#: (Harati's definition, paper sec. III-A): left, above, upper-left, lower-left.
BEARING_DIRECTIONS: dict[str, tuple[int, int]] = {
    "horizontal": (0, -1),
    "vertical": (-1, 0),
    "diagonal": (-1, -1),
    "antidiagonal": (1, -1),
}
CURVATURE_KINDS: tuple[str, ...] = ("gaussian", "mean", "max")

#: Every kind :func:`convert` accepts.
KINDS: tuple[str, ...] = (
    "flexion",
    "flexion-normalized",
    "flexion-angle",
    *(f"bearing-{d}" for d in BEARING_DIRECTIONS),
    "range",
    *(f"curvature-{c}" for c in CURVATURE_KINDS),
)

_FLEXION_MODES = {"flexion": 0, "flexion-normalized": 1, "flexion-angle": 2}
_CURVATURE_MODES = {"gaussian": 0, "mean": 1, "max": 2}


# ---------------------------------------------------------------------------- helpers


def _points(data: PointsLike, wrap: bool | None) -> tuple[NDArray[np.floating], bool]:
    """The (H, W, 3) C-contiguous float32/float64 points of ``data`` and the wrap flag."""
    if isinstance(data, RangeImage):
        xyz = data.xyz
        bad = ~data.valid
        if bad.any() and np.isfinite(xyz[bad]).all(axis=-1).any():
            xyz = xyz.copy()  # honour the mask for points it excludes
            xyz[bad] = np.nan
        w = data.wraps if wrap is None else bool(wrap)
    else:
        xyz = np.asarray(data)
        w = bool(wrap) if wrap is not None else False
    if xyz.ndim != 3 or xyz.shape[2] != 3:
        raise InputError("xyz", f"organised points must have shape (H, W, 3), got {xyz.shape}")
    if xyz.dtype not in (np.float32, np.float64):
        if not (np.issubdtype(xyz.dtype, np.number) or xyz.dtype == np.bool_):
            raise InputError("xyz", f"points must be numbers, got dtype {xyz.dtype}")
        xyz = xyz.astype(np.float64)
    return np.ascontiguousarray(xyz), w


def _offset(n: int) -> int:
    """Pixel offset ``k = (n - 1) / 2`` of the Flexion n x n grid."""
    if (
        isinstance(n, bool)
        or not isinstance(n, (int, np.integer))
        or not 3 <= n <= MAX_GRID_SIZE
        or n % 2 == 0
    ):
        raise ConfigError(f"n must be an odd grid size 3, 5, 7, ... {MAX_GRID_SIZE}, got {n!r}")
    return (int(n) - 1) // 2


def _prepared(data: PointsLike, n: int, median: int, wrap: bool | None):
    k = _offset(n)
    xyz, w = _points(data, wrap)
    H, W = xyz.shape[:2]
    if n > H or (n > W and not w):
        raise ConfigError(
            f"n: a {n} x {n} grid needs an image of at least {n} x {n} pixels, this one is "
            f"{W} x {H}"
        )
    if median:
        xyz = median_prefilter(xyz, window=median, wrap=w)
    return xyz, k, w


def _block(xyz: NDArray[np.floating], k: int) -> int:
    """Rows per parallel block: about four blocks per thread, at least 8k rows (halo cost)."""
    rows = max(1, xyz.shape[0] - 2 * k)
    per = -(-rows // (4 * numba.get_num_threads()))
    return int(max(8 * k, min(128, per)))


def _empty(xyz: NDArray[np.floating]) -> NDArray[np.float32]:
    return np.empty(xyz.shape[:2], dtype=np.float32)


# ---------------------------------------------------------------------------- public API


def median_prefilter(
    xyz: PointsLike, *, window: int = 3, wrap: bool | None = None
) -> NDArray[np.float64]:
    """Invalid-aware median filter of the range, keeping every point on its ray (sec. III-B-1).

    The median is taken over the *range* (distance to the sensor) of the valid pixels in the
    ``window x window`` neighbourhood, and each point is moved along its own ray to that range:
    ``P' = P * median_range / |P|``. Moving along the ray keeps the pixel's viewing direction
    (the image geometry) exact for any sensor model. Invalid pixels neither spread nor pull
    values: an invalid pixel stays invalid and is left out of its neighbours' medians, and a
    valid pixel stays valid. With an even number of valid samples the lower median is used, so
    the new range is always one that was measured (no points invented between two surfaces).

    Parameters
    ----------
    xyz : (H, W, 3) float32/float64 array or RangeImage, metres
        Organised points; NaN/Inf or ``(0, 0, 0)`` mark invalid pixels.
    window : {3, 5}
        Filter window size in pixels.
    wrap : bool, optional
        Wrap columns around (full-turn equirectangular images). Default: ``RangeImage.wraps``
        for a range image, False for an array.

    Returns
    -------
    (H, W, 3) float64 (float32 for float32 points), metres
        Filtered points, NaN where invalid.

    Examples
    --------
    >>> P = np.zeros((1, 5, 3))
    >>> P[0, :, 2] = [1.0, 1.1, 9.0, 1.2, 1.0]   # a spike in the middle
    >>> median_prefilter(P, window=3)[0, :, 2].tolist()
    [1.0, 1.1, 1.2, 1.2, 1.0]
    """
    if isinstance(window, bool) or window not in (3, 5):
        raise ConfigError(f"median window must be 3 or 5 pixels, got {window!r}")
    pts, w = _points(xyz, wrap)
    rng = np.empty(pts.shape[:2], dtype=np.float64)
    range_kernel(pts, rng)
    out = np.empty(pts.shape, dtype=pts.dtype)  # float32 points stay float32 (half the memory)
    median_kernel(pts, rng, (int(window) - 1) // 2, w, out)
    return out


def flexion(
    xyz: PointsLike, *, n: int = 3, wrap: bool | None = None, median: int = 0
) -> NDArray[np.float32]:
    """Flexion n x n image (paper eq. 11-13).

    With ``k = (n - 1) / 2`` and ``P`` the point of a pixel::

        n1 = unit(P[i, j-k] - P[i, j+k])     x unit(P[i-k, j] - P[i+k, j])      (eq. 11)
        n2 = unit(P[i-k, j-k] - P[i+k, j+k]) x unit(P[i-k, j+k] - P[i+k, j-k])  (eq. 12)
        F  = |n1 . n2|                                                           (eq. 13)

    The normals are *not* re-normalised, so ``F`` also shrinks where the neighbours' directions
    are far from perpendicular (grazing surfaces); ``F`` is in ``[0, 1]``. A plane facing the
    sensor gives 1, a crease or depth edge gives a low value.

    Parameters
    ----------
    xyz : (H, W, 3) float32/float64 array or RangeImage, metres
        Organised points; NaN/Inf or ``(0, 0, 0)`` mark invalid pixels.
    n : int
        Odd grid size 3, 5, 7, ... (neighbours at pixel offset ``(n - 1) / 2``).
    wrap : bool, optional
        Wrap columns around (full-turn equirectangular images). Default: ``RangeImage.wraps``
        for a range image, False for an array.
    median : {0, 3, 5}
        Median pre-filter window (0: none), see :func:`median_prefilter`.

    Returns
    -------
    (H, W) float32
        Flexion in ``[0, 1]``; NaN where the pixel or one of its 8 neighbours is invalid, at
        the border (rows always, columns unless ``wrap``), or where a normal is undefined.
    """
    pts, k, w = _prepared(xyz, n, median, wrap)
    out = _empty(pts)
    flexion_kernel(pts, k, w, 0, _block(pts, k), out)
    return out


def flexion_normalized(
    xyz: PointsLike, *, n: int = 3, wrap: bool | None = None, median: int = 0
) -> NDArray[np.float32]:
    """Flexion with normalised normals: ``|n1 . n2| / (|n1| |n2|)`` (paper sec. III-B-4).

    The cosine of the angle between the two normals of eq. 11-12, so the grazing-angle shading
    of :func:`flexion` disappears. Parameters and invalid handling as in :func:`flexion`.

    Returns
    -------
    (H, W) float32 in ``[0, 1]``, NaN where invalid.
    """
    pts, k, w = _prepared(xyz, n, median, wrap)
    out = _empty(pts)
    flexion_kernel(pts, k, w, 1, _block(pts, k), out)
    return out


def flexion_angle(
    xyz: PointsLike, *, n: int = 3, wrap: bool | None = None, median: int = 0
) -> NDArray[np.float32]:
    """Flexion angle image (paper eq. 14): ``1 - arccos(n1 . n2 / (|n1| |n2|)) / pi``.

    1 where the two normals of eq. 11-12 agree (flat surface), 0.5 where they are
    perpendicular. Parameters and invalid handling as in :func:`flexion`.

    Returns
    -------
    (H, W) float32 in ``[0, 1]``, NaN where invalid.
    """
    pts, k, w = _prepared(xyz, n, median, wrap)
    out = _empty(pts)
    flexion_kernel(pts, k, w, 2, _block(pts, k), out)
    return out


def bearing_angle(
    xyz: PointsLike,
    direction: BearingDirection = "horizontal",
    *,
    n: int = 3,
    wrap: bool | None = None,
    median: int = 0,
) -> NDArray[np.float32]:
    """Bearing Angle image (paper eq. 9, Harati's definition).

    ``beta = arccos(P . (P - Q) / (|P| |P - Q|))``: the angle at ``P`` between the ray to the
    sensor and the line to its "previous" neighbour ``Q``.

    Parameters
    ----------
    xyz : (H, W, 3) float32/float64 array or RangeImage, metres
    direction : {"horizontal", "vertical", "diagonal", "antidiagonal"}
        ``Q`` is the left, upper, upper-left or lower-left neighbour.
    n : int
        Odd grid size; ``Q`` is ``(n - 1) / 2`` pixels away (3: the adjacent pixel, the paper's
        definition).
    wrap, median
        As in :func:`flexion`.

    Returns
    -------
    (H, W) float32, radians in ``[0, pi]``
        NaN where ``P`` or ``Q`` is invalid or outside the image. Quantise with
        ``quantize(beta, bits, value_range=(0, pi))`` for eq. 10.
    """
    if direction not in BEARING_DIRECTIONS:
        raise ConfigError(
            f"unknown bearing direction {direction!r}; known: {', '.join(BEARING_DIRECTIONS)}"
        )
    pts, k, w = _prepared(xyz, n, median, wrap)
    di, dj = BEARING_DIRECTIONS[direction]
    out = _empty(pts)
    bearing_kernel(pts, di * k, dj * k, w, out)
    return out


def range_values(
    xyz: PointsLike, *, median: int = 0, wrap: bool | None = None
) -> NDArray[np.float32]:
    """Range image: Euclidean distance of every point to the sensor (paper eq. 4).

    Returns
    -------
    (H, W) float32, metres; NaN where invalid.
    """
    pts, _, _ = _prepared(xyz, 3, median, wrap)
    out = _empty(pts)
    range_kernel(pts, out)
    return out


def curvature(
    xyz: PointsLike,
    kind: CurvatureKind = "mean",
    *,
    n: int = 3,
    wrap: bool | None = None,
    median: int = 0,
) -> NDArray[np.float32]:
    """Pixel-wise surface curvature, the classical baseline of the paper's Fig. 5.

    The grid is read as a parametric surface ``P(u, v)`` sampled every ``k = (n - 1) / 2``
    pixels; central differences give ``P_u, P_v, P_uu, P_vv, P_uv`` from the same 9 points as
    Flexion n x n, and the fundamental forms give

    * Gaussian ``K = (L N - M^2) / (E G - F^2)`` (1/m^2),
    * mean ``H = (E N - 2 F M + G L) / (2 (E G - F^2))`` (1/m),
    * max: the principal curvature ``H +- sqrt(H^2 - K)`` of largest magnitude (1/m).

    The normal is oriented away from the sensor, so a surface bulging towards the sensor (a
    ball seen from outside) has positive ``H``.

    Parameters
    ----------
    xyz : (H, W, 3) float32/float64 array or RangeImage, metres
    kind : {"gaussian", "mean", "max"}
    n, wrap, median
        As in :func:`flexion`.

    Returns
    -------
    (H, W) float32; NaN where invalid or degenerate.
    """
    if kind not in _CURVATURE_MODES:
        raise ConfigError(f"unknown curvature {kind!r}; known: {', '.join(CURVATURE_KINDS)}")
    pts, k, w = _prepared(xyz, n, median, wrap)
    out = _empty(pts)
    curvature_kernel(pts, k, w, _CURVATURE_MODES[kind], out)
    return out


def convert(
    data: PointsLike,
    kind: str,
    *,
    n: int = 3,
    median: int = 0,
    wrap: bool | None = None,
) -> NDArray[np.float32]:
    """The one call: any conversion of :data:`KINDS` on an organised point grid.

    Parameters
    ----------
    data : (H, W, 3) float32/float64 array or RangeImage, metres
        Organised points; NaN/Inf or ``(0, 0, 0)`` mark invalid pixels (for a RangeImage its
        ``valid`` mask too).
    kind : str
        One of :data:`KINDS` (see the module table).
    n : int
        Odd grid size, neighbours at pixel offset ``(n - 1) / 2`` (Flexion n x n).
    median : {0, 3, 5}
        Median pre-filter window on the range (0: off), see :func:`median_prefilter`.
    wrap : bool, optional
        Wrap columns around. Default: ``RangeImage.wraps`` (full-turn equirectangular image),
        False for a plain array.

    Returns
    -------
    (H, W) float32
        NaN where invalid. Units per kind: Flexion variants in ``[0, 1]``, Bearing Angles in
        radians, range in metres, curvatures in 1/m (1/m^2 for Gaussian).
        :func:`value_range` gives the range :func:`quantize` should map to.

    Examples
    --------
    >>> v, u = np.mgrid[0:3, 0:4].astype(float)
    >>> P = np.stack([u, v, np.full_like(u, 2.0)], axis=-1)   # plane 2 m away, 1 m spacing
    >>> beta = convert(P, "bearing-horizontal").astype(float)
    >>> np.degrees(beta[1, 1:3]).round(1).tolist()
    [65.9, 48.2]
    """
    if median not in (0, 3, 5) or isinstance(median, bool):
        raise ConfigError(f"median must be 0 (off), 3 or 5, got {median!r}")
    if kind in _FLEXION_MODES:
        pts, k, w = _prepared(data, n, median, wrap)
        out = _empty(pts)
        flexion_kernel(pts, k, w, _FLEXION_MODES[kind], _block(pts, k), out)
        return out
    if kind.startswith("bearing-"):
        return bearing_angle(data, kind[len("bearing-") :], n=n, wrap=wrap, median=median)  # type: ignore[arg-type]
    if kind.startswith("curvature-"):
        return curvature(data, kind[len("curvature-") :], n=n, wrap=wrap, median=median)  # type: ignore[arg-type]
    if kind == "range":
        _offset(n)
        return range_values(data, median=median, wrap=wrap)
    raise ConfigError(f"unknown conversion {kind!r}; known: {', '.join(KINDS)}")


def value_range(kind: str, image: NDArray[np.floating] | None = None) -> tuple[float, float]:
    """The value interval :func:`quantize` maps to ``[0, 2^b - 1]`` for a kind.

    Flexion variants: ``(0, 1)`` (eq. 13 scaled "analogous to eq. 10"); Bearing Angles:
    ``(0, pi)`` (eq. 10). Range and curvatures have no natural bound, so they need ``image``:
    range ``(0, max)``, curvatures symmetric ``(-c, c)`` with ``c`` the 99th percentile of
    ``|value|`` (a few extreme pixels at depth edges would otherwise flatten everything).
    """
    if kind in _FLEXION_MODES:
        return (0.0, 1.0)
    if kind.startswith("bearing-") and kind[len("bearing-") :] in BEARING_DIRECTIONS:
        return (0.0, math.pi)
    if kind == "range" or (kind.startswith("curvature-") and kind[10:] in _CURVATURE_MODES):
        if image is None:
            raise ConfigError(f"the value range of {kind!r} depends on the image; pass it")
        v = np.asarray(image, dtype=np.float64)
        v = v[np.isfinite(v)]
        if v.size == 0:
            return (0.0, 1.0)
        if kind == "range":
            hi = float(v.max())
            return (0.0, hi if hi > 0 else 1.0)
        c = float(np.percentile(np.abs(v), 99.0))
        return (-c, c) if c > 0 else (-1.0, 1.0)
    raise ConfigError(f"unknown conversion {kind!r}; known: {', '.join(KINDS)}")


def quantize(
    image: ArrayLike,
    bits: int = 8,
    *,
    value_range: tuple[float, float] = (0.0, 1.0),
    stretch: Stretch | None = None,
    percentiles: Sequence[float] = (1.0, 99.0),
    clahe_clip: float = 2.0,
    clahe_tiles: tuple[int, int] = (8, 8),
) -> tuple[NDArray[np.unsignedinteger], NDArray[np.bool_]]:
    """Quantise a float image to 8 or 16 bit (paper eq. 10), optionally contrast-stretched.

    ``g = round((2^b - 1) (value - lo) / (hi - lo))``, saturated to ``[0, 2^b - 1]``, with
    ``(lo, hi) = value_range``. For a Bearing Angle pass ``value_range=(0, pi)``: this is eq. 10
    with rounding instead of the floor (as the authors' implementation does), which halves the
    worst-case error. Invalid (NaN/Inf) pixels become 0 and are reported in the mask.

    Extensions for feature detection (not in the paper):

    * ``stretch="percentile"``: ``(lo, hi)`` are the given percentiles of the valid values
      instead of ``value_range`` (a linear contrast stretch).
    * ``stretch="clahe"``: after quantising with ``value_range``, OpenCV's contrast-limited
      adaptive histogram equalisation (``clahe_clip``, ``clahe_tiles``); invalid pixels are
      filled with the median valid grey value for the equalisation and zeroed afterwards.

    Parameters
    ----------
    image : (H, W) float
    bits : {8, 16}
    value_range : (float, float)
        Values mapped to 0 and ``2^b - 1``.
    stretch : {None, "percentile", "clahe"}
    percentiles : (float, float)
        Lower and upper percentile for ``stretch="percentile"``.
    clahe_clip : float
        CLAHE clip limit.
    clahe_tiles : (int, int)
        CLAHE tile grid (columns, rows).

    Returns
    -------
    image : (H, W) uint8 or uint16
    valid : (H, W) bool

    Examples
    --------
    >>> q, ok = quantize(np.array([[0.0, 0.25, 1.0, 1.5, np.nan]]), 8)
    >>> q.tolist(), ok.tolist()
    ([[0, 64, 255, 255, 0]], [[True, True, True, True, False]])
    """
    if bits not in (8, 16) or isinstance(bits, bool):
        raise ConfigError(f"bits must be 8 or 16, got {bits!r}")
    img = np.asarray(image)
    if img.ndim != 2:
        raise InputError("image", f"must be a 2D (H, W) array, got shape {img.shape}")
    lo, hi = (float(value_range[0]), float(value_range[1]))
    if stretch == "percentile":
        valid = np.isfinite(img)
        v = img[valid]
        if v.size:
            p_lo, p_hi = (float(p) for p in percentiles)
            if not 0.0 <= p_lo < p_hi <= 100.0:
                raise ConfigError(
                    f"percentiles must satisfy 0 <= low < high <= 100, got {percentiles}"
                )
            lo, hi = (float(x) for x in np.percentile(v, [p_lo, p_hi]))
            if not hi > lo:
                hi = lo + 1.0
    elif stretch not in (None, "clahe"):
        raise ConfigError(f"stretch must be None, 'percentile' or 'clahe', got {stretch!r}")
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ConfigError(f"value_range must be finite and increasing, got {(lo, hi)}")
    top = float(2**bits - 1)
    dtype = np.uint8 if bits == 8 else np.uint16
    out: NDArray[np.unsignedinteger]
    if img.dtype in (np.float32, np.float64):  # one compiled pass, the same arithmetic
        out = np.empty(img.shape, dtype=dtype)
        valid = np.empty(img.shape, dtype=np.bool_)
        quantize_kernel(img, lo, top / (hi - lo), top, out, valid)
    else:
        valid = np.isfinite(img)
        with np.errstate(invalid="ignore"):
            g = (img.astype(np.float64) - lo) * (top / (hi - lo))
            g = np.rint(np.clip(np.where(valid, g, 0.0), 0.0, top))
        out = g.astype(dtype)
    if stretch == "clahe":
        import cv2

        if valid.any():
            fill = np.median(out[valid])
            tmp = np.where(valid, out, fill).astype(dtype)
            tx, ty = (int(t) for t in clahe_tiles)
            clahe = cv2.createCLAHE(clipLimit=float(clahe_clip), tileGridSize=(tx, ty))
            out = np.asarray(clahe.apply(tmp), dtype=dtype)
            out[~valid] = 0
    return out, valid


def feature_image(
    image: RangeImage,
    *,
    kind: str = "flexion",
    n: int = 5,
    median: int = 3,
    stretch: Stretch | None = None,
    fill_holes: bool = False,
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image keypoints are detected on, and its valid mask: :func:`convert` then
    :func:`quantize` (paper eq. 10) with the kind's :func:`value_range`.

    Parameters
    ----------
    image : RangeImage
    kind : str
        One of :data:`KINDS`, or ``"intensity"``: the scan's intensity, its 1st to 99th
        percentile mapped to 0..255.
    n : int
        Odd grid size of the conversion (Flexion n x n).
    median : {0, 3, 5}
        Median pre-filter window on the range (0: off).
    stretch : {None, "percentile", "clahe"}
        Contrast normalisation (see :func:`quantize`).
    fill_holes : bool
        Fill isolated no-return pixels first (:func:`flexreg.stages.projection.fill_holes`).

    Returns
    -------
    image : (H, W) uint8
    valid : (H, W) bool
        Pixels with a defined value.

    Raises
    ------
    RegistrationError
        ``kind="intensity"`` on a scan without intensity.
    """
    img = fill_image_holes(image) if fill_holes else image
    if kind == "intensity":
        if img.intensity is None:
            raise RegistrationError("the scan has no intensity for an intensity feature image")
        val = img.intensity.astype(np.float64)
        lo, hi = np.nanpercentile(val, [1, 99])
        f = ((val - lo) / max(hi - lo, 1e-12)).astype(np.float32)
        f[~img.valid] = np.nan
        vrange: tuple[float, float] = (0, 1)
    else:
        f = convert(img, kind, n=n, median=median)
        vrange = value_range(kind, f)
    q, valid = quantize(f, bits=8, value_range=vrange, stretch=stretch)  # valid: finite f
    return np.asarray(q, dtype=np.uint8), np.asarray(valid, dtype=bool)
