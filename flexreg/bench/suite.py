"""The comparison benchmark behind ``flexreg bench``: flexreg against the baselines on synthetic
station pairs, on real pairs with a reference, and across resolutions.

Suites (every pair runs through :func:`flexreg.bench.compare.compare`, each method in its own
process, wall time and peak memory of the call alone):

- **synthetic**: TLS station pairs from the simulator ``flexreg synth`` uses
  (:mod:`flexreg.synth`: :func:`~flexreg.synth.make_scene`,
  :func:`~flexreg.synth.place_stations`, :func:`~flexreg.synth.scan_tls`), generated in memory.
  Pair ``i`` takes station distance bin ``d = i mod 4`` of
  :attr:`BenchConfig.distance_bins_m` (1–4, 4–8, 8–12, 12–15 m) and relative-yaw bin
  ``(d + i div 4) mod 4`` of :attr:`BenchConfig.yaw_bins_deg` (0–45, ..., 135–180°), a Latin
  square: any 4 consecutive pairs cover every distance bin and every yaw bin, 16 pairs every
  combination once. The yaw is drawn uniformly within its bin, each station gets its own tilt
  (uniform up to ``max_tilt_deg`` about a random horizontal axis), range noise cycles through
  ``noise_mm``. Rooms for the two near bins (alternating with halls), courtyards and halls for
  the far ones. Stations stand on free floor with a mutual visibility overlap of at least
  ``min_overlap`` (a draw that misses it is replaced by the next seed). Exact ground truth.
- **real**: the pairs of ``../shared/data`` with a reference -- Stanford bunny (ground truth;
  limits 1° / 5 mm for a 15 cm object), 3DMatch demo pair (ground truth), fast_gicp Velodyne
  pair (a reference registration that another one contradicts by 0.22° / 1.9 cm; limits
  1° / 5 cm), consecutive Ouster OS1-128 scans (the SDK's reference poses), 3DTK Kurt3D scans
  (odometry prior only: gross limits, 5° / 0.5 m); the others use the synthetic limits.
- **resolution** (part of *synthetic*): one room pair scanned at every resolution of
  ``sweep_resolutions`` (1024x512 ... 8192x4096), for time and peak memory against size.

Results go to a timestamped folder: per-case CSV, summary (CSV, Markdown, JSON), plots (success
rate against station distance and against yaw, time and peak memory against resolution) and
the configuration used. The folder is assembled under a temporary name and renamed at the end,
so a failed run leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from flexreg.bench.compare import (
    DEFAULT_METHODS,
    Comparison,
    SuccessCriteria,
    compare,
    machine_info,
    parse_methods,
    peak_memory_note,
)
from flexreg.core.transforms import invert, rotation_about_axis, rotation_error_deg
from flexreg.errors import ConfigError, DegenerateGeometryError, FlexregError, InputError

if TYPE_CHECKING:
    from flexreg.core.scan import Scan

log = logging.getLogger(__name__)

SUITES = ("synthetic", "real", "all")


@dataclass(frozen=True)
class BenchConfig:
    """Everything a benchmark run depends on; written next to its results.

    Attributes
    ----------
    suite : {"synthetic", "real", "all"}
    quick : bool
        The short variant (fewer, smaller pairs; see :meth:`make`).
    methods : tuple of str
    seed : int
        Seeds the synthetic pairs and every method's randomness.
    pairs : int
        Synthetic pairs.
    resolution : (int, int)
        Synthetic station grid (width, height).
    distance_bins_m : tuple of (float, float), metres
    yaw_bins_deg : tuple of (float, float), degrees
    max_tilt_deg : float, degrees
    noise_mm : tuple of float, millimetres
        Range noise sigma, cycled over the pairs.
    min_overlap : float
        Mutual visibility overlap of the stations (0..1).
    sweep_resolutions : tuple of (int, int)
        Resolutions of the time / memory sweep (empty: no sweep).
    real_pairs : tuple of str
        Names of the real pairs to run (see :data:`REAL_PAIRS`).
    timeout_s : float, seconds
        Time limit per method and pair.
    criteria : SuccessCriteria
        Success limits of the synthetic pairs (the real pairs state their own).
    data_dir : str
        Folder of the real data.
    """

    suite: str = "all"
    quick: bool = False
    methods: tuple[str, ...] = DEFAULT_METHODS
    seed: int = 0
    pairs: int = 16
    resolution: tuple[int, int] = (1024, 512)
    distance_bins_m: tuple[tuple[float, float], ...] = ((1, 4), (4, 8), (8, 12), (12, 15))
    yaw_bins_deg: tuple[tuple[float, float], ...] = ((0, 45), (45, 90), (90, 135), (135, 180))
    max_tilt_deg: float = 5.0
    noise_mm: tuple[float, ...] = (1.0, 3.0, 6.0)
    min_overlap: float = 0.3
    sweep_resolutions: tuple[tuple[int, int], ...] = (
        (1024, 512),
        (2048, 1024),
        (4096, 2048),
        (8192, 4096),
    )
    real_pairs: tuple[str, ...] = ()
    timeout_s: float = 300.0
    criteria: SuccessCriteria = field(default_factory=SuccessCriteria)
    data_dir: str = "../shared/data"

    def __post_init__(self) -> None:
        if self.suite not in SUITES:
            raise ConfigError(f"suite must be one of {', '.join(SUITES)}, got {self.suite!r}")
        parse_methods(self.methods)
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        if int(self.pairs) != self.pairs or self.pairs < 1:
            raise ConfigError(f"pairs must be a positive integer, got {self.pairs}")
        for w, h in (self.resolution, *self.sweep_resolutions):
            if not (16 <= int(w) <= 20000 and 8 <= int(h) <= 10000):
                raise ConfigError(f"resolution must be within 16x8 .. 20000x10000, got {w}x{h}")
        for lo, hi in self.distance_bins_m:
            if not 0 < lo < hi:
                raise ConfigError(f"distance bin must satisfy 0 < min < max, got {lo}..{hi} m")
        for lo, hi in self.yaw_bins_deg:
            if not 0 <= lo < hi <= 180:
                raise ConfigError(f"yaw bin must lie within 0..180 deg, got {lo}..{hi}")
        if not self.distance_bins_m or not self.yaw_bins_deg or not self.noise_mm:
            raise ConfigError("distance bins, yaw bins and noise levels must not be empty")
        if not 0 <= self.max_tilt_deg <= 30:
            raise ConfigError(f"max tilt must be 0..30 deg, got {self.max_tilt_deg}")
        if not 0 <= self.min_overlap < 1:
            raise ConfigError(f"min overlap must be within 0..1, got {self.min_overlap}")
        if any(not (0 <= n <= 1000) for n in self.noise_mm):
            raise ConfigError(f"noise must be 0..1000 mm, got {self.noise_mm}")
        unknown = [n for n in self.real_pairs if n not in REAL_PAIRS]
        if unknown:
            raise ConfigError(
                f"unknown real pair(s) {', '.join(unknown)}; known: {', '.join(REAL_PAIRS)}"
            )
        if not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise ConfigError(f"time limit must be positive, got {self.timeout_s}")

    @classmethod
    def make(cls, suite: str = "all", *, quick: bool = False, **overrides: Any) -> BenchConfig:
        """The full or quick configuration of a suite, with ``overrides``.

        Quick: 4 synthetic pairs at 384x192 (one per distance bin and one per yaw bin), a
        256x128 / 384x192 sweep, two small real pairs (bunny, Ouster), 120 s per method.
        """
        base: dict[str, Any] = {"suite": suite, "quick": quick}
        if quick:
            base |= {
                "pairs": 4,
                "resolution": (384, 192),
                "sweep_resolutions": ((256, 128), (384, 192)),
                "real_pairs": QUICK_REAL_PAIRS,
                "timeout_s": 120.0,
            }
        else:
            base |= {"real_pairs": tuple(REAL_PAIRS)}
        return cls(**(base | overrides))

    @property
    def runs_synthetic(self) -> bool:
        return self.suite in ("synthetic", "all")

    @property
    def runs_real(self) -> bool:
        return self.suite in ("real", "all")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["criteria"] = self.criteria.to_dict()
        return d


@dataclass(eq=False)
class Case:
    """One pair of the benchmark.

    Attributes
    ----------
    suite : {"synthetic", "real", "resolution"}
    name : str
    target, source : Scan
    T_gt : (4, 4) float64
        Reference ``T_target_source``.
    criteria : SuccessCriteria
    params : dict
        What describes the pair (distance, yaw, tilt, noise, resolution, overlap, scene,
        seed, reference, ...).
    """

    suite: str
    name: str
    target: Scan
    source: Scan
    T_gt: NDArray[np.float64]
    criteria: SuccessCriteria
    params: dict[str, Any] = field(default_factory=dict)


# ------------------------------------------------------------------ synthetic pairs


def _tilted(yaw_rad: float, tilt_rad: float, axis_rad: float) -> NDArray[np.float64]:
    Rz = rotation_about_axis([0.0, 0.0, 1.0], yaw_rad)
    Rt = rotation_about_axis([math.cos(axis_rad), math.sin(axis_rad), 0.0], tilt_rad)
    return Rt @ Rz


def synthetic_case(
    index: int,
    config: BenchConfig,
    *,
    resolution: tuple[int, int] | None = None,
    distance_bin_m: tuple[float, float] | None = None,
    yaw_bin_deg: tuple[float, float] | None = None,
    suite: str = "synthetic",
    max_attempts: int = 12,
) -> Case:
    """Synthetic pair ``index`` (see the module notes for the design).

    Raises
    ------
    DegenerateGeometryError
        No placement met the distance and overlap in ``max_attempts`` seeds.
    """
    from flexreg.synth import make_scene, place_stations, scan_tls, station_overlap, stream
    from flexreg.synth.sensors import TLSConfig

    nd, ny = len(config.distance_bins_m), len(config.yaw_bins_deg)
    dbin = distance_bin_m or config.distance_bins_m[index % nd]
    ybin = yaw_bin_deg or config.yaw_bins_deg[(index % nd + index // nd) % ny]
    noise_mm = config.noise_mm[index % len(config.noise_mm)]
    w, h = resolution or config.resolution
    far = dbin[1] > 8.0
    kinds = ("courtyard", "hall") if far else ("room", "hall")
    scene_kind = kinds[(index // nd) % 2]
    tls = TLSConfig(width=int(w), height=int(h), range_noise_m=noise_mm / 1000.0)
    last: Exception | None = None
    for attempt in range(max_attempts):
        seed = config.seed * 100_003 + index * 101 + attempt
        scene = make_scene(scene_kind, seed)
        try:
            Ta, Tb = place_stations(
                scene,
                2,
                min_overlap=config.min_overlap,
                distance_range_m=dbin,
                max_tilt_rad=0.0,
                config=tls,
                rng=stream(seed, 0),
            )
        except DegenerateGeometryError as e:
            last = e
            continue
        gen = stream(seed, 1)
        yaw_a = gen.uniform(-math.pi, math.pi)
        yaw_rel = math.radians(gen.uniform(*ybin)) * (1 if gen.random() < 0.5 else -1)
        max_tilt = math.radians(config.max_tilt_deg)
        tilts = gen.uniform(0.0, max_tilt, size=2)
        axes = gen.uniform(0.0, 2 * math.pi, size=2)
        Ta, Tb = Ta.copy(), Tb.copy()
        Ta[:3, :3] = _tilted(yaw_a, tilts[0], axes[0])
        Tb[:3, :3] = _tilted(yaw_a + yaw_rel, tilts[1], axes[1])
        overlap = station_overlap(scene, Ta, Tb, config=tls)
        if overlap < config.min_overlap:
            last = DegenerateGeometryError(f"overlap {overlap:.2f} after setting the yaw")
            continue
        target = scan_tls(scene, Ta, config=tls, rng=stream(seed, 100), name="station_a")
        source = scan_tls(scene, Tb, config=tls, rng=stream(seed, 101), name="station_b")
        T_gt = invert(Ta) @ Tb
        distance = float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3]))
        params = {
            "scene": scene_kind,
            "seed": seed,
            "distance_m": distance,
            "distance_bin_m": list(dbin),
            "yaw_deg": abs(math.degrees(yaw_rel)),
            "yaw_bin_deg": list(ybin),
            "rotation_deg": rotation_error_deg(T_gt, np.eye(4)),
            "tilt_deg": math.degrees(float(max(tilts))),
            "tilts_deg": [math.degrees(t) for t in tilts],
            "noise_mm": noise_mm,
            "width": int(w),
            "height": int(h),
            "overlap": overlap,
            "points": [len(target), len(source)],
            "reference": "exact (simulated)",
        }
        name = (
            f"{scene_kind} {distance:.1f} m, yaw {abs(math.degrees(yaw_rel)):.0f}°, "
            f"{noise_mm:g} mm, {w}x{h}"
        )
        return Case(suite, name, target, source, T_gt, config.criteria, params)
    raise DegenerateGeometryError(
        f"synthetic pair {index}: no placement {dbin[0]:g}-{dbin[1]:g} m apart with overlap "
        f">= {config.min_overlap:g} in {max_attempts} seeds ({last})"
    )


def synthetic_cases(config: BenchConfig) -> Iterator[Case]:
    """The synthetic pairs, generated one at a time."""
    for i in range(config.pairs):
        yield synthetic_case(i, config)


#: the pair of the resolution sweep: a room, stations 3-6 m apart, yaw 20-40°
SWEEP_DISTANCE_M = (3.0, 6.0)
SWEEP_YAW_DEG = (20.0, 40.0)


def resolution_cases(config: BenchConfig) -> Iterator[Case]:
    """The same room pair scanned at every sweep resolution (largest last)."""
    for w, h in config.sweep_resolutions:
        c = synthetic_case(
            0,
            replace(config, noise_mm=(3.0,)),
            resolution=(w, h),
            distance_bin_m=SWEEP_DISTANCE_M,
            yaw_bin_deg=SWEEP_YAW_DEG,
            suite="resolution",
        )
        c.name = f"room sweep {w}x{h}"
        yield c


# ------------------------------------------------------------------ real pairs

#: real pairs: name -> (folder, what the reference is)
REAL_PAIRS: dict[str, tuple[str, str]] = {
    "bunny bun000 <- bun045": ("bunny_range_scans_gt", "ground truth (bun.conf)"),
    "3DMatch ref <- src": ("reg_3dmatch_geotransformer_demo", "ground truth (gt.npy)"),
    "Velodyne 251370668 <- 251371071": (
        "lidar_pair_fast_gicp",
        "fast_gicp relative.txt (a registration; small_gicp's differs by 0.22° / 1.9 cm)",
    ),
    "Ouster frame 0 <- 1": ("lidar_ouster_os1_128_3scans", "SDK reference poses"),
    "Ouster frame 1 <- 2": ("lidar_ouster_os1_128_3scans", "SDK reference poses"),
    "3DTK scan000 <- scan001": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
    "3DTK scan001 <- scan002": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
    "3DTK scan000 <- scan002": ("tls_3dtk_kurt3d", "odometry prior (gross limits)"),
}
QUICK_REAL_PAIRS: tuple[str, ...] = ("bunny bun000 <- bun045", "Ouster frame 0 <- 1")
#: success limits per reference: exact ground truth of a 15 cm object; a reference
#: registration that disagrees with a second one by 0.22° / 1.9 cm (every converged method
#: lands 0.2-0.6° from it); odometry priors (gross errors only)
BUNNY_CRITERIA = SuccessCriteria(rotation_deg=1.0, translation_m=0.005)
VELODYNE_CRITERIA = SuccessCriteria(rotation_deg=1.0, translation_m=0.05)
ODOMETRY_CRITERIA = SuccessCriteria(rotation_deg=5.0, translation_m=0.5)
#: 3DTK: points nearer than this belong to the robot (the data's config.ini)
KURT_MIN_RANGE_M = 0.48
#: a reference rotation this close (largest element difference) to a rotation is snapped to it
REORTHONORMALISE_TOLERANCE = 1e-3


def check_real_data(data_dir: str | PathLike[str], names: tuple[str, ...]) -> None:
    """Raise :class:`InputError` naming the first missing folder of the chosen real pairs."""
    root = Path(data_dir)
    if not root.is_dir():
        raise InputError(root, "real data folder not found (give it with --data)")
    for name in names:
        folder = root / REAL_PAIRS[name][0]
        if not folder.is_dir():
            raise InputError(folder, f"folder of the real pair {name!r} not found")


def real_case(name: str, data_dir: str | PathLike[str], criteria: SuccessCriteria) -> Case:
    """Load one real pair with its reference ``T_target_source``.

    Raises
    ------
    ConfigError
        Unknown pair name.
    InputError
        Missing or unreadable files.
    """
    from flexreg.io import read_scan, read_scans

    if name not in REAL_PAIRS:
        raise ConfigError(f"unknown real pair {name!r}; known: {', '.join(REAL_PAIRS)}")
    folder_name, reference = REAL_PAIRS[name]
    d = Path(data_dir) / folder_name
    crit = criteria
    if name.startswith("bunny"):
        a, b = read_scans(d / "derived_bunny_grids_and_gt.npz")
        T = invert(a.T_world_scanner) @ b.T_world_scanner
        crit = BUNNY_CRITERIA
    elif name.startswith("3DMatch"):
        a, b = read_scan(d / "ref.npy"), read_scan(d / "src.npy")
        T = _matrix(d / "gt.npy")
    elif name.startswith("Velodyne"):
        a, b = read_scan(d / "251370668.pcd"), read_scan(d / "251371071.pcd")
        T = _matrix(d / "relative.txt")
        crit = VELODYNE_CRITERIA
    elif name.startswith("Ouster"):
        i, j = (0, 1) if name.endswith("0 <- 1") else (1, 2)
        frames = read_scans(d / "derived_destaggered_3scans.npz")
        poses = _kitti_poses(d / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
        a, b = frames[i], frames[j]
        T = invert(poses[i]) @ poses[j]
    else:
        i, j = (int(s[-1]) for s in name.split()[1::2])
        a = read_scan(d / f"scan00{i}.3d", min_range_m=KURT_MIN_RANGE_M)
        b = read_scan(d / f"scan00{j}.3d", min_range_m=KURT_MIN_RANGE_M)
        T = invert(a.T_world_scanner) @ b.T_world_scanner
        crit = ODOMETRY_CRITERIA
    params = {
        "reference": reference,
        "points": [len(a), len(b)],
        "distance_m": float(np.linalg.norm(T[:3, 3])),
        "rotation_deg": rotation_error_deg(T, np.eye(4)),
        "grids": [list(s.grid_shape) if s.grid_shape else None for s in (a, b)],
    }
    return Case("real", name, a, b, T, crit, params)


def _matrix(path: Path) -> NDArray[np.float64]:
    from flexreg.core.transforms import as_transform

    try:
        M = np.array(np.load(path) if path.suffix == ".npy" else np.loadtxt(path), dtype=float)
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot read the reference transform ({e})") from None
    if M.shape == (4, 4) and np.isfinite(M).all():
        # references stored with few digits (3DMatch's gt.npy: orthonormal to 7e-5) get the
        # nearest rotation (SVD); anything further from a rotation is refused below
        U, _, Vt = np.linalg.svd(M[:3, :3])
        R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        if np.abs(R - M[:3, :3]).max() < REORTHONORMALISE_TOLERANCE:
            M[:3, :3] = R
    return as_transform(M, name=str(path))


def _kitti_poses(path: Path) -> list[NDArray[np.float64]]:
    from flexreg.core.transforms import as_transform

    try:
        rows = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot read the poses ({e})") from None
    if rows.shape[1] != 12:
        raise InputError(path, f"expected 12 numbers per KITTI pose line, got {rows.shape[1]}")
    out = []
    for r in rows:
        T = np.eye(4)
        T[:3, :] = r.reshape(3, 4)
        out.append(as_transform(T, name=str(path)))
    return out


def real_cases(config: BenchConfig) -> Iterator[Case]:
    """The chosen real pairs, loaded one at a time."""
    for name in config.real_pairs:
        yield real_case(name, config.data_dir, config.criteria)


# ------------------------------------------------------------------ running


@dataclass(eq=False)
class BenchResult:
    """Every record of a run.

    Attributes
    ----------
    config : BenchConfig
    records : list of dict
        One per (case, method): the case's parameters and the method's row.
    cases : list of dict
        One per case: suite, name, parameters, success limits.
    started, finished : str
        Local times, ISO format.
    elapsed_s : float, seconds
    machine : dict
    command : str
    memory_note : str
        How peak memory was measured.
    """

    config: BenchConfig
    records: list[dict[str, Any]]
    cases: list[dict[str, Any]]
    started: str
    finished: str
    elapsed_s: float
    machine: dict[str, Any]
    command: str
    memory_note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "command": self.command,
            "started": self.started,
            "finished": self.finished,
            "elapsed_s": self.elapsed_s,
            "machine": self.machine,
            "config": self.config.to_dict(),
            "cases": self.cases,
            "records": self.records,
            "memory_note": self.memory_note,
            "summary": summarise(self.records),
        }


def _records(case: Case, cmp: Comparison, index: int) -> list[dict[str, Any]]:
    out = []
    for r in cmp.runs:
        rec: dict[str, Any] = {
            "suite": case.suite,
            "case": index,
            "name": case.name,
            **{k: v for k, v in case.params.items() if not isinstance(v, list | dict)},
            "points_target": cmp.points[0],
            "points_source": cmp.points[1],
            "success_rotation_deg": case.criteria.rotation_deg,
            "success_translation_m": case.criteria.translation_m,
            "scale_m": cmp.scale_m,
            "method": r.method,
            "status": r.status,
            "message": r.message,
            "rotation_error_deg": r.rotation_error_deg,
            "translation_error_m": r.translation_error_m,
            "coarse_rotation_error_deg": r.coarse_rotation_error_deg,
            "coarse_translation_error_m": r.coarse_translation_error_m,
            "success": r.success,
            "coarse_success": r.coarse_success,
            "inlier_rmse_m": r.inlier_rmse_m,
            "fitness": r.fitness,
            "time_s": r.time_s,
            "peak_memory_mb": r.peak_memory_mb,
        }
        out.append(rec)
    return out


def planned_cases(config: BenchConfig) -> list[tuple[str, str, Callable[[], Case]]]:
    """``(suite, label, loader)`` of every case of a run, in order (nothing loaded yet)."""
    plan: list[tuple[str, str, Callable[[], Case]]] = []
    if config.runs_synthetic:
        for i in range(config.pairs):
            label = f"synthetic pair {i + 1}/{config.pairs}"
            plan.append(("synthetic", label, _loader(synthetic_case, i, config)))
        for w, h in config.sweep_resolutions:
            plan.append(("resolution", f"resolution {w}x{h}", _sweep_loader(config, (w, h))))
    if config.runs_real:
        for name in config.real_pairs:
            plan.append(("real", name, _loader(real_case, name, config.data_dir, config.criteria)))
    return plan


def _loader(fn: Callable[..., Case], *args: Any) -> Callable[[], Case]:
    return lambda: fn(*args)


def _sweep_loader(config: BenchConfig, res: tuple[int, int]) -> Callable[[], Case]:
    def load() -> Case:
        return next(resolution_cases(replace(config, sweep_resolutions=(res,))))

    return load


def _unloaded(
    suite: str, label: str, index: int, methods: tuple[str, ...], message: str
) -> list[dict[str, Any]]:
    """Records of a pair that could not be loaded or generated: an error row per method."""
    return [
        {
            "suite": suite,
            "case": index,
            "name": label,
            "method": m,
            "status": "error",
            "message": f"pair not loaded: {message}",
            "success": False,
            "coarse_success": None,
            "rotation_error_deg": None,
            "translation_error_m": None,
            "coarse_rotation_error_deg": None,
            "coarse_translation_error_m": None,
            "inlier_rmse_m": None,
            "fitness": None,
            "time_s": math.nan,
            "peak_memory_mb": None,
        }
        for m in methods
    ]


def run_bench(
    config: BenchConfig,
    *,
    command: str = "",
    progress: Callable[[str, int, int, str], None] | None = None,
) -> BenchResult:
    """Run every case of ``config`` and collect the records.

    Parameters
    ----------
    config : BenchConfig
    command : str
        The command line, recorded with the results.
    progress : callable, optional
        ``progress(case label, case index, number of cases, method)`` before each method.

    Raises
    ------
    InputError
        The real data folder (or a pair's folder) is missing.
    """
    if config.runs_real:
        check_real_data(config.data_dir, config.real_pairs)
    plan = planned_cases(config)
    t0 = time.perf_counter()
    started = datetime.now().isoformat(timespec="seconds")
    machine = machine_info()
    records: list[dict[str, Any]] = []
    cases: list[dict[str, Any]] = []
    for k, (suite, label, load) in enumerate(plan):
        if progress is not None:
            progress(label, k, len(plan), "loading")
        t_load = time.perf_counter()
        try:
            case = load()
        except FlexregError as e:  # a broken pair is a row per method, not the end of the run
            log.warning("%s: %s", label, e)
            cases.append({"suite": suite, "name": label, "load_error": str(e)})
            records += _unloaded(suite, label, k, config.methods, str(e))
            continue
        load_s = time.perf_counter() - t_load

        def report(method: str, i: int, n: int, label: str = label, k: int = k) -> None:
            if progress is not None and method:
                progress(label, k, len(plan), method)

        cmp = compare(
            case.target,
            case.source,
            methods=config.methods,
            T_gt=case.T_gt,
            seed=config.seed,
            criteria=case.criteria,
            timeout_s=config.timeout_s,
            names=(f"{case.name} (target)", f"{case.name} (source)"),
            progress=report,
            require_overlap=False,
        )
        cases.append(
            {
                "suite": case.suite,
                "name": case.name,
                "load_s": load_s,
                "criteria": case.criteria.to_dict(),
                "scale_m": cmp.scale_m,
                "scale_source": cmp.scale_source,
                "fit_denominator": cmp.fit_denominator,
                "T_gt": case.T_gt.tolist(),
                **case.params,
            }
        )
        records += _records(case, cmp, k)
        log.info("%s: %s", case.name, ", ".join(f"{r.method} {r.status}" for r in cmp.runs))
        del case, cmp
    machine["load_average_end"] = machine_info().get("load_average")
    return BenchResult(
        config=config,
        records=records,
        cases=cases,
        started=started,
        finished=datetime.now().isoformat(timespec="seconds"),
        elapsed_s=time.perf_counter() - t0,
        machine=machine,
        command=command,
        memory_note=peak_memory_note(),
    )


# ------------------------------------------------------------------ summaries


def _median(values: list[float]) -> float:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.median(vals) if vals else math.nan


def summarise(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per suite and method: cases, successes, success rate, median errors over the
    successes, median time and peak memory over every run, and the failures by status."""
    out = []
    suites = list(dict.fromkeys(r["suite"] for r in records))
    methods = list(dict.fromkeys(r["method"] for r in records))
    for suite in suites:
        for method in methods:
            rs = [r for r in records if r["suite"] == suite and r["method"] == method]
            if not rs:
                continue
            succ = [r for r in rs if r["success"]]
            coarse = [r for r in rs if r["coarse_success"] is not None]
            statuses: dict[str, int] = {}
            for r in rs:
                if r["status"] != "ok":
                    statuses[r["status"]] = statuses.get(r["status"], 0) + 1
            out.append(
                {
                    "suite": suite,
                    "method": method,
                    "cases": len(rs),
                    "successes": len(succ),
                    "success_rate": len(succ) / len(rs),
                    "coarse_successes": (
                        sum(bool(r["coarse_success"]) for r in coarse) if coarse else None
                    ),
                    "median_rotation_error_deg": _median([r["rotation_error_deg"] for r in succ]),
                    "median_translation_error_m": _median([r["translation_error_m"] for r in succ]),
                    "median_time_s": _median([r["time_s"] for r in rs]),
                    "median_time_success_s": _median([r["time_s"] for r in succ]),
                    "median_peak_memory_mb": _median([r["peak_memory_mb"] for r in rs]),
                    "not_ok": statuses,
                }
            )
    return out


def success_by(
    records: list[dict[str, Any]], key: str, bins: tuple[tuple[float, float], ...]
) -> dict[str, list[tuple[int, int]]]:
    """Synthetic records: per method, ``(successes, cases)`` in each bin of ``key``
    (``distance_m`` or ``yaw_deg``; the last bin includes its upper end)."""
    syn = [r for r in records if r["suite"] == "synthetic"]
    methods = list(dict.fromkeys(r["method"] for r in syn))
    out: dict[str, list[tuple[int, int]]] = {}
    for m in methods:
        cells = []
        for k, (lo, hi) in enumerate(bins):
            last = k == len(bins) - 1
            rs = [
                r
                for r in syn
                if r["method"] == m
                and r.get(key) is not None
                and lo <= r[key]
                and (r[key] <= hi if last else r[key] < hi)
            ]
            cells.append((sum(bool(r["success"]) for r in rs), len(rs)))
        out[m] = cells
    return out


# ------------------------------------------------------------------ rendering

CSV_FIELDS = (
    "suite",
    "case",
    "name",
    "scene",
    "seed",
    "reference",
    "distance_m",
    "yaw_deg",
    "rotation_deg",
    "tilt_deg",
    "noise_mm",
    "width",
    "height",
    "overlap",
    "points_target",
    "points_source",
    "scale_m",
    "method",
    "status",
    "message",
    "rotation_error_deg",
    "translation_error_m",
    "coarse_rotation_error_deg",
    "coarse_translation_error_m",
    "success",
    "coarse_success",
    "success_rotation_deg",
    "success_translation_m",
    "inlier_rmse_m",
    "fitness",
    "time_s",
    "peak_memory_mb",
)
SUMMARY_FIELDS = (
    "suite",
    "method",
    "cases",
    "successes",
    "success_rate",
    "coarse_successes",
    "median_rotation_error_deg",
    "median_translation_error_m",
    "median_time_s",
    "median_time_success_s",
    "median_peak_memory_mb",
)


def to_csv(rows: list[dict[str, Any]], fields: tuple[str, ...]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(fields), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _csv_cell(r.get(k)) for k in fields})
    return buf.getvalue()


