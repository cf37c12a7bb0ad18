"""Duels at the scans' full resolution: where two poses disagree, a small unique object decides.

The dense check's duel (:func:`flexreg.registration.check.duel`) counts, on each scan's even
sample of about 20 000 points, the points one pose explains and the other puts in open space.
A small cue near the stations (a forklift, a niche, a bookshelf) holds a few dozen of them,
no more than the edges of a repeating structure put on both sides. Here the valid pixels of
both range images take part, one per about equal solid angle, so objects near the scanners
weigh what they cover, and the tests are built so that nothing but a real disagreement
counts:

* a point *explains* a pose when the other scanner measured its range along its ray (half an
  inlier threshold plus 0.2 % of the range plus the pixel's range slack);
* a point lies in *open space* only when the other scanner saw farther than it along the whole
  5 x 5 neighbourhood of its pixel, by more than the free-space tolerance (2.5 inlier
  thresholds plus 1 % of the range) plus the point's own range slack: thin bars, hangers and
  silhouettes seen from two viewpoints do not count. A pixel without a return in that square
  leaves the point unknown on a sensor's own grid (the ray may have met something dark);
  on a cloud projected into an image with gaps between its returns (a narrow-field lidar's
  rosette, a fused fragment: :func:`~flexreg.stages.projection.sampling_gaps`) an empty
  pixel is a direction never sampled, and the square's returns alone bound the open space
  around a returned pixel;
* points on their own scan's silhouettes (range slack above :data:`MAX_SLACK_PER_M` of their
  range) take no part, and each scan's points are thinned to one per about equal solid angle
  (:func:`even_solid_angle`: a panorama's rows near its poles hold many times the points of
  its equator per square metre);
* a point explains nothing where the other scanner would have seen its surface from behind
  (:data:`BEHIND_COS`): a wall's two faces, seen from the rooms either side, do not fit.

Under two poses of a symmetric or repeating scene the same surfaces fit, so both poses explain
the same points: only where they disagree, on the cue, does one pose explain what the other
puts in open space. :func:`pose_masks` gives a pose's masks; the dense check's
:func:`~flexreg.registration.check.duel` compares two of them. The tolerances are the dense
check's (:data:`~flexreg.registration.check.TOLERANCE`).
"""

from __future__ import annotations

import math
import weakref
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import RangeImage
from flexreg.core.transforms import invert
from flexreg.registration.check import TOLERANCE, Masks
from flexreg.stages.normals import grid_normals
from flexreg.stages.refinement.projective import camera_params, spherical_pixel
from flexreg.stages.viewpoint import one_viewpoint

#: points whose own range slack exceeds this share of their range (silhouettes, grazing
#: surfaces beyond about 3 degrees of incidence) take no part in a full-resolution duel
MAX_SLACK_PER_M = 0.05

#: the open-space test looks at the smallest range over this many pixels square around a
#: point's pixel: a thin bar, a cabinet's edge or a sill seen edge-on covers less than a pixel
#: of a distant scanner while the near one resolves it (3 x 3 left 30-200 such points on
#: right poses of the synthetic tunnels and arcades, 5 x 5 none to two)
NEIGHBOURHOOD = 5

#: a point whose normal (towards its own scanner), turned into the other scan's frame,
#: points away from that scanner by more than this cosine (about 15 degrees beyond grazing)
#: lies on a surface that scanner saw from behind, if at all: it explains nothing there. The
#: two faces of an interior wall, seen from the rooms either side, otherwise fit a pose slid
#: by the wall's thickness (10.6 % of a doorway pair's points at such a pose, about 1 % on
#: right poses: thin boards seen from both sides, normals a few degrees off on grazing
#: surfaces; docs/benchmarks.md)
BEHIND_COS = 0.25


