"""flexreg and the baselines side by side on one scan pair.

:func:`compare` runs each method (``flexreg`` = :func:`flexreg.registration.pipeline.register`, the
others
from :mod:`flexreg.baselines`) on the same two scans and measures, per method:

- **errors** against a known ``T_target_source`` (:func:`read_ground_truth`): rotation angle of
  ``R_est^T R_gt`` in degrees (:func:`flexreg.core.transforms.rotation_error_deg`) and distance of
  the
  translations in metres (:func:`flexreg.core.transforms.translation_error_m`), of the final
  transform and, for methods with a global stage (flexreg, fpfh-ransac), of the coarse
  transform before their ICP refinement;
- **success**: the final transform within ``SuccessCriteria.rotation_deg`` (default 0.5°) *and*
  ``SuccessCriteria.translation_m`` (default 5 cm) of the truth; *coarse success* applies the
  same limits to the transform before refinement (global methods only);
- **fit**, the same for every method: of at most 20,000 evenly spaced source points mapped by
  the method's transform, the share with a target point within ``fit_distance_m`` (the scale
  voxel, see :func:`flexreg.baselines.default_voxel`) -- *fitness*, denominator stated -- and
  the RMS distance of those points (*inlier RMSE*);
- **wall time** of the method's call alone (scans already in memory; a process's start-up,
  imports and data transfer excluded) and **peak memory**: the increase of the resident set
  size during the call (Linux: the kernel's high-water mark ``VmHWM``, reset through
  ``/proc/self/clear_refs`` just before the call, minus the resident size then; elsewhere the
  Python-heap peak from :mod:`tracemalloc`, which misses native allocations).

By default each method runs in its own process (``multiprocessing`` forkserver), so that a
crash, a hang (``timeout_s``) or memory kept by one method's allocator cannot touch the others;
a method that fails (raises a :class:`~flexreg.errors.FlexregError`), raises anything else,
dies or times out is a row saying so, never a missing row.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import multiprocessing
import os
import platform
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.baselines import BASELINES, GLOBAL, available_baselines, default_voxel, get_baseline
from flexreg.core.transforms import as_transform, invert, rotation_error_deg, translation_error_m
from flexreg.errors import ConfigError, FlexregError, InputError, RegistrationError

if TYPE_CHECKING:
    from flexreg.registration.pipeline import RegistrationConfig, RegistrationResult

log = logging.getLogger(__name__)

#: every method name :func:`compare` knows (``small-gicp`` only runs when installed)
METHODS: tuple[str, ...] = ("flexreg", *BASELINES)
#: the methods compared unless told otherwise
DEFAULT_METHODS: tuple[str, ...] = (
    "flexreg",
    "icp-point",
    "icp-plane",
    "gicp",
    "fpfh-ransac",
    "kiss-icp",
)
#: methods with a global (coarse) stage before their refinement
GLOBAL_METHODS: frozenset[str] = frozenset({"flexreg", *GLOBAL})
#: source points (evenly spaced) and target points (every k-th) the common fit uses
FIT_SOURCE_POINTS = 20_000
FIT_TARGET_POINTS = 1_000_000
#: a pair whose source lies less than this share on the target (common fit) has no overlap
MIN_OVERLAP_FITNESS = 0.01

STATUSES = ("ok", "failed", "error", "crashed", "timeout")


# ------------------------------------------------------------------ methods and inputs


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


def read_ground_truth(
    path: str | PathLike[str], *, target: str | None = None, source: str | None = None
) -> NDArray[np.float64]:
    """A known ``T_target_source`` from a file.

    Accepted: JSON ``{"T_target_source": [[4x4]], ...}`` (what ``flexreg register`` writes),
    a ``flexreg synth`` ``gt.json`` (its ``pairs`` entry for the stems ``target`` and
    ``source``, inverted if listed the other way round), or a 4x4 text matrix.

    Raises
    ------
    InputError
        Missing or unreadable file, no matching entry, or a matrix that is not a rigid
        transform (non-orthonormal rotation block, reflection, bad last row, NaN).
    """
    from flexreg.io import read_transform

    p = Path(path)
    if not p.is_file():
        raise InputError(p, "no such file")
    if p.suffix.lower() == ".json":
        try:
            doc = json.loads(p.read_text(errors="replace"))
        except json.JSONDecodeError as e:
            raise InputError(p, f"invalid JSON: {e.msg} (line {e.lineno})") from None
        if isinstance(doc, dict) and "T_target_source" not in doc and "pairs" in doc:
            for pair in doc["pairs"]:
                names = (pair.get("target"), pair.get("source"))
                T = pair.get("T_target_source")
                if names == (target, source):
                    return _rigid(T, p)
                if names == (source, target):
                    return invert(_rigid(T, p))
            raise InputError(p, f"no pair {target} / {source} in its 'pairs'")
        if isinstance(doc, dict) and "T_target_source" not in doc:
            raise InputError(p, "no 'T_target_source' entry")
        return _rigid(doc["T_target_source"] if isinstance(doc, dict) else doc, p)
    return _rigid(read_transform(p), p)


def _rigid(T: Any, path: Path) -> NDArray[np.float64]:
    try:
        return as_transform(T, name=str(path), rigid=True)
    except (TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(path, f"not a 4x4 matrix of numbers ({e})") from None


def run_method(
    name: str,
    target: Any,
    source: Any,
    *,
    T_init: ArrayLike | None = None,
    voxel_m: float | None = None,
    seed: int = 0,
    config: RegistrationConfig | None = None,
) -> RegistrationResult:
    """Run one method by name: ``flexreg`` (``register`` with ``config`` or the default
    configuration and ``seed``) or a baseline. ``T_init`` goes to the local methods only
    (flexreg and fpfh-ransac are global); ``voxel_m`` to the baselines only (flexreg derives
    its own thresholds). FPFH + RANSAC runs its RANSAC on all cores, as Open3D does by default:
    its rows are the fastest configuration users get, not bit-reproducible from run to run."""
    if name == "flexreg":
        from flexreg.registration.pipeline import RegistrationConfig, register

        return register(target, source, config or RegistrationConfig(seed=seed))
    options: dict[str, Any] = {"voxel_m": voxel_m, "seed": seed}
    if name not in GLOBAL and T_init is not None:
        options["T_init"] = T_init
    if name == "fpfh-ransac":
        # as Open3D runs it by default (all cores): fast, but not bit-reproducible
        options["ransac_threads"] = None
    return get_baseline(name)(target, source, **options)


# ------------------------------------------------------------------ measuring one call


@dataclass(eq=False)
class Measured:
    """Outcome of one measured call.

    Attributes
    ----------
    status : {"ok", "failed", "error", "crashed", "timeout"}
        ``failed``: the method raised a :class:`FlexregError` (it reports that it could not
        register); ``error``: it raised another exception; ``crashed``: its process died;
        ``timeout``: no result within the time limit.
    result : RegistrationResult or None
    message : str or None
        The error message (``"Type: message"`` for ``error``).
    time_s : float, seconds
        Wall time of the call (the limit for ``timeout``).
    peak_memory_mb : float or None, MiB
        Increase of the peak memory during the call (see :data:`PEAK_MEMORY_NOTE`).
    """

    status: str
    result: RegistrationResult | None
    message: str | None
    time_s: float
    peak_memory_mb: float | None


def _read_status_kib(key: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_high_water_mark() -> bool:
    """Reset the kernel's peak-RSS counter of this process (Linux); False if impossible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return _read_status_kib("VmHWM") is not None


