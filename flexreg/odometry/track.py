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

The front end (feature images, keypoints, pair solvers) is :mod:`flexreg.odometry.frontend`;
the result types are in :mod:`flexreg.odometry.result`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from flexreg.core.range_image import RangeImage
from flexreg.core.trajectory import Trajectory
from flexreg.core.transforms import as_transform, invert, scale_motion
from flexreg.errors import ConfigError, RegistrationError
from flexreg.io.sequence import Sequence
from flexreg.odometry.config import OdometryConfig
from flexreg.odometry.frontend import FrameFeatures, frame_features, solve_pair
from flexreg.odometry.result import FrameFailure, OdometryResult, PairAttempt
from flexreg.stages.keypoints import create_detector
from flexreg.stages.projection import range_image

log = logging.getLogger(__name__)

__all__ = ["odometry", "track"]


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
        data = sequence.frame(i)  # a depth frame's points, or a scan to project
        img = data if isinstance(data, RangeImage) else range_image(data)
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
    stamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    n = len(stamps)
    if n < 2:
        raise ConfigError(f"odometry needs at least 2 frames, got {n}")
    get = _frame_source(frames, n)
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
        solved, reasons = _solve_first(refs, cur, k, config, attempts, tm)
        dt = float(stamps[k] - stamps[k - 1])
        if solved is None:
            step, how = _bridge_step(velocity, dt)
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
            ref, T_ref_k = solved
            T_world_k = poses[ref] @ T_ref_k
            reference.append(ref)
            status.append("estimated")
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


def _frame_source(
    frames: Callable[[int], FrameFeatures] | list[FrameFeatures], n: int
) -> Callable[[int], FrameFeatures]:
    """``frames`` as a function of the frame index (a list must hold ``n`` frames)."""
    if isinstance(frames, list):
        if len(frames) != n:
            raise ConfigError(f"{len(frames)} frames for {n} timestamps")
        return frames.__getitem__
    return frames


def _solve_first(
    refs: list[FrameFeatures],
    cur: FrameFeatures,
    k: int,
    config: OdometryConfig,
    attempts: list[PairAttempt],
    timings: dict[str, float],
) -> tuple[tuple[int, NDArray[np.float64]] | None, list[str]]:
    """Solve ``cur`` (frame ``k``) against each of ``refs`` in turn until one succeeds.

    Every attempt is appended to ``attempts``. Returns ``(reference index, T_ref_cur)`` of the
    first success (None if all fail) and the reasons of the failed attempts. The RANSAC of
    attempt ``j`` on frame ``k`` is seeded with ``(config.seed, k, j)``.
    """
    reasons: list[str] = []
    for j, ref in enumerate(refs):
        rng = np.random.default_rng([config.seed, k, j])
        try:
            T_ref_k, att = solve_pair(ref, cur, config, rng=rng, timings=timings)
        except RegistrationError as e:
            attempts.append(PairAttempt(ref.index, k, False, 0, 0, str(e)))
            reasons.append(str(e))
            log.info("frames %d -> %d: not solved: %s", ref.index, k, e)
            continue
        attempts.append(att)
        return (ref.index, T_ref_k), reasons
    return None, reasons


def _bridge_step(
    velocity: tuple[NDArray[np.float64], float] | None, dt: float
) -> tuple[NDArray[np.float64], str]:
    """The motion over ``dt`` at the last measured ``(T_prev_cur, dt)`` velocity (constant
    velocity model; zero motion when none was measured yet) and how it was obtained."""
    if velocity is None:
        return np.eye(4), "constant velocity (no motion measured yet: zero velocity)"
    V, vdt = velocity
    return scale_motion(V, dt / vdt if vdt > 0 else 1.0), "constant velocity"
