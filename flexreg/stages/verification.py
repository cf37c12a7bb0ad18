"""Verification: how well a transform explains the target's view of the source.

The dense free-space check of :func:`overlap_score`: source points mapped into the target frame
are looked up in the target's range image; a point is consistent when the target saw a
surface at its range and in conflict when it lies clearly in front of what the target saw.
:func:`classify_points` is its core on points already sampled (the registration samples each
scan once and checks many candidates), :func:`range_slack` the per-pixel range tolerance and
:func:`measured_image` what the camera measures per pixel.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import RangeImage
from flexreg.errors import ConfigError
from flexreg.stages.sampling import area_sample


def measured_image(image: RangeImage) -> NDArray[np.float32]:
    """What the camera model measures per pixel: depth z (pinhole) or range, NaN where invalid."""
    return image.depth_z() if isinstance(image.camera, PinholeCamera) else image.range


def range_slack(
    image: RangeImage, measured: NDArray[np.float32] | None = None
) -> NDArray[np.float32]:
    """(H, W) largest range (or depth) change from each pixel to its 4 neighbours, metres (0
    where unknown): how much range one pixel spans on an oblique surface. ``measured`` is the
    image's range (depth for pinhole cameras), when already at hand."""
    ref = measured_image(image) if measured is None else measured
    out = np.zeros(image.shape, dtype=np.float32)
    if image.wraps:  # the seam columns are neighbours
        ref = np.concatenate([ref, ref[:, :1]], axis=1)
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            d = np.abs(np.diff(ref, axis=axis))
            d = np.nan_to_num(d, nan=0.0)
            W = out.shape[1]
            if axis == 0:
                out[1:] = np.maximum(out[1:], d[:, :W])
                out[:-1] = np.maximum(out[:-1], d[:, :W])
            else:
                out[:, 1:] = np.maximum(out[:, 1:], d[:, : W - 1])
                out[:, :-1] = np.maximum(out[:, :-1], d[:, : W - 1])
                if image.wraps:
                    out[:, -1] = np.maximum(out[:, -1], d[:, -1])
                    out[:, 0] = np.maximum(out[:, 0], d[:, -1])
    return out


def open_space_witnesses(ref: NDArray[np.float32], wraps: bool = False) -> NDArray[np.bool_]:
    """(H, W) bool: the pixels that can testify to what lies in their footprint (a surface, or
    open space in front of what they measured): measured, and each of their 4 neighbours
    measured too.

    A pixel's range bounds the open space across its whole footprint only where its
    neighbours bound how far the surface runs within it (:func:`range_slack`). Beside a pixel
    with no return that bound is missing: the footprint may hold a surface the neighbouring
    ray did not return from (one seen too obliquely, or too dark or far), running at any range
    in front of this pixel's. A far wall seen along its length falls into one column of a
    scan, the last one before its returns stop, and that column's centre ray may pass the wall
    and measure the corner behind it: by the pixel's range, every point of the wall would
    lie in open space.

    Parameters
    ----------
    ref : (H, W) float32
        :func:`measured_image` (NaN or 0 where nothing was measured).
    wraps : bool
        Whether the first and last columns are neighbours (a full panorama).
    """
    seen = np.isfinite(ref) & (ref > 0)
    out = seen.copy()
    out[1:] &= seen[:-1]
    out[:-1] &= seen[1:]
    out[:, 1:] &= seen[:, :-1]
    out[:, :-1] &= seen[:, 1:]
    if wraps:
        out[:, 0] &= seen[:, -1]
        out[:, -1] &= seen[:, 0]
    return out


