"""The resolution set of ``benchmarks/survey.py`` (issue 39) as Markdown and figures: a survey of
the same project at several station grids and formats, cold and warm, its wall time split by
stage, the peak memory of every Dask worker, the cache against the input, how fast the files
are read, and what 100 such stations would take.

``survey.py`` imports this module as a sibling.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.transforms import rotation_error_deg, translation_error_m

Record = dict[str, Any]

#: the acceptance's bounds: peak resident set of one Dask worker, cache against the input
WORKER_LIMIT_MB = 2048.0
CACHE_LIMIT = 0.5
#: the stages of ``poses.json``'s ``timings_s`` shown as wall time, in order
STAGES = ("prepare", "pairs", "links", "graph", "map_check", "refine")


def _command(state: Record) -> str:
    """The run's command with the folders it was given (``--data``, ``--results``,
    ``--resume``: somewhere outside the repository) as their option names."""
    words = state["command"].split()
    for i, w in enumerate(words[:-1]):
        if w in ("--data", "--results", "--resume"):
            words[i + 1] = w.removeprefix("--").upper()
    return " ".join(words)


def _recs(state: Record) -> list[Record]:
    return [r for r in state["records"] if r["set"] == "resolution"]


def _points(r: Record) -> float | None:
    """Median valid points per station of a run (None: no poses.json)."""
    pts = [p for p in r.get("points") or [] if p]
    return float(np.median(pts)) if pts else None


def _t(r: Record, key: str) -> float | None:
    return (r.get("timings_s") or {}).get(key)


def _fmt(x: float | None, f: str = ".1f") -> str:
    return "not measured" if x is None else format(x, f)


def _worker_mb(r: Record) -> float | None:
    """The largest high-water mark among the run's child processes (its Dask workers); the
    main process's when it ran with one worker in-process."""
    others = r.get("peak_other_mb") or []
    return max((o["peak_mb"] for o in others), default=None) or r.get("peak_main_mb")


def _run(r: Record) -> str:
    return ("warm" if r.get("warm") else "cold") + f", {r.get('workers')} worker(s)"


def _outcome(r: Record) -> str:
    ev = r.get("evaluation")
    if not ev:
        return f"exit {r.get('exit')}, no poses.json"
    return f"{ev['success']} / {ev['placed']} / {ev['wrong']}"


def run_table(recs: Sequence[Record]) -> list[str]:
    """One row per run: wall time by stage, memory, cache."""
    head = (
        "| format | grid | points / station | run | wall s | read Σ | prepare Σ | prepare | "
        "pairs | links | graph | map check | final alignment | start-up + outputs | "
        "peak worker MB | main MB | tree MB | cache MB (× input) | within / placed / wrong |"
    )
    lines = [head, "|" + "---|" * 19]
    for r in recs:
        p = r["project"]
        wall = r.get("wall_s")
        inner = (r.get("summary") or {}).get("wall_s")
        rest = wall - inner if wall is not None and inner is not None else None
        cache_mb = r.get("cache_bytes", 0) / 2**20
        ratio = r.get("cache_bytes", 0) / max(1, r.get("input_bytes", 1))
        pts = _points(r)
        lines.append(
            f"| {p.get('format', 'ptx')} | {p['width']}x{p['height']} | "
            f"{_fmt(pts / 1e6 if pts else None, '.1f')} M | {_run(r)} | {_fmt(wall, '.0f')} | "
            f"{_fmt(_t(r, 'read_sum'))} | {_fmt(_t(r, 'prepare_sum'))} | "
            + " | ".join(_fmt(_t(r, k)) for k in STAGES)
            + f" | {_fmt(rest)} | {_fmt(_worker_mb(r), '.0f')} | "
            f"{_fmt(r.get('peak_main_mb'), '.0f')} | {_fmt(r.get('peak_tree_mb'), '.0f')} | "
            f"{cache_mb:.0f} ({ratio:.2f}) | {_outcome(r)} |"
        )
    return lines


