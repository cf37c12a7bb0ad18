"""flexreg and the baselines side by side on one scan pair.

:func:`compare` runs each method (``flexreg`` = :func:`flexreg.registration.pipeline.register`,
the others from :mod:`flexreg.baselines`; see :mod:`flexreg.bench.methods`) on the same two
scans and measures, per method:

- **errors** against a known ``T_target_source`` (:func:`flexreg.io.read_ground_truth`):
  rotation angle of ``R_est^T R_gt`` in degrees (:func:`flexreg.core.transforms.rotation_error_deg`)
  and distance of the translations in metres (:func:`flexreg.core.transforms.translation_error_m`),
  of the final transform and, for methods with a global stage (flexreg, fpfh-ransac), of the
  coarse transform before their ICP refinement;
- **success**: the final transform within ``SuccessCriteria.rotation_deg`` (default 0.5°) *and*
  ``SuccessCriteria.translation_m`` (default 5 cm) of the truth; *coarse success* applies the
  same limits to the transform before refinement (global methods only);
- **overlap**, the same for every method and the same figure ``flexreg register`` reports
  (:mod:`flexreg.stages.overlap`): both clouds voxelised at the scale voxel
  (:func:`flexreg.baselines.default_voxel`), the share of the source points mapped by the
  method's transform with a target point within that voxel (denominator stated) and their RMS
  distance; beside it Open3D's ``fitness`` and ``inlier_rmse`` of ``evaluate_registration`` on
  the same clouds at the same distance;
- **wall time** of the method's call alone and **peak memory** (:mod:`flexreg.bench.measure`).

By default each method runs in its own process (``multiprocessing`` forkserver), so that a
crash, a hang (``timeout_s``) or memory kept by one method's allocator cannot touch the others;
a method that fails (raises a :class:`~flexreg.errors.FlexregError`), raises anything else,
dies or times out is a row saying so, never a missing row. Tables are in
:mod:`flexreg.bench.tables`, the figure in :mod:`flexreg.bench.plots`, the files in
:mod:`flexreg.bench.results`.
"""

from __future__ import annotations

import logging
import math
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.baselines import default_voxel
from flexreg.bench.measure import (
    Measured,
    isolation_note,
    machine_info,
    measure_call,
    measure_isolated,
    peak_memory_note,
    save_pair,
)
from flexreg.bench.methods import DEFAULT_METHODS, GLOBAL_METHODS, parse_methods, run_method
from flexreg.core.results import format_length
from flexreg.core.scan import as_points
from flexreg.core.transforms import as_transform, rotation_error_deg, translation_error_m
from flexreg.errors import ConfigError, InputError, RegistrationError
from flexreg.registration.config import RegistrationConfig
from flexreg.stages.overlap import OverlapMeter

__all__ = [
    "MIN_OVERLAP_FITNESS",
    "Comparison",
    "MethodRun",
    "SuccessCriteria",
    "compare",
    "make_row",
]

log = logging.getLogger(__name__)

#: a pair whose source lies less than this share on the target (the overlap) has no overlap
MIN_OVERLAP_FITNESS = 0.01


# ------------------------------------------------------------------ criteria, fit, rows


@dataclass(frozen=True)
class SuccessCriteria:
    """A transform is a success when both errors are at most these limits.

    Attributes
    ----------
    rotation_deg : float, degrees
    translation_m : float, metres
    """

    rotation_deg: float = 0.5
    translation_m: float = 0.05

    def __post_init__(self) -> None:
        for name, value in (
            ("rotation_deg", self.rotation_deg),
            ("translation_m", self.translation_m),
        ):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"success {name} must be a positive number, got {value}")

    def met(self, rotation_deg: float, translation_m: float) -> bool:
        return bool(rotation_deg <= self.rotation_deg and translation_m <= self.translation_m)

    def label(self) -> str:
        return f"≤ {self.rotation_deg:g}° and ≤ {format_length(self.translation_m, 'g')}"

    def to_dict(self) -> dict[str, float]:
        return {"rotation_deg": self.rotation_deg, "translation_m": self.translation_m}