@dataclass(eq=False)
class FullView:
    """One scan at full resolution, as the other scan's points are checked against it and as
    its own points are checked against the other.

    Attributes
    ----------
    image : RangeImage
        The working range image, with a camera model.
    measured, slack : (H, W) float32
        What it measured per pixel and the pixel's range slack
        (:func:`~flexreg.stages.verification.range_slack`).
    nearest : (H, W) float32 (the measured image's type), metres
        The smallest measured range over each pixel's :data:`NEIGHBOURHOOD` square; ``-inf`` where a
        neighbour has no return (nothing is known to be open there), or, on an image with
        :func:`~flexreg.stages.projection.sampling_gaps`, the smallest over the square's
        returns where the pixel itself has one (``-inf`` where it has none).
    points : (N, 3) float32 or float64 (the image's type), metres
        Its valid points off its own silhouettes (see :data:`MAX_SLACK_PER_M`), thinned to
        about one per equal solid angle (:func:`even_solid_angle`).
    point_slack : (N,) float32 or float64, metres
        Their own range slack.
    normals : (N, 3) float32 (the normals' type)
        Their unit normals (:func:`~flexreg.stages.normals.grid_normals`), own frame; NaN
        where unknown.
    """

    image: RangeImage
    measured: NDArray[np.float32]
    slack: NDArray[np.float32]
    nearest: NDArray[np.floating[Any]]
    points: NDArray[np.floating[Any]]
    point_slack: NDArray[np.floating[Any]]
    normals: NDArray[np.floating[Any]]

    def take(self, which: Any) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]]:
        """Its points, their slack and their normals at ``which`` (a slice, indices or a
        mask), contiguous: the arguments of :func:`full_masks` and the scores for a subset."""
        c = np.ascontiguousarray
        return c(self.points[which]), c(self.point_slack[which]), c(self.normals[which])


def full_view(
    image: RangeImage,
    measured: NDArray[np.float32],
    slack: NDArray[np.float32],
    normals: NDArray[np.float32] | None = None,
    *,
    max_slack_per_m: float = MAX_SLACK_PER_M,
    free_space: bool = True,
    gaps: bool = False,
) -> FullView:
    """A :class:`FullView` of a range image (with a camera model).

    Parameters
    ----------
    image : RangeImage
    measured, slack : (H, W) float32
        :func:`~flexreg.stages.verification.measured_image` and
        :func:`~flexreg.stages.verification.range_slack` of ``image``.
    normals : (H, W, 3) float32, optional
        Its :func:`~flexreg.stages.normals.grid_normals` (computed when not given).
    max_slack_per_m : float
        Points whose own slack exceeds this share of their range are left out.
    gaps : bool
        The image is a cloud projected with gaps between its returns
        (:attr:`~flexreg.registration.preparation.ScanView.gaps`): an empty pixel is a
        direction never sampled, and the returns of a returned pixel's square bound its open
        space.
    free_space : bool
        False for a cloud not taken from one point
        (:func:`~flexreg.stages.viewpoint.one_viewpoint`): nothing is known to be open space
        in its view (``nearest`` is ``-inf`` everywhere).

    Returns
    -------
    FullView
    """
    # the scan's own types (float32 from every reader): the checks promote each value to
    # float64 as they read it, so they test exactly what float64 copies would hold
    m = np.asarray(measured)
    seen = np.isfinite(m)
    modes = ["nearest", "wrap" if image.wraps else "nearest"]
    if not free_space:
        nearest = np.full(m.shape, -np.inf, dtype=m.dtype)
    elif gaps:  # empty pixels are unsampled: the returns bound it
        near = ndimage.minimum_filter(
            np.where(seen, m, np.array(np.inf, dtype=m.dtype)), size=NEIGHBOURHOOD, mode=modes
        )
        nearest = np.where(seen, near, np.array(-np.inf, dtype=m.dtype))
    else:
        m = np.where(seen, m, np.array(-np.inf, dtype=m.dtype))
        nearest = ndimage.minimum_filter(m, size=NEIGHBOURHOOD, mode=modes)
    valid = image.valid
    pts = image.xyz[valid]
    own = np.asarray(slack)[valid]
    keep = own <= max_slack_per_m * np.sqrt(np.einsum("ij,ij->i", pts, pts, dtype=np.float64))
    keep &= even_solid_angle(image)
    n = grid_normals(image) if normals is None else normals
    return FullView(image, measured, slack, nearest, pts[keep], own[keep], n[valid][keep])


