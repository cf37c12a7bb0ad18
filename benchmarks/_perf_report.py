"""Markdown and figure of ``benchmarks/perf.py`` (from its ``results.json``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from _perf_runs import (
    TARGET_PEAK_2048_GB,
    TARGET_PEAK_8192_GB,
    TARGET_PREPARE_RATIO,
    TARGET_SPEED_RATIO,
    TARGET_WHOLE_S,
)

STAGES = (
    "range images",
    "feature images",
    "features",
    "lifting",
    "matching",
    "plan views",
    "preparation",
    "estimation",
    "refinement",
    "verdict",
    "overlap",
)


def _f(x: Any, fmt: str = ".2f") -> str:
    return "–" if x is None else format(x, fmt)


def _size(row: dict[str, Any]) -> tuple[int, int]:
    return int(row["width"]), int(row["height"])


def _by_size(state: dict[str, Any], w: int, h: int) -> dict[str, Any] | None:
    return next((r for r in state.get("whole", []) if _size(r) == (w, h)), None)


def _verdict(ok: bool | None, miss: str) -> str:
    return "–" if ok is None else ("**met**" if ok else f"**missed** ({miss})")


def _goals(state: dict[str, Any]) -> list[str]:
    r2, r8 = _by_size(state, 2048, 1024), _by_size(state, 8192, 4096)
    cmp = state.get("compare") or {}
    prep = state.get("prepare", [])
    lines = ["| target | measured | verdict |", "|---|---|---|"]
    for r, target, name in (
        (r2, TARGET_PEAK_2048_GB, "2048 × 1024"),
        (r8, TARGET_PEAK_8192_GB, "8192 × 4096"),
    ):
        peak = None if r is None else r["median_peak_gb"]
        ok = None if peak is None else peak <= target
        miss = "" if peak is None else f"{peak / target:.2f}× the target"
        got = "not measured in this run" if peak is None else f"{_f(peak)} GB"
        lines.append(
            f"| whole-process peak RSS, {name} pair ≤ {target:g} GB | {got} | "
            f"{_verdict(ok, miss)} |"
        )
    for p in prep:
        ratio = p.get("ratio")
        ok = None if ratio is None else ratio <= TARGET_PREPARE_RATIO
        miss = f"{_f(ratio, '.1f')}× instead of {TARGET_PREPARE_RATIO:g}×"
        cold = ""
        if p.get("cold_ratio") is not None:
            cold = (
                f"; first station of a process {_f(p.get('peak_above_imports_gb'), '.3f')} GB = "
                f"{_f(p['cold_ratio'], '.1f')}×"
            )
        lines.append(
            f"| survey preparation of one station ({p.get('cols')} × {p.get('rows')}) ≤ "
            f"{TARGET_PREPARE_RATIO:g}× its float32 xyz ({_f(p.get('grid_f32_gb'), '.3f')} GB) | "
            f"{_f(p.get('peak_above_base_gb', p.get('peak_above_imports_gb')), '.3f')} GB = "
            f"{_f(ratio, '.1f')}×{cold} | {_verdict(ok, miss)} |"
        )
    wall = None if r2 is None else r2["median_wall_s"]
    cpu = None if r2 is None else r2["median_cpu_s"]
    ok = None if wall is None else wall <= TARGET_WHOLE_S
    lines.append(
        f"| whole process, 2048 × 1024 PTX pair ≤ {TARGET_WHOLE_S:g} s (measured under load) | "
        f"{_f(wall)} s wall, {_f(cpu)} s CPU | "
        f"{_verdict(ok, '' if wall is None else f'{wall / TARGET_WHOLE_S:.1f}× the target')} |"
    )
    ratio = cmp.get("median_ratio")
    ok = None if ratio is None else ratio >= TARGET_SPEED_RATIO
    lines.append(
        f"| registration call ≥ {TARGET_SPEED_RATIO:g}× faster than FPFH + RANSAC + ICP "
        f"(median of per-pair ratios) | {_f(ratio, '.1f')}× (ratio of medians "
        f"{_f(cmp.get('ratio_of_medians'), '.1f')}×) | "
        f"{_verdict(ok, '' if ratio is None else f'{ratio:.1f}× of {TARGET_SPEED_RATIO:g}×')} |"
    )
    return lines


def _whole_table(state: dict[str, Any]) -> list[str]:
    lines = [
        "| pair | points (target + source) | runs | wall s | CPU s | peak RSS GB | "
        "register call s | verdict | error vs truth |",
        "|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in state.get("whole", []):
        last = r["runs"][-1] if r["runs"] else {}
        err = last.get("error_vs_truth") or {}
        e = (
            f"{err['rotation_deg']:.4f}° / {1000 * err['translation_m']:.2f} mm"
            if "rotation_deg" in err
            else "–"
        )
        pts = sum(r.get("points") or []) or None
        lines.append(
            f"| {r['width']} × {r['height']} | {_f(pts, ',')} | {len(r['runs'])} | "
            f"{_f(r['median_wall_s'])} | {_f(r['median_cpu_s'])} | {_f(r['median_peak_gb'])} | "
            f"{_f(r['median_call_s'])} | {last.get('verdict', 'failed')} | {e} |"
        )
    return lines


def _before_table(state: dict[str, Any]) -> list[str]:
    """Peak RSS and CPU seconds of the same runs on the code before this benchmark's changes
    (``state["before"]``: pair name -> :func:`_perf_runs.whole_register` summary)."""
    before = state.get("before") or {}
    lines = [
        f"Before the memory and speed changes ({state.get('before_note', 'main')}), the same "
        "harness on the same pairs in a separate run earlier the same hour (so under a "
        "different load):",
        "",
        "| pair | peak RSS GB before → after | CPU s before → after | wall s before → after |",
        "|---|---:|---:|---:|",
    ]
    for r in state.get("whole", []):
        b = before.get(r["pair"])
        if b is None:
            continue
        lines.append(
            f"| {r['width']} × {r['height']} | {_f(b['median_peak_gb'])} → "
            f"{_f(r['median_peak_gb'])} | {_f(b['median_cpu_s'], '.1f')} → "
            f"{_f(r['median_cpu_s'], '.1f')} | {_f(b['median_wall_s'], '.1f')} → "
            f"{_f(r['median_wall_s'], '.1f')} |"
        )
    return lines + [""] if before else []


def _stage_table(state: dict[str, Any]) -> list[str]:
    r2 = _by_size(state, 2048, 1024)
    start = state.get("startup") or {}
    lines = ["| stage | seconds |", "|---|---:|"]
    lines.append(f"| interpreter start | {_f(start.get('interpreter_s'))} |")
    lines.append(f"| interpreter + `import flexreg.cli` | {_f(start.get('median_wall_s'))} |")
    prep = next((p for p in state.get("prepare", []) if p.get("cols") == 2048), None)
    if prep is not None:
        lines.append(f"| PTX parsing, one 2048 × 1024 station | {_f(prep.get('read_s'))} |")
    if r2 is not None and r2["runs"]:
        t = r2["runs"][-1].get("timings_s") or {}
        for name in STAGES:
            if name in t:
                lines.append(f"| register: {name} | {_f(t[name])} |")
        lines.append(f"| register call (wall) | {_f(r2['runs'][-1].get('call_s'))} |")
    return lines


def _compare_table(cmp: dict[str, Any]) -> list[str]:
    lines = [
        "| pair | flexreg s | FPFH + RANSAC + ICP s | ratio | flexreg peak MB | FPFH peak MB | "
        "flexreg ok | FPFH ok |",
        "|---|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in cmp.get("pairs", []):
        lines.append(
            f"| {r['name']} | {r['flexreg_s']:.2f} | {r['fpfh_s']:.2f} | {r['ratio']:.1f}× | "
            f"{_f(r.get('flexreg_peak_mb'), '.0f')} | {_f(r.get('fpfh_peak_mb'), '.0f')} | "
            f"{'yes' if r['flexreg_success'] else 'no'} | {'yes' if r['fpfh_success'] else 'no'} |"
        )
    return lines


def _median(values: list[Any]) -> float | None:
    v = sorted(float(x) for x in values if x is not None)
    if not v:
        return None
    return v[len(v) // 2] if len(v) % 2 else (v[len(v) // 2 - 1] + v[len(v) // 2]) / 2


def _load(x: Any) -> str:
    """The 1-minute load average of :func:`machine_info`'s triple."""
    if isinstance(x, list | tuple) and x:
        x = x[0]
    return "?" if x is None else f"{float(x):.1f}"