@dataclass(eq=False)
class MethodRun:
    """One row of a comparison.

    Attributes
    ----------
    method : str
    status : {"ok", "failed", "error", "crashed", "timeout"}
    message : str or None
    time_s : float, seconds
    peak_memory_mb : float or None, MiB
    T_target_source, T_coarse : (4, 4) float64 or None
        Final and coarse transform (``T_coarse`` only for global methods).
    rotation_error_deg, translation_error_m : float or None
        Final errors against the ground truth (None without one, or without a result).
    coarse_rotation_error_deg, coarse_translation_error_m : float or None
    success, coarse_success : bool or None
        None without ground truth (and ``coarse_success`` for local methods).
    fitness, inlier_rmse_m : float or None
        The overlap of the final transform and its RMS distance in metres, the same figure
        for every method and for ``flexreg register`` (:mod:`flexreg.stages.overlap`);
        written as ``overlap`` and ``overlap_rmse_m``.
    open3d_fitness, open3d_inlier_rmse_m : float or None
        Open3D's ``evaluate_registration`` on the same clouds at the same distance.
    verdict : str or None
        The method's own verdict on its result: ``"confident"`` or ``"uncertain"`` (flexreg),
        ``"n/a"`` for methods that give none (the baselines); None without a result. The
        reasons and evidence are in ``details["verdict"]``.
    details : dict
        The method's own figures: matches, inliers, its fitness and denominator, threshold,
        timings per stage, configuration.
    """

    method: str
    status: str
    message: str | None = None
    time_s: float = math.nan
    peak_memory_mb: float | None = None
    T_target_source: NDArray[np.float64] | None = None
    T_coarse: NDArray[np.float64] | None = None
    rotation_error_deg: float | None = None
    translation_error_m: float | None = None
    coarse_rotation_error_deg: float | None = None
    coarse_translation_error_m: float | None = None
    success: bool | None = None
    coarse_success: bool | None = None
    fitness: float | None = None
    inlier_rmse_m: float | None = None
    open3d_fitness: float | None = None
    open3d_inlier_rmse_m: float | None = None
    verdict: str | None = None
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, Any]:
        def mat(T: NDArray[np.float64] | None) -> list[list[float]] | None:
            return None if T is None else np.asarray(T).tolist()

        return {
            "method": self.method,
            "status": self.status,
            "message": self.message,
            "time_s": self.time_s,
            "peak_memory_mb": self.peak_memory_mb,
            "T_target_source": mat(self.T_target_source),
            "T_coarse": mat(self.T_coarse),
            "rotation_error_deg": self.rotation_error_deg,
            "translation_error_m": self.translation_error_m,
            "coarse_rotation_error_deg": self.coarse_rotation_error_deg,
            "coarse_translation_error_m": self.coarse_translation_error_m,
            "success": self.success,
            "coarse_success": self.coarse_success,
            "overlap": self.fitness,
            "overlap_rmse_m": self.inlier_rmse_m,
            "open3d_fitness": self.open3d_fitness,
            "open3d_inlier_rmse_m": self.open3d_inlier_rmse_m,
            "verdict": self.verdict,
            "details": self.details,
        }


def make_row(
    name: str,
    m: Measured,
    *,
    T_gt: NDArray[np.float64] | None,
    criteria: SuccessCriteria,
    fit: OverlapMeter | None,
) -> MethodRun:
    """Turn a :class:`Measured` call into a :class:`MethodRun` (errors, success, overlap)."""
    row = MethodRun(
        method=name,
        status=m.status,
        message=m.message,
        time_s=m.time_s,
        peak_memory_mb=m.peak_memory_mb,
    )
    r = m.result
    if r is not None and not np.all(np.isfinite(np.asarray(r.T_target_source, dtype=float))):
        row.status, row.message = "failed", "returned a transform with NaN or Inf"
        r = None
    if r is None:
        if T_gt is not None:
            row.success = False
            row.coarse_success = False if name in GLOBAL_METHODS else None
        return row
    row.T_target_source = np.asarray(r.T_target_source, dtype=np.float64)
    if name in GLOBAL_METHODS:
        row.T_coarse = np.asarray(r.T_coarse, dtype=np.float64)
    if T_gt is not None:
        row.rotation_error_deg = rotation_error_deg(row.T_target_source, T_gt)
        row.translation_error_m = translation_error_m(row.T_target_source, T_gt)
        row.success = criteria.met(row.rotation_error_deg, row.translation_error_m)
        if row.T_coarse is not None:
            row.coarse_rotation_error_deg = rotation_error_deg(row.T_coarse, T_gt)
            row.coarse_translation_error_m = translation_error_m(row.T_coarse, T_gt)
            row.coarse_success = criteria.met(
                row.coarse_rotation_error_deg, row.coarse_translation_error_m
            )
    if fit is not None:
        ov = fit(row.T_target_source)
        row.fitness, row.inlier_rmse_m = ov.share, ov.rmse_m
        row.open3d_fitness, row.open3d_inlier_rmse_m = ov.open3d_fitness, ov.open3d_inlier_rmse_m
    verdict = getattr(r, "verdict", None)
    row.verdict = "n/a" if verdict is None else verdict.status
    cfg = r.config.to_dict() if hasattr(r.config, "to_dict") else {}
    row.details = {
        "matches": r.matches,
        "inliers": r.inliers,
        "stage_fitness": r.fitness,
        "stage_fitness_denominator": r.fitness_denominator,
        "own_inlier_rmse_m": r.inlier_rmse_m,
        "threshold_m": r.threshold_m,
        "start": r.prior,
        "timings_s": dict(r.timings_s),
        "config": cfg,
        "verdict": None if verdict is None else verdict.to_dict(),
    }
    return row


