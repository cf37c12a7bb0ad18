"""`flexreg compare` (flexreg and the ICP baselines on one pair) and `flexreg bench` (the
comparison benchmark suites)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from flexreg.cli._common import console, err_console, progress_bar, read_input, stage
from flexreg.cli.app import app
from flexreg.errors import ConfigError

if TYPE_CHECKING:
    from flexreg.bench.compare import Comparison
    from flexreg.bench.types import BenchResult

#: the default of --methods (flexreg.bench.compare.DEFAULT_METHODS, spelled out so that --help
#: needs no import)
DEFAULT_METHODS = "flexreg,icp-point,icp-plane,gicp,fpfh-ransac,kiss-icp"


def _positive(option: str, value: float | None, unit: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{option}: must be a positive number of {unit}, got {value}")


def _check_out_folder(out: Path, inputs: tuple[Path, ...]) -> None:
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out}: exists and is not a folder")
    for p in inputs:
        if p.resolve() == out.resolve():
            raise ConfigError(f"--out: {out}: is also an input")


@app.command("compare")
def compare_command(
    target: Path = typer.Argument(
        ..., metavar="TARGET", help="Target scan (any readable scan file), in its scanner frame."
    ),
    source: Path = typer.Argument(
        ..., metavar="SOURCE", help="Source scan, mapped onto TARGET by T_target_source."
    ),
    out: Path = typer.Option(
        ...,
        "--out",
        help="Output folder (created): comparison.json, comparison.md and comparison.png.",
    ),
    gt: Path | None = typer.Option(
        None,
        "--gt",
        help='Known T_target_source: JSON {"T_target_source": [[4x4]]} (a flexreg synth '
        "gt.json works, pair by file stems) or a 4x4 text matrix. Gives errors and success.",
    ),
    methods: str = typer.Option(
        DEFAULT_METHODS,
        "--methods",
        help="Comma-separated: flexreg, icp-point, icp-plane, gicp, fpfh-ransac, kiss-icp "
        "(small-gicp when installed).",
    ),
    init: Path | None = typer.Option(
        None,
        "--init",
        help="Initial T_target_source for the local methods (ICP variants, KISS-ICP); "
        "default identity. flexreg and fpfh-ransac need none.",
    ),
    voxel: float | None = typer.Option(
        None,
        "--voxel",
        metavar="METRES",
        help="Scale voxel of the baselines, metres (default: from the scan resolution).",
    ),
    seed: int = typer.Option(0, "--seed", help="Seed of flexreg and RANSAC."),
    success_deg: float = typer.Option(
        0.5, "--success-deg", help="Success: rotation error at most this, degrees."
    ),
    success_m: float = typer.Option(
        0.05, "--success-m", help="Success: translation error at most this, metres."
    ),
    timeout_s: float = typer.Option(
        600.0, "--timeout-s", help="Time limit per method, seconds (a timeout is a row)."
    ),
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

    chosen = parse_methods(methods)
    _positive("--voxel", voxel, "metres")
    _positive("--success-deg", success_deg, "degrees")
    _positive("--success-m", success_m, "metres")
    _positive("--timeout-s", timeout_s, "seconds")
    if seed < 0:
        raise ConfigError(f"--seed: must be a non-negative integer, got {seed}")
    _check_out_folder(out, (target, source))
    criteria = SuccessCriteria(rotation_deg=success_deg, translation_m=success_m)
    T_gt = None if gt is None else read_ground_truth(gt, target=target.stem, source=source.stem)
    T_init = None if init is None else read_transform(init)
    scans = []
    for path in (target, source):
        with stage(f"Reading {path.name}"):
            (scan,) = read_input(path)
        scans.append(scan)
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
            voxel_m=voxel,
            seed=seed,
            criteria=criteria,
            timeout_s=timeout_s,
            names=(str(target), str(source)),
            progress=progress,
        )
    written = write_comparison(cmp, out)
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
    "coarse error (° / m)": "coarse ° / m",
    "inlier RMSE (m)": "RMSE m",
    "fitness": "fitness",
    "time (s)": "time s",
    "peak memory (MB)": "peak MB",
}


def _print_comparison(cmp: Comparison) -> None:
    from rich.console import Console
    from rich.table import Table

    from flexreg.bench.tables import COLUMNS, notes, table_rows

    t = Table(title=f"{cmp.target} ← {cmp.source}", title_justify="left")
    for c in COLUMNS:
        left = c in ("method", "status", "success")
        t.add_column(_SHORT[c], justify="left" if left else "right", no_wrap=c != "status")
    for row, run in zip(table_rows(cmp), cmp.runs, strict=True):
        cells = dict(row)
        cells["status"] = run.status  # the message follows the table
        t.add_row(*(cells[c] for c in COLUMNS))
    # the table needs about 130 columns: as wide as that even when piped
    wide = console if console.width >= 132 else Console(highlight=False, width=132)
    wide.print(t)
    for run in cmp.runs:
        if not run.ok:
            console.print(f"{run.method} {run.status}: {run.message}", markup=False, soft_wrap=True)
    for line in notes(cmp):
        console.print(f"- {line}", markup=False, highlight=False, soft_wrap=True)


@app.command("bench")
def bench_command(
    suite: str = typer.Option("all", "--suite", help="synthetic, real or all."),
    out: Path = typer.Option(
        ..., "--out", help="Folder that receives the timestamped result folder (created)."
    ),
    quick: bool = typer.Option(
        False,
        "--quick",
        help="Short run (about 2-3 min): 4 small synthetic pairs, a small sweep, 2 real pairs.",
    ),
    methods: str = typer.Option(DEFAULT_METHODS, "--methods", help="Comma-separated methods."),
    seed: int = typer.Option(0, "--seed", help="Seed of the synthetic pairs and the methods."),
    data: Path = typer.Option(
        Path("../shared/data"), "--data", help="Folder of the real data sets."
    ),
    timeout_s: float | None = typer.Option(
        None,
        "--timeout-s",
        help="Time limit per method and pair, seconds (default 300; 120 quick).",
    ),
) -> None:
    """Benchmark flexreg against the baselines: synthetic pairs over station distance, yaw,
    tilt, noise and resolution, and the real pairs with a reference.

    Writes cases.csv, summary.csv / .md, results.json, config.json and plots into
    OUT/bench-<time>/ once everything has run.
    """
    from flexreg.bench.methods import parse_methods
    from flexreg.bench.results import write_bench
    from flexreg.bench.suite import check_real_data, run_bench
    from flexreg.bench.types import SUITES, BenchConfig

    if suite not in SUITES:
        raise ConfigError(f"--suite: must be one of {', '.join(SUITES)}, got {suite!r}")
    chosen = parse_methods(methods)
    _positive("--timeout-s", timeout_s, "seconds")
    if seed < 0:
        raise ConfigError(f"--seed: must be a non-negative integer, got {seed}")
    _check_out_folder(out, ())
    overrides: dict[str, Any] = {"methods": chosen, "seed": seed, "data_dir": str(data)}
    if timeout_s is not None:
        overrides["timeout_s"] = timeout_s
    config = BenchConfig.make(suite, quick=quick, **overrides)
    if config.runs_real:
        check_real_data(config.data_dir, config.real_pairs)
    command = f"flexreg bench --suite {suite}" + (" --quick" if quick else "")
    command += f" --out {out}"
    if methods != DEFAULT_METHODS:
        command += f" --methods {','.join(chosen)}"
    if seed:
        command += f" --seed {seed}"
    if str(data) != "../shared/data":
        command += f" --data {data}"
    if timeout_s is not None:
        command += f" --timeout-s {timeout_s:g}"
    from flexreg.bench.suite import planned_cases

    n_cases = len(planned_cases(config))
    with progress_bar() as bar:
        task = bar.add_task("bench", total=n_cases)

        def progress(label: str, k: int, n: int, method: str) -> None:
            bar.update(task, completed=k, description=f"{label}: {method}")

        result = run_bench(config, command=command, progress=progress)
        bar.update(task, completed=n_cases, description="done")
    folder = write_bench(result, out)
    _print_bench(result)
    console.print(f"wrote {folder}", markup=False, soft_wrap=True)


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