def markdown(state: dict[str, Any], *, figure: str) -> str:
    """The section's Markdown."""
    m = state.get("machine", {})
    cmp = state.get("compare") or {}
    load = [_load(m.get("load_average")), _load(m.get("load_average_end"))]
    out = [
        f"Command: `.venv/bin/python {state.get('command', 'benchmarks/perf.py')}` "
        f"(`make bench-perf`); {m.get('cores', '?')} cores, Python {m.get('python', '?')}. "
        f"Measured under load: the machine was shared with other jobs (1-minute load average "
        f"{load[0]} at the start, {load[1]} at the "
        "end), so wall times are pessimistic; CPU seconds are less affected. Raw results: "
        "`benchmarks/results/perf-*/results.json`.",
        "",
        "**Against the targets:**",
        "",
        *_goals(state),
        "",
        "### Whole process: `flexreg register` on PTX pairs",
        "",
        "Synthetic room pairs (`flexreg synth --scene room --seed 0`), run as a user runs them "
        "(`flexreg register A.ptx B.ptx --truth gt.json --out T.json`). Peak RSS is the whole "
        "process's high-water mark (`VmHWM` read by the process itself at exit: interpreter, "
        "libraries, both scans, every stage); CPU seconds are user + system of the process; "
        "medians over the runs.",
        "",
        *_whole_table(state),
        "",
        *_before_table(state),
        f"![peak RSS against points]({figure})",
        "",
        "### Where the time goes (2048 × 1024 pair)",
        "",
        "The stage timings `register` reports (the plan views and the preparation run in "
        "background threads beside the feature stages, so stages overlap), and the start-up "
        "and PTX parsing around the call:",
        "",
        *_stage_table(state),
        "",
    ]
    if cmp:
        out += [
            "### Registration call against Open3D FPFH + RANSAC + ICP",
            "",
            f"The synthetic pairs of the comparison suite ({cmp['resolution'][0]} × "
            f"{cmp['resolution'][1]}, `flexreg bench --suite synthetic`), both methods pair by "
            f"pair in the same run, each call timed alone in its own process (scans in memory). "
            f"Median {cmp.get('median_flexreg_s', 0):.2f} s against "
            f"{cmp.get('median_fpfh_s', 0):.2f} s; success {cmp.get('flexreg_success')} / "
            f"{cmp.get('fpfh_success')} of {len(cmp.get('pairs', []))}. Peak memory is the "
            "increase of the process's resident set during the call (scans already loaded; "
            "median "
            f"{_f(_median([r.get('flexreg_peak_mb') for r in cmp.get('pairs', [])]), '.0f')} MB "
            "against "
            f"{_f(_median([r.get('fpfh_peak_mb') for r in cmp.get('pairs', [])]), '.0f')} MB).",
            "",
            *_compare_table(cmp),
            "",
        ]
    return "\n".join(out)


