"""Simulated sensors: terrestrial laser scanner, spinning lidar and pinhole RGB-D camera.

All sensors ray-cast a :class:`~flexreg.synth.scene.Scene` (open3d ``RaycastingScene``; the hit
of every ray is deterministic regardless of threading) and then apply a noise model drawn from
the seeded ``rng`` in a fixed order, one full-image array per effect, so a given scene, pose,
configuration and seed always give the same measurement, bit for bit.

TLS measurement model (per pixel of the equirectangular grid, paper eq. 3-8):

* ray-cast range ``r`` to the first surface; no return if nothing is hit, ``r`` is outside
  ``[min_range_m, max_range_m]``, the incidence angle exceeds ``max_incidence_rad`` (grazing),
  or the ray falls in the tripod's blind cone below the scanner;
* mixed pixels: at a depth edge (a neighbour more than ``mixed_pixel_jump_m`` or 2 % away) the
  beam footprint straddles both surfaces; with probability ``mixed_pixel_prob`` the return lies
  at a uniform fraction of the way to the neighbour's range;
* Gaussian range noise with ``sigma = range_noise_m + range_noise_per_m * r``;
* intensity ``rho * cos(incidence) * exp(-r / intensity_range_scale_m)`` with multiplicative
  speckle, clipped to 0..1; returns weaker than ``min_intensity`` are lost;
* random dropouts with probability ``dropout_rate``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.scan import Scan
from flexreg.core.transforms import as_transform
from flexreg.errors import ConfigError
from flexreg.io import atomic_write
from flexreg.io.depth import TUM_DEPTH_SCALE
from flexreg.synth.config import RGBDConfig, TLSConfig
from flexreg.synth.scene import RayHits, Scene
from flexreg.synth.seeding import as_rng

# ====================================================================================== TLS


def lidar_config(
    rings: int = 64,
    columns: int = 1024,
    *,
    fov_up_rad: float = math.radians(15.0),
    fov_down_rad: float = math.radians(-25.0),
    range_noise_m: float = 0.015,
    max_range_m: float = 100.0,
) -> TLSConfig:
    """Model of a spinning multi-beam lidar (``rings`` x ``columns`` grid, uniform ring spacing).

    Returns a :class:`TLSConfig` without tripod cone, with the elevation field of view
    ``[fov_down_rad, fov_up_rad]`` above the horizon and lidar-like noise.
    """
    if not fov_up_rad > fov_down_rad:
        raise ConfigError(f"fov_up_rad ({fov_up_rad}) must exceed fov_down_rad ({fov_down_rad})")
    return TLSConfig(
        width=columns,
        height=rings,
        theta_min=math.pi / 2 - fov_up_rad,
        theta_max=math.pi / 2 - fov_down_rad,
        range_noise_m=range_noise_m,
        range_noise_per_m=0.0,
        min_range_m=1.0,
        max_range_m=max_range_m,
        tripod_cone_rad=0.0,
        mixed_pixel_prob=0.3,
        intensity_range_scale_m=60.0,
    )


@lru_cache(maxsize=4)
def _spherical_rays(camera: SphericalCamera) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Unit rays (H*W, 3) float32 of a spherical camera, and the polar angle (H,) of each row."""
    rays = camera.rays().reshape(-1, 3).astype(np.float32)
    rays.setflags(write=False)
    _, theta = camera.angles(np.zeros(camera.height), np.arange(camera.height, dtype=np.float64))
    return rays, theta


