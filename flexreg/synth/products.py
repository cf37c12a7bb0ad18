"""What a synthetic data set holds beside its TLS stations: object views, lidar frames (a
spinning or a rosette lidar) and fused fragments.

:func:`plan_products` sets up whatever can fail cheaply (the views' ring and scanner, the
lidar's path) before anything is written; :func:`write_products` simulates and writes them
and returns each one's part of ``gt.json`` and its neighbouring pairs
(``T_target_source = inv(T_world_target) @ T_world_source``, the overlap, and ``kind``:
``"view"``, ``"lidar"`` or ``"fragment"``). Each draws from its own streams of the seed
(:func:`~flexreg.synth.placement.stream`), so adding one never changes another.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.transforms import invert
from flexreg.io import write_scan
from flexreg.synth.config import RGBDConfig, SynthConfig
from flexreg.synth.fragments import (
    FRAGMENT_MAX_DEPTH_M,
    FRAGMENT_PAN_RAD,
    FRAGMENT_WALK_M,
    OVERLAP_VOXELS,
    write_fragments,
)
from flexreg.synth.objectscan import ViewRing, view_config, view_ring, write_views
from flexreg.synth.paths import lidar_trajectory
from flexreg.synth.placement import station_overlap, stream
from flexreg.synth.rosette import (
    DROPOUT_RATE,
    MAX_INCIDENCE_RAD,
    MIN_RANGE_M,
    PRISM_HZ,
    write_rosette_frames,
)
from flexreg.synth.scene import Scene
from flexreg.synth.sensors import lidar_config, scan_tls

__all__ = [
    "FRAGMENT_STREAM",
    "LIDAR_PATH_STREAM",
    "LIDAR_STREAM",
    "VIEW_NOISE_STREAM",
    "VIEW_RING_STREAM",
    "ProductPlan",
    "Products",
    "plan_products",
    "write_products",
]

#: streams of the seed (:func:`~flexreg.synth.placement.stream`): the lidar's path and noise,
#: the views' ring and noise, the fragments (path, overlap targets, every frame's noise)
LIDAR_PATH_STREAM, LIDAR_STREAM = 3, 4
VIEW_RING_STREAM, VIEW_NOISE_STREAM, FRAGMENT_STREAM = 7, 8, 9

Progress = Callable[[str, int, int], None]


@dataclass(eq=False)
class ProductPlan:
    """What :func:`plan_products` set up: the views' ring, scanner and depth step (metres per
    stored unit), and the lidar's ``T_world_sensor`` along its path."""

    ring: ViewRing | None = None
    view_camera: RGBDConfig | None = None
    view_scale_m: float = 0.0
    lidar_poses: list[NDArray[np.float64]] = field(default_factory=list)


@dataclass(eq=False)
class Products:
    """What :func:`write_products` wrote: the files, each product's part of ``gt.json``
    (``"views"``, ``"lidar"``, ``"fragments"``) and the pairs (dicts with ``target``,
    ``source``, ``T_target_source``, ``distance_m``, ``overlap``, ``kind`` and any details).
    """

    files: list[Path] = field(default_factory=list)
    sections: dict[str, dict[str, Any]] = field(default_factory=dict)
    pairs: list[dict[str, Any]] = field(default_factory=list)


def plan_products(scene: Scene, cfg: SynthConfig) -> ProductPlan:
    """Set up the object views and the lidar path of a configuration (nothing is written).

    Raises
    ------
    InputError
        An object too large for object views, or no clear path for the lidar.
    """
    plan = ProductPlan()
    if cfg.views:
        plan.ring = view_ring(
            scene,
            cfg.views,
            step_range_rad=cfg.view_step_rad,
            floor=cfg.floor,
            rng=stream(cfg.seed, VIEW_RING_STREAM),
        )
        plan.view_camera, plan.view_scale_m = view_config(
            scene, noise_m=cfg.noise_m, floor=cfg.floor
        )
    if cfg.lidar_frames:
        step = 0.5  # the spinning lidar: 10 Hz at 5 m/s
        if cfg.lidar_kind == "rosette":
            step = cfg.rosette.speed_mps / cfg.rosette.rate_hz
        plan.lidar_poses = lidar_trajectory(
            scene, cfg.lidar_frames, step_m=step, rng=stream(cfg.seed, LIDAR_PATH_STREAM)
        )
    return plan


def write_products(
    out: Path,
    scene: Scene,
    cfg: SynthConfig,
    plan: ProductPlan,
    *,
    progress: Progress | None = None,
) -> Products:
    """Simulate and write the object views (``views/``), the lidar frames (``lidar/``) and
    the fragments (``fragments/``) a configuration asks for.

    Parameters
    ----------
    out : Path
        The data set's folder.
    scene : Scene
    cfg : SynthConfig
    plan : ProductPlan
        From :func:`plan_products`.
    progress : callable, optional
        ``progress(stage, done, total)`` with stage ``"views"``, ``"lidar"`` or
        ``"fragments"``.

    Returns
    -------
    Products
    """
    res = Products()

    def tick(stage: str) -> Callable[[int, int], None] | None:
        return None if progress is None else (lambda d, n: progress(stage, d, n))

    if plan.ring is not None and plan.view_camera is not None:
        _views(out, scene, cfg, plan, res, tick("views"))
    if plan.lidar_poses and cfg.lidar_kind == "rosette":
        files, frames, pairs = write_rosette_frames(
            out / "lidar",
            scene,
            plan.lidar_poses,
            config=cfg.rosette,
            embed_poses=cfg.embed_poses,
            rng=stream(cfg.seed, LIDAR_STREAM),
            progress=tick("lidar"),
        )
        sensor = {
            **cfg.rosette.to_dict(),
            "prism_hz": list(PRISM_HZ),
            "min_range_m": MIN_RANGE_M,
            "max_incidence_deg": math.degrees(MAX_INCIDENCE_RAD),
            "dropout_rate": DROPOUT_RATE,
        }
        res.files += files
        res.sections["lidar"] = {
            "kind": "rosette",
            "sensor": sensor,
            "frame": "x forward, y left, z up; unorganised PCD, VIEWPOINT the identity "
            "unless embed_poses",
            "overlap_definition": "min over both directions of the share of a frame's returns "
            "inside the other's field of view, range and line of sight",
            "frames": frames,
        }
        res.pairs += [{**p, "kind": "lidar"} for p in pairs]
    elif plan.lidar_poses:
        _spinning(out, scene, cfg, plan.lidar_poses, res, tick("lidar"))
    if cfg.fragments:
        _fragments(out, scene, cfg, res, tick("fragments"))
    return res