def peak_memory_note() -> str:
    """How peak memory is measured on this machine (stated with every result)."""
    if _reset_high_water_mark():
        return (
            "increase of the resident set size during the call: kernel high-water mark VmHWM "
            "(reset via /proc/self/clear_refs right before the call) minus the resident size then"
        )
    return (
        "Python-heap peak during the call (tracemalloc); native allocations (Open3D, KISS-ICP, "
        "OpenCV) are not counted on this platform"
    )


def measure_call(fn: Callable[[], RegistrationResult]) -> Measured:
    """Call ``fn()`` in this process: wall time, peak memory increase, and the outcome
    (exceptions become ``failed``/``error`` statuses, never propagate)."""
    import tracemalloc

    hwm = _reset_high_water_mark()
    rss0 = _read_status_kib("VmRSS") if hwm else None
    if not hwm:
        tracemalloc.start()
    status, result, message = "ok", None, None
    t0 = time.perf_counter()
    try:
        result = fn()
    except FlexregError as e:
        status, message = "failed", str(e)
    except Exception as e:
        status, message = "error", f"{type(e).__name__}: {e}"
        log.debug("method raised:\n%s", traceback.format_exc())
    elapsed = time.perf_counter() - t0
    if hwm and rss0 is not None:
        peak = _read_status_kib("VmHWM")
        peak_mb = None if peak is None else max(0, peak - rss0) / 1024.0
    else:
        _, peak_b = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        peak_mb = peak_b / 2**20
    return Measured(status, result, message, elapsed, peak_mb)


