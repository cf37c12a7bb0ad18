"""`flexreg synth`: write a synthetic data set with exact ground truth."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.cli._common import console, err_console, progress_bar
from flexreg.cli.app import app
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_out_folder,
    with_default,
)
from flexreg.errors import ConfigError
from flexreg.synth.config import SynthConfig

if TYPE_CHECKING:
    from flexreg.synth.dataset import SynthResult


def _parse_pair(text: str, sep: str, what: str, option: str) -> tuple[float, float]:
    parts = text.lower().replace(" ", "").split(sep)
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"{option}: expected {what}, got {text!r}") from None
    return a, b


#: options that set fields of SynthConfig (option -> field or fields)
OPTIONS: dict[str, str | tuple[str, ...]] = {
    "--scene": "scene",
    "--stations": "stations",
    "--resolution": ("width", "height"),
    "--noise-mm": "noise_m",
    "--seed": "seed",
    "--format": "format",
    "--rgbd-frames": "rgbd_frames",
    "--lidar-frames": "lidar_frames",
    "--min-overlap": "min_overlap",
    "--distance-m": "distance_range_m",
    "--max-tilt-deg": "max_tilt_rad",
    "--mixed-pixels": "mixed_pixels",
    "--size-m": "size_m",
    "--mesh-scale": "mesh_scale",
    "--mesh-up": "mesh_up_axis",
    "--embed-poses": "embed_poses",
    "--groups": "groups",
    "--rig": "rig",
    "--views": "views",
    "--view-step-deg": "view_step_rad",
    "--floor": "floor",
    "--lidar-kind": "lidar_kind",
    "--fragments": "fragments",
}
_C = SynthConfig


def _resolution(text: str | None) -> tuple[int | None, int | None]:
    if text is None:
        return None, None
    w, h = _parse_pair(text, "x", "WIDTHxHEIGHT such as 2048x1024", "--resolution")
    if w != int(w) or h != int(h):
        raise ConfigError(f"--resolution: width and height must be integers, got {text!r}")
    return int(w), int(h)


def _option_values(
    resolution: str | None,
    noise_mm: float | None,
    fmt: str | None,
    distance_m: str | None,
    max_tilt_deg: float | None,
    size_m: str | None,
    mesh_up: str | None,
    view_step_deg: str | None = None,
    lidar_kind: str | None = None,
) -> dict[str, Any]:
    """The options given in other units or spellings than their fields, as field values."""
    width, height = _resolution(resolution)
    if max_tilt_deg is not None and not math.isfinite(max_tilt_deg):
        raise ConfigError(f"--max-tilt-deg must be a number, got {max_tilt_deg}")
    distance = None
    if distance_m is not None:
        distance = _parse_pair(distance_m, ",", "MIN,MAX metres such as 2,10", "--distance-m")
    step = None
    if view_step_deg is not None:
        lo, hi = _parse_pair(
            view_step_deg, ",", "MIN,MAX degrees such as 30,120", "--view-step-deg"
        )
        step = (math.radians(lo), math.radians(hi))
    return {
        "view_step_rad": step,
        "lidar_kind": None if lidar_kind is None else lidar_kind.lower(),
        "width": width,
        "height": height,
        "noise_m": None if noise_mm is None else noise_mm / 1000.0,
        "format": None if fmt is None else fmt.lower().lstrip("."),
        "distance_range_m": distance,
        "max_tilt_rad": None if max_tilt_deg is None else math.radians(max_tilt_deg),
        "size_m": None
        if size_m is None
        else _parse_pair(size_m, "x", "XxY metres such as 12x9", "--size-m"),
        "mesh_up_axis": None if mesh_up is None else mesh_up.lower(),
    }


_OutOption = Annotated[Path, typer.Option("--out", help="Output folder.")]
_SceneOption = Annotated[
    str | None,
    typer.Option(
        "--scene",
        help=(
            "Scene kind: room, courtyard, hall; the ambiguous symmetric-room, tunnel, bays, "
            "or their variants with one asymmetric cue (symmetric-room-cue, tunnel-cue, "
            "bays-cue); a multi-station project sized by --stations: building (rooms, "
            "corridors, doorways), warehouse (identical rack bays), street (with a side "
            "street); object (a procedural object of about 0.3 m for --views); or a mesh file "
            "to scan (with --views: an object scanned all round). [default: room]"
        ),
    ),
]
_StationsOption = Annotated[
    int | None,
    typer.Option(
        "--stations",
        help="Number of TLS stations; 0: none (only with --rgbd-frames, --lidar-frames or "
        "--fragments). [default: 2; with --views none]",
    ),
]
_ResolutionOption = Annotated[
    str | None,
    typer.Option(
        "--resolution", help="Station grid WIDTHxHEIGHT (azimuth x polar). [default: 2048x1024]"
    ),
]
_NoiseMmOption = Annotated[
    float | None,
    typer.Option(
        "--noise-mm",
        help="Range noise sigma (constant part) of the stations, mm; with --views the depth "
        "noise sigma of the views. [default: 3; with --views 0.1]",
    ),
]
_SeedOption = Annotated[
    int | None,
    typer.Option(
        "--seed", help=with_default(_C, "seed", "Random seed; the same seed gives identical files.")
    ),
]
_FmtOption = Annotated[
    str | None,
    typer.Option(
        "--format", help=with_default(_C, "format", "Station file format: ptx, e57 or npz.")
    ),
]
_RgbdFramesOption = Annotated[
    int | None,
    typer.Option(
        "--rgbd-frames",
        help=with_default(_C, "rgbd_frames", "Frames of a TUM-style RGB-D sequence."),
    ),
]
_LidarFramesOption = Annotated[
    int | None,
    typer.Option(
        "--lidar-frames",
        help=with_default(
            _C, "lidar_frames", "Lidar frames along a path (the sensor: --lidar-kind)."
        ),
    ),
]
_LidarKindOption = Annotated[
    str | None,
    typer.Option(
        "--lidar-kind",
        help=with_default(
            _C,
            "lidar_kind",
            "Sensor of --lidar-frames: spinning (64 x 1024 sweeps in the --format of the "
            "stations) or rosette (a Livox-style narrow-field lidar, 70.4 x 77.2 deg, 24000 "
            "points per 0.1 s frame, as PCD; --set rosette.KEY=VALUE changes it).",
        ),
    ),
]
_ViewsOption = Annotated[
    int | None,
    typer.Option(
        "--views",
        help="Object views instead of stations: pinhole depth scans (640 x 480, depth PNG + "
        "camera sidecar) on a ring around the object of --scene object or a mesh file, each "
        "looking at its centre. [default: 0; --scene object: 6]",
    ),
]
_ViewStepDegOption = Annotated[
    str | None,
    typer.Option(
        "--view-step-deg",
        help="MIN,MAX azimuth between neighbouring object views, degrees (each drawn from "
        "it). [default: 30,120]",
    ),
]
_FloorOption = Annotated[
    bool | None,
    typer.Option(
        "--floor/--no-floor",
        help="Object views: a floor under the object (by default it floats in the air). "
        "[default: no-floor]",
    ),
]
_FragmentsOption = Annotated[
    int | None,
    typer.Option(
        "--fragments",
        help=with_default(
            _C,
            "fragments",
            "3DMatch-style fragments: depth frames of a hand-held camera fused into PLY "
            "clouds (1 cm voxels), consecutive ones overlapping 30-70 %; --set "
            "fragment.frames=N, fragment.voxel_m, fragment.overlap change them.",
        ),
    ),
]
_MinOverlapOption = Annotated[
    float | None,
    typer.Option(
        "--min-overlap",
        help=with_default(
            _C,
            "min_overlap",
            "Minimal mutual overlap (0..1) of a station with its neighbour.",
        ),
    ),
]
_DistanceMOption = Annotated[
    str | None,
    typer.Option(
        "--distance-m",
        help="MIN,MAX distance between neighbouring stations, metres. [default: 2,10]",
    ),
]
_MaxTiltDegOption = Annotated[
    float | None, typer.Option("--max-tilt-deg", help="Maximal station tilt, degrees. [default: 3]")
]
_MixedPixelsOption = Annotated[
    bool | None,
    typer.Option(
        "--mixed-pixels/--no-mixed-pixels",
        help=with_default(_C, "mixed_pixels", "Simulate mixed pixels at depth edges."),
    ),
]
_SizeMOption = Annotated[
    str | None,
    typer.Option(
        "--size-m", help="Floor size XxY of a procedural scene, metres (default: random)."
    ),
]
_MeshScaleOption = Annotated[
    float | None,
    typer.Option(
        "--mesh-scale", help=with_default(_C, "mesh_scale", "Scale of a mesh scene to metres.")
    ),
]
_MeshUpOption = Annotated[
    str | None,
    typer.Option(
        "--mesh-up", help=with_default(_C, "mesh_up_axis", "Up axis of a mesh scene: x, y or z.")
    ),
]
_GroupsOption = Annotated[
    int | None,
    typer.Option(
        "--groups",
        help=with_default(
            _C,
            "groups",
            "Project scenes: disconnected sites sharing the stations, too far apart to see "
            "each other (1-4).",
        ),
    ),
]
_EmbedPosesOption = Annotated[
    bool | None,
    typer.Option(
        "--embed-poses/--no-embed-poses",
        help=with_default(
            _C, "embed_poses", "Write true poses into station files (default: identity)."
        ),
    ),
]
_RigOption = Annotated[
    bool | None,
    typer.Option(
        "--rig",
        help="A camera-lidar rig: a camera on the first station looking at its most textured "
        "part (camera.png, camera.json, a rough init.json; the true T_camera_lidar in gt.json, "
        "for pick, calibrate and calibrate --truth). One station unless --stations says more.",
    ),
]


@app.command("synth")
def synth(
    out: _OutOption,
    scene: _SceneOption = None,
    stations: _StationsOption = None,
    resolution: _ResolutionOption = None,
    noise_mm: _NoiseMmOption = None,
    seed: _SeedOption = None,
    fmt: _FmtOption = None,
    rgbd_frames: _RgbdFramesOption = None,
    lidar_frames: _LidarFramesOption = None,
    min_overlap: _MinOverlapOption = None,
    distance_m: _DistanceMOption = None,
    max_tilt_deg: _MaxTiltDegOption = None,
    mixed_pixels: _MixedPixelsOption = None,
    size_m: _SizeMOption = None,
    mesh_scale: _MeshScaleOption = None,
    mesh_up: _MeshUpOption = None,
    embed_poses: _EmbedPosesOption = None,
    groups: _GroupsOption = None,
    rig: _RigOption = None,
    views: _ViewsOption = None,
    view_step_deg: _ViewStepDegOption = None,
    floor: _FloorOption = None,
    lidar_kind: _LidarKindOption = None,
    fragments: _FragmentsOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Simulate TLS stations (and optionally RGB-D / lidar) of a procedural scene.

    Writes scene.ply, one file per station, and gt.json with every station pose
    T_world_scanner and the pairwise T_target_source = inv(T_world_target) @ T_world_source;
    gt.json's configuration reruns it with --config. Project scenes (building, warehouse,
    street) also get each station's group and the overlap of every pair in gt.json. With
    --rig, a camera on the first station: camera.png, camera.json, init.json and the true
    T_camera_lidar in gt.json.

    Data that are not TLS stations, each with its poses and neighbouring pairs in gt.json:
    --views N (--scene object or a mesh file) writes object views instead of stations,
    views/view_NN.png with its camera sidecar; --lidar-frames N --lidar-kind rosette writes
    Livox-style frames, lidar/lidar_NNNNN.pcd; --fragments N writes 3DMatch-style fused
    fragments, fragments/fragment_NNN.ply (--stations 0: no stations beside them).
    """
    from flexreg.synth.dataset import synthesize

    check_out_folder("--out", out)
    converted = _option_values(
        resolution,
        noise_mm,
        fmt,
        distance_m,
        max_tilt_deg,
        size_m,
        mesh_up,
        view_step_deg,
        lidar_kind,
    )
    cfg = build_config(
        SynthConfig,
        config_file,
        sets,
        OPTIONS,
        scene=scene,
        stations=stations,
        seed=seed,
        rgbd_frames=rgbd_frames,
        lidar_frames=lidar_frames,
        min_overlap=min_overlap,
        mixed_pixels=mixed_pixels,
        mesh_scale=mesh_scale,
        embed_poses=embed_poses,
        groups=groups,
        rig=rig,
        views=views,
        floor=floor,
        fragments=fragments,
        **converted,
    )
    t0 = time.perf_counter()
    with progress_bar() as bar:
        tasks: dict[str, object] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total)
            bar.update(tasks[stage], completed=done)  # type: ignore[arg-type]

        res = synthesize(out, cfg, progress=progress)
    _print_summary(res, time.perf_counter() - t0)


