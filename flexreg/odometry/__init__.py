"""Frame-to-frame odometry on depth sequences and trajectory evaluation (ATE / RPE).

``from flexreg.odometry import odometry, OdometryConfig, evaluate`` gives the public API:

- :mod:`~flexreg.odometry.config`: :class:`OdometryConfig` and the accepted feature images and
  solvers;
- :mod:`~flexreg.odometry.frontend`: feature images, keypoints and the pair solvers;
- :mod:`~flexreg.odometry.track`: :func:`odometry` (the one call) and :func:`track`;
- :mod:`~flexreg.odometry.result`: :class:`OdometryResult` and what it records;
- :mod:`~flexreg.odometry.evaluation`: ATE, RPE, :func:`evaluate`;
- :mod:`~flexreg.odometry.plots`: :func:`plot_evaluation`.
"""

from flexreg.odometry.config import IMAGES, METHODS, OdometryConfig
from flexreg.odometry.evaluation import (
    AssociationError,
    AteResult,
    EvaluationResult,
    RpeResult,
    ate,
    check_interval,
    evaluate,
    interval_label,
    nearest_partner,
    rpe,
)
from flexreg.odometry.frontend import (
    FrameFeatures,
    essential_pose,
    feature_image,
    frame_features,
    solve_pair,
    svd_pose,
)
from flexreg.odometry.plots import plot_evaluation
from flexreg.odometry.result import FrameFailure, OdometryResult, PairAttempt
from flexreg.odometry.track import odometry, track

__all__ = [
    "IMAGES",
    "METHODS",
    "AssociationError",
    "AteResult",
    "EvaluationResult",
    "FrameFailure",
    "FrameFeatures",
    "OdometryConfig",
    "OdometryResult",
    "PairAttempt",
    "RpeResult",
    "ate",
    "check_interval",
    "essential_pose",
    "evaluate",
    "feature_image",
    "frame_features",
    "interval_label",
    "nearest_partner",
    "odometry",
    "plot_evaluation",
    "rpe",
    "solve_pair",
    "svd_pose",
    "track",
]
