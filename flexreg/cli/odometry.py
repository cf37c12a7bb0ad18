"""`flexreg odometry`: frame-to-frame odometry on a depth sequence -> TUM trajectory."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.cli._common import (
    EXIT_UNCERTAIN,
    console,
    err_console,
    progress_bar,
    stage,
    write_all,
)
from flexreg.cli.app import app
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_outputs,
    with_default,
)
from flexreg.errors import ConfigError, InputError
from flexreg.odometry.config import EvaluationConfig, OdometryConfig

if TYPE_CHECKING:
    from flexreg.io.sequence import Sequence
    from flexreg.odometry.evaluation import EvaluationResult
    from flexreg.odometry.result import OdometryResult


#: options that set a field of OdometryConfig (option -> field)
OPTIONS = {
    "--image": "image",
    "--n": "n",
    "--median": "median",
    "--features": "features",
    "--method": "method",
    "--ratio": "ratio",
    "--ransac-px": "ransac_threshold_px",
    "--threshold": "threshold_m",
    "--min-inliers": "min_inliers",
    "--seed": "seed",
}
#: options that set a field of the summary's EvaluationConfig
EVALUATION_OPTIONS = {"--delta": "delta", "--delta-unit": "delta_unit"}
_C = OdometryConfig


def _check_reading(
    sequence: Path,
    max_frames: int | None,
    intrinsics: tuple[float, float, float, float] | None,
    depth_scale: float | None,
    rate_hz: float | None,
) -> None:
    """The sequence-reading options (not part of the configuration), before anything is read."""
    if max_frames is not None and max_frames < 2:
        raise ConfigError(f"--max-frames: odometry needs at least 2 frames, got {max_frames}")
    if intrinsics is not None:
        if not all(math.isfinite(v) for v in intrinsics) or min(intrinsics[:2]) <= 0:
            raise ConfigError(
                f"--intrinsics: FX FY must be positive and all four finite, got {intrinsics}"
            )
    if depth_scale is not None and not (math.isfinite(depth_scale) and depth_scale > 0):
        raise ConfigError(
            f"--depth-scale: must be a positive number of metres per unit, got {depth_scale}"
        )
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(f"--rate-hz: must be a positive frame rate, got {rate_hz}")
    if not sequence.exists():
        raise InputError(sequence, "no such folder")
    if not sequence.is_dir():
        raise InputError(
            sequence, "a sequence is a folder (TUM RGB-D, 7-Scenes, depth PNGs, scans)"
        )


_SequenceArgument = Annotated[
    Path,
    typer.Argument(
        metavar="SEQUENCE",
        help="Sequence folder: TUM RGB-D (rgb.txt, depth.txt, groundtruth.txt), 7-Scenes "
        "(frame-XXXXXX.depth.png + pose.txt), depth PNGs + intrinsics, or scan files. The "
        "output folder of 'flexreg synth --rgbd-frames N' works too.",
    ),
]
_OutOption = Annotated[
    Path,
    typer.Option("--out", help="Output trajectory (TUM: t tx ty tz qx qy qz qw, T_world_camera)."),
]
_ImageOption = Annotated[
    str | None,
    typer.Option(
        "--image",
        help=with_default(
            _C,
            "image",
            "Feature image: flexion, flexion-normalized, flexion-angle, bearing-horizontal, "
            "bearing-vertical, bearing-diagonal, bearing-antidiagonal, or color (the "
            "sequence's colour images).",
        ),
    ),
]
_NOption = Annotated[
    int | None,
    typer.Option(
        "--n", help=with_default(_C, "n", "Odd grid size n of Flexion n x n (and Bearing Angle).")
    ),
]
_MedianOption = Annotated[
    int | None,
    typer.Option(
        "--median", help=with_default(_C, "median", "Median pre-filter window: 0 (off), 3 or 5.")
    ),
]
_FeaturesOption = Annotated[
    str | None,
    typer.Option(
        "--features",
        help=with_default(
            _C, "features", "Detector/descriptor: akaze, orb, sift, kaze, brisk, surf."
        ),
    ),
]
_MethodOption = Annotated[
    str | None,
    typer.Option(
        "--method",
        help=with_default(
            _C,
            "method",
            "essential: the paper's 2D-2D method (essential matrix by RANSAC, recoverPose, "
            "metric scale from depth); svd: matches lifted to 3D, RANSAC + SVD.",
        ),
    ),
]
_RatioOption = Annotated[
    float | None,
    typer.Option("--ratio", help=with_default(_C, "ratio", "Lowe's ratio-test threshold.")),
]
_RansacPxOption = Annotated[
    float | None,
    typer.Option(
        "--ransac-px",
        metavar="PIXELS",
        help=with_default(_C, "ransac_threshold_px", "Essential-matrix RANSAC threshold, pixels."),
    ),
]
_ThresholdOption = Annotated[
    float | None,
    typer.Option(
        "--threshold",
        metavar="METRES",
        help="SVD RANSAC inlier distance, metres (default 1.5 % of the median range, >= 1 cm).",
    ),
]
_MinInliersOption = Annotated[
    int | None,
    typer.Option(
        "--min-inliers",
        help=with_default(_C, "min_inliers", "Fewer inliers make a frame pair count as failed."),
    ),
]
_SeedOption = Annotated[
    int | None,
    typer.Option(
        "--seed", help=with_default(_C, "seed", "Random seed; the same seed gives the same output.")
    ),
]
_MaxFramesOption = Annotated[
    int | None, typer.Option("--max-frames", help="Use only the first frames of the sequence.")
]
_IntrinsicsOption = Annotated[
    tuple[float, float, float, float] | None,
    typer.Option(
        "--intrinsics",
        metavar="FX FY CX CY",
        help="Pinhole intrinsics of the depth images, pixels (default: from the folder).",
    ),
]
_DepthScaleOption = Annotated[
    float | None,
    typer.Option(
        "--depth-scale",
        metavar="METRES_PER_UNIT",
        help="Depth PNG scale (default: TUM 1/5000, 7-Scenes 1/1000, camera.json's, or 1/1000).",
    ),
]
_RateHzOption = Annotated[
    float | None,
    typer.Option(
        "--rate-hz", help="Frame rate where the layout has no timestamps (default 30 Hz)."
    ),
]
_DeltaOption = Annotated[
    float | None,
    typer.Option(
        "--delta",
        help=with_default(
            EvaluationConfig, "delta", "RPE interval of the summary, in --delta-unit."
        ),
    ),
]
_DeltaUnitOption = Annotated[
    str | None,
    typer.Option(
        "--delta-unit",
        help=with_default(
            EvaluationConfig, "delta_unit", "RPE interval unit: frames, seconds or metres."
        ),
    ),
]
_JsonOutOption = Annotated[
    Path | None,
    typer.Option(
        "--json",
        help="Also write a .json: per-frame status, every frame pair tried (matches, inliers, "
        "why it failed), bridged frames, timings, configuration and ATE/RPE.",
    ),
]


@app.command("odometry")
def odometry_command(
    sequence: _SequenceArgument,
    out: _OutOption,
    image: _ImageOption = None,
    n: _NOption = None,
    median: _MedianOption = None,
    features: _FeaturesOption = None,
    method: _MethodOption = None,
    ratio: _RatioOption = None,
    ransac_px: _RansacPxOption = None,
    threshold: _ThresholdOption = None,
    min_inliers: _MinInliersOption = None,
    seed: _SeedOption = None,
    max_frames: _MaxFramesOption = None,
    intrinsics: _IntrinsicsOption = None,
    depth_scale: _DepthScaleOption = None,
    rate_hz: _RateHzOption = None,
    delta: _DeltaOption = None,
    delta_unit: _DeltaUnitOption = None,
    json_out: _JsonOutOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Frame-to-frame odometry through feature images; write the trajectory (TUM format).

    A frame pair that cannot be solved is reported and bridged (matched against the last good
    frame, else constant velocity). Nothing is written unless the run succeeds.

    \b
    Exit status:
      0  written; every motion measured, or at most 10 % of the frames bridged (a closing
         warning names them)
      3  written, but more than 10 % of the frames were bridged: the trajectory is
         unreliable there (warning on screen, "run_status": "unreliable" in --json)
      1  failed: one error line, nothing written
    """
    from flexreg.io.sequence import read_sequence
    from flexreg.odometry.track import odometry

    config = build_config(
        OdometryConfig,
        config_file,
        sets,
        OPTIONS,
        image=image,
        n=n,
        median=median,
        features=features,
        method=method,
        ratio=ratio,
        ransac_threshold_px=ransac_px,
        threshold_m=threshold,
        min_inliers=min_inliers,
        seed=seed,
    )
    summary = build_config(
        EvaluationConfig, None, (), EVALUATION_OPTIONS, delta=delta, delta_unit=delta_unit
    )
    _check_reading(sequence, max_frames, intrinsics, depth_scale, rate_hz)
    outputs = [("--out", out, None), ("--json", json_out, ".json")]
    check_outputs(outputs, input_folders=(sequence,))
    with stage(f"Reading {sequence.name}"):
        seq = read_sequence(
            sequence,
            intrinsics=intrinsics,
            depth_scale=depth_scale,
            rate_hz=rate_hz,
            max_frames=max_frames,
        )
    t0 = time.perf_counter()
    with progress_bar() as bar:
        task = bar.add_task(f"{config.image} / {config.features} / {config.method}", total=len(seq))

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done)

        result = odometry(seq, config, progress=progress)
    seconds = time.perf_counter() - t0
    evaluation, note = _evaluate(seq, result, summary.delta, summary.delta_unit)
    warning = bridged_warning(result.n_frames - 1, len(result.failures))
    writers = _writers(seq, result, seconds, evaluation, out, json_out, warning)
    write_all(writers)
    _print_summary(seq, result, seconds, evaluation, note)
    for path, _ in writers:
        console.print(f"wrote {path}", markup=False, soft_wrap=True)
    if warning is not None:
        err_console.print(f"warning: {warning[0]}", markup=False, highlight=False, soft_wrap=True)
        if warning[1]:
            raise typer.Exit(EXIT_UNCERTAIN)


