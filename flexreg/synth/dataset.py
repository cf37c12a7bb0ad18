"""Write a complete synthetic data set: stations, mesh, ground truth, optional RGB-D and lidar.

:func:`synthesize` is what ``flexreg synth`` runs. Output folder layout::

    scene.ply              the mesh (float64 vertices, per-face colour and reflectance)
    station_00.ptx ...     one file per TLS station (.ptx, .e57 or .npz), scanner frame
    gt.json                station poses, pairwise T_target_source, scene and configuration
    rgbd/                  TUM-style RGB-D sequence (with --rgbd-frames N)
    camera.png ...         a camera on the first station (with --rig: camera.json, init.json
                           and T_camera_lidar in gt.json; see flexreg.synth.rig)
    lidar/                 spinning-lidar sweeps and poses (with --lidar-frames N)

The station files hold points in each scanner's own frame with an identity pose (as an
unregistered scanner export would), unless ``embed_poses`` is set; the truth is in ``gt.json``.
Nothing in the output depends on the time, the folder name or the machine: the same
configuration gives byte-identical PTX, PLY, PNG and JSON files.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg._version import __version__
from flexreg.core.transforms import as_transform, invert
from flexreg.errors import ConfigError, InputError
from flexreg.io import atomic_write, write_scan
from flexreg.synth.config import RGBDConfig, SynthConfig, TLSConfig
from flexreg.synth.placement import free_map, place_stations, station_overlap, stream
from flexreg.synth.project import (
    ProjectPlacement,
    overlap_matrix,
    place_project,
    project_ground_truth,
)
from flexreg.synth.rig import Rig, place_rig, write_rig
from flexreg.synth.scene import Scene
from flexreg.synth.scenes import (
    PROJECT_SCENE_KINDS,
    SCENE_KINDS,
    make_project_scene,
    make_scene,
    scene_from_mesh,
)
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import (
    lidar_config,
    look_at,
    scan_tls,
    write_tum_sequence,
)

Progress = Callable[[str, int, int], None]

# stream ids (see placement.stream)
_PLACEMENT, _TRAJECTORY, _RGBD, _LIDAR_TRAJ, _LIDAR, _STATION = 0, 1, 2, 3, 4, 100
_RIG, _RIG_IMAGE = 5, 6


@dataclass(eq=False)
class StationInfo:
    """One written station."""

    name: str
    file: str
    T_world_scanner: NDArray[np.float64]
    n_points: int
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "file": self.file,
            "T_world_scanner": self.T_world_scanner.tolist(),
            "points": self.n_points,
        }


@dataclass(eq=False)
class PairInfo:
    """A pair of stations with its ground truth."""

    target: str
    source: str
    T_target_source: NDArray[np.float64]
    distance_m: float
    overlap: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "source": self.source,
            "T_target_source": self.T_target_source.tolist(),
            "distance_m": self.distance_m,
            "overlap": self.overlap,
        }


@dataclass(eq=False)
class SynthResult:
    """What :func:`synthesize` wrote (timings are reported here, never written to files);
    ``project`` is the ``"project"`` part of ``gt.json`` for project scenes (else empty),
    ``rig`` the camera of ``--rig`` (else None)."""

    out_dir: Path
    scene: Scene
    stations: list[StationInfo]
    pairs: list[PairInfo]
    files: list[Path] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    project: dict[str, Any] = field(default_factory=dict)
    rig: Rig | None = None

    def __repr__(self) -> str:
        return (
            f"SynthResult({self.scene!r}, {len(self.stations)} stations, {len(self.pairs)} pairs, "
            f"{len(self.files)} files in {self.out_dir})"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "out_dir": str(self.out_dir),
            "scene": self.scene.to_dict(),
            "stations": [s.to_dict() for s in self.stations],
            "pairs": [p.to_dict() for p in self.pairs],
            "files": [str(f) for f in self.files],
            "seconds": dict(self.seconds),
            "project": dict(self.project),
            "rig": None if self.rig is None else self.rig.to_dict(),
        }


def build_scene(config: SynthConfig) -> Scene:
    """The scene of a configuration: procedural (seeded), a project sized for its stations, or
    a mesh file."""
    if config.scene in SCENE_KINDS:
        return make_scene(config.scene, config.seed, size_m=config.size_m)
    if config.scene in PROJECT_SCENE_KINDS:
        return make_project_scene(
            config.scene,
            config.seed,
            stations=config.stations,
            groups=config.groups,
            size_m=config.size_m,
        )
    return scene_from_mesh(config.scene, scale=config.mesh_scale, up_axis=config.mesh_up_axis)


def _catmull_rom(p0: Any, p1: Any, p2: Any, p3: Any) -> NDArray[np.float64]:
    """Catmull-Rom spline from ``p1`` to ``p2`` (excluding ``p2``), ~5 cm spacing."""
    n = max(4, int(np.linalg.norm(p2 - p1) / 0.05))
    t = np.linspace(0, 1, n, endpoint=False)[:, None]
    return 0.5 * (
        2 * p1
        + (-p0 + p2) * t
        + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2
        + (-p0 + 3 * p1 - 3 * p2 + p3) * t**3
    )


def smooth_path(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float,
    height_range_m: tuple[float, float] = (1.2, 1.7),
    clearance_m: float = 0.5,
    rng: np.random.Generator | int | None = 0,
    tries: int = 200,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions and headings of a smooth walk through free space.

    A random walk over free floor (steps of 0.8-2.5 m with gentle turns, stepping back out of
    dead ends) is smoothed by a Catmull-Rom spline and sampled every ``step_m`` metres. Each new
    waypoint is accepted only if the spline piece it completes stays on free floor and
    ``clearance_m`` away from all surfaces.

    Returns
    -------
    positions : (n_frames, 3) float64, metres
    heading : (n_frames,) float64, radians
        Direction of travel (azimuth from +X).
    """
    gen, _ = as_rng(rng)
    if step_m <= 0:
        raise ConfigError(f"step must be positive, got {step_m}")
    fm = free_map(scene)
    fy, fx = np.nonzero(fm.free)
    if len(fx) == 0:
        raise InputError(scene.name or "scene", "no free floor for a sensor path")
    length = max(n_frames, 2) * step_m + 0.5
    h0, h1 = height_range_m

    def clear(pts: NDArray[np.float64]) -> bool:
        return bool(fm.lookup(pts[:, :2])[0].all() and scene.distance(pts).min() >= clearance_m)

    for _ in range(tries):
        # a random walk over free floor (steps of 0.8-2.5 m, gentle turns); each new waypoint
        # must keep the spline piece it completes on free floor and clear of all surfaces
        c = gen.integers(0, len(fx))
        xy0 = np.array([fm.x0 + fx[c] * fm.cell_m, fm.y0 + fy[c] * fm.cell_m])
        W = [np.array([*xy0, fm.lookup(xy0[None])[1][0] + gen.uniform(h0, h1)])]
        if not clear(W[0][None]):
            continue
        heading = gen.uniform(-math.pi, math.pi)
        pieces: list[NDArray[np.float64]] = []
        lengths: list[float] = []
        stuck = backtracks = 0
        while sum(lengths) < length and backtracks < 200:
            if stuck >= 48:  # dead end: step back one waypoint and try elsewhere
                if len(W) < 3:
                    break
                W.pop()
                pieces.pop()
                lengths.pop()
                heading = gen.uniform(-math.pi, math.pi)
                stuck = 0
                backtracks += 1
                continue
            turn = gen.normal(0.0, 0.5) if stuck < 24 else gen.uniform(-math.pi, math.pi)
            step = gen.uniform(0.8, 2.5)
            h = heading + turn
            qxy = W[-1][:2] + step * np.array([math.cos(h), math.sin(h)])
            free, gz = fm.lookup(qxy[None])
            if not free[0]:
                stuck += 1
                continue
            q = np.array([*qxy, gz[0] + gen.uniform(h0, h1)])
            if len(W) == 1:
                seg = W[0] + np.linspace(0, 1, max(2, int(step / 0.05)))[:, None] * (q - W[0])
                new = None
                ok = clear(seg)
            else:
                p0 = W[-3] if len(W) >= 3 else 2 * W[-2] - W[-1]
                new = _catmull_rom(p0, W[-2], W[-1], q)
                ok = clear(new) and clear(q[None])
            if not ok:
                stuck += 1
                continue
            if new is not None:
                pieces.append(new)
                lengths.append(
                    float(np.linalg.norm(np.diff(np.vstack([new, W[-1]]), axis=0), axis=1).sum())
                )
            W.append(q)
            heading = h
            stuck = 0
        if sum(lengths) < length:
            continue
        dense = np.vstack(pieces)
        cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
        s = np.arange(n_frames) * step_m
        P = np.column_stack([np.interp(s, cum, dense[:, i]) for i in range(3)])
        ahead = np.column_stack([np.interp(s + 0.3, cum, dense[:, i]) for i in range(3)])
        return P, np.arctan2(ahead[:, 1] - P[:, 1], ahead[:, 0] - P[:, 0])
    raise InputError(
        scene.name or "scene",
        f"could not find a clear sensor path of {length:.1f} m in {tries} tries; use fewer frames "
        "or a larger scene",
    )


