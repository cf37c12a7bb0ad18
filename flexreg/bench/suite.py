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

The configuration and record types are in :mod:`flexreg.bench.types`, the summaries and tables
in :mod:`flexreg.bench.summary`, the result folder (:func:`~flexreg.bench.results.write_bench`)
in :mod:`flexreg.bench.results`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.bench.compare import Comparison, SuccessCriteria, compare
from flexreg.bench.measure import machine_info, peak_memory_note
from flexreg.bench.types import REAL_PAIRS, BenchConfig, BenchResult, Case
from flexreg.core.transforms import as_transform, invert, rotation_about_axis, rotation_error_deg
from flexreg.errors import ConfigError, DegenerateGeometryError, FlexregError, InputError
from flexreg.io import read_scan, read_scans
from flexreg.io.transform_io import read_ground_truth
from flexreg.synth import make_scene, place_stations, scan_tls, station_overlap, stream
from flexreg.synth.config import TLSConfig

__all__ = [
    "check_real_data",
    "planned_cases",
    "real_case",
    "real_cases",
    "resolution_cases",
    "run_bench",
    "synthetic_case",
    "synthetic_cases",
]

log = logging.getLogger(__name__)


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
            config.replace(noise_mm=(3.0,)),
            resolution=(w, h),
            distance_bin_m=SWEEP_DISTANCE_M,
            yaw_bin_deg=SWEEP_YAW_DEG,
            suite="resolution",
        )
        c.name = f"room sweep {w}x{h}"
        yield c


# ------------------------------------------------------------------ real pairs

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
        T = read_ground_truth(d / "gt.npy", reorthonormalize=REORTHONORMALISE_TOLERANCE)
    elif name.startswith("Velodyne"):
        a, b = read_scan(d / "251370668.pcd"), read_scan(d / "251371071.pcd")
        T = read_ground_truth(d / "relative.txt", reorthonormalize=REORTHONORMALISE_TOLERANCE)
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


def _kitti_poses(path: Path) -> list[NDArray[np.float64]]:
    """The poses of a KITTI trajectory file as written: :func:`flexreg.io.read_trajectory`
    projects each rotation block onto the nearest rotation, which moves the reference poses
    by rounding errors."""
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
            "open3d_fitness": r.open3d_fitness,
            "open3d_inlier_rmse_m": r.open3d_inlier_rmse_m,
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
        return next(resolution_cases(config.replace(sweep_resolutions=(res,))))

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
            "open3d_fitness": None,
            "open3d_inlier_rmse_m": None,
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
