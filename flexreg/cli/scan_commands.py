"""`flexreg info` and `flexreg project`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from flexreg.cli._common import about_file, console, read_input, scan_file, stage
from flexreg.cli.app import app

PinholeOpt = typer.Option(
    None,
    "--pinhole",
    help="Depth PNG intrinsics FX FY CX CY in pixels (size from the image).",
    metavar="FX FY CX CY",
)
EquirectOpt = typer.Option(
    None,
    "--equirect",
    help="Range PNG polar range THETA_MIN THETA_MAX in radians (azimuth: 360°).",
    metavar="THETA_MIN THETA_MAX",
)
DepthKindOpt = typer.Option(
    None, "--depth-kind", help="Depth PNG values: z (orthographic) or range."
)
DepthScaleOpt = typer.Option(None, "--depth-scale", help="Depth PNG metres per stored unit.")


@app.command("info")
def info(
    scan: Path = typer.Argument(
        ...,
        help="Scan file (PTX, E57, PLY, PCD, LAS/LAZ, KITTI .bin, 3DTK .3d, npy/npz, depth "
        "PNG): every setup it holds, or FILE#N / FILE#NAME for one.",
    ),
    pinhole: tuple[float, float, float, float] | None = PinholeOpt,
    equirect: tuple[float, float] | None = EquirectOpt,
    depth_kind: str | None = DepthKindOpt,
    depth_scale: float | None = DepthScaleOpt,
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    detail: bool = typer.Option(
        False,
        "--detail",
        help="A file with several setups: the full table of each (without it, one line per "
        "setup; FILE#N shows one setup in full).",
    ),
    origin: tuple[float, float, float] | None = typer.Option(
        None,
        "--origin",
        metavar="X Y Z",
        help="Where the scanner stood, in the file's frame, metres: describe a cloud in "
        "project or map coordinates as seen from there.",
    ),
) -> None:
    """Describe a scan file: format, points, grid, field of view, ranges, pose.

    A file with several setups (E57, PTX) is listed one line per setup: name, points, grid
    and whether the file stores its pose; FILE#N or --detail shows the full table."""
    import json

    from flexreg.io.info import render_scan_summary, render_setup_list, scan_summary
    from flexreg.io.selector import parse_scan_ref

    with stage(f"Reading {scan.name}"):
        scans = read_input(
            scan,
            pinhole=pinhole,
            equirect=equirect,
            depth_kind=depth_kind,
            depth_scale=depth_scale,
            all_scans=True,
            origin=origin,
            origin_option=None if origin is None else "--origin",
        )
    ref = parse_scan_ref(scan)
    summaries = [scan_summary(s) for s in scans]
    for i, s in enumerate(summaries):  # how to name each setup on the command line
        s["setup"] = str(scan) if ref.selector is not None else f"{ref.path}#{i}"
    if as_json:
        console.print_json(json.dumps(summaries))
        return
    if len(summaries) > 1 and not detail:
        console.print(
            f"{ref.path}: {len(summaries)} setups ({summaries[0]['format']}); "
            f"details: flexreg info {ref.path}#N, or --detail for all",
            markup=False,
            soft_wrap=True,
        )
        console.print(render_setup_list(summaries))
        return
    for s in summaries:
        if len(summaries) > 1:
            console.print(f"setup {s['setup']}", markup=False, soft_wrap=True)
        console.print(render_scan_summary(s))


def check_resolution_deg(resolution_deg: float | None) -> None:
    """``--resolution-deg``: a finite pixel pitch in (0, 360] degrees."""
    import math

    from flexreg.errors import InputError

    if resolution_deg is not None and not (
        math.isfinite(resolution_deg) and 0 < resolution_deg <= 360
    ):
        raise InputError("--resolution-deg", f"must be in (0, 360] degrees, got {resolution_deg}")


def _with_index(scan: Path, index: int | None) -> Path:
    """``project --index N``: the scan reference ``FILE#N`` (refused when ``scan`` already
    names a setup)."""
    if index is None:
        return scan
    from flexreg.errors import InputError
    from flexreg.io.selector import parse_scan_ref

    if parse_scan_ref(scan).selector is not None:
        raise InputError("--index", f"{scan} already names a setup; give it one way")
    if index < 0:
        raise InputError("--index", f"must be 0 or more, got {index}")
    return Path(f"{scan}#{index}")


