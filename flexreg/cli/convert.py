"""`flexreg convert`: a scan or depth image -> Flexion / Bearing Angle / range PNG.

:class:`ConvertConfig` (the conversion settings) lives here, beside its only user: conversion
has no application package of its own (the command calls the stage functions
:func:`~flexreg.stages.feature_images.convert` and ``quantize`` directly), and everything this
module imports at start-up (``flexreg.stages.feature_images`` for :data:`KINDS`, the
registration's median windows) is imported by the command line anyway, so ``flexreg --help``
does not get slower.
"""

from __future__ import annotations

import typing
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from flexreg.cli._common import (
    about_file,
    console,
    err_console,
    progress_bar,
    read_input,
    scan_file,
)
from flexreg.cli.app import app
from flexreg.cli.config_cmd import add_config
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_out_folder,
    check_outputs,
    with_default,
)
from flexreg.config import Config, OddSize, one_of, parse_sets
from flexreg.errors import ConfigError, FlexregError, InputError
from flexreg.io.safety import written_files
from flexreg.registration.config import MEDIANS
from flexreg.stages.feature_images import KINDS, Stretch

if TYPE_CHECKING:
    from flexreg.core.range_image import RangeImage

#: contrast stretches of ``quantize``, and "none"
STRETCHES: tuple[str, ...] = ("none", *typing.get_args(Stretch))
#: output bit depths of ``quantize``
BITS: tuple[int, ...] = (8, 16)


class ConvertConfig(Config):
    """Settings of ``flexreg convert`` (``flexreg config show convert``); the input's camera
    model (``--pinhole``, ``--equirect``, ``--depth-kind``, ``--depth-scale``) belongs to the
    input file, not here.

    Attributes
    ----------
    kind : str
        Conversion, one of :data:`flexreg.stages.feature_images.KINDS`; required (no default).
    n : int
        Odd grid size n of Flexion n x n (neighbours at (n - 1) / 2).
    median : {0, 3, 5}
        Median pre-filter window (0: off).
    bits : {8, 16}
        Output bit depth.
    stretch : {"none", "percentile", "clahe"}
        Contrast stretch of the quantised image (for feature detection).
    """

    kind: Annotated[str, one_of(KINDS, "kind")]
    n: OddSize = 3
    median: Annotated[int, one_of(MEDIANS)] = 0
    bits: Annotated[int, one_of(BITS)] = 8
    stretch: Annotated[str, one_of(STRETCHES)] = "none"


def _shown_config() -> ConvertConfig:
    """What ``flexreg config show convert`` prints: the defaults, with ``kind`` (which has no
    default) set to flexion so the file is ready to use."""
    return ConvertConfig(kind="flexion")


add_config("convert", _shown_config)
#: options that set a field of ConvertConfig (option -> field)
OPTIONS = {
    "--kind": "kind",
    "--n": "n",
    "--median": "median",
    "--bits": "bits",
    "--stretch": "stretch",
}
_C = ConvertConfig


def _check_camera(
    pinhole: tuple[float, float, float, float] | None,
    equirect: tuple[float, float] | None,
    depth_kind: str | None,
    depth_scale: float | None,
) -> None:
    """The camera-model options of the input, checked before anything is read."""
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


def _check_out(
    out: Path, input: Path, folder: bool, keep_float: bool, config_file: Path | None
) -> None:
    """``--out`` is a folder when INPUT is one, else a .png file that is neither the input nor
    one of its companion files (nor its ``.npz`` with ``--keep-float``)."""
    if folder:
        check_out_folder("--out", out, (input,))
        return
    if out.suffix.lower() != ".png":
        raise ConfigError(f"--out: {out}: output must be a .png file")
    check_outputs(
        [("--out", out, None)],
        inputs=(scan_file(input),),
        extra_inputs=[("--config", config_file)],
        companions={"--out": written_files(out, keep_float=keep_float)[1:]},
    )


def load_range_image(
    path: Path,
    *,
    pinhole: tuple[float, float, float, float] | None = None,
    equirect: tuple[float, float] | None = None,
    depth_kind: str | None = None,
    depth_scale: float | None = None,
    origin: tuple[float, float, float] | None = None,
) -> RangeImage:
    """Range image of the scan (one setup) of any ``read_scan`` input (depth PNGs: intrinsics
    from the options or the ``<stem>.camera.json`` sidecar; clouds in project coordinates:
    the scanner position ``origin``)."""
    from flexreg.stages.projection import range_image

    (scan,) = read_input(
        path,
        pinhole=pinhole,
        equirect=equirect,
        depth_kind=depth_kind,
        depth_scale=depth_scale,
        origin=origin,
        origin_option="--origin",
    )
    with about_file(path):
        return range_image(scan)


def _convert_one(
    src: Path,
    dst: Path,
    config: ConvertConfig,
    *,
    keep_float: bool,
    camera_options: dict[str, object],
) -> tuple[int, int, float]:
    """Convert one input file; write ``dst`` (and ``dst.npz``) only once all is computed."""
    import json

    import cv2
    import numpy as np

    from flexreg.io import atomic_write
    from flexreg.io.files import discard
    from flexreg.stages.feature_images import convert, quantize, value_range

    if not scan_file(src).is_file():
        raise InputError(scan_file(src), "no such file")
    rimg = load_range_image(src, **camera_options)  # type: ignore[arg-type]
    kind = config.kind
    image = convert(rimg, kind, n=config.n, median=config.median)
    q, valid = quantize(
        image,
        config.bits,
        value_range=value_range(kind, image),
        stretch=None if config.stretch == "none" else config.stretch,  # type: ignore[arg-type]
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
                n=np.int64(config.n),
                median=np.int64(config.median),
                wraps=np.bool_(rimg.wraps),
                config=np.array(json.dumps(config.to_dict())),
            )

    try:
        if keep_float:
            atomic_write(dst.with_suffix(".npz"), write_npz)
        atomic_write(dst, write_png)
    except OSError as e:
        discard(dst.with_suffix(".npz"), dst)
        raise InputError(dst, f"cannot write: {e.strerror or e}") from e
    except BaseException:
        discard(dst.with_suffix(".npz"), dst)  # a folder's other images are still written
        raise
    H, W = image.shape
    return W, H, float(valid.mean()) if valid.size else 0.0


