"""Camera pose from 2D-3D correspondences: projection with lens distortion, reprojection errors
and Perspective-n-Point (RANSAC + Levenberg-Marquardt).

``T_camera_lidar`` is a 4 x 4 float64 rigid transform mapping lidar-frame points (metres) into
the camera frame (OpenCV: x right, y down, z forward): ``p_camera = R p_lidar + t``. Pixels are
those of the image as taken (distorted); the lens model is OpenCV's. The camera is any object
with ``K`` (3 x 3) and ``distortion`` (OpenCV coefficients) -- :class:`Lens`, which
:class:`flexreg.io.intrinsics.CameraIntrinsics` satisfies.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.correspondences import Correspondences2D3D
from flexreg.errors import CalibrationError, InputError

log = logging.getLogger(__name__)

__all__ = [
    "MIN_CORRESPONDENCES",
    "Lens",
    "PnPResult",
    "distort_pixels",
    "distortion_coefficients",
    "from_rvec_tvec",
    "project_points",
    "reprojection_errors",
    "solve_pnp",
    "to_rvec_tvec",
]

#: fewest 2D-3D correspondences accepted (PnP needs 4; 6 leave RANSAC something to check)
MIN_CORRESPONDENCES = 6


class Lens(Protocol):
    """What the pose functions need of a camera: the pinhole matrix and OpenCV distortion."""

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) float64 camera matrix, pixels."""
        ...

    @property
    def distortion(self) -> NDArray[np.float64]:
        """OpenCV distortion coefficients ``k1, k2, p1, p2[, k3, ...]`` (may be empty)."""
        ...


@dataclass(eq=False)
class PnPResult:
    """The pose :func:`solve_pnp` found and its inliers.

    Attributes
    ----------
    T_camera_lidar : (4, 4) float64
        Maps lidar points into the camera frame, metres.
    inlier_mask : (N,) bool
        Pairs in front of the camera within ``threshold_px`` of their projection.
    residuals_px : (N,) float64, pixels
        Reprojection error of every pair (inf behind the camera).
    threshold_px : float, pixels
    timings_s : dict of str to float
        ``"ransac"`` and ``"refine"``.
    """

    T_camera_lidar: NDArray[np.float64]
    inlier_mask: NDArray[np.bool_]
    residuals_px: NDArray[np.float64]
    threshold_px: float
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def inliers(self) -> int:
        """Number of inlier pairs."""
        return int(np.count_nonzero(self.inlier_mask))


def to_rvec_tvec(T: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """OpenCV's ``(rvec (3,), tvec (3,))`` of a rigid transform (Rodrigues rotation vector,
    radians)."""
    import cv2  # heavy: OpenCV loads only when a pose is computed

    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    return np.asarray(rvec, dtype=np.float64).reshape(3), np.array(T[:3, 3], dtype=np.float64)


def from_rvec_tvec(rvec: ArrayLike, tvec: ArrayLike) -> NDArray[np.float64]:
    """(4, 4) float64 rigid transform from OpenCV's rotation vector and translation."""
    import cv2  # heavy: OpenCV loads only when a pose is computed

    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).reshape(3)
    return T


def distortion_coefficients(lens: Lens) -> NDArray[np.float64]:
    """The lens's OpenCV distortion coefficients; five zeros when it has none."""
    d = np.array(lens.distortion, dtype=np.float64)
    return d if d.size else np.zeros(5)


