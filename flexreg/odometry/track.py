"""Frame-to-frame odometry on depth sequences through feature images (paper sec. IV).

Each frame becomes a feature image — any Flexion variant (eq. 11-14), a Bearing Angle image in
one of four directions (eq. 9-10), or the sequence's colour image — keypoints are detected and
matched to the previous frame's, and the relative pose comes from one of two solvers:

``essential`` (the paper's visual odometry, sec. IV-B-1)
    Lowe's ratio test on k-NN matches, the essential matrix by RANSAC
    (``cv2.findEssentialMat``) on the pixel coordinates, rotation and translation direction by
    ``cv2.recoverPose``; the metric length of the translation comes from the depth of the
    inlier keypoints: with ``P_t`` and ``P_s`` the 3D points of an inlier in the target and
    source frames and ``t`` the unit direction, ``s = median(t . (P_t - R P_s))``.
``svd``
    The matched keypoints are lifted to 3D on their depth images
    (:func:`flexreg.stages.correspondences.lift`) and aligned with 3-point RANSAC and the
    Kabsch/Umeyama SVD (:func:`flexreg.stages.alignment.ransac_rigid`).

The relative poses ``T_prev_cur`` are chained into ``T_world_frame`` (the first frame is the
world unless ``initial_pose`` says otherwise). A frame that cannot be solved against its
predecessor is never silently given the identity: the failure (frames and reason) is logged and
recorded, and the frame is bridged — the next frame is matched against the last frame that was
solved (and then against the bridged one), and if that fails too the pose is extrapolated with
the last measured velocity (constant-velocity model, scaled by the time step).

All randomness is seeded per frame pair from ``OdometryConfig.seed``: the same sequence and
configuration give the same trajectory.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.errors import ConfigError, RegistrationError
from flexreg.odometry.config import IMAGES, METHODS, OdometryConfig
from flexreg.stages.keypoints import Features

if TYPE_CHECKING:
    from flexreg.core.camera import PinholeCamera
    from flexreg.io.sequence import Sequence
    from flexreg.io.trajectory import Trajectory

log = logging.getLogger(__name__)

#: feature images odometry can run on
CHEIRALITY_DISTANCE = 1.0e6


# ------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class PairAttempt:
    """One attempt to solve the motion between two frames.

    Attributes
    ----------
    target, source : int
        Frame indices: the pose solved is ``T_target_source``.
    ok : bool
    matches : int
        Ratio-tested matches (for ``svd``: those with 3D points on both frames).
    inliers : int
        RANSAC inliers of the accepted (or best rejected) model; 0 when none.
    reason : str
        Why the attempt failed (empty when ok).
    """

    target: int
    source: int
    ok: bool
    matches: int
    inliers: int
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class FrameFailure:
    """A frame whose motion could not be measured, and how its pose was bridged.

    Attributes
    ----------
    frame : int
        The frame that got a bridged pose.
    tried : tuple of int
        The reference frames it was matched against, in order.
    reasons : tuple of str
        Why each attempt failed.
    bridge : str
        How its pose was obtained (constant-velocity extrapolation).
    """

    frame: int
    tried: tuple[int, ...]
    reasons: tuple[str, ...]
    bridge: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "frame": self.frame,
            "tried": list(self.tried),
            "reasons": list(self.reasons),
            "bridge": self.bridge,
        }


@dataclass(eq=False)
class OdometryResult:
    """What :func:`odometry` found.

    Attributes
    ----------
    trajectory : Trajectory
        ``T_world_frame`` of every frame, with the frames' timestamps.
    status : tuple of str
        Per frame: ``"start"``, ``"estimated"`` (measured against ``reference``) or
        ``"bridged"`` (extrapolated, see ``failures``).
    reference : (N,) int64
        The frame each estimated pose was measured against (-1 for the start and bridged
        frames).
    attempts : list of PairAttempt
        Every frame pair tried, in order.
    failures : list of FrameFailure
        Frames that could not be solved and how they were bridged.
    timings_s : dict
        Seconds per stage (``load``, ``image``, ``features``, ``match``, ``solve``).
    config : OdometryConfig
    """

    trajectory: Trajectory
    status: tuple[str, ...]
    reference: NDArray[np.int64]
    attempts: list[PairAttempt]
    failures: list[FrameFailure]
    timings_s: dict[str, float]
    config: OdometryConfig

    def __repr__(self) -> str:
        return (
            f"OdometryResult({len(self.status)} frames, {self.n_estimated} estimated, "
            f"{len(self.failures)} bridged, {self.config.image}/{self.config.features}/"
            f"{self.config.method})"
        )

    @property
    def n_frames(self) -> int:
        return len(self.status)

    @property
    def n_estimated(self) -> int:
        """Frames whose pose was measured (not the start, not bridged)."""
        return sum(s == "estimated" for s in self.status)

    @property
    def failed_pairs(self) -> list[PairAttempt]:
        """Attempts that failed (a bridged frame has one or two)."""
        return [a for a in self.attempts if not a.ok]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (poses included as nested lists)."""
        return {
            "frames": self.n_frames,
            "estimated": self.n_estimated,
            "bridged": len(self.failures),
            "status": list(self.status),
            "reference": self.reference.tolist(),
            "attempts": [a.to_dict() for a in self.attempts],
            "failures": [f.to_dict() for f in self.failures],
            "timings_s": self.timings_s,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
            "timestamps": np.asarray(self.trajectory.timestamps).tolist(),
            "T_world_frame": np.asarray(self.trajectory.poses).tolist(),
        }


