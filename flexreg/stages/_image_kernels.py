"""Compiled kernels of the depth conversions (:mod:`flexreg.stages.feature_images`).

Flexion (paper eq. 11-14), Bearing Angles (eq. 9), range, curvatures and the median
pre-filter of the range, each over an organised (H, W, 3) point grid; parallel over rows,
every pixel independent of the thread count. Called only through the functions of
:mod:`flexreg.stages.feature_images`, which validate the arguments.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from flexreg.core.grid import wrap_col


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
def flexion_kernel(xyz, k, wrap, mode, block, out):  # pragma: no cover
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
def bearing_kernel(xyz, di, dj, wrap, out):  # pragma: no cover
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
def range_kernel(xyz, out):  # pragma: no cover
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
def curvature_kernel(xyz, k, wrap, mode, out):  # pragma: no cover
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
def median_kernel(xyz, rng, half, wrap, out):  # pragma: no cover
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


@numba.njit(cache=True, nogil=True)
def quantize_kernel(img, lo, scale, top, out, valid):  # pragma: no cover - compiled
    """``out = rint(clip((img - lo) * scale, 0, top))`` where ``img`` is finite (float64
    arithmetic, as numpy evaluates it), 0 elsewhere, and ``valid`` the finite pixels: the
    quantisation of :func:`~flexreg.stages.feature_images.quantize` in one pass."""
    for i in range(img.shape[0]):
        for j in range(img.shape[1]):
            v = np.float64(img[i, j])
            ok = math.isfinite(v)
            valid[i, j] = ok
            g = 0.0
            if ok:
                g = (v - lo) * scale
                if g < 0.0:
                    g = 0.0
                elif g > top:
                    g = top
                g = np.rint(g)
            out[i, j] = g