def hard_markdown(state: dict[str, Any]) -> str:
    """The harder pairs' section: per size, the call against FPFH + RANSAC + ICP."""
    m = state.get("machine", {})
    load = [_load(m.get("load_average")), _load(m.get("load_average_end"))]
    bins = state.get("bins", {})
    out = [
        f"Command: `.venv/bin/python {state['command']}`; {m.get('cores', '?')} cores, "
        f"{m.get('cpu', '?')}; 1-minute load average {load[0]} at the start, {load[1]} at the "
        f"end. Pairs of the comparison suite (`flexreg bench --suite synthetic`: a furnished "
        f"room and a hall in turn) {bins.get('distance_bins_m')} m apart and turned "
        f"{bins.get('yaw_bins_deg')}° (each pair one bin of each), both methods pair by pair "
        "in the same run, each call timed alone in its own process (scans in memory).",
        "",
        "| size | pairs | flexreg median s | FPFH + RANSAC + ICP median s | median ratio | "
        "flexreg ok | FPFH ok |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for cmp in state.get("hard", []):
        w, h = cmp["resolution"]
        out.append(
            f"| {w} × {h} | {len(cmp['pairs'])} | {_f(cmp.get('median_flexreg_s'))} | "
            f"{_f(cmp.get('median_fpfh_s'))} | {_f(cmp.get('median_ratio'), '.2f')}× | "
            f"{cmp.get('flexreg_success')} | {cmp.get('fpfh_success')} |"
        )
    for cmp in state.get("hard", []):
        w, h = cmp["resolution"]
        out += ["", f"**{w} × {h}**", "", *_compare_table(cmp)]
    return "\n".join(out) + "\n"


def plot(state: dict[str, Any], path: Path) -> Path:
    """Peak RSS of the whole process against the pair's points, with the targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    rows = [r for r in state.get("whole", []) if r.get("median_peak_gb") is not None]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    x = [sum(r.get("points") or [0]) / 1e6 for r in rows]
    y = [r["median_peak_gb"] for r in rows]
    ax.plot(x, y, "o-", label="flexreg register (whole process)")
    for xi, yi, r in zip(x, y, rows, strict=True):
        ax.annotate(
            f"{r['width']}×{r['height']}", (xi, yi), textcoords="offset points", xytext=(4, -12)
        )
    targets = [(2048, 1024, TARGET_PEAK_2048_GB), (8192, 4096, TARGET_PEAK_8192_GB)]
    for w, h, t in targets:
        r = _by_size(state, w, h)
        if r is not None:
            ax.plot([sum(r.get("points") or [0]) / 1e6], [t], "r_", markersize=20, mew=2)
    ax.plot([], [], "r_", label="target")
    before = state.get("before") or {}
    bx = [sum(b.get("points") or [0]) / 1e6 for b in before.values() if b.get("median_peak_gb")]
    by = [b["median_peak_gb"] for b in before.values() if b.get("median_peak_gb")]
    if bx:
        ax.plot(bx, by, "s--", color="0.5", label=f"before ({state.get('before_note', 'main')})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_yticks([0.25, 0.5, 1, 2, 3, 4])
    ax.set_xlabel("points of the pair (millions)")
    ax.set_ylabel("peak RSS (GB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax.set_title("Peak memory of flexreg register (measured under load)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