def camera_trajectory(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float,
    rng: np.random.Generator | int | None = 0,
) -> list[NDArray[np.float64]]:
    """Hand-held RGB-D camera poses (x right, y down, z forward) along :func:`smooth_path`,
    looking ahead with a slow pan (+-23 deg) and a downward tilt (11 +- 6 deg)."""
    gen, _ = as_rng(rng)
    P, heading = smooth_path(scene, n_frames, step_m=step_m, rng=gen)
    phase = gen.uniform(0, 2 * math.pi, size=2)
    poses = []
    for i in range(n_frames):
        s = i * step_m
        yaw = heading[i] + 0.4 * math.sin(s / 2.0 + phase[0])
        pitch = -0.2 + 0.1 * math.sin(s / 3.1 + phase[1])
        d = [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
        poses.append(look_at(P[i], P[i] + d))
    return poses


def lidar_trajectory(
    scene: Scene,
    n_frames: int,
    *,
    step_m: float = 0.5,
    rng: np.random.Generator | int | None = 0,
) -> list[NDArray[np.float64]]:
    """Level spinning-lidar poses (x forward, z up) every ``step_m`` along :func:`smooth_path`
    (0.5 m: a 10 Hz lidar moving at 5 m/s)."""
    P, heading = smooth_path(
        scene, n_frames, step_m=step_m, height_range_m=(1.7, 1.9), clearance_m=0.3, rng=rng
    )
    poses = []
    for p, h in zip(P, heading, strict=True):
        T = np.eye(4)
        c, s_ = math.cos(h), math.sin(h)
        T[:3, :3] = [[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]
        T[:3, 3] = p
        poses.append(T)
    return poses


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    text = json.dumps(doc, indent=2) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _place(
    scene: Scene, cfg: SynthConfig, tls: TLSConfig, poses: Sequence[ArrayLike] | None
) -> tuple[list[NDArray[np.float64]], ProjectPlacement | None]:
    """The stations' ``T_world_scanner``: the given ones, a project's or a seeded placement
    (and the project's placement record)."""
    if poses is not None:
        placed = [as_transform(T) for T in poses]
        if len(placed) != cfg.stations:
            raise ConfigError(f"poses: {len(placed)} given for {cfg.stations} stations")
        return placed, None
    place = place_project if cfg.is_project else place_stations
    result = place(
        scene,
        cfg.stations,
        min_overlap=cfg.min_overlap,
        distance_range_m=cfg.distance_range_m,
        max_tilt_rad=cfg.max_tilt_rad,
        config=tls,
        rng=stream(cfg.seed, _PLACEMENT),
    )
    if isinstance(result, ProjectPlacement):
        return result.poses, result
    return result, None


def synthesize(
    out_dir: str | PathLike[str],
    config: SynthConfig | None = None,
    *,
    poses: Sequence[ArrayLike] | None = None,
    progress: Progress | None = None,
) -> SynthResult:
    """Generate a scene, place and simulate stations, and write everything to ``out_dir``.

    Nothing is written until the scene exists and all stations are placed, so bad settings
    (e.g. an impossible distance range) leave no partial output.

    Parameters
    ----------
    out_dir : path-like
        Output folder (created; existing files of the same names are replaced).
    config : SynthConfig
    poses : sequence of (4, 4) float64, optional
        ``T_world_scanner`` of every station (metres), one per ``config.stations``, instead
        of placing them: a fixed view whatever the CPU (seeded placement depends on ray-cast
        ties between coplanar faces, see docs/determinism.md).
    progress : callable, optional
        ``progress(stage, done, total)`` after each station / frame.

    Returns
    -------
    SynthResult

    Raises
    ------
    ConfigError, InputError, DegenerateGeometryError
    """
    cfg = config or SynthConfig()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "output exists and is not a folder")
    tls = cfg.tls_config()
    secs: dict[str, float] = {}
    t0 = time.perf_counter()
    scene = build_scene(cfg)
    secs["scene"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    placed, plan = _place(scene, cfg, tls, poses)
    secs["placement"] = time.perf_counter() - t0
    traj: list[NDArray[np.float64]] = []
    rgbd_cfg = RGBDConfig()
    if cfg.rgbd_frames:
        traj = camera_trajectory(
            scene,
            cfg.rgbd_frames,
            step_m=rgbd_cfg.speed_mps / rgbd_cfg.rate_hz,
            rng=stream(cfg.seed, _TRAJECTORY),
        )
    lidar_traj: list[NDArray[np.float64]] = []
    if cfg.lidar_frames:
        lidar_traj = lidar_trajectory(scene, cfg.lidar_frames, rng=stream(cfg.seed, _LIDAR_TRAJ))
    rig: Rig | None = None
    if cfg.rig:
        rig = place_rig(scene, placed[0], station_width=cfg.width, rng=stream(cfg.seed, _RIG))

    # nothing is written before this point
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    t0 = time.perf_counter()
    files.append(scene.write(out / "scene.ply"))
    secs["mesh"] = time.perf_counter() - t0
    stations = _write_stations(out, scene, placed, cfg, tls, files, progress)
    secs["stations"] = sum(s.seconds for s in stations)
    t0 = time.perf_counter()
    project_doc: dict[str, Any] = {}
    if plan is None:
        pairs = _station_pairs(scene, placed, stations, cfg, tls)
    else:
        overlap = overlap_matrix(scene, placed, config=tls)
        pairs = _project_pairs(overlap, placed, stations, cfg)
        names = [s.name for s in stations]
        project_doc = project_ground_truth(plan, overlap, names, cfg.min_overlap)
    secs["pairs"] = time.perf_counter() - t0
    if cfg.rgbd_frames:
        t0 = time.perf_counter()
        files += write_tum_sequence(
            out / "rgbd",
            scene,
            traj,
            config=rgbd_cfg,
            rng=stream(cfg.seed, _RGBD),
            progress=None if progress is None else (lambda d, n: progress("rgbd", d, n)),
        )
        secs["rgbd"] = time.perf_counter() - t0
    lidar_doc: list[dict[str, Any]] = []
    if cfg.lidar_frames:
        t0 = time.perf_counter()
        lidar_doc = _write_lidar(out, scene, lidar_traj, cfg, files, progress)
        secs["lidar"] = time.perf_counter() - t0
    doc = _ground_truth(cfg, tls, scene, stations, pairs, rgbd_cfg, lidar_doc)
    if rig is not None:
        t0 = time.perf_counter()
        written, entry = write_rig(
            out, scene, rig, station_file=stations[0].file, rng=stream(cfg.seed, _RIG_IMAGE)
        )
        files += written
        doc["T_camera_lidar"] = entry["T_camera_lidar"]
        doc["rig"] = entry
        doc["convention"] += (
            "; T_camera_lidar = inv(T_world_camera) @ T_world_scanner maps the first station "
            "file's points into the camera frame (x right, y down, z forward)"
        )
        secs["rig"] = time.perf_counter() - t0
    if plan is not None:
        for entry, g, parent in zip(doc["stations"], plan.groups, plan.parents, strict=True):
            entry["T_world_station"] = entry["T_world_scanner"]
            entry["group"] = g
            entry["parent"] = stations[parent].name if parent >= 0 else None
        doc["project"] = project_doc
    _write_json(out / "gt.json", doc)
    files.append(out / "gt.json")
    return SynthResult(out, scene, stations, pairs, files, secs, project_doc, rig)


def _write_stations(
    out: Path,
    scene: Scene,
    poses: list[NDArray[np.float64]],
    cfg: SynthConfig,
    tls: TLSConfig,
    files: list[Path],
    progress: Progress | None,
) -> list[StationInfo]:
    """Simulate and write every station (appending to ``files``)."""
    stations: list[StationInfo] = []
    digits = max(2, len(str(len(poses) - 1)))  # names sort in file order
    for i, T in enumerate(poses):
        t0 = time.perf_counter()
        name = f"station_{i:0{digits}d}"
        scan = scan_tls(scene, T, config=tls, rng=stream(cfg.seed, _STATION + i), name=name)
        t_sim = time.perf_counter() - t0
        if not cfg.embed_poses:
            scan = replace(scan, T_world_scanner=np.eye(4))
        path = out / f"{name}.{cfg.format}"
        write_scan(path, scan)
        files.append(path)
        stations.append(StationInfo(name, path.name, T, len(scan), t_sim))
        if progress is not None:
            progress("stations", i + 1, len(poses))
    return stations


def _station_pairs(
    scene: Scene,
    poses: list[NDArray[np.float64]],
    stations: list[StationInfo],
    cfg: SynthConfig,
    tls: TLSConfig,
) -> list[PairInfo]:
    """Every station pair within the distance range and with at least the minimal overlap,
    with its ground truth ``T_target_source = inv(T_world_target) @ T_world_source``."""
    pairs: list[PairInfo] = []
    d0, d1 = cfg.distance_range_m
    for i in range(len(poses)):
        for j in range(i + 1, len(poses)):
            d = float(np.linalg.norm(poses[j][:3, 3] - poses[i][:3, 3]))
            if not d0 <= d <= d1:
                continue
            ov = station_overlap(scene, poses[i], poses[j], config=tls)
            if ov >= cfg.min_overlap:
                pairs.append(
                    PairInfo(stations[i].name, stations[j].name, invert(poses[i]) @ poses[j], d, ov)
                )
    return pairs


def _project_pairs(
    overlap: NDArray[np.float64],
    poses: list[NDArray[np.float64]],
    stations: list[StationInfo],
    cfg: SynthConfig,
) -> list[PairInfo]:
    """The pairs of :func:`_station_pairs` (distance within the range, overlap at least the
    minimum), from a project's overlap matrix."""
    pairs: list[PairInfo] = []
    d0, d1 = cfg.distance_range_m
    for i in range(len(poses)):
        for j in range(i + 1, len(poses)):
            d = float(np.linalg.norm(poses[j][:3, 3] - poses[i][:3, 3]))
            ov = float(min(overlap[i, j], overlap[j, i]))
            if d0 <= d <= d1 and ov >= cfg.min_overlap:
                pairs.append(
                    PairInfo(stations[i].name, stations[j].name, invert(poses[i]) @ poses[j], d, ov)
                )
    return pairs


def _write_lidar(
    out: Path,
    scene: Scene,
    lidar_traj: list[NDArray[np.float64]],
    cfg: SynthConfig,
    files: list[Path],
    progress: Progress | None,
) -> list[dict[str, Any]]:
    """Simulate and write the spinning-lidar sweeps (appending to ``files``); their entries of
    ``gt.json``."""
    lidar_doc: list[dict[str, Any]] = []
    lcfg = lidar_config()
    gen = stream(cfg.seed, _LIDAR)
    for i, T in enumerate(lidar_traj):
        name = f"lidar_{i:05d}"
        scan = scan_tls(scene, T, config=lcfg, rng=gen, name=name)
        if not cfg.embed_poses:
            scan = replace(scan, T_world_scanner=np.eye(4))
        path = out / "lidar" / f"{name}.{cfg.format}"
        write_scan(path, scan)
        files.append(path)
        lidar_doc.append({"name": name, "file": f"lidar/{path.name}", "T_world_sensor": T.tolist()})
        if progress is not None:
            progress("lidar", i + 1, len(lidar_traj))
    return lidar_doc


def _ground_truth(
    cfg: SynthConfig,
    tls: TLSConfig,
    scene: Scene,
    stations: list[StationInfo],
    pairs: list[PairInfo],
    rgbd_cfg: RGBDConfig,
    lidar_doc: list[dict[str, Any]],
) -> dict[str, Any]:
    """The content of ``gt.json``."""
    doc: dict[str, Any] = {
        "flexreg_version": __version__,
        "convention": (
            "T_target_source = inv(T_world_target) @ T_world_source; points of the station "
            "files are in each scanner's frame; 4x4 row-major, metres"
        ),
        "overlap_definition": (
            "min over both directions of the share of a station's returns "
            "(2 degree grid) that the other station also sees"
        ),
        "config": cfg.to_dict(),
        "sensor": tls.to_dict(),
        "scene": {**scene.to_dict(), "mesh": "scene.ply"},
        "stations": [s.to_dict() for s in stations],
        "pairs": [p.to_dict() for p in pairs],
    }
    if cfg.rgbd_frames:
        doc["rgbd"] = {
            "folder": "rgbd",
            "frames": cfg.rgbd_frames,
            "camera": rgbd_cfg.camera().to_dict(),
        }
    if cfg.lidar_frames:
        doc["lidar"] = {"sensor": lidar_config().to_dict(), "frames": lidar_doc}
    return doc


def make_project(
    kind: str,
    *,
    stations: int,
    out: str | PathLike[str],
    resolution: tuple[int, int] = (1024, 512),
    seed: int = 0,
    groups: int = 1,
    max_tilt_rad: float = math.radians(3.0),
    progress: Progress | None = None,
    **settings: Any,
) -> SynthResult:
    """Write a multi-station project: what ``flexreg synth --scene KIND --stations N`` writes.

    >>> make_project("building", stations=36, out="proj", seed=2)  # doctest: +SKIP

    Parameters
    ----------
    kind : {"building", "warehouse", "street"}
    stations : int
        At least 2 per group.
    out : path-like
        Output folder.
    resolution : (int, int)
        Station grid ``(width, height)``.
    seed : int
    groups : int
        Disconnected sites (1..4).
    max_tilt_rad : float, radians
    progress : callable, optional
        As for :func:`synthesize`.
    **settings
        Further :class:`~flexreg.synth.config.SynthConfig` fields (``format``, ``noise_m``,
        ``min_overlap``...).

    Returns
    -------
    SynthResult
    """
    if kind not in PROJECT_SCENE_KINDS:
        raise ConfigError(
            f"unknown project kind {kind!r}; choose one of {', '.join(PROJECT_SCENE_KINDS)}"
        )
    cfg = SynthConfig(
        **{
            "scene": kind,
            "stations": stations,
            "width": int(resolution[0]),
            "height": int(resolution[1]),
            "seed": seed,
            "groups": groups,
            "max_tilt_rad": max_tilt_rad,
            **settings,
        }
    )
    return synthesize(out, cfg, progress=progress)
