"""`flexreg odometry`: frame-to-frame odometry on a depth sequence -> TUM trajectory."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from flexreg.cli._common import console, err_console, progress_bar, stage
from flexreg.cli.app import app
from flexreg.errors import ConfigError, InputError

if TYPE_CHECKING:
    from flexreg.io.sequence import Sequence
    from flexreg.odometry.evaluation import EvaluationResult
    from flexreg.odometry.track import OdometryResult


def _check_options(
    *,
    image: str,
    n: int,
    median: int,
    features: str,
    method: str,
    ratio: float,
    threshold: float | None,
    ransac_px: float,
    min_inliers: int,
    seed: int,
    max_frames: int | None,
    intrinsics: tuple[float, float, float, float] | None,
    depth_scale: float | None,
    rate_hz: float | None,
    delta: float,
    delta_unit: str,
    sequence: Path,
    out: Path,
    json_out: Path | None,
) -> None:
    """Validate everything that does not need the sequence, before anything is read."""
    from flexreg.odometry.track import IMAGES, METHODS
    from flexreg.stages.keypoints import METHODS as FEATURES

    if image not in IMAGES:
        raise ConfigError(f"--image: unknown feature image {image!r}; known: {', '.join(IMAGES)}")
    if n < 3 or n % 2 == 0:
        raise ConfigError(f"--n: must be an odd grid size 3, 5, 7, ..., got {n}")
    if median not in (0, 3, 5):
        raise ConfigError(f"--median: must be 0 (off), 3 or 5, got {median}")
    if features not in FEATURES:
        raise ConfigError(f"--features: unknown method {features!r}; known: {', '.join(FEATURES)}")
    if method not in METHODS:
        raise ConfigError(f"--method: must be one of {', '.join(METHODS)}, got {method!r}")
    if not (math.isfinite(ratio) and 0 < ratio <= 1):
        raise ConfigError(f"--ratio: must be in (0, 1], got {ratio}")
    if threshold is not None and not (math.isfinite(threshold) and threshold > 0):
        raise ConfigError(f"--threshold: must be a positive number of metres, got {threshold}")
    if not (math.isfinite(ransac_px) and ransac_px > 0):
        raise ConfigError(f"--ransac-px: must be a positive number of pixels, got {ransac_px}")
    if min_inliers < 5:
        raise ConfigError(f"--min-inliers: must be at least 5, got {min_inliers}")
    if seed < 0:
        raise ConfigError(f"--seed: must be a non-negative integer, got {seed}")
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
    from flexreg.odometry.evaluation import check_interval

    check_interval(delta, delta_unit, names=("--delta", "--delta-unit"))
    if not sequence.exists():
        raise InputError(sequence, "no such folder")
    if not sequence.is_dir():
        raise InputError(
            sequence, "a sequence is a folder (TUM RGB-D, 7-Scenes, depth PNGs, scans)"
        )
    seen: dict[Path, str] = {}
    for option, path, suffix in (("--out", out, None), ("--json", json_out, ".json")):
        if path is None:
            continue
        if suffix is not None and path.suffix.lower() != suffix:
            raise ConfigError(f"{option}: {path}: must be a {suffix} file")
        if path.is_dir():
            raise ConfigError(f"{option}: {path}: is a folder, not a file")
        key = path.resolve()
        if key in seen:
            raise ConfigError(f"{option}: {path}: is also {seen[key]}")
        if sequence.resolve() in key.parents and path.exists():
            raise ConfigError(f"{option}: {path}: would overwrite a file of the sequence")
        seen[key] = option


@app.command("odometry")
def odometry_command(
    sequence: Path = typer.Argument(
        ...,
        metavar="SEQUENCE",
        help="Sequence folder: TUM RGB-D (rgb.txt, depth.txt, groundtruth.txt), 7-Scenes "
        "(frame-XXXXXX.depth.png + pose.txt), depth PNGs + intrinsics, or scan files. The "
        "output folder of 'flexreg synth --rgbd-frames N' works too.",
    ),
    out: Path = typer.Option(
        ..., "--out", help="Output trajectory (TUM: t tx ty tz qx qy qz qw, T_world_camera)."
    ),
    image: str = typer.Option(
        "flexion",
        "--image",
        help="Feature image: flexion, flexion-normalized, flexion-angle, bearing-horizontal, "
        "bearing-vertical, bearing-diagonal, bearing-antidiagonal, or color (the sequence's "
        "colour images).",
    ),
    n: int = typer.Option(5, "--n", help="Odd grid size n of Flexion n x n (and Bearing Angle)."),
    median: int = typer.Option(3, "--median", help="Median pre-filter window: 0 (off), 3 or 5."),
    features: str = typer.Option(
        "orb", "--features", help="Detector/descriptor: akaze, orb, sift, kaze, brisk, surf."
    ),
    method: str = typer.Option(
        "essential",
        "--method",
        help="essential: the paper's 2D-2D method (essential matrix by RANSAC, recoverPose, "
        "metric scale from depth); svd: matches lifted to 3D, RANSAC + SVD.",
    ),
    ratio: float = typer.Option(0.8, "--ratio", help="Lowe's ratio-test threshold."),
    ransac_px: float = typer.Option(
        1.0, "--ransac-px", metavar="PIXELS", help="Essential-matrix RANSAC threshold, pixels."
    ),
    threshold: float | None = typer.Option(
        None,
        "--threshold",
        metavar="METRES",
        help="SVD RANSAC inlier distance, metres (default 1.5 % of the median range, >= 1 cm).",
    ),
    min_inliers: int = typer.Option(
        12, "--min-inliers", help="Fewer inliers make a frame pair count as failed."
    ),
    seed: int = typer.Option(0, "--seed", help="Random seed; the same seed gives the same output."),
    max_frames: int | None = typer.Option(
        None, "--max-frames", help="Use only the first frames of the sequence."
    ),
    intrinsics: tuple[float, float, float, float] | None = typer.Option(
        None,
        "--intrinsics",
        metavar="FX FY CX CY",
        help="Pinhole intrinsics of the depth images, pixels (default: from the folder).",
    ),
    depth_scale: float | None = typer.Option(
        None,
        "--depth-scale",
        metavar="METRES_PER_UNIT",
        help="Depth PNG scale (default: TUM 1/5000, 7-Scenes 1/1000, camera.json's, or 1/1000).",
    ),
    rate_hz: float | None = typer.Option(
        None, "--rate-hz", help="Frame rate where the layout has no timestamps (default 30 Hz)."
    ),
    delta: float = typer.Option(
        1.0, "--delta", help="RPE interval of the summary, in --delta-unit."
    ),
    delta_unit: str = typer.Option(
        "frames", "--delta-unit", help="RPE interval unit: frames, seconds or metres."
    ),
    json_out: Path | None = typer.Option(
        None,
        "--json",
        help="Also write a .json: per-frame status, every frame pair tried (matches, inliers, "
        "why it failed), bridged frames, timings, configuration and ATE/RPE.",
    ),
) -> None:
    """Frame-to-frame odometry through feature images; write the trajectory (TUM format).

    A frame pair that cannot be solved is reported and bridged (matched against the last good
    frame, else constant velocity). Nothing is written unless the run succeeds.
    """
    from flexreg._version import __version__
    from flexreg.io import atomic_write
    from flexreg.io.sequence import read_sequence
    from flexreg.io.trajectory import write_trajectory
    from flexreg.odometry.track import OdometryConfig, odometry

    _check_options(
        image=image,
        n=n,
        median=median,
        features=features,
        method=method,
        ratio=ratio,
        threshold=threshold,
        ransac_px=ransac_px,
        min_inliers=min_inliers,
        seed=seed,
        max_frames=max_frames,
        intrinsics=intrinsics,
        depth_scale=depth_scale,
        rate_hz=rate_hz,
        delta=delta,
        delta_unit=delta_unit,
        sequence=sequence,
        out=out,
        json_out=json_out,
    )
    config = OdometryConfig(
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
        task = bar.add_task(f"{image} / {features} / {method}", total=len(seq))

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done)

        result = odometry(seq, config, progress=progress)
    seconds = time.perf_counter() - t0
    evaluation, note = _evaluate(seq, result, delta, delta_unit)

    # everything is computed before the first file is written
    written = [write_trajectory(out, result.trajectory, "tum")]
    if json_out is not None:
        doc: dict[str, Any] = {
            "sequence": seq.to_dict(),
            **result.to_dict(),
            "seconds": seconds,
            "evaluation": None if evaluation is None else evaluation.to_dict(),
            "flexreg_version": __version__,
        }
        text = json.dumps(doc, indent=2, default=_json_default) + "\n"
        try:
            atomic_write(json_out, lambda tmp: tmp.write_text(text))
        except BaseException:
            out.unlink(missing_ok=True)  # all outputs or none
            raise
        written.append(json_out)
    _print_summary(seq, result, seconds, evaluation, note)
    for p in written:
        console.print(f"wrote {p}", markup=False, soft_wrap=True)


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


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
