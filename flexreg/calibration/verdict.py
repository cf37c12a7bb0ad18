"""Whether a calibration can be trusted: the geometry of its correspondences.

PnP needs pairs that pin the camera down from several directions. Its answer is unreliable when
the pairs are nearly degenerate, even though the reprojection error looks small:

* **few inliers** -- with fewer than ``verdict_min_inliers`` agreeing pairs, one wrong pair
  cannot be told from a right one;
* **coplanar lidar points** -- a plane admits a second, mirrored pose that projects it almost
  the same way (the planar PnP ambiguity); it is computed (``cv2.SOLVEPNP_IPPE``) and listed as
  the runner-up when it explains the pairs at least half as well;
* **lidar points near one line** -- rotation about the line is barely constrained; points
  *on* one line (within ``collinear_ratio`` of their extent) leave it free: a camera turned
  about that line sees them exactly the same, so PnP has no answer and calibration fails;
* **pixels in one small region** of the image -- the pose is held by a narrow cone of rays;
* **weak axes** -- the pose's standard deviation about or along any camera axis, from the
  information matrix of the reprojection (pixel noise = the inliers' RMS error per axis, at
  least 0.5 px), exceeds ``verdict_max_rotation_std_deg`` / ``verdict_max_translation_std_m``.

The thresholds live in :class:`~flexreg.calibration.config.CalibrationConfig`; how they were
chosen is in docs/calibration.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.calibration.config import CalibrationConfig
from flexreg.core.correspondences import Correspondences2D3D
from flexreg.core.results import Hypothesis, Reason, Verdict
from flexreg.core.transforms import rotation_about_axis, rotation_error_deg, translation_error_m
from flexreg.errors import CalibrationError
from flexreg.io.intrinsics import CameraIntrinsics
from flexreg.stages.camera_pose import from_rvec_tvec, project_points, to_rvec_tvec

__all__ = [
    "MIN_PIXEL_NOISE_PX",
    "calibration_verdict",
    "image_coverage",
    "point_spread",
    "pose_std",
    "require_determined",
]

#: pixel noise assumed at least (pixels per axis) when the inliers fit better than that
MIN_PIXEL_NOISE_PX = 0.5
#: thin sets up to this many times ``verdict_planar_ratio`` are searched for a mirrored pose
PLANAR_SEARCH = 5.0
#: camera axes: rotation about x tilts, about y pans, about z rolls (x right, y down, z forward)
ROTATION_AXES = ("x_tilt", "y_pan", "z_roll")
TRANSLATION_AXES = ("x_right", "y_down", "z_forward")


def point_spread(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3,) float64 standard deviations of ``points`` along their principal axes, largest
    first, metres.

    Examples
    --------
    >>> point_spread(np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0]])).round(3).tolist()
    [1.0, 1.0, 0.0]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) < 2:
        return np.zeros(3)
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False) / math.sqrt(len(p))
    return np.pad(s, (0, 3 - len(s)))


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else 0.0


def image_coverage(pixels: NDArray[np.float64], width: float, height: float) -> float:
    """Share of the image inside the convex hull of ``pixels`` (0 for fewer than 3 or
    collinear pixels)."""
    from scipy.spatial import ConvexHull, QhullError

    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    if len(p) < 3:
        return 0.0
    try:
        area = float(ConvexHull(p).volume)  # in 2D, "volume" is the area
    except QhullError:
        return 0.0
    return min(1.0, area / (width * height))


def _perturbed(T: NDArray[np.float64], k: int, h: float) -> NDArray[np.float64]:
    """``T`` moved by ``h`` along camera-frame parameter ``k`` (0-2 rotation, 3-5 shift)."""
    D = np.eye(4)
    if k < 3:
        D[:3, :3] = rotation_about_axis(np.eye(3)[k], h)
    else:
        D[k - 3, 3] = h
    return D @ T


def pose_std(
    points: NDArray[np.float64],
    intrinsics: CameraIntrinsics,
    T_camera_lidar: NDArray[np.float64],
    *,
    noise_px: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Standard deviation of the pose about and along each camera axis.

    The covariance is ``noise_px² (JᵀJ)⁻¹`` with ``J`` the (2N, 6) Jacobian of the projected
    pixels with respect to a small rotation (radians) and shift (metres) of the camera frame
    (central differences through :func:`~flexreg.stages.camera_pose.project_points`, lens
    distortion included).

    Returns
    -------
    rotation_deg : (3,) float64, degrees
        About camera x (tilt), y (pan), z (roll); ``inf`` where the pairs do not constrain it.
    translation_m : (3,) float64, metres
        Along camera x (right), y (down), z (forward).
    """
    h = 1e-6
    cols = []
    for k in range(6):
        plus, _ = project_points(points, intrinsics, _perturbed(T_camera_lidar, k, h))
        minus, _ = project_points(points, intrinsics, _perturbed(T_camera_lidar, k, -h))
        cols.append(((plus - minus) / (2 * h)).reshape(-1))
    J = np.nan_to_num(np.column_stack(cols))
    eig, vec = np.linalg.eigh(J.T @ J)
    tiny = eig <= max(float(eig.max(initial=0.0)), 1e-300) * 1e-12
    inv = np.zeros(6)
    inv[~tiny] = 1.0 / eig[~tiny]
    var = (vec**2) @ inv
    var[((vec**2)[:, tiny] > 1e-12).any(axis=1)] = np.inf  # moves no pixel: not held at all
    std = noise_px * np.sqrt(var)
    return np.degrees(std[:3]), std[3:]