def _print_summary(res: SynthResult, seconds: float) -> None:
    import numpy as np
    from rich.table import Table

    sc = res.scene
    x0, y0, x1, y1 = sc.region
    n_obj = sum(sc.objects.values())
    seed = "" if sc.seed is None else f" (seed {sc.seed})"
    where = f", stations within {x1 - x0:.1f} x {y1 - y0:.1f} m" if res.stations else ""
    console.print(f"scene {sc.kind}{seed}: {sc.n_triangles} triangles, {n_obj} objects{where}")
    if res.stations:
        t = Table(title="stations", title_justify="left")
        for c in ("name", "x m", "y m", "z m", "yaw deg", "tilt deg", "points", "sim s"):
            t.add_column(c, justify="left" if c == "name" else "right")
        for s in res.stations:
            T = s.T_world_scanner
            yaw = math.degrees(math.atan2(T[1, 0], T[0, 0]))
            tilt = math.degrees(math.acos(float(np.clip(T[2, 2], -1.0, 1.0))))
            t.add_row(
                s.name,
                f"{T[0, 3]:.2f}",
                f"{T[1, 3]:.2f}",
                f"{T[2, 3]:.2f}",
                f"{yaw:.1f}",
                f"{tilt:.2f}",
                f"{s.n_points}",
                f"{s.seconds:.2f}",
            )
        console.print(t)
    _print_extras(res)
    kinds = any(pr.kind is not None for pr in res.pairs)
    if res.pairs:
        p = Table(
            title="pairs",
            title_justify="left",
            caption="overlap: the smaller of the two shares (defined in gt.json)"
            if kinds
            else "overlap: smaller share of one station's returns the other also sees",
            caption_justify="left",
        )
        for c in ("target", "source", *(("kind",) if kinds else ()), "distance m", "overlap"):
            p.add_column(c, justify="left" if c in ("target", "source", "kind") else "right")
        for pr in res.pairs:
            kind = ((pr.kind or "station"),) if kinds else ()
            p.add_row(pr.target, pr.source, *kind, f"{pr.distance_m:.2f}", f"{pr.overlap:.2f}")
        console.print(p)
    if len(res.stations) > 1 and not any(pr.kind is None for pr in res.pairs):
        err_console.print("no station pair within the distance range and overlap")
    if res.project:
        proj = res.project
        sizes = ", ".join(str(len(g)) for g in proj["groups"])
        console.print(
            f"project: {len(proj['groups'])} group(s) of {sizes} stations; overlap graph at "
            f">= {proj['min_overlap']:g}: {len(proj['components'])} component(s); "
            f"{len(proj['overlaps'])} pairs share a view (all listed in gt.json)"
        )
    if res.rig is not None:
        _print_rig(res)
    console.print(f"wrote {len(res.files)} files to {res.out_dir} in {seconds:.1f} s")