def _csv_cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return v


def _f(x: Any, fmt: str, scale: float = 1.0) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return format(x * scale, fmt)


def _bin_label(lo: float, hi: float, unit: str) -> str:
    return f"{lo:g}–{hi:g}{unit}"


def summary_markdown(result: BenchResult, figures: dict[str, str] | None = None) -> str:
    """Tables of a run (summary per suite, success by distance and yaw, real pairs, time and
    memory against resolution) with the figures and the protocol notes."""
    cfg = result.config
    figs = figures or {}
    m = result.machine
    load0 = (m.get("load_average") or [math.nan])[0]
    load1 = (m.get("load_average_end") or [math.nan])[0]
    lines = [
        f"Command: `{result.command}` — {m.get('cores')} cores ({m.get('cpu')}), Python "
        f"{m.get('python')}, numpy {m.get('numpy')}, Open3D {m.get('open3d')}, KISS-ICP "
        f"{m.get('kiss_icp')}. Run {result.started} – {result.finished}: "
        f"{result.elapsed_s / 60:.1f} min; 1-minute load average {load0:.1f} at the start, "
        f"{load1:.1f} at the end"
        + (
            " (other jobs shared the machine: times are pessimistic)"
            if max(load0, load1) > 0.5 * (m.get("cores") or 1) + 0.5
            else ""
        )
        + ".",
        "",
        f"Success = final transform within the pair's limits of the reference (synthetic: "
        f"{cfg.criteria.label()}). Median errors over the successes; median time and peak "
        f"memory over every run of the method (time = the method's call alone, scans in "
        f"memory; peak memory = {result.memory_note}).",
        "",
    ]
    summary = summarise(result.records)
    flex = {s["suite"]: s for s in summary if s["method"] == "flexreg"}
    for suite in dict.fromkeys(s["suite"] for s in summary):
        rows = [s for s in summary if s["suite"] == suite]
        title = {
            "synthetic": "Synthetic station pairs, all methods",
            "real": "Real pairs, all methods",
            "resolution": "Resolution sweep, all methods (one room pair)",
        }.get(suite, suite)
        lines += [
            f"### {title}",
            "",
            "| method | success | coarse success | median rotation error ° | median translation "
            "error mm | median time s | time / flexreg | median peak memory MB | not ok |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|",
        ]
        base = flex.get(suite, {}).get("median_time_s", math.nan)
        for s in rows:
            ratio = s["median_time_s"] / base if base and math.isfinite(base) else math.nan
            bad = ", ".join(f"{k} {v}" for k, v in s["not_ok"].items()) or "–"
            coarse = (
                "–" if s["coarse_successes"] is None else f"{s['coarse_successes']}/{s['cases']}"
            )
            lines.append(
                f"| {s['method']} | {s['successes']}/{s['cases']} ({s['success_rate']:.0%}) "
                f"| {coarse} | {_f(s['median_rotation_error_deg'], '.4f')} "
                f"| {_f(s['median_translation_error_m'], '.2f', 1000)} "
                f"| {_f(s['median_time_s'], '.2f')} | {_f(ratio, '.2f')}x "
                f"| {_f(s['median_peak_memory_mb'], '.0f')} | {bad} |"
            )
        lines.append("")
        if suite == "synthetic":
            lines += _bin_tables(result.records, cfg)
            for key in ("success_vs_distance", "success_vs_yaw"):
                if key in figs:
                    lines += [f"![{key.replace('_', ' ')}]({figs[key]})", ""]
            lines += _case_table(result.records, "synthetic")
        if suite == "real":
            lines += _case_table(result.records, "real")
        if suite == "resolution":
            lines += _resolution_table(result.records)
            for key in ("time_vs_resolution", "memory_vs_resolution"):
                if key in figs:
                    lines += [f"![{key.replace('_', ' ')}]({figs[key]})", ""]
    return "\n".join(lines).rstrip() + "\n"