def _child(
    conn: Any,
    fn: Callable[..., Any],
    args: tuple[Any, ...],
    kwargs: dict[str, Any],
    pair_file: str | None = None,
) -> None:
    """Process entry point: measure ``fn(*args, **kwargs)`` and send the :class:`Measured`.

    With ``pair_file``, ``(target, source)`` are read from it first (not measured) and
    appended to ``args``."""
    if pair_file is not None:
        import pickle

        with open(pair_file, "rb") as f:
            args = (*args, *pickle.load(f))
    m = measure_call(partial(fn, *args, **kwargs))
    try:
        conn.send(m)
    except Exception as e:  # an unpicklable result still reports something
        conn.send(Measured("error", None, f"result not transferable: {e}", m.time_s, None))
    conn.close()


#: every module a method imports on its first call (imports are not part of the measured time),
#: and numba's deferred start-up (:mod:`flexreg.bench._preload`)
_PRELOAD = [
    "flexreg.bench.compare",
    "flexreg.bench._preload",
    "flexreg.registration.pipeline",
    "flexreg.stages.alignment",
    "flexreg.stages.feature_images",
    "flexreg.stages.matching",
    "flexreg.stages.refinement.projective",
    "flexreg.stages.refinement.icp",
    "flexreg.stages.priors",
    "flexreg.baselines.open3d_icp",
    "flexreg.baselines.fpfh",
    "flexreg.baselines.kiss",
    "kiss_icp.config",
    "kiss_icp.kiss_icp",
    "open3d",
    "cv2",
    "scipy.fft",
    "scipy.ndimage",
    "scipy.spatial",
]