def overlap_score(
    target: RangeImage,
    source: RangeImage,
    T_target_source: NDArray[np.float64],
    *,
    tolerance_m: float = 0.05,
    tolerance_rel: float = 0.01,
    samples: int = 20000,
    slack: NDArray[np.float32] | None = None,
    sampling: str = "area",
) -> tuple[float, float]:
    """How well a transform explains the target's view of the source: a dense check.

    A regular sample of the source's points is mapped into the target frame and looked up in
    the target's range image. A point is *consistent* when the target saw a surface at the
    same range (within ``tolerance_m + tolerance_rel * range``) and *in conflict* when it
    lies clearly in front of what the target saw: the target looked through the place where
    the transform puts it, so a wrong transform collects conflicts while a right one only
    collects consistent and occluded points. Each pixel's tolerance also grows by the range
    change to its neighbours (``slack``, see :func:`range_slack`), since a pixel on a surface
    seen at grazing incidence spans a long stretch of range. Native grids without a camera
    model fall back to nearest-neighbour distances (no conflicts).

    With ``sampling="area"`` (default) the sample is spread evenly over the source's surfaces
    (one point per cell of a voxel grid sized to give about ``samples`` points,
    :func:`area_sample`), so fractions are fractions of surface area; ``"pixels"`` takes every
    k-th valid pixel instead, which weights surfaces near the scanner by their many pixels. Area
    matters where the near field is self-similar: in a corridor the walls beside the scanner
    fill most pixels and fit any shift along it, while the far structure that fixes the shift
    has few pixels but most of the area.

    Returns
    -------
    consistent, conflicting : float
        Fractions of the sampled source points.
    """
    if sampling not in ("area", "pixels"):
        raise ConfigError(f"sampling must be 'area' or 'pixels', got {sampling!r}")
    valid = source.xyz[source.valid]
    ps = (
        area_sample(valid, samples)
        if sampling == "area"
        else np.asarray(valid[:: max(1, len(valid) // samples)], dtype=np.float64)
    )
    _, ok, bad = classify_points(target, ps, T_target_source, tolerance_m, tolerance_rel, slack)
    return (float(ok.mean()), float(bad.mean())) if len(ok) else (0.0, 0.0)


def classify_points(
    target: RangeImage,
    ps: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    tolerance_m: float,
    tolerance_rel: float,
    slack: NDArray[np.float32] | None = None,
    ref: NDArray[np.float32] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Source points checked against the target's view: the core of :func:`overlap_score`.

    Parameters
    ----------
    target : RangeImage
        The target's view (with a camera model; without one, nearest-neighbour distances and no
        conflicts).
    ps : (N, 3) float64, metres
        Source points, already sampled (e.g. :func:`flexreg.stages.sampling.area_sample`).
    T_target_source : (4, 4) float64
    tolerance_m, tolerance_rel : float
        Range tolerance: metres plus a fraction of the range.
    slack : (H, W) float32, optional
        :func:`range_slack` of the target, when at hand.
    ref : (H, W) float32, optional
        :func:`measured_image` of the target, when at hand.

    Returns
    -------
    q : (N, 3) float64
        The points in the target frame.
    consistent, conflicting : (N,) bool
    """
    if len(ps) == 0:
        return np.zeros((0, 3)), np.zeros(0, bool), np.zeros(0, bool)
    T = np.asarray(T_target_source, dtype=np.float64)
    q = ps @ T[:3, :3].T + T[:3, 3]
    if target.camera is None:
        pt = target.xyz[target.valid]
        pt = pt[:: max(1, len(pt) // 200_000)]
        from scipy.spatial import cKDTree  # heavy (0.1 s): the CLI imports this module at start-up

        dist, _ = cKDTree(pt).query(q, distance_upper_bound=4 * tolerance_m)
        ok = dist < tolerance_m + tolerance_rel * np.linalg.norm(q, axis=1)
        return q, ok, np.zeros(len(q), dtype=bool)
    d, r, tol = _ray_ranges(target, q, tolerance_m, tolerance_rel, slack, ref)
    with np.errstate(invalid="ignore"):
        consistent = np.abs(d - r) < tol
        conflict = d < r - tol
    return q, consistent, conflict


def classify_points_at(
    target: RangeImage,
    ps: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    tolerances: list[tuple[float, float]],
    slack: NDArray[np.float32] | None = None,
    ref: NDArray[np.float32] | None = None,
    witnesses: NDArray[np.bool_] | None = None,
) -> list[tuple[NDArray[np.bool_], NDArray[np.bool_]]]:
    """:func:`classify_points` at several tolerances ``(tolerance_m, tolerance_rel)``, the
    points projected into the target's view once: ``(consistent, conflicting)`` per
    tolerance, each exactly as :func:`classify_points` gives it; with ``witnesses`` ((H, W)
    bool, e.g. :func:`open_space_witnesses`), only points at those pixels are judged (the
    rest are neither consistent nor conflicting)."""
    T = np.asarray(T_target_source, dtype=np.float64)
    if len(ps) == 0 or target.camera is None:
        return [classify_points(target, ps, T, m, rel, slack, ref)[1:] for m, rel in tolerances]
    q = ps @ T[:3, :3].T + T[:3, 3]
    inside, pix, d = _pixels(target, q)
    r, extra = _measured_at(target, inside, pix, len(q), slack, ref)
    if witnesses is not None:
        testifies = np.zeros(len(q), dtype=bool)
        testifies[inside] = witnesses[pix]
    out = []
    for m, rel in tolerances:
        tol = m + rel * np.abs(d) + extra
        with np.errstate(invalid="ignore"):
            consistent, conflict = np.abs(d - r) < tol, d < r - tol
        if witnesses is not None:
            consistent, conflict = consistent & testifies, conflict & testifies
        out.append((consistent, conflict))
    return out


def _pixels(
    target: RangeImage, q: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], tuple[NDArray[np.int64], NDArray[np.int64]], NDArray[np.float64]]:
    """Which points fall inside the target's image, their (row, column) pixels and their
    measured coordinate (range or depth) ``d``."""
    assert target.camera is not None
    u, v, d = target.camera.project(q)
    with np.errstate(invalid="ignore"):
        iu = np.floor(u + 0.5)
        iv = np.floor(v + 0.5)
        if target.wraps:
            iu = np.where(iu >= target.width, iu - target.width, iu)
        inside = np.isfinite(iu) & np.isfinite(iv) & (d > 0)
        inside &= (iu >= 0) & (iu < target.width) & (iv >= 0) & (iv < target.height)
    return inside, (iv[inside].astype(np.int64), iu[inside].astype(np.int64)), d


def _ray_ranges(
    target: RangeImage,
    q: NDArray[np.float64],
    tolerance_m: float,
    tolerance_rel: float,
    slack: NDArray[np.float32] | None,
    ref: NDArray[np.float32] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per point (target frame): its range ``d`` along the target's ray, what the target
    measured there ``r`` (NaN outside its view or where it saw nothing) and the tolerance."""
    inside, pix, d = _pixels(target, q)
    r, extra = _measured_at(target, inside, pix, len(q), slack, ref)
    tol = tolerance_m + tolerance_rel * np.abs(d) + extra
    return d, r, tol


def _measured_at(
    target: RangeImage,
    inside: NDArray[np.bool_],
    pix: tuple[NDArray[np.int64], NDArray[np.int64]],
    n: int,
    slack: NDArray[np.float32] | None,
    ref: NDArray[np.float32] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What the target measured at each of ``n`` points' pixels (NaN outside its view) and
    the slack there (0 outside)."""
    if ref is None:
        ref = measured_image(target)
    if slack is None:
        slack = range_slack(target, ref)
    r = np.full(n, np.nan)
    extra = np.zeros(n)
    r[inside] = ref[pix]
    extra[inside] = slack[pix]
    return r, extra


def soft_score(
    target: RangeImage,
    ps: NDArray[np.float64],
    T_target_source: NDArray[np.float64],
    tolerance_m: float,
    tolerance_rel: float,
    slack: NDArray[np.float32] | None = None,
    ref: NDArray[np.float32] | None = None,
    *,
    open_space: bool = True,
) -> tuple[float, NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """A continuous version of the dense check: how well ``T_target_source`` explains the
    target's view of the points ``ps``, sensitive to changes far below the tolerance.

    Each point consistent with the target's view (see :func:`classify_points`) counts
    ``1 - (e / tol)^2`` (a truncated quadratic of its range residual ``e`` along the target's
    ray: 1 when exact, 0 at the tolerance), each conflicting point ``-3``, every other point 0;
    the score is their mean. Used to decide whether a refinement improved a transform.

    Parameters
    ----------
    target, ps, T_target_source, tolerance_m, tolerance_rel, slack, ref
        As :func:`classify_points`.
    open_space : bool
        Whether the target's view tells open space (a scan taken from one point): False
        counts no point as conflicting (a cloud fused from many viewpoints,
        :func:`~flexreg.stages.viewpoint.one_viewpoint`).

    Returns
    -------
    score : float
        At most 1 (every point exactly on what the target saw).
    q, consistent, conflicting
        As :func:`classify_points`.
    """
    if len(ps) == 0 or target.camera is None:
        q, ok, bad = classify_points(
            target, ps, T_target_source, tolerance_m, tolerance_rel, slack, ref
        )
        bad = bad if open_space else np.zeros_like(bad)
        return (float(ok.mean() - 3 * bad.mean()) if len(q) else 0.0), q, ok, bad
    T = np.asarray(T_target_source, dtype=np.float64)
    q = ps @ T[:3, :3].T + T[:3, 3]
    d, r, tol = _ray_ranges(target, q, tolerance_m, tolerance_rel, slack, ref)
    with np.errstate(invalid="ignore"):
        ok = np.abs(d - r) < tol
        bad = (d < r - tol) if open_space else np.zeros(len(q), dtype=bool)
    w = np.zeros(len(q))
    w[ok] = 1.0 - ((d[ok] - r[ok]) / tol[ok]) ** 2
    return float(w.mean() - 3 * bad.mean()), q, ok, bad


def plane_information(
    target: RangeImage, normals: NDArray[np.float32], q: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Point-to-plane information of points lying on the target's surfaces, about their
    centroid: the sum of ``J^T J`` with ``J = [(q - c) x n, n]`` (Open3D's order: rotation
    ``rx, ry, rz``, then translation ``tx, ty, tz``), ``n`` the target's normal at the pixel
    each point falls on.

    Unlike a point-to-point information, it knows that a point on a plane fixes nothing along
    the plane: a corridor gives no translation information along its axis.

    Parameters
    ----------
    target : RangeImage
        The target's view, with a camera model.
    normals : (H, W, 3) float32
        Its :func:`flexreg.stages.normals.grid_normals`.
    q : (N, 3) float64, metres
        Points in the target frame (e.g. the source points consistent with the target's view).

    Returns
    -------
    information : (6, 6) float64
        Rotations in radians about axes through the centroid, translations in metres.
    centroid : (3,) float64, metres
    count : int
        How many points had a normal (the others are left out).
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
    if len(q) == 0 or target.camera is None:
        return np.zeros((6, 6)), np.zeros(3), 0
    inside, pix, _ = _pixels(target, q)
    n = np.full((len(q), 3), np.nan)
    n[inside] = normals[pix]
    good = np.isfinite(n).all(axis=1)
    q, n = q[good], n[good]
    if len(q) == 0:
        return np.zeros((6, 6)), np.zeros(3), 0
    c = q.mean(axis=0)
    J = np.concatenate([np.cross(q - c, n), n], axis=1)
    return J.T @ J, c, len(q)


#: names of the six pose parameters in Open3D's order
AXES = ("roll", "pitch", "yaw", "x", "y", "z")


def axis_strength(
    information: NDArray[np.float64], points: int, length_m: float | NDArray[np.float64]
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """How firmly each of the six pose parameters is fixed, per point, on a 0-1 scale.

    Each parameter's information once the other five are free to adjust (``1 / (H^-1)_ii``),
    divided by ``points``; rotations are expressed in metres at their lever arm ``length_m``
    (a rotation of ``a`` radians moves points at that distance from its axis by
    ``a * length_m``). A corridor has near-zero translation strength along its axis even when
    its walls fix everything else. For planar surfaces the translation strengths are at most
    1 (the share of surface facing that axis), and so are the rotation strengths when each
    lever arm is the RMS distance of the points from that axis.

    Parameters
    ----------
    information : (6, 6) float64
        Rotation (radians) then translation (metres), Open3D's order.
    points : int
        How many points it sums.
    length_m : float or (3,) float64, metres
        Lever arm of the rotations, one for all or one per rotation axis.

    Returns
    -------
    strength : (6,) float64
        Per parameter of :data:`AXES` (roll, pitch, yaw, x, y, z).
    weakest : float
        The smallest eigenvalue of the normalised information (rotations in metres at the
        mean lever arm): the strength of the least constrained combination of parameters.
    direction : (6,) float64
        That combination (unit eigenvector, rotations scaled as for ``weakest``).

    Examples
    --------
    >>> import numpy as np
    >>> H = np.diag([1.0, 1.0, 1.0, 1.0, 0.5, 0.0])  # nothing along z
    >>> s, weakest, d = axis_strength(H, 1, 1.0)
    >>> s.round(3).tolist(), weakest, int(np.abs(d).argmax())
    ([1.0, 1.0, 1.0, 1.0, 0.5, 0.0], 0.0, 5)
    """
    if points <= 0 or not np.all(np.isfinite(information)):
        return np.zeros(6), 0.0, np.zeros(6)
    L = np.maximum(np.broadcast_to(np.asarray(length_m, dtype=np.float64), (3,)), 1e-9)
    scale = np.concatenate([1 / L, np.ones(3)])
    H = np.asarray(information, dtype=np.float64) * np.outer(scale, scale) / points
    H = (H + H.T) / 2
    lam, V = np.linalg.eigh(H)
    lam = np.clip(lam, 0.0, None)
    inv_diag = (V**2 / np.maximum(lam, 1e-12)).sum(axis=1)
    strength = np.where(inv_diag > 0, 1.0 / inv_diag, 0.0)
    strength = np.where(strength < 1e-12, 0.0, strength)
    # the weakest combination with one lever arm for all rotations (eigenvectors depend on it)
    m = float(np.sqrt(np.mean(L**2)))
    s1 = np.concatenate([np.full(3, 1 / m), np.ones(3)])
    H1 = np.asarray(information, dtype=np.float64) * np.outer(s1, s1) / points
    lam1, V1 = np.linalg.eigh((H1 + H1.T) / 2)
    return strength, max(float(lam1[0]), 0.0), V1[:, 0]


def spread(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """How points spread in 3D: standard deviation per axis and along the principal axes.

    Parameters
    ----------
    points : (N, 3) float64, metres

    Returns
    -------
    std_xyz : (3,) float64, metres
        Standard deviation along x, y, z (zeros for fewer than two points).
    std_principal : (3,) float64, metres
        Standard deviations along the principal axes, largest first: a line has one large
        value, a plane two, a volume three.

    Examples
    --------
    >>> import numpy as np
    >>> line = np.stack([np.arange(5.0), np.zeros(5), np.zeros(5)], axis=1)
    >>> [v.round(3).tolist() for v in spread(line)]
    [[1.414, 0.0, 0.0], [1.414, 0.0, 0.0]]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return np.zeros(3), np.zeros(3)
    c = p - p.mean(axis=0)
    cov = c.T @ c / len(p)
    ev = np.sqrt(np.clip(np.linalg.eigvalsh(cov)[::-1], 0.0, None))
    return np.sqrt(np.diag(cov)), ev


__all__ = [
    "AXES",
    "axis_strength",
    "classify_points",
    "classify_points_at",
    "measured_image",
    "open_space_witnesses",
    "overlap_score",
    "plane_information",
    "range_slack",
    "soft_score",
    "spread",
]