def _neighbour_jump(r: NDArray[np.float64], wraps: bool) -> NDArray[np.float64]:
    """Signed range difference to the 4-neighbour with the largest jump (0 where none valid).

    Parameters
    ----------
    r : (H, W) float, metres, NaN where invalid
    wraps : bool
        Columns wrap around (full-turn panorama).
    """
    r32 = r.astype(np.float32)
    best = np.zeros_like(r32)
    best_abs = np.zeros_like(r32)

    def consider(dst: Any, d: NDArray[np.float32]) -> None:
        a = np.abs(d)
        take = a > best_abs[dst]  # False where NaN
        np.copyto(best[dst], d, where=take)
        np.copyto(best_abs[dst], a, where=take)

    with np.errstate(invalid="ignore"):
        dv = r32[1:] - r32[:-1]
        consider(np.s_[:-1], dv)
        consider(np.s_[1:], -dv)
        dh = r32[:, 1:] - r32[:, :-1]
        consider(np.s_[:, :-1], dh)
        consider(np.s_[:, 1:], -dh)
        if wraps:
            dw = r32[:, :1] - r32[:, -1:]
            consider(np.s_[:, -1:], dw)
            consider(np.s_[:, :1], -dw)
    return best.astype(np.float64)


def _hash_texture(points: NDArray[np.float64], cell_m: float = 0.04) -> NDArray[np.float32]:
    """Blocky value-noise texture in 0..1 from world coordinates (a deterministic hash)."""
    q = np.floor(points / cell_m).astype(np.int64)
    h = (q[:, 0] * 73856093) ^ (q[:, 1] * 19349663) ^ (q[:, 2] * 83492791)
    h = (h * 2654435761) >> 7
    return ((h & 0xFFFF).astype(np.float32)) / np.float32(65535.0)


def _shade(
    scene: Scene,
    hits: RayHits,
    dirs_world: NDArray[np.float32],
    points_world: NDArray[np.float64],
    cos_inc: NDArray[np.float32],
) -> NDArray[np.float32]:
    """Colour of the hit points (N, 3) float32 0..255: albedo x texture x (sun + headlight)."""
    prim = np.maximum(hits.primitive, 0)
    albedo = scene.colors[prim].astype(np.float32)
    n = hits.normal
    facing = np.where((np.einsum("ij,ij->i", n, dirs_world) > 0)[:, None], -n, n)
    sun = np.array([0.35, 0.25, 0.9], dtype=np.float32)
    sun /= np.linalg.norm(sun)
    lambert = np.clip(facing @ sun, 0.0, 1.0)
    tex = 0.82 + 0.18 * _hash_texture(points_world)
    light = 0.3 + 0.45 * lambert + 0.25 * cos_inc
    return albedo * (tex * light)[:, None]


