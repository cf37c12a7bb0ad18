"""`flexreg calibrate`: camera image + lidar scan + 2D-3D correspondences -> ``T_camera_lidar``
as JSON (+ overlay PNG, + picking views)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.calibration.config import CalibrationConfig
from flexreg.cli._common import (
    about_pair,
    console,
    err_console,
    exit_for,
    pair_label,
    print_verdict,
    read_input,
    scan_file,
    stage,
    write_all,
)
from flexreg.cli.app import app
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_out_folder,
    check_outputs,
    with_default,
)
from flexreg.errors import ConfigError, InputError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from flexreg.calibration import CalibrationResult
    from flexreg.core.scan import Scan
    from flexreg.io.intrinsics import CameraIntrinsics

#: header and help of the template written with --export-views
PAIRS_TEMPLATE = """\
# flexreg calibrate correspondences: one pair per line.
# u,v     pixel in camera.png (column, row; the cursor position of an image viewer)
# row,col pixel in panorama.png (the cursor's y, x), lifted to the lidar point there
# Alternatively use the header u,v,X,Y,Z with lidar-frame coordinates in metres.
u,v,row,col
"""


#: options that set a field of CalibrationConfig (option -> field)
OPTIONS = {"--seed": "seed", "--threshold-px": "threshold_px"}
_C = CalibrationConfig


def _check_mode(
    *,
    camera: Path | None,
    pinhole: tuple[float, float, float, float] | None,
    distortion: str | None,
    pairs: Path | None,
    out: Path | None,
    overlay: Path | None,
    auto: bool,
    init: Path | None,
    export_views: Path | None,
    kitti_camera: int,
    truth: Path | None,
) -> None:
    """Check that the options make one consistent task, before anything is read."""
    if (camera is None) == (pinhole is None):
        raise ConfigError("give the camera intrinsics with either --camera FILE or --pinhole")
    if distortion is not None and pinhole is None:
        raise ConfigError("--distortion: only with --pinhole (a --camera file holds its own)")
    if pinhole is not None and not all(math.isfinite(x) for x in pinhole):
        raise ConfigError(f"--pinhole: FX FY CX CY must be finite numbers, got {pinhole}")
    if kitti_camera not in (0, 1, 2, 3):
        raise ConfigError(f"--kitti-camera: must be 0, 1, 2 or 3, got {kitti_camera}")
    solving = pairs is not None or auto
    if not solving and export_views is None:
        raise ConfigError("nothing to do: give --pairs and/or --auto (or --export-views DIR)")
    if auto and init is None and pairs is None:
        raise ConfigError("--auto: needs an initial guess (--init) or correspondences (--pairs)")
    if solving and out is None:
        raise ConfigError("--out: required to write the calibration (a .json file)")
    if not solving:
        for option, value in (("--out", out), ("--overlay", overlay), ("--truth", truth)):
            if value is not None:
                raise ConfigError(f"{option}: needs a calibration: give --pairs and/or --auto")


def parse_distortion(text: str | None) -> list[float]:
    if text is None:
        return []
    try:
        values = [float(x) for x in text.replace(" ", "").split(",") if x]
    except ValueError:
        raise ConfigError(f"--distortion: expected comma-separated numbers, got {text!r}") from None
    from flexreg.io.intrinsics import DISTORTION_LENGTHS

    if len(values) not in DISTORTION_LENGTHS or not all(math.isfinite(x) for x in values):
        raise ConfigError(
            f"--distortion: {len(values)} coefficients; OpenCV takes "
            f"{', '.join(str(n) for n in DISTORTION_LENGTHS[1:])} finite numbers "
            "(k1,k2,p1,p2[,k3[,k4,k5,k6...]])"
        )
    return values


def read_image(path: Path) -> NDArray[np.uint8]:
    """An 8-bit camera image as BGR (grey images are expanded)."""
    import cv2
    import numpy as np

    from flexreg.io.depth import check_image_size

    if not path.is_file():
        raise InputError(path, "no such file")
    check_image_size(path)  # a PNG header declaring a huge image is refused before decoding
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, "not a readable image (PNG, JPEG, ...)")
    if img.dtype != np.uint8:
        raise InputError(path, f"camera image must be 8 bit per channel, got {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return np.asarray(img, dtype=np.uint8)


def intrinsics_from_options(
    camera: Path | None,
    pinhole: tuple[float, float, float, float] | None,
    distortion: list[float],
    kitti_camera: int,
    image_path: Path,
    width: int,
    height: int,
) -> CameraIntrinsics:
    import numpy as np

    from flexreg.io.intrinsics import CameraIntrinsics, read_intrinsics

    if camera is not None:
        intr = read_intrinsics(camera, kitti_camera=kitti_camera)
    else:
        assert pinhole is not None
        fx, fy, cx, cy = pinhole
        try:
            intr = CameraIntrinsics(
                np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]),
                np.asarray(distortion, dtype=np.float64),
                width,
                height,
                "--pinhole",
            )
        except InputError as e:
            raise ConfigError(f"--pinhole: {e.problem}") from None
    return intr.for_image(width, height, image=str(image_path))


def _png_writer(path: Path, image: NDArray[np.uint8]) -> Any:
    import cv2

    from flexreg.io import atomic_write

    def write_png(tmp: Path) -> None:
        if not cv2.imwrite(str(tmp), image):
            raise InputError(tmp, "cannot write the PNG file")

    return lambda: atomic_write(path, write_png)


ImageOption = Annotated[Path, typer.Option("--image", help="Camera image (PNG, JPEG, ...).")]
ScanOption = Annotated[
    Path,
    typer.Option("--scan", help="Lidar scan in any readable format (KITTI .bin, .pcd, .ply, ...)."),
]
CameraOption = Annotated[
    Path | None,
    typer.Option(
        "--camera",
        help="Intrinsics: OpenCV/ROS .yaml, .json (K, distortion, width, height; or the PJLab "
        "intrinsic JSON) or a KITTI calib .txt (P2, rectified, no distortion).",
    ),
]
PinholeOption = Annotated[
    tuple[float, float, float, float] | None,
    typer.Option(
        "--pinhole",
        metavar="FX FY CX CY",
        help="Intrinsics as options instead of --camera (pixels; size from the image).",
    ),
]
DistortionOption = Annotated[
    str | None,
    typer.Option(
        "--distortion",
        metavar="K1,K2,P1,P2[,K3...]",
        help="OpenCV distortion coefficients with --pinhole.",
    ),
]
_PairsOption = Annotated[
    Path | None,
    typer.Option(
        "--pairs",
        help="CSV of correspondences with a header: u,v,X,Y,Z (lidar frame, metres) or "
        "u,v,row,col (pixel of the scan's panorama.png, see --export-views).",
    ),
]
_OutOption = Annotated[
    Path | None,
    typer.Option(
        "--out",
        help="Output .json: T_camera_lidar (lidar points into the camera frame), its inverse, "
        "quaternions (xyzw and wxyz), reprojection RMSE, inliers, per-pair residuals.",
    ),
]
_OverlayOption = Annotated[
    Path | None,
    typer.Option(
        "--overlay", help="Write a .png of the lidar points projected, coloured by range."
    ),
]
_AutoOption = Annotated[
    bool,
    typer.Option(
        "--auto",
        help="Propose correspondences automatically (Flexion view vs. camera edges) around the "
        "initial guess; --pairs, if given, join them.",
    ),
]
InitOption = Annotated[
    Path | None,
    typer.Option(
        "--init",
        help="Initial T_camera_lidar: .json (a calibrate output, a 4x4 list, the PJLab "
        "extrinsic JSON), KITTI calib .txt, or 4x4 text.",
    ),
]
_ExportViewsOption = Annotated[
    Path | None,
    typer.Option(
        "--export-views",
        metavar="DIR",
        help="Write picking aids to DIR: camera.png and panorama.png with pixel grids, "
        "flexion-view.png (with --init) and pairs-template.csv.",
    ),
]
SeedOption = Annotated[
    int | None,
    typer.Option(
        "--seed", help=with_default(_C, "seed", "RANSAC seed; the same seed gives the same result.")
    ),
]
ThresholdPxOption = Annotated[
    float | None,
    typer.Option(
        "--threshold-px",
        help=with_default(
            _C, "threshold_px", "RANSAC inlier threshold on the reprojection error, pixels."
        ),
    ),
]
KittiCameraOption = Annotated[
    int,
    typer.Option("--kitti-camera", help="Camera of a KITTI calib file (2: left colour, image_2)."),
]
_TruthOption = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        help="Known T_camera_lidar (same formats as --init): report the errors in degrees and "
        "metres and store them in the output JSON.",
    ),
]


@app.command("calibrate")
def calibrate_command(
    image: ImageOption,
    scan: ScanOption,
    camera: CameraOption = None,
    pinhole: PinholeOption = None,
    distortion: DistortionOption = None,
    pairs: _PairsOption = None,
    out: _OutOption = None,
    overlay: _OverlayOption = None,
    auto: _AutoOption = False,
    init: InitOption = None,
    export_views: _ExportViewsOption = None,
    seed: SeedOption = None,
    threshold_px: ThresholdPxOption = None,
    kitti_camera: KittiCameraOption = 2,
    truth: _TruthOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Camera-lidar extrinsic calibration: write T_camera_lidar (maps lidar points into the
    camera frame).

    Correspondences come from --pairs and/or --auto; nothing is written unless everything
    succeeds. Pairs whose pixel lies outside the image, or whose lidar point lies behind the
    camera (of --init, or of the solution), are left out with a warning naming their lines;
    fewer than 6 usable pairs is an error.

    \b
    Exit status:
      0  written, and the correspondences determine the pose well (confident)
      3  written, but uncertain: near-degenerate pairs (few inliers, points on one plane or
         near one line, pixels in one small region, weak axes); the reasons are on screen
         and in the output JSON under "verdict"
      1  failed (also: lidar points on one line, which leave the pose undetermined): one
         error line, nothing written
    """
    from flexreg.calibration import calibrate, overlay_image, read_correspondences
    from flexreg.io.intrinsics import read_extrinsic

    config = build_config(
        CalibrationConfig, config_file, sets, OPTIONS, seed=seed, threshold_px=threshold_px
    )
    _check_mode(
        camera=camera,
        pinhole=pinhole,
        distortion=distortion,
        pairs=pairs,
        out=out,
        overlay=overlay,
        auto=auto,
        init=init,
        export_views=export_views,
        kitti_camera=kitti_camera,
        truth=truth,
    )
    inputs = [
        p
        for p in (image, camera, scan_file(scan), pairs, init, truth, config_file)
        if p is not None
    ]
    check_outputs([("--out", out, ".json"), ("--overlay", overlay, ".png")], inputs=inputs)
    check_out_folder("--export-views", export_views)
    dist = parse_distortion(distortion)

    with stage(f"Reading {image.name}"):
        img = read_image(image)
    H, W = img.shape[:2]
    intr = intrinsics_from_options(camera, pinhole, dist, kitti_camera, image, W, H)
    T_init = None if init is None else read_extrinsic(init, kitti_camera=kitti_camera)
    T_true = None if truth is None else read_extrinsic(truth, kitti_camera=kitti_camera)
    with stage(f"Reading {scan.name}"):
        (lidar,) = read_input(scan)
    corr = None
    if pairs is not None:
        with stage(f"Reading {pairs.name}"):
            corr = read_correspondences(pairs, scan=lidar)

    result = None
    if pairs is not None or auto:
        with (
            stage("Solving PnP" + (" with automatic proposals" if auto else "")),
            about_pair(image, scan),
        ):
            result = calibrate(
                img, lidar, intr, pairs=corr, T_init=T_init, auto=auto, config=config
            )

    # everything is computed before the first file is written
    writers: list[tuple[Path, Any]] = []
    if export_views is not None:
        writers += _view_writers(export_views, img, lidar, intr, T_init)
    errors = None
    if result is not None:
        assert out is not None
        errors = None if T_true is None else _errors(result.T_camera_lidar, T_true)
        inputs_meta = {
            "image": str(image),
            "camera": str(camera) if camera is not None else "--pinhole",
            "scan": str(scan),
            "pairs_file": None if pairs is None else str(pairs),
            "init": None if init is None else str(init),
        }
        if overlay is not None:
            with stage("Drawing overlay"):
                picture = overlay_image(
                    img, lidar.points, intr, result.T_camera_lidar, result=result
                )
            writers.append((overlay, _png_writer(overlay, picture)))
        writers.append((out, _result_writer(out, result, inputs_meta, truth, errors)))
    write_all(writers)
    _report(result, (image, scan), errors, pairs, writers, out, overlay)