def project_points(
    points: ArrayLike, intrinsics: Lens, T_camera_lidar: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project lidar points into the camera image, lens distortion included.

    ``x = K distort(R p + t)`` (paper eq. 1 with OpenCV's distortion model), via
    ``cv2.projectPoints``.

    Parameters
    ----------
    points : (N, 3) float, metres, lidar frame
    intrinsics : Lens
        E.g. :class:`flexreg.io.intrinsics.CameraIntrinsics`.
    T_camera_lidar : (4, 4) float

    Returns
    -------
    uv : (N, 2) float64, pixels
        NaN for points not in front of the camera (``z <= 0``).
    z : (N,) float64, metres
        Depth in the camera frame.

    Examples
    --------
    >>> from flexreg.io.intrinsics import CameraIntrinsics
    >>> K = [[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]
    >>> uv, z = project_points([[0.1, -0.2, 2.0]], CameraIntrinsics(K, []), np.eye(4))
    >>> uv.round(6).tolist(), z.tolist()
    ([[345.0, 190.0]], [2.0])
    """
    import cv2  # heavy: OpenCV loads only when a pose is computed

    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    z = P @ T[2, :3] + T[2, 3]
    uv = np.full((len(P), 2), np.nan)
    front = z > 0
    if front.any():
        rvec, tvec = to_rvec_tvec(T)
        proj, _ = cv2.projectPoints(
            np.ascontiguousarray(P[front]),
            rvec,
            tvec,
            np.array(intrinsics.K),
            distortion_coefficients(intrinsics),
        )
        uv[front] = proj.reshape(-1, 2)
    return uv, z


def distort_pixels(uv: NDArray[np.float64], intrinsics: Lens) -> NDArray[np.float64]:
    """Undistorted pixel coordinates -> the distorted image's (OpenCV model).

    Parameters
    ----------
    uv : (N, 2) float64, pixels
        Positions in the distortion-free image with the same ``K``.
    intrinsics : Lens

    Returns
    -------
    (N, 2) float64, pixels
        ``uv`` itself when the lens has no distortion.
    """
    import cv2  # heavy: OpenCV loads only when a pose is computed

    d = np.array(intrinsics.distortion, dtype=np.float64)
    if not np.any(d != 0) or len(uv) == 0:
        return uv
    K = np.asarray(intrinsics.K, dtype=np.float64)
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    rays = np.column_stack([x, y, np.ones_like(x)])
    out, _ = cv2.projectPoints(
        rays, np.zeros(3), np.zeros(3), np.array(K), distortion_coefficients(intrinsics)
    )
    return np.asarray(out.reshape(-1, 2), dtype=np.float64)


def reprojection_errors(
    correspondences: Correspondences2D3D,
    intrinsics: Lens,
    T_camera_lidar: ArrayLike,
) -> NDArray[np.float64]:
    """(N,) float64 distance in pixels between each pixel and its point's projection; ``inf``
    for points behind the camera."""
    uv, z = project_points(correspondences.points, intrinsics, T_camera_lidar)
    err = np.linalg.norm(uv - correspondences.pixels, axis=1)
    err[~(z > 0)] = np.inf
    return err


def _inliers(
    c: Correspondences2D3D, intrinsics: Lens, T: NDArray[np.float64], thr: float
) -> NDArray[np.bool_]:
    err = reprojection_errors(c, intrinsics, T)
    return np.asarray(err <= thr)


def solve_pnp(
    correspondences: Correspondences2D3D,
    intrinsics: Lens,
    *,
    threshold_px: float = 3.0,
    confidence: float = 0.9999,
    max_iterations: int = 10000,
    seed: int = 0,
    refine: bool = True,
) -> PnPResult:
    """``T_camera_lidar`` from 2D-3D pairs: PnP in MAGSAC++ RANSAC, then Levenberg-Marquardt.

    ``cv2.solvePnPRansac`` with OpenCV's USAC framework (MAGSAC++ scoring, seeded by ``seed``)
    finds the pose and its inliers; ``cv2.solvePnPRefineLM`` then minimises the reprojection
    error of the inliers, and the inliers are re-selected under the refined pose (until they no
    longer change, at most 5 times). A pair is an inlier when its point lies in front of the
    camera and reprojects within ``threshold_px``.

    Parameters
    ----------
    correspondences : Correspondences2D3D
        At least :data:`MIN_CORRESPONDENCES` pairs.
    intrinsics : Lens
        Pixels are distorted image coordinates; the distortion is modelled, not removed.
    threshold_px : float, pixels
        Inlier threshold on the reprojection error.
    confidence : float
        RANSAC confidence in (0, 1).
    max_iterations : int
        RANSAC iteration cap.
    seed : int
        Seed of OpenCV's USAC random generator (same seed, same result).
    refine : bool
        Levenberg-Marquardt refinement on the inliers.

    Returns
    -------
    PnPResult

    Raises
    ------
    InputError
        Fewer than :data:`MIN_CORRESPONDENCES` pairs.
    CalibrationError
        RANSAC finds no pose with at least :data:`MIN_CORRESPONDENCES` inliers in front of the
        camera.
    """
    import cv2  # heavy: OpenCV loads only when a pose is computed

    t0 = time.perf_counter()
    c = correspondences
    if len(c) < MIN_CORRESPONDENCES:
        raise InputError(
            c.source or "correspondences",
            f"only {len(c)} correspondence(s); PnP needs at least {MIN_CORRESPONDENCES}",
        )
    thr = float(threshold_px)
    obj = np.ascontiguousarray(c.points)
    img = np.ascontiguousarray(c.pixels)
    K, dist = np.array(intrinsics.K), distortion_coefficients(intrinsics)
    params = cv2.UsacParams()
    params.score = cv2.SCORE_METHOD_MAGSAC
    params.sampler = cv2.SAMPLING_UNIFORM
    params.threshold = thr
    params.confidence = confidence
    params.maxIterations = max_iterations
    params.randomGeneratorState = seed
    params.loMethod = cv2.LOCAL_OPTIM_SIGMA
    params.loIterations = 10
    params.loSampleSize = min(14, len(c))
    params.final_polisher = cv2.NONE_POLISHER
    try:
        ok, _, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, K, dist, params=params)
    except cv2.error as e:
        raise CalibrationError(f"PnP failed on {len(c)} correspondences: {e.err}") from None
    if not ok or inl is None or len(inl) < 4:
        raise CalibrationError(
            f"RANSAC found no pose explaining at least 4 of {len(c)} correspondences within "
            f"{thr:g} px"
        )
    T = from_rvec_tvec(rvec, tvec)
    t_ransac = time.perf_counter() - t0
    mask = _inliers(c, intrinsics, T, thr)
    if refine:
        for _ in range(5):
            if np.count_nonzero(mask) < 4:
                break
            rvec, tvec = to_rvec_tvec(T)
            rvec, tvec = cv2.solvePnPRefineLM(
                obj[mask],
                img[mask],
                K,
                dist,
                rvec.reshape(3, 1),
                tvec.reshape(3, 1),
                (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12),
            )
            T = from_rvec_tvec(rvec, tvec)
            new = _inliers(c, intrinsics, T, thr)
            if np.array_equal(new, mask):
                break
            mask = new
    res = reprojection_errors(c, intrinsics, T)
    n_in = int(np.count_nonzero(mask))
    if n_in < MIN_CORRESPONDENCES:
        raise CalibrationError(
            f"only {n_in} of {len(c)} correspondences agree on one pose within {thr:g} px "
            f"(at least {MIN_CORRESPONDENCES} needed)"
        )
    timings = {"ransac": t_ransac, "refine": time.perf_counter() - t0 - t_ransac}
    log.info(
        "PnP: %d/%d inliers, RMSE %.3f px", n_in, len(c), float(np.sqrt(np.mean(res[mask] ** 2)))
    )
    return PnPResult(
        T_camera_lidar=T, inlier_mask=mask, residuals_px=res, threshold_px=thr, timings_s=timings
    )