def scan_tls(
    scene: Scene,
    T_world_scanner: ArrayLike,
    *,
    config: TLSConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    name: str = "",
) -> Scan:
    """Simulate one TLS station (or lidar sweep) of a scene.

    Parameters
    ----------
    scene : Scene
    T_world_scanner : (4, 4) float64
        Scanner pose; the scanner's Z axis is its rotation axis (tilted by the pose).
    config : TLSConfig, optional
        Grid and noise model (default: 2048 x 1024 full sphere, 3 mm noise).
    rng : numpy Generator, int or None
        Source of all noise; draws happen in a fixed order, one full-grid array per effect.
    name : str
        Scan name.

    Returns
    -------
    Scan
        Valid returns in the scanner frame with intensity (and colours if
        ``config.colors``), the native ``(height, width)`` grid and ``grid_index``, the pose
        ``T_world_scanner`` and the :class:`~flexreg.core.camera.SphericalCamera` of the grid.
    """
    cfg = config or TLSConfig()
    gen, _ = as_rng(rng)
    T = as_transform(T_world_scanner, name="T_world_scanner")
    cam = cfg.camera()
    H, W = cam.shape
    N = H * W
    rays, theta = _spherical_rays(cam)
    R = T[:3, :3].astype(np.float32)
    dirs = rays @ R.T
    hits = scene.cast(T[:3, 3], dirs)

    valid = hits.primitive >= 0
    valid &= (hits.t >= cfg.min_range_m) & (hits.t <= cfg.max_range_m)
    cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal, dirs))
    valid &= cos_inc >= np.float32(math.cos(cfg.max_incidence_rad))
    if cfg.tripod_cone_rad > 0:
        row_ok = theta <= math.pi - cfg.tripod_cone_rad
        valid &= np.repeat(row_ok, W)
    r = np.where(valid, hits.t, np.nan)

    # all random draws, in a fixed order, for every pixel
    u_mix = gen.random(N, dtype=np.float32)
    f_mix = gen.random(N, dtype=np.float32)
    z_range = gen.standard_normal(N, dtype=np.float32)
    z_int = gen.standard_normal(N, dtype=np.float32)
    u_drop = gen.random(N, dtype=np.float32)

    if cfg.mixed_pixel_prob > 0:
        jump = _neighbour_jump(r.reshape(H, W), cam.wraps).reshape(-1)
        with np.errstate(invalid="ignore"):
            edge = np.abs(jump) > np.maximum(cfg.mixed_pixel_jump_m, 0.02 * r)
        mix = edge & (u_mix < cfg.mixed_pixel_prob)
        r = np.where(mix, r + f_mix * jump, r)
    r_clean = r
    sigma = cfg.range_noise_m + cfg.range_noise_per_m * r_clean
    r = r_clean + sigma * z_range

    prim = np.maximum(hits.primitive, 0)
    with np.errstate(invalid="ignore", over="ignore"):
        inten = (
            scene.reflectance[prim]
            * cos_inc
            * np.exp(-r_clean / cfg.intensity_range_scale_m)
            * (1.0 + cfg.intensity_speckle * z_int)
        )
    inten = np.clip(np.nan_to_num(inten, nan=0.0), 0.0, 1.0).astype(np.float32)
    with np.errstate(invalid="ignore"):
        valid &= (
            (u_drop >= cfg.dropout_rate)
            & (inten >= cfg.min_intensity)
            & (r > cfg.min_range_m * 0.5)
        )

    idx = np.flatnonzero(valid)
    points = r[idx, None] * rays[idx].astype(np.float64)
    colors = None
    if cfg.colors:
        pw = points @ T[:3, :3].T + T[:3, 3]
        sub = RayHits(hits.t[idx], hits.primitive[idx], hits.normal[idx])
        colors = np.clip(_shade(scene, sub, dirs[idx], pw, cos_inc[idx]) + 0.5, 0, 255).astype(
            np.uint8
        )
    grid_index = np.stack([idx // W, idx % W], axis=1).astype(np.int32)
    return Scan(
        points=points,
        intensity=inten[idx],
        colors=colors,
        grid_shape=(H, W),
        grid_index=grid_index,
        T_world_scanner=T,
        camera=cam,
        name=name,
    )


def scan_lidar(
    scene: Scene,
    T_world_sensor: ArrayLike,
    *,
    config: TLSConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    name: str = "",
) -> Scan:
    """One sweep of a spinning lidar (default :func:`lidar_config`: 64 rings x 1024 columns).

    Motion during the sweep is not simulated (the sweep is instantaneous).
    """
    return scan_tls(scene, T_world_sensor, config=config or lidar_config(), rng=rng, name=name)


# ====================================================================================== RGB-D


@dataclass(eq=False)
class RGBDFrame:
    """One simulated RGB-D frame.

    Attributes
    ----------
    depth : (H, W) float32, metres
        Orthographic depth ``Z`` (paper eq. 2), NaN where there is no reading, quantised to the
        TUM step of 0.2 mm (or the ``depth_step_m`` of :func:`render_rgbd`).
    image : (H, W, 3) uint8 (RGB) or (H, W) uint8 (grey)
    T_world_camera : (4, 4) float64
        Camera pose (x right, y down, z forward).
    camera : PinholeCamera
    """

    depth: NDArray[np.float32]
    image: NDArray[np.uint8]
    T_world_camera: NDArray[np.float64]
    camera: PinholeCamera

    def depth_png(self) -> NDArray[np.uint16]:
        """Depth as TUM 16-bit units (5000 per metre), 0 = no reading."""
        d = np.nan_to_num(self.depth, nan=0.0)
        return np.clip(np.rint(d / TUM_DEPTH_SCALE), 0, 65535).astype(np.uint16)


@lru_cache(maxsize=2)
def _pinhole_rays(camera: PinholeCamera) -> NDArray[np.float32]:
    rays = camera.rays().reshape(-1, 3)
    rays = (rays / np.linalg.norm(rays, axis=1, keepdims=True)).astype(np.float32)
    rays.setflags(write=False)
    return rays


def render_rgbd(
    scene: Scene,
    T_world_camera: ArrayLike,
    *,
    config: RGBDConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    depth_step_m: float = TUM_DEPTH_SCALE,
    image: bool = True,
) -> RGBDFrame:
    """Render one depth + shaded image pair (or the depth alone).

    Depth noise ``sigma = depth_noise_m + depth_noise_quadratic * z^2``; no reading beyond the
    depth range, at grazing incidence, at random dropouts and (with ``edge_dropout_prob``) at
    depth edges. The image is the scene colour under a sun and a headlight, with a small
    world-fixed texture and Gaussian image noise; rays that hit nothing see a pale sky.
    Depths are quantised to ``depth_step_m`` metres (the TUM step of 0.2 mm by default; a
    finer one for close-range scanners whose files store finer units). With ``image=False``
    only the depth is made (a third faster): the image is left black and its noise is not
    drawn, which changes nothing of the depth.
    """
    if not (math.isfinite(depth_step_m) and depth_step_m > 0):
        raise ConfigError(f"depth_step_m must be a positive number of metres, got {depth_step_m}")
    cfg = config or RGBDConfig()
    gen, _ = as_rng(rng)
    T = as_transform(T_world_camera, name="T_world_camera")
    cam = cfg.camera()
    H, W = cam.shape
    N = H * W
    rays = _pinhole_rays(cam)
    dirs = rays @ T[:3, :3].astype(np.float32).T
    hits = scene.cast(T[:3, 3], dirs)
    z = hits.t * rays[:, 2].astype(np.float64)
    cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal, dirs))
    valid = hits.hit & (z >= cfg.min_depth_m) & (z <= cfg.max_depth_m)
    valid &= cos_inc >= np.float32(math.cos(cfg.max_incidence_rad))
    zr = np.where(valid, z, np.nan)

    z_noise = gen.standard_normal(N, dtype=np.float32)
    u_drop = gen.random(N, dtype=np.float32)
    u_edge = gen.random(N, dtype=np.float32)
    if image:
        img_noise = gen.standard_normal(N * 3 if cfg.colour else N, dtype=np.float32)

    jump = _neighbour_jump(zr.reshape(H, W), False).reshape(-1)
    with np.errstate(invalid="ignore"):
        edge = np.abs(jump) > np.maximum(0.05, 0.03 * zr)
    sigma = cfg.depth_noise_m + cfg.depth_noise_quadratic * zr * zr
    zn = zr + sigma * z_noise
    valid &= (u_drop >= cfg.dropout_rate) & ~(edge & (u_edge < cfg.edge_dropout_prob))
    with np.errstate(invalid="ignore"):
        valid &= zn > 0
    depth = np.where(valid, zn, np.nan)
    step = depth_step_m
    depth = (np.rint(depth / step) * step).astype(np.float32).reshape(H, W)
    if not image:
        blank = np.zeros((H, W, 3) if cfg.colour else (H, W), dtype=np.uint8)
        return RGBDFrame(depth=depth, image=blank, T_world_camera=T, camera=cam)

    hit = hits.hit
    pw = T[:3, 3] + np.where(hit, hits.t, 0.0)[:, None] * dirs.astype(np.float64)
    col = _shade(scene, hits, dirs, pw, cos_inc)
    sky = np.array([205.0, 218.0, 235.0], dtype=np.float32)
    col = np.where(hit[:, None], col, sky)
    picture: NDArray[np.uint8]
    if cfg.colour:
        img = col + cfg.image_noise * img_noise.reshape(N, 3)
        picture = np.clip(img + 0.5, 0, 255).astype(np.uint8).reshape(H, W, 3)
    else:
        grey = col @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
        picture = (
            np.clip(grey + cfg.image_noise * img_noise + 0.5, 0, 255).astype(np.uint8).reshape(H, W)
        )
    return RGBDFrame(depth=depth, image=picture, T_world_camera=T, camera=cam)


