"""A camera-lidar rig: a pinhole camera mounted on a TLS station, with the exact extrinsic.

What ``flexreg synth --rig`` adds to a data set (the camera rides on the first station)::

    camera.png     the camera's image (colour, 8 bit)
    camera.json    its intrinsics, ``{"camera": {"model": "pinhole", "fx", ...}}`` (what
                   ``flexreg pick --camera`` and ``flexreg calibrate --camera`` read)
    init.json      a rough initial guess of ``T_camera_lidar`` (the truth moved by
                   :data:`INIT_ROTATION_DEG` and :data:`INIT_TRANSLATION_M`), as a tape
                   measure and a look along the camera would give
    gt.json        ``T_camera_lidar`` at its top level (``calibrate --truth gt.json``)

``T_camera_lidar = inv(T_world_camera) @ T_world_scanner`` maps the points of the station file
(scanner frame) into the camera frame (x right, y down, z forward): the convention of
``flexreg calibrate``'s output.

The camera sits on top of the scanner (a lever arm of 10-25 cm up and 5-15 cm aside) and looks
at the part of the scene with the most texture: of :data:`HEADINGS` headings around the station,
the one whose quick low-resolution rendering has the most corners (Shi-Tomasi), weighted by the
share of its pixels that see a surface and by the spread of their depths (near and far points
hold the pose better than one wall).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flexreg.core.camera import PinholeCamera
from flexreg.core.transforms import as_transform, invert, make_transform, rotation_about_axis
from flexreg.errors import DegenerateGeometryError, InputError
from flexreg.io import atomic_write
from flexreg.synth.config import RGBDConfig
from flexreg.synth.scene import Scene
from flexreg.synth.seeding import as_rng
from flexreg.synth.sensors import RGBDFrame, look_at, render_rgbd

__all__ = [
    "HEADINGS",
    "INIT_ROTATION_DEG",
    "INIT_TRANSLATION_M",
    "Rig",
    "place_rig",
    "render_rig",
    "rig_camera",
    "write_rig",
]

#: headings tried around the station for the camera's view
HEADINGS = 16
#: how far the rough initial guess of init.json lies from the truth (degrees, metres)
INIT_ROTATION_DEG = 2.0
INIT_TRANSLATION_M = 0.05
#: width of the quick renderings that score the headings, pixels
_SCORE_WIDTH = 160
#: nearest a surface may be to the camera's centre, metres
_CLEARANCE_M = 0.05


@dataclass(frozen=True, eq=False)
class Rig:
    """A camera on a scanner station.

    Attributes
    ----------
    camera : PinholeCamera
        Intrinsics (no lens distortion), pixels.
    T_world_camera : (4, 4) float64
        Camera pose (x right, y down, z forward), metres.
    T_world_scanner : (4, 4) float64
        The station's pose, metres.
    T_init : (4, 4) float64
        A rough guess of :attr:`T_camera_lidar` (see :data:`INIT_ROTATION_DEG`).
    """

    camera: PinholeCamera
    T_world_camera: NDArray[np.float64]
    T_world_scanner: NDArray[np.float64]
    T_init: NDArray[np.float64]

    @property
    def T_camera_lidar(self) -> NDArray[np.float64]:
        """(4, 4) float64: maps scanner-frame points (metres) into the camera frame."""
        return invert(self.T_world_camera) @ self.T_world_scanner

    def to_dict(self) -> dict[str, Any]:
        """The ``"rig"`` entry of ``gt.json``."""
        T = self.T_camera_lidar
        return {
            "camera": self.camera.to_dict(),
            "T_world_camera": self.T_world_camera.tolist(),
            "T_camera_lidar": T.tolist(),
            "T_lidar_camera": invert(T).tolist(),
            "lever_arm_m": (invert(self.T_world_scanner)[:3] @ np.r_[self.T_world_camera[:3, 3], 1])
            .round(12)
            .tolist(),
            "init_error": {"rotation_deg": INIT_ROTATION_DEG, "translation_m": INIT_TRANSLATION_M},
        }


def rig_camera(station_width: int) -> PinholeCamera:
    """The rig's camera for a station grid ``station_width`` columns wide: half as many
    columns (640 to 4096, 4:3), a 64 degree horizontal field of view (f = 0.8 x width).

    >>> c = rig_camera(2048)
    >>> (c.width, c.height, c.fx)
    (1024, 768, 819.2)
    """
    w = int(min(max(2 * round(station_width / 4), 640), 4096))
    h = 3 * w // 4
    f = 0.8 * w
    return PinholeCamera(f, f, (w - 1) / 2, (h - 1) / 2, w, h)


def _frame_config(camera: PinholeCamera, *, noise: float) -> RGBDConfig:
    return RGBDConfig(
        width=camera.width,
        height=camera.height,
        fx=camera.fx,
        fy=camera.fy,
        cx=camera.cx,
        cy=camera.cy,
        max_depth_m=13.0,
        image_noise=noise,
        dropout_rate=0.0,
        edge_dropout_prob=0.0,
    )


def _view_score(scene: Scene, T_world_camera: NDArray[np.float64], camera: PinholeCamera) -> float:
    """How good a view is to pick pairs in: the corners of the scene's structure (Shi-Tomasi
    on a quick rendering of albedo and surface orientation, without the surfaces' fine
    texture) x share of pixels seeing a surface within 13 m x (0.25 + spread of their log
    depths)."""
    import cv2  # heavy: only for the corner detector

    s = _SCORE_WIDTH / camera.width
    cx, cy = (camera.cx + 0.5) * s - 0.5, (camera.cy + 0.5) * s - 0.5
    small = PinholeCamera(
        camera.fx * s, camera.fy * s, cx, cy, _SCORE_WIDTH, round(camera.height * s)
    )
    rays = small.rays().reshape(-1, 3)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    dirs = (rays @ T_world_camera[:3, :3].T).astype(np.float32)
    hits = scene.cast(T_world_camera[:3, 3], dirs)
    depth = np.where(hits.hit, hits.t * rays[:, 2], np.inf)
    seen = depth < 13.0
    if seen.mean() < 0.2:
        return 0.0
    shade = 0.4 + 0.6 * np.abs(hits.normal @ np.array([0.3, 0.5, 0.81], dtype=np.float32))
    grey = np.where(seen, scene.colors[np.maximum(hits.primitive, 0)].mean(axis=1) * shade, 0)
    grey = np.clip(grey, 0, 255).astype(np.uint8).reshape(small.height, small.width)
    corners = cv2.goodFeaturesToTrack(grey, 400, 0.05, 3)
    n = 0 if corners is None else len(corners)
    return float(n * seen.mean() * (0.25 + np.std(np.log(depth[seen]))))


def place_rig(
    scene: Scene,
    T_world_scanner: ArrayLike,
    *,
    station_width: int,
    rng: np.random.Generator | int | None = 0,
    tries: int = 50,
) -> Rig:
    """Mount a camera on a station, looking at the most textured part of the scene.

    Parameters
    ----------
    scene : Scene
    T_world_scanner : (4, 4) float
        The station's pose, metres.
    station_width : int
        Columns of the station's grid (the camera's size follows, :func:`rig_camera`).
    rng : numpy Generator, int or None
        Lever arm, heading offset, pitch (-15 to -3 degrees), roll (+-3 degrees) and the
        initial guess's error.
    tries : int
        Lever arms tried before giving up.

    Returns
    -------
    Rig

    Raises
    ------
    DegenerateGeometryError
        No lever arm keeps the camera clear of the scene, or no heading sees any surface.
    """
    gen, _ = as_rng(rng)
    T_ws = as_transform(T_world_scanner, name="T_world_scanner")
    camera = rig_camera(station_width)
    eye = None
    for _ in range(tries):
        a = gen.uniform(0, 2 * math.pi)
        lever = np.r_[gen.uniform(0.05, 0.15) * np.r_[np.cos(a), np.sin(a)], gen.uniform(0.1, 0.25)]
        p = T_ws[:3, :3] @ lever + T_ws[:3, 3]
        if float(scene.distance(p[None])[0]) >= _CLEARANCE_M:
            eye = p
            break
    if eye is None:
        raise DegenerateGeometryError(f"no room for a camera on the station in {tries} tries")
    offset = gen.uniform(0, 2 * math.pi / HEADINGS)
    pitch = math.radians(gen.uniform(-15.0, -3.0))
    roll = math.radians(gen.uniform(-3.0, 3.0))
    best, best_score = None, 0.0
    for k in range(HEADINGS):
        yaw = offset + 2 * math.pi * k / HEADINGS
        d = [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
        T = look_at(eye, eye + np.asarray(d))
        T[:3, :3] = T[:3, :3] @ rotation_about_axis([0.0, 0.0, 1.0], roll)
        score = _view_score(scene, T, camera)
        if score > best_score:
            best, best_score = T, score
    if best is None:
        raise DegenerateGeometryError("the camera sees no surface in any direction")
    T_cl = invert(best) @ T_ws
    axis = gen.normal(size=3)
    shift = gen.normal(size=3)
    wrong = make_transform(
        rotation_about_axis(axis, math.radians(INIT_ROTATION_DEG)),
        INIT_TRANSLATION_M * shift / np.linalg.norm(shift),
    )
    return Rig(camera, best, T_ws, wrong @ T_cl)


def render_rig(scene: Scene, rig: Rig, *, rng: np.random.Generator | int | None = 0) -> RGBDFrame:
    """The rig camera's picture (colour, 2 grey levels of noise) and depth."""
    return render_rgbd(
        scene, rig.T_world_camera, config=_frame_config(rig.camera, noise=2.0), rng=rng
    )


