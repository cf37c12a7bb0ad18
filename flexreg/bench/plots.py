"""The benchmarks' figures (matplotlib, drawn off-screen): a comparison's bar chart, success
rate against station distance and yaw, time and peak memory against resolution."""

from __future__ import annotations

import math
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.bench.compare import Comparison
from flexreg.bench.summary import bin_label, success_by

__all__ = ["plot_comparison", "plot_success_vs", "plot_vs_resolution"]


def _pyplot() -> Any:
    """matplotlib's pyplot on the off-screen Agg canvas."""
    import matplotlib  # heavy: only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_comparison(cmp: Comparison, path: str | PathLike[str]) -> Path:
    """Bar chart PNG: rotation and translation error (log scale, success limits dashed), time
    and peak memory per method. Failed methods are marked instead of drawn."""
    plt = _pyplot()
    names = [r.method for r in cmp.runs]
    x = np.arange(len(names))
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.4), dpi=110)
    colour = {True: "#009E73", False: "#D55E00", None: "#56B4E9"}
    panels = (
        (axes[0, 0], "rotation error (°)", [r.rotation_error_deg for r in cmp.runs], True),
        (axes[0, 1], "translation error (m)", [r.translation_error_m for r in cmp.runs], True),
        (axes[1, 0], "time (s)", [r.time_s if r.ok else None for r in cmp.runs], False),
        (axes[1, 1], "peak memory (MB)", [r.peak_memory_mb for r in cmp.runs], False),
    )
    for ax, label, values, log_scale in panels:
        vals = [v if v is not None and math.isfinite(v) else None for v in values]
        heights = [v if v is not None else 0.0 for v in vals]
        if log_scale:
            heights = [
                max(h, 1e-6) if v is not None else 0.0 for h, v in zip(heights, vals, strict=True)
            ]
        ax.bar(x, heights, color=[colour[r.success] for r in cmp.runs])
        for xi, (v, r) in enumerate(zip(vals, cmp.runs, strict=True)):
            if v is None:
                text = r.status if not r.ok else "no ground truth"
                ax.text(
                    xi,
                    0.5,
                    text,
                    rotation=90,
                    ha="center",
                    va="center",
                    fontsize=8,
                    transform=ax.get_xaxis_transform(),
                )
        if log_scale and any(v is not None for v in vals):
            ax.set_yscale("log")
        if label.startswith("rotation"):
            ax.axhline(cmp.criteria.rotation_deg, color="0.3", ls="--", lw=0.8)
        if label.startswith("translation"):
            ax.axhline(cmp.criteria.translation_m, color="0.3", ls="--", lw=0.8)
        ax.set_ylabel(label)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    title = f"{Path(cmp.target).name} ← {Path(cmp.source).name}"
    if cmp.T_gt is not None:
        title += f"  (green: success {cmp.criteria.label()}, orange: not; dashed: limits)"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    p = Path(path)
    fig.savefig(p)
    plt.close(fig)
    return p


def plot_success_vs(
    records: list[dict[str, Any]],
    key: str,
    bins: tuple[tuple[float, float], ...],
    unit: str,
    xlabel: str,
    path: Path,
) -> None:
    """Success rate per bin of ``key``, one line per method."""
    plt = _pyplot()
    table = success_by(records, key, bins)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    x = np.arange(len(bins))
    for i, (method, cells) in enumerate(table.items()):
        rate = [100.0 * s / n if n else np.nan for s, n in cells]
        ax.plot(
            x + (i - len(table) / 2) * 0.02,
            rate,
            marker="os^vDP*"[i % 7],
            lw=2.2 if method == "flexreg" else 1.2,
            label=method,
        )
    counts = [max((c[k][1] for c in table.values()), default=0) for k in range(len(bins))]
    ax.set_xticks(x)
    ax.set_xticklabels(
        [
            f"{bin_label(lo, hi, unit)}\n({n} pairs)"
            for (lo, hi), n in zip(bins, counts, strict=True)
        ]
    )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-5, 105)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_vs_resolution(records: list[dict[str, Any]], value: str, ylabel: str, path: Path) -> None:
    """``value`` (time_s or peak_memory_mb) against the station size, one line per method;
    hollow markers: no success."""
    plt = _pyplot()
    rs = [r for r in records if r["suite"] == "resolution" and r.get("width") is not None]
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    sizes = sorted({(r["width"], r["height"]) for r in rs})
    for i, method in enumerate(dict.fromkeys(r["method"] for r in rs)):
        pts = sorted(
            (
                (r["width"] * r["height"] / 1e6, r[value], bool(r["success"]))
                for r in rs
                if r["method"] == method and r[value] is not None
            ),
        )
        if not pts:
            continue
        xs, ys, ok = zip(*pts, strict=True)
        line = ax.plot(xs, ys, lw=2.2 if method == "flexreg" else 1.2, label=method)[0]
        c = line.get_color()
        mk = "os^vDP*"[i % 7]
        ax.scatter(
            [x for x, o in zip(xs, ok, strict=True) if o],
            [y for y, o in zip(ys, ok, strict=True) if o],
            color=c,
            marker=mk,
        )
        ax.scatter(
            [x for x, o in zip(xs, ok, strict=True) if not o],
            [y for y, o in zip(ys, ok, strict=True) if not o],
            facecolors="none",
            edgecolors=c,
            marker=mk,
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks([w * h / 1e6 for w, h in sizes])
    ax.set_xticklabels([f"{w}x{h}" for w, h in sizes], fontsize=8)
    ax.minorticks_off()
    ax.set_xlabel("station grid (both stations this size)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="best", title="hollow: no success", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