# ------------------------------------------------------------------------------ stages


def feature_image(
    image: RangeImage,
    config: OdometryConfig = OdometryConfig(),
    *,
    color: NDArray[np.uint8] | None = None,
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The 8-bit image keypoints are detected on, and its valid mask.

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
    from flexreg.errors import InputError
    from flexreg.stages import feature_images as images

    if config.image == "color":
        if color is None:
            raise InputError("color", "a colour feature image needs the frame's colour image")
        g = np.asarray(color)
        if g.ndim != 2 or g.dtype != np.uint8:
            raise InputError(
                "color", f"expected an (H, W) uint8 grey image, got {g.shape} {g.dtype}"
            )
        return g, np.ones(g.shape, dtype=bool)
    from flexreg.stages.projection import fill_holes

    img = fill_holes(image) if config.fill_holes else image
    f = images.convert(img, config.image, n=config.n, median=config.median)
    q, valid = images.quantize(
        f,
        bits=8,
        value_range=images.value_range(config.image),
        stretch=config.stretch,  # type: ignore[arg-type]
    )
    return np.asarray(q, dtype=np.uint8), np.asarray(valid, dtype=bool)


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
    from flexreg.core.camera import PinholeCamera
    from flexreg.errors import InputError
    from flexreg.stages.correspondences import lift
    from flexreg.stages.keypoints import detect_and_describe

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
    import cv2

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
    from flexreg.errors import DegenerateGeometryError
    from flexreg.stages.alignment import ransac_rigid

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
    import cv2

    from flexreg.stages.matching import match

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


def scale_motion(T: NDArray[np.float64], factor: float) -> NDArray[np.float64]:
    """The rigid motion ``T`` continued for ``factor`` times as long at constant velocity:
    ``exp(factor * log(T))`` on SE(3) (a screw motion; ``factor`` 2 gives ``T @ T``).

    >>> from flexreg.core.transforms import make_transform
    >>> scale_motion(make_transform(np.eye(3), [0.2, 0.0, 0.0]), 0.5)[:3, 3].round(12).tolist()
    [0.1, 0.0, 0.0]
    """
    from scipy.linalg import expm, logm

    M = np.asarray(T, dtype=np.float64)
    L = np.real(logm(M))
    out = np.asarray(np.real(expm(float(factor) * L)), dtype=np.float64)
    U, _, Vt = np.linalg.svd(out[:3, :3])  # exact rotation despite rounding
    out[:3, :3] = U @ Vt
    out[3] = [0.0, 0.0, 0.0, 1.0]
    return out


# ------------------------------------------------------------------------------ the one call


def odometry(
    sequence: Sequence,
    config: OdometryConfig = OdometryConfig(),
    *,
    initial_pose: NDArray[np.float64] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> OdometryResult:
    """Frame-to-frame odometry over a whole sequence: the one call.

    Each frame is read, converted (:func:`feature_image`), described (:func:`frame_features`)
    and solved against its predecessor (:func:`solve_pair`); :func:`track` chains and bridges.

    Parameters
    ----------
    sequence : Sequence
        From :func:`flexreg.io.sequence.read_sequence`.
    config : OdometryConfig
    initial_pose : (4, 4) float64, optional
        ``T_world_frame`` of the first frame (default identity: the first camera is the world).
    progress : callable, optional
        Called as ``progress(frames_done, frames_total)`` after each frame.

    Returns
    -------
    OdometryResult

    Raises
    ------
    ConfigError
        ``color`` on a sequence without colour, or ``essential`` on a folder of scans.
    InputError
        A frame file that cannot be read (named).
    RegistrationError
        Not a single frame pair could be solved (the trajectory would be pure guesswork).
    """
    from flexreg.stages.keypoints import create_detector

    if config.image == "color" and not sequence.has_color:
        raise ConfigError(
            f"image: {sequence.root} has no colour image for every frame; choose a depth "
            "conversion (flexion, bearing-*)"
        )
    if config.method == "essential" and sequence.camera is None:
        raise ConfigError(
            "method: the essential-matrix solver needs pinhole depth images; for a folder of "
            "scans use method 'svd'"
        )
    timings: dict[str, float] = {"load": 0.0, "image": 0.0, "features": 0.0}
    # one detector for the whole run (OpenCV defaults, as in the paper)
    detector = create_detector(config.features, max_features=config.max_features)

    def load(i: int) -> FrameFeatures:
        t0 = time.perf_counter()
        img = sequence.range_image(i)
        color = sequence.color_image(i) if config.image == "color" else None
        timings["load"] += time.perf_counter() - t0
        return frame_features(img, config, color=color, index=i, detector=detector, timings=timings)

    return track(
        load,
        sequence.timestamps,
        config,
        initial_pose=initial_pose,
        progress=progress,
        timings=timings,
    )


def track(
    frames: Callable[[int], FrameFeatures] | list[FrameFeatures],
    timestamps: NDArray[np.float64],
    config: OdometryConfig = OdometryConfig(),
    *,
    initial_pose: NDArray[np.float64] | None = None,
    progress: Callable[[int, int], None] | None = None,
    timings: dict[str, float] | None = None,
) -> OdometryResult:
    """Chain frame-to-frame poses, bridging frames that cannot be solved.

    Frame ``k`` is solved against frame ``k - 1``; when ``k - 1`` was itself bridged, against
    the last solved frame first and then ``k - 1``. When no attempt succeeds the frame is
    bridged with the last measured motion, rescaled to its time step (zero motion when none
    was measured yet), and the failure is logged and recorded.

    Parameters
    ----------
    frames : callable or list of FrameFeatures
        ``frames(i)`` returns frame ``i`` (called once per frame, in order), or the frames
        themselves (e.g. computed once and shared by runs that differ only in the solver).
    timestamps : (N,) float64, seconds
    config : OdometryConfig
        ``method``, ``ratio``, ``mutual``, thresholds and ``seed`` are used here.
    initial_pose : (4, 4) float64, optional
    progress : callable, optional
        ``progress(frames_done, frames_total)``.
    timings : dict, optional
        Accumulates seconds per stage (``match``, ``solve``); returned in the result.

    Returns
    -------
    OdometryResult
    """
    from flexreg.core.transforms import as_transform, invert
    from flexreg.io.trajectory import Trajectory

    stamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    n = len(stamps)
    if n < 2:
        raise ConfigError(f"odometry needs at least 2 frames, got {n}")
    get: Callable[[int], FrameFeatures]
    if isinstance(frames, list):
        if len(frames) != n:
            raise ConfigError(f"{len(frames)} frames for {n} timestamps")
        get = frames.__getitem__
    else:
        get = frames
    T0 = np.eye(4) if initial_pose is None else as_transform(initial_pose, name="initial_pose")
    tm: dict[str, float] = timings if timings is not None else {}
    tm.setdefault("match", 0.0)
    tm.setdefault("solve", 0.0)

    poses = [T0]
    status = ["start"]
    reference = [-1]
    attempts: list[PairAttempt] = []
    failures: list[FrameFailure] = []
    prev = get(0)
    last_good = prev
    velocity: tuple[NDArray[np.float64], float] | None = None  # (T_prev_cur, dt)
    if progress is not None:
        progress(1, n)
    for k in range(1, n):
        cur = get(k)
        refs = [prev] if status[k - 1] != "bridged" else [last_good, prev]
        T_world_k = None
        reasons: list[str] = []
        for j, ref in enumerate(refs):
            rng = np.random.default_rng([config.seed, k, j])
            try:
                T_ref_k, att = solve_pair(ref, cur, config, rng=rng, timings=tm)
            except RegistrationError as e:
                attempts.append(PairAttempt(ref.index, k, False, 0, 0, str(e)))
                reasons.append(str(e))
                log.info("frames %d -> %d: not solved: %s", ref.index, k, e)
                continue
            attempts.append(att)
            T_world_k = poses[ref.index] @ T_ref_k
            reference.append(ref.index)
            status.append("estimated")
            break
        dt = float(stamps[k] - stamps[k - 1])
        if T_world_k is None:
            if velocity is None:
                step = np.eye(4)
                how = "constant velocity (no motion measured yet: zero velocity)"
            else:
                V, vdt = velocity
                step = scale_motion(V, dt / vdt if vdt > 0 else 1.0)
                how = "constant velocity"
            T_world_k = poses[k - 1] @ step
            reference.append(-1)
            status.append("bridged")
            tried = tuple(r.index for r in refs)
            failures.append(FrameFailure(k, tried, tuple(reasons), how))
            log.warning(
                "frame %d could not be solved against frame(s) %s (%s); bridged by %s",
                k,
                ", ".join(map(str, tried)),
                "; ".join(reasons),
                how,
            )
        else:
            velocity = (invert(poses[k - 1]) @ T_world_k, dt)
            last_good = cur
        poses.append(T_world_k)
        prev = cur
        if progress is not None:
            progress(k + 1, n)
    if not any(s == "estimated" for s in status):
        reasons = sorted({a.reason for a in attempts if not a.ok})
        raise RegistrationError(
            f"none of the {n - 1} frame pairs could be solved with {config.features} on "
            f"{config.image} ({config.method}): " + "; ".join(reasons[:3])
        )
    traj = Trajectory(timestamps=stamps.copy(), poses=np.stack(poses))
    return OdometryResult(
        trajectory=traj,
        status=tuple(status),
        reference=np.asarray(reference, dtype=np.int64),
        attempts=attempts,
        failures=failures,
        timings_s=tm,
        config=config,
    )


__all__ = [
    "IMAGES",
    "METHODS",
    "FrameFailure",
    "FrameFeatures",
    "OdometryConfig",
    "OdometryResult",
    "PairAttempt",
    "essential_pose",
    "feature_image",
    "frame_features",
    "odometry",
    "scale_motion",
    "solve_pair",
    "svd_pose",
    "track",
]
