"""A benchmark run's records summarised: per suite and method, success by distance and yaw bin,
and the CSV and Markdown tables of ``flexreg bench``."""

from __future__ import annotations

import csv
import io
import math
import statistics
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flexreg.bench.types import BenchConfig, BenchResult

__all__ = [
    "CSV_FIELDS",
    "SUMMARY_FIELDS",
    "bin_label",
    "success_by",
    "summarise",
    "summary_markdown",
    "to_csv",
]


def _median(values: list[float]) -> float:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.median(vals) if vals else math.nan


def summarise(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per suite and method: cases, successes, success rate, median errors over the
    successes, median time and peak memory over every run, and the failures by status."""
    out = []
    suites = list(dict.fromkeys(r["suite"] for r in records))
    methods = list(dict.fromkeys(r["method"] for r in records))
    for suite in suites:
        for method in methods:
            rs = [r for r in records if r["suite"] == suite and r["method"] == method]
            if not rs:
                continue
            succ = [r for r in rs if r["success"]]
            coarse = [r for r in rs if r["coarse_success"] is not None]
            statuses: dict[str, int] = {}
            for r in rs:
                if r["status"] != "ok":
                    statuses[r["status"]] = statuses.get(r["status"], 0) + 1
            out.append(
                {
                    "suite": suite,
                    "method": method,
                    "cases": len(rs),
                    "successes": len(succ),
                    "success_rate": len(succ) / len(rs),
                    "coarse_successes": (
                        sum(bool(r["coarse_success"]) for r in coarse) if coarse else None
                    ),
                    "median_rotation_error_deg": _median([r["rotation_error_deg"] for r in succ]),
                    "median_translation_error_m": _median([r["translation_error_m"] for r in succ]),
                    "median_time_s": _median([r["time_s"] for r in rs]),
                    "median_time_success_s": _median([r["time_s"] for r in succ]),
                    "median_peak_memory_mb": _median([r["peak_memory_mb"] for r in rs]),
                    "not_ok": statuses,
                }
            )
    return out


def success_by(
    records: list[dict[str, Any]], key: str, bins: tuple[tuple[float, float], ...]
) -> dict[str, list[tuple[int, int]]]:
    """Synthetic records: per method, ``(successes, cases)`` in each bin of ``key``
    (``distance_m`` or ``yaw_deg``; the last bin includes its upper end)."""
    syn = [r for r in records if r["suite"] == "synthetic"]
    methods = list(dict.fromkeys(r["method"] for r in syn))
    out: dict[str, list[tuple[int, int]]] = {}
    for m in methods:
        cells = []
        for k, (lo, hi) in enumerate(bins):
            last = k == len(bins) - 1
            rs = [
                r
                for r in syn
                if r["method"] == m
                and r.get(key) is not None
                and lo <= r[key]
                and (r[key] <= hi if last else r[key] < hi)
            ]
            cells.append((sum(bool(r["success"]) for r in rs), len(rs)))
        out[m] = cells
    return out


# ------------------------------------------------------------------ rendering

CSV_FIELDS = (
    "suite",
    "case",
    "name",
    "scene",
    "seed",
    "reference",
    "distance_m",
    "yaw_deg",
    "rotation_deg",
    "tilt_deg",
    "noise_mm",
    "width",
    "height",
    "overlap",
    "points_target",
    "points_source",
    "scale_m",
    "method",
    "status",
    "message",
    "rotation_error_deg",
    "translation_error_m",
    "coarse_rotation_error_deg",
    "coarse_translation_error_m",
    "success",
    "coarse_success",
    "success_rotation_deg",
    "success_translation_m",
    "inlier_rmse_m",
    "fitness",
    "open3d_fitness",
    "open3d_inlier_rmse_m",
    "time_s",
    "peak_memory_mb",
)
SUMMARY_FIELDS = (
    "suite",
    "method",
    "cases",
    "successes",
    "success_rate",
    "coarse_successes",
    "median_rotation_error_deg",
    "median_translation_error_m",
    "median_time_s",
    "median_time_success_s",
    "median_peak_memory_mb",
)


def to_csv(rows: list[dict[str, Any]], fields: tuple[str, ...]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(fields), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _csv_cell(r.get(k)) for k in fields})
    return buf.getvalue()


def _csv_cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return v


def _f(x: Any, fmt: str, scale: float = 1.0) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return format(x * scale, fmt)


def bin_label(lo: float, hi: float, unit: str) -> str:
    return f"{lo:g}–{hi:g}{unit}"


def summary_markdown(result: BenchResult, figures: dict[str, str] | None = None) -> str:
    """Tables of a run (summary per suite, success by distance and yaw, real pairs, time and
    memory against resolution) with the figures and the protocol notes."""
    cfg = result.config
    figs = figures or {}
    m = result.machine
    load0 = (m.get("load_average") or [math.nan])[0]
    load1 = (m.get("load_average_end") or [math.nan])[0]
    lines = [
        f"Command: `{result.command}` — {m.get('cores')} cores ({m.get('cpu')}), Python "
        f"{m.get('python')}, numpy {m.get('numpy')}, Open3D {m.get('open3d')}, KISS-ICP "
        f"{m.get('kiss_icp')}. Run {result.started} – {result.finished}: "
        f"{result.elapsed_s / 60:.1f} min; 1-minute load average {load0:.1f} at the start, "
        f"{load1:.1f} at the end"
        + (
            " (other jobs shared the machine: times are pessimistic)"
            if max(load0, load1) > 0.5 * (m.get("cores") or 1) + 0.5
            else ""
        )
        + ".",
        "",
        f"Success = final transform within the pair's limits of the reference (synthetic: "
        f"{cfg.criteria.label()}). Median errors over the successes; median time and peak "
        f"memory over every run of the method (time = the method's call alone, scans in "
        f"memory; peak memory = {result.memory_note}).",
        "",
    ]
    summary = summarise(result.records)
    flex = {s["suite"]: s for s in summary if s["method"] == "flexreg"}
    for suite in dict.fromkeys(s["suite"] for s in summary):
        rows = [s for s in summary if s["suite"] == suite]
        title = {
            "synthetic": "Synthetic station pairs, all methods",
            "real": "Real pairs, all methods",
            "resolution": "Resolution sweep, all methods (one room pair)",
        }.get(suite, suite)
        lines += [
            f"### {title}",
            "",
            "| method | success | coarse success | median rotation error ° | median translation "
            "error mm | median time s | time / flexreg | median peak memory MB | not ok |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|",
        ]
        base = flex.get(suite, {}).get("median_time_s", math.nan)
        for s in rows:
            ratio = s["median_time_s"] / base if base and math.isfinite(base) else math.nan
            bad = ", ".join(f"{k} {v}" for k, v in s["not_ok"].items()) or "–"
            coarse = (
                "–" if s["coarse_successes"] is None else f"{s['coarse_successes']}/{s['cases']}"
            )
            lines.append(
                f"| {s['method']} | {s['successes']}/{s['cases']} ({s['success_rate']:.0%}) "
                f"| {coarse} | {_f(s['median_rotation_error_deg'], '.4f')} "
                f"| {_f(s['median_translation_error_m'], '.2f', 1000)} "
                f"| {_f(s['median_time_s'], '.2f')} | {_f(ratio, '.2f')}x "
                f"| {_f(s['median_peak_memory_mb'], '.0f')} | {bad} |"
            )
        lines.append("")
        if suite == "synthetic":
            lines += _bin_tables(result.records, cfg)
            for key in ("success_vs_distance", "success_vs_yaw"):
                if key in figs:
                    lines += [f"![{key.replace('_', ' ')}]({figs[key]})", ""]
            lines += _case_table(result.records, "synthetic")
        if suite == "real":
            lines += _case_table(result.records, "real")
        if suite == "resolution":
            lines += _resolution_table(result.records)
            for key in ("time_vs_resolution", "memory_vs_resolution"):
                if key in figs:
                    lines += [f"![{key.replace('_', ' ')}]({figs[key]})", ""]
    return "\n".join(lines).rstrip() + "\n"


def _bin_tables(records: list[dict[str, Any]], cfg: BenchConfig) -> list[str]:
    lines: list[str] = []
    for key, bins, unit, what in (
        ("distance_m", cfg.distance_bins_m, " m", "station distance"),
        ("yaw_deg", cfg.yaw_bins_deg, "°", "relative yaw"),
    ):
        table = success_by(records, key, bins)
        lines += [
            f"Successes by {what}:",
            "",
            "| method | " + " | ".join(bin_label(lo, hi, unit) for lo, hi in bins) + " |",
            "|---|" + "---:|" * len(bins),
        ]
        for method, cells in table.items():
            lines.append(f"| {method} | " + " | ".join(f"{s}/{n}" for s, n in cells) + " |")
        lines.append("")
    return lines


def _case_table(records: list[dict[str, Any]], suite: str) -> list[str]:
    rs = [r for r in records if r["suite"] == suite]
    if not rs:
        return []
    methods = list(dict.fromkeys(r["method"] for r in rs))
    lines = [
        "Per pair: rotation error ° / translation error m (**bold** = success), time s; "
        "failures give their status:",
        "",
        "| pair | limits | " + " | ".join(methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for case in dict.fromkeys(r["case"] for r in rs):
        row = [r for r in rs if r["case"] == case]
        first = row[0]
        cells = []
        for m in methods:
            r = next((x for x in row if x["method"] == m), None)
            if r is None:
                cells.append("")
            elif r["status"] != "ok":
                t = r["time_s"]
                cells.append(r["status"] + (f", {t:.1f} s" if math.isfinite(t) else ""))
            else:
                txt = f"{r['rotation_error_deg']:.3f} / {r['translation_error_m']:.3f}"
                cells.append((f"**{txt}**" if r["success"] else txt) + f", {r['time_s']:.1f} s")
        lim = (first.get("success_rotation_deg"), first.get("success_translation_m"))
        limits = "–" if None in lim else f"{lim[0]:g}° / {lim[1]:g} m"
        lines.append(f"| {first['name']} | {limits} | " + " | ".join(cells) + " |")
    lines.append("")
    fails = [r for r in rs if r["status"] != "ok" and r["status"] != "failed"]
    if fails:
        lines += ["Errors, crashes and timeouts:", ""]
        lines += [f"- {r['name']}, {r['method']}: {r['status']} ({r['message']})" for r in fails]
        lines.append("")
    return lines


def _resolution_table(records: list[dict[str, Any]]) -> list[str]:
    rs = [r for r in records if r["suite"] == "resolution" and r.get("width") is not None]
    if not rs:
        return []
    methods = list(dict.fromkeys(r["method"] for r in rs))
    sizes = list(dict.fromkeys((r["width"], r["height"]) for r in rs))
    lines = [
        "Time s / peak memory MB per resolution (millions of target points in brackets; *fail* "
        "= no success):",
        "",
        "| method | " + " | ".join(f"{w}x{h} ({_mpts(rs, w, h)})" for w, h in sizes) + " |",
        "|---|" + "---:|" * len(sizes),
    ]
    for m in methods:
        cells = []
        for w, h in sizes:
            r = next(
                (x for x in rs if x["method"] == m and (x["width"], x["height"]) == (w, h)), None
            )
            if r is None:
                cells.append("")
                continue
            mem = _f(r["peak_memory_mb"], ".0f")
            tag = (
                "" if r["success"] else (" *fail*" if r["status"] == "ok" else f" *{r['status']}*")
            )
            cells.append(f"{r['time_s']:.1f} / {mem}{tag}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines.append("")
    return lines


def _mpts(rs: list[dict[str, Any]], w: int, h: int) -> str:
    n = next((r.get("points_target") for r in rs if (r["width"], r["height"]) == (w, h)), None)
    return "–" if n is None else f"{n / 1e6:.3g}"
