"""`flexreg convert`: a scan or depth image -> Flexion / Bearing Angle / range PNG."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from flexreg.cli._common import console, err_console, progress_bar, read_input
from flexreg.cli.app import app
from flexreg.errors import FlexregError, InputError

if TYPE_CHECKING:
    from flexreg.core.range_image import RangeImage

_KIND_HELP = (
    "flexion, flexion-normalized, flexion-angle, bearing-horizontal, bearing-vertical, "
    "bearing-diagonal, bearing-antidiagonal, range, curvature-gaussian, curvature-mean, "
    "curvature-max."
)


def _check_options(
    kind: str,
    n: int,
    median: int,
    bits: int,
    stretch: str,
    pinhole: tuple[float, float, float, float] | None,
    equirect: tuple[float, float] | None,
    depth_kind: str | None,
    depth_scale: float | None,
    out: Path,
    folder: bool,
) -> None:
    """Validate everything that does not need the input file, before anything is read."""
    from flexreg.stages.feature_images import KINDS

    if kind not in KINDS:
        raise InputError("--kind", f"unknown kind {kind!r}; known: {', '.join(KINDS)}")
    if n < 3 or n % 2 == 0:
        raise InputError("--n", f"must be an odd grid size 3, 5, 7, ... 13, got {n}")
    if median not in (0, 3, 5):
        raise InputError("--median", f"must be 0 (off), 3 or 5, got {median}")
    if bits not in (8, 16):
        raise InputError("--bits", f"must be 8 or 16, got {bits}")
    if stretch not in ("none", "percentile", "clahe"):
        raise InputError("--stretch", f"must be none, percentile or clahe, got {stretch!r}")
    if pinhole is not None and equirect is not None:
        raise InputError("--pinhole/--equirect", "give one camera model, not both")
    if depth_kind not in (None, "z", "range"):
        raise InputError("--depth-kind", f"must be z or range, got {depth_kind!r}")
    if equirect is not None and depth_kind == "z":
        raise InputError("--depth-kind", "an equirectangular image stores range, not z")
    if depth_scale is not None and not depth_scale > 0:
        raise InputError(
            "--depth-scale", f"must be a positive number of metres per unit, got {depth_scale}"
        )
    if folder:
        if out.exists() and not out.is_dir():
            raise InputError(out, "exists and is not a folder (INPUT is a folder)")
    elif out.suffix.lower() != ".png":
        raise InputError(out, "output must be a .png file")


def load_range_image(
    path: Path,
    *,
    pinhole: tuple[float, float, float, float] | None = None,
    equirect: tuple[float, float] | None = None,
    depth_kind: str | None = None,
    depth_scale: float | None = None,
) -> RangeImage:
    """Range image of the first scan of any ``read_scan`` input (depth PNGs: intrinsics from
    the options or the ``<stem>.camera.json`` sidecar)."""
    from flexreg.stages.projection import range_image

    (scan,) = read_input(
        path, pinhole=pinhole, equirect=equirect, depth_kind=depth_kind, depth_scale=depth_scale
    )
    return range_image(scan)


def _convert_one(
    src: Path,
    dst: Path,
    *,
    kind: str,
    n: int,
    median: int,
    bits: int,
    stretch: str,
    keep_float: bool,
    camera_options: dict[str, object],
) -> tuple[int, int, float]:
    """Convert one input file; write ``dst`` (and ``dst.npz``) only once all is computed."""
    import cv2
    import numpy as np

    from flexreg.io import atomic_write
    from flexreg.stages.feature_images import convert, quantize, value_range

    if not src.is_file():
        raise InputError(src, "no such file")
    rimg = load_range_image(src, **camera_options)  # type: ignore[arg-type]
    image = convert(rimg, kind, n=n, median=median)
    q, valid = quantize(
        image,
        bits,
        value_range=value_range(kind, image),
        stretch=None if stretch == "none" else stretch,  # type: ignore[arg-type]
    )

    def write_png(tmp: Path) -> None:
        if not cv2.imwrite(str(tmp), q):
            raise InputError(dst, "cannot write the PNG file")

    def write_npz(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                image=image,
                valid=valid,
                kind=np.array(kind),
                n=np.int64(n),
                median=np.int64(median),
                wraps=np.bool_(rimg.wraps),
            )

    try:
        if keep_float:
            atomic_write(dst.with_suffix(".npz"), write_npz)
        atomic_write(dst, write_png)
    except OSError as e:
        raise InputError(dst, f"cannot write: {e.strerror or e}") from e
    H, W = image.shape
    return W, H, float(valid.mean()) if valid.size else 0.0


def _inputs(folder: Path) -> list[Path]:
    from flexreg.io import FORMATS

    return sorted(
        p
        for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in FORMATS
    )


@app.command("convert")
def convert_command(
    input: Path = typer.Argument(
        ..., metavar="INPUT", help="Scan file, 16-bit depth/range PNG, or a folder of them."
    ),
    kind: str = typer.Option(..., "--kind", help=f"Conversion: {_KIND_HELP}"),
    out: Path = typer.Option(..., "--out", help="Output .png (a folder when INPUT is a folder)."),
    n: int = typer.Option(
        3, "--n", help="Odd grid size n of Flexion n x n (neighbours at (n-1)/2)."
    ),
    median: int = typer.Option(0, "--median", help="Median pre-filter window: 0 (off), 3 or 5."),
    bits: int = typer.Option(8, "--bits", help="Output bit depth: 8 or 16."),
    pinhole: tuple[float, float, float, float] | None = typer.Option(
        None, "--pinhole", metavar="FX FY CX CY", help="Pinhole intrinsics of a depth PNG (pixels)."
    ),
    equirect: tuple[float, float] | None = typer.Option(
        None,
        "--equirect",
        metavar="THETA_MIN THETA_MAX",
        help="Polar range of a full-turn equirectangular range PNG (radians).",
    ),
    depth_kind: str | None = typer.Option(
        None, "--depth-kind", help="z or range (default: z for --pinhole, range for --equirect)."
    ),
    depth_scale: float | None = typer.Option(
        None, "--depth-scale", help="Metres per PNG unit (default 1, or the camera sidecar's)."
    ),
    stretch: str = typer.Option(
        "none", "--stretch", help="Contrast stretch for feature detection: none, percentile, clahe."
    ),
    keep_float: bool = typer.Option(
        False, "--keep-float", help="Also write the float32 image as .npz."
    ),
) -> None:
    """Convert a scan or depth image into a Flexion, Bearing Angle or range image."""
    folder = input.is_dir()
    _check_options(
        kind, n, median, bits, stretch, pinhole, equirect, depth_kind, depth_scale, out, folder
    )
    options = dict(kind=kind, n=n, median=median, bits=bits, stretch=stretch, keep_float=keep_float)
    camera_options: dict[str, object] = dict(
        pinhole=pinhole, equirect=equirect, depth_kind=depth_kind, depth_scale=depth_scale
    )
    if not folder:
        if not input.exists():
            raise InputError(input, "no such file or folder")
        W, H, frac = _convert_one(input, out, camera_options=camera_options, **options)  # type: ignore[arg-type]
        console.print(f"wrote {out} ({kind}, {W}x{H}, {100 * frac:.1f}% valid)", markup=False)
        return

    files = _inputs(input)
    if not files:
        raise InputError(input, "folder holds no scan or depth image")
    failed = 0
    with progress_bar() as progress:
        task = progress.add_task(f"convert {kind}", total=len(files))
        for src in files:
            dst = out / f"{src.stem}.png"
            try:
                _convert_one(src, dst, camera_options=camera_options, **options)  # type: ignore[arg-type]
            except FlexregError as e:
                failed += 1
                own = isinstance(e, InputError) and e.source == str(src)
                msg = str(e) if own else f"{src}: {e}"
                err_console.print(f"error: {msg}", markup=False, highlight=False, soft_wrap=True)
            progress.advance(task)
    console.print(f"wrote {len(files) - failed} of {len(files)} images to {out}", markup=False)
    if failed:
        raise typer.Exit(1)