def _report(
    result: CalibrationResult | None,
    files: tuple[Path, Path],
    errors: Any,
    pairs: Path | None,
    writers: list[tuple[Path, Any]],
    out: Path | None,
    overlay: Path | None,
) -> None:
    """What ``calibrate`` tells once everything is written, and its exit status."""
    if result is not None and result.dropped:
        _print_dropped(result, pairs)
    if result is not None:
        _print_summary(result, errors, files)
        print_verdict(result.verdict)
    for path, _ in writers:
        console.print(f"wrote {path}", markup=False, soft_wrap=True)
    if result is not None and out is not None:
        look = f"; check {overlay}" if overlay is not None else "; --overlay overlay.png shows it"
        exit_for(result.verdict, out, extra=look)


def _view_writers(
    folder: Path, img: NDArray[np.uint8], lidar: Scan, intr: CameraIntrinsics, T_init: Any
) -> list[tuple[Path, Any]]:
    """The picking aids of --export-views: PNG views and the pairs template."""
    from flexreg.calibration import picking_views

    with stage("Drawing picking views"):
        views = picking_views(img, lidar, intrinsics=intr, T_init=T_init)
    writers = []
    for name, picture in views.items():
        path = folder / f"{name}.png"
        writers.append((path, _png_writer(path, picture)))
    template = folder / "pairs-template.csv"
    writers.append((template, _text_writer(template, PAIRS_TEMPLATE)))
    return writers


