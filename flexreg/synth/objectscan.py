"""Object scans: pinhole depth views on a ring around an object, each looking at its centre.

This is how a structured-light or triangulation scanner (or a depth camera) scans an object
that is walked round or turned on a turntable: :func:`view_ring` sets up ``n`` views at one
distance from the object's centre, consecutive views a random azimuth step apart (within a
given range, so the ring may wrap round more than once) and each at a random elevation
(:data:`ELEVATION_RAD`, :data:`FLOOR_ELEVATION_RAD` over a floor), without roll.
:func:`view_config` is the scanner: a 640 x 480 pinhole camera (:data:`VIEW_F_PX`) at the
distance where the object's bounding sphere fills :data:`FILL` of the vertical half field of
view, measuring depth ``z`` with a constant noise sigma. :func:`write_views` renders every view
(:func:`~flexreg.synth.sensors.render_rgbd`) and writes it as a 16-bit depth PNG whose
``<stem>.camera.json`` sidecar gives the intrinsics and a depth step fine enough for the
object (a micrometre multiple; 7 µm for the 0.15 m Stanford bunny), so ``read_scan`` and
``flexreg register`` read each view as a gridded pinhole scan in its camera frame
(x right, y down, z forward).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import InputError
from flexreg.io.depth import TUM_DEPTH_SCALE, write_depth_png
from flexreg.synth.config import RGBDConfig
from flexreg.synth.placement import in_line_of_sight, neighbour_pairs
from flexreg.synth.scene import Scene
from flexreg.synth.scenes import object_extent
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import look_at, render_rgbd

__all__ = [
    "ELEVATION_RAD",
    "FILL",
    "FLOOR_ELEVATION_RAD",
    "VIEW_F_PX",
    "ViewRing",
    "view_config",
    "view_overlap",
    "view_points",
    "view_ring",
    "write_views",
]

#: the object scanner's image: columns x rows, pixels
VIEW_SIZE_PX = (640, 480)
#: its focal length, pixels (60 degrees across, 46 degrees up-down)
VIEW_F_PX = 560.0
#: share of the vertical half field of view (an angle) the object's bounding sphere takes
FILL = 0.85
#: elevation of the views above the object's centre, radians, for an object in the air
ELEVATION_RAD = (math.radians(-15.0), math.radians(35.0))
#: the same over a floor (never from below it)
FLOOR_ELEVATION_RAD = (math.radians(10.0), math.radians(35.0))
#: farthest depth a 16-bit view can store at the TUM step, metres (RGBDConfig's limit)
MAX_VIEW_DEPTH_M = 65535 * TUM_DEPTH_SCALE

Progress = Callable[[int, int], None]


@dataclass(eq=False)
class ViewRing:
    """Views set up round an object.

    Attributes
    ----------
    poses : list of (4, 4) float64
        ``T_world_camera`` of each view (x right, y down, z forward), metres.
    azimuth_rad, elevation_rad : (N,) float64, radians
        Direction from the object's centre to each camera (azimuth from +X, unwrapped: it
        grows by the steps; elevation above the horizontal).
    distance_m : float, metres
        Distance of every camera from the object's centre.
    center_m : (3,) float64, metres
        The object's centre, which every view looks at.
    radius_m : float, metres
        Radius of the object's bounding sphere about ``center_m``.
    """

    poses: list[NDArray[np.float64]]
    azimuth_rad: NDArray[np.float64]
    elevation_rad: NDArray[np.float64]
    distance_m: float
    center_m: NDArray[np.float64]
    radius_m: float

    @property
    def step_rad(self) -> NDArray[np.float64]:
        """(N - 1,) float64, radians: azimuth from each view to the next."""
        return np.diff(self.azimuth_rad)


def view_distance(radius_m: float) -> float:
    """Distance (metres) from the object's centre at which its bounding sphere of
    ``radius_m`` fills :data:`FILL` of the views' vertical half field of view.

    >>> round(view_distance(0.1), 4)
    0.2964
    """
    half_fov = math.atan2(VIEW_SIZE_PX[1] / 2, VIEW_F_PX)
    return float(radius_m / math.sin(FILL * half_fov))


def view_config(scene: Scene, *, noise_m: float, floor: bool = False) -> tuple[RGBDConfig, float]:
    """The object scanner of a scene's object, and the depth step its files store.

    Parameters
    ----------
    scene : Scene
        An object scene (:func:`~flexreg.synth.scenes.object_extent`).
    noise_m : float, metres
        Depth noise sigma (constant: a triangulation scanner at a fixed stand-off).
    floor : bool
        The object stands on a floor (seen farther away than the object itself).

    Returns
    -------
    config : RGBDConfig
        640 x 480, :data:`VIEW_F_PX`; depths from half the distance to the object's near side
        up to its far side (over a floor: 3 radii beyond the centre); 80 degree incidence
        limit, 0.2 % dropouts, shadows at half of the depth edges, grey images.
    depth_scale : float, metres per unit
        The farthest depth over 65535, rounded up to a whole micrometre.

    Raises
    ------
    InputError
        An object too large for 16-bit views (farther than 13.1 m).
    """
    _, r = object_extent(scene)
    d = view_distance(r)
    far = d + (3.0 if floor else 1.05) * r
    if far > MAX_VIEW_DEPTH_M:
        raise InputError(
            scene.name or "object",
            f"an object of {2 * r:.2f} m is seen up to {far:.1f} m away, beyond the "
            f"{MAX_VIEW_DEPTH_M:.1f} m of object views (scale it down with mesh_scale)",
        )
    scale = math.ceil(far / 65535 * 1e6) / 1e6
    w, h = VIEW_SIZE_PX
    config = RGBDConfig(
        width=w,
        height=h,
        fx=VIEW_F_PX,
        fy=VIEW_F_PX,
        cx=(w - 1) / 2,
        cy=(h - 1) / 2,
        depth_noise_m=float(noise_m),
        depth_noise_quadratic=0.0,
        min_depth_m=0.5 * (d - r),
        max_depth_m=far,
        max_incidence_rad=math.radians(80.0),
        dropout_rate=0.002,
        edge_dropout_prob=0.5,
        colour=False,
        image_noise=0.0,
    )
    return config, scale


def view_ring(
    scene: Scene,
    n: int,
    *,
    step_range_rad: tuple[float, float],
    floor: bool = False,
    rng: np.random.Generator | int | None = 0,
) -> ViewRing:
    """Set up ``n`` views round the object of a scene.

    The first view's azimuth is uniform; each next one is a step uniform in
    ``step_range_rad`` further on (drawn in view order after it), and then each view's
    elevation is uniform in :data:`ELEVATION_RAD` (:data:`FLOOR_ELEVATION_RAD` with a floor).

    Parameters
    ----------
    scene : Scene
        An object scene.
    n : int
        Number of views, >= 1.
    step_range_rad : (float, float), radians
        ``0 < min <= max <= pi``.
    floor : bool
    rng : numpy Generator, int or None

    Returns
    -------
    ViewRing
    """
    gen, _ = as_rng(rng)
    lo, hi = step_range_rad
    if not (n >= 1 and 0 < lo <= hi <= math.pi):
        raise InputError("views", f"need n >= 1 and 0 < min <= max <= pi, got {n}, {lo}..{hi}")
    c, r = object_extent(scene)
    d = view_distance(r)
    az = gen.uniform(-math.pi, math.pi) + np.r_[0.0, np.cumsum(gen.uniform(lo, hi, n - 1))]
    e0, e1 = FLOOR_ELEVATION_RAD if floor else ELEVATION_RAD
    el = gen.uniform(e0, e1, n)
    eye = c + d * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    poses = [look_at(e, c) for e in eye]
    return ViewRing(poses, az, el, d, c, r)


def view_points(depth_m: NDArray[np.floating], config: RGBDConfig) -> NDArray[np.float64]:
    """Camera-frame points (N, 3) float64, metres, of a depth image's readings (row-major
    order), as ``read_scan`` gives them back (paper eq. 2)."""
    v, u = np.nonzero(np.isfinite(depth_m) & (depth_m > 0))
    return config.camera().backproject(u, v, np.asarray(depth_m, dtype=np.float64)[v, u])


def view_overlap(
    scene: Scene,
    points_world: NDArray[np.float64],
    T_world_camera: NDArray[np.float64],
    config: RGBDConfig,
    *,
    tol_m: float,
) -> float:
    """Share of a view's points (world frame) that another view also sees: inside its image
    and depth range, in its line of sight (the scene's first hit from its centre towards the
    point no nearer than the point's distance less ``tol_m``) and below its incidence
    limit. Denominator: the points given.

    Parameters
    ----------
    scene : Scene
    points_world : (N, 3) float64, metres
    T_world_camera : (4, 4) float64
        The other view's pose.
    config : RGBDConfig
        The other view's camera.
    tol_m : float, metres

    Returns
    -------
    float
        0..1 (0 for no points).
    """
    if len(points_world) == 0:
        return 0.0
    cam = config.camera()
    T = np.asarray(T_world_camera, dtype=np.float64)
    pc = (points_world - T[:3, 3]) @ T[:3, :3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = cam.fx * pc[:, 0] / z + cam.cx
        v = cam.fy * pc[:, 1] / z + cam.cy
    inside = (z >= config.min_depth_m) & (z <= config.max_depth_m)
    inside &= (u > -0.5) & (u < cam.width - 0.5) & (v > -0.5) & (v < cam.height - 0.5)
    seen = np.zeros(len(pc), dtype=bool)
    idx = np.flatnonzero(inside)
    if len(idx):
        dist = np.linalg.norm(points_world[idx] - T[:3, 3], axis=1)
        seen[idx] = in_line_of_sight(
            scene, T[:3, 3], points_world[idx], dist,
            tol_m=tol_m, max_incidence_rad=config.max_incidence_rad,
        )  # fmt: skip
    return float(seen.mean())


def write_views(
    out_dir: str | PathLike[str],
    scene: Scene,
    ring: ViewRing,
    *,
    config: RGBDConfig,
    depth_scale: float,
    rng: np.random.Generator | int | None = 0,
    progress: Progress | None = None,
) -> tuple[list[Path], list[dict[str, Any]], list[dict[str, Any]]]:
    """Render every view of a ring and write ``view_NN.png`` + ``view_NN.camera.json``.

    Parameters
    ----------
    out_dir : path-like
        Folder of the views (created).
    scene : Scene
    ring : ViewRing
    config : RGBDConfig
        The scanner (:func:`view_config`).
    depth_scale : float, metres per unit
        Depth step of the renders and the files.
    rng : numpy Generator, int or None
        Noise of every view, drawn view after view.
    progress : callable, optional
        ``progress(done, total)`` after each view.

    Returns
    -------
    files : list of Path
        Every file written.
    views : list of dict
        Per view: ``name``, ``file`` (relative to ``out_dir``'s parent), ``T_world_scanner``
        (the camera pose), ``azimuth_deg``, ``elevation_deg``, ``points``.
    pairs : list of dict
        Each view and the next: ``target``, ``source``, ``T_target_source``
        ``= inv(T_world_target) @ T_world_source``, ``distance_m`` (between the cameras),
        ``overlap`` (the smaller of the two shares of :func:`view_overlap`).
    """
    gen, _ = as_rng(rng)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = len(ring.poses)
    digits = max(2, len(str(n - 1)))
    cam = config.camera()
    files: list[Path] = []
    views: list[dict[str, Any]] = []
    world: list[NDArray[np.float64]] = []
    for i, T in enumerate(ring.poses):
        # depths quantised to the files' unit: storing them loses nothing more
        frame = render_rgbd(scene, T, config=config, rng=gen, depth_step_m=depth_scale, image=False)
        name = f"view_{i:0{digits}d}"
        files += write_depth_png(out / f"{name}.png", frame.depth, cam, depth_scale=depth_scale)
        pts = view_points(frame.depth, config)
        world.append(pts @ T[:3, :3].T + T[:3, 3])
        views.append(
            {
                "name": name,
                "file": f"{out.name}/{name}.png",
                "T_world_scanner": T.tolist(),
                "azimuth_deg": math.degrees(float(ring.azimuth_rad[i])),
                "elevation_deg": math.degrees(float(ring.elevation_rad[i])),
                "points": len(pts),
            }
        )
        if progress is not None:
            progress(i + 1, n)
    tol = 3.0 * config.depth_noise_m + 0.005 * ring.distance_m

    def overlap(i: int, j: int) -> float:
        P = ring.poses
        seen_j = view_overlap(scene, world[j], P[i], config, tol_m=tol)
        return min(seen_j, view_overlap(scene, world[i], P[j], config, tol_m=tol))

    pairs = neighbour_pairs([v["name"] for v in views], list(ring.poses[:n]), overlap)
    return files, views, pairs
