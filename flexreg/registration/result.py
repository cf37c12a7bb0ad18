"""What :func:`flexreg.registration.register` returns."""

from __future__ import annotations

from dataclasses import dataclass

from flexreg.core.results import PairResult
from flexreg.registration.config import RegistrationConfig


@dataclass(eq=False)
class RegistrationResult(PairResult):
    """What :func:`~flexreg.registration.pipeline.register` found: a
    :class:`~flexreg.core.results.PairResult` made by flexreg's own pipeline.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        Final transform (refined when ``config.refine``).
    T_coarse : (4, 4) float64
        The keypoint (or plan) transform before refinement.
    matches : int
        Putative 2D matches lifted to 3D (the final guided matching).
    inliers : int
        Inliers among them.
    inlier_rmse_m : float
        RMSE of the final stage's inliers (ICP when refined, else the keypoints), metres.
    fitness : float
        Final-stage overlap: ICP fitness or, unrefined, the share of the source's even sample
        consistent with the target's view; ``fitness_denominator`` says which.
    fitness_denominator : str
        What ``fitness`` divides by.
    information : (6, 6) float64
        Information matrix (rotation, translation) for pose graphs.
    timings_s : dict
        Seconds per stage. The plan views and the preparation of the checks run in background
        threads beside the feature stages, so the stages add up to more than ``wall_s``.
    threshold_m : float
        Inlier threshold used.
    config : RegistrationConfig
    correspondences : (Q, 2, 3) float64
        Lifted ``[target point, source point]`` pairs of the final matches.
    inlier_mask : (Q,) bool
    keypoints : tuple of (K, 2) arrays
        Target and source keypoint positions of the lifted matches (for drawing).
    prior : str
        Which prior led to the estimate: ``"plan"`` (plan-view overlay), ``"descriptors"``
        (global descriptor matching) or ``"init"`` (the given initial transform),
        ``"+keypoints"`` when refined by guided matching.
    wall_s : float
        Seconds the whole call took.
    verdict : Verdict
        Whether the result can be trusted, why, and the evidence
        (:mod:`flexreg.registration.verdict`); always set by :func:`register`.
    """

    config: RegistrationConfig


__all__ = ["RegistrationResult"]
