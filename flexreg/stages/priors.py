"""Levelling and top-view (plan) images: a yaw-and-translation prior for levelled scanners.

Terrestrial scanners stand levelled (their dual-axis compensators keep the tilt within a few
degrees), so two stations differ mostly by a rotation about the vertical and a translation.
Seen from above, walls, pillars and furniture draw the same plan in both scans, whatever the
stations' distance: an orthographic projection onto the ground plane removes the perspective
that makes panoramic feature matching fail across wide baselines. This module

- estimates each scan's vertical from its own surfaces (:func:`estimate_up`: floors and
  ceilings are perpendicular to it, walls parallel),
- rasterises the vertical surfaces of the levelled scan into a plan image whose cells hold
  the metres of vertical surface they contain (:func:`top_view`), and
- finds the yaw and horizontal offset that best overlay two plans by exhaustive FFT
  cross-correlation over yaw (:func:`match_top_views`); the height offset comes from the 1D
  correlation of the heights of horizontal surfaces (floor, tables, ceiling).

The result, :func:`upright_priors`, is a short list of ``T_target_source`` candidates, best
first; the registration pipeline uses them to guide feature matching and verifies them
against the data (:mod:`flexreg.registration.candidates`). Its per-scan half
(:func:`plan_view`) is computed once per scan, the pair half (:func:`plan_overlays`) once per
pair.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import fft, ndimage

from flexreg.core.range_image import RangeImage
from flexreg.core.transforms import invert, rotation_about_axis
from flexreg.errors import DegenerateGeometryError
from flexreg.stages.levelling import MAX_TILT_RAD, Levelling, estimate_up
from flexreg.stages.normals import surface_normals
from flexreg.stages.plan_correlation import (
    Offsets,
    correlation,
    raster,
    rotated_rasters,
    top_local_maxima,
)

log = logging.getLogger(__name__)


@dataclass(eq=False)
class TopView:
    """A plan image of a levelled scan's vertical surfaces.

    Attributes
    ----------
    cells : (K, 2) int64
        ``(ix, iy)`` of the occupied cells, scanner at cell ``(0, 0)``'s centre.
    values : (K,) float64, metres
        Height of vertical surface in each cell (surface area / cell width), clipped.
    cell_m : float, metres
    xy : (K, 2) float64, metres
        Cell centres in the levelled scanner frame.
    heights : (B,) float64
        Area-weighted histogram of the heights of horizontal surfaces (see ``z0_m``, ``dz_m``).
    z0_m, dz_m : float, metres
        Height of the histogram's first bin and bin width.
    """

    cells: NDArray[np.int64]
    values: NDArray[np.float64]
    cell_m: float
    xy: NDArray[np.float64]
    heights: NDArray[np.float64]
    z0_m: float
    dz_m: float


def top_view(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    area: NDArray[np.float64],
    levelling: Levelling,
    *,
    cell_m: float = 0.2,
    radius_m: float = 40.0,
    max_surface_m: float = 0.25,
    height_bin_m: float = 0.01,
) -> TopView:
    """Plan image of a scan's vertical surfaces (and its horizontal surfaces' heights).

    Parameters
    ----------
    points, normals, area
        From :func:`surface_normals`, scanner frame.
    levelling : Levelling
    cell_m : float, metres
        Plan cell size.
    radius_m : float, metres
        Ignore surfaces farther than this horizontally (sparse, noisy far field).
    max_surface_m : float, metres
        Clip each cell's vertical-surface height: a tall wall should not outweigh the
        chair legs, shelves and pillars that make a site unique, so the plan is close to an
        occupancy map of vertical structure (cells with less than 5 mm are dropped).
    height_bin_m : float, metres
        Bin of the horizontal-surface height histogram.
    """
    return top_views(
        points,
        normals,
        area,
        levelling,
        [(cell_m, radius_m)],
        max_surface_m=max_surface_m,
        height_bin_m=height_bin_m,
    )[0]


def top_views(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    area: NDArray[np.float64],
    levelling: Levelling,
    plans: list[tuple[float, float]],
    *,
    max_surface_m: float = 0.25,
    height_bin_m: float = 0.01,
) -> list[TopView]:
    """:func:`top_view` at several ``(cell_m, radius_m)`` at once (the scan is levelled and
    split into vertical and horizontal surfaces once)."""
    R = np.ascontiguousarray(levelling.R_level, dtype=np.float64)
    reach = max(r for _, r in plans)
    vxy, vd, va, hz, hd, ha = _levelled_split(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(area, dtype=np.float64),
        R,
        float(reach),
    )
    out = []
    for cell_m, radius_m in plans:
        near = vd < radius_m
        ij = np.floor(vxy[near] / cell_m + 0.5).astype(np.int64)
        a = va[near]
        if len(ij) == 0:
            raise DegenerateGeometryError("no vertical surfaces to draw a plan from")
        # sum per cell on the dense grid of the cells in reach (no sort): |ij| <= radius / cell
        lo = ij.min(axis=0)
        nx, ny = (ij.max(axis=0) - lo + 1).tolist()
        lin = (ij[:, 1] - lo[1]) * nx + (ij[:, 0] - lo[0])
        grid = np.bincount(lin, weights=a, minlength=nx * ny) / cell_m
        occupied = np.flatnonzero(grid > 0.005)  # row-major: cells sorted by (iy, ix)
        cells = np.column_stack([occupied % nx + lo[0], occupied // nx + lo[1]]).astype(np.int64)
        vals = np.minimum(grid[occupied], max_surface_m)
        hnear = hd < radius_m
        z = hz[hnear]
        h: NDArray[np.float64] = np.zeros(1)
        z0 = 0.0
        if len(z):
            z0 = math.floor(float(z.min()) / height_bin_m) * height_bin_m
            nb = math.ceil((float(z.max()) - z0) / height_bin_m) + 1
            h = np.bincount(
                np.floor((z - z0) / height_bin_m).astype(np.int64),
                weights=ha[hnear],
                minlength=nb,
            ).astype(np.float64)
        xy = (cells * float(cell_m)).astype(np.float64)
        out.append(TopView(cells, vals, cell_m, xy, h, z0, height_bin_m))
    return out


@numba.njit(cache=True, nogil=True)
def _levelled_split(points, normals, area, R, reach):  # pragma: no cover - compiled
    """Points levelled by ``R`` within ``reach`` horizontally, split into vertical surfaces
    (normal within 30 degrees of horizontal: plan position, horizontal distance, area) and
    horizontal ones (normal within 18 degrees of vertical: height, horizontal distance,
    area)."""
    n = points.shape[0]
    vxy = np.empty((n, 2))  # (entries of area 0 are skipped: see surface_normals' compact)
    vd = np.empty(n)
    va = np.empty(n)
    hz = np.empty(n)
    hd = np.empty(n)
    ha = np.empty(n)
    nv = 0
    nh = 0
    for i in range(n):
        if not area[i] > 0.0:
            continue
        x = R[0, 0] * points[i, 0] + R[0, 1] * points[i, 1] + R[0, 2] * points[i, 2]
        y = R[1, 0] * points[i, 0] + R[1, 1] * points[i, 1] + R[1, 2] * points[i, 2]
        d = math.hypot(x, y)
        if not d < reach:
            continue
        nz = R[2, 0] * normals[i, 0] + R[2, 1] * normals[i, 1] + R[2, 2] * normals[i, 2]
        if abs(nz) < 0.5:
            vxy[nv, 0] = x
            vxy[nv, 1] = y
            vd[nv] = d
            va[nv] = area[i]
            nv += 1
        elif abs(nz) > 0.95:
            hz[nh] = R[2, 0] * points[i, 0] + R[2, 1] * points[i, 1] + R[2, 2] * points[i, 2]
            hd[nh] = d
            ha[nh] = area[i]
            nh += 1
    return vxy[:nv], vd[:nv], va[:nv], hz[:nh], hd[:nh], ha[:nh]


@dataclass(frozen=True)
class PlanMatch:
    """One yaw / offset that overlays two plans.

    Attributes
    ----------
    yaw_rad : float, radians
        Rotation about the vertical taking the levelled source into the levelled target.
    t_xy : (2,) float64, metres
    score : float
        Correlation of the two plans (overlapping vertical surface, metres of height x cells).
    """

    yaw_rad: float
    t_xy: tuple[float, float]
    score: float


def _yaw_peaks(
    target: TopView, source: TopView, yaws: NDArray[Any], cell_m: float, peaks: int = 1
) -> list[list[tuple[float, float, float]]]:
    """For each yaw, the best correlations of the rotated source plan with the target plan
    over all offsets (FFT), rasterised at ``cell_m``: the ``peaks`` highest local maxima at
    least :data:`PEAK_SEPARATION_M` apart, best first, as ``(score, t_x, t_y)``, each offset
    refined to sub-cell by parabolas. More than one peak per yaw is what a row of bays needs:
    at the right turn, the overlay a bay off may correlate better than the true one."""
    c = cell_m
    tcells = np.floor(target.xy / c + 0.5).astype(np.int64)
    rt = int(np.abs(tcells).max()) + 1
    rs = math.ceil(float(np.hypot(source.xy[:, 0], source.xy[:, 1]).max()) / c) + 2
    size = fft.next_fast_len(2 * (rt + rs) + 1, real=True)
    shape = (size, size)
    T = raster(tcells, target.values, shape, rt).astype(np.float32)
    FT = np.conj(fft.rfft2(T))
    out: list[list[tuple[float, float, float]]] = []
    batch = 8  # yaws per FFT call (single precision: a plan is a coarse picture)
    for b0 in range(0, len(yaws), batch):
        S = rotated_rasters(
            source.xy,
            source.values,
            np.ascontiguousarray(yaws[b0 : b0 + batch], dtype=np.float64),
            0.0,
            0.0,
            float(c),
            rs,
            size,
            -1,
        )
        for corr in correlation(S, FT, shape):
            if peaks == 1:
                tops = [divmod(int(np.argmax(corr)), size)]
            else:
                sep = 2 * math.ceil(PEAK_SEPARATION_M / c) + 1
                flat = top_local_maxima(corr, sep, peaks)
                tops = [divmod(int(f), size) for f in flat] or [divmod(int(np.argmax(corr)), size)]
            row = []
            for iy, ix in tops:
                best = float(corr[iy, ix])
                fy = _parabola(corr[(iy - 1) % size, ix], best, corr[(iy + 1) % size, ix])
                fx = _parabola(corr[iy, (ix - 1) % size], best, corr[iy, (ix + 1) % size])
                dx = (ix if ix <= 2 * rs else ix - size) + fx
                dy = (iy if iy <= 2 * rs else iy - size) + fy
                # source cell s sits at raster s + rs, target cell t at t + rt:
                # t = s + (rs - rt - d)
                row.append((best, (rs - rt - dx) * c, (rs - rt - dy) * c))
            out.append(row)
    return out


def match_top_views(
    target: TopView,
    source: TopView,
    *,
    yaw_step_rad: float = math.radians(1.0),
    top_k: int = 5,
    min_separation_m: float = 1.0,
    coarse_candidates: int = 8,
    peaks: int = 1,
) -> list[PlanMatch]:
    """Best yaw / horizontal offsets overlaying ``source``'s plan onto ``target``'s.

    For every yaw on a regular grid the source cells are rotated and re-rasterised, and the
    cross-correlation with the target plan over all offsets is one FFT product. This runs
    first on plans of twice the cell size (a quarter of the FFT work), then at the plans' own
    cell for the ``coarse_candidates`` best yaws there (local maxima over yaw) and their two
    neighbouring yaws. The ``top_k`` best distinct peaks (different yaw or more than
    ``min_separation_m`` apart) are returned, each refined to sub-cell offset and sub-step
    yaw by parabolas through the peak's neighbours; then, with ``peaks`` above 1, the next
    best offsets of each of their yaws (:func:`_yaw_peaks`), at least
    :data:`PEAK_SEPARATION_M` from every overlay returned: after the ``top_k``, never in
    their place.
    """
    c = target.cell_m
    if source.cell_m != c:
        raise ValueError("plans must share their cell size")
    n = max(1, round(2 * math.pi / yaw_step_rad))
    yaws = np.arange(n, dtype=np.float64) * (2 * math.pi / n)
    coarse = np.array([p[0][0] for p in _yaw_peaks(target, source, yaws, 2 * c)])
    # local maxima over the yaw circle, best first
    left, right = np.roll(coarse, 1), np.roll(coarse, -1)
    maxima = np.flatnonzero((coarse >= left) & (coarse >= right))
    maxima = maxima[np.argsort(-coarse[maxima], kind="stable")][:coarse_candidates]
    ks = sorted({int((k + d) % n) for k in maxima for d in (-1, 0, 1)})
    fine = dict(zip(ks, _yaw_peaks(target, source, yaws[ks], c, peaks), strict=True))
    out: list[PlanMatch] = []
    turns: list[int] = []  # the yaw index of each overlay in out
    for k in sorted(fine, key=lambda k: (-fine[k][0][0], k)):
        best, tx, ty = fine[k][0]
        prev, nxt = fine.get((k - 1) % n), fine.get((k + 1) % n)
        yaw = float(yaws[k])
        if prev is not None and nxt is not None:
            yaw += _parabola(prev[0][0], best, nxt[0][0]) * yaw_step_rad
        dup = any(
            abs(_wrap_angle(yaw - m.yaw_rad)) < 3 * yaw_step_rad
            or (
                math.hypot(tx - m.t_xy[0], ty - m.t_xy[1]) < min_separation_m
                and abs(_wrap_angle(yaw - m.yaw_rad)) < math.radians(10.0)
            )
            for m in out
        )
        if not dup:
            out.append(PlanMatch(_wrap_angle(yaw), (tx, ty), best))
            turns.append(k)
        if len(out) >= top_k:
            break
    # then the further offsets of the turns kept, after all of them (they never displace one)
    for m, k in list(zip(out, turns, strict=True)):
        for best, tx, ty in fine[k][1:]:
            if all(math.hypot(tx - o.t_xy[0], ty - o.t_xy[1]) >= PEAK_SEPARATION_M for o in out):
                out.append(PlanMatch(m.yaw_rad, (tx, ty), best))
    return out


def refine_plan_match(
    target: TopView,
    source: TopView,
    match: PlanMatch,
    *,
    yaw_range_rad: float = math.radians(1.5),
    yaw_step_rad: float = math.radians(0.5),
    shift_m: float = 0.4,
) -> PlanMatch:
    """Refine a plan overlay on finer plans: local yaw search, sub-cell correlation peak.

    The source plan, placed by ``match``, is rotated about its scanner through
    ``yaw ± yaw_range_rad`` and correlated (FFT, all yaws in one batch) with the target plan,
    lightly blurred, over offsets up to ``shift_m``; the best yaw and offset are interpolated by
    parabolas.
    """
    return refine_plan_matches(
        target,
        source,
        [match],
        yaw_range_rad=yaw_range_rad,
        yaw_step_rad=yaw_step_rad,
        shift_m=shift_m,
    )[0]


def refine_plan_matches(
    target: TopView,
    source: TopView,
    matches: list[PlanMatch],
    *,
    yaw_range_rad: float = math.radians(1.5),
    yaw_step_rad: float = math.radians(0.5),
    shift_m: float = 0.4,
) -> list[PlanMatch]:
    """:func:`refine_plan_match` of several overlays of the same plans (the target's
    transform is computed once)."""
    c = target.cell_m
    if source.cell_m != c:
        raise ValueError("plans must share their cell size")
    offsets = Offsets.of(target.cells, target.values, target.cell_m, shift_m)
    w = offsets.w
    out = []
    for match in matches:
        t0 = np.asarray(match.t_xy)
        yaws = match.yaw_rad + np.arange(-yaw_range_rad, yaw_range_rad + 1e-12, yaw_step_rad)
        best = []
        for yaw, win in zip(yaws, offsets.near(source.xy, source.values, t0, yaws), strict=True):
            iy, ix = divmod(int(np.argmax(win)), 2 * w + 1)
            b = float(win[iy, ix])
            fy = _parabola(win[iy - 1, ix], b, win[iy + 1, ix]) if 0 < iy < 2 * w else 0.0
            fx = _parabola(win[iy, ix - 1], b, win[iy, ix + 1]) if 0 < ix < 2 * w else 0.0
            # the source at x + d lies on the target at x: move it by -d
            best.append((b, float(yaw), t0[0] - (ix - w + fx) * c, t0[1] - (iy - w + fy) * c))
        scores = np.array([b[0] for b in best])
        i = int(np.argmax(scores))
        b, yaw, tx, ty = best[i]
        if 0 < i < len(best) - 1:
            f = _parabola(scores[i - 1], b, scores[i + 1])
            j = i + (1 if f > 0 else -1)
            # interpolate the offset towards the neighbouring yaw's as well
            tx += abs(f) * (best[j][2] - tx)
            ty += abs(f) * (best[j][3] - ty)
            yaw += f * yaw_step_rad
        out.append(PlanMatch(_wrap_angle(yaw), (float(tx), float(ty)), b))
    return out


def _parabola(a: float, b: float, c: float) -> float:
    d = a - 2 * b + c
    return 0.0 if d >= 0 else float(np.clip(0.5 * (a - c) / d, -0.5, 0.5))


def _wrap_angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def height_offset(target: TopView, source: TopView, *, max_offset_m: float = 5.0) -> float:
    """Height of the source scanner above the target's (levelled frames), metres: the shift
    that best overlays the two histograms of horizontal-surface heights."""
    a = np.log1p(target.heights / max(target.heights.max(), 1e-12) * 100)
    b = np.log1p(source.heights / max(source.heights.max(), 1e-12) * 100)
    # full cross-correlation (lags -(len(b) - 1) .. len(a) - 1) as a convolution with the
    # reversed source histogram
    n = len(a) + len(b) - 1
    m = fft.next_fast_len(n, real=True)
    corr = fft.irfft(fft.rfft(a, m) * fft.rfft(b[::-1], m), m)[:n]
    lags = np.arange(-len(b) + 1, len(a))
    # target bin i + lag... z_t = z0_t + (j + lag) * dz  <->  z_s = z0_s + j * dz
    shift = target.z0_m - source.z0_m + lags * target.dz_m
    ok = np.abs(shift) <= max_offset_m
    if not ok.any():
        return 0.0
    i = int(np.flatnonzero(ok)[np.argmax(corr[ok])])
    return float(shift[i])


# ------------------------------------------------------------------------- priors of a pair

#: the plan views are drawn from at most about this many pixels per scan (every k-th row and
#: column of larger images); 300 k at 1024 x 512 already lost the far structure that places a
#: distant station
PLAN_PIXELS = 1_000_000
#: overlays at one turn count as distinct when their offsets are this far apart, metres: less
#: than a bay of a warehouse or a room of a building, more than a plan cell's uncertainty
PEAK_SEPARATION_M = 2.0
#: overlays kept per turn by :func:`plan_overlays` (the true one and the look-alikes a bay or
#: a room off on either side)
PEAKS_PER_TURN = 3


@dataclass(eq=False)
class PlanView:
    """What the plan overlays need of one scan (:func:`plan_view`).

    Attributes
    ----------
    levelling : Levelling
        The scan's vertical.
    coarse, fine : TopView
        Plan images at the plan cell (40 m around the scanner) and a quarter of it (20 m).
    """

    levelling: Levelling
    coarse: TopView
    fine: TopView


def plan_view(
    image: RangeImage,
    *,
    max_tilt_rad: float = MAX_TILT_RAD,
    plan_cell_m: float = 0.25,
    max_pixels: int = PLAN_PIXELS,
) -> PlanView:
    """The levelling and the two plan images of one scan: the per-scan half of
    :func:`upright_priors`.

    Parameters
    ----------
    image : RangeImage
        An organised scan (every k-th row and column of it when it has more than
        ``max_pixels`` pixels).
    max_tilt_rad : float, radians
        Largest tilt of a scan still treated as levelled.
    plan_cell_m : float, metres
        Cell of the coarse plan image (the fine one has a quarter of it).
    max_pixels : int
        Pixel budget of the normals.

    Raises
    ------
    DegenerateGeometryError
        The scan is not levelled or shows too little horizontal or vertical surface.
    """
    stride = max(1, math.ceil(math.sqrt(image.height * image.width / max_pixels)))
    pts, nrm, area = surface_normals(image, k=2, stride=stride, compact=False)
    lev = estimate_up(nrm, area, max_tilt_rad=max_tilt_rad, points=pts)
    coarse, fine = top_views(pts, nrm, area, lev, [(plan_cell_m, 40.0), (plan_cell_m / 4, 20.0)])
    return PlanView(lev, coarse, fine)


def plan_overlays(
    target: PlanView, source: PlanView, *, hypotheses: int = 3
) -> list[NDArray[np.float64]]:
    """``T_target_source`` candidates of two levelled scans from their plan views, best first:
    the pair half of :func:`upright_priors`.

    The coarse plans are overlaid by FFT correlation over yaw (2 degree steps, 6 coarse yaw
    candidates, :data:`PEAKS_PER_TURN` offsets each, ``hypotheses`` overlays kept), the fine
    plans refine each over +-1 degree, and the height offset comes from the horizontal
    surfaces.
    """
    lt, ls = target.levelling, source.levelling
    plans = match_top_views(
        target.coarse,
        source.coarse,
        yaw_step_rad=math.radians(2.0),
        top_k=hypotheses,
        coarse_candidates=6,
        peaks=PEAKS_PER_TURN,
    )
    plans = refine_plan_matches(target.fine, source.fine, plans, yaw_range_rad=math.radians(1.0))
    dz = height_offset(target.coarse, source.coarse)
    out = [_unlevelled(m, dz, target, source) for m in plans]
    log.info(
        "plan overlays: %s (tilts %.2f / %.2f deg, dz %.3f m)",
        ", ".join(f"{math.degrees(m.yaw_rad):.1f} deg score {m.score:.0f}" for m in plans),
        math.degrees(lt.tilt_rad),
        math.degrees(ls.tilt_rad),
        dz,
    )
    return out


def _levellers(
    target: PlanView, source: PlanView
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    Lt, Ls = np.eye(4), np.eye(4)
    Lt[:3, :3], Ls[:3, :3] = target.levelling.R_level, source.levelling.R_level
    return Lt, Ls


def _unlevelled(m: PlanMatch, dz: float, target: PlanView, source: PlanView) -> NDArray[np.float64]:
    """``T_target_source`` of a plan overlay (yaw and offset of the levelled plans)."""
    M = np.eye(4)
    M[:3, :3] = rotation_about_axis([0.0, 0.0, 1.0], m.yaw_rad)
    M[:3, 3] = (m.t_xy[0], m.t_xy[1], dz)
    Lt, Ls = _levellers(target, source)
    return invert(Lt) @ M @ Ls


def _window_peaks(
    target: TopView, source: TopView, seed: PlanMatch, turn_rad: float, shift_m: float, k: int
) -> list[PlanMatch]:
    """The ``k`` best distinct overlays of ``source`` on ``target`` with yaw within
    ``turn_rad`` of ``seed``'s (1 degree steps) and offset within ``shift_m`` of its: local
    maxima of the correlation over (yaw, offset), at least 1 m or 3 degrees apart."""
    c = target.cell_m
    offsets = Offsets.of(target.cells, target.values, target.cell_m, shift_m)
    w = offsets.w
    yaws = seed.yaw_rad + np.arange(-turn_rad, turn_rad + 1e-12, math.radians(1.0))
    t0 = np.asarray(seed.t_xy)
    vol = offsets.near(source.xy, source.values, t0, yaws).astype(np.float64)
    d = np.arange(-w, w + 1) * c
    inside = np.hypot(d[None, :], d[:, None]) <= shift_m
    vol[:, ~inside] = -np.inf
    size = (3, 2 * math.ceil(1.0 / c) + 1, 2 * math.ceil(1.0 / c) + 1)
    peak = (vol == ndimage.maximum_filter(vol, size=size, mode="nearest")) & np.isfinite(vol)
    idx = np.argwhere(peak)
    idx = idx[np.argsort(-vol[peak], kind="stable")]
    out: list[PlanMatch] = []
    for yi, iy, ix in idx[:k]:
        # the source at x + d lies on the target at x: move it by -d
        t = (t0[0] - (ix - w) * c, t0[1] - (iy - w) * c)
        out.append(PlanMatch(_wrap_angle(float(yaws[yi])), t, float(vol[yi, iy, ix])))
    return out


def windowed_plan_overlays(
    target: PlanView,
    source: PlanView,
    T_prior: NDArray[np.float64],
    *,
    shift_m: float,
    turn_rad: float,
    hypotheses: int = 3,
) -> list[NDArray[np.float64]]:
    """The best plan overlays inside a rough prior's window, best first: yaws within
    ``turn_rad`` of the prior's (1 degree steps, on the coarse plans) and offsets within
    ``shift_m`` of its, ``hypotheses`` distinct local maxima of the correlation, each refined
    on the fine plans as :func:`plan_overlays` refines its overlays.

    Where the plans repeat (a row of bays, look-alike rooms) the global overlays may all be a
    bay off; a prior that rules the other bays out (rough positions of both stations) leaves
    the few overlays it allows, for the dense check to judge.

    Parameters
    ----------
    target, source : PlanView
    T_prior : (4, 4) float64
        The rough ``T_target_source``.
    shift_m : float, metres
    turn_rad : float, radians
        How far the true pose may be from the prior.
    hypotheses : int
        Overlays kept.

    Returns
    -------
    list of (4, 4) float64
        ``T_target_source`` of each overlay.
    """
    Lt, Ls = _levellers(target, source)
    M0 = Lt @ np.asarray(T_prior, dtype=np.float64) @ invert(Ls)
    seed = PlanMatch(math.atan2(M0[1, 0], M0[0, 0]), (float(M0[0, 3]), float(M0[1, 3])), 0.0)
    plans = _window_peaks(target.coarse, source.coarse, seed, turn_rad, shift_m, hypotheses)
    plans = refine_plan_matches(target.fine, source.fine, plans, yaw_range_rad=math.radians(1.0))
    dz = height_offset(target.coarse, source.coarse)
    log.info(
        "plan overlays in the window: %s",
        ", ".join(f"{math.degrees(m.yaw_rad):.1f} deg score {m.score:.0f}" for m in plans),
    )
    return [_unlevelled(m, dz, target, source) for m in plans]


def upright_priors(
    target: RangeImage,
    source: RangeImage,
    *,
    max_tilt_rad: float = MAX_TILT_RAD,
    plan_cell_m: float = 0.25,
    plan_hypotheses: int = 3,
) -> list[NDArray[np.float64]]:
    """``T_target_source`` candidates of two levelled scans from their plan views, best first.

    Each scan's vertical is estimated from its surfaces, the plans of the levelled scans are
    overlaid by FFT correlation over yaw and the height offset is read from their horizontal
    surfaces. Accurate to about a plan cell and a degree: a prior for guided matching, not a
    result. :func:`plan_view` (per scan) then :func:`plan_overlays` (per pair).

    Raises
    ------
    DegenerateGeometryError
        A scan is not levelled (tilt above ``max_tilt_rad``) or shows too little horizontal or
        vertical surface.
    """
    views = [
        plan_view(img, max_tilt_rad=max_tilt_rad, plan_cell_m=plan_cell_m)
        for img in (target, source)
    ]
    return plan_overlays(views[0], views[1], hypotheses=plan_hypotheses)


__all__ = [
    "MAX_TILT_RAD",
    "PEAKS_PER_TURN",
    "PEAK_SEPARATION_M",
    "PLAN_PIXELS",
    "Levelling",
    "PlanMatch",
    "PlanView",
    "TopView",
    "estimate_up",
    "height_offset",
    "match_top_views",
    "plan_overlays",
    "plan_view",
    "refine_plan_match",
    "refine_plan_matches",
    "top_view",
    "top_views",
    "upright_priors",
    "windowed_plan_overlays",
]