# ------------------------------------------------------------------ the comparison


@dataclass(eq=False)
class Comparison:
    """Every method's row on one pair, with what the numbers mean.

    Attributes
    ----------
    target, source : str
        Names (file paths) of the scans.
    runs : list of MethodRun
        One per method, in the order asked for.
    criteria : SuccessCriteria
    T_gt : (4, 4) float64 or None
        Ground truth ``T_target_source``.
    T_init : (4, 4) float64 or None
        Start given to the local methods (None: identity).
    scale_m : float, metres
        The scale voxel (given, or :func:`~flexreg.baselines.default_voxel` of the target).
    scale_source : str
    fit_denominator : str
        What the overlap divides by, with its distance and voxel.
    peak_memory : str
        How peak memory was measured.
    isolation : str
    points : (int, int)
        Target and source point counts.
    seed : int
    machine : dict
    """

    target: str
    source: str
    runs: list[MethodRun]
    criteria: SuccessCriteria
    T_gt: NDArray[np.float64] | None
    T_init: NDArray[np.float64] | None
    scale_m: float
    scale_source: str
    fit_denominator: str
    peak_memory: str
    isolation: str
    points: tuple[int, int]
    seed: int
    machine: dict[str, Any] = field(default_factory=dict)

    def run(self, method: str) -> MethodRun:
        for r in self.runs:
            if r.method == method:
                return r
        raise KeyError(method)

    def to_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "source": self.source,
            "points": list(self.points),
            "ground_truth": None if self.T_gt is None else self.T_gt.tolist(),
            "initial_guess": None if self.T_init is None else self.T_init.tolist(),
            "success_criteria": self.criteria.to_dict(),
            "success_definition": (
                "final transform within both limits of the ground truth; coarse success: the "
                "transform before refinement (global methods only)"
            ),
            "scale_m": self.scale_m,
            "scale_source": self.scale_source,
            "fit_denominator": self.fit_denominator,
            "peak_memory": self.peak_memory,
            "time": "wall time of the method's call alone (scans in memory)",
            "isolation": self.isolation,
            "seed": self.seed,
            "machine": self.machine,
            "methods": [r.to_dict() for r in self.runs],
        }


# ------------------------------------------------------------------ the comparison


