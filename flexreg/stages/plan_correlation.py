"""Correlation of plan rasters: the arithmetic of :mod:`flexreg.stages.priors`' overlays.

A plan is a list of cells (their centres ``xy`` in metres, or integer ``cells``) with a value
each (metres of vertical surface). The overlays of two plans are the peaks of their
cross-correlation over yaw and offset: over every offset at once by FFT products of rasters
(:func:`rotated_rasters`, :func:`correlation`, :func:`top_local_maxima`), or over a few
offsets about a seed by sums over the source's cells (:func:`window_scores`,
:class:`Offsets`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import fft, ndimage


def raster(
    cells: NDArray[np.int64], vals: NDArray[np.float64], shape: tuple[int, int], off: int
) -> NDArray[np.float64]:
    """``shape`` float64 raster of the plan ``cells`` (N, 2) int64 ``(ix, iy)`` with their
    values summed, cell ``(ix, iy)`` at ``[iy + off, ix + off]``."""
    lin = (cells[:, 1] + off) * shape[1] + (cells[:, 0] + off)
    img = np.bincount(lin, weights=vals, minlength=shape[0] * shape[1])
    return np.asarray(img, dtype=np.float64).reshape(shape)


@numba.njit(cache=True, nogil=True, inline="always")
def _turned_cell(x0, y0, cy, sy, tx, ty, cell):  # pragma: no cover - compiled
    """The cell ``(ix, iy)`` of ``cell`` metres of the point ``(x0, y0)`` turned by the yaw
    of cosine ``cy`` and sine ``sy`` about the scanner and shifted by ``(tx, ty)``."""
    x = x0 * cy - y0 * sy + tx
    y = x0 * sy + y0 * cy + ty
    return np.int64(math.floor(x / cell + 0.5)), np.int64(math.floor(y / cell + 0.5))


@numba.njit(cache=True, nogil=True)
def rotated_rasters(xy, values, yaws, tx, ty, cell, off, size, bound):  # pragma: no cover
    """(len(yaws), size, size) float32 rasters of the plan cells ``xy`` rotated by each yaw
    about the scanner and shifted by ``(tx, ty)``, then rounded to cells of ``cell`` metres
    (cell ``(ix, iy)`` at ``[iy + off, ix + off]``, as :func:`raster`); cells beyond ``bound``
    in x or y are left out when ``bound >= 0``."""
    out = np.empty((yaws.shape[0], size, size), dtype=np.float32)
    acc = np.empty((size, size))
    for k in range(yaws.shape[0]):
        acc[:] = 0.0
        cy = math.cos(yaws[k])
        sy = math.sin(yaws[k])
        for i in range(xy.shape[0]):
            ix, iy = _turned_cell(xy[i, 0], xy[i, 1], cy, sy, tx, ty, cell)
            if bound >= 0 and (abs(ix) > bound or abs(iy) > bound):
                continue
            acc[iy + off, ix + off] += values[i]
        for r in range(size):
            for c in range(size):
                out[k, r, c] = acc[r, c]
    return out


def correlation(S: NDArray[Any], FT: Any, shape: tuple[int, int]) -> NDArray[Any]:
    """``corr[d] = sum_x T[x] S[x + d]`` (circular) of each raster in ``S`` (..., H, W), given
    ``FT = conj(rfft2(T))``: source raster position ``x + d`` lies on target position ``x``."""
    return np.asarray(fft.irfft2(fft.rfft2(S, axes=(-2, -1)) * FT, s=shape, axes=(-2, -1)))


def top_local_maxima(corr: NDArray[Any], sep: int, k: int) -> NDArray[np.int64]:
    """Flat indices of the ``k`` highest positive local maxima of ``corr`` (H, W): cells
    not below any cell of the ``sep`` x ``sep`` square about them (the image wraps), highest
    first, ties in index order. Only the highest cells are examined, as many as it takes:
    the same cells as comparing the whole image with its maximum filter, without filtering
    all of it.

    >>> c = np.zeros((6, 6)); c[1, 1], c[1, 2], c[4, 4] = 3.0, 2.0, 1.0
    >>> top_local_maxima(c, 3, 5).tolist()
    [7, 28]
    """
    flat_corr = corr.ravel()
    m = min(flat_corr.size, max(64, 16 * k))
    while True:
        if m >= flat_corr.size:
            top = (corr == ndimage.maximum_filter(corr, size=sep, mode="wrap")) & (corr > 0)
            cand = np.flatnonzero(top)
            return cand[np.argsort(-flat_corr[cand], kind="stable")][:k]
        floor = np.partition(flat_corr, flat_corr.size - m)[flat_corr.size - m]
        cand = np.flatnonzero((flat_corr >= floor) & (flat_corr > 0))
        if len(cand) == 0:
            return cand.astype(np.int64)
        cand = cand[np.argsort(-flat_corr[cand], kind="stable")]
        H, W = corr.shape
        d = np.arange(-(sep // 2), sep // 2 + 1)
        iy, ix = np.divmod(cand, W)
        rows, cols = (iy[:, None] + d) % H, (ix[:, None] + d) % W
        square = corr[rows[:, :, None], cols[:, None, :]].reshape(len(cand), -1).max(axis=1)
        found = cand[flat_corr[cand] >= square]
        if len(found) >= k or floor <= 0:  # or every positive cell examined
            return found[:k].astype(np.int64)
        m *= 4


@numba.njit(cache=True, nogil=True)
def window_scores(xy, values, yaws, tx, ty, cell, T, off, w, bound):  # pragma: no cover
    """(len(yaws), 2w + 1, 2w + 1) correlations of the plan cells ``xy`` turned by each yaw
    about the scanner, shifted by ``(tx, ty)`` and rounded to cells of ``cell`` metres (as
    :func:`rotated_rasters`, cells beyond ``bound`` left out), with the raster ``T`` (the
    target's cell ``(ix, iy)`` at ``[iy + off, ix + off]``) at offsets ``d`` in ``[-w, w]^2``:
    ``[k, iy, ix]`` is ``sum_i values_i T[cell_i - d]``, ``d = (ix - w, iy - w)``."""
    n = 2 * w + 1
    out = np.zeros((yaws.shape[0], n, n))
    for k in range(yaws.shape[0]):
        cy = math.cos(yaws[k])
        sy = math.sin(yaws[k])
        for i in range(xy.shape[0]):
            ix, iy = _turned_cell(xy[i, 0], xy[i, 1], cy, sy, tx, ty, cell)
            if abs(ix) > bound or abs(iy) > bound:
                continue
            v = values[i]
            for a in range(n):
                row = iy + off + w - a
                for b in range(n):
                    out[k, a, b] += v * T[row, ix + off + w - b]
    return out


@dataclass(frozen=True, eq=False)
class Offsets:
    """The target's plan, blurred and transformed once, for correlations with the source's
    plan turned by several yaws and shifted to a seed offset: the scores of every offset
    within ``w`` cells of the seed (:meth:`near`)."""

    cell_m: float
    rt: int
    w: int
    n: int
    T: NDArray[np.float32]

    @cached_property
    def FT(self) -> Any:
        """``conj(rfft2(T))``: made when an FFT product is first asked for (the windows
        summed cell by cell do not need it)."""
        return np.conj(fft.rfft2(self.T))

    @classmethod
    def of(
        cls, cells: NDArray[np.int64], values: NDArray[np.float64], cell_m: float, shift_m: float
    ) -> Offsets:
        """Of the target's plan: its ``cells`` (N, 2) int64 and their ``values`` (N,), at
        ``cell_m`` metres; offsets within ``shift_m`` metres."""
        c = cell_m
        rt = int(np.abs(cells).max()) + 1
        w = math.ceil(shift_m / c) + 1
        n = fft.next_fast_len(2 * (rt + w) + 1, real=True)
        T = ndimage.gaussian_filter(raster(cells, values, (n, n), rt + w), 1.0)
        return cls(c, rt, w, n, T.astype(np.float32))

    def near(
        self,
        xy: NDArray[np.float64],
        values: NDArray[np.float64],
        t0: NDArray[np.float64],
        yaws: NDArray[np.float64],
    ) -> NDArray[Any]:
        """``(len(yaws), 2w + 1, 2w + 1)`` correlations of the source's plan (its cells'
        centres ``xy`` (N, 2) metres and ``values`` (N,)) turned by each yaw and
        shifted by ``t0``, at offsets ``d`` in ``[-w, w]^2`` cells (``[iy, ix]`` is
        ``d = (ix - w, iy - w)``: the source at ``x + d`` lies on the target at ``x``).

        Summed cell by cell over the offsets asked for (:func:`window_scores`) when that
        is less work than the FFT products over the whole plan (eight yaws per batch),
        which it is for the refinement's few tenths of a metre; the window of a rough
        position's metres takes the FFT."""
        per_yaw_direct = len(xy) * (2 * self.w + 1) ** 2
        per_yaw_fft = 2 * self.n * self.n * math.log2(self.n)
        if per_yaw_direct < per_yaw_fft:
            return window_scores(
                np.ascontiguousarray(xy, dtype=np.float64),
                np.ascontiguousarray(values, dtype=np.float64),
                np.ascontiguousarray(yaws, dtype=np.float64),
                float(t0[0]),
                float(t0[1]),
                float(self.cell_m),
                self.T,
                self.rt + self.w,
                self.w,
                self.rt,
            )
        near = np.arange(-self.w, self.w + 1) % self.n
        out = []
        for b0 in range(0, len(yaws), 8):
            rasters = rotated_rasters(
                xy,
                values,
                np.ascontiguousarray(yaws[b0 : b0 + 8], dtype=np.float64),
                float(t0[0]),
                float(t0[1]),
                float(self.cell_m),
                self.rt + self.w,
                self.n,
                self.rt,
            )
            out += [
                corr[np.ix_(near, near)] for corr in correlation(rasters, self.FT, (self.n,) * 2)
            ]
        return np.stack(out)