def reader_table(recs: Sequence[Record]) -> list[str]:
    """How fast one station file of each project is read, against ``cat``, and what its
    preparation peaks at against its float32 coordinates (12 bytes a point)."""
    lines = [
        "| format | grid | file MB | points | `cat` MB/s (disk) | first read MB/s (disk) | "
        "read MB/s (memory) | read s | first read / `cat` | prepare s | MB: after imports / "
        "read peak / prepared peak | prepared peak above imports (× float32 xyz) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    seen = set()
    for r in recs:
        rd = r.get("reader")
        if not rd or r["project"]["name"] in seen:  # one row a project
            continue
        seen.add(r["project"]["name"])
        p = r["project"]
        first = rd.get("first_read_s")
        slower = first / rd["cat_s"] if first else None
        disk = "" if rd.get("from_disk") else " (page cache)"
        over = None
        if rd.get("prepare_peak_mb") and rd.get("base_mb") and rd.get("points"):
            over = (rd["prepare_peak_mb"] - rd["base_mb"]) / (12 * rd["points"] / 2**20)
        pts = rd.get("points")
        lines.append(
            f"| {p.get('format', 'ptx')} | {p['width']}x{p['height']} | {rd['mb']:.0f} | "
            f"{_fmt(pts / 1e6 if pts else None, '.1f')} M | "
            f"{rd['cat_mb_s']:.0f}{disk} | {_fmt(rd['mb'] / first if first else None, '.0f')} | "
            f"{_fmt(rd.get('read_mb_s'), '.0f')} | "
            f"{_fmt(rd.get('read_s'), '.2f')} | {_fmt(slower, '.1f')}× | "
            f"{_fmt(rd.get('prepare_s'), '.2f')} | {_fmt(rd.get('base_mb'), '.0f')} / "
            f"{_fmt(rd.get('read_peak_mb'), '.0f')} / {_fmt(rd.get('prepare_peak_mb'), '.0f')} | "
            f"{_fmt(over, '.2f')}× |"
        )
    return lines


def same_poses(recs: Sequence[Record]) -> list[str]:
    """How the one-worker run's poses compare with the other runs of its project: bit for bit
    (the poses as ``poses.json`` stores them), else the largest difference."""
    out = []
    for one in (r for r in recs if r.get("workers") == 1 and r.get("poses")):
        name = one["project"]["name"]
        for other in recs:
            if other is one or other["project"]["name"] != name or not other.get("poses"):
                continue
            rot, trans, diff, missing = 0.0, 0.0, 0.0, []
            for st, T in one["poses"].items():
                U = other["poses"].get(st)
                if (T is None) != (U is None):
                    missing.append(st)
                elif T is not None:
                    A, B = np.asarray(T), np.asarray(U)
                    diff = max(diff, float(np.abs(A - B).max()))
                    rot = max(rot, rotation_error_deg(A, B))
                    trans = max(trans, translation_error_m(A, B))
            placed = "the same stations placed" if not missing else f"placed differ: {missing}"
            same = (
                "every pose bit-identical"
                if diff == 0.0
                else f"largest difference {rot:.2g}° / {1e3 * trans:.2g} mm"
            )
            out.append(f"- {name}, 1 worker against {_run(other)}: {placed}; {same}.")
    return out


def extrapolation(recs: Sequence[Record], n: int = 100) -> list[str]:
    """Time and memory of ``n`` stations like the largest grid's, from its cold run's
    per-station and per-link costs."""
    cold = [r for r in recs if not r.get("warm") and r.get("evaluation") and r.get("timings_s")]
    if not cold:
        return ["No cold run finished: nothing to extrapolate from."]
    r = max(cold, key=lambda x: (_points(x) or 0, x.get("workers") or 0))
    k = len(r["points"])
    tm = r["timings_s"]
    per_station = (tm.get("read_sum", 0.0) + tm.get("prepare_sum", 0.0)) / k
    links = r["evaluation"]["links_attempted"]
    w = r.get("workers") or 1
    per_link = tm.get("links", 0.0) * w / max(1, links)  # worker-seconds per link
    per_check = (tm.get("map_check", 0.0) + tm.get("refine", 0.0)) * w / k  # per station
    graph_per_station = tm.get("graph", 0.0) / k
    links_n = links / k * n
    cache_per_station = r.get("cache_bytes", 0) / k
    work = n * per_station + links_n * per_link + n * per_check
    rows = []
    for label, workers in (
        ("this machine, 2 workers", 2),
        ("4 machines x 4 cores, 16 workers", 16),
    ):
        hours = (work / workers + n * graph_per_station) / 3600
        rows.append(f"| {label} | {hours:.2f} h | {_fmt(_worker_mb(r), '.0f')} MB per worker |")
    return [
        f"From the cold run of {r['project']['name']} ({_run(r)}, {k} stations): "
        f"{per_station:.1f} worker-s to read and prepare a station, {per_link:.1f} worker-s a "
        f"link ({links} links, {links / k:.1f} a station), {per_check:.1f} worker-s a station "
        f"for the map check and final alignment, {graph_per_station:.2f} s a station of graph "
        "solves (serial). Assumed: links grow linearly with the stations (place recognition "
        "keeps a bounded number per station), the parallel stages divide by the workers, and "
        "the serial graph solves grow linearly (they grow faster on loop-rich projects). "
        f"Cache: {cache_per_station * n / 2**30:.1f} GB for {n} stations.",
        "",
        f"| {n} stations | wall time | memory |",
        "|---|---|---|",
        *rows,
    ]


def acceptance(recs: Sequence[Record]) -> list[tuple[str, str, str]]:
    big = [r for r in recs if r["project"]["width"] >= 8192 and r.get("workers") == 2]
    cold = [r for r in big if not r.get("warm")]
    rows: list[tuple[str, str, str]] = []
    for r in cold:
        wmb = _worker_mb(r)
        ratio = r.get("cache_bytes", 0) / max(1, r.get("input_bytes", 1))
        fmt = r["project"].get("format", "ptx")
        rows.append(
            (
                f"{r['project']['stations']} stations of 8192x4096 ({fmt}), 2 workers: peak RSS "
                f"per worker ≤ {WORKER_LIMIT_MB / 1024:.0f} GB",
                f"{_fmt(wmb, '.0f')} MB",
                "met" if wmb is not None and wmb <= WORKER_LIMIT_MB else "NOT met",
            )
        )
        rows.append(
            (
                f"cache ≤ {CACHE_LIMIT}× the input ({fmt})",
                f"{ratio:.2f}×",
                "met" if ratio <= CACHE_LIMIT else "NOT met",
            )
        )
    return rows


def resolution_markdown(state: Record, figures: Sequence[str]) -> str:
    """The ``## Survey at scanner resolution`` section."""
    recs = _recs(state)
    las = state.get("las_reader")
    again = ""
    if state.get("readers_remeasured"):
        when = state["readers_remeasured"]["when"]
        again = f" The readers were measured again after the surveys ({when}, newer code)."
    m = state.get("machine", {})
    loads = [x for r in recs for x in (r["load_before"][0], r["load_after"][0])]
    load = f"{min(loads):.1f}–{max(loads):.1f}" if loads else "?"
    lines = [
        f"Measured with `{_command(state)}` on {m.get('cpu', 'this machine')} "
        f"({m.get('cores', '?')} cores, {m.get('memory_gb', '?')} GB), 1-minute load average "
        f"{load} at the starts and ends of the runs (per run in `results.json`). One synthetic "
        "project (`flexreg synth`, the same scene and stations) at each grid and format; each "
        "survey a child process. *Cold*: an empty output folder; *warm*: the same command "
        "again, its cache reused. Wall time by stage from `poses.json`'s `timings_s`; *read Σ* "
        "and *prepare Σ* are summed over the stations (worker-seconds: hashing and reading "
        "the files, then the rest of their preparation), *prepare* is that stage's wall time; "
        "*start-up + outputs* is the process's wall time beyond the survey's own. *Peak "
        "worker*: the largest high-water mark (`VmHWM`) of any Dask worker process; *main*: "
        "the `flexreg` process; *tree*: the largest sampled sum over all of them.",
        "",
        "### Acceptance (issue 39)",
        "",
        "| criterion | measured | |",
        "|---|---|---|",
        *[f"| {a} | {b} | {c} |" for a, b, c in acceptance(recs)],
        "",
        "### Every run",
        "",
        *run_table(recs),
        "",
        "### The same poses, whatever the number of workers",
        "",
        *(same_poses(recs) or ["No one-worker run in this set."]),
        "",
        "### Reading",
        "",
        "One station file of each project, read as a survey worker reads it (points and "
        "working image) in a child process, against `cat FILE > /dev/null`: the page cache "
        "is emptied before each (`/proc/sys/vm/drop_caches`), so `cat` and the first read "
        "come from the disk; the second read comes from memory (the parser's own speed). "
        "Then the station is prepared in the same child (read again included); its peak "
        "above the child's resident set after its imports is set against its float32 "
        "coordinates (12 bytes a point)." + again,
        "",
        *reader_table(recs + ([{"project": las["project"], "reader": las}] if las else [])),
        "",
        "### 100 stations",
        "",
        *extrapolation(recs),
        "",
        *[f"![{Path(f).stem}]({f})" for f in figures],
    ]
    return "\n".join(lines) + "\n"


def plot_resolution(state: Record, folder: Path) -> list[Path]:
    """Time and memory against points per station (cold and warm, per format)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    recs = [r for r in _recs(state) if _points(r) and r.get("workers") != 1]
    if not recs:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for fmt, marker in (("e57", "o"), ("ptx", "s")):
        for warm, style in ((False, "-"), (True, ":")):
            rs = sorted(
                (r for r in recs if r["project"].get("format", "ptx") == fmt and r["warm"] == warm),
                key=_points,
            )
            if not rs:
                continue
            x = [_points(r) / 1e6 for r in rs]
            tag = f"{fmt} {'warm' if warm else 'cold'}"
            axes[0].plot(x, [r["wall_s"] for r in rs], style, marker=marker, label=tag)
            if not warm:
                axes[1].plot(x, [_worker_mb(r) for r in rs], "-", marker=marker,
                             label=f"{fmt}: peak worker")  # fmt: skip
                axes[1].plot(x, [r["peak_main_mb"] for r in rs], "--", marker=marker,
                             label=f"{fmt}: main process")  # fmt: skip
    axes[1].axhline(WORKER_LIMIT_MB, color="grey", lw=0.8)
    axes[0].set(xlabel="points per station (millions)", ylabel="survey wall time (s)",
                title="Time", ylim=(0, None))  # fmt: skip
    axes[1].set(xlabel="points per station (millions)", ylabel="peak resident set (MB)",
                title="Memory", ylim=(0, None))  # fmt: skip
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path = folder / "survey_resolution.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]