@app.command("project")
def project(
    scan: Path = typer.Argument(
        ..., help="Scan file (any readable format); FILE#N or FILE#NAME for one setup."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output 16-bit range PNG (a float32 .npz is written beside it)."
    ),
    index: int | None = typer.Option(
        None,
        "--index",
        help="Which setup of a multi-setup file (PTX, E57), from 0; same as SCAN#N.",
    ),
    resample: bool = typer.Option(
        False, "--resample", help="Z-buffer project even if the scan has a native grid."
    ),
    resolution_deg: float | None = typer.Option(
        None,
        "--resolution-deg",
        help="Pixel pitch in degrees of the automatic equirectangular image.",
    ),
    scale: float | None = typer.Option(
        None,
        "--png-scale",
        help="Metres per PNG unit (default: the finest of 0.1, 0.2, 0.5, 1, 2 ... mm that fits).",
    ),
    pinhole: tuple[float, float, float, float] | None = PinholeOpt,
    equirect: tuple[float, float] | None = EquirectOpt,
    depth_kind: str | None = DepthKindOpt,
    depth_scale: float | None = DepthScaleOpt,
    origin: tuple[float, float, float] | None = typer.Option(
        None,
        "--origin",
        metavar="X Y Z",
        help="Where the scanner stood, in the file's frame, metres: for clouds in project or "
        "map coordinates.",
    ),
) -> None:
    """Make a range image of a scan: 16-bit PNG + float32 npz + camera sidecar JSON.

    A scanner's native grid (PTX, E57, organised PCD) keeps its pixels when an equirectangular
    or pinhole camera fits it; otherwise, and with --resample, the points are projected through
    a fitted equirectangular camera. Either way the camera sidecar is written, so the PNG reads
    back as a scan."""
    from flexreg.cli.options import check_outputs
    from flexreg.errors import InputError
    from flexreg.io.files import all_or_nothing
    from flexreg.io.info import write_range_image
    from flexreg.io.safety import written_files

    if out.suffix.lower() != ".png":
        raise InputError(out, "output must be a .png file")
    check_outputs(
        [("--out", out, ".png")],
        inputs=(scan_file(scan),),
        companions={"--out": written_files(out, range_image=True)[1:]},
    )
    check_resolution_deg(resolution_deg)
    scan = _with_index(scan, index)
    with stage(f"Reading {scan.name}"):
        (s,) = read_input(
            scan,
            pinhole=pinhole,
            equirect=equirect,
            depth_kind=depth_kind,
            depth_scale=depth_scale,
            origin=origin,
            origin_option="--origin",
        )
    with stage("Building range image"), about_file(scan):
        img, note = _build_image(s, scan, resample, resolution_deg)
    with stage(f"Writing {out.name}"), all_or_nothing():
        written = write_range_image(out, img, png_scale_m=scale)
    console.print(
        f"{img.height} x {img.width} range image, {img.n_valid:,} valid pixels "
        f"({100 * img.n_valid / max(1, img.height * img.width):.1f} %), "
        f"{written['png_scale_m'] * 1000:g} mm per PNG unit"
    )
    if note:
        console.print(note, markup=False, soft_wrap=True)
    for p in written["files"]:
        console.print(f"wrote {p}", markup=False, soft_wrap=True)


def _build_image(
    s: Any, scan: Path, resample: bool, resolution_deg: float | None
) -> tuple[Any, str]:
    """The range image ``project`` writes, always with a camera model (so with a camera
    sidecar), and a note on how its camera was found: a native grid keeps its pixels when an
    equirectangular or pinhole camera fits it (:func:`flexreg.stages.grid_camera.grid_with_camera`),
    else the points are projected through a fitted equirectangular camera (as ``--resample``)."""
    import math

    from flexreg.core.budget import check_memory
    from flexreg.core.scan import GRID_CELL_BYTES
    from flexreg.errors import InputError
    from flexreg.stages.grid_camera import grid_with_camera
    from flexreg.stages.projection import auto_spherical_camera, range_image
    from flexreg.stages.projection import project as zproject

    note = ""
    if s.has_grid and not resample:
        img, fit_px = grid_with_camera(range_image(s))
        if img.camera is not None:
            kind = "equirectangular" if hasattr(img.camera, "phi_min") else "pinhole"
            return img, (
                f"camera sidecar: {kind} camera fitted to the scanner's grid, 95 % of its "
                f"points within {fit_px:.2g} px of their own pixel"
            )
        off = "none fits" if math.isinf(fit_px) else f"the best is {fit_px:.2f} px off"
        note = (
            f"the grid of {scan} is not a regular equirectangular or pinhole grid (camera "
            f"models: {off}): resampled through a fitted equirectangular camera, as --resample"
        )
    if len(s) == 0:
        raise InputError(scan, "scan has no points")
    res = None if resolution_deg is None else math.radians(resolution_deg)
    cam = (
        s.camera
        if (s.camera is not None and res is None)
        else auto_spherical_camera(s.points, angular_resolution_rad=res)
    )
    if resolution_deg is not None:
        check_memory(
            cam.height * cam.width * GRID_CELL_BYTES,
            f"a {cam.height} x {cam.width} image at {resolution_deg}° per pixel",
            source="--resolution-deg",
        )
    return zproject(s, cam), note