def look_at(eye: ArrayLike, target: ArrayLike) -> NDArray[np.float64]:
    """Camera pose (x right, y down, z forward) at ``eye`` looking at ``target``, world Z up.

    >>> T = look_at([0, 0, 1], [1, 0, 1])
    >>> T[:3, 2].round(6).tolist()   # forward = +X
    [1.0, 0.0, 0.0]
    """
    e = np.asarray(eye, dtype=np.float64)
    f = np.asarray(target, dtype=np.float64) - e
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        raise ConfigError("look_at: viewing direction is vertical")
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    T = np.eye(4)
    T[:3, :3] = np.stack([right, down, f], axis=1)
    T[:3, 3] = e
    return T


def write_tum_sequence(
    out_dir: str | PathLike[str],
    scene: Scene,
    poses: list[NDArray[np.float64]],
    *,
    config: RGBDConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Render frames along ``poses`` and write a TUM RGB-D style sequence.

    Layout: ``rgb/<t>.png`` (8-bit colour or grey), ``depth/<t>.png`` (16-bit, 5000 per
    metre, 0 = no reading), ``rgb.txt``, ``depth.txt`` (``timestamp filename``),
    ``groundtruth.txt`` (``timestamp tx ty tz qx qy qz qw``, camera pose in the world) and
    ``camera.json`` (intrinsics, depth scale). Timestamps start at 0 and step by
    ``1 / rate_hz``.

    Returns
    -------
    list of Path
        Every file written.
    """
    import cv2  # heavy: only for writing PNG files

    cfg = config or RGBDConfig()
    gen, _ = as_rng(rng)
    out = Path(out_dir)
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    rgb_lines = ["# color images", "# timestamp filename"]
    depth_lines = ["# depth maps", "# timestamp filename"]
    gt_lines = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]

    def _png(path: Path, arr: NDArray[Any]) -> None:
        ok, buf = cv2.imencode(".png", arr, [cv2.IMWRITE_PNG_COMPRESSION, 3])
        if not ok:  # pragma: no cover - cv2 failure
            raise ConfigError(f"could not encode {path.name}")
        atomic_write(path, lambda tmp: tmp.write_bytes(buf.tobytes()))
        written.append(path)

    for i, T in enumerate(poses):
        frame = render_rgbd(scene, T, config=cfg, rng=gen)
        ts = f"{i / cfg.rate_hz:.6f}"
        img = frame.image[..., ::-1] if frame.image.ndim == 3 else frame.image
        _png(out / "rgb" / f"{ts}.png", np.ascontiguousarray(img))
        _png(out / "depth" / f"{ts}.png", frame.depth_png())
        rgb_lines.append(f"{ts} rgb/{ts}.png")
        depth_lines.append(f"{ts} depth/{ts}.png")
        q = Rotation.from_matrix(frame.T_world_camera[:3, :3]).as_quat()  # x y z w
        t = frame.T_world_camera[:3, 3]
        gt_lines.append(f"{ts} " + " ".join(f"{v:.9f}" for v in (*t, *q)))
        if progress is not None:
            progress(i + 1, len(poses))

    def _write_text(path: Path, text: str) -> None:
        atomic_write(path, lambda tmp: tmp.write_text(text))

    for name, lines in (
        ("rgb.txt", rgb_lines),
        ("depth.txt", depth_lines),
        ("groundtruth.txt", gt_lines),
    ):
        p = out / name
        _write_text(p, "\n".join(lines) + "\n")
        written.append(p)
    cam_doc = {
        "camera": cfg.camera().to_dict(),
        "depth_scale_m_per_unit": 1.0 / 5000.0,
        "depth_kind": "z",
        "config": cfg.to_dict(),
    }
    p = out / "camera.json"
    atomic_write(p, lambda tmp: tmp.write_text(json.dumps(cam_doc, indent=2) + "\n"))
    written.append(p)
    return written
