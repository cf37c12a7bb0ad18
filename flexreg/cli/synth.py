"""`flexreg synth`: write a synthetic data set with exact ground truth."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from flexreg.cli._common import console, err_console, progress_bar
from flexreg.cli.app import app

if TYPE_CHECKING:
    from flexreg.synth.dataset import SynthResult


def _parse_pair(text: str, sep: str, what: str, option: str) -> tuple[float, float]:
    from flexreg.errors import ConfigError

    parts = text.lower().replace(" ", "").split(sep)
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"{option}: expected {what}, got {text!r}") from None
    return a, b


@app.command("synth")
def synth(
    scene: str = typer.Option(
        "room", "--scene", help="Scene kind: room, courtyard or hall; or a mesh file to scan."
    ),
    stations: int = typer.Option(2, "--stations", help="Number of TLS stations."),
    resolution: str = typer.Option(
        "2048x1024", "--resolution", help="Station grid WIDTHxHEIGHT (azimuth x polar)."
    ),
    noise_mm: float = typer.Option(
        3.0, "--noise-mm", help="Range noise sigma (constant part), mm."
    ),
    seed: int = typer.Option(0, "--seed", help="Random seed; the same seed gives identical files."),
    out: Path = typer.Option(..., "--out", help="Output folder."),
    fmt: str = typer.Option("ptx", "--format", help="Station file format: ptx, e57 or npz."),
    rgbd_frames: int = typer.Option(
        0, "--rgbd-frames", help="Frames of a TUM-style RGB-D sequence."
    ),
    lidar_frames: int = typer.Option(
        0, "--lidar-frames", help="Sweeps of a spinning lidar (64 x 1024)."
    ),
    min_overlap: float = typer.Option(
        0.5, "--min-overlap", help="Minimal mutual overlap (0..1) of a station with its neighbour."
    ),
    distance_m: str = typer.Option(
        "2,10", "--distance-m", help="MIN,MAX distance between neighbouring stations, metres."
    ),
    max_tilt_deg: float = typer.Option(
        3.0, "--max-tilt-deg", help="Maximal station tilt, degrees."
    ),
    mixed_pixels: bool = typer.Option(
        True, "--mixed-pixels/--no-mixed-pixels", help="Simulate mixed pixels at depth edges."
    ),
    size_m: str | None = typer.Option(
        None, "--size-m", help="Floor size XxY of a procedural scene, metres (default: random)."
    ),
    mesh_scale: float = typer.Option(1.0, "--mesh-scale", help="Scale of a mesh scene to metres."),
    mesh_up: str = typer.Option("z", "--mesh-up", help="Up axis of a mesh scene: x, y or z."),
    embed_poses: bool = typer.Option(
        False, "--embed-poses", help="Write true poses into station files (default: identity)."
    ),
) -> None:
    """Simulate TLS stations (and optionally RGB-D / lidar) of a procedural scene.

    Writes scene.ply, one file per station, and gt.json with every station pose
    T_world_scanner and the pairwise T_target_source = inv(T_world_target) @ T_world_source.
    """
    from flexreg.errors import ConfigError
    from flexreg.synth.dataset import SynthConfig, synthesize

    w, h = _parse_pair(resolution, "x", "WIDTHxHEIGHT such as 2048x1024", "--resolution")
    if w != int(w) or h != int(h):
        raise ConfigError(f"--resolution: width and height must be integers, got {resolution!r}")
    d0, d1 = _parse_pair(distance_m, ",", "MIN,MAX metres such as 2,10", "--distance-m")
    size = (
        None if size_m is None else _parse_pair(size_m, "x", "XxY metres such as 12x9", "--size-m")
    )
    if not math.isfinite(max_tilt_deg):
        raise ConfigError(f"--max-tilt-deg must be a number, got {max_tilt_deg}")
    cfg = SynthConfig(
        scene=scene,
        stations=stations,
        width=int(w),
        height=int(h),
        noise_m=noise_mm / 1000.0,
        seed=seed,
        format=fmt.lower().lstrip("."),
        rgbd_frames=rgbd_frames,
        lidar_frames=lidar_frames,
        min_overlap=min_overlap,
        distance_range_m=(d0, d1),
        max_tilt_rad=math.radians(max_tilt_deg),
        mixed_pixels=mixed_pixels,
        mesh_scale=mesh_scale,
        mesh_up_axis=mesh_up.lower(),
        size_m=size,
        embed_poses=embed_poses,
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
    console.print(
        f"scene {sc.kind}{seed}: {sc.n_triangles} triangles, {n_obj} objects, "
        f"stations within {x1 - x0:.1f} x {y1 - y0:.1f} m"
    )
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
    if res.pairs:
        p = Table(
            title="pairs",
            title_justify="left",
            caption="overlap: smaller share of one station's returns the other also sees",
            caption_justify="left",
        )
        for c in ("target", "source", "distance m", "overlap"):
            p.add_column(c, justify="left" if c in ("target", "source") else "right")
        for pr in res.pairs:
            p.add_row(pr.target, pr.source, f"{pr.distance_m:.2f}", f"{pr.overlap:.2f}")
        console.print(p)
    else:
        err_console.print("no station pair within the distance range and overlap")
    console.print(f"wrote {len(res.files)} files to {res.out_dir} in {seconds:.1f} s")
