"""Narrow-field lidar frames with a non-repetitive rosette scan (Livox Avia / Mid-70 style).

Two prisms turning at nearly equal, incommensurate rates (:data:`PRISM_HZ`) steer one beam
along a rose curve: with the phases ``a = 2 pi f1 t`` and ``b = 2 pi f2 t``,

    u = (cos a + cos b) / 2,   v = (sin a - sin b) / 2,   u^2 + v^2 = (1 + cos(a + b)) / 2 <= 1,

so the beam passes through the centre ``f1 + f2`` times a second, and between two passes it
runs out to the edge of the field of view and back on a petal while the petals turn round the
centre by ``pi (f1 - f2) / (f1 + f2)`` (25 degrees): a frame of 0.1 s lays 150 petals over the
whole field, densest in its middle and at its rim, and the next frame other ones (the pattern
does not repeat for 10^4 s). The
angles ``azimuth = u * fov_x / 2`` and ``elevation = v * fov_y / 2`` fill the ellipse of the
field of view; the sensor frame is x forward, y left, z up, the direction of a shot
``(cos el cos az, cos el sin az, sin el)``. Shot ``k`` of frame ``i`` fires at
``t = (i * points + k) / (points * rate_hz)``; the motion during a frame is not simulated.

Returns: the first surface along the shot within 1 m (:data:`MIN_RANGE_M`, the blind zone)
to ``max_range_m`` and below :data:`MAX_INCIDENCE_RAD`, with Gaussian range noise, random
dropouts (:data:`DROPOUT_RATE`) and an intensity ``rho * cos(incidence) * exp(-r / 60 m)``.
:func:`write_rosette_frames` writes them as unorganised PCD files in the sensor frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.scan import Scan
from flexreg.core.transforms import as_transform
from flexreg.io import write_scan
from flexreg.synth.config import RosetteConfig
from flexreg.synth.placement import in_line_of_sight, neighbour_pairs
from flexreg.synth.scene import Scene
from flexreg.synth.seeding import as_rng

__all__ = [
    "DROPOUT_RATE",
    "MAX_INCIDENCE_RAD",
    "MIN_RANGE_M",
    "PRISM_HZ",
    "fov_ellipse",
    "rosette_angles",
    "rosette_overlap",
    "scan_rosette",
    "write_rosette_frames",
]

#: rates of the two prisms that steer the beam, hertz (their ratio keeps the pattern from
#: repeating for 10^4 s)
PRISM_HZ = (852.9137, 647.0863)
#: returns nearer than this are lost (the blind zone), metres
MIN_RANGE_M = 1.0
#: returns at a larger incidence angle are lost, radians
MAX_INCIDENCE_RAD = math.radians(86.0)
#: probability that a return is lost at random
DROPOUT_RATE = 0.002
#: range at which the intensity has fallen to 1/e, metres
INTENSITY_RANGE_M = 60.0

Progress = Callable[[int, int], None]


def rosette_angles(
    config: RosetteConfig, frame: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Azimuth and elevation of every shot of a frame.

    Parameters
    ----------
    config : RosetteConfig
    frame : int
        Frame index: frame ``i`` takes the pattern from ``t = i / rate_hz`` on.

    Returns
    -------
    azimuth, elevation : (points,) float64, radians
        Within the ellipse of the field of view (:func:`fov_ellipse` <= 1).

    Examples
    --------
    >>> az, el = rosette_angles(RosetteConfig(points=1000))
    >>> round(math.degrees(az[0]), 6), float(el[0])  # t = 0: the rim, straight across
    (35.2, 0.0)
    """
    n = int(config.points)
    t = (int(frame) * n + np.arange(n, dtype=np.float64)) / (n * float(config.rate_hz))
    a, b = 2 * math.pi * PRISM_HZ[0] * t, 2 * math.pi * PRISM_HZ[1] * t
    u = 0.5 * (np.cos(a) + np.cos(b))
    v = 0.5 * (np.sin(a) - np.sin(b))
    hx, hy = (math.radians(f) / 2 for f in config.fov_deg)
    return u * hx, v * hy