def compare(
    target: Any,
    source: Any,
    *,
    methods: str | Sequence[str] = DEFAULT_METHODS,
    T_gt: ArrayLike | None = None,
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    seed: int = 0,
    criteria: SuccessCriteria = SuccessCriteria(),
    timeout_s: float | None = None,
    isolate: bool = True,
    flexreg_config: RegistrationConfig | None = None,
    names: tuple[str, str] = ("target", "source"),
    progress: Callable[[str, int, int], None] | None = None,
    require_overlap: bool = True,
) -> Comparison:
    """Run ``methods`` on one pair and measure each (see the module notes).

    Parameters
    ----------
    target, source : Scan (or RangeImage / (N, 3) array for the baselines)
        Points in their own scanner frames.
    methods : str or sequence of str
        Names (:data:`flexreg.bench.methods.METHODS`), e.g. ``"flexreg,icp-plane"``.
    T_gt : (4, 4) float, optional
        Ground truth ``T_target_source``; without it there are no errors and no success.
    T_init : (4, 4) float, optional
        Start of the local methods (ICP variants, KISS-ICP, small_gicp); identity when None.
    voxel_m : float, optional, metres
        Scale voxel given to every baseline (default: each derives it from the scan
        resolution, the same value, inside its timed call). The overlap always uses the
        default scale voxel, as ``flexreg register`` does.
    seed : int
        flexreg's and RANSAC's seed.
    criteria : SuccessCriteria
    timeout_s : float, optional, seconds
        Time limit per method (isolated runs only).
    isolate : bool
        Run each method in its own process (crash and memory isolation, time limit).
    flexreg_config : RegistrationConfig, optional
        flexreg's configuration (default: ``RegistrationConfig(seed=seed)``).
    names : (str, str)
        Names of the scans for the report.
    progress : callable, optional
        ``progress(method, index, total)`` before each method.
    require_overlap : bool
        Refuse a pair without overlap: with a ground truth, when less than
        :data:`MIN_OVERLAP_FITNESS` of the source lies on the target at the true pose (checked
        before any method runs); in any case, when no method returned a transform that puts
        that much of the source on the target.

    Notes
    -----
    Isolated runs use :mod:`multiprocessing` (a fork server): a script that calls
    :func:`compare` must do so under ``if __name__ == "__main__":``, as any multiprocessing
    program.

    Raises
    ------
    ConfigError
        Unknown method, invalid voxel, criteria or time limit.
    InputError
        Invalid scans, ground truth or initial guess; no overlap at the ground-truth pose.
    RegistrationError
        No method found an overlap (``require_overlap``).
    """
    chosen = parse_methods(methods)
    _check_limits(timeout_s, voxel_m)
    Tg = None if T_gt is None else as_transform(T_gt, name="ground truth")
    Ti = None if T_init is None else as_transform(T_init, name="initial guess")
    pt = as_points(target, name=names[0])
    ps = as_points(source, name=names[1])
    if voxel_m is None:
        scale, scale_source = default_voxel(pt)
    else:
        scale, scale_source = float(voxel_m), "given"
    # the overlap's voxel is the scale voxel of the target whatever --voxel says, so that
    # register and compare state the same overlap for the same transform
    fit = OverlapMeter(pt, ps, voxel_m=scale if voxel_m is None else None)
    d = fit.distance_m
    denominator = (
        f"{len(fit.source_points):,} source points within {d:.3g} m of a target point "
        f"after alignment (both clouds voxelised at {fit.voxel_m:.3g} m; "
        f"{len(fit.target_points):,} target points)"
    )
    if require_overlap and Tg is not None:
        at_truth = fit(Tg)
        if at_truth.share < MIN_OVERLAP_FITNESS:
            raise InputError(
                f"{names[0]} / {names[1]}",
                f"the scans do not overlap at the ground-truth pose: overlap {at_truth.headline()}",
            )
    machine = machine_info()
    options: dict[str, Any] = {"T_init": Ti, "voxel_m": voxel_m, "seed": seed}
    if flexreg_config is not None:
        options["config"] = flexreg_config
    runs: list[MethodRun] = []
    with tempfile.TemporaryDirectory(prefix="flexreg-compare-") as tmp:
        pair_file = save_pair(target, source, Path(tmp) / "pair.pickle") if isolate else None
        for i, name in enumerate(chosen):
            if progress is not None:
                progress(name, i, len(chosen))
            opts = dict(options)
            if name != "flexreg":
                opts.pop("config", None)
            if isolate:
                m = measure_isolated(
                    name, target, source, timeout_s=timeout_s, pair_file=pair_file, **opts
                )
            else:
                m = measure_call(partial(run_method, name, target, source, **opts))
            row = make_row(name, m, T_gt=Tg, criteria=criteria, fit=fit)
            log.info("%s: %s in %.2f s", name, row.status, row.time_s)
            runs.append(row)
    if progress is not None:
        progress("", len(chosen), len(chosen))
    if require_overlap:
        _require_some_overlap(runs, names)
    machine["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    return Comparison(
        target=names[0],
        source=names[1],
        runs=runs,
        criteria=criteria,
        T_gt=Tg,
        T_init=Ti,
        scale_m=scale,
        scale_source=scale_source,
        fit_denominator=denominator,
        peak_memory=peak_memory_note(),
        isolation=(
            isolation_note() if isolate else "all methods in one process, one after the other"
        ),
        points=(len(pt), len(ps)),
        seed=seed,
        machine=machine,
    )


def _check_limits(timeout_s: float | None, voxel_m: float | None) -> None:
    if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0):
        raise ConfigError(f"time limit must be a positive number of seconds, got {timeout_s}")
    if voxel_m is not None and not (math.isfinite(voxel_m) and voxel_m > 0):
        raise ConfigError(f"voxel must be a positive number of metres, got {voxel_m}")


def _require_some_overlap(runs: list[MethodRun], names: tuple[str, str]) -> None:
    """Raise :class:`RegistrationError` when no method put :data:`MIN_OVERLAP_FITNESS` of the
    source on the target."""
    best = max((r.fitness or 0.0 for r in runs if r.ok), default=0.0)
    if best >= MIN_OVERLAP_FITNESS:
        return
    outcome = "; ".join(
        f"{r.method}: "
        + (f"{r.status} ({r.message})" if not r.ok else f"overlap {r.fitness or 0.0:.3f}")
        for r in runs
    )
    raise RegistrationError(
        f"no overlap found between {names[0]} and {names[1]}: no method put "
        f"{100 * MIN_OVERLAP_FITNESS:g}% of the source on the target ({outcome})"
    )
