"""Result files: a comparison's JSON, Markdown and bar chart; a benchmark run's folder (CSV,
summary, JSON, configuration, figures), and a run read back from its ``results.json``."""

from __future__ import annotations

import contextlib
import json
import math
import shutil
from collections.abc import Callable
from datetime import datetime
from os import PathLike
from pathlib import Path

from flexreg.bench.compare import Comparison
from flexreg.bench.harness import json_text
from flexreg.bench.measure import peak_memory_note
from flexreg.bench.plots import plot_comparison, plot_success_vs, plot_vs_resolution
from flexreg.bench.summary import CSV_FIELDS, SUMMARY_FIELDS, summarise, summary_markdown, to_csv
from flexreg.bench.tables import to_markdown
from flexreg.bench.types import BenchConfig, BenchResult
from flexreg.config import Config
from flexreg.errors import InputError
from flexreg.io import atomic_write
from flexreg.io.files import all_or_nothing

__all__ = ["FIGURES", "load_bench", "write_bench", "write_comparison", "write_files"]


def write_comparison(
    cmp: Comparison, out_dir: str | PathLike[str], *, config: Config | None = None
) -> list[Path]:
    """Write ``comparison.json``, ``comparison.md`` and ``comparison.png`` into ``out_dir``
    (created). Each file is written under a temporary name and renamed; if one fails, those
    already written here are removed again. ``config`` (the run's settings) is stored under
    the JSON's ``"config"`` key, so ``flexreg compare --config comparison.json`` repeats it.

    Raises
    ------
    InputError
        ``out_dir`` exists and is not a folder, or a file cannot be written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    doc = json_text(
        {**cmp.to_dict(), **({"config": config.to_dict()} if config is not None else {})},
        indent=2,
    )
    md = f"# target = {Path(cmp.target).name}, source = {Path(cmp.source).name}\n\n" + to_markdown(
        cmp, figure="comparison.png"
    )
    writers: list[tuple[Path, Callable[[Path], object]]] = [
        (out / "comparison.json", lambda tmp: tmp.write_text(doc)),
        (out / "comparison.md", lambda tmp: tmp.write_text(md)),
        (out / "comparison.png", lambda tmp: plot_comparison(cmp, tmp)),
    ]
    return write_files(writers)


def write_files(writers: list[tuple[Path, Callable[[Path], object]]]) -> list[Path]:
    """Write each file atomically, all or none (:func:`flexreg.io.files.all_or_nothing`): on
    any failure no file is replaced, and the folders made for them are removed again."""
    with all_or_nothing():
        for path, write in writers:
            atomic_write(path, write)
    return [path for path, _ in writers]


FIGURES = {
    "success_vs_distance": "success_vs_distance.png",
    "success_vs_yaw": "success_vs_yaw.png",
    "time_vs_resolution": "time_vs_resolution.png",
    "memory_vs_resolution": "memory_vs_resolution.png",
}


def write_bench(result: BenchResult, out_dir: str | PathLike[str]) -> Path:
    """Write a run into ``out_dir/bench-<start time>/`` and return that folder.

    Files: ``cases.csv`` (one row per pair and method), ``summary.csv``, ``summary.md``,
    ``results.json`` (everything), ``config.json``, and the figures of :data:`FIGURES` that
    the suites produced. The folder is assembled as ``.bench-<time>.partial`` and renamed
    when complete.

    Raises
    ------
    InputError
        ``out_dir`` is a file, or the folder cannot be written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    stamp = datetime.fromisoformat(result.started).strftime("%Y%m%d-%H%M%S")
    final = out / f"bench-{stamp}"
    n = 1
    while final.exists():
        n += 1
        final = out / f"bench-{stamp}-{n}"
    tmp = out / f".{final.name}.partial"
    created = [d for d in (out, *out.parents) if not d.exists()]
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        recs = result.records
        figs: dict[str, str] = {}
        cfg = result.config
        if any(r["suite"] == "synthetic" for r in recs):
            plot_success_vs(
                recs,
                "distance_m",
                cfg.distance_bins_m,
                " m",
                "station distance",
                tmp / FIGURES["success_vs_distance"],
            )
            plot_success_vs(
                recs,
                "yaw_deg",
                cfg.yaw_bins_deg,
                "°",
                "relative yaw of the stations",
                tmp / FIGURES["success_vs_yaw"],
            )
            figs["success_vs_distance"] = FIGURES["success_vs_distance"]
            figs["success_vs_yaw"] = FIGURES["success_vs_yaw"]
        if any(r["suite"] == "resolution" for r in recs):
            plot_vs_resolution(
                recs, "time_s", "time of the call (s)", tmp / FIGURES["time_vs_resolution"]
            )
            plot_vs_resolution(
                recs,
                "peak_memory_mb",
                "peak memory increase (MB)",
                tmp / FIGURES["memory_vs_resolution"],
            )
            figs["time_vs_resolution"] = FIGURES["time_vs_resolution"]
            figs["memory_vs_resolution"] = FIGURES["memory_vs_resolution"]
        (tmp / "cases.csv").write_text(to_csv(recs, CSV_FIELDS))
        (tmp / "summary.csv").write_text(to_csv(summarise(recs), SUMMARY_FIELDS))
        (tmp / "summary.md").write_text(
            "# Comparison benchmark\n\n" + summary_markdown(result, figs)
        )
        doc = {**result.to_dict(), "summary": summarise(recs)}
        (tmp / "results.json").write_text(json_text(doc, indent=1))
        (tmp / "config.json").write_text(json_text(result.config.to_dict(), indent=2))
        tmp.rename(final)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        for d in created:  # innermost first; only folders this call made, if still empty
            with contextlib.suppress(OSError):
                d.rmdir()
        if isinstance(e, OSError):
            raise InputError(out, f"cannot write the results: {e.strerror or e}") from e
        raise
    return final


def load_bench(path: str | PathLike[str]) -> BenchResult:
    """A run again from its ``results.json`` (to render its tables and plots anew).

    Raises
    ------
    InputError
        Missing or unreadable file, or not a benchmark result.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
        config = BenchConfig(**doc["config"])
        records = [
            {k: (math.nan if k == "time_s" and v is None else v) for k, v in r.items()}
            for r in doc["records"]
        ]
        cases = doc["cases"]
        for r in records:  # runs before the point counts were per record
            pts = cases[r["case"]].get("points") if r["case"] < len(cases) else None
            if "points_target" not in r and pts:
                r["points_target"], r["points_source"] = pts
        return BenchResult(
            config=config,
            records=records,
            cases=cases,
            started=doc["started"],
            finished=doc["finished"],
            elapsed_s=float(doc["elapsed_s"]),
            machine=doc["machine"],
            command=doc["command"],
            memory_note=doc.get("memory_note") or peak_memory_note(),
        )
    except OSError as e:
        raise InputError(p, f"cannot read: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, IndexError) as e:
        raise InputError(p, f"not a benchmark results.json ({type(e).__name__}: {e})") from None
