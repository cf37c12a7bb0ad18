"""Synthetic scanner: seeded procedural scenes and simulated sensors with exact ground truth.

>>> from flexreg.synth import station_pair
>>> target, source, T_target_source = station_pair("room", seed=3)  # doctest: +SKIP

Scenes (:func:`make_scene`: ``room``, ``courtyard``, ``hall``; the ambiguous
``symmetric-room``, ``tunnel``, ``bays`` and their ``-cue`` variants; :func:`scene_from_mesh`) are
triangle meshes with a reflectance and colour per triangle. Sensors ray-cast them:
:func:`scan_tls` (equirectangular TLS station), :func:`scan_lidar` (spinning lidar),
:func:`render_rgbd` (pinhole depth + image); :func:`place_rig` mounts a camera on a station
(a camera-lidar rig with its exact extrinsic). :func:`place_stations` finds stations with a
guaranteed mutual overlap and inter-station distance; :func:`synthesize` writes a whole data set
(what ``flexreg synth`` runs). Project scenes (:data:`PROJECT_SCENE_KINDS`: ``building``,
``warehouse``, ``street``) are sized for many stations, which :func:`place_project` sets up as
a surveyor walks a site; :func:`make_project` writes one. Beside stations: object views
round an object (:func:`procedural_object`, :func:`object_from_mesh`, :func:`view_ring`,
:func:`write_views`), rosette-lidar frames (:func:`scan_rosette`) and fused fragments
(:func:`write_fragments`). Ground truth:
``T_target_source = inv(T_world_target) @ T_world_source``; scans hold points in the scanner
frame with ``T_world_scanner`` as pose.
"""

from flexreg.exports import lazy

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "AMBIGUOUS_SCENE_KINDS": "flexreg.synth.scenes",
    "CUE_SCENE_KINDS": "flexreg.synth.scenes",
    "SCENE_KINDS": "flexreg.synth.scenes",
    "FragmentConfig": "flexreg.synth.config",
    "FreeMap": "flexreg.synth.placement",
    "GROUP_GAP_M": "flexreg.synth.scenes",
    "OBJECT_SCENE_KINDS": "flexreg.synth.scenes",
    "PROJECT_SCENE_KINDS": "flexreg.synth.scenes",
    "ProjectPlacement": "flexreg.synth.project",
    "Material": "flexreg.synth.mesh",
    "MeshBuilder": "flexreg.synth.mesh",
    "RGBDConfig": "flexreg.synth.config",
    "RGBDFrame": "flexreg.synth.sensors",
    "RayHits": "flexreg.synth.scene",
    "Rig": "flexreg.synth.rig",
    "RosetteConfig": "flexreg.synth.config",
    "Scene": "flexreg.synth.scene",
    "StationPair": "flexreg.synth.placement",
    "SynthConfig": "flexreg.synth.config",
    "SynthResult": "flexreg.synth.dataset",
    "TLSConfig": "flexreg.synth.config",
    "add_mesh_objects": "flexreg.synth.scenes",
    "bays": "flexreg.synth.scenes",
    "building": "flexreg.synth.scenes",
    "camera_trajectory": "flexreg.synth.paths",
    "courtyard": "flexreg.synth.scenes",
    "fragment_overlap": "flexreg.synth.fragments",
    "fragment_trajectory": "flexreg.synth.fragments",
    "free_map": "flexreg.synth.placement",
    "hall": "flexreg.synth.scenes",
    "lidar_config": "flexreg.synth.sensors",
    "lidar_trajectory": "flexreg.synth.paths",
    "look_at": "flexreg.synth.sensors",
    "make_project": "flexreg.synth.dataset",
    "make_project_scene": "flexreg.synth.scenes",
    "make_scene": "flexreg.synth.scenes",
    "object_extent": "flexreg.synth.scenes",
    "object_from_mesh": "flexreg.synth.scenes",
    "overlap_components": "flexreg.synth.project",
    "overlap_matrix": "flexreg.synth.project",
    "place_project": "flexreg.synth.project",
    "place_rig": "flexreg.synth.rig",
    "place_stations": "flexreg.synth.placement",
    "procedural_object": "flexreg.synth.scenes",
    "read_scene": "flexreg.synth.scene",
    "render_rgbd": "flexreg.synth.sensors",
    "render_rig": "flexreg.synth.rig",
    "room": "flexreg.synth.scenes",
    "rosette_angles": "flexreg.synth.rosette",
    "scan_lidar": "flexreg.synth.sensors",
    "scan_rosette": "flexreg.synth.rosette",
    "scan_tls": "flexreg.synth.sensors",
    "scene_from_mesh": "flexreg.synth.scenes",
    "smooth_path": "flexreg.synth.paths",
    "station_overlap": "flexreg.synth.placement",
    "station_pair": "flexreg.synth.placement",
    "street": "flexreg.synth.scenes",
    "stream": "flexreg.synth.placement",
    "symmetric_room": "flexreg.synth.scenes",
    "synthesize": "flexreg.synth.dataset",
    "tunnel": "flexreg.synth.scenes",
    "view_ring": "flexreg.synth.objectscan",
    "visible_fraction": "flexreg.synth.placement",
    "voxel_downsample": "flexreg.synth.fragments",
    "warehouse": "flexreg.synth.scenes",
    "with_floor": "flexreg.synth.scenes",
    "write_fragments": "flexreg.synth.fragments",
    "write_rosette_frames": "flexreg.synth.rosette",
    "write_tum_sequence": "flexreg.synth.sensors",
    "write_views": "flexreg.synth.objectscan",
    "zone_free_map": "flexreg.synth.project",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
