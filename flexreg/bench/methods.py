"""The methods a comparison runs, by name: flexreg itself and the baselines.

``flexreg`` is :func:`flexreg.registration.pipeline.register`; every other name is a baseline of
:mod:`flexreg.baselines`. :func:`run_method` is what a measured call (in this process or in its
own, :mod:`flexreg.bench.measure`) runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import ArrayLike

from flexreg.baselines import BASELINES, GLOBAL, available_baselines, get_baseline
from flexreg.bench.config import DEFAULT_METHODS as COMPARE_DEFAULT_METHODS
from flexreg.core.results import PairResult
from flexreg.errors import ConfigError
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.pipeline import register

__all__ = ["DEFAULT_METHODS", "GLOBAL_METHODS", "METHODS", "parse_methods", "run_method"]

#: every method name :func:`~flexreg.bench.compare.compare` knows (``small-gicp`` only runs when
#: installed)
METHODS: tuple[str, ...] = ("flexreg", *BASELINES)
#: the methods compared unless told otherwise (the default of CompareConfig.methods)
DEFAULT_METHODS: tuple[str, ...] = tuple(COMPARE_DEFAULT_METHODS.split(","))
#: methods with a global (coarse) stage before their refinement
GLOBAL_METHODS: frozenset[str] = frozenset({"flexreg", *GLOBAL})


def parse_methods(spec: str | Sequence[str]) -> tuple[str, ...]:
    """Method names from ``"flexreg,icp-plane"`` (or a sequence), in order, without repeats.

    Raises
    ------
    ConfigError
        Empty list, an unknown name, or a baseline whose optional package is missing.
    """
    parts = spec.split(",") if isinstance(spec, str) else list(spec)
    names = list(dict.fromkeys(p.strip() for p in parts if p.strip()))
    if not names:
        raise ConfigError(f"no method given; known: {', '.join(METHODS)}")
    for name in names:
        if name not in METHODS:
            raise ConfigError(f"unknown method {name!r}; known: {', '.join(METHODS)}")
        if name != "flexreg" and name not in available_baselines():
            get_baseline(name)  # raises the "needs the optional package" error
    return tuple(names)


def run_method(
    name: str,
    target: Any,
    source: Any,
    *,
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    seed: int = 0,
    config: RegistrationConfig | None = None,
) -> PairResult:
    """Run one method by name: ``flexreg`` (``register`` with ``config`` or the default
    configuration and ``seed``) or a baseline. ``T_init`` goes to the local methods only
    (flexreg and fpfh-ransac are global); ``voxel_m`` to the baselines only (flexreg derives
    its own thresholds). FPFH + RANSAC runs its RANSAC on all cores, as Open3D does by default:
    its rows are the fastest configuration users get, not bit-reproducible from run to run."""
    if name == "flexreg":
        return register(target, source, config or RegistrationConfig(seed=seed))
    options: dict[str, Any] = {"voxel_m": voxel_m, "seed": seed}
    if name not in GLOBAL and T_init is not None:
        options["T_init"] = T_init
    if name == "fpfh-ransac":
        # as Open3D runs it by default (all cores): fast, but not bit-reproducible
        options["ransac_threads"] = None
    return get_baseline(name)(target, source, **options)