def even_solid_angle(image: RangeImage) -> NDArray[np.bool_]:
    """Which valid pixels (row-major, as ``image.xyz[image.valid]``) to keep so that each kept
    one stands for about the same solid angle.

    A panorama's pixel covers ``sin(theta)`` of the solid angle of one on its equator (eq. 7:
    equal steps in azimuth and polar angle), so the ceiling straight above a scanner holds
    ten times the points per square metre of its walls at the same range; a pinhole's pixel
    ``cos^3`` of its principal ray's (eq. 1). Counted point by point, a full-resolution test
    then lets a pose win by laying one scan's dense patch above its scanner into a doorway
    the other scanner sees the ceiling through (docs/benchmarks.md). Each row keeps that share
    of its pixels, evenly spaced (the shares' running sum over the pixels in row-major order:
    a pixel is kept where it passes a whole number); an image without a camera keeps all.

    Returns
    -------
    (N,) bool
    """
    cam = image.camera
    v, u = np.nonzero(image.valid)
    if isinstance(cam, SphericalCamera):
        share = np.abs(np.sin(cam.theta_min + v * cam.dtheta))
    elif isinstance(cam, PinholeCamera):
        x, y = cam.normalized(u.astype(np.float64), v.astype(np.float64))
        share = (1.0 + x * x + y * y) ** -1.5
    else:
        return np.ones(len(v), dtype=bool)
    # from a quarter, so that no common share (a half, a third) lands on whole numbers
    passed = np.floor(np.cumsum(share) + 0.25)
    return np.asarray(np.diff(passed, prepend=0.0) > 0)


#: points a full-resolution check projects together before testing them: the projections of a
#: block (turn, shift, the arc tangents of eq. 4-7) are independent of one another, and done
#: apart from the tests and sums that read their pixels their long chains of arithmetic
#: overlap instead of waiting on each other (about 14 % less time a test than one point at a
#: time, docs/benchmarks.md; the same numbers: each point is projected and tested exactly as
#: before, in order)
BLOCK = 64


@numba.njit(cache=True, nogil=True, inline="always")
def _project_block(spherical, points, i0, m, R, t, cam, W, Q, U, V, D):  # pragma: no cover
    """Points ``i0 .. i0 + m - 1`` turned by ``R``, moved by each ``t[k]`` and projected:
    ``U[k, j]``, ``V[k, j]`` their pixel coordinates before rounding, ``D[k, j]`` their range
    along the ray (``spherical``, eq. 4-7) or depth (pinhole, eq. 1); where that is not
    positive, ``U`` and ``V`` are left as they were (the tests skip the point). ``Q``
    (3, :data:`BLOCK`) takes the turned points."""
    c0, c1, c2, c3, c4 = cam[0], cam[1], cam[2], cam[3], cam[4]
    r00, r01, r02, r10, r11, r12 = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    for j in range(m):
        px = np.float64(points[i0 + j, 0])
        py, pz = np.float64(points[i0 + j, 1]), np.float64(points[i0 + j, 2])
        Q[0, j] = r00 * px + r01 * py + r02 * pz
        Q[1, j] = r10 * px + r11 * py + r12 * pz
        Q[2, j] = r20 * px + r21 * py + r22 * pz
    for k in range(t.shape[0]):
        tx, ty, tz = t[k, 0], t[k, 1], t[k, 2]
        for j in range(m):
            qx, qy, qz = Q[0, j] + tx, Q[1, j] + ty, Q[2, j] + tz
            if spherical:  # range along the ray (eq. 4-7)
                d = math.sqrt(qx * qx + qy * qy + qz * qz)
                if d > 0.0:
                    U[k, j], V[k, j] = spherical_pixel(qx, qy, qz, d, c0, c1, c2, c3, c4, W)
            else:  # pinhole: depth (eq. 1)
                d = qz
                if d > 0.0:
                    x, y = qx / qz, qy / qz
                    U[k, j] = c0 * x + c4 * y + c2
                    V[k, j] = c1 * y + c3
            D[k, j] = d


