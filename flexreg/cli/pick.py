"""`flexreg pick`: pick camera-lidar correspondences in the browser, solved live; save writes the
pairs CSV ``calibrate --pairs`` reads and the calibration JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from flexreg.calibration.config import CalibrationConfig
from flexreg.cli._common import console, err_console, stage
from flexreg.cli.app import app
from flexreg.cli.calibrate import (
    OPTIONS,
    CameraOption,
    DistortionOption,
    ImageOption,
    InitOption,
    KittiCameraOption,
    PinholeOption,
    ScanOption,
    SeedOption,
    ThresholdPxOption,
    intrinsics_from_options,
    parse_distortion,
    read_image,
)
from flexreg.cli.options import ConfigFileOption, SetOption, build_config, check_outputs
from flexreg.errors import ConfigError

_PickPairsOption = Annotated[
    Path | None,
    typer.Option(
        "--pairs",
        help="Start from these pairs (a CSV calibrate --pairs reads: u,v,X,Y,Z or u,v,row,col); "
        "may be the --out file itself.",
    ),
]
_PickOutOption = Annotated[
    Path,
    typer.Option(
        "--out",
        help="Pairs CSV written on Save (u,v,X,Y,Z: the format calibrate --pairs reads). "
        "Nothing is written before.",
    ),
]
_ResultOption = Annotated[
    Path | None,
    typer.Option(
        "--result",
        help="Calibration JSON written on Save once solved (as calibrate --out writes it) "
        "[default: the --out name with -calib.json].",
    ),
]
_PortOption = Annotated[
    int,
    typer.Option("--port", help="Port on 127.0.0.1 (0: a free port).", min=0, max=65535),
]
_NoBrowserOption = Annotated[
    bool,
    typer.Option("--no-browser", help="Only print the page's address; do not open a browser."),
]
_PreviewOption = Annotated[
    int,
    typer.Option(
        "--preview-px",
        help="Longer side of the images shown at first, pixels (full size loads on zoom).",
        min=256,
    ),
]


@app.command("pick")
def pick_command(
    image: ImageOption,
    scan: ScanOption,
    out: _PickOutOption,
    camera: CameraOption = None,
    pinhole: PinholeOption = None,
    distortion: DistortionOption = None,
    init: InitOption = None,
    pairs: _PickPairsOption = None,
    result: _ResultOption = None,
    port: _PortOption = 0,
    no_browser: _NoBrowserOption = False,
    preview_px: _PreviewOption = 2048,
    seed: SeedOption = None,
    threshold_px: ThresholdPxOption = None,
    kitti_camera: KittiCameraOption = 2,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Pick camera-lidar correspondences in the browser and see the calibration live.

    Starts a local web page (127.0.0.1 only; the printed address carries the session's token):
    the camera image beside the lidar scan's panorama (Flexion, range, intensity, or the
    perspective Flexion view from --init). Click a point in one, then its partner in the other;
    from 6 pairs on, every change re-solves with the solver of 'calibrate --pairs'. Save writes
    --out (and --result once solved); nothing is written before. Stop with Ctrl-C.
    """
    from flexreg.calibration import read_correspondences
    from flexreg.io import read_scan
    from flexreg.io.intrinsics import read_extrinsic
    from flexreg.picker.server import PickerServer
    from flexreg.picker.session import PickSession

    config = build_config(
        CalibrationConfig, config_file, sets, OPTIONS, seed=seed, threshold_px=threshold_px
    )
    if (camera is None) == (pinhole is None):
        raise ConfigError("give the camera intrinsics with either --camera FILE or --pinhole")
    if distortion is not None and pinhole is None:
        raise ConfigError("--distortion: only with --pinhole (a --camera file holds its own)")
    result = result if result is not None else out.with_name(out.stem + "-calib.json")
    inputs = [p for p in (image, camera, scan, init) if p is not None]
    check_outputs([("--out", out, ".csv"), ("--result", result, ".json")], inputs=inputs)
    dist = parse_distortion(distortion)

    with stage(f"Reading {image.name}"):
        img = read_image(image)
    H, W = img.shape[:2]
    intr = intrinsics_from_options(camera, pinhole, dist, kitti_camera, image, W, H)
    T_init = None if init is None else read_extrinsic(init, kitti_camera=kitti_camera)
    with stage(f"Reading {scan.name}"):
        lidar = read_scan(scan)
    meta = {
        "image": str(image),
        "camera": str(camera) if camera is not None else "--pinhole",
        "scan": str(scan),
        "init": None if init is None else str(init),
    }
    with stage("Preparing the lidar views"):
        session = PickSession(
            img,
            lidar,
            intr,
            out=out,
            result_out=result,
            T_init=T_init,
            config=config,
            inputs=meta,
            preview_px=preview_px,
        )
        session.views.picture(session.views.modes[0])
    if pairs is not None:
        with stage(f"Reading {pairs.name}"):
            session.load_pairs(read_correspondences(pairs, scan=lidar))
    if pairs is None and out.exists():
        err_console.print(
            f"note: {out} exists; Save will replace it (--pairs {out} continues from it)",
            markup=False,
            soft_wrap=True,
        )
    server = PickerServer(session, port=port)
    console.print(f"flexreg pick: open {server.url}", markup=False, soft_wrap=True)
    console.print("(127.0.0.1 only; Ctrl-C stops; Save in the page writes the files)")
    if not no_browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.run()
    except KeyboardInterrupt:  # Ctrl-C (or SIGTERM): the normal way to stop the server
        pass
    if session.pairs and session.saved_revision != session.revision:
        err_console.print(
            f"warning: the last changes were not saved ({len(session.pairs)} pairs; "
            f"{out} {'holds an older state' if session.saved else 'was not written'})",
            markup=False,
            soft_wrap=True,
        )
