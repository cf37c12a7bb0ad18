"""A comparison as table rows and Markdown, with notes on what each column means (the console
table of ``flexreg compare`` renders the same rows)."""

from __future__ import annotations

import math

from flexreg.bench.compare import Comparison

__all__ = ["COLUMNS", "notes", "table_rows", "to_markdown"]

COLUMNS: tuple[str, ...] = (
    "method",
    "status",
    "rotation error (°)",
    "translation error (m)",
    "success",
    "verdict",
    "coarse error (° / m)",
    "overlap",
    "overlap RMSE (m)",
    "open3d fitness",
    "open3d inlier_rmse (m)",
    "time (s)",
    "peak memory (MB)",
)


def _num(x: float | None, fmt: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return format(x, fmt)


def _yes(x: bool | None) -> str:
    return "–" if x is None else ("yes" if x else "no")


def table_rows(cmp: Comparison) -> list[dict[str, str]]:
    """One dict of formatted cells per method (keys :data:`COLUMNS`), for every renderer."""
    rows = []
    for r in cmp.runs:
        status = r.status if r.ok else f"{r.status}: {r.message or ''}".strip()
        coarse = (
            f"{_num(r.coarse_rotation_error_deg, '.3f')} / "
            f"{_num(r.coarse_translation_error_m, '.3f')}"
            if r.coarse_rotation_error_deg is not None
            else "–"
        )
        rows.append(
            {
                "method": r.method,
                "status": status,
                "rotation error (°)": _num(r.rotation_error_deg, ".4f"),
                "translation error (m)": _num(r.translation_error_m, ".4f"),
                "success": _yes(r.success),
                "verdict": r.verdict or "–",
                "coarse error (° / m)": coarse,
                "overlap": _num(r.fitness, ".3f"),
                "overlap RMSE (m)": _num(r.inlier_rmse_m, ".4f"),
                "open3d fitness": _num(r.open3d_fitness, ".3f"),
                "open3d inlier_rmse (m)": _num(r.open3d_inlier_rmse_m, ".4f"),
                "time (s)": _num(r.time_s, ".2f"),
                "peak memory (MB)": _num(r.peak_memory_mb, ".0f"),
            }
        )
    return rows


def notes(cmp: Comparison) -> list[str]:
    """What the columns mean, for the Markdown and the console."""
    out = [
        f"Scans: target = {cmp.target} ({cmp.points[0]:,} points), source = {cmp.source} "
        f"({cmp.points[1]:,} points); T_target_source maps the source onto the target.",
        "Success: final transform "
        + cmp.criteria.label()
        + " of the ground truth; coarse error = the transform before refinement (global "
        "methods: flexreg, fpfh-ransac)."
        + ("" if cmp.T_gt is not None else " No ground truth given: no errors, no success."),
        "Verdict: the method's own judgement of its result, before any ground truth is seen "
        "(flexreg: confident or uncertain; n/a: the method gives none, as the baselines).",
        f"Overlap: share of {cmp.fit_denominator} (the figure flexreg register reports); "
        "overlap RMSE over those points; open3d fitness / inlier_rmse: Open3D's "
        "evaluate_registration on the same clouds at the same distance.",
        f"Scale voxel {cmp.scale_m:.4g} m ({cmp.scale_source}); local methods start from "
        + ("the given initial guess." if cmp.T_init is not None else "the identity."),
        "Time: wall time of each method's call alone (scans in memory); peak memory: "
        + cmp.peak_memory
        + f"; {cmp.isolation}.",
    ]
    return out


def to_markdown(cmp: Comparison, *, figure: str | None = None) -> str:
    """The comparison as a Markdown table with its notes (and the bar chart, if given)."""
    rows = table_rows(cmp)
    lines = [
        "| " + " | ".join(COLUMNS) + " |",
        "|---|---|" + "---:|" * 2 + "---|" * 2 + "---:|" * 7,
    ]
    for row in rows:
        cells = [row[c].replace("|", "\\|") for c in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [""] + [f"- {n}" for n in notes(cmp)]
    if figure:
        lines += ["", f"![errors, time and memory per method]({figure})"]
    return "\n".join(lines) + "\n"
