"""Surface normals of organised scans, from the pixel grid.

Each pixel's normal is the cross product of the central differences to its neighbours at a
pixel offset ``k`` (:func:`normals_area`, compiled, which also gives the surface area the pixel
covers). :func:`surface_normals` returns them per pixel for levelling and plan views
(:mod:`flexreg.stages.priors`); :func:`grid_normals` smooths them over each pixel's 3x3
neighbours of the same surface for the projective refinement
(:mod:`flexreg.stages.refinement.projective`) and the candidate checks.
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np
from numpy.typing import NDArray

from flexreg.core.grid import wrap_col
from flexreg.core.range_image import RangeImage

#: each image's points with NaN where invalid, as the kernels read them (see masked_xyz)
_MASKED: weakref.WeakKeyDictionary[RangeImage, tuple[object, object, NDArray[np.floating]]] = (
    weakref.WeakKeyDictionary()
)


def masked_xyz(image: RangeImage) -> NDArray[np.floating]:
    """``image.xyz`` with NaN at invalid pixels, (H, W, 3) C-contiguous float32 (a float32
    image) or float64, metres.

    The image's own array when it already is (the usual case: every builder leaves invalid
    pixels NaN), else a copy made once per image and shared by every later call (the normals
    and each projective ICP run on the image: candidate polishing runs one per candidate);
    recomputed if the image's arrays are replaced. Treat the result as read-only."""
    hit = _MASKED.get(image)
    if hit is not None and hit[0] is image.xyz and hit[1] is image.valid:
        return hit[2]
    xyz = image.xyz
    usable = xyz.dtype in (np.float32, np.float64) and xyz.flags.c_contiguous
    if not (usable and np.isnan(xyz[~image.valid]).all()):  # else: already NaN where invalid
        xyz = np.ascontiguousarray(np.where(image.valid[..., None], xyz, np.nan))
    _MASKED[image] = (image.xyz, image.valid, xyz)
    return xyz


