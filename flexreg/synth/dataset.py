"""Write a complete synthetic data set: stations, mesh, ground truth, optional RGB-D and lidar.

:func:`synthesize` is what ``flexreg synth`` runs. Output folder layout::

    scene.ply              the mesh (float64 vertices, per-face colour and reflectance)
    station_00.ptx ...     one file per TLS station (.ptx, .e57 or .npz), scanner frame
    gt.json                station poses, pairwise T_target_source, scene and configuration
    rgbd/                  TUM-style RGB-D sequence (with --rgbd-frames N)
    camera.png ...         a camera on the first station (with --rig: camera.json, init.json
                           and T_camera_lidar in gt.json; see flexreg.synth.rig)
    lidar/                 lidar frames (with --lidar-frames N): spinning-lidar sweeps in the
                           stations' format, or rosette frames as PCD (--lidar-kind rosette)
    views/                 object views instead of stations (with --views N, --scene object or
                           a mesh): view_00.png + view_00.camera.json ...
    fragments/             fused fragments (with --fragments N): fragment_000.ply ...

The station files hold points in each scanner's own frame with an identity pose (as an
unregistered scanner export would), unless ``embed_poses`` is set; the truth is in ``gt.json``.
So do the lidar frames and views (their sensor's frame) and the fragments (their first
camera's frame); see :mod:`flexreg.synth.products`. Everything is written at the end or, on
an error, nothing (:func:`flexreg.io.files.all_or_nothing`). Nothing in the output depends on
the time, the folder name or the machine: the same configuration gives byte-identical PTX,
PLY, PCD, PNG and JSON files.
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
from flexreg.io.files import all_or_nothing
from flexreg.synth.config import RGBDConfig, SynthConfig, TLSConfig
from flexreg.synth.paths import camera_trajectory, lidar_trajectory, smooth_path
from flexreg.synth.placement import place_stations, station_overlap, stream
from flexreg.synth.products import Products, plan_products, write_products
from flexreg.synth.project import (
    ProjectPlacement,
    overlap_matrix,
    place_project,
    project_ground_truth,
)
from flexreg.synth.rig import Rig, place_rig, write_rig
from flexreg.synth.scene import Scene
from flexreg.synth.scenes import (
    OBJECT_SCENE_KINDS,
    PROJECT_SCENE_KINDS,
    SCENE_KINDS,
    make_project_scene,
    make_scene,
    object_from_mesh,
    procedural_object,
    scene_from_mesh,
)
from flexreg.synth.sensors import scan_tls, write_tum_sequence

__all__ = [
    "PairInfo",
    "StationInfo",
    "SynthResult",
    "build_scene",
    "camera_trajectory",
    "lidar_trajectory",
    "make_project",
    "smooth_path",
    "synthesize",
]

Progress = Callable[[str, int, int], None]

# stream ids (see placement.stream; 3, 4, 7, 8 and 9: flexreg.synth.products)
_PLACEMENT, _TRAJECTORY, _RGBD, _STATION = 0, 1, 2, 100
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
    kind: str | None = None
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "target": self.target,
            "source": self.source,
            "T_target_source": self.T_target_source.tolist(),
            "distance_m": self.distance_m,
            "overlap": self.overlap,
        }
        if self.kind is not None:
            d["kind"] = self.kind
        return {**d, **self.details}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PairInfo:
        """A pair of :func:`~flexreg.synth.products.write_products` (a dict with ``kind`` and
        any details)."""
        main = ("target", "source", "T_target_source", "distance_m", "overlap", "kind")
        return cls(
            str(d["target"]),
            str(d["source"]),
            np.asarray(d["T_target_source"], dtype=np.float64),
            float(d["distance_m"]),
            float(d["overlap"]),
            d.get("kind"),
            {k: v for k, v in d.items() if k not in main},
        )


@dataclass(eq=False)
class SynthResult:
    """What :func:`synthesize` wrote (timings are reported here, never written to files);
    ``project`` is the ``"project"`` part of ``gt.json`` for project scenes (else empty),
    ``rig`` the camera of ``--rig`` (else None), ``extras`` the ``"views"``, ``"lidar"`` and
    ``"fragments"`` parts of ``gt.json`` that were made."""

    out_dir: Path
    scene: Scene
    stations: list[StationInfo]
    pairs: list[PairInfo]
    files: list[Path] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    project: dict[str, Any] = field(default_factory=dict)
    rig: Rig | None = None
    extras: dict[str, Any] = field(default_factory=dict)

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
            "extras": dict(self.extras),
        }


def build_scene(config: SynthConfig) -> Scene:
    """The scene of a configuration: procedural (seeded), a project sized for its stations,
    an object for object views (procedural or a mesh file, alone or on a floor), or a mesh
    file."""
    if config.scene in OBJECT_SCENE_KINDS:
        return procedural_object(config.seed, floor=config.floor)
    if config.views:
        return object_from_mesh(
            config.scene, scale=config.mesh_scale, up_axis=config.mesh_up_axis, floor=config.floor
        )
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
    if cfg.stations == 0:
        return [], None
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

    Nothing is written until the scene exists and all stations (the object views, the lidar
    path) are placed, so bad settings (e.g. an impossible distance range) leave no partial
    output; the files are then staged and renamed into place together at the end, so a
    failure on the way (fragments whose overlaps cannot be met) leaves none either.

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
        ``progress(stage, done, total)`` after each station / frame / view / fragment.

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
    products = plan_products(scene, cfg)
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
    rig: Rig | None = None
    if cfg.rig:
        rig = place_rig(scene, placed[0], station_width=cfg.width, rng=stream(cfg.seed, _RIG))

    # nothing is written before this point, and everything or nothing at the end of the block
    with all_or_nothing():
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
        t0 = time.perf_counter()
        made = write_products(out, scene, cfg, products, progress=progress)
        files += made.files
        pairs += [PairInfo.from_dict(p) for p in made.pairs]
        secs["products"] = time.perf_counter() - t0
        doc = _ground_truth(cfg, tls, scene, stations, pairs, rgbd_cfg, made)
        if rig is not None:
            t0 = time.perf_counter()
            _add_rig(out, scene, rig, stations, cfg, files, doc)
            secs["rig"] = time.perf_counter() - t0
        if plan is not None:
            for entry, g, parent in zip(doc["stations"], plan.groups, plan.parents, strict=True):
                entry["T_world_station"] = entry["T_world_scanner"]
                entry["group"] = g
                entry["parent"] = stations[parent].name if parent >= 0 else None
            doc["project"] = project_doc
        _write_json(out / "gt.json", doc)
        files.append(out / "gt.json")
    return SynthResult(
        out, scene, stations, pairs, files, secs, project_doc, rig, dict(made.sections)
    )


def _add_rig(
    out: Path,
    scene: Scene,
    rig: Rig,
    stations: list[StationInfo],
    cfg: SynthConfig,
    files: list[Path],
    doc: dict[str, Any],
) -> None:
    """Write the rig's camera files (appending to ``files``) and add it to ``doc``."""
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


def _ground_truth(
    cfg: SynthConfig,
    tls: TLSConfig,
    scene: Scene,
    stations: list[StationInfo],
    pairs: list[PairInfo],
    rgbd_cfg: RGBDConfig,
    made: Products,
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
    doc.update(made.sections)
    if made.sections:
        doc["convention"] += (
            "; lidar frames and object views hold points in their sensor's frame, fragments "
            "in their first camera's; their pairs carry a kind and their overlap is defined "
            "in their part of this file"
        )
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
