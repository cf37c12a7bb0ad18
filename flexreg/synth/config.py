"""Every knob of the synthetic data: the data set (:class:`SynthConfig`), the laser scanner and
spinning lidar (:class:`TLSConfig`), the RGB-D camera (:class:`RGBDConfig`), the rosette lidar
(:class:`RosetteConfig`) and the fused fragments (:class:`FragmentConfig`), validated in one
place (each rule once, on its field)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from flexreg.config import Config, Positive, Seed, one_of
from flexreg.core.budget import ENV_VAR, format_bytes, memory_budget
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.errors import ConfigError
from flexreg.io.depth import TUM_DEPTH_SCALE
from flexreg.synth.scenes import OBJECT_SCENE_KINDS, PROJECT_SCENE_KINDS, SCENE_KINDS

__all__ = [
    "DEFAULT_OBJECT_VIEWS",
    "FORMATS",
    "LIDAR_KINDS",
    "OBJECT_NOISE_M",
    "PROJECT_MIN_OVERLAP",
    "FragmentConfig",
    "RGBDConfig",
    "RosetteConfig",
    "SynthConfig",
    "TLSConfig",
]

#: station file formats of a data set
FORMATS = ("ptx", "e57", "npz")
#: widest station grid (height: half of it); the documented maximum, 8192 x 4096 (33.5 M
#: pixels), takes about 6 GB while simulated
MAX_WIDTH = 8192
#: memory a station takes per pixel while it is simulated and written, bytes (measured: 1.34 GB
#: more for 4096x2048 than for 1024x512, about 170 bytes per pixel; rounded up)
STATION_PIXEL_BYTES = 180
#: floor sizes of a procedural scene, metres
MIN_SIZE_M, MAX_SIZE_M = 1.0, 1000.0

#: default minimal overlap of a station with the one it was set up from, in project scenes
#: (low enough for links that only see each other through a doorway)
PROJECT_MIN_OVERLAP = 0.15

#: sensors of the lidar frames (``lidar_kind``)
LIDAR_KINDS = ("spinning", "rosette")
#: object views of the ``"object"`` scene unless ``views`` is given
DEFAULT_OBJECT_VIEWS = 6
#: depth noise sigma of object views unless ``noise_m`` is given, metres (a structured-light
#: scanner's 0.1 mm, not a TLS's 3 mm)
OBJECT_NOISE_M = 0.0001

#: a finite number >= 0 (noise levels, ranges, angles)
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
#: a probability in [0, 1]
Probability = Annotated[float, Field(ge=0, le=1)]


# ====================================================================================== TLS
class TLSConfig(Config):
    """Terrestrial laser scanner (or spinning lidar) model on an equirectangular grid.

    Attributes
    ----------
    width, height : int, pixels
        Grid size: columns (azimuth) x rows (polar angle), at least 4 x 2.
    phi_min, phi_max : float, radians
        Azimuth field of view (full turn by default).
    theta_min, theta_max : float, radians
        Polar field of view, from +Z (zenith) down.
    range_noise_m : float, metres
        Constant part of the range noise standard deviation.
    range_noise_per_m : float, metres per metre of range
        Range-proportional part of the range noise standard deviation (1e-5 = 10 ppm).
    min_range_m, max_range_m : float, metres
        Returns outside this interval are lost.
    max_incidence_rad : float, radians
        Returns at a larger incidence angle (grazing) are lost; in (0, pi/2].
    tripod_cone_rad : float, radians
        Half-angle of the blind cone straight down (tripod and scanner body); 0 disables it.
    dropout_rate : float
        Probability that a return is randomly lost.
    mixed_pixel_prob : float
        Probability that a pixel at a depth edge becomes a mixed pixel; 0 disables them.
    mixed_pixel_jump_m : float, metres
        Minimal range jump to a neighbour that makes a depth edge (or 2 % of the range).
    intensity_range_scale_m : float, metres
        Range at which the intensity has fallen to 1/e.
    intensity_speckle : float
        Relative standard deviation of the multiplicative intensity noise.
    min_intensity : float
        Returns with a lower intensity are lost (dark surfaces far away or at grazing angles).
    colors : bool
        Also give each point the scene colour under simple shading (as a TLS camera would).
    """

    width: int = Field(2048, ge=4)
    height: int = Field(1024, ge=2)
    phi_min: float = -math.pi
    phi_max: float = math.pi
    theta_min: float = 0.0
    theta_max: float = math.pi
    range_noise_m: NonNegative = 0.003
    range_noise_per_m: NonNegative = 1e-5
    min_range_m: NonNegative = 0.4
    max_range_m: float = 150.0
    max_incidence_rad: float = Field(math.radians(86.0), gt=0, le=math.pi / 2)
    tripod_cone_rad: NonNegative = math.radians(30.0)
    dropout_rate: Probability = 0.002
    mixed_pixel_prob: Probability = 0.5
    mixed_pixel_jump_m: Positive = 0.1
    intensity_range_scale_m: Positive = 80.0
    intensity_speckle: NonNegative = 0.04
    min_intensity: NonNegative = 0.004
    colors: bool = False

    @field_validator("max_range_m")
    @classmethod
    def _beyond_min_range(cls, v: float, info: ValidationInfo) -> float:
        lo = info.data.get("min_range_m")
        if lo is not None and not v > lo:
            raise ValueError(f"must exceed min_range_m ({lo:g})")
        return v

    @model_validator(mode="after")
    def _field_of_view(self) -> TLSConfig:
        self.camera()  # raises for a bad angular field of view
        return self

    def camera(self) -> SphericalCamera:
        """The equirectangular camera of this grid."""
        return SphericalCamera(
            int(self.width),
            int(self.height),
            float(self.phi_min),
            float(self.phi_max),
            float(self.theta_min),
            float(self.theta_max),
        )


# ====================================================================================== RGB-D
class RGBDConfig(Config):
    """Pinhole RGB-D camera (Kinect/TUM-like by default).

    Attributes
    ----------
    width, height : int, pixels
        Image size: columns x rows.
    fx, fy, cx, cy : float, pixels
        Intrinsics: focal lengths and principal point (paper eq. 1).
    depth_noise_m : float, metres
        Constant part of the depth noise standard deviation.
    depth_noise_quadratic : float, 1/metres
        Quadratic part: ``sigma = depth_noise_m + depth_noise_quadratic * z**2``.
    min_depth_m, max_depth_m : float, metres
        Depths outside this interval are lost; ``0 <= min_depth_m < max_depth_m``, and the
        maximum must fit 16-bit TUM depth (13.1 m).
    max_incidence_rad : float, radians
        Depths at a larger incidence angle (grazing) are lost.
    dropout_rate : float
        Probability of a random missing depth pixel.
    edge_dropout_prob : float
        Probability that a pixel at a depth edge has no depth (structured-light shadows).
    colour : bool
        Colour (RGB) or grey images.
    image_noise : float, 8-bit grey levels
        Standard deviation of the image noise.
    rate_hz : float, hertz
        Frame rate of sequences (timestamps).
    speed_mps : float, metres per second
        Mean speed along a sequence's trajectory.
    """

    width: int = 640
    height: int = 480
    fx: float = 525.0
    fy: float = 525.0
    cx: float = 319.5
    cy: float = 239.5
    depth_noise_m: float = 0.001
    depth_noise_quadratic: float = 0.0015
    min_depth_m: float = Field(0.4, ge=0)
    max_depth_m: float = 8.0
    max_incidence_rad: float = math.radians(80.0)
    dropout_rate: Probability = 0.005
    edge_dropout_prob: Probability = 0.5
    colour: bool = True
    image_noise: float = 2.0
    rate_hz: Positive = 30.0
    speed_mps: Positive = 0.4

    @field_validator("max_depth_m")
    @classmethod
    def _depth_range(cls, v: float, info: ValidationInfo) -> float:
        lo = info.data.get("min_depth_m")
        if lo is not None and not v > lo:
            raise ValueError(f"must exceed min_depth_m ({lo:g})")
        if v / TUM_DEPTH_SCALE > 65535:
            raise ValueError("does not fit 16-bit TUM depth (13.1 m)")
        return v

    @model_validator(mode="after")
    def _intrinsics(self) -> RGBDConfig:
        self.camera()  # raises for bad intrinsics
        return self

    def camera(self) -> PinholeCamera:
        """The pinhole camera of these intrinsics."""
        return PinholeCamera(self.fx, self.fy, self.cx, self.cy, int(self.width), int(self.height))


# ====================================================================================== rosette
class RosetteConfig(Config):
    """Narrow-field lidar with a non-repetitive rosette scan (Livox Avia / Mid-70 style).

    One beam is steered by two prisms turning at incommensurate rates
    (:data:`flexreg.synth.rosette.PRISM_HZ`): its direction sweeps petals through the centre
    that never repeat, so each frame covers other parts of the field of view and the coverage
    grows with integration time. The sensor frame is x forward, y left, z up.

    Attributes
    ----------
    fov_deg : (float, float), degrees
        Full field of view across (horizontal) and up-down (vertical), each within (0, 170]:
        the rosette fills the ellipse of these axes (Avia: 70.4 x 77.2).
    points : int
        Shots per frame, 100..1000000 (returns are fewer: misses, range limits, dropouts).
    rate_hz : float, hertz
        Frame rate: a frame integrates ``1 / rate_hz`` seconds of the pattern.
    speed_mps : float, metres per second
        Speed along the trajectory: frames ``speed_mps / rate_hz`` apart.
    range_noise_m : float, metres
        Range noise standard deviation (Avia: 2 cm).
    max_range_m : float, metres
        Returns beyond this range are lost (returns nearer than 1 m too, the blind zone).
    """

    fov_deg: tuple[float, float] = (70.4, 77.2)
    points: int = Field(24000, ge=100, le=1_000_000)
    rate_hz: Positive = 10.0
    speed_mps: Positive = 1.5
    range_noise_m: NonNegative = 0.02
    max_range_m: float = Field(190.0, gt=1.0, allow_inf_nan=False)

    @field_validator("fov_deg")
    @classmethod
    def _fov(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not all(math.isfinite(a) and 0 < a <= 170 for a in v):
            raise ValueError(
                f"field of view must be within (0, 170] deg each way, got {v[0]:g}x{v[1]:g}"
            )
        return v


# ====================================================================================== fragments
class FragmentConfig(Config):
    """Fused depth fragments (3DMatch style): consecutive depth frames of a hand-held camera
    fused into one cloud in the first frame's coordinates.

    Attributes
    ----------
    frames : int
        Depth frames fused into each fragment, 1..1000 (3DMatch: 50).
    voxel_m : float, metres
        Voxel size of the fused cloud (each occupied voxel: the mean of its points), 1 mm..1 m.
    overlap : (float, float)
        ``0 < min < max < 1``: the overlap of consecutive fragments lies in this range (the
        smaller share of a fragment's points within 3 voxels of the other's).
    """

    frames: int = Field(50, ge=1, le=1000)
    voxel_m: float = Field(0.01, ge=0.001, le=1.0)
    overlap: tuple[float, float] = (0.3, 0.7)

    @field_validator("overlap")
    @classmethod
    def _overlap_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (0 < lo < hi < 1 and hi - lo >= 0.05):
            raise ValueError(
                "overlap range must satisfy 0 < min < max < 1, at least 0.05 wide, got "
                f"{lo:g}..{hi:g}"
            )
        return v


# ====================================================================================== data set
class SynthConfig(Config):
    """Everything ``flexreg synth`` needs; saved in ``gt.json``.

    Attributes
    ----------
    scene : str
        Scene to scan: a procedural kind, a project kind, or the path of a mesh file. A kind
        of :data:`~flexreg.synth.scenes.SCENE_KINDS` (``"room"``, ``"courtyard"``,
        ``"hall"``, ``"symmetric-room"``, ``"tunnel"``, ``"bays"`` and their ``"-cue"``
        variants), a project kind of :data:`~flexreg.synth.scenes.PROJECT_SCENE_KINDS`
        (``"building"``, ``"warehouse"``, ``"street"``: sized for the stations, placed as a
        walked survey), ``"object"`` (a procedural object of about 0.3 m for ``views``), or
        the path of a mesh file to scan.
    stations : int
        Number of TLS stations, 0..200: 0 only beside ``views`` (which replace them),
        ``fragments`` or a sequence; a project needs at least 2 per group.
    width, height : int, pixels
        Station grid (azimuth columns x polar rows), within 8x4 .. 8192x4096 and the memory
        budget. See :mod:`flexreg.core.budget`; a station takes about
        :data:`STATION_PIXEL_BYTES` per pixel while it is simulated and written).
    noise_m : float, metres
        Constant part of the range noise sigma of the stations (0..1 m); with ``views`` the
        depth noise sigma of the views (:data:`OBJECT_NOISE_M` unless given).
    seed : int
        Seed of the scene, the station placement and the sensor noise (same seed, same data).
    format : {"ptx", "e57", "npz"}
        File format of the stations.
    rgbd_frames : int
        Length of the optional RGB-D sequence, frames (0..100000; 0: none).
    lidar_frames : int
        Length of the optional spinning-lidar sequence, frames (0..100000; 0: none).
    min_overlap : float
        Minimal mutual overlap of a station with its neighbour, 0..1 (project kinds:
        :data:`PROJECT_MIN_OVERLAP` unless given).
    distance_range_m : (float, float), metres
        ``0 < min <= max`` distance between neighbouring stations.
    max_tilt_rad : float, radians
        Maximal station tilt, 0..30 degrees. (A result's ``max_tilt_deg`` is accepted too.)
    mixed_pixels : bool
        Simulate mixed pixels at depth edges (returns between the near and the far surface).
    mesh_scale : float
        Scale of a mesh scene to metres.
    mesh_up_axis : {"x", "y", "z"}
        Up axis of a mesh scene.
    size_m : (float, float) or None, metres
        Floor size of a procedural scene, 1..1000 each way (None: the scene's own).
    embed_poses : bool
        Write each station's (and lidar frame's) true pose into its file instead of the
        identity (not for object views, whose depth PNGs hold no pose, nor for fragments,
        whose PLY files hold none).
    groups : int
        Project kinds only: number of disconnected sites (1..4) sharing the stations, far
        enough apart that no station of one sees anything of another.
    rig : bool
        Mount a pinhole camera on the first station (:mod:`flexreg.synth.rig`): its image,
        intrinsics, a rough initial guess and the true ``T_camera_lidar`` in ``gt.json``; the
        stations then carry colours, and one station is the default.
    views : int
        Object views (0..1000; 0: none), which replace the stations: pinhole depth scans on
        a ring around the object of ``scene`` (``"object"`` or a mesh file), each looking at
        its centre (:mod:`flexreg.synth.objectscan`; ``"object"``: :data:`DEFAULT_OBJECT_VIEWS`
        unless given).
    view_step_rad : (float, float), radians
        ``0 < min <= max <= pi``: azimuth between neighbouring object views, each drawn
        uniformly from this range.
    floor : bool
        Object views: a floor under the object (by default it floats alone in the air).
    lidar_kind : {"spinning", "rosette"}
        Sensor of the lidar frames: a 64-ring spinning lidar, or a narrow-field rosette lidar
        (table ``rosette``; unorganised PCD frames).
    fragments : int
        Fused fragments along a hand-held depth camera's path (0..10000; 0: none), table
        ``fragment`` (:mod:`flexreg.synth.fragments`).
    rosette : RosetteConfig
        The rosette lidar of ``lidar_kind = "rosette"``.
    fragment : FragmentConfig
        How fragments are fused and how much consecutive ones overlap.
    """

    scene: str = "room"
    stations: int = 2
    width: int = 2048
    height: int = 1024
    noise_m: float = 0.003
    seed: Seed = 0
    format: str = "ptx"
    rgbd_frames: int = Field(0, ge=0, le=100000)
    lidar_frames: int = Field(0, ge=0, le=100000)
    min_overlap: float = 0.5
    distance_range_m: tuple[float, float] = (2.0, 10.0)
    max_tilt_rad: float = math.radians(3.0)
    mixed_pixels: bool = True
    mesh_scale: Positive = 1.0
    mesh_up_axis: Annotated[str, one_of(("x", "y", "z"))] = "z"
    size_m: tuple[float, float] | None = None
    embed_poses: bool = False
    groups: int = Field(1, ge=1, le=4)
    rig: bool = False
    views: int = Field(0, ge=0, le=1000)
    view_step_rad: tuple[float, float] = (math.radians(30.0), math.radians(120.0))
    floor: bool = False
    lidar_kind: Annotated[str, one_of(LIDAR_KINDS)] = "spinning"
    fragments: int = Field(0, ge=0, le=10000)
    rosette: RosetteConfig = RosetteConfig()
    fragment: FragmentConfig = FragmentConfig()

    @model_validator(mode="before")
    @classmethod
    def _tilt_in_degrees(cls, data: Any) -> Any:
        """Accept the ``max_tilt_deg`` that :meth:`to_dict` adds (a result file's config);
        give project kinds their own default minimal overlap, and a rig one station."""
        if isinstance(data, dict) and "max_tilt_deg" in data:
            data = dict(data)
            deg = data.pop("max_tilt_deg")
            data.setdefault("max_tilt_rad", math.radians(float(deg)))
        if isinstance(data, dict) and data.get("scene") in PROJECT_SCENE_KINDS:
            if data.get("min_overlap") is None:
                data = {**data, "min_overlap": PROJECT_MIN_OVERLAP}
        if isinstance(data, dict) and data.get("rig") is True and data.get("stations") is None:
            data = {**data, "stations": 1}  # a rig is one station and its camera
        if isinstance(data, dict):
            data = cls._object_defaults(data)
        return data

    @staticmethod
    def _object_defaults(data: dict[str, Any]) -> dict[str, Any]:
        """Object views: ``"object"`` takes :data:`DEFAULT_OBJECT_VIEWS`; views replace the
        stations (none unless given, which is refused) and take a scanner's noise."""
        if data.get("scene") in OBJECT_SCENE_KINDS and data.get("views") is None:
            data = {**data, "views": DEFAULT_OBJECT_VIEWS}
        views = data.get("views")
        if isinstance(views, int) and not isinstance(views, bool) and views > 0:
            if data.get("stations") is None:
                data = {**data, "stations": 0}
            if data.get("noise_m") is None:
                data = {**data, "noise_m": OBJECT_NOISE_M}
        return data

    @field_validator("groups")
    @classmethod
    def _groups(cls, v: int, info: ValidationInfo) -> int:
        scene, n = info.data.get("scene"), info.data.get("stations")
        if scene in PROJECT_SCENE_KINDS:
            if n is not None and n < 2 * v:
                raise ValueError(
                    f"a {scene} project needs at least 2 stations per group, got {n} "
                    f"station(s) for {v} group(s)"
                )
        elif v != 1 and scene is not None:
            raise ValueError(
                f"groups apply to project scenes ({', '.join(PROJECT_SCENE_KINDS)}), "
                f"not to {scene!r}"
            )
        return v

    @property
    def is_project(self) -> bool:
        """Whether the scene is a multi-station project kind."""
        return self.scene in PROJECT_SCENE_KINDS

    @field_validator("scene")
    @classmethod
    def _scene(cls, v: str) -> str:
        kinds_ = (*SCENE_KINDS, *PROJECT_SCENE_KINDS, *OBJECT_SCENE_KINDS)
        if v not in kinds_ and not Path(v).is_file():
            kinds = ", ".join(kinds_)
            raise ValueError(f"scene must be one of {kinds} or an existing mesh file")
        return v

    @field_validator("stations", mode="before")
    @classmethod
    def _stations(cls, v: Any, info: ValidationInfo) -> Any:
        if isinstance(v, bool) or int(v) != v or v < 0:
            raise ValueError("stations must be a positive integer")
        if v > 200:
            raise ValueError("at most 200 stations")
        if v < 2 and info.data.get("scene") in PROJECT_SCENE_KINDS:
            raise ValueError(f"a {info.data['scene']} project needs at least 2 stations")
        return v

    @field_validator("height")
    @classmethod
    def _resolution(cls, v: int, info: ValidationInfo) -> int:
        w = info.data.get("width", 8)
        if not (8 <= int(w) <= MAX_WIDTH and 4 <= int(v) <= MAX_WIDTH // 2):
            raise ValueError(
                f"resolution must be within 8x4 .. {MAX_WIDTH}x{MAX_WIDTH // 2}, got {w}x{v}"
            )
        need, budget = int(w) * int(v) * STATION_PIXEL_BYTES, memory_budget()
        if need > budget:
            raise ValueError(
                f"a {w}x{v} station would need {format_bytes(need)} of memory, more than the "
                f"memory budget of {format_bytes(budget)} (set {ENV_VAR} or flexreg "
                "--memory-budget to change it)"
            )
        return v

    @field_validator("size_m")
    @classmethod
    def _size(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not all(math.isfinite(x) and MIN_SIZE_M <= x <= MAX_SIZE_M for x in v):
            raise ValueError(
                f"floor size must be {MIN_SIZE_M:g} to {MAX_SIZE_M:g} m each way, got "
                f"{v[0]:g}x{v[1]:g}"
            )
        return v

    @field_validator("noise_m")
    @classmethod
    def _noise(cls, v: float) -> float:
        if not (np.isfinite(v) and 0 <= v <= 1.0):
            raise ValueError(f"range noise must be 0..1000 mm, got {v * 1000:g} mm")
        return v

    @field_validator("format")
    @classmethod
    def _format(cls, v: str) -> str:
        if v not in FORMATS:
            raise ValueError(f"format must be one of {', '.join(FORMATS)}")
        return v

    @field_validator("min_overlap")
    @classmethod
    def _overlap(cls, v: float) -> float:
        if not 0 <= v <= 1:
            raise ValueError("min overlap must be within 0..1")
        return v

    @field_validator("distance_range_m")
    @classmethod
    def _distance_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        d0, d1 = v
        if not (0 < d0 <= d1):
            raise ValueError(f"distance range must satisfy 0 < min <= max, got {d0:g}..{d1:g} m")
        return v

    @field_validator("max_tilt_rad")
    @classmethod
    def _tilt(cls, v: float) -> float:
        if not 0 <= v <= math.radians(30):
            raise ValueError(f"max tilt must be 0..30 deg, got {math.degrees(v):g} deg")
        return v

    @field_validator("view_step_rad")
    @classmethod
    def _view_step(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi <= math.pi):
            raise ValueError(
                "view step must satisfy 0 < min <= max <= 180 deg, got "
                f"{math.degrees(lo):g}..{math.degrees(hi):g} deg"
            )
        return v

    @model_validator(mode="after")
    def _products(self) -> SynthConfig:
        """What the data set holds fits together: object views alone, on an object; a floor
        only under one; no stations only when something else is made."""
        on_object = self.scene in OBJECT_SCENE_KINDS or self.is_mesh
        if self.views:
            if not on_object:
                raise ConfigError(
                    f"views: object views need scene 'object' or a mesh file, not {self.scene!r}"
                )
            if self.stations:
                raise ConfigError("stations: object views replace the stations; leave it out")
            if self.rgbd_frames or self.lidar_frames or self.fragments or self.rig:
                raise ConfigError(
                    "views: object views come alone (no rgbd_frames, lidar_frames, fragments "
                    "or rig)"
                )
            if self.embed_poses:
                raise ConfigError(
                    "embed_poses: object views are depth PNGs, which hold no pose (their "
                    "poses are in gt.json)"
                )
        elif self.scene in OBJECT_SCENE_KINDS:
            raise ConfigError("views: the object scene is scanned by object views (1..1000)")
        if self.floor and not self.views:
            raise ConfigError("floor: a floor goes under the object of object views (views)")
        if self.lidar_kind != "spinning" and not self.lidar_frames:
            raise ConfigError(f"lidar_kind: {self.lidar_kind} frames need lidar_frames")
        if self.stations == 0 and not (
            self.views or self.fragments or self.rgbd_frames or self.lidar_frames
        ):
            raise ConfigError(
                "stations: stations must be a positive integer (0 only with views, fragments, "
                "rgbd_frames or lidar_frames)"
            )
        if self.rig and self.stations == 0:
            raise ConfigError("rig: a rig is mounted on a station; stations must be 1 or more")
        return self

    @property
    def is_mesh(self) -> bool:
        """Whether the scene is a mesh file (not a procedural, project or object kind)."""
        return self.scene not in (*SCENE_KINDS, *PROJECT_SCENE_KINDS, *OBJECT_SCENE_KINDS)

    def tls_config(self) -> TLSConfig:
        """Sensor model of the stations."""
        return TLSConfig(
            width=int(self.width),
            height=int(self.height),
            range_noise_m=float(self.noise_m),
            mixed_pixel_prob=0.5 if self.mixed_pixels else 0.0,
            colors=bool(self.rig),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field, plus ``max_tilt_deg`` for readers."""
        d = super().to_dict()
        d["max_tilt_deg"] = round(math.degrees(self.max_tilt_rad), 9)
        return d
