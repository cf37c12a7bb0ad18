"""`flexreg evaluate`: ATE and RPE of an estimated trajectory against ground truth (TUM or
KITTI text), as a table, JSON and a figure."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.cli._common import console, stage, write_all
from flexreg.cli.app import app
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_outputs,
    with_default,
)
from flexreg.errors import InputError
from flexreg.odometry.config import EvaluationConfig

if TYPE_CHECKING:
    from flexreg.odometry.evaluation import EvaluationResult

#: options that set a field of EvaluationConfig (option -> field)
OPTIONS = {
    "--format": "format",
    "--delta": "delta",
    "--delta-unit": "delta_unit",
    "--rpe-convention": "convention",
    "--scale": "scale",
    "--max-dt-s": "max_dt_s",
    "--offset-s": "offset_s",
}
_C = EvaluationConfig


_GtOption = Annotated[
    Path,
    typer.Option(
        "--gt", help="Ground-truth trajectory: TUM (t tx ty tz qx qy qz qw) or KITTI (3x4)."
    ),
]
_EstOption = Annotated[Path, typer.Option("--est", help="Estimated trajectory, same format.")]
_FmtOption = Annotated[
    str | None,
    typer.Option(
        "--format",
        help=with_default(
            _C,
            "format",
            "tum, kitti, or auto (by the number of values per line: 8 or 12). KITTI "
            "timestamps are frame indices.",
        ),
    ),
]
_DeltaOption = Annotated[
    float | None,
    typer.Option(
        "--delta",
        help=with_default(_C, "delta", "RPE interval, in --delta-unit (a whole number of frames)."),
    ),
]
_DeltaUnitOption = Annotated[
    str | None,
    typer.Option(
        "--delta-unit",
        help=with_default(
            _C,
            "delta_unit",
            "RPE interval unit: frames (consecutive poses for --delta 1), seconds (the TUM "
            "tools' unit; use --delta 1 --delta-unit seconds to reproduce evaluate_rpe.py "
            "--fixed_delta) or metres travelled along the estimate.",
        ),
    ),
]
_ConventionOption = Annotated[
    str | None,
    typer.Option(
        "--rpe-convention",
        help=with_default(
            _C,
            "convention",
            "RPE error composition, with A and B the estimated and true motions over the "
            "interval: tools (E = A B^-1, as evaluate_rpe.py computes it) or paper (E = B^-1 A, "
            "eq. 1 of the TUM benchmark paper as printed, as evo computes it).",
        ),
    ),
]
_ScaleOption = Annotated[
    bool | None,
    typer.Option(
        "--scale/--no-scale",
        help=with_default(
            _C,
            "scale",
            "Also estimate a scale in the ATE alignment (monocular estimates); the RPE uses "
            "the estimate's translations multiplied by it.",
        ),
    ),
]
_MaxDtSOption = Annotated[
    float | None,
    typer.Option(
        "--max-dt-s",
        metavar="SECONDS",
        help="Largest time difference of matched poses, seconds. Default: 0.02 s for ATE "
        "(associate.py) and twice the ground truth's median sampling interval for RPE "
        "(evaluate_rpe.py); a value given here applies to both.",
    ),
]
_OffsetSOption = Annotated[
    float | None,
    typer.Option(
        "--offset-s",
        metavar="SECONDS",
        help=with_default(_C, "offset_s", "Time offset added to the estimate, seconds."),
    ),
]
_PlotOption = Annotated[
    Path | None,
    typer.Option(
        "--plot",
        help="Write a .png: top view of the ground truth and the aligned estimate, and the "
        "errors over time.",
    ),
]
_JsonOutOption = Annotated[
    Path | None,
    typer.Option(
        "--json",
        help="Write a .json with ate_rmse_m, rpe_trans_rmse_m, rpe_trans_mean_m, "
        "rpe_rot_mean_deg, the other statistics and the configuration.",
    ),
]


@app.command("evaluate")
def evaluate_command(
    gt: _GtOption,
    est: _EstOption,
    fmt: _FmtOption = None,
    delta: _DeltaOption = None,
    delta_unit: _DeltaUnitOption = None,
    convention: _ConventionOption = None,
    scale: _ScaleOption = None,
    max_dt_s: _MaxDtSOption = None,
    offset_s: _OffsetSOption = None,
    plot: _PlotOption = None,
    json_out: _JsonOutOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Absolute trajectory error (ATE) and relative pose error (RPE) of EST against GT,
    with the definitions of the TUM RGB-D benchmark tools.

    Nothing is written unless the evaluation succeeds.
    """
    from flexreg._version import __version__
    from flexreg.io.trajectory import detect_format, read_trajectory
    from flexreg.odometry.evaluation import evaluate

    config = build_config(
        EvaluationConfig,
        config_file,
        sets,
        OPTIONS,
        format=fmt,
        delta=delta,
        delta_unit=delta_unit,
        convention=convention,
        scale=scale,
        max_dt_s=max_dt_s,
        offset_s=offset_s,
    )
    check_outputs([("--plot", plot, ".png"), ("--json", json_out, ".json")], inputs=(gt, est))
    formats = [config.format if config.format != "auto" else detect_format(p) for p in (gt, est)]
    if formats[0] != formats[1]:
        raise InputError(est, f"is a {formats[1]} trajectory but --gt {gt} is {formats[0]}")
    with stage("Reading trajectories"):
        traj_gt = read_trajectory(gt, formats[0])
        traj_est = read_trajectory(est, formats[1])
    with stage("Evaluating"):
        result = evaluate(
            traj_gt,
            traj_est,
            scale=config.scale,
            delta=config.delta,
            delta_unit=config.delta_unit,
            max_dt_s=config.max_dt_s,
            offset_s=config.offset_s,
            convention=config.convention,
        )

    # everything is computed before the first file is written
    writers: list[tuple[Path, Any]] = []
    if plot is not None:
        with stage("Drawing"):
            fig = _figure(result, traj_gt, traj_est, formats[0])
        writers.append((plot, lambda: _save_figure(plot, fig)))
    if json_out is not None:
        doc = {
            "gt": str(gt),
            "est": str(est),
            "format": formats[0],
            **result.to_dict(),
            "config": config.to_dict(),
            "flexreg_version": __version__,
        }
        writers.append((json_out, lambda: _write_json(json_out, doc)))
    write_all(writers)
    _print_table(result, formats[0])
    for path, _ in writers:
        console.print(f"wrote {path}", markup=False, soft_wrap=True)


def _figure(result: EvaluationResult, traj_gt: Any, traj_est: Any, fmt: str) -> Any:
    from flexreg.odometry.plots import plot_evaluation

    time_unit = "frame" if fmt == "kitti" else "s"
    return plot_evaluation(result, traj_gt, traj_est, time_unit=time_unit)


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