def _views(
    out: Path,
    scene: Scene,
    cfg: SynthConfig,
    plan: ProductPlan,
    res: Products,
    progress: Callable[[int, int], None] | None,
) -> None:
    ring, camera = plan.ring, plan.view_camera
    assert ring is not None and camera is not None
    files, views, pairs = write_views(
        out / "views",
        scene,
        ring,
        config=camera,
        depth_scale=plan.view_scale_m,
        rng=stream(cfg.seed, VIEW_NOISE_STREAM),
        progress=progress,
    )
    res.files += files
    lo, hi = cfg.view_step_rad
    res.sections["views"] = {
        "folder": "views",
        "camera": camera.camera().to_dict(),
        "frame": "x right, y down, z forward (pinhole camera); T_world_scanner is the camera pose",
        "depth_scale_m_per_unit": plan.view_scale_m,
        "depth_kind": "z",
        "depth_range_m": [camera.min_depth_m, camera.max_depth_m],
        "noise_m": camera.depth_noise_m,
        "object": {"center_m": ring.center_m.tolist(), "radius_m": ring.radius_m},
        "distance_m": ring.distance_m,
        "step_range_deg": [round(math.degrees(lo), 9), round(math.degrees(hi), 9)],
        "floor": cfg.floor,
        "overlap_definition": "min over both directions of the share of a view's points "
        "inside the other view's image and depth range, in its line of sight and below its "
        "incidence limit",
        "views": views,
    }
    for p, step in zip(pairs, ring.step_rad, strict=True):
        res.pairs.append({**p, "kind": "view", "step_deg": math.degrees(float(step))})


def _spinning(
    out: Path,
    scene: Scene,
    cfg: SynthConfig,
    poses: list[NDArray[np.float64]],
    res: Products,
    progress: Callable[[int, int], None] | None,
) -> None:
    """The spinning-lidar sweeps (``lidar_NNNNN`` in the stations' format)."""
    lcfg = lidar_config()
    gen = stream(cfg.seed, LIDAR_STREAM)
    frames: list[dict[str, Any]] = []
    for i, T in enumerate(poses):
        name = f"lidar_{i:05d}"
        scan = scan_tls(scene, T, config=lcfg, rng=gen, name=name)
        if not cfg.embed_poses:
            scan = replace(scan, T_world_scanner=np.eye(4))
        res.files.append(write_scan(out / "lidar" / f"{name}.{cfg.format}", scan))
        frames.append(
            {"name": name, "file": f"lidar/{name}.{cfg.format}", "T_world_sensor": T.tolist()}
        )
        if progress is not None:
            progress(i + 1, len(poses))
    res.sections["lidar"] = {"kind": "spinning", "sensor": lcfg.to_dict(), "frames": frames}
    for i in range(len(poses) - 1):
        Ta, Tb = poses[i], poses[i + 1]
        res.pairs.append(
            {
                "target": frames[i]["name"],
                "source": frames[i + 1]["name"],
                "T_target_source": invert(Ta) @ Tb,
                "distance_m": float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])),
                "overlap": station_overlap(scene, Ta, Tb, config=lcfg),
                "kind": "lidar",
            }
        )


def _fragments(
    out: Path,
    scene: Scene,
    cfg: SynthConfig,
    res: Products,
    progress: Callable[[int, int], None] | None,
) -> None:
    camera = RGBDConfig(max_depth_m=FRAGMENT_MAX_DEPTH_M)
    files, fragments, pairs = write_fragments(
        out / "fragments",
        scene,
        cfg.fragments,
        config=cfg.fragment,
        camera=camera,
        rng=stream(cfg.seed, FRAGMENT_STREAM),
        progress=progress,
    )
    res.files += files
    res.sections["fragments"] = {
        "folder": "fragments",
        "camera": camera.camera().to_dict(),
        "depth_range_m": [camera.min_depth_m, camera.max_depth_m],
        "frames_per_fragment": cfg.fragment.frames,
        "voxel_m": cfg.fragment.voxel_m,
        "overlap_range": list(cfg.fragment.overlap),
        "pan_deg_per_fragment": math.degrees(FRAGMENT_PAN_RAD),
        "walk_m_per_fragment": FRAGMENT_WALK_M,
        "frame": "each fragment in its first frame's camera frame (x right, y down, "
        "z forward); T_world_fragment is that camera's pose",
        "overlap_definition": "min over both directions of the share of a fragment's points "
        f"within {OVERLAP_VOXELS:g} voxel sizes of the other's (true relative pose)",
        "fragments": fragments,
    }
    res.pairs += [{**p, "kind": "fragment"} for p in pairs]
