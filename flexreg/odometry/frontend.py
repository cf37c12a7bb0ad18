"""The odometry front end: a frame's feature image, keypoints and their 3D points, and the
relative pose of two frames (paper sec. IV-B).

- :func:`feature_image` converts a frame's depth (any Flexion variant, eq. 11-14, or a Bearing
  Angle image, eq. 9-10) or takes its grey colour image, as 8 bits.
- :func:`frame_features` detects and describes keypoints on it and lifts them to 3D.
- :func:`solve_pair` matches two frames and solves ``T_target_source`` with
  :func:`essential_pose` (essential matrix, ``recoverPose``, metric scale from the depth) or
  :func:`svd_pose` (3-point RANSAC and the Kabsch/Umeyama SVD on the lifted points).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.camera import PinholeCamera
from flexreg.core.range_image import RangeImage
from flexreg.errors import DegenerateGeometryError, InputError, RegistrationError
from flexreg.odometry.config import OdometryConfig
from flexreg.odometry.result import PairAttempt
from flexreg.stages import feature_images as images
from flexreg.stages.alignment import ransac_rigid
from flexreg.stages.correspondences import lift
from flexreg.stages.keypoints import Features, detect_and_describe
from flexreg.stages.matching import match

log = logging.getLogger(__name__)

__all__ = [
    "CHEIRALITY_DISTANCE",
    "FrameFeatures",
    "essential_pose",
    "feature_image",
    "frame_features",
    "solve_pair",
    "svd_pose",
]

#: ``recoverPose`` distance beyond which triangulated points count as at infinity
CHEIRALITY_DISTANCE = 1.0e6


def feature_image(
    image: RangeImage,
    config: OdometryConfig = OdometryConfig(),
    *,
    color: NDArray[np.uint8] | None = None,
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image keypoints are detected on, and its valid mask: the depth conversion of
    :func:`flexreg.stages.feature_images.feature_image`, or the frame's grey colour image.

    Parameters
    ----------
    image : RangeImage
        The frame's depth as organised points.
    config : OdometryConfig
        ``image``, ``n``, ``median``, ``fill_holes`` and ``stretch`` are used.
    color : (H, W) uint8, optional
        The grey colour image, required for ``config.image == "color"``.

    Returns
    -------
    image : (H, W) uint8
        Flexion values in [0, 1] or Bearing Angles in [0, pi] mapped to 0..255 (eq. 10), or the
        grey colour image as it is.
    valid : (H, W) bool
        Pixels with a defined value (all True for colour).
    """
    if config.image == "color":
        if color is None:
            raise InputError("color", "a colour feature image needs the frame's colour image")
        g = np.asarray(color)
        if g.ndim != 2 or g.dtype != np.uint8:
            raise InputError(
                "color", f"expected an (H, W) uint8 grey image, got {g.shape} {g.dtype}"
            )
        return g, np.ones(g.shape, dtype=bool)
    return images.feature_image(
        image,
        kind=config.image,
        n=config.n,
        median=config.median,
        stretch=config.stretch,  # type: ignore[arg-type]
        fill_holes=config.fill_holes,
    )


@dataclass(eq=False)
class FrameFeatures:
    """A frame ready for matching: keypoints, descriptors and their 3D points.

    Attributes
    ----------
    index : int
    features : Features
    xyz : (K, 3) float64, metres
        Camera-frame point of each keypoint (bilinear on the depth image), NaN where not
        liftable.
    camera : PinholeCamera or None
        The frame's pinhole camera (needed by the ``essential`` solver).
    """

    index: int
    features: Features
    xyz: NDArray[np.float64] = field(repr=False)
    camera: PinholeCamera | None = None