def _context() -> Any:
    """The multiprocessing context for isolated runs: a fork server that has imported the
    heavy modules but run nothing (so its children start in a fraction of a second and
    inherit no thread pools), or spawn where there is no fork server."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(_PRELOAD)
        return ctx
    return multiprocessing.get_context("spawn")


def measure_isolated(
    name: str,
    target: Any,
    source: Any,
    *,
    timeout_s: float | None = None,
    pair_file: str | PathLike[str] | None = None,
    **options: Any,
) -> Measured:
    """:func:`run_method` in a separate process, measured there (see :func:`run_isolated`).

    With ``pair_file`` (written by :func:`save_pair`), the process reads ``(target, source)``
    from that file before the measured call instead of receiving them through a pipe, which
    is much faster for scans of tens of millions of points read by several methods.
    """
    if pair_file is not None:
        return run_isolated(
            run_method, (name,), options, timeout_s=timeout_s, pair_file=str(pair_file)
        )
    return run_isolated(run_method, (name, target, source), options, timeout_s=timeout_s)


def save_pair(target: Any, source: Any, path: str | PathLike[str]) -> Path:
    """Pickle ``(target, source)`` to ``path`` for :func:`measure_isolated`."""
    import pickle

    p = Path(path)
    with open(p, "wb") as f:
        pickle.dump((target, source), f, protocol=pickle.HIGHEST_PROTOCOL)
    return p


def run_isolated(
    fn: Callable[..., Any],
    args: tuple[Any, ...] = (),
    kwargs: dict[str, Any] | None = None,
    *,
    timeout_s: float | None = None,
    pair_file: str | None = None,
) -> Measured:
    """Measure ``fn(*args, **kwargs)`` (:func:`measure_call`) in a separate process.

    ``fn`` must be importable by name (a module-level function). With ``pair_file`` (see
    :func:`save_pair`) the pickled ``(target, source)`` are read from it in the process,
    before the measured call, and appended to ``args``. A process that dies becomes
    ``crashed`` (with its signal or exit code), one that sends nothing within ``timeout_s``
    seconds is killed and becomes ``timeout``.
    """
    ctx = _context()
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, kwargs or {}, pair_file), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    try:
        ready = recv.poll(timeout_s)
        msg: Measured | None = None
        if ready:
            try:
                msg = recv.recv()
            except (EOFError, OSError):
                msg = None
        if not ready:
            proc.kill()
            proc.join()
            limit = float(timeout_s) if timeout_s is not None else time.perf_counter() - t0
            return Measured("timeout", None, f"no result within {limit:g} s", limit, None)
        proc.join(30)
        if msg is None:
            if proc.is_alive():
                proc.kill()
                proc.join()
            code = proc.exitcode
            how = (
                f"killed by signal {-code}"
                if code is not None and code < 0
                else f"exit status {code}"
            )
            return Measured(
                "crashed", None, f"process died ({how})", time.perf_counter() - t0, None
            )
        return msg
    finally:
        recv.close()
        if proc.is_alive():
            proc.kill()
            proc.join()


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
        return f"≤ {self.rotation_deg:g}° and ≤ {_length(self.translation_m)}"

    def to_dict(self) -> dict[str, float]:
        return {"rotation_deg": self.rotation_deg, "translation_m": self.translation_m}


def _length(m: float) -> str:
    if m >= 1:
        return f"{m:g} m"
    if m >= 0.01:
        return f"{100 * m:g} cm"
    return f"{1000 * m:g} mm"


class FitEvaluator:
    """The common fit measure of every method's transform on one pair.

    Parameters
    ----------
    target, source : (N, 3) float64, metres
    distance_m : float, metres
        Inlier distance.
    """

    def __init__(
        self, target: NDArray[np.float64], source: NDArray[np.float64], distance_m: float
    ) -> None:
        from scipy.spatial import cKDTree

        if not (math.isfinite(distance_m) and distance_m > 0):
            raise ConfigError(f"fit distance must be positive, got {distance_m}")
        t = target[:: max(1, math.ceil(len(target) / FIT_TARGET_POINTS))]
        self.source = source[:: max(1, math.ceil(len(source) / FIT_SOURCE_POINTS))]
        self.distance_m = float(distance_m)
        self._tree = cKDTree(t)
        thinned = (
            f", target thinned to every {math.ceil(len(target) / len(t))}-th point"
            if len(t) < len(target)
            else ""
        )
        self.denominator = (
            f"{len(self.source)} evenly spaced source points with a target point within "
            f"{self.distance_m:.3g} m{thinned}"
        )

    def __call__(self, T: NDArray[np.float64]) -> tuple[float, float]:
        """``(fitness, inlier RMSE in metres)`` of a transform."""
        q = self.source @ T[:3, :3].T + T[:3, 3]
        d, _ = self._tree.query(q, distance_upper_bound=self.distance_m)
        ok = np.isfinite(d)
        rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else math.nan
        return float(ok.mean()), rmse


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
        The common fit (:class:`FitEvaluator`).
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
            "fitness": self.fitness,
            "inlier_rmse_m": self.inlier_rmse_m,
            "details": self.details,
        }


def make_row(
    name: str,
    m: Measured,
    *,
    T_gt: NDArray[np.float64] | None,
    criteria: SuccessCriteria,
    fit: FitEvaluator | None,
) -> MethodRun:
    """Turn a :class:`Measured` call into a :class:`MethodRun` (errors, success, fit)."""
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
        row.fitness, row.inlier_rmse_m = fit(row.T_target_source)
    cfg = r.config.to_dict() if hasattr(r.config, "to_dict") else {}
    row.details = {
        "matches": r.matches,
        "inliers": r.inliers,
        "own_fitness": r.fitness,
        "own_fitness_denominator": r.fitness_denominator,
        "own_inlier_rmse_m": r.inlier_rmse_m,
        "threshold_m": r.threshold_m,
        "start": r.prior,
        "timings_s": dict(r.timings_s),
        "config": cfg,
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
        The scale voxel (given, or :func:`~flexreg.baselines.default_voxel` of the target);
        also the common fit distance.
    scale_source : str
    fit_denominator : str
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


def machine_info() -> dict[str, Any]:
    """Cores, CPU, Python and library versions, load average (for the protocol)."""
    import open3d

    info: dict[str, Any] = {
        "cores": os.cpu_count(),
        "cpu": _cpu_name(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "open3d": open3d.__version__,
    }
    try:
        from importlib.metadata import version

        info["kiss_icp"] = version("kiss-icp")
    except Exception:
        info["kiss_icp"] = None
    if hasattr(os, "getloadavg"):
        info["load_average"] = list(os.getloadavg())
    return info


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


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
        Names (:data:`METHODS`), e.g. ``"flexreg,icp-plane"``.
    T_gt : (4, 4) float, optional
        Ground truth ``T_target_source``; without it there are no errors and no success.
    T_init : (4, 4) float, optional
        Start of the local methods (ICP variants, KISS-ICP, small_gicp); identity when None.
    voxel_m : float, optional, metres
        Scale voxel given to every baseline (default: each derives it from the scan
        resolution, the same value, inside its timed call); also the common fit distance.
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
    from flexreg.baselines._common import as_points

    chosen = parse_methods(methods)
    if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0):
        raise ConfigError(f"time limit must be a positive number of seconds, got {timeout_s}")
    if voxel_m is not None and not (math.isfinite(voxel_m) and voxel_m > 0):
        raise ConfigError(f"voxel must be a positive number of metres, got {voxel_m}")
    Tg = None if T_gt is None else as_transform(T_gt, name="ground truth")
    Ti = None if T_init is None else as_transform(T_init, name="initial guess")
    pt = as_points(target, name=names[0])
    ps = as_points(source, name=names[1])
    if voxel_m is None:
        scale, scale_source = default_voxel(pt)
    else:
        scale, scale_source = float(voxel_m), "given"
    fit = FitEvaluator(pt, ps, scale)
    if require_overlap and Tg is not None:
        share, _ = fit(Tg)
        if share < MIN_OVERLAP_FITNESS:
            raise InputError(
                f"{names[0]} / {names[1]}",
                f"the scans do not overlap at the ground-truth pose: {100 * share:.1f}% of "
                f"{fit.denominator}",
            )
    machine = machine_info()
    runs: list[MethodRun] = []
    options: dict[str, Any] = {"T_init": Ti, "voxel_m": voxel_m, "seed": seed}
    if flexreg_config is not None:
        options["config"] = flexreg_config
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
    best = max((r.fitness or 0.0 for r in runs if r.ok), default=0.0)
    if require_overlap and best < MIN_OVERLAP_FITNESS:
        outcome = "; ".join(
            f"{r.method}: "
            + (f"{r.status} ({r.message})" if not r.ok else f"fitness {r.fitness or 0.0:.3f}")
            for r in runs
        )
        raise RegistrationError(
            f"no overlap found between {names[0]} and {names[1]}: no method put "
            f"{100 * MIN_OVERLAP_FITNESS:g}% of the source on the target ({outcome})"
        )
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
        fit_denominator=fit.denominator,
        peak_memory=peak_memory_note(),
        isolation=(
            f"each method in its own process ({_context().get_start_method()})"
            if isolate
            else "all methods in one process, one after the other"
        ),
        points=(len(pt), len(ps)),
        seed=seed,
        machine=machine,
    )


# ------------------------------------------------------------------ rendering

COLUMNS: tuple[str, ...] = (
    "method",
    "status",
    "rotation error (°)",
    "translation error (m)",
    "success",
    "coarse error (° / m)",
    "inlier RMSE (m)",
    "fitness",
    "time (s)",
    "peak memory (MB)",
)


def _num(x: float | None, fmt: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return format(x, fmt)


def _yes(x: bool | None) -> str:
    return "–" if x is None else ("yes" if x else "no")


def table_rows(cmp: Comparison) -> list[dict[str, str]]:
    """One dict of formatted cells per method (keys :data:`COLUMNS`), for every renderer."""
    rows = []
    for r in cmp.runs:
        status = r.status if r.ok else f"{r.status}: {r.message or ''}".strip()
        coarse = (
            f"{_num(r.coarse_rotation_error_deg, '.3f')} / "
            f"{_num(r.coarse_translation_error_m, '.3f')}"
            if r.coarse_rotation_error_deg is not None
            else "–"
        )
        rows.append(
            {
                "method": r.method,
                "status": status,
                "rotation error (°)": _num(r.rotation_error_deg, ".4f"),
                "translation error (m)": _num(r.translation_error_m, ".4f"),
                "success": _yes(r.success),
                "coarse error (° / m)": coarse,
                "inlier RMSE (m)": _num(r.inlier_rmse_m, ".4f"),
                "fitness": _num(r.fitness, ".3f"),
                "time (s)": _num(r.time_s, ".2f"),
                "peak memory (MB)": _num(r.peak_memory_mb, ".0f"),
            }
        )
    return rows


def notes(cmp: Comparison) -> list[str]:
    """What the columns mean, for the Markdown and the console."""
    out = [
        f"Scans: target {cmp.target} ({cmp.points[0]:,} points), source {cmp.source} "
        f"({cmp.points[1]:,} points).",
        "Success: final transform "
        + cmp.criteria.label()
        + " of the ground truth; coarse error = the transform before refinement (global "
        "methods: flexreg, fpfh-ransac)."
        + ("" if cmp.T_gt is not None else " No ground truth given: no errors, no success."),
        f"Fitness: share of {cmp.fit_denominator}; inlier RMSE over those points.",
        f"Scale voxel {cmp.scale_m:.4g} m ({cmp.scale_source}); local methods start from "
        + ("the given initial guess." if cmp.T_init is not None else "the identity."),
        "Time: wall time of each method's call alone (scans in memory); peak memory: "
        + cmp.peak_memory
        + f"; {cmp.isolation}.",
    ]
    return out


def to_markdown(cmp: Comparison, *, figure: str | None = None) -> str:
    """The comparison as a Markdown table with its notes (and the bar chart, if given)."""
    rows = table_rows(cmp)
    lines = [
        "| " + " | ".join(COLUMNS) + " |",
        "|---|---|" + "---:|" * 3 + "---|" + "---:|" * 4,
    ]
    for row in rows:
        cells = [row[c].replace("|", "\\|") for c in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [""] + [f"- {n}" for n in notes(cmp)]
    if figure:
        lines += ["", f"![errors, time and memory per method]({figure})"]
    return "\n".join(lines) + "\n"


def plot_comparison(cmp: Comparison, path: str | PathLike[str]) -> Path:
    """Bar chart PNG: rotation and translation error (log scale, success limits dashed), time
    and peak memory per method. Failed methods are marked instead of drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r.method for r in cmp.runs]
    x = np.arange(len(names))
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.4), dpi=110)
    colour = {True: "#009E73", False: "#D55E00", None: "#56B4E9"}
    panels = (
        (axes[0, 0], "rotation error (°)", [r.rotation_error_deg for r in cmp.runs], True),
        (axes[0, 1], "translation error (m)", [r.translation_error_m for r in cmp.runs], True),
        (axes[1, 0], "time (s)", [r.time_s if r.ok else None for r in cmp.runs], False),
        (axes[1, 1], "peak memory (MB)", [r.peak_memory_mb for r in cmp.runs], False),
    )
    for ax, label, values, log_scale in panels:
        vals = [v if v is not None and math.isfinite(v) else None for v in values]
        heights = [v if v is not None else 0.0 for v in vals]
        if log_scale:
            heights = [
                max(h, 1e-6) if v is not None else 0.0 for h, v in zip(heights, vals, strict=True)
            ]
        ax.bar(x, heights, color=[colour[r.success] for r in cmp.runs])
        for xi, (v, r) in enumerate(zip(vals, cmp.runs, strict=True)):
            if v is None:
                text = r.status if not r.ok else "no ground truth"
                ax.text(
                    xi,
                    0.5,
                    text,
                    rotation=90,
                    ha="center",
                    va="center",
                    fontsize=8,
                    transform=ax.get_xaxis_transform(),
                )
        if log_scale and any(v is not None for v in vals):
            ax.set_yscale("log")
        if label.startswith("rotation"):
            ax.axhline(cmp.criteria.rotation_deg, color="0.3", ls="--", lw=0.8)
        if label.startswith("translation"):
            ax.axhline(cmp.criteria.translation_m, color="0.3", ls="--", lw=0.8)
        ax.set_ylabel(label)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    title = f"{Path(cmp.target).name} ← {Path(cmp.source).name}"
    if cmp.T_gt is not None:
        title += f"  (green: success {cmp.criteria.label()}, orange: not; dashed: limits)"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    p = Path(path)
    fig.savefig(p)
    plt.close(fig)
    return p