def surface_normals(
    image: RangeImage, *, k: int = 2, stride: int = 1, compact: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Unit normals of an organised scan from central differences at pixel offset ``k``.

    Parameters
    ----------
    image : RangeImage
    k : int
        Pixel offset of the neighbours (larger is smoother on noisy surfaces).
    stride : int
        Use every ``stride``-th row and column (speed on very large images).
    compact : bool
        Keep only the usable pixels (default). Otherwise every (strided) pixel in row-major
        order, with area 0 (and zero normal) where unusable: no copies of the image, and every
        function here accepts that form.

    Returns
    -------
    points : (M, 3) float64, metres
        The pixels' points (only pixels whose four neighbours are valid and continuous).
    normals : (M, 3) float64
        Unit normals, oriented towards the scanner.
    area : (M,) float64, square metres
        Surface area each pixel covers (product of its neighbour spacings), so that sums over
        pixels measure surface independently of the distance to the scanner.
    """
    xyz = np.ascontiguousarray(image.xyz[::stride, ::stride], dtype=np.float64)
    H, W = xyz.shape[:2]
    if H <= 2 * k or W <= 2 * k:
        z = np.zeros((0, 3))
        return z, z, np.zeros(0)
    nrm, area = normals_area(xyz, int(k), image.wraps)
    if not compact:
        return xyz.reshape(-1, 3), nrm.reshape(-1, 3), area.reshape(-1)
    ok = area > 0
    return xyz[ok], nrm[ok], area[ok]


@numba.njit(cache=True, nogil=True)
def normals_area(xyz, k, wrap):  # pragma: no cover - compiled
    """Per pixel: unit normal (towards the scanner) from the cross product of the central
    differences at offset ``k`` and the area the pixel covers; area 0 where a neighbour is
    missing or lies across a depth jump (a span of 0.2 x the range or more). (H, W, 3) and
    (H, W) float64."""
    H, W = xyz.shape[0], xyz.shape[1]
    nrm = np.zeros((H, W, 3))
    area = np.zeros((H, W))
    _normals_area_into(xyz, k, wrap, nrm, area)
    return nrm, area


@numba.njit(cache=True, nogil=True, inline="always")
def _unit_gap(xyz, i0, j0, i1, j1):  # pragma: no cover - compiled
    """The distance between the unit directions of pixels ``(i0, j0)`` and ``(i1, j1)``: the
    angle (radians, for small ones) their rays span, whatever the surface; NaN where one has
    no point."""
    a = math.sqrt(xyz[i0, j0, 0] ** 2 + xyz[i0, j0, 1] ** 2 + xyz[i0, j0, 2] ** 2)
    b = math.sqrt(xyz[i1, j1, 0] ** 2 + xyz[i1, j1, 1] ** 2 + xyz[i1, j1, 2] ** 2)
    dx = xyz[i1, j1, 0] / b - xyz[i0, j0, 0] / a
    dy = xyz[i1, j1, 1] / b - xyz[i0, j0, 1] / a
    dz = xyz[i1, j1, 2] / b - xyz[i0, j0, 2] / a
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@numba.njit(cache=True, nogil=True, inline="always")
def _beside(j, kc, W, wrap):  # pragma: no cover - compiled
    """The columns ``kc`` left and right of ``j`` (wrapped round a full turn); -1 where one
    falls off the image."""
    jl, jr = j - kc, j + kc
    if wrap:
        return jl % W, jr % W
    if jl < 0 or jr >= W:
        return -1, -1
    return jl, jr


@numba.njit(cache=True, nogil=True)
def _normals_area_into(xyz, k, wrap, nrm, area, balance=False):  # pragma: no cover - compiled
    """:func:`normals_area` written into ``nrm`` (H, W, 3) and ``area`` (H, W), zeroed, of
    any float type. With ``balance`` the column offset doubles (up to ``W // 32``) while the
    row neighbours' rays span less than half the angle of the column neighbours' (near the
    poles of a panorama, where a row is a small circle: its neighbours a pixel apart lie a
    millimetre apart and range noise turns the normal anywhere)."""
    H, W = xyz.shape[0], xyz.shape[1]
    kmax = max(k, W // 32)
    for i in range(k, H - k):
        for j in range(W):
            kc = k
            if balance:
                av = _unit_gap(xyz, i - k, j, i + k, j)
                while 2 * kc <= kmax:
                    jl, jr = _beside(j, kc, W, wrap)
                    if jl < 0 or not (_unit_gap(xyz, i, jl, i, jr) < 0.5 * av):  # NaN: stop
                        break
                    kc *= 2
            jl, jr = _beside(j, kc, W, wrap)
            if jl < 0:
                continue
            x0, y0, z0 = xyz[i, j, 0], xyz[i, j, 1], xyz[i, j, 2]
            hx = xyz[i, jr, 0] - xyz[i, jl, 0]
            hy = xyz[i, jr, 1] - xyz[i, jl, 1]
            hz = xyz[i, jr, 2] - xyz[i, jl, 2]
            vx = xyz[i + k, j, 0] - xyz[i - k, j, 0]
            vy = xyz[i + k, j, 1] - xyz[i - k, j, 1]
            vz = xyz[i + k, j, 2] - xyz[i - k, j, 2]
            nx = hy * vz - hz * vy
            ny = hz * vx - hx * vz
            nz = hx * vy - hy * vx
            r = math.sqrt(x0 * x0 + y0 * y0 + z0 * z0)
            lh = math.sqrt(hx * hx + hy * hy + hz * hz)
            lv = math.sqrt(vx * vx + vy * vy + vz * vz)
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            # continuity: both neighbour spans short compared with the range (no depth jump);
            # every comparison is False for NaN
            if not (lh < 0.2 * r and lv < 0.2 * r and nn > 0.0 and math.isfinite(nn)):
                continue
            if nx * x0 + ny * y0 + nz * z0 > 0.0:
                nn = -nn
            nrm[i, j, 0] = nx / nn
            nrm[i, j, 1] = ny / nn
            nrm[i, j, 2] = nz / nn
            # neighbours 2k x 2kc strided pixels apart: the product covers one cell
            area[i, j] = lh * lv / (4.0 * k * kc)


def grid_normals(image: RangeImage, *, k: int = 1) -> NDArray[np.float32]:
    """Unit surface normals of every pixel of an organised scan, from its grid.

    The cross product of the central differences at pixel offset ``k`` along the rows and the
    columns, averaged with the neighbouring pixels' normals of the same surface (3x3). Pixels
    whose neighbours are missing or lie across a depth jump get NaN. Where a row's
    neighbours' rays span less than half the angle of the column's (above about 60 degrees of
    elevation in a panorama) the row offset doubles until they do not (at most ``W // 32``):
    a ceiling straight above the scanner otherwise gets normals tilted by range noise (a
    third of the points above 80 degrees more than 100 degrees from a neighbouring
    scanner's view of the same ceiling, docs/benchmarks.md).

    Parameters
    ----------
    image : RangeImage
    k : int
        Pixel offset of the differences (larger is smoother on noisy surfaces, but blurs
        edges; 1 was the most accurate for refinement on synthetic and real scans).

    Returns
    -------
    (H, W, 3) float32
        Unit normals, oriented towards the scanner; NaN where unknown.
    """
    H, W = image.valid.shape
    if H <= 2 * k or W <= 2 * k:
        return np.full((H, W, 3), np.nan, dtype=np.float32)
    nrm = np.zeros((H, W, 3), dtype=np.float32)  # float32: the result's own precision
    area = np.zeros((H, W), dtype=np.float32)
    _normals_area_into(masked_xyz(image), int(k), image.wraps, nrm, area, True)
    nrm[~(area > 0)] = np.nan  # in place: no third (H, W, 3) array
    del area
    return _smooth_normals(nrm, image.wraps)


@numba.njit(cache=True, nogil=True)
def _smooth_normals(raw, wrap):  # pragma: no cover - compiled
    """Each unit normal averaged with its 3x3 neighbours' of the same surface (within about
    25 degrees), renormalised; NaN stays NaN."""
    H, W = raw.shape[0], raw.shape[1]
    out = np.full((H, W, 3), np.nan, dtype=np.float32)
    for i in range(H):
        for j in range(W):
            if not math.isfinite(raw[i, j, 0]):
                continue
            sx = sy = sz = 0.0
            for di in range(-1, 2):
                ii = i + di
                if ii < 0 or ii >= H:
                    continue
                for dj in range(-1, 2):
                    jj = wrap_col(j + dj, W, wrap)
                    if jj >= 0 and math.isfinite(raw[ii, jj, 0]):
                        c = (
                            raw[ii, jj, 0] * raw[i, j, 0]
                            + raw[ii, jj, 1] * raw[i, j, 1]
                            + raw[ii, jj, 2] * raw[i, j, 2]
                        )
                        if c > 0.9:  # same surface (within about 25 degrees)
                            sx += raw[ii, jj, 0]
                            sy += raw[ii, jj, 1]
                            sz += raw[ii, jj, 2]
            s = math.sqrt(sx * sx + sy * sy + sz * sz)
            out[i, j, 0] = sx / s
            out[i, j, 1] = sy / s
            out[i, j, 2] = sz / s
    return out


__all__ = ["grid_normals", "masked_xyz", "normals_area", "surface_normals"]
