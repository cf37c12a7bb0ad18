"""`flexreg compare` (flexreg and the ICP baselines on one pair) and `flexreg bench` (the
comparison benchmark suites)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from flexreg.bench.config import DEFAULT_METHODS, CompareConfig
from flexreg.cli._common import console, err_console, pair_label, progress_bar, read_pair
from flexreg.cli.app import app
from flexreg.cli.config_cmd import add_config
from flexreg.cli.options import (
    ConfigFileOption,
    SetOption,
    build_config,
    check_out_folder,
    with_default,
)

if TYPE_CHECKING:
    from flexreg.bench.compare import Comparison
    from flexreg.bench.types import BenchResult

add_config("compare", CompareConfig)
#: options that set a field of CompareConfig (option -> field)
OPTIONS = {
    "--methods": "methods",
    "--voxel": "voxel_m",
    "--seed": "seed",
    "--success-deg": "success_deg",
    "--success-m": "success_m",
    "--timeout-s": "timeout_s",
}
_C = CompareConfig


_TargetArgument = Annotated[
    Path,
    typer.Argument(
        metavar="TARGET", help="Target scan (any readable scan file), in its scanner frame."
    ),
]
_SourceArgument = Annotated[
    Path,
    typer.Argument(metavar="SOURCE", help="Source scan, mapped onto TARGET by T_target_source."),
]
_OutOption = Annotated[
    Path,
    typer.Option(
        "--out", help="Output folder (created): comparison.json, comparison.md and comparison.png."
    ),
]
_GtOption = Annotated[
    Path | None,
    typer.Option(
        "--gt",
        help='Known T_target_source: JSON {"T_target_source": [[4x4]]} (a flexreg synth '
        "gt.json works, pair by file stems) or a 4x4 text matrix. Gives errors and success.",
    ),
]
_MethodsOption = Annotated[
    str | None,
    typer.Option(
        "--methods",
        help=with_default(
            _C,
            "methods",
            "Comma-separated: flexreg, icp-point, icp-plane, gicp, fpfh-ransac, kiss-icp "
            "(small-gicp when installed).",
        ),
    ),
]
_InitOption = Annotated[
    Path | None,
    typer.Option(
        "--init",
        help="Initial T_target_source for the local methods (ICP variants, KISS-ICP); "
        "default identity. flexreg and fpfh-ransac need none.",
    ),
]
_VoxelOption = Annotated[
    float | None,
    typer.Option(
        "--voxel",
        metavar="METRES",
        help="Scale voxel of the baselines, metres (default: from the scan resolution).",
    ),
]
_SeedOption = Annotated[
    int | None, typer.Option("--seed", help=with_default(_C, "seed", "Seed of flexreg and RANSAC."))
]
_SuccessDegOption = Annotated[
    float | None,
    typer.Option(
        "--success-deg",
        help=with_default(_C, "success_deg", "Success: rotation error at most this, degrees."),
    ),
]
_SuccessMOption = Annotated[
    float | None,
    typer.Option(
        "--success-m",
        help=with_default(_C, "success_m", "Success: translation error at most this, metres."),
    ),
]
_TimeoutSOption = Annotated[
    float | None,
    typer.Option(
        "--timeout-s",
        help=with_default(_C, "timeout_s", "Time limit per method, seconds (a timeout is a row)."),
    ),
]


@app.command("compare")
def compare_command(
    target: _TargetArgument,
    source: _SourceArgument,
    out: _OutOption,
    gt: _GtOption = None,
    methods: _MethodsOption = None,
    init: _InitOption = None,
    voxel: _VoxelOption = None,
    seed: _SeedOption = None,
    success_deg: _SuccessDegOption = None,
    success_m: _SuccessMOption = None,
    timeout_s: _TimeoutSOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Run flexreg and the ICP baselines on one pair; table, JSON, Markdown and bar chart.

    Every method gets a row: a method that fails, crashes or times out says so. Nothing is
    written unless the comparison completes.
    """
    from flexreg.bench.compare import SuccessCriteria, compare
    from flexreg.bench.methods import parse_methods
    from flexreg.bench.results import write_comparison
    from flexreg.io import read_transform
    from flexreg.io.transform_io import read_ground_truth

    config = build_config(
        CompareConfig,
        config_file,
        sets,
        OPTIONS,
        methods=methods,
        voxel_m=voxel,
        seed=seed,
        success_deg=success_deg,
        success_m=success_m,
        timeout_s=timeout_s,
    )
    chosen = parse_methods(config.methods)
    check_out_folder("--out", out, (target, source))
    criteria = SuccessCriteria(rotation_deg=config.success_deg, translation_m=config.success_m)
    T_gt = None if gt is None else read_ground_truth(gt, target=target.stem, source=source.stem)
    T_init = None if init is None else read_transform(init)
    scans = read_pair(target, source)
    with progress_bar() as bar:
        task = bar.add_task("comparing", total=len(chosen))

        def progress(method: str, i: int, n: int) -> None:
            bar.update(task, completed=i, description=method or "done")

        cmp = compare(
            scans[0],
            scans[1],
            methods=chosen,
            T_gt=T_gt,
            T_init=T_init,
            voxel_m=config.voxel_m,
            seed=config.seed,
            criteria=criteria,
            timeout_s=config.timeout_s,
            names=(str(target), str(source)),
            progress=progress,
        )
    written = write_comparison(cmp, out, config=config)
    _print_comparison(cmp)
    for p in written:
        console.print(f"wrote {p}", markup=False, soft_wrap=True)