def write_comparison(cmp: Comparison, out_dir: str | PathLike[str]) -> list[Path]:
    """Write ``comparison.json``, ``comparison.md`` and ``comparison.png`` into ``out_dir``
    (created). Each file is written under a temporary name and renamed; if one fails, those
    already written here are removed again.

    Raises
    ------
    InputError
        ``out_dir`` exists and is not a folder, or a file cannot be written.
    """

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    doc = json.dumps(_json_safe(cmp.to_dict()), indent=2) + "\n"
    md = f"# {Path(cmp.target).name} ← {Path(cmp.source).name}\n\n" + to_markdown(
        cmp, figure="comparison.png"
    )
    writers: list[tuple[Path, Callable[[Path], object]]] = [
        (out / "comparison.json", lambda tmp: tmp.write_text(doc)),
        (out / "comparison.md", lambda tmp: tmp.write_text(md)),
        (out / "comparison.png", lambda tmp: plot_comparison(cmp, tmp)),
    ]
    return write_files(writers)


def write_files(writers: list[tuple[Path, Callable[[Path], object]]]) -> list[Path]:
    """Write each file atomically (temporary name, then rename). On any failure, the files
    already written here are removed again, and so are the folders created for them."""
    from flexreg.io import atomic_write

    done: list[Path] = []
    created: list[Path] = []
    try:
        for path, write in writers:
            missing = [d for d in (path.parent, *path.parent.parents) if not d.exists()]
            created += [d for d in reversed(missing) if d not in created]
            try:
                atomic_write(path, write)
            except OSError as e:
                raise InputError(path, f"cannot write: {e.strerror or e}") from e
            done.append(path)
    except BaseException:
        for p in done:
            p.unlink(missing_ok=True)
        for d in reversed(created):
            with contextlib.suppress(OSError):
                d.rmdir()  # only if empty
        raise
    return done


def _json_safe(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return _json_safe(x.tolist())
    if isinstance(x, np.generic):
        return _json_safe(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Path):
        return str(x)
    return x


__all__ = [
    "COLUMNS",
    "DEFAULT_METHODS",
    "GLOBAL_METHODS",
    "METHODS",
    "MIN_OVERLAP_FITNESS",
    "Comparison",
    "FitEvaluator",
    "Measured",
    "MethodRun",
    "SuccessCriteria",
    "compare",
    "machine_info",
    "make_row",
    "measure_call",
    "measure_isolated",
    "notes",
    "parse_methods",
    "peak_memory_note",
    "plot_comparison",
    "read_ground_truth",
    "run_isolated",
    "run_method",
    "save_pair",
    "table_rows",
    "to_markdown",
    "write_comparison",
    "write_files",
]