#: above this share of bridged frames the run exits 3 (written but unreliable)
BRIDGED_EXIT_SHARE = 0.10


def bridged_warning(motions: int, bridged: int) -> tuple[str, bool] | None:
    """The closing warning of a run with bridged frames, and whether it exits 3.

    Any bridged frame is warned about: its pose is extrapolated (constant velocity or the last
    good frame), not measured. The run exits 3 when more than :data:`BRIDGED_EXIT_SHARE` of the
    motions were bridged.

    >>> text, exit_3 = bridged_warning(19, 17)
    >>> text.split(":")[0], exit_3
    ('17 of 19 frames bridged', True)
    >>> bridged_warning(59, 0) is None, bridged_warning(59, 5)[1], bridged_warning(59, 6)[1]
    (True, False, True)
    """
    if bridged <= 0:
        return None
    over = bridged > BRIDGED_EXIT_SHARE * motions
    text = (
        f"{bridged} of {motions} frames bridged: the trajectory is unreliable there (poses "
        "extrapolated, not measured)"
    )
    if over:
        text += f"; more than {100 * BRIDGED_EXIT_SHARE:g} % bridged: exit status 3"
    return text, over


def _writers(
    seq: Sequence,
    result: OdometryResult,
    seconds: float,
    evaluation: EvaluationResult | None,
    out: Path,
    json_out: Path | None,
    warning: tuple[str, bool] | None = None,
) -> list[tuple[Path, Any]]:
    """The trajectory and, with --json, the run's report (written all or none)."""
    from flexreg._version import __version__
    from flexreg.core.jsonable import to_jsonable
    from flexreg.io import atomic_write
    from flexreg.io.trajectory import write_trajectory

    writers: list[tuple[Path, Any]] = [
        (out, lambda: write_trajectory(out, result.trajectory, "tum"))
    ]
    if json_out is not None:
        doc: dict[str, Any] = {
            "sequence": seq.to_dict(),
            **result.to_dict(),
            "seconds": seconds,
            "evaluation": None if evaluation is None else evaluation.to_dict(),
            "run_status": "unreliable" if warning is not None and warning[1] else "done",
            "warning": None if warning is None else warning[0],
            "flexreg_version": __version__,
        }
        text = json.dumps(to_jsonable(doc), indent=2) + "\n"
        writers.append((json_out, lambda: atomic_write(json_out, lambda tmp: tmp.write_text(text))))
    return writers


