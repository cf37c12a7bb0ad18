"""Synthetic scanner: seeded procedural scenes and simulated sensors with exact ground truth.

>>> from flexreg.synth import station_pair
>>> target, source, T_target_source = station_pair("room", seed=3)  # doctest: +SKIP

Scenes (:func:`make_scene`: ``room``, ``courtyard``, ``hall``; the ambiguous
``symmetric-room``, ``tunnel``, ``bays`` and their ``-cue`` variants; :func:`scene_from_mesh`) are
triangle meshes with a reflectance and colour per triangle. Sensors ray-cast them:
:func:`scan_tls` (equirectangular TLS station), :func:`scan_lidar` (spinning lidar),
:func:`render_rgbd` (pinhole depth + image). :func:`place_stations` finds stations with a
guaranteed mutual overlap and inter-station distance; :func:`synthesize` writes a whole data set
(what ``flexreg synth`` runs). Ground truth: ``T_target_source = inv(T_world_target) @
T_world_source``; scans hold points in the scanner frame with ``T_world_scanner`` as pose.
"""

from flexreg.synth.config import RGBDConfig, SynthConfig, TLSConfig
from flexreg.synth.dataset import (
    SynthResult,
    camera_trajectory,
    lidar_trajectory,
    smooth_path,
    synthesize,
)
from flexreg.synth.mesh import Material, MeshBuilder
from flexreg.synth.placement import (
    FreeMap,
    StationPair,
    free_map,
    place_stations,
    station_overlap,
    station_pair,
    stream,
    visible_fraction,
)
from flexreg.synth.scene import RayHits, Scene, read_scene
from flexreg.synth.scenes import (
    AMBIGUOUS_SCENE_KINDS,
    CUE_SCENE_KINDS,
    SCENE_KINDS,
    add_mesh_objects,
    bays,
    courtyard,
    hall,
    make_scene,
    room,
    scene_from_mesh,
    symmetric_room,
    tunnel,
)
from flexreg.synth.sensors import (
    RGBDFrame,
    lidar_config,
    look_at,
    render_rgbd,
    scan_lidar,
    scan_tls,
    write_tum_sequence,
)

__all__ = [
    "AMBIGUOUS_SCENE_KINDS",
    "CUE_SCENE_KINDS",
    "SCENE_KINDS",
    "FreeMap",
    "Material",
    "MeshBuilder",
    "RGBDConfig",
    "RGBDFrame",
    "RayHits",
    "Scene",
    "StationPair",
    "SynthConfig",
    "SynthResult",
    "TLSConfig",
    "add_mesh_objects",
    "bays",
    "camera_trajectory",
    "courtyard",
    "free_map",
    "hall",
    "lidar_config",
    "lidar_trajectory",
    "look_at",
    "make_scene",
    "place_stations",
    "read_scene",
    "render_rgbd",
    "room",
    "scan_lidar",
    "scan_tls",
    "scene_from_mesh",
    "smooth_path",
    "station_overlap",
    "station_pair",
    "stream",
    "symmetric_room",
    "synthesize",
    "tunnel",
    "visible_fraction",
    "write_tum_sequence",
]