def frame_features(
    image: RangeImage,
    config: OdometryConfig = OdometryConfig(),
    *,
    color: NDArray[np.uint8] | None = None,
    index: int = 0,
    detector: Any = None,
    converted: tuple[NDArray[np.uint8], NDArray[np.bool_]] | None = None,
    timings: dict[str, float] | None = None,
) -> FrameFeatures:
    """Feature image, keypoints + descriptors, and the keypoints' 3D points of one frame.

    Parameters
    ----------
    image : RangeImage
        The frame's depth as organised points (keypoints are lifted on it).
    config : OdometryConfig
    color : (H, W) uint8, optional
        Grey colour image (for ``config.image == "color"``).
    index : int
        Frame index recorded in the result.
    detector : cv2.Feature2D, optional
        A detector built once for many frames (:func:`flexreg.stages.keypoints.create_detector`).
    converted : (image, valid), optional
        The output of :func:`feature_image` when it is already computed (e.g. shared by
        several detectors).
    timings : dict, optional
        Accumulates seconds in ``image`` and ``features``.
    """
    t = timings if timings is not None else {}
    t0 = time.perf_counter()
    g, valid = converted if converted is not None else feature_image(image, config, color=color)
    if g.shape != image.shape:
        raise InputError(
            "color",
            f"colour image {g.shape[1]}x{g.shape[0]} does not match the depth image "
            f"{image.width}x{image.height}",
        )
    t1 = time.perf_counter()
    feats = detect_and_describe(
        g,
        config.features,
        None if config.image == "color" else valid,
        max_features=config.max_features,
        border_px=config.border_px,
        support=config.support,
        detector=detector,
    )
    t2 = time.perf_counter()
    xyz, _ = lift(image, feats.xy, max_jump=config.max_jump)
    t["image"] = t.get("image", 0.0) + t1 - t0
    t["features"] = t.get("features", 0.0) + time.perf_counter() - t1
    cam = image.camera if isinstance(image.camera, PinholeCamera) else None
    log.debug("frame %d: %d keypoints (%.3f s detection)", index, len(feats), t2 - t1)
    return FrameFeatures(index=index, features=feats, xyz=xyz, camera=cam)


