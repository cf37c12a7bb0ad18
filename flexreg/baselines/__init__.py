"""Registration baselines with flexreg's result type: Open3D ICP, Open3D FPFH + RANSAC, KISS-ICP.

Every baseline is a function ``f(target, source, *, T_init=None, voxel_m=None, seed=0)`` that
returns a :class:`flexreg.core.results.PairResult` (``T_target_source`` maps source points into
the target frame), the type :func:`flexreg.registration.register` returns too, so a baseline can
stand in for it:

==============  =====================================================================  =========
name            what                                                                   start
==============  =====================================================================  =========
``icp-point``   Open3D point-to-point ICP, 3 levels (:mod:`.open3d_icp`)               identity
``icp-plane``   Open3D point-to-plane ICP, 3 levels                                    identity
``gicp``        Open3D generalized ICP, 3 levels                                       identity
``fpfh-ransac`` Open3D FPFH + RANSAC, then point-to-plane ICP (:mod:`.fpfh`)           global
``kiss-icp``    KISS-ICP fed the pair as a two-frame sequence (:mod:`.kiss`)           identity
``small-gicp``  small_gicp GICP, only when ``small_gicp`` is installed (:mod:`.smallgicp`) identity
==============  =====================================================================  =========

A multi-station baseline stands beside these pairwise ones: :func:`flexreg.baselines.multiway.
multiway` runs Open3D's documented multiway registration (FPFH + RANSAC + point-to-plane ICP
for every pair, then a pose graph with odometry and loop-closure edges and
``global_optimization``) on N stations and returns their poses in the first station's frame
(:class:`~flexreg.baselines.multiway.MultiwayResult`, in the layout of a survey's
``poses.json``); ``benchmarks/survey.py`` runs it beside ``flexreg survey``. It is not in
:data:`BASELINES` (those take one pair).

The local methods start from the identity, or from ``T_init`` when given. All sizes derive
from one scale parameter, the voxel ``voxel_m`` (default from the scan resolution: twice the
target's median point spacing, enlarged until at most 20,000 target points remain;
KISS-ICP keeps its own rule, ``max_range / 100``). Open3D, KISS-ICP and small_gicp are imported
only when a baseline runs.

>>> from flexreg.baselines import get_baseline
>>> result = get_baseline("icp-plane")(target_scan, source_scan)  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from typing import Any

from flexreg.baselines._common import DEFAULT_MAX_POINTS, BaselineConfig, default_voxel
from flexreg.core.results import PairResult
from flexreg.errors import ConfigError

Baseline = Callable[..., PairResult]

#: registry: name -> "module:function" (resolved on first use, so nothing heavy is imported)
BASELINES: dict[str, str] = {
    "icp-point": "open3d_icp:icp_point_to_point",
    "icp-plane": "open3d_icp:icp_point_to_plane",
    "gicp": "open3d_icp:generalized_icp",
    "fpfh-ransac": "fpfh:fpfh_ransac",
    "kiss-icp": "kiss:kiss_icp",
    "small-gicp": "smallgicp:small_gicp_align",
}
#: baselines that need an optional package, and the package
OPTIONAL: dict[str, str] = {"small-gicp": "small_gicp"}
#: baselines that need no start (global registration); the others start from T_init or identity
GLOBAL: frozenset[str] = frozenset({"fpfh-ransac"})


def available_baselines() -> tuple[str, ...]:
    """Names of the baselines that can run here (optional packages installed)."""
    return tuple(
        name
        for name in BASELINES
        if name not in OPTIONAL or importlib.util.find_spec(OPTIONAL[name]) is not None
    )


def get_baseline(name: str) -> Baseline:
    """The function registered as ``name``.

    Raises
    ------
    ConfigError
        Unknown name, or its optional package is not installed.
    """
    if name not in BASELINES:
        raise ConfigError(f"unknown baseline {name!r}; known: {', '.join(BASELINES)}")
    if name not in available_baselines():
        raise ConfigError(
            f"baseline {name!r} needs the optional package {OPTIONAL[name]!r} "
            f"(pip install {OPTIONAL[name].replace('_', '-')})"
        )
    module, func = BASELINES[name].split(":")
    fn: Any = getattr(importlib.import_module(f"{__name__}.{module}"), func)
    return fn


def run_baseline(name: str, target: Any, source: Any, **options: Any) -> PairResult:
    """``get_baseline(name)(target, source, **options)``."""
    return get_baseline(name)(target, source, **options)


__all__ = [
    "BASELINES",
    "DEFAULT_MAX_POINTS",
    "GLOBAL",
    "OPTIONAL",
    "Baseline",
    "BaselineConfig",
    "available_baselines",
    "default_voxel",
    "get_baseline",
    "run_baseline",
]
