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
from typing import TYPE_CHECKING, Literal, Union

import numba
import numpy as np
from numba import prange
from numpy.typing import ArrayLike, NDArray

from flexreg.core.grid import wrap_col
from flexreg.errors import ConfigError, InputError

if TYPE_CHECKING:
    from flexreg.core.range_image import RangeImage

__all__ = [
    "BEARING_DIRECTIONS",
    "CURVATURE_KINDS",
    "KINDS",
    "bearing_angle",
    "convert",
    "curvature",
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


# ---------------------------------------------------------------------------- numba kernels


@numba.njit(cache=True, nogil=True, inline="always")
def _ok(x: float, y: float, z: float) -> bool:  # pragma: no cover - compiled
    """A point is valid if finite and not the origin (a zero depth is no return)."""
    return (
        math.isfinite(x)
        and math.isfinite(y)
        and math.isfinite(z)
        and (x != 0.0 or y != 0.0 or z != 0.0)
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _soa_row(xyz, i, k, wrap, B, s):  # pragma: no cover
    """Copy image row ``i`` into slot ``s`` of the ring buffer ``B`` (m, 3, W + 2k) as float64
    x / y / z planes, invalid points as NaN, with ``k`` padding columns on each side holding
    the other end of the row (``wrap``) or NaN."""
    W = xyz.shape[1]
    X = B[s, 0]
    Y = B[s, 1]
    Z = B[s, 2]
    for j in range(W):
        x = np.float64(xyz[i, j, 0])
        y = np.float64(xyz[i, j, 1])
        z = np.float64(xyz[i, j, 2])
        # finite (x - x is NaN for NaN and Inf) and not the origin; no branches, so it vectorises
        ok = (
            (x - x == 0.0)
            & (y - y == 0.0)
            & (z - z == 0.0)
            & ((x != 0.0) | (y != 0.0) | (z != 0.0))
        )
        X[j + k] = x if ok else np.nan
        Y[j + k] = y if ok else np.nan
        Z[j + k] = z if ok else np.nan
    for p in range(k):
        left = p  # buffer column of image column p - k
        right = W + k + p  # buffer column of image column W + p
        if wrap:
            X[left] = X[(p - k) % W + k]
            Y[left] = Y[(p - k) % W + k]
            Z[left] = Z[(p - k) % W + k]
            X[right] = X[p % W + k]
            Y[right] = Y[p % W + k]
            Z[right] = Z[p % W + k]
        else:
            X[left] = Y[left] = Z[left] = np.nan
            X[right] = Y[right] = Z[right] = np.nan


@numba.njit(cache=True, nogil=True, inline="always")
def _flexion_row(B, s0, s1, s2, k, mode, out, i):  # pragma: no cover
    """Flexion variant ``mode`` of one image row from the ring-buffer rows i-k, i, i+k.

    mode 0: eq. 13; 1: normalised normals; 2: eq. 14. NaN propagates from any invalid
    neighbour; the centre is folded into the denominator so that it does too.
    """
    W = out.shape[1]
    X0 = B[s0, 0]
    Y0 = B[s0, 1]
    Z0 = B[s0, 2]
    X1 = B[s1, 0]
    Y1 = B[s1, 1]
    Z1 = B[s1, 2]
    X2 = B[s2, 0]
    Y2 = B[s2, 1]
    Z2 = B[s2, 2]
    for j in range(W):
        c = j + k  # buffer column of image column j
        cl = j  # ... of j - k
        cr = j + 2 * k  # ... of j + k
        # eq. 11: h = P[i, j-k] - P[i, j+k], v = P[i-k, j] - P[i+k, j]
        hx = X1[cl] - X1[cr]
        hy = Y1[cl] - Y1[cr]
        hz = Z1[cl] - Z1[cr]
        vx = X0[c] - X2[c]
        vy = Y0[c] - Y2[c]
        vz = Z0[c] - Z2[c]
        # eq. 12: e = P[i-k, j-k] - P[i+k, j+k], f = P[i-k, j+k] - P[i+k, j-k]
        ex = X0[cl] - X2[cr]
        ey = Y0[cl] - Y2[cr]
        ez = Z0[cl] - Z2[cr]
        fx = X0[cr] - X2[cl]
        fy = Y0[cr] - Y2[cl]
        fz = Z0[cr] - Z2[cl]
        n1x = hy * vz - hz * vy
        n1y = hz * vx - hx * vz
        n1z = hx * vy - hy * vx
        n2x = ey * fz - ez * fy
        n2y = ez * fx - ex * fz
        n2z = ex * fy - ey * fx
        dot = n1x * n2x + n1y * n2y + n1z * n2z
        if mode == 0:
            # the four unit factors of eq. 11-12 applied together: one sqrt, one division
            den = (hx * hx + hy * hy + hz * hz) * (vx * vx + vy * vy + vz * vz)
            den *= (ex * ex + ey * ey + ez * ez) * (fx * fx + fy * fy + fz * fz)
        else:
            den = (n1x * n1x + n1y * n1y + n1z * n1z) * (n2x * n2x + n2y * n2y + n2z * n2z)
        den += 0.0 * (X1[c] + Y1[c] + Z1[c])  # NaN if the pixel itself has no point
        q = dot / math.sqrt(den)
        if mode == 2:
            q = -1.0 if q < -1.0 else (1.0 if q > 1.0 else q)
            q = 1.0 - math.acos(q) / math.pi  # eq. 14
        else:
            q = abs(q)  # eq. 13
            q = 1.0 if q > 1.0 else q  # rounding; NaN stays NaN
        # den == 0: coincident neighbours or a collinear triplet, no normal; NaN: invalid
        out[i, j] = q if den > 0.0 else np.nan


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _flexion_kernel(xyz, k, wrap, mode, block, out):  # pragma: no cover
    H, W = out.shape
    m = 2 * k + 1
    for i in range(min(k, H)):  # rows without the neighbours above / below
        out[i, :] = np.nan
        out[H - 1 - i, :] = np.nan
    rows = H - 2 * k
    nblocks = (rows + block - 1) // block if rows > 0 else 0
    for b in prange(nblocks):
        # each block of rows keeps a ring buffer of the 2k + 1 rows it needs as float64
        # planes, so every input row is read and checked once per block and the arithmetic
        # below runs on contiguous arrays (SIMD)
        B = np.empty((m, 3, W + 2 * k))
        i0 = k + b * block
        i1 = min(H - k, i0 + block)
        for r in range(i0 - k, i0 + k):
            _soa_row(xyz, r, k, wrap, B, r % m)
        for i in range(i0, i1):
            _soa_row(xyz, i + k, k, wrap, B, (i + k) % m)
            s0 = (i - k) % m
            s1 = i % m
            s2 = (i + k) % m
            # literal modes: each call inlines into a loop without mode branches
            if mode == 0:
                _flexion_row(B, s0, s1, s2, k, 0, out, i)
            elif mode == 1:
                _flexion_row(B, s0, s1, s2, k, 1, out, i)
            else:
                _flexion_row(B, s0, s1, s2, k, 2, out, i)


@numba.njit(cache=True, nogil=True, inline="always")
def _bearing_px(xyz, i, j, ip, jp):  # pragma: no cover
    """Bearing Angle (eq. 9) at P = xyz[i, j] with the previous neighbour Q = xyz[ip, jp]."""
    px = np.float64(xyz[i, j, 0])
    py = np.float64(xyz[i, j, 1])
    pz = np.float64(xyz[i, j, 2])
    qx = np.float64(xyz[ip, jp, 0])
    qy = np.float64(xyz[ip, jp, 1])
    qz = np.float64(xyz[ip, jp, 2])
    if not (_ok(px, py, pz) and _ok(qx, qy, qz)):
        return np.nan
    ex = px - qx
    ey = py - qy
    ez = pz - qz
    den = (px * px + py * py + pz * pz) * (ex * ex + ey * ey + ez * ez)
    if not den > 0.0:
        return np.nan  # P and Q coincide: no direction
    c = (px * ex + py * ey + pz * ez) / math.sqrt(den)
    return math.acos(min(1.0, max(-1.0, c)))


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _bearing_kernel(xyz, di, dj, wrap, out):  # pragma: no cover
    H, W = out.shape
    j0 = max(0, -dj)
    j1 = min(W, W - dj)
    for i in prange(H):
        ip = i + di
        if ip < 0 or ip >= H:
            for j in range(W):
                out[i, j] = np.nan
            continue
        for j in range(j0, j1):
            out[i, j] = _bearing_px(xyz, i, j, ip, j + dj)
        for j in range(W):
            if j0 <= j < j1:
                continue
            jp = wrap_col(j + dj, W, wrap)
            out[i, j] = np.nan if jp < 0 else _bearing_px(xyz, i, j, ip, jp)


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _range_kernel(xyz, out):  # pragma: no cover
    H, W = out.shape
    for i in prange(H):
        for j in range(W):
            x = np.float64(xyz[i, j, 0])
            y = np.float64(xyz[i, j, 1])
            z = np.float64(xyz[i, j, 2])
            if _ok(x, y, z):
                out[i, j] = math.sqrt(x * x + y * y + z * z)
            else:
                out[i, j] = np.nan


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _curvature_kernel(xyz, k, wrap, mode, out):  # pragma: no cover
    H, W = out.shape
    for i in prange(H):
        Q = np.empty((3, 3, 3))  # the 3 x 3 points, one buffer per row
        D = np.empty((5, 3))  # P_u, P_v, P_uu, P_vv, P_uv
        for j in range(W):
            out[i, j] = np.nan
            jl = wrap_col(j - k, W, wrap)
            jr = wrap_col(j + k, W, wrap)
            if i - k < 0 or i + k >= H or jl < 0 or jr < 0:
                continue
            good = True
            for a in range(3):
                ii = i + (a - 1) * k
                for b in range(3):
                    jj = jl if b == 0 else (j if b == 1 else jr)
                    x = np.float64(xyz[ii, jj, 0])
                    y = np.float64(xyz[ii, jj, 1])
                    z = np.float64(xyz[ii, jj, 2])
                    if not _ok(x, y, z):
                        good = False
                    Q[a, b, 0] = x
                    Q[a, b, 1] = y
                    Q[a, b, 2] = z
            if not good:
                continue
            # central differences with the parameter step = k pixels (curvature does not
            # depend on the parameterisation)
            for c in range(3):
                D[0, c] = 0.5 * (Q[1, 2, c] - Q[1, 0, c])
                D[1, c] = 0.5 * (Q[2, 1, c] - Q[0, 1, c])
                D[2, c] = Q[1, 2, c] - 2.0 * Q[1, 1, c] + Q[1, 0, c]
                D[3, c] = Q[2, 1, c] - 2.0 * Q[1, 1, c] + Q[0, 1, c]
                D[4, c] = 0.25 * (Q[2, 2, c] - Q[2, 0, c] - Q[0, 2, c] + Q[0, 0, c])
            pu = D[0]
            pv = D[1]
            puu = D[2]
            pvv = D[3]
            puv = D[4]
            E = pu[0] * pu[0] + pu[1] * pu[1] + pu[2] * pu[2]
            F = pu[0] * pv[0] + pu[1] * pv[1] + pu[2] * pv[2]
            G = pv[0] * pv[0] + pv[1] * pv[1] + pv[2] * pv[2]
            nx = pu[1] * pv[2] - pu[2] * pv[1]
            ny = pu[2] * pv[0] - pu[0] * pv[2]
            nz = pu[0] * pv[1] - pu[1] * pv[0]
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            det = E * G - F * F
            if not (nn > 0.0 and det > 0.0):
                continue
            # unit normal pointing away from the sensor: a ball seen from outside is positive
            if nx * Q[1, 1, 0] + ny * Q[1, 1, 1] + nz * Q[1, 1, 2] < 0.0:
                nn = -nn
            nx /= nn
            ny /= nn
            nz /= nn
            L = puu[0] * nx + puu[1] * ny + puu[2] * nz
            M = puv[0] * nx + puv[1] * ny + puv[2] * nz
            N = pvv[0] * nx + pvv[1] * ny + pvv[2] * nz
            K = (L * N - M * M) / det
            Hm = (E * N - 2.0 * F * M + G * L) / (2.0 * det)
            if mode == 0:
                out[i, j] = K
            elif mode == 1:
                out[i, j] = Hm
            else:
                s = math.sqrt(max(Hm * Hm - K, 0.0))
                out[i, j] = Hm + s if Hm >= 0.0 else Hm - s


@numba.njit(cache=True, nogil=True, inline="always")
def _sort3(a, b, c):  # pragma: no cover
    lo = min(a, b)
    hi = max(a, b)
    return min(lo, c), max(lo, min(hi, c)), max(hi, c)


@numba.njit(cache=True, nogil=True, inline="always")
def _full9(r, i, j):  # pragma: no cover
    """True if the 3x3 window of ranges around (i, j) holds no NaN (invalid) sample."""
    s = r[i - 1, j - 1] + r[i - 1, j] + r[i - 1, j + 1]
    s += r[i, j - 1] + r[i, j] + r[i, j + 1]
    s += r[i + 1, j - 1] + r[i + 1, j] + r[i + 1, j + 1]
    return s == s


@numba.njit(cache=True, nogil=True, inline="always")
def _med9(r, i, j0, j1, j2):  # pragma: no cover
    """Median of a full 3x3 window without branches: sort the columns, then the median is
    med3(max of the minima, med3 of the middles, min of the maxima)."""
    a0, a1, a2 = _sort3(r[i - 1, j0], r[i, j0], r[i + 1, j0])
    b0, b1, b2 = _sort3(r[i - 1, j1], r[i, j1], r[i + 1, j1])
    c0, c1, c2 = _sort3(r[i - 1, j2], r[i, j2], r[i + 1, j2])
    lo = max(a0, max(b0, c0))
    hi = min(a2, min(b2, c2))
    md = _sort3(a1, b1, c1)[1]
    return _sort3(lo, md, hi)[1]


@numba.njit(cache=True, nogil=True, inline="always")
def _median_slow(rng, i, j, half, wrap, buf):  # pragma: no cover
    """Lower median of the valid ranges in the window around (i, j), any window size.

    Selection by counting: the lower median is the sample with at most ``(cnt - 1) // 2``
    samples below it and more than that at or below it. Branch-free inner loops, so it beats
    sorting with unpredictable comparisons for the 25 samples of a 5 x 5 window.
    """
    H, W = rng.shape
    cnt = 0
    for a in range(max(0, i - half), min(H, i + half + 1)):
        for b in range(j - half, j + half + 1):
            bb = wrap_col(b, W, wrap)
            if bb < 0:
                continue
            r = rng[a, bb]
            if r > 0.0:  # invalid (NaN) neighbours do not pull the median
                buf[cnt] = r
                cnt += 1
    target = (cnt - 1) // 2
    med = buf[0]
    for t in range(cnt):
        x = buf[t]
        below = 0
        at_or_below = 0
        for u in range(cnt):
            below += buf[u] < x
            at_or_below += buf[u] <= x
        if below <= target < at_or_below:
            med = x
    # lower median: always one of the measured ranges, never a mix of two surfaces
    return med


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _median_kernel(xyz, rng, half, wrap, out):  # pragma: no cover
    H, W = rng.shape
    m = (2 * half + 1) * (2 * half + 1)
    for i in prange(H):
        buf = np.empty(m)
        inner_row = half == 1 and 0 < i < H - 1
        for j in range(W):
            r0 = rng[i, j]
            if not r0 > 0.0:  # NaN: invalid stays invalid
                out[i, j, 0] = np.nan
                out[i, j, 1] = np.nan
                out[i, j, 2] = np.nan
                continue
            if inner_row and 0 < j < W - 1 and _full9(rng, i, j):
                med = _med9(rng, i, j - 1, j, j + 1)
            else:
                med = _median_slow(rng, i, j, half, wrap, buf)
            s = med / r0
            out[i, j, 0] = np.float64(xyz[i, j, 0]) * s
            out[i, j, 1] = np.float64(xyz[i, j, 1]) * s
            out[i, j, 2] = np.float64(xyz[i, j, 2]) * s


# ---------------------------------------------------------------------------- helpers


def _points(data: PointsLike, wrap: bool | None) -> tuple[NDArray[np.floating], bool]:
    """The (H, W, 3) C-contiguous float32/float64 points of ``data`` and the wrap flag."""
    from flexreg.core.range_image import RangeImage

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
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3 or n % 2 == 0:
        raise ConfigError(f"n must be an odd grid size >= 3 (3, 5, 7, ... 13), got {n!r}")
    return (int(n) - 1) // 2


def _prepared(data: PointsLike, n: int, median: int, wrap: bool | None):
    k = _offset(n)
    xyz, w = _points(data, wrap)
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
    (H, W, 3) float64, metres
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
    _range_kernel(pts, rng)
    out = np.empty(pts.shape, dtype=np.float64)
    _median_kernel(pts, rng, (int(window) - 1) // 2, w, out)
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
    _flexion_kernel(pts, k, w, 0, _block(pts, k), out)
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
    _flexion_kernel(pts, k, w, 1, _block(pts, k), out)
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
    _flexion_kernel(pts, k, w, 2, _block(pts, k), out)
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
    _bearing_kernel(pts, di * k, dj * k, w, out)
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
    _range_kernel(pts, out)
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
    _curvature_kernel(pts, k, w, _CURVATURE_MODES[kind], out)
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
        _flexion_kernel(pts, k, w, _FLEXION_MODES[kind], _block(pts, k), out)
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
    valid = np.isfinite(img)
    lo, hi = (float(value_range[0]), float(value_range[1]))
    if stretch == "percentile":
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
            out = clahe.apply(tmp)
            out[~valid] = 0
    return out, valid