@numba.njit(cache=True, nogil=True, inline="always")
def _check_loop(
    spherical,
    points,
    own,
    normals,
    R,
    t,
    cam,
    measured,
    slack,
    nearest,
    threshold_m,
    tolerance,
    coarse,
    explained,
    open_space,
    scores,
    opens,
):  # pragma: no cover
    """The loop of :func:`_check_full` for one kind of camera (``spherical`` a constant where
    it is inlined, so the camera's branch leaves the inner loop): the points :data:`BLOCK` at
    a time, projected (:func:`_project_block`), then tested in order."""
    H, W = measured.shape[0], measured.shape[1]
    wrap = spherical and cam[4] > 0.5
    masks = explained.shape[0] == points.shape[0]
    sided = normals.shape[0] == points.shape[0]
    K = t.shape[0]
    fine_rel, free_k, free_rel, behind_cos = tolerance
    free_m = free_k * threshold_m
    explain_m = free_m if coarse else threshold_m / 2
    explain_rel = free_rel if coarse else fine_rel
    total = np.zeros(K)
    bad_count = np.zeros(K, dtype=np.int64)
    Q = np.empty((3, BLOCK))
    U, V, D = np.empty((K, BLOCK)), np.empty((K, BLOCK)), np.empty((K, BLOCK))
    n = points.shape[0]
    for i0 in range(0, n, BLOCK):
        m = min(BLOCK, n - i0)
        _project_block(spherical, points, i0, m, R, t, cam, W, Q, U, V, D)
        for j in range(m):
            own_i = np.float64(own[i0 + j])
            ok = bad = False
            gx = gy = gz = 0.0  # its normal turned into the view's frame (none: no side test)
            if sided:
                a0, a1 = np.float64(normals[i0 + j, 0]), np.float64(normals[i0 + j, 1])
                a2 = np.float64(normals[i0 + j, 2])
                if math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2):
                    gx = R[0, 0] * a0 + R[0, 1] * a1 + R[0, 2] * a2
                    gy = R[1, 0] * a0 + R[1, 1] * a1 + R[1, 2] * a2
                    gz = R[2, 0] * a0 + R[2, 1] * a1 + R[2, 2] * a2
            for k in range(K):
                d = D[k, j]
                if not d > 0.0:
                    continue
                fu, fv = math.floor(U[k, j] + 0.5), math.floor(V[k, j] + 0.5)
                if wrap and fu >= W:
                    fu -= W
                if not (fu >= 0 and fu < W and fv >= 0 and fv < H):  # NaN fails too
                    continue
                iu, iv = int(fu), int(fv)
                e = d - np.float64(measured[iv, iu])
                tol = explain_m + explain_rel * d + np.float64(slack[iv, iu])
                free = free_m + free_rel * d + own_i
                qx, qy, qz = Q[0, j] + t[k, 0], Q[1, j] + t[k, 1], Q[2, j] + t[k, 2]
                # seen from behind: its surface faces away from the view's scanner (a
                # panorama's d is the point's range already)
                rq = d if spherical else math.sqrt(qx * qx + qy * qy + qz * qz)
                behind = gx * qx + gy * qy + gz * qz > behind_cos * rq
                ok = abs(e) < tol and not behind
                bad = d < nearest[iv, iu] - free
                r = e / tol
                total[k] += (1.0 - r * r) if ok else 0.0  # a select, not a branch
                bad_count[k] += bad
            if masks:  # one pose: its tests of this point (none when it falls outside)
                explained[i0 + j] = ok
                open_space[i0 + j] = bad
    for k in range(K):
        scores[k] += total[k] - 3.0 * bad_count[k]
    if opens.shape[0] == K:
        for k in range(K):
            opens[k] += bad_count[k]


