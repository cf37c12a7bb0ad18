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

from flexreg.exports import lazy

# bound now: the submodule of the same name would otherwise shadow it once imported
from flexreg.odometry.track import track as track

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "IMAGES": "flexreg.odometry.config",
    "METHODS": "flexreg.odometry.config",
    "AssociationError": "flexreg.odometry.evaluation",
    "AteResult": "flexreg.odometry.evaluation",
    "EvaluationResult": "flexreg.odometry.evaluation",
    "FrameFailure": "flexreg.odometry.result",
    "FrameFeatures": "flexreg.odometry.frontend",
    "OdometryConfig": "flexreg.odometry.config",
    "OdometryResult": "flexreg.odometry.result",
    "PairAttempt": "flexreg.odometry.result",
    "RpeResult": "flexreg.odometry.evaluation",
    "ate": "flexreg.odometry.evaluation",
    "check_interval": "flexreg.odometry.evaluation",
    "essential_pose": "flexreg.odometry.frontend",
    "evaluate": "flexreg.odometry.evaluation",
    "feature_image": "flexreg.odometry.frontend",
    "frame_features": "flexreg.odometry.frontend",
    "interval_label": "flexreg.odometry.evaluation",
    "nearest_partner": "flexreg.odometry.evaluation",
    "odometry": "flexreg.odometry.track",
    "plot_evaluation": "flexreg.odometry.plots",
    "rpe": "flexreg.odometry.evaluation",
    "solve_pair": "flexreg.odometry.frontend",
    "svd_pose": "flexreg.odometry.frontend",
    "track": "flexreg.odometry.track",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
