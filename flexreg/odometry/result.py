"""What odometry returns: per-pair attempts, bridged frames, and the whole run's result."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.trajectory import Trajectory
from flexreg.odometry.config import OdometryConfig

__all__ = ["FrameFailure", "OdometryResult", "PairAttempt"]


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
    """What :func:`flexreg.odometry.track.odometry` found.

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
