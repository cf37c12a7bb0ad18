"""The result of registering one pair of scans, shared by flexreg and every baseline."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray


class Settings(Protocol):
    """What a result needs of the configuration that produced it."""

    @property
    def seed(self) -> int: ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Reason:
    """Why a result is not trusted, for machines (``code``) and for people (``message``).

    Attributes
    ----------
    code : str
        Stable identifier, e.g. ``"low_overlap"``, ``"weak_axis"``, ``"ambiguous"``,
        ``"few_inliers"``, ``"clustered_inliers"``, ``"free_space"``, ``"high_residual"``.
    message : str
        One sentence a surveyor understands ("two poses 3.4 m apart along x fit almost equally
        well: repeating structure").
    """

    code: str
    message: str


@dataclass(frozen=True)
class Hypothesis:
    """A transform that competed with the winner.

    Attributes
    ----------
    T_target_source : (4, 4) float64
    score_ratio : float
        Its score divided by the winner's (1 = explains the data as well).
    rotation_deg, translation_m : float
        How far it is from the winner.
    origin : str
        Which prior produced it.
    """

    T_target_source: NDArray[np.float64]
    score_ratio: float
    rotation_deg: float
    translation_m: float
    origin: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "T_target_source": np.asarray(self.T_target_source).tolist(),
            "score_ratio": self.score_ratio,
            "rotation_deg": self.rotation_deg,
            "translation_m": self.translation_m,
            "origin": self.origin,
        }


@dataclass(frozen=True)
class Verdict:
    """Whether a registration can be trusted, why, and the evidence behind it.

    Attributes
    ----------
    status : {"confident", "uncertain"}
        ``"uncertain"`` whenever any reason is given.
    reasons : tuple of Reason
    evidence : mapping
        JSON-ready measurements the decision used (a registration's is its typed
        :class:`~flexreg.registration.evidence.Evidence`) (overlaps, inlier spread, per-axis
        strength, runner-up, free-space violations, residuals), with units in the keys.
    runner_up : tuple of Hypothesis
        Clearly different transforms that explain the data almost as well, best first.
    notes : tuple of Reason
        Things worth knowing that do not make the result uncertain (e.g.
        ``"refinement_rejected"``: the refinement was discarded, the coarse transform kept).
    """

    status: Literal["confident", "uncertain"]
    reasons: tuple[Reason, ...] = ()
    evidence: Mapping[str, Any] = field(default_factory=dict)
    runner_up: tuple[Hypothesis, ...] = ()
    notes: tuple[Reason, ...] = ()

    @property
    def confident(self) -> bool:
        return self.status == "confident"

    def summary(self) -> str:
        """One line: the status and the reasons in words (and any notes, in brackets)."""
        text = (
            "confident"
            if self.confident
            else "uncertain: " + "; ".join(r.message for r in self.reasons)
        )
        if self.notes:
            text += " (note: " + "; ".join(r.message for r in self.notes) + ")"
        return text

    def to_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "reasons": [{"code": r.code, "message": r.message} for r in self.reasons],
            "evidence": dict(self.evidence),
            "runner_up": [h.to_dict() for h in self.runner_up],
            "notes": [{"code": r.code, "message": r.message} for r in self.notes],
        }


def format_length(m: float, spec: str = ".3g") -> str:
    """A distance in metres in the unit that reads best (m, cm or mm), numbers as ``spec``."""
    if m >= 1:
        return f"{m:{spec}} m"
    if m >= 0.01:
        return f"{100 * m:{spec}} cm"
    return f"{1000 * m:{spec}} mm"


@dataclass(frozen=True)
class Overlap:
    """The overlap of one transform (the one definition, :mod:`flexreg.stages.overlap`).

    Attributes
    ----------
    share : float
        Overlap, 0..1: voxelised source points with a target point within ``distance_m``.
    rmse_m : float, metres
        RMS distance of those points (NaN when none).
    source_points, target_points : int
        Voxelised point counts (``source_points`` is the denominator).
    distance_m, voxel_m : float, metres
    voxel_source : str
        How ``voxel_m`` was chosen.
    open3d_fitness, open3d_inlier_rmse_m : float or None
        Open3D's ``evaluate_registration`` on the same clouds at ``distance_m`` (None when not
        computed: ``open3d_check=False``).
    """

    share: float
    rmse_m: float
    source_points: int
    target_points: int
    distance_m: float
    voxel_m: float
    voxel_source: str
    open3d_fitness: float | None
    open3d_inlier_rmse_m: float | None

    @property
    def definition(self) -> str:
        """What ``share`` divides by, in words."""
        d, v = format_length(self.distance_m), format_length(self.voxel_m)
        return (
            f"of {self.source_points:,} source points within {d} of a target point after "
            f"alignment (both clouds voxelised at {v}; {self.target_points:,} target points)"
        )

    def headline(self) -> str:
        """``overlap 43.5 % of 12,043 source points within 5 cm ... (n = 12,043)``."""
        return f"{100 * self.share:.1f} % {self.definition}"

    def to_dict(self) -> dict[str, Any]:
        def num(x: float | None) -> float | None:
            return float(x) if x is not None and math.isfinite(x) else None

        return {
            "share": self.share,
            "rmse_m": num(self.rmse_m),
            "source_points": self.source_points,
            "target_points": self.target_points,
            "distance_m": self.distance_m,
            "voxel_m": self.voxel_m,
            "voxel_source": self.voxel_source,
            "definition": "share " + self.definition,
            "open3d_definition": (
                "share and rmse_m are what Open3D's evaluate_registration calls fitness and "
                "inlier_rmse on these clouds at distance_m; open3d_fitness and "
                "open3d_inlier_rmse_m are Open3D's own call"
                + (
                    ""
                    if self.open3d_fitness is not None
                    else " (not made: set open3d_overlap_check=true)"
                )
            ),
            "open3d_fitness": self.open3d_fitness,
            "open3d_inlier_rmse_m": num(self.open3d_inlier_rmse_m),
        }


@dataclass(eq=False)
class PairResult:
    """``T_target_source`` of one pair and the evidence for it.

    Returned by :func:`flexreg.registration.register` (as its subclass
    :class:`~flexreg.registration.result.RegistrationResult`) and by every baseline
    (:mod:`flexreg.baselines`), so that the comparison and the coming survey treat them alike.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        Final transform (refined when the method refines).
    T_coarse : (4, 4) float64
        The coarse transform before refinement.
    matches : int
        Putative matches (flexreg: 2D matches lifted to 3D).
    inliers : int
        Inliers among them.
    inlier_rmse_m : float
        RMSE of the final stage's inliers (ICP when refined, else the coarse stage), metres.
    fitness : float
        The final stage's own share (ICP fitness, RANSAC inliers / matches...; written as
        ``stage_fitness``); ``fitness_denominator`` says what it divides by. Not comparable
        between methods: ``overlap`` is.
    fitness_denominator : str
        What ``fitness`` divides by.
    information : (6, 6) float64
        Information matrix (rotation, translation) for pose graphs (Open3D's convention).
    timings_s : dict
        Seconds per stage. Stages that run in background threads overlap, so the stages may
        add up to more than ``wall_s``.
    threshold_m : float
        Inlier threshold used, metres.
    config : RegistrationConfig, BaselineConfig or another settings object
        How the pair was registered (``seed`` and ``to_dict()`` are used).
    correspondences : (Q, 2, 3) float64
        ``[target point, source point]`` pairs (the coarse stage's input).
    inlier_mask : (Q,) bool
    keypoints : tuple of (K, 2) arrays
        Target and source keypoint positions of the matches (for drawing; empty for
        methods without image features).
    prior : str
        Which prior or method led to the estimate.
    wall_s : float
        Seconds the whole call took.
    verdict : Verdict or None
        Whether the result can be trusted (None for methods that give no verdict, such as
        the ICP baselines: reported as "n/a").
    overlap : Overlap or None
        The one overlap figure of the final transform, with Open3D's fitness and inlier RMSE
        (:mod:`flexreg.stages.overlap`); set by :func:`flexreg.registration.register`.
    """

    T_target_source: NDArray[np.float64]
    T_coarse: NDArray[np.float64]
    matches: int
    inliers: int
    inlier_rmse_m: float
    fitness: float
    fitness_denominator: str
    information: NDArray[np.float64]
    timings_s: dict[str, float]
    threshold_m: float
    config: Settings
    correspondences: NDArray[np.float64] = field(repr=False)
    inlier_mask: NDArray[np.bool_] = field(repr=False)
    keypoints: tuple[NDArray[np.float64], NDArray[np.float64]] = field(repr=False)
    prior: str = "descriptors"
    wall_s: float = float("nan")
    verdict: Verdict | None = None
    overlap: Overlap | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-match arrays)."""
        ov = self.overlap
        return {
            "T_target_source": self.T_target_source.tolist(),
            "T_coarse": self.T_coarse.tolist(),
            "matches": self.matches,
            "inliers": self.inliers,
            "inlier_rmse_m": self.inlier_rmse_m,
            "overlap": None if ov is None else ov.to_dict(),
            "open3d_fitness": None if ov is None else ov.open3d_fitness,
            "open3d_inlier_rmse_m": None if ov is None else ov.to_dict()["open3d_inlier_rmse_m"],
            "stage_fitness": self.fitness,
            "stage_fitness_denominator": self.fitness_denominator,
            "information": self.information.tolist(),
            "threshold_m": self.threshold_m,
            "timings_s": self.timings_s,
            "wall_s": self.wall_s,
            "prior": self.prior,
            "seed": self.config.seed,
            "config": self.config.to_dict(),
            "verdict": None if self.verdict is None else self.verdict.to_dict(),
        }


__all__ = [
    "Hypothesis",
    "Overlap",
    "PairResult",
    "Reason",
    "Settings",
    "Verdict",
    "format_length",
]