def _print_extras(res: SynthResult) -> None:
    """One line for each of the object views, the lidar frames and the fragments."""
    ex = res.extras
    if "views" in ex:
        v = ex["views"]
        lo, hi = v["step_range_deg"]
        console.print(
            f"views: {len(v['views'])} depth views {v['distance_m']:.3f} m from the object's "
            f"centre (bounding radius {v['object']['radius_m']:.3f} m), {lo:g}-{hi:g} deg "
            f"apart; depth PNGs at {1e6 * v['depth_scale_m_per_unit']:.0f} µm per unit in "
            f"{v['folder']}/",
            markup=False,
        )
    if "lidar" in ex and ex["lidar"].get("kind") == "rosette":
        sensor, frames = ex["lidar"]["sensor"], ex["lidar"]["frames"]
        fx, fy = sensor["fov_deg"]
        console.print(
            f"lidar: {len(frames)} rosette frames of {sensor['points']} shots "
            f"({fx:g} x {fy:g} deg, {sensor['rate_hz']:g} Hz) as PCD in lidar/",
            markup=False,
        )
    if "fragments" in ex:
        f = ex["fragments"]
        lo, hi = f["overlap_range"]
        console.print(
            f"fragments: {len(f['fragments'])} fragments of {f['frames_per_fragment']} depth "
            f"frames, {100 * f['voxel_m']:g} cm voxels, consecutive ones overlapping "
            f"{lo:g}-{hi:g}, as PLY in {f['folder']}/",
            markup=False,
        )


def _print_rig(res: SynthResult) -> None:
    import numpy as np

    rig = res.rig
    assert rig is not None
    T = rig.T_camera_lidar
    c = rig.camera
    hfov = math.degrees(2 * math.atan2(c.width / 2, c.fx))
    console.print(
        f"rig: a {c.width}x{c.height} camera ({hfov:.0f} deg across) "
        f"{100 * np.linalg.norm(T[:3, 3]):.0f} cm from {res.stations[0].name}'s centre; the "
        "true T_camera_lidar in gt.json, a rough guess in init.json",
        markup=False,
    )