def require_determined(
    correspondences: Correspondences2D3D, *, config: CalibrationConfig, what: str = "pairs"
) -> None:
    """Refuse lidar points on one line: PnP cannot determine a pose from them.

    A camera turned about the line sees every point on it at the same pixel, so a whole family
    of poses explains the pairs equally well.

    Raises
    ------
    CalibrationError
        The second principal spread of the points is below ``config.collinear_ratio`` of the
        first.
    """
    s = point_spread(correspondences.points)
    if len(correspondences) >= 2 and _ratio(s[1], s[0]) < config.collinear_ratio:
        raise CalibrationError(
            f"{correspondences.source or 'correspondences'}: the {len(correspondences)} {what}' "
            f"lidar points lie on one line (within {100 * _ratio(s[1], s[0]):.2g} % of their "
            f"{2 * s[0]:.2f} m extent): a camera turned about that line sees them the same, so "
            "the pose is not determined; add pairs whose points lie off that line"
        )


def _mirror_pose(
    c: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    T: NDArray[np.float64],
    rmse_px: float,
) -> Hypothesis | None:
    """The second pose of a planar set (IPPE), refined, when it differs from ``T``."""
    import cv2

    K, dist = np.asarray(intrinsics.K), np.asarray(intrinsics.distortion, dtype=np.float64)
    obj, img = np.ascontiguousarray(c.points), np.ascontiguousarray(c.pixels)
    try:
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:
        return None
    poses = [from_rvec_tvec(r, t) for r, t in zip(rvecs, tvecs, strict=True)]
    if not poses:
        return None
    other = max(poses, key=lambda P: rotation_error_deg(P, T))
    if rotation_error_deg(other, T) < 1.0:
        return None
    r0, t0 = to_rvec_tvec(other)
    try:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, r0.reshape(3, 1), t0.reshape(3, 1))
    except cv2.error:
        return None
    other = from_rvec_tvec(rvec, tvec)
    uv, z = project_points(c.points, intrinsics, other)
    if not np.all(z > 0):
        return None
    rmse_other = float(np.sqrt(np.mean(np.sum((uv - c.pixels) ** 2, axis=1))))
    ratio = min(1.0, max(rmse_px, 1e-9) / max(rmse_other, 1e-9))
    if ratio < 0.5 or rotation_error_deg(other, T) < 1.0:
        return None
    return Hypothesis(
        T_target_source=other,
        score_ratio=ratio,
        rotation_deg=rotation_error_deg(other, T),
        translation_m=translation_error_m(other, T),
        origin=f"mirrored planar pose, RMSE {rmse_other:.2f} px",
    )


def _size(intrinsics: CameraIntrinsics) -> tuple[float, float]:
    if intrinsics.size is not None:
        return float(intrinsics.size[0]), float(intrinsics.size[1])
    K = np.asarray(intrinsics.K)
    return 2.0 * float(K[0, 2]) + 1.0, 2.0 * float(K[1, 2]) + 1.0