@numba.njit(cache=True, nogil=True)
def _check_full(
    points,
    own,
    normals,
    R,
    t,
    kind,
    cam,
    measured,
    slack,
    nearest,
    threshold_m,
    tolerance,
    coarse,
    explained,
    open_space,
    scores,
    opens,
):  # pragma: no cover
    """The tests of :func:`full_masks` and the soft score of :func:`full_score` in one pass over
    the points, without temporaries, for the poses ``(R, t[k])`` at the tolerances
    ``tolerance`` (``fine_rel, free_k, free_rel`` of a
    :class:`~flexreg.registration.check.Tolerance`, then the cosine beyond which a point's
    ``normals`` face away from the view's scanner): each point turned by ``R``
    (once) and moved by each ``t[k]`` into the view's frame, projected through its camera
    (``kind``, ``cam``: :func:`camera_params`) onto the nearest pixel, and tested there.
    Adds each pose's score to ``scores[k]`` (and its count of points in open space to
    ``opens[k]`` when ``opens`` has a slot per pose); fills ``explained`` and ``open_space``
    (one pose) when they are as long as ``points``."""
    if kind == 0:
        _check_loop(
            True, points, own, normals, R, t, cam, measured, slack, nearest, threshold_m,
            tolerance, coarse, explained, open_space, scores, opens,
        )  # fmt: skip
    else:
        _check_loop(
            False, points, own, normals, R, t, cam, measured, slack, nearest, threshold_m,
            tolerance, coarse, explained, open_space, scores, opens,
        )  # fmt: skip


_NO_COUNT = np.zeros(0, dtype=np.int64)
_NO_NORMALS = np.zeros((0, 3), dtype=np.float32)


def _kernel_tolerance() -> tuple[float, float, float, float]:
    """The dense check's :data:`~flexreg.registration.check.TOLERANCE` as the kernel takes it,
    with :data:`BEHIND_COS`: an argument, not a global (a compiled kernel keeps a global's
    value in its cache, and the cache follows this file only)."""
    t = TOLERANCE
    return float(t.fine_rel), float(t.free_k), float(t.free_rel), float(BEHIND_COS)


def _floats(a: NDArray[Any]) -> NDArray[Any]:
    """``a`` contiguous, float32 kept as it is, anything else as float64."""
    a = np.asarray(a)
    return np.ascontiguousarray(a, dtype=a.dtype if a.dtype == np.float32 else np.float64)


def _run_check(
    view: FullView,
    points: NDArray[np.floating[Any]],
    point_slack: NDArray[np.floating[Any]],
    normals: NDArray[np.floating[Any]] | None,
    T: NDArray[np.float64],
    shifts: NDArray[np.float64] | None,
    threshold_m: float,
    coarse: bool,
    explained: NDArray[np.bool_],
    open_space: NDArray[np.bool_],
    opens: NDArray[np.int64] = _NO_COUNT,
) -> NDArray[np.float64]:
    """Scores of ``T`` moved by each of ``shifts`` (``T`` alone when None), masks of ``T``,
    counts of points in open space per pose (into ``opens`` when it has a slot per pose);
    with ``normals`` (the points' own, NaN where unknown) points seen from behind
    (:data:`BEHIND_COS`) explain nothing."""
    T = np.asarray(T, dtype=np.float64)
    t = T[:3, 3][None] if shifts is None else T[:3, 3] + np.asarray(shifts, dtype=np.float64)
    scores = np.zeros(len(t))
    if len(points) == 0 or view.image.camera is None:
        return scores
    kind, cam = camera_params(view.image)
    _check_full(  # float32 inputs stay float32 (read as float64 in the kernel: no copies)
        _floats(points),
        _floats(point_slack),
        _NO_NORMALS if normals is None else _floats(normals),
        np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(t.reshape(-1, 3)), kind, cam,
        np.ascontiguousarray(view.measured, dtype=np.float32),
        np.ascontiguousarray(view.slack, dtype=np.float32),
        _floats(view.nearest),
        float(threshold_m), _kernel_tolerance(), bool(coarse), explained, open_space, scores,
        opens,
    )  # fmt: skip
    return scores


_NO_MASK = np.zeros(0, dtype=bool)