def _write_text(text: str, path: Path) -> None:
    path.write_text(text)


def write_rig(
    out: Path,
    scene: Scene,
    rig: Rig,
    *,
    station_file: str,
    rng: np.random.Generator | int | None = 0,
) -> tuple[list[Path], dict[str, Any]]:
    """Write ``camera.png``, ``camera.json`` and ``init.json`` into ``out``.

    Returns
    -------
    files : list of Path
        The files written.
    entry : dict
        The ``"rig"`` entry of ``gt.json`` (with the files' names).
    """
    import cv2  # heavy: only for writing the PNG

    frame = render_rig(scene, rig, rng=rng)
    ok, buf = cv2.imencode(
        ".png", np.ascontiguousarray(frame.image[..., ::-1]), [cv2.IMWRITE_PNG_COMPRESSION, 3]
    )
    if not ok:  # pragma: no cover - cv2 failure
        raise InputError(out / "camera.png", "cannot encode the PNG")
    texts = {
        "camera.json": {
            "camera": rig.camera.to_dict(),
            "distortion": [],
            "note": "pinhole intrinsics in pixels (pixel centres at integer coordinates)",
        },
        "init.json": {
            "T_camera_lidar": rig.T_init.tolist(),
            "note": (
                f"a rough guess, {INIT_ROTATION_DEG:g} deg and {INIT_TRANSLATION_M:g} m "
                "from the truth (gt.json)"
            ),
        },
    }
    files = [out / "camera.png"]
    atomic_write(files[0], lambda tmp: tmp.write_bytes(buf.tobytes()))
    for name, doc in texts.items():
        atomic_write(out / name, functools.partial(_write_text, json.dumps(doc, indent=2) + "\n"))
        files.append(out / name)
    entry = {
        "image": "camera.png",
        "intrinsics": "camera.json",
        "init": "init.json",
        "lidar": station_file,
        **rig.to_dict(),
    }
    return files, entry