def fov_ellipse(config: RosetteConfig, points: ArrayLike) -> NDArray[np.float64]:
    """Where sensor-frame points lie in the field of view: ``(az / hx)^2 + (el / hy)^2``
    (``hx``, ``hy``: the half angles), <= 1 inside; ``inf`` behind the sensor (x <= 0).

    Parameters
    ----------
    config : RosetteConfig
    points : (N, 3) float, metres
        Sensor frame (x forward, y left, z up).

    Returns
    -------
    (N,) float64
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    az = np.arctan2(P[:, 1], P[:, 0])
    el = np.arctan2(P[:, 2], np.hypot(P[:, 0], P[:, 1]))
    hx, hy = (math.radians(f) / 2 for f in config.fov_deg)
    e = (az / hx) ** 2 + (el / hy) ** 2
    return np.where(P[:, 0] > 0, e, np.inf)


def scan_rosette(
    scene: Scene,
    T_world_sensor: ArrayLike,
    *,
    config: RosetteConfig | None = None,
    frame: int = 0,
    rng: np.random.Generator | int | None = 0,
    name: str = "",
) -> Scan:
    """One frame of a rosette lidar.

    Parameters
    ----------
    scene : Scene
    T_world_sensor : (4, 4) float64
        Sensor pose (x forward, y left, z up), metres.
    config : RosetteConfig, optional
    frame : int
        Which part of the pattern (:func:`rosette_angles`).
    rng : numpy Generator, int or None
        Range noise, intensity speckle and dropouts: three draws of ``points`` values each,
        in that order.
    name : str

    Returns
    -------
    Scan
        The returns in the sensor frame (N, 3) float64 with intensity (N,) float32, in
        shot order, no grid; ``T_world_scanner`` is the pose.
    """
    cfg = config or RosetteConfig()
    gen, _ = as_rng(rng)
    T = as_transform(T_world_sensor, name="T_world_sensor")
    az, el = rosette_angles(cfg, frame)
    rays = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    dirs = rays @ T[:3, :3].T
    hits = scene.cast(T[:3, 3], dirs)
    n = len(rays)
    z_range = gen.standard_normal(n)
    z_int = gen.standard_normal(n)
    u_drop = gen.random(n)
    cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal.astype(np.float64), dirs))
    valid = hits.hit & (hits.t >= MIN_RANGE_M) & (hits.t <= cfg.max_range_m)
    valid &= (cos_inc >= math.cos(MAX_INCIDENCE_RAD)) & (u_drop >= DROPOUT_RATE)
    idx = np.flatnonzero(valid)
    r = hits.t[idx] + cfg.range_noise_m * z_range[idx]
    prim = hits.primitive[idx]
    inten = scene.reflectance[prim] * cos_inc[idx] * np.exp(-hits.t[idx] / INTENSITY_RANGE_M)
    inten = np.clip(inten * (1.0 + 0.04 * z_int[idx]), 0.0, 1.0).astype(np.float32)
    return Scan(points=r[:, None] * rays[idx], intensity=inten, T_world_scanner=T, name=name)


def rosette_overlap(
    scene: Scene,
    points_world: NDArray[np.float64],
    T_world_sensor: NDArray[np.float64],
    config: RosetteConfig,
    *,
    tol_m: float,
) -> float:
    """Share of a frame's points (world frame) that another frame's sensor also covers:
    inside its field of view and range, in its line of sight (the first hit towards the
    point no nearer than its distance less ``tol_m``) and below the incidence limit.
    Denominator: the points given. The rosette of one frame samples only part of that field,
    so this is the overlap of the fields of view, not of the shots.

    Returns
    -------
    float
        0..1 (0 for no points).
    """
    if len(points_world) == 0:
        return 0.0
    T = np.asarray(T_world_sensor, dtype=np.float64)
    local = (points_world - T[:3, 3]) @ T[:3, :3]
    dist = np.linalg.norm(local, axis=1)
    inside = (fov_ellipse(config, local) <= 1.0) & (dist >= MIN_RANGE_M)
    inside &= dist <= config.max_range_m
    seen = np.zeros(len(local), dtype=bool)
    idx = np.flatnonzero(inside)
    if len(idx):
        seen[idx] = in_line_of_sight(
            scene, T[:3, 3], points_world[idx], dist[idx],
            tol_m=tol_m, max_incidence_rad=MAX_INCIDENCE_RAD,
        )  # fmt: skip
    return float(seen.mean())


def write_rosette_frames(
    out_dir: str | PathLike[str],
    scene: Scene,
    poses: list[NDArray[np.float64]],
    *,
    config: RosetteConfig,
    embed_poses: bool = False,
    rng: np.random.Generator | int | None = 0,
    progress: Progress | None = None,
) -> tuple[list[Path], list[dict[str, Any]], list[dict[str, Any]]]:
    """Simulate a rosette frame at each pose and write ``lidar_NNNNN.pcd``.

    Parameters
    ----------
    out_dir : path-like
        Folder of the frames (created).
    scene : Scene
    poses : list of (4, 4) float64
        ``T_world_sensor`` of each frame (x forward, y left, z up), metres.
    config : RosetteConfig
    embed_poses : bool
        PCD ``VIEWPOINT`` = the true pose; by default the identity (the points are in the
        sensor frame either way).
    rng : numpy Generator, int or None
        Noise of every frame, drawn frame after frame.
    progress : callable, optional
        ``progress(done, total)`` after each frame.

    Returns
    -------
    files : list of Path
    frames : list of dict
        Per frame: ``name``, ``file`` (relative to ``out_dir``'s parent), ``T_world_sensor``,
        ``t0_s`` (start of its part of the pattern), ``points``.
    pairs : list of dict
        Each frame and the next: ``target``, ``source``, ``T_target_source``,
        ``distance_m``, ``overlap`` (the smaller of the two shares of
        :func:`rosette_overlap`).
    """
    gen, _ = as_rng(rng)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    frames: list[dict[str, Any]] = []
    world: list[NDArray[np.float64]] = []
    for i, T in enumerate(poses):
        name = f"lidar_{i:05d}"
        scan = scan_rosette(scene, T, config=config, frame=i, rng=gen, name=name)
        world.append(scan.points_world())
        if not embed_poses:
            scan = replace(scan, T_world_scanner=np.eye(4))
        files.append(write_scan(out / f"{name}.pcd", scan))
        frames.append(
            {
                "name": name,
                "file": f"{out.name}/{name}.pcd",
                "T_world_sensor": np.asarray(T).tolist(),
                "t0_s": i / float(config.rate_hz),
                "points": len(scan),
            }
        )
        if progress is not None:
            progress(i + 1, len(poses))
    tol = 3.0 * config.range_noise_m + 0.01

    def overlap(i: int, j: int) -> float:
        share_j = rosette_overlap(scene, world[j], poses[i], config, tol_m=tol)
        return min(share_j, rosette_overlap(scene, world[i], poses[j], config, tol_m=tol))

    pairs = neighbour_pairs([f["name"] for f in frames], list(poses), overlap)
    return files, frames, pairs