def full_masks(
    view: FullView,
    points: NDArray[np.floating[Any]],
    point_slack: NDArray[np.floating[Any]],
    T_view_points: NDArray[np.float64],
    threshold_m: float,
    *,
    normals: NDArray[np.floating[Any]] | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which of ``points`` a pose explains in ``view`` and which it puts in open space.

    A point maps into the view's frame, falls on the view's nearest pixel (its camera
    model), and is tested there: *explained* when its range (depth for a pinhole view) is
    within the fine tolerance (:meth:`~flexreg.registration.check.Tolerance.fine`: half an
    inlier threshold plus 0.2 % of its range) plus the pixel's range slack of what the view
    measured; in *open space* when it lies nearer than the smallest range of the pixel's
    :data:`NEIGHBOURHOOD` square by more than the free-space tolerance
    (:meth:`~flexreg.registration.check.Tolerance.free`: 2.5 inlier thresholds plus 1 % of its
    range) plus its own range slack. Points outside the view are neither. With their
    ``normals``, points on a surface the view's scanner saw from behind (the normal turned
    away from it beyond :data:`BEHIND_COS`) are not explained: a wall's two faces, seen from
    either side, do not fit one another.

    Parameters
    ----------
    view : FullView
        The scan the points are checked against.
    points : (N, 3) float64, metres
        The other scan's points (its :attr:`FullView.points`).
    point_slack : (N,) float64, metres
        Their own range slack.
    T_view_points : (4, 4) float64
        Maps the points into the view's frame.
    threshold_m : float, metres
        The registration's inlier threshold.
    normals : (N, 3) float32 or float64, optional
        The points' unit normals (their :attr:`FullView.normals`), oriented towards their own
        scanner, NaN where unknown; without them no point is seen from behind.

    Returns
    -------
    explained, open_space : (N,) bool
    """
    explained = np.zeros(len(points), dtype=bool)
    open_space = np.zeros(len(points), dtype=bool)
    _run_check(
        view, points, point_slack, normals, T_view_points, None, threshold_m, False, explained,
        open_space,
    )  # fmt: skip
    return explained, open_space


def full_score(
    view: FullView,
    points: NDArray[np.floating[Any]],
    point_slack: NDArray[np.floating[Any]],
    T_view_points: NDArray[np.float64],
    threshold_m: float,
    *,
    coarse: bool = False,
    normals: NDArray[np.floating[Any]] | None = None,
) -> float:
    """A pose's soft score on full-resolution points: each explained point counts
    ``1 - (e / tol)^2`` (``e`` its range residual, 1 when exact), each point in open space
    ``-3`` (the tests of :func:`full_masks`); the sum, a count of points.

    It peaks where a cue fits exactly, so a pose can be placed along an axis that only the
    cue fixes. With ``coarse`` a point counts as explained within the open-space tolerance
    (for poses not yet polished). ``normals`` as :func:`full_masks`.
    """
    return float(
        _run_check(
            view, points, point_slack, normals, T_view_points, None, threshold_m, coarse,
            _NO_MASK, _NO_MASK,
        )[0]
    )  # fmt: skip


def full_scores(
    view: FullView,
    points: NDArray[np.floating[Any]],
    point_slack: NDArray[np.floating[Any]],
    T_view_points: NDArray[np.float64],
    shifts_m: NDArray[np.float64],
    threshold_m: float,
    *,
    coarse: bool = False,
    normals: NDArray[np.floating[Any]] | None = None,
    open_counts: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """:func:`full_score` of ``T_view_points`` moved by each of ``shifts_m`` (added to its
    translation, view frame), in one pass over the points: each point is turned once and looked
    up at every shift while its pixels are at hand. Equal to calling :func:`full_score` on each
    moved pose, bit for bit.

    Parameters
    ----------
    view, points, point_slack, T_view_points, threshold_m, coarse, normals
        As :func:`full_score`.
    shifts_m : (K, 3) float64, metres
    open_counts : (K,) int64, optional
        Zeros, filled with how many of ``points`` each moved pose puts in open space (the
        test of :func:`full_masks`), in the same pass.

    Returns
    -------
    (K,) float64
    """
    shifts = np.asarray(shifts_m, dtype=np.float64).reshape(-1, 3)
    opens = _NO_COUNT if open_counts is None else open_counts
    return _run_check(
        view, points, point_slack, normals, T_view_points, shifts, threshold_m, coarse,
        _NO_MASK, _NO_MASK, opens,
    )  # fmt: skip


#: bytes of bit-packed :func:`pose_masks` a :class:`FullPair` keeps (the tournament, the
#: rescue and the verdict ask for the same poses): about 0.2 MB a pose at 1024 x 512, 0.8 MB
#: at 2048 x 1024, so a few dozen poses; none at 8192 x 4096 beyond four
MASKS_BUDGET_BYTES = 64 * 2**20


@dataclass(eq=False)
class FullPair:
    """Both scans at full resolution (see :class:`FullView`), with the masks of the poses
    last asked of :func:`pose_masks`, bit-packed, within :data:`MASKS_BUDGET_BYTES`."""

    target: FullView
    source: FullView
    masks: OrderedDict[tuple[bytes, float], list[NDArray[np.uint8]]] = field(
        default_factory=OrderedDict, repr=False
    )

    @property
    def points(self) -> int:
        """How many points a duel checks (both directions)."""
        return len(self.source.points) + len(self.target.points)


def full_pair_of(views: Sequence[Any]) -> Callable[[], FullPair]:
    """Makes both scans at full resolution when a near-tie needs them: ``views`` are the
    target's and the source's prepared views (``image``, ``measured``, ``slack``,
    ``normals``)."""

    def make() -> FullPair:
        target, source = (_full_view_of(v) for v in views)
        return FullPair(target, source)

    return make


#: each prepared view's full view, while the prepared view lives (a survey worker keeps its
#: last stations loaded and registers each in a dozen links)
_FULL_VIEWS: weakref.WeakKeyDictionary[Any, FullView] = weakref.WeakKeyDictionary()


def _full_view_of(v: Any) -> FullView:
    """:func:`full_view` of a prepared view, made once per view object."""
    kw = {
        "free_space": one_viewpoint(getattr(v, "hidden", None)),
        "gaps": bool(getattr(v, "gaps", False)),
    }
    try:
        hit = _FULL_VIEWS.get(v)
    except TypeError:  # not weakly referable: made each time
        return full_view(v.image, v.measured, v.slack, v.normals, **kw)
    if hit is None:
        hit = _FULL_VIEWS[v] = full_view(v.image, v.measured, v.slack, v.normals, **kw)
    return hit


def pose_masks(pair: FullPair, T_target_source: NDArray[np.float64], threshold_m: float) -> Masks:
    """A pose's explained and open-space masks in both directions (the source's points in the
    target's view, then the target's points in the source's view), at full resolution: the
    inputs of :func:`flexreg.registration.check.duel`.

    Parameters
    ----------
    pair : FullPair
    T_target_source : (4, 4) float64
    threshold_m : float, metres
        The registration's inlier threshold.

    Returns
    -------
    ((explained, open_space), (explained, open_space))
    """
    s, t = pair.source, pair.target
    T = np.ascontiguousarray(T_target_source, dtype=np.float64)
    key = (T.tobytes(), float(threshold_m))
    sizes = (len(s.points), len(s.points), len(t.points), len(t.points))
    packed = pair.masks.get(key)
    if packed is not None:
        pair.masks.move_to_end(key)
        a, b, c, d = (
            np.unpackbits(p, count=n).view(bool) for p, n in zip(packed, sizes, strict=True)
        )
        return ((a, b), (c, d))
    out = (
        full_masks(t, s.points, s.point_slack, T, threshold_m, normals=s.normals),
        full_masks(s, t.points, t.point_slack, invert(T), threshold_m, normals=t.normals),
    )
    pair.masks[key] = [np.packbits(m) for direction in out for m in direction]
    while sum(p.nbytes for v in pair.masks.values() for p in v) > MASKS_BUDGET_BYTES:
        pair.masks.popitem(last=False)
    return out


__all__ = [
    "BEHIND_COS",
    "MASKS_BUDGET_BYTES",
    "MAX_SLACK_PER_M",
    "NEIGHBOURHOOD",
    "FullPair",
    "FullView",
    "even_solid_angle",
    "full_masks",
    "full_pair_of",
    "full_score",
    "full_scores",
    "full_view",
    "pose_masks",
]