#: short console headers of flexreg.bench.compare.COLUMNS
_SHORT = {
    "method": "method",
    "status": "status",
    "rotation error (°)": "rot. err °",
    "translation error (m)": "trans. err m",
    "success": "success",
    "verdict": "verdict",
    "coarse error (° / m)": "coarse ° / m",
    "overlap": "overlap",
    "overlap RMSE (m)": "RMSE m",
    "open3d fitness": "o3d fitness",
    "open3d inlier_rmse (m)": "o3d rmse m",
    "time (s)": "time s",
    "peak memory (MB)": "peak MB",
}


def _print_comparison(cmp: Comparison) -> None:
    from rich.console import Console
    from rich.table import Table

    from flexreg.bench.tables import COLUMNS, notes, table_rows

    t = Table(
        title=f"{pair_label(cmp.target, cmp.source)} (T_target_source: source onto target)",
        title_justify="left",
    )
    for c in COLUMNS:
        left = c in ("method", "status", "success", "verdict")
        t.add_column(_SHORT[c], justify="left" if left else "right", no_wrap=c != "status")
    for row, run in zip(table_rows(cmp), cmp.runs, strict=True):
        cells = dict(row)
        cells["status"] = run.status  # the message follows the table
        t.add_row(*(cells[c] for c in COLUMNS))
    # the table needs about 150 columns: as wide as that even when piped
    wide = console if console.width >= 150 else Console(highlight=False, width=150)
    wide.print(t)
    for run in cmp.runs:
        if not run.ok:
            console.print(f"{run.method} {run.status}: {run.message}", markup=False, soft_wrap=True)
    for line in notes(cmp):
        console.print(f"- {line}", markup=False, highlight=False, soft_wrap=True)


#: options that set a field of BenchConfig (option -> field)
BENCH_OPTIONS = {
    "--suite": "suite",
    "--quick": "quick",
    "--methods": "methods",
    "--seed": "seed",
    "--data": "data_dir",
    "--timeout-s": "timeout_s",
}


_BenchSuiteOption = Annotated[
    str | None, typer.Option("--suite", help="synthetic, real or all. [default: all]")
]
_BenchOutOption = Annotated[
    Path,
    typer.Option("--out", help="Folder that receives the timestamped result folder (created)."),
]
_BenchQuickOption = Annotated[
    bool | None,
    typer.Option(
        "--quick/--full",
        help="Short run (about 2-3 min): 4 small synthetic pairs, a small sweep, 2 real pairs; "
        "its defaults apply unless --config is given. [default: full]",
    ),
]
_BenchMethodsOption = Annotated[
    str | None,
    typer.Option("--methods", help=f"Comma-separated methods. [default: {DEFAULT_METHODS}]"),
]
_BenchSeedOption = Annotated[
    int | None,
    typer.Option("--seed", help="Seed of the synthetic pairs and the methods. [default: 0]"),
]
_BenchDataOption = Annotated[
    Path | None,
    typer.Option("--data", help="Folder of the real data sets. [default: ../shared/data]"),
]
_BenchTimeoutSOption = Annotated[
    float | None,
    typer.Option(
        "--timeout-s", help="Time limit per method and pair, seconds (default 300; 120 quick)."
    ),
]