def _evaluate(
    seq: Sequence, result: OdometryResult, delta: float, delta_unit: str
) -> tuple[EvaluationResult | None, str]:
    """ATE/RPE against the sequence's ground truth, or None and why not."""
    from flexreg.errors import FlexregError
    from flexreg.odometry.evaluation import evaluate

    if seq.groundtruth is None:
        return None, "no ground truth in the sequence"
    try:
        return evaluate(seq.groundtruth, result.trajectory, delta=delta, delta_unit=delta_unit), ""
    except FlexregError as e:
        return None, f"not evaluated: {e}"


def _print_summary(
    seq: Sequence,
    result: OdometryResult,
    seconds: float,
    evaluation: EvaluationResult | None,
    note: str,
) -> None:
    from rich.table import Table

    from flexreg.odometry.evaluation import interval_label

    c = result.config
    t = Table(title="odometry", show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column()
    t.add_row(
        "sequence", f"{seq.kind}, {len(seq)} frames, {seq.timestamps[-1] - seq.timestamps[0]:.2f} s"
    )
    t.add_row(
        "method",
        f"{c.method} on {c.image}"
        + (f" {c.n}x{c.n}" if c.image.startswith("flexion") else "")
        + f" with {c.features}",
    )
    ok = [a for a in result.attempts if a.ok]
    med_inl = sorted(a.inliers for a in ok)[len(ok) // 2] if ok else 0
    t.add_row(
        "frames",
        f"{result.n_estimated} of {result.n_frames - 1} motions measured "
        f"(median {med_inl} inliers)",
    )
    t.add_row(
        "failed pairs", f"{len(result.failed_pairs)}; {len(result.failures)} frame(s) bridged"
    )
    t.add_row("path length", f"{result.trajectory.path_length_m:.3f} m")
    t.add_row("time", f"{seconds:.1f} s ({seconds / max(1, result.n_frames):.3f} s per frame)")
    if evaluation is not None:
        a, r = evaluation.ate, evaluation.rpe
        t.add_row(
            "ATE",
            f"rmse {a.rmse_m:.4f} m, mean {a.mean_m:.4f} m, max {a.max_m:.4f} m "
            f"({a.n_associated} poses)",
        )
        t.add_row(
            f"RPE ({interval_label(r.delta, r.delta_unit)})",
            f"translation rmse {r.trans_rmse_m:.4f} m, mean {r.trans_mean_m:.4f} m; rotation "
            f"mean {r.rot_mean_deg:.3f}°",
        )
    else:
        t.add_row("ATE / RPE", note)
    console.print(t)
    for f in result.failures[:10]:
        err_console.print(
            f"frame {f.frame}: not solved against frame(s) {', '.join(map(str, f.tried))} "
            f"({'; '.join(f.reasons)}); bridged by {f.bridge}",
            markup=False,
            highlight=False,
        )
    if len(result.failures) > 10:
        err_console.print(f"... and {len(result.failures) - 10} more bridged frames (see --json)")