def calibration_verdict(
    correspondences: Correspondences2D3D,
    inlier_mask: NDArray[np.bool_],
    intrinsics: CameraIntrinsics,
    T_camera_lidar: NDArray[np.float64],
    *,
    config: CalibrationConfig,
) -> Verdict:
    """The verdict on a PnP solution from the geometry of its inlier pairs (module notes).

    Raises
    ------
    CalibrationError
        The inliers' lidar points lie on one line (:func:`require_determined`).
    """
    c = correspondences.subset(inlier_mask)
    require_determined(c, config=config, what="inlier pairs")
    n = len(c)
    s = point_spread(c.points)
    planar, linear = _ratio(s[2], s[0]), _ratio(s[1], s[0])
    W, H = _size(intrinsics)
    coverage = image_coverage(c.pixels, W, H)
    uv, _ = project_points(c.points, intrinsics, T_camera_lidar)
    rmse = float(np.sqrt(np.mean(np.sum((uv - c.pixels) ** 2, axis=1)))) if n else math.nan
    noise = max(rmse / math.sqrt(2.0), MIN_PIXEL_NOISE_PX)
    rot_std, trans_std = pose_std(c.points, intrinsics, T_camera_lidar, noise_px=noise)
    reasons: list[Reason] = []
    runner_up: list[Hypothesis] = []
    if n < config.verdict_min_inliers:
        reasons.append(
            Reason(
                "few_inliers",
                f"only {n} pairs agree on the pose (at least {config.verdict_min_inliers} "
                "wanted): a wrong pair among them could not be noticed",
            )
        )
    if linear < config.verdict_line_ratio:
        reasons.append(
            Reason(
                "collinear_points",
                f"the lidar points lie near one line ({100 * linear:.1f} % as wide as long): "
                "rotation about that line is barely held",
            )
        )
    else:
        reason, mirror = _planar(c, intrinsics, T_camera_lidar, rmse, planar, config)
        reasons += [reason] if reason is not None else []
        runner_up += [mirror] if mirror is not None else []
    if coverage < config.verdict_min_image_coverage:
        reasons.append(
            Reason(
                "clustered_pixels",
                f"the pixels cover {100 * coverage:.1f} % of the image (at least "
                f"{100 * config.verdict_min_image_coverage:.0f} % wanted): one small region "
                "holds the pose poorly",
            )
        )
    reasons += _weak_axes(rot_std, trans_std, config)
    evidence: dict[str, Any] = {
        "inliers": n,
        "correspondences": len(correspondences),
        "point_spread_m": s.tolist(),
        "thickness_ratio": planar,
        "width_ratio": linear,
        "image_coverage": coverage,
        "noise_px": noise,
        "rotation_std_deg": dict(zip(ROTATION_AXES, _finite(rot_std), strict=True)),
        "translation_std_m": dict(zip(TRANSLATION_AXES, _finite(trans_std), strict=True)),
    }
    if reasons:
        return Verdict("uncertain", tuple(reasons), evidence, tuple(runner_up))
    return Verdict("confident", (), evidence)


def _planar(
    c: Correspondences2D3D,
    intrinsics: CameraIntrinsics,
    T: NDArray[np.float64],
    rmse_px: float,
    planar: float,
    config: CalibrationConfig,
) -> tuple[Reason | None, Hypothesis | None]:
    """The ``coplanar_points`` reason and the mirrored pose: points within
    ``verdict_planar_ratio`` of one plane always; points up to :data:`PLANAR_SEARCH` times
    thicker only when a mirrored pose fits them at least half as well."""
    if planar >= PLANAR_SEARCH * config.verdict_planar_ratio:
        return None, None
    mirror = _mirror_pose(c, intrinsics, T, rmse_px)
    if mirror is None and planar >= config.verdict_planar_ratio:
        return None, None
    extra = (
        ""
        if mirror is None
        else f"; a pose {mirror.rotation_deg:.1f}° and {mirror.translation_m:.2f} m away fits "
        f"{100 * mirror.score_ratio:.0f} % as well"
    )
    reason = Reason(
        "coplanar_points",
        f"the lidar points lie on one plane ({100 * planar:.1f} % as thick as wide): a mirrored "
        f"second pose can fit them almost as well{extra}; add pairs off that plane",
    )
    return reason, mirror


def _finite(x: NDArray[np.float64]) -> list[float | None]:
    """JSON has no infinity: an unconstrained axis is None."""
    return [float(v) if math.isfinite(v) else None for v in x]


def _weak_axes(
    rot_std: NDArray[np.float64], trans_std: NDArray[np.float64], config: CalibrationConfig
) -> list[Reason]:
    """A ``weak_axis`` reason naming the camera axes the pairs hold too loosely."""

    def name(axis: str) -> str:
        return axis.replace("_", " (") + ")"

    weak = [
        f"rotation about {name(axis)} " + (f"±{v:.2f}°" if math.isfinite(v) else "free")
        for axis, v in zip(ROTATION_AXES, rot_std, strict=True)
        if not v <= config.verdict_max_rotation_std_deg
    ]
    weak += [
        f"position along {name(axis)} " + (f"±{100 * v:.1f} cm" if math.isfinite(v) else "free")
        for axis, v in zip(TRANSLATION_AXES, trans_std, strict=True)
        if not v <= config.verdict_max_translation_std_m
    ]
    if not weak:
        return []
    return [Reason("weak_axis", "the pairs hold the pose loosely: " + ", ".join(weak))]