def _result_writer(
    out: Path,
    result: CalibrationResult,
    inputs: dict[str, Any],
    truth: Path | None,
    errors: dict[str, float] | None,
) -> Any:
    """Write the calibration JSON: inputs, result (with its configuration), errors vs truth."""
    from flexreg._version import __version__
    from flexreg.io import write_transform_json

    meta = result.to_dict()
    T = meta.pop("T_camera_lidar")
    meta = {**inputs, **meta, "flexreg_version": __version__}
    if errors is not None:
        meta["error_vs_truth"] = {"truth": str(truth), **errors}
    return lambda: write_transform_json(out, T, key="T_camera_lidar", **meta)


def _text_writer(path: Path, text: str) -> Any:
    from flexreg.io import atomic_write

    return lambda: atomic_write(path, lambda tmp: tmp.write_text(text))


def _errors(T: NDArray[np.float64], T_true: NDArray[np.float64]) -> dict[str, float]:
    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    return {
        "rotation_deg": rotation_error_deg(T, T_true),
        "translation_m": translation_error_m(T, T_true),
    }


def _print_dropped(result: CalibrationResult, pairs: Path | None) -> None:
    """One warning line naming the given pairs left out (line numbers and reasons)."""
    from flexreg.calibration.types import describe_dropped

    d = result.dropped
    src = f"{pairs}: " if pairs is not None else ""
    err_console.print(
        f"warning: {src}left out {len(d)} pair(s): {describe_dropped(d)}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )


def _print_summary(
    result: CalibrationResult, errors: dict[str, float] | None, files: tuple[Path, Path]
) -> None:
    import numpy as np
    from rich.table import Table

    r = result
    label = pair_label(files[0], files[1], "camera", "lidar")
    t = Table(title=f"T_camera_lidar: {label}", show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column()
    n = len(r.correspondences)
    share = 100.0 * r.inliers / n if n else 0.0
    t.add_row("method", "automatic proposals" if r.method == "auto" else "given correspondences")
    t.add_row("inliers", f"{r.inliers} of {n} ({share:.1f} %) within {r.threshold_px:g} px")
    t.add_row("reprojection RMSE", f"{r.reprojection_rmse_px:.3f} px (inliers)")
    tx, ty, tz = r.translation_m
    t.add_row("translation", f"[{tx:.4f}, {ty:.4f}, {tz:.4f}] m (lidar origin in the camera frame)")
    q = r.quaternion_xyzw
    t.add_row("quaternion xyzw", f"[{q[0]:.6f}, {q[1]:.6f}, {q[2]:.6f}, {q[3]:.6f}]")
    if r.auto is not None:
        s0 = r.auto["edge_score_init"]
        before = "none" if s0 is None else f"{s0:.3f}"
        t.add_row(
            "edge score",
            f"{before} (initial guess) -> {r.auto['edge_score_final']:.3f} "
            f"({len(r.auto['rounds'])} rounds)",
        )
    if errors is not None:
        t.add_row(
            "error vs truth",
            f"{errors['rotation_deg']:.4f}°, {1000 * errors['translation_m']:.1f} mm",
        )
    console.print(t)
    with np.printoptions(precision=6, suppress=True):
        console.print(str(r.T_camera_lidar), markup=False)