def _bin_tables(records: list[dict[str, Any]], cfg: BenchConfig) -> list[str]:
    lines: list[str] = []
    for key, bins, unit, what in (
        ("distance_m", cfg.distance_bins_m, " m", "station distance"),
        ("yaw_deg", cfg.yaw_bins_deg, "°", "relative yaw"),
    ):
        table = success_by(records, key, bins)
        lines += [
            f"Successes by {what}:",
            "",
            "| method | " + " | ".join(_bin_label(lo, hi, unit) for lo, hi in bins) + " |",
            "|---|" + "---:|" * len(bins),
        ]
        for method, cells in table.items():
            lines.append(f"| {method} | " + " | ".join(f"{s}/{n}" for s, n in cells) + " |")
        lines.append("")
    return lines


def _case_table(records: list[dict[str, Any]], suite: str) -> list[str]:
    rs = [r for r in records if r["suite"] == suite]
    if not rs:
        return []
    methods = list(dict.fromkeys(r["method"] for r in rs))
    lines = [
        "Per pair: rotation error ° / translation error m (**bold** = success), time s; "
        "failures give their status:",
        "",
        "| pair | limits | " + " | ".join(methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for case in dict.fromkeys(r["case"] for r in rs):
        row = [r for r in rs if r["case"] == case]
        first = row[0]
        cells = []
        for m in methods:
            r = next((x for x in row if x["method"] == m), None)
            if r is None:
                cells.append("")
            elif r["status"] != "ok":
                t = r["time_s"]
                cells.append(r["status"] + (f", {t:.1f} s" if math.isfinite(t) else ""))
            else:
                txt = f"{r['rotation_error_deg']:.3f} / {r['translation_error_m']:.3f}"
                cells.append((f"**{txt}**" if r["success"] else txt) + f", {r['time_s']:.1f} s")
        lim = (first.get("success_rotation_deg"), first.get("success_translation_m"))
        limits = "–" if None in lim else f"{lim[0]:g}° / {lim[1]:g} m"
        lines.append(f"| {first['name']} | {limits} | " + " | ".join(cells) + " |")
    lines.append("")
    fails = [r for r in rs if r["status"] != "ok" and r["status"] != "failed"]
    if fails:
        lines += ["Errors, crashes and timeouts:", ""]
        lines += [f"- {r['name']}, {r['method']}: {r['status']} ({r['message']})" for r in fails]
        lines.append("")
    return lines


def _resolution_table(records: list[dict[str, Any]]) -> list[str]:
    rs = [r for r in records if r["suite"] == "resolution" and r.get("width") is not None]
    if not rs:
        return []
    methods = list(dict.fromkeys(r["method"] for r in rs))
    sizes = list(dict.fromkeys((r["width"], r["height"]) for r in rs))
    lines = [
        "Time s / peak memory MB per resolution (millions of target points in brackets; *fail* "
        "= no success):",
        "",
        "| method | " + " | ".join(f"{w}x{h} ({_mpts(rs, w, h)})" for w, h in sizes) + " |",
        "|---|" + "---:|" * len(sizes),
    ]
    for m in methods:
        cells = []
        for w, h in sizes:
            r = next(
                (x for x in rs if x["method"] == m and (x["width"], x["height"]) == (w, h)), None
            )
            if r is None:
                cells.append("")
                continue
            mem = _f(r["peak_memory_mb"], ".0f")
            tag = (
                "" if r["success"] else (" *fail*" if r["status"] == "ok" else f" *{r['status']}*")
            )
            cells.append(f"{r['time_s']:.1f} / {mem}{tag}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines.append("")
    return lines


def _mpts(rs: list[dict[str, Any]], w: int, h: int) -> str:
    n = next((r.get("points_target") for r in rs if (r["width"], r["height"]) == (w, h)), None)
    return "–" if n is None else f"{n / 1e6:.3g}"


def plot_success_vs(
    records: list[dict[str, Any]],
    key: str,
    bins: tuple[tuple[float, float], ...],
    unit: str,
    xlabel: str,
    path: Path,
) -> None:
    """Success rate per bin of ``key``, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = success_by(records, key, bins)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    x = np.arange(len(bins))
    for i, (method, cells) in enumerate(table.items()):
        rate = [100.0 * s / n if n else np.nan for s, n in cells]
        ax.plot(
            x + (i - len(table) / 2) * 0.02,
            rate,
            marker="os^vDP*"[i % 7],
            lw=2.2 if method == "flexreg" else 1.2,
            label=method,
        )
    counts = [max((c[k][1] for c in table.values()), default=0) for k in range(len(bins))]
    ax.set_xticks(x)
    ax.set_xticklabels(
        [
            f"{_bin_label(lo, hi, unit)}\n({n} pairs)"
            for (lo, hi), n in zip(bins, counts, strict=True)
        ]
    )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-5, 105)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_vs_resolution(records: list[dict[str, Any]], value: str, ylabel: str, path: Path) -> None:
    """``value`` (time_s or peak_memory_mb) against the station size, one line per method;
    hollow markers: no success."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rs = [r for r in records if r["suite"] == "resolution" and r.get("width") is not None]
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    sizes = sorted({(r["width"], r["height"]) for r in rs})
    for i, method in enumerate(dict.fromkeys(r["method"] for r in rs)):
        pts = sorted(
            (
                (r["width"] * r["height"] / 1e6, r[value], bool(r["success"]))
                for r in rs
                if r["method"] == method and r[value] is not None
            ),
        )
        if not pts:
            continue
        xs, ys, ok = zip(*pts, strict=True)
        line = ax.plot(xs, ys, lw=2.2 if method == "flexreg" else 1.2, label=method)[0]
        c = line.get_color()
        mk = "os^vDP*"[i % 7]
        ax.scatter(
            [x for x, o in zip(xs, ok, strict=True) if o],
            [y for y, o in zip(ys, ok, strict=True) if o],
            color=c,
            marker=mk,
        )
        ax.scatter(
            [x for x, o in zip(xs, ok, strict=True) if not o],
            [y for y, o in zip(ys, ok, strict=True) if not o],
            facecolors="none",
            edgecolors=c,
            marker=mk,
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks([w * h / 1e6 for w, h in sizes])
    ax.set_xticklabels([f"{w}x{h}" for w, h in sizes], fontsize=8)
    ax.minorticks_off()
    ax.set_xlabel("station grid (both stations this size)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="best", title="hollow: no success", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


FIGURES = {
    "success_vs_distance": "success_vs_distance.png",
    "success_vs_yaw": "success_vs_yaw.png",
    "time_vs_resolution": "time_vs_resolution.png",
    "memory_vs_resolution": "memory_vs_resolution.png",
}


def write_bench(result: BenchResult, out_dir: str | PathLike[str]) -> Path:
    """Write a run into ``out_dir/bench-<start time>/`` and return that folder.

    Files: ``cases.csv`` (one row per pair and method), ``summary.csv``, ``summary.md``,
    ``results.json`` (everything), ``config.json``, and the figures of :data:`FIGURES` that
    the suites produced. The folder is assembled as ``.bench-<time>.partial`` and renamed
    when complete.

    Raises
    ------
    InputError
        ``out_dir`` is a file, or the folder cannot be written.
    """
    import shutil

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    stamp = datetime.fromisoformat(result.started).strftime("%Y%m%d-%H%M%S")
    final = out / f"bench-{stamp}"
    n = 1
    while final.exists():
        n += 1
        final = out / f"bench-{stamp}-{n}"
    tmp = out / f".{final.name}.partial"
    created = [d for d in (out, *out.parents) if not d.exists()]
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        recs = result.records
        figs: dict[str, str] = {}
        cfg = result.config
        if any(r["suite"] == "synthetic" for r in recs):
            plot_success_vs(
                recs,
                "distance_m",
                cfg.distance_bins_m,
                " m",
                "station distance",
                tmp / FIGURES["success_vs_distance"],
            )
            plot_success_vs(
                recs,
                "yaw_deg",
                cfg.yaw_bins_deg,
                "°",
                "relative yaw of the stations",
                tmp / FIGURES["success_vs_yaw"],
            )
            figs["success_vs_distance"] = FIGURES["success_vs_distance"]
            figs["success_vs_yaw"] = FIGURES["success_vs_yaw"]
        if any(r["suite"] == "resolution" for r in recs):
            plot_vs_resolution(
                recs, "time_s", "time of the call (s)", tmp / FIGURES["time_vs_resolution"]
            )
            plot_vs_resolution(
                recs,
                "peak_memory_mb",
                "peak memory increase (MB)",
                tmp / FIGURES["memory_vs_resolution"],
            )
            figs["time_vs_resolution"] = FIGURES["time_vs_resolution"]
            figs["memory_vs_resolution"] = FIGURES["memory_vs_resolution"]
        (tmp / "cases.csv").write_text(to_csv(recs, CSV_FIELDS))
        (tmp / "summary.csv").write_text(to_csv(summarise(recs), SUMMARY_FIELDS))
        (tmp / "summary.md").write_text(
            "# Comparison benchmark\n\n" + summary_markdown(result, figs)
        )
        (tmp / "results.json").write_text(json.dumps(_json_safe(result.to_dict()), indent=1) + "\n")
        (tmp / "config.json").write_text(
            json.dumps(_json_safe(result.config.to_dict()), indent=2) + "\n"
        )
        tmp.rename(final)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        for d in created:  # innermost first; only folders this call made, if still empty
            with contextlib.suppress(OSError):
                d.rmdir()
        if isinstance(e, OSError):
            raise InputError(out, f"cannot write the results: {e.strerror or e}") from e
        raise
    return final


def load_bench(path: str | PathLike[str]) -> BenchResult:
    """A run again from its ``results.json`` (to render its tables and plots anew).

    Raises
    ------
    InputError
        Missing or unreadable file, or not a benchmark result.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
        cfg = dict(doc["config"])
        crit = SuccessCriteria(**cfg.pop("criteria"))
        for key in (
            "methods",
            "resolution",
            "distance_bins_m",
            "yaw_bins_deg",
            "noise_mm",
            "sweep_resolutions",
            "real_pairs",
        ):  # JSON lists back to the tuples of the frozen configuration
            cfg[key] = tuple(tuple(v) if isinstance(v, list) else v for v in cfg[key])
        config = BenchConfig(**cfg, criteria=crit)
        records = [
            {k: (math.nan if k == "time_s" and v is None else v) for k, v in r.items()}
            for r in doc["records"]
        ]
        cases = doc["cases"]
        for r in records:  # runs before the point counts were per record
            pts = cases[r["case"]].get("points") if r["case"] < len(cases) else None
            if "points_target" not in r and pts:
                r["points_target"], r["points_source"] = pts
        return BenchResult(
            config=config,
            records=records,
            cases=cases,
            started=doc["started"],
            finished=doc["finished"],
            elapsed_s=float(doc["elapsed_s"]),
            machine=doc["machine"],
            command=doc["command"],
            memory_note=doc.get("memory_note") or peak_memory_note(),
        )
    except OSError as e:
        raise InputError(p, f"cannot read: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, IndexError) as e:
        raise InputError(p, f"not a benchmark results.json ({type(e).__name__}: {e})") from None


def _json_safe(x: Any) -> Any:
    from flexreg.bench.compare import _json_safe as safe

    return safe(x)


__all__ = [
    "QUICK_REAL_PAIRS",
    "REAL_PAIRS",
    "SUITES",
    "BenchConfig",
    "BenchResult",
    "Case",
    "check_real_data",
    "load_bench",
    "planned_cases",
    "real_case",
    "resolution_cases",
    "run_bench",
    "success_by",
    "summarise",
    "summary_markdown",
    "synthetic_case",
    "synthetic_cases",
    "write_bench",
]
