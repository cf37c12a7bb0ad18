"""`flexreg evaluate`: ATE and RPE of an estimated trajectory against ground truth (TUM or
KITTI text), as a table, JSON and a figure."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from flexreg.cli._common import console, stage, write_all
from flexreg.cli.app import app
from flexreg.errors import ConfigError, InputError

if TYPE_CHECKING:
    from flexreg.odometry.evaluation import EvaluationResult

FORMATS = ("auto", "tum", "kitti")
CONVENTIONS = ("tools", "paper")


def _check_options(
    *,
    fmt: str,
    delta: float,
    delta_unit: str,
    convention: str,
    max_dt_s: float | None,
    offset_s: float,
    inputs: tuple[Path, Path],
    plot: Path | None,
    json_out: Path | None,
) -> None:
    """Validate everything that does not need the input files, before anything is read."""
    if fmt not in FORMATS:
        raise ConfigError(f"--format: must be one of {', '.join(FORMATS)}, got {fmt!r}")
    from flexreg.odometry.evaluation import check_interval

    check_interval(delta, delta_unit, names=("--delta", "--delta-unit"))
    if convention not in CONVENTIONS:
        raise ConfigError(
            f"--rpe-convention: must be one of {', '.join(CONVENTIONS)}, got {convention!r}"
        )
    if max_dt_s is not None and not (math.isfinite(max_dt_s) and max_dt_s > 0):
        raise ConfigError(f"--max-dt-s: must be a positive number of seconds, got {max_dt_s}")
    if not math.isfinite(offset_s):
        raise ConfigError(f"--offset-s: must be a finite number of seconds, got {offset_s}")
    seen: dict[Path, str] = {p.resolve(): "an input" for p in inputs}
    for option, path, suffix in (("--plot", plot, ".png"), ("--json", json_out, ".json")):
        if path is None:
            continue
        if path.suffix.lower() != suffix:
            raise ConfigError(f"{option}: {path}: must be a {suffix} file")
        if path.is_dir():
            raise ConfigError(f"{option}: {path}: is a folder, not a file")
        key = path.resolve()
        if key in seen:
            raise ConfigError(f"{option}: {path}: is also {seen[key]}")
        seen[key] = option


@app.command("evaluate")
def evaluate_command(
    gt: Path = typer.Option(
        ..., "--gt", help="Ground-truth trajectory: TUM (t tx ty tz qx qy qz qw) or KITTI (3x4)."
    ),
    est: Path = typer.Option(..., "--est", help="Estimated trajectory, same format."),
    fmt: str = typer.Option(
        "auto",
        "--format",
        help="tum, kitti, or auto (by the number of values per line: 8 or 12). KITTI "
        "timestamps are frame indices.",
    ),
    delta: float = typer.Option(
        1.0, "--delta", help="RPE interval, in --delta-unit (a whole number of frames)."
    ),
    delta_unit: str = typer.Option(
        "frames",
        "--delta-unit",
        help="RPE interval unit: frames (default, consecutive poses for --delta 1), seconds "
        "(the TUM tools' unit; use --delta 1 --delta-unit seconds to reproduce evaluate_rpe.py "
        "--fixed_delta) or metres travelled along the estimate.",
    ),
    convention: str = typer.Option(
        "tools",
        "--rpe-convention",
        help="RPE error composition, with A and B the estimated and true motions over the "
        "interval: tools (E = A B^-1, as evaluate_rpe.py computes it) or paper (E = B^-1 A, "
        "eq. 1 of the TUM benchmark paper as printed, as evo computes it).",
    ),
    scale: bool = typer.Option(
        False,
        "--scale",
        help="Also estimate a scale in the ATE alignment (monocular estimates); the RPE uses "
        "the estimate's translations multiplied by it.",
    ),
    max_dt_s: float | None = typer.Option(
        None,
        "--max-dt-s",
        metavar="SECONDS",
        help="Largest time difference of matched poses, seconds. Default: 0.02 s for ATE "
        "(associate.py) and twice the ground truth's median sampling interval for RPE "
        "(evaluate_rpe.py); a value given here applies to both.",
    ),
    offset_s: float = typer.Option(
        0.0, "--offset-s", metavar="SECONDS", help="Time offset added to the estimate, seconds."
    ),
    plot: Path | None = typer.Option(
        None,
        "--plot",
        help="Write a .png: top view of the ground truth and the aligned estimate, and the "
        "errors over time.",
    ),
    json_out: Path | None = typer.Option(
        None,
        "--json",
        help="Write a .json with ate_rmse_m, rpe_trans_rmse_m, rpe_trans_mean_m, "
        "rpe_rot_mean_deg and the other statistics.",
    ),
) -> None:
    """Absolute trajectory error (ATE) and relative pose error (RPE) of EST against GT,
    with the definitions of the TUM RGB-D benchmark tools.

    Nothing is written unless the evaluation succeeds.
    """
    from flexreg._version import __version__
    from flexreg.io.trajectory import detect_format, read_trajectory
    from flexreg.odometry.evaluation import evaluate

    _check_options(
        fmt=fmt,
        delta=delta,
        delta_unit=delta_unit,
        convention=convention,
        max_dt_s=max_dt_s,
        offset_s=offset_s,
        inputs=(gt, est),
        plot=plot,
        json_out=json_out,
    )
    formats = [fmt if fmt != "auto" else detect_format(p) for p in (gt, est)]
    if formats[0] != formats[1]:
        raise InputError(est, f"is a {formats[1]} trajectory but --gt {gt} is {formats[0]}")
    with stage("Reading trajectories"):
        traj_gt = read_trajectory(gt, formats[0])
        traj_est = read_trajectory(est, formats[1])
    with stage("Evaluating"):
        result = evaluate(
            traj_gt,
            traj_est,
            scale=scale,
            delta=delta,
            delta_unit=delta_unit,
            max_dt_s=max_dt_s,
            offset_s=offset_s,
            convention=convention,
        )

    # everything is computed before the first file is written
    writers: list[tuple[Path, Any]] = []
    if plot is not None:
        from flexreg.odometry.evaluation import plot_evaluation

        with stage("Drawing"):
            fig = plot_evaluation(
                result,
                traj_gt,
                traj_est,
                time_unit="frame" if formats[0] == "kitti" else "s",
            )
        writers.append((plot, lambda: _save_figure(plot, fig)))
    if json_out is not None:
        doc = {
            "gt": str(gt),
            "est": str(est),
            "format": formats[0],
            **result.to_dict(),
            "flexreg_version": __version__,
        }
        writers.append((json_out, lambda: _write_json(json_out, doc)))
    write_all(writers)
    _print_table(result, formats[0])
    for path, _ in writers:
        console.print(f"wrote {path}", markup=False, soft_wrap=True)


def _save_figure(path: Path, fig: Any) -> None:
    from flexreg.io import atomic_write

    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    import json

    from flexreg.io import atomic_write

    text = json.dumps(doc, indent=2) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _print_table(result: EvaluationResult, fmt: str) -> None:
    from rich.table import Table
    from rich.text import Text

    from flexreg.odometry.evaluation import interval_label

    a, r = result.ate, result.rpe
    tu = "frames" if fmt == "kitti" else "s"  # KITTI timestamps are frame indices
    keys = ("rmse", "mean", "median", "std", "min", "max")
    t = Table(title="Trajectory error", title_justify="left")
    t.add_column("", style="bold")
    t.add_column(Text("ATE [m]"), justify="right")
    t.add_column(Text("RPE translation [m]"), justify="right")
    t.add_column(Text("RPE rotation [deg]"), justify="right")
    for k in keys:
        t.add_row(
            k,
            f"{getattr(a, f'{k}_m'):.6f}",
            f"{getattr(r, f'trans_{k}_m'):.6f}",
            f"{getattr(r, f'rot_{k}_deg'):.4f}",
        )
    console.print(t)
    align = f"similarity, scale {a.scale:.6g}" if a.with_scale else "rigid, no scale"
    console.print(
        f"ATE: {a.n_associated} of {a.n_est} estimate poses associated with the {a.n_gt} "
        f"ground-truth poses (within {a.max_dt_s:g} {tu}); Horn/Umeyama alignment, {align}",
        markup=False,
    )
    kitti_time = fmt == "kitti" and r.delta_unit == "seconds"  # timestamps are frame indices
    interval = interval_label(r.delta, "frames" if kitti_time else r.delta_unit)
    console.print(
        f"RPE: {r.n_pairs} pose pairs {interval} apart, {r.convention} convention "
        f"(ground truth within {r.max_dt_s:.4g} {tu})",
        markup=False,
    )