def essential_pose(
    target_xy: NDArray[np.float64],
    source_xy: NDArray[np.float64],
    target_xyz: NDArray[np.float64],
    source_xyz: NDArray[np.float64],
    camera: PinholeCamera,
    *,
    threshold_px: float = 1.0,
    confidence: float = 0.999,
    min_inliers: int = 12,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Relative pose from matched pixels: essential matrix, recoverPose, scale from depth.

    Parameters
    ----------
    target_xy, source_xy : (Q, 2) float64, pixels
        Matched keypoints ``(u, v)`` in the target and source images.
    target_xyz, source_xyz : (Q, 3) float64, metres
        Their 3D points in each camera frame (NaN where the depth is missing).
    camera : PinholeCamera
        Intrinsics of both images (paper eq. 1).
    threshold_px : float, pixels
        RANSAC threshold on the epipolar distance.
    confidence : float
        RANSAC confidence.
    min_inliers : int
        Fewer inliers (after the cheirality check of ``recoverPose``) raise.

    Returns
    -------
    T_target_source : (4, 4) float64
        Maps source-camera points into the target camera frame; the translation is metric.
    inliers : (Q,) bool
        Matches consistent with the pose (epipolar and cheirality).

    Raises
    ------
    RegistrationError
        Too few matches or inliers, no essential matrix, or no inlier with depth in both
        frames to fix the scale.
    """
    import cv2  # heavy: OpenCV loads in about a second

    q = len(target_xy)
    if q < max(5, min_inliers):
        raise RegistrationError(f"{q} matches, need at least {max(5, min_inliers)}")
    pt = np.ascontiguousarray(target_xy, dtype=np.float64)
    ps = np.ascontiguousarray(source_xy, dtype=np.float64)
    K = camera.K
    E, mask = cv2.findEssentialMat(
        ps, pt, K, method=cv2.RANSAC, prob=confidence, threshold=threshold_px
    )
    if E is None or mask is None or E.shape[0] < 3:
        raise RegistrationError("no essential matrix found (degenerate matches)")
    best: tuple[int, Any, Any, Any] | None = None
    for k in range(E.shape[0] // 3):  # several solutions may come back stacked
        m = mask.copy()
        n_good, R, t, m, _ = cv2.recoverPose(
            E[3 * k : 3 * k + 3], ps, pt, K, distanceThresh=CHEIRALITY_DISTANCE, mask=m
        )
        if best is None or n_good > best[0]:
            best = (int(n_good), R, t, m)
    assert best is not None
    n_good, R, t, m = best
    inl = np.asarray(m).reshape(-1) > 0
    if n_good < min_inliers or inl.sum() < min_inliers:
        raise RegistrationError(
            f"only {int(inl.sum())} of {q} matches fit an essential matrix within "
            f"{threshold_px:g} px (need {min_inliers})"
        )
    R = np.asarray(R, dtype=np.float64)
    u = np.asarray(t, dtype=np.float64).reshape(3)
    u /= np.linalg.norm(u)
    both = inl & np.isfinite(target_xyz).all(1) & np.isfinite(source_xyz).all(1)
    if both.sum() < 3:
        raise RegistrationError(
            f"only {int(both.sum())} of {int(inl.sum())} inliers have depth in both frames: "
            "metric scale undetermined"
        )
    d = target_xyz[both] - source_xyz[both] @ R.T
    s = float(np.median(d @ u))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = s * u
    return T, inl


def svd_pose(
    target_xyz: NDArray[np.float64],
    source_xyz: NDArray[np.float64],
    *,
    threshold_m: float | None = None,
    confidence: float = 0.999,
    min_inliers: int = 12,
    rng: np.random.Generator | int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], float]:
    """Relative pose from lifted 3D matches: 3-point RANSAC + Kabsch/Umeyama SVD.

    Parameters
    ----------
    target_xyz, source_xyz : (Q, 3) float64, metres
        Matched keypoints' 3D points (rows with NaN are ignored).
    threshold_m : float, optional
        Inlier distance; default ``max(0.01, 0.015 * median range)`` of the source points.
    confidence : float
    min_inliers : int
    rng : Generator, int or None

    Returns
    -------
    T_target_source : (4, 4) float64
    inliers : (Q,) bool
    threshold_m : float
        The threshold used.

    Raises
    ------
    RegistrationError
        Too few 3D matches or inliers, or collinear inliers.
    """
    ok = np.isfinite(target_xyz).all(1) & np.isfinite(source_xyz).all(1)
    if ok.sum() < max(3, min_inliers):
        raise RegistrationError(
            f"{int(ok.sum())} matches with depth in both frames, need at least "
            f"{max(3, min_inliers)}"
        )
    Q, P = target_xyz[ok], source_xyz[ok]
    thr = threshold_m
    if thr is None:
        thr = max(0.01, 0.015 * float(np.median(np.linalg.norm(P, axis=1))))
    try:
        res = ransac_rigid(
            Q, P, threshold_m=thr, confidence=confidence, min_inliers=min_inliers, rng=rng
        )
    except DegenerateGeometryError as e:
        raise RegistrationError(str(e)) from None
    inl = np.zeros(len(target_xyz), dtype=bool)
    inl[np.flatnonzero(ok)[res.inliers]] = True
    return res.T_target_source, inl, float(thr)


def solve_pair(
    target: FrameFeatures,
    source: FrameFeatures,
    config: OdometryConfig = OdometryConfig(),
    *,
    rng: np.random.Generator | int | None = None,
    timings: dict[str, float] | None = None,
) -> tuple[NDArray[np.float64], PairAttempt]:
    """Match two frames and solve ``T_target_source`` with ``config.method``.

    Returns
    -------
    T_target_source : (4, 4) float64
    attempt : PairAttempt
        Matches and inliers.

    Raises
    ------
    RegistrationError
        The pair cannot be solved; the message says why.
    """
    import cv2  # heavy: OpenCV loads in about a second

    t = timings if timings is not None else {}
    t0 = time.perf_counter()
    m = match(target.features, source.features, ratio=config.ratio, mutual=config.mutual)
    t1 = time.perf_counter()
    t["match"] = t.get("match", 0.0) + t1 - t0
    ti, si = m[:, 0], m[:, 1]
    try:
        if config.method == "essential":
            cam = source.camera
            if cam is None:
                raise RegistrationError("the essential-matrix solver needs a pinhole camera")
            gen = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
            cv2.setRNGSeed(int(gen.integers(0, 2**31 - 1)))
            T, inl = essential_pose(
                target.features.xy[ti],
                source.features.xy[si],
                target.xyz[ti],
                source.xyz[si],
                cam,
                threshold_px=config.ransac_threshold_px,
                confidence=config.ransac_confidence,
                min_inliers=config.min_inliers,
            )
            n_matches = len(m)
        else:
            T, inl, _ = svd_pose(
                target.xyz[ti],
                source.xyz[si],
                threshold_m=config.threshold_m,
                confidence=config.ransac_confidence,
                min_inliers=config.min_inliers,
                rng=rng,
            )
            n_matches = int(
                (np.isfinite(target.xyz[ti]).all(1) & np.isfinite(source.xyz[si]).all(1)).sum()
            )
    finally:
        t["solve"] = t.get("solve", 0.0) + time.perf_counter() - t1
    return T, PairAttempt(target.index, source.index, True, n_matches, int(inl.sum()))