def _inputs(folder: Path) -> list[Path]:
    from flexreg.io import FORMATS

    return sorted(
        p
        for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in FORMATS
    )


_InputArgument = Annotated[
    Path,
    typer.Argument(metavar="INPUT", help="Scan file, 16-bit depth/range PNG, or a folder of them."),
]
_KindOption = Annotated[
    str | None,
    typer.Option(
        "--kind",
        help=f"Conversion (required here, in --config or as --set kind=...): {', '.join(KINDS)}.",
    ),
]
_OutOption = Annotated[
    Path, typer.Option("--out", help="Output .png (a folder when INPUT is a folder).")
]
_NOption = Annotated[
    int | None,
    typer.Option(
        "--n",
        help=with_default(_C, "n", "Odd grid size n of Flexion n x n (neighbours at (n-1)/2)."),
    ),
]
_MedianOption = Annotated[
    int | None,
    typer.Option(
        "--median", help=with_default(_C, "median", "Median pre-filter window: 0 (off), 3 or 5.")
    ),
]
_BitsOption = Annotated[
    int | None, typer.Option("--bits", help=with_default(_C, "bits", "Output bit depth: 8 or 16."))
]
_PinholeOption = Annotated[
    tuple[float, float, float, float] | None,
    typer.Option(
        "--pinhole", metavar="FX FY CX CY", help="Pinhole intrinsics of a depth PNG (pixels)."
    ),
]
_EquirectOption = Annotated[
    tuple[float, float] | None,
    typer.Option(
        "--equirect",
        metavar="THETA_MIN THETA_MAX",
        help="Polar range of a full-turn equirectangular range PNG (radians).",
    ),
]
_DepthKindOption = Annotated[
    str | None,
    typer.Option(
        "--depth-kind", help="z or range (default: z for --pinhole, range for --equirect)."
    ),
]
_DepthScaleOption = Annotated[
    float | None,
    typer.Option("--depth-scale", help="Metres per PNG unit (default 1, or the camera sidecar's)."),
]
_StretchOption = Annotated[
    str | None,
    typer.Option(
        "--stretch",
        help=with_default(
            _C, "stretch", "Contrast stretch for feature detection: none, percentile, clahe."
        ),
    ),
]
_KeepFloatOption = Annotated[
    bool,
    typer.Option(
        "--keep-float",
        help="Also write the float32 image as .npz (with the configuration used, as JSON).",
    ),
]
_OriginOption = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--origin",
        metavar="X Y Z",
        help="Where the scanner stood, in the file's frame, metres: for clouds in project or "
        "map coordinates.",
    ),
]


@app.command("convert")
def convert_command(
    input: _InputArgument,
    out: _OutOption,
    kind: _KindOption = None,
    n: _NOption = None,
    median: _MedianOption = None,
    bits: _BitsOption = None,
    pinhole: _PinholeOption = None,
    equirect: _EquirectOption = None,
    depth_kind: _DepthKindOption = None,
    depth_scale: _DepthScaleOption = None,
    stretch: _StretchOption = None,
    keep_float: _KeepFloatOption = False,
    origin: _OriginOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Convert a scan or depth image into a Flexion, Bearing Angle or range image.

    Nothing is written for an input that fails; a folder's other files are still converted.
    """
    if kind is None and config_file is None and "kind" not in parse_sets(sets or ()):
        raise ConfigError("--kind: required (or kind in --config FILE, or --set kind=...)")
    config = build_config(
        ConvertConfig,
        config_file,
        sets,
        OPTIONS,
        kind=kind,
        n=n,
        median=median,
        bits=bits,
        stretch=stretch,
    )
    _check_camera(pinhole, equirect, depth_kind, depth_scale)
    folder = input.is_dir()
    _check_out(out, input, folder, keep_float, config_file)
    camera_options: dict[str, object] = dict(
        pinhole=pinhole,
        equirect=equirect,
        depth_kind=depth_kind,
        depth_scale=depth_scale,
        origin=origin,
    )
    options = dict(keep_float=keep_float, camera_options=camera_options)
    if not folder:
        if not scan_file(input).exists():
            raise InputError(scan_file(input), "no such file or folder")
        W, H, frac = _convert_one(input, out, config, **options)  # type: ignore[arg-type]
        console.print(
            f"wrote {out} ({config.kind}, {W}x{H}, {100 * frac:.1f}% valid)", markup=False
        )
        return

    files = _inputs(input)
    if not files:
        raise InputError(input, "folder holds no scan or depth image")
    failed = 0
    with progress_bar() as progress:
        task = progress.add_task(f"convert {config.kind}", total=len(files))
        for src in files:
            dst = out / f"{src.stem}.png"
            try:
                _convert_one(src, dst, config, **options)  # type: ignore[arg-type]
            except FlexregError as e:
                failed += 1
                own = isinstance(e, InputError) and e.source == str(src)
                msg = str(e) if own else f"{src}: {e}"
                err_console.print(f"error: {msg}", markup=False, highlight=False, soft_wrap=True)
            progress.advance(task)
    console.print(f"wrote {len(files) - failed} of {len(files)} images to {out}", markup=False)
    if failed:
        raise typer.Exit(1)