@app.command("bench")
def bench_command(
    out: _BenchOutOption,
    suite: _BenchSuiteOption = None,
    quick: _BenchQuickOption = None,
    methods: _BenchMethodsOption = None,
    seed: _BenchSeedOption = None,
    data: _BenchDataOption = None,
    timeout_s: _BenchTimeoutSOption = None,
    config_file: ConfigFileOption = None,
    sets: SetOption = None,
) -> None:
    """Benchmark flexreg against the baselines: synthetic pairs over station distance, yaw,
    tilt, noise and resolution, and the real pairs with a reference.

    Writes cases.csv, summary.csv / .md, results.json, config.json and plots into
    OUT/bench-<time>/ once everything has run; --config OUT/bench-<time>/config.json reruns
    it.
    """
    from flexreg.bench.methods import parse_methods
    from flexreg.bench.results import write_bench
    from flexreg.bench.suite import check_real_data, planned_cases, run_bench
    from flexreg.bench.types import BenchConfig

    base = BenchConfig.make(quick=bool(quick))  # --suite is set below, with its name
    config = build_config(
        BenchConfig,
        config_file,
        sets,
        BENCH_OPTIONS,
        base=base,
        suite=suite,
        quick=quick,
        methods=None if methods is None else tuple(parse_methods(methods)),
        seed=seed,
        data_dir=None if data is None else str(data),
        timeout_s=timeout_s,
    )
    check_out_folder("--out", out)
    if config.runs_real:
        check_real_data(config.data_dir, config.real_pairs)
    n_cases = len(planned_cases(config))
    with progress_bar() as bar:
        task = bar.add_task("bench", total=n_cases)

        def progress(label: str, k: int, n: int, method: str) -> None:
            bar.update(task, completed=k, description=f"{label}: {method}")

        command = _bench_command_line(config, out, config_file, sets)
        result = run_bench(config, command=command, progress=progress)
        bar.update(task, completed=n_cases, description="done")
    folder = write_bench(result, out)
    _print_bench(result)
    console.print(f"wrote {folder}", markup=False, soft_wrap=True)


def _bench_command_line(
    config: Any, out: Path, config_file: Path | None, sets: list[str] | None
) -> str:
    """The command that reruns this benchmark (recorded with its results)."""
    command = f"flexreg bench --suite {config.suite}" + (" --quick" if config.quick else "")
    command += f" --out {out}"
    if config_file is not None:
        command += f" --config {config_file}"
    if ",".join(config.methods) != DEFAULT_METHODS:
        command += f" --methods {','.join(config.methods)}"
    if config.seed:
        command += f" --seed {config.seed}"
    if config.data_dir != "../shared/data":
        command += f" --data {config.data_dir}"
    if config.timeout_s != (120.0 if config.quick else 300.0):
        command += f" --timeout-s {config.timeout_s:g}"
    return command + "".join(f" --set {item}" for item in sets or ())


def _print_bench(result: BenchResult) -> None:
    from rich.table import Table

    from flexreg.bench.summary import summarise

    t = Table(title=f"{result.command} ({result.elapsed_s / 60:.1f} min)", title_justify="left")
    for c in ("suite", "method", "success", "median rot °", "median trans mm", "median s", "MB"):
        t.add_column(c, justify="left" if c in ("suite", "method") else "right")

    def f(x: Any, fmt: str, scale: float = 1.0) -> str:
        return "–" if x is None or not math.isfinite(x) else format(x * scale, fmt)

    for s in summarise(result.records):
        t.add_row(
            s["suite"],
            s["method"],
            f"{s['successes']}/{s['cases']}",
            f(s["median_rotation_error_deg"], ".4f"),
            f(s["median_translation_error_m"], ".2f", 1000),
            f(s["median_time_s"], ".2f"),
            f(s["median_peak_memory_mb"], ".0f"),
        )
    console.print(t)
    if result.machine.get("load_average") is not None:
        err_console.print(
            f"load average {result.machine['load_average'][0]:.1f} at the start, "
            f"{(result.machine.get('load_average_end') or [math.nan])[0]:.1f} at the end",
            markup=False,
        )
