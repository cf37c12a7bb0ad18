"""Settings of ``flexreg compare`` (light: the command line imports it before any method)."""

from __future__ import annotations

from flexreg.config import Config, Positive, Seed, VoxelM

__all__ = ["DEFAULT_METHODS", "CompareConfig"]

#: the methods compared unless told otherwise (:data:`flexreg.bench.methods.DEFAULT_METHODS`
#: is this, split)
DEFAULT_METHODS = "flexreg,icp-point,icp-plane,gicp,fpfh-ransac,kiss-icp"


class CompareConfig(Config):
    """Settings of ``flexreg compare`` (``flexreg config show compare``).

    Attributes
    ----------
    methods : str
        Comma-separated methods (see :func:`flexreg.bench.methods.parse_methods`).
    voxel_m : float or None, metres
        Scale voxel of the baselines (None: from the scan resolution).
    seed : int
        Seed of flexreg and RANSAC.
    success_deg : float, degrees
        Largest rotation error of a success.
    success_m : float, metres
        Largest translation error of a success.
    timeout_s : float, seconds
        Time limit per method.
    """

    methods: str = DEFAULT_METHODS
    voxel_m: VoxelM | None = None
    seed: Seed = 0
    success_deg: Positive = 0.5
    success_m: Positive = 0.05
    timeout_s: Positive = 600.0
