"""The Markdown and the figure of ``benchmarks/paper_tables.py``, made from its runs.

Tables in the layout of the paper's Tables I-II (best three of each column in bold, the best
also underlined), bridged frames, the computed findings and mean ranks, the set-up text, and
the ATE heat maps.

``paper_tables.py`` imports this module as a sibling: ``python benchmarks/paper_tables.py``
puts ``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import Any

import numpy as np
from _paper_tables_runs import VARIANTS, key


def _cell(v: float | None, rank: int | None, scale: float, digits: int) -> str:
    """A table cell: ``v * scale`` to ``digits`` decimals, bold in the best three of its
    column (``rank``), also underlined as the best; ``–`` for None.

    Parameters
    ----------
    v : float or None
        The value; None for a run that solved no pair.
    rank : int or None
        Its rank in the column (ties share a rank).
    scale : float
        Factor applied before formatting.
    digits : int
        Decimals.

    Returns
    -------
    str
    """
    if v is None:
        return "–"
    s = f"{v * scale:.{digits}f}"
    if rank is None or rank > 3:
        return s
    return f"<ins>**{s}**</ins>" if rank == 1 else f"**{s}**"


def table(
    runs: dict[str, dict[str, Any]],
    dataset: str,
    method: str,
    metric: str,
    features: tuple[str, ...],
    labels: list[str],
    *,
    scale: float,
    digits: int,
) -> list[str]:
    """Markdown table: rows variants, columns features; best three per column bold, best
    underlined (ties share a rank).

    Parameters
    ----------
    runs : dict
        The records by :func:`key`.
    dataset, method, metric : str
        Data set, solver, and the record's field shown.
    features : tuple of str
        The columns.
    labels : list of str
        The rows.
    scale : float
        Factor applied before formatting and ranking.
    digits : int
        Decimals (values equal when rounded share a rank).

    Returns
    -------
    list of str
        Markdown lines; cells of runs not made (yet) are empty.
    """
    vals: dict[tuple[str, str], float | None] = {}
    for lab in labels:
        for f in features:
            rec = runs.get(key(dataset, lab, f, method))
            if rec is None:  # not run (yet)
                continue
            vals[(lab, f)] = rec.get(metric) if rec.get("ok") else None
    ranks: dict[tuple[str, str], int] = {}
    for f in features:
        col = sorted(
            {round(v * scale, digits) for lab in labels if (v := vals.get((lab, f))) is not None}
        )
        for lab in labels:
            v = vals.get((lab, f))
            if v is not None:
                ranks[(lab, f)] = col.index(round(v * scale, digits)) + 1
    head = "| Variant | " + " | ".join(f.upper() for f in features) + " |"
    lines = [head, "|---|" + "---|" * len(features)]
    for lab in labels:
        cells = [
            _cell(vals[(lab, f)], ranks.get((lab, f)), scale, digits) if (lab, f) in vals else ""
            for f in features
        ]
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return lines


def bridged_table(
    runs: dict[str, dict[str, Any]],
    dataset: str,
    method: str,
    features: tuple[str, ...],
    labels: list[str],
    frames: int,
) -> list[str]:
    """Markdown table of the bridged frames (and median inliers) of each variant and feature.

    Parameters
    ----------
    runs : dict
        The records by :func:`key`.
    dataset, method : str
        Data set and solver.
    features : tuple of str
        The columns.
    labels : list of str
        The rows.
    frames : int
        Frames of the sequence (a run that solved no pair bridges ``frames - 1``).

    Returns
    -------
    list of str
        Markdown lines.
    """
    lines = [
        "| Variant | " + " | ".join(f.upper() for f in features) + " |",
        "|---|" + "---|" * len(features),
    ]
    for lab in labels:
        cells = []
        for f in features:
            rec = runs.get(key(dataset, lab, f, method))
            if rec is None:
                cells.append("")
            elif not rec.get("ok"):
                cells.append(f"all {frames - 1}")
            else:
                cells.append(f"{rec['bridged']} ({rec['median_inliers']:.0f})")
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return lines


def findings(state: dict[str, Any]) -> list[str]:
    """Computed statements: Flexion n x n vs Bearing Angle per data set, solver and feature.

    Parameters
    ----------
    state : dict
        The run (``results.json``).

    Returns
    -------
    list of str
        One Markdown list item per solver and metric.
    """
    runs = state["runs"]
    feats = tuple(state["features"])
    flex = [lab for lab, kind, _ in VARIANTS if kind == "flexion"]
    ba = [lab for lab, kind, _ in VARIANTS if kind.startswith("bearing")]
    out: list[str] = []
    for method in state["methods"]:
        for metric, name in (("ate_rmse_m", "ATE"), ("rpe_trans_mean_m", "RPE")):
            wins_best = wins_median = total = 0
            best_n: list[str] = []
            for ds in state["datasets"]:
                for f in feats:
                    fv, bv = (
                        [
                            r[metric]
                            for lab in labels
                            if (r := runs.get(key(ds, lab, f, method))) and r.get("ok")
                        ]
                        for labels in (flex, ba)
                    )
                    if not fv or not bv:
                        continue
                    total += 1
                    wins_best += min(fv) < min(bv)
                    wins_median += statistics.median(fv) < statistics.median(bv)
                    lab_best = min(
                        (
                            (runs[key(ds, lab, f, method)][metric], lab)
                            for lab in flex
                            if runs.get(key(ds, lab, f, method), {}).get("ok")
                        ),
                    )[1]
                    best_n.append(lab_best.split()[-1])
            if total:
                counts = {n: best_n.count(n) for n in sorted(set(best_n), key=best_n.index)}
                out.append(
                    f"- **{method}, {name}**: the best Flexion n×n beats the best Bearing Angle "
                    f"image in {wins_best} of {total} (data set, feature) columns; the median "
                    f"Flexion n×n beats the median Bearing Angle in {wins_median} of {total}. "
                    "Best n per column: "
                    + ", ".join(f"{n} ({c}×)" for n, c in sorted(counts.items()))
                    + "."
                )
    return out


def mean_ranks(state: dict[str, Any]) -> list[str]:
    """Markdown table: each variant's mean rank over all (data set, feature) columns, per
    solver and metric (a run where no pair could be solved ranks last).

    Parameters
    ----------
    state : dict
        The run (``results.json``).

    Returns
    -------
    list of str
        Markdown lines.
    """
    runs = state["runs"]
    labels = [lab for lab, _, _ in VARIANTS if lab in state["variants"]]
    feats = tuple(state["features"])
    dss = [d for d in state["datasets"] if d in state["sequences"]]
    cols = [(m, metric) for m in state["methods"] for metric in ("ate_rmse_m", "rpe_trans_mean_m")]
    ranks: dict[tuple[str, str, str], list[float]] = {}
    for m, metric in cols:
        for ds in dss:
            for f in feats:
                recs = {lab: runs.get(key(ds, lab, f, m)) for lab in labels}
                have = {lab: r for lab, r in recs.items() if r is not None}
                if len(have) < 2:
                    continue
                order = sorted(
                    have, key=lambda lab: have[lab][metric] if have[lab].get("ok") else math.inf
                )
                for i, lab in enumerate(order):
                    ranks.setdefault((lab, m, metric), []).append(i + 1.0)
    head = "| Variant | " + " | ".join(
        f"{m} {'ATE' if metric.startswith('ate') else 'RPE'}" for m, metric in cols
    )
    lines = [head + " |", "|---|" + "---|" * len(cols)]
    for lab in labels:
        cells = []
        for m, metric in cols:
            r = ranks.get((lab, m, metric))
            cells.append(f"{statistics.mean(r):.1f}" if r else "")
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return lines


def _ordinal(k: int) -> str:
    """``2nd``, ``3rd``, ``4th``... (``1`` -> ``""``: every frame).

    Parameters
    ----------
    k : int
        The step.

    Returns
    -------
    str
    """
    if k == 1:
        return ""
    suffix = {1: "st", 2: "nd", 3: "rd"}.get(k % 10 if k % 100 not in (11, 12, 13) else 0, "th")
    return f"{k}{suffix}"


def _setup(state: dict[str, Any]) -> list[str]:
    """Title, data sets and how the images, features, solvers and errors are made.

    Parameters
    ----------
    state : dict
        The run (``results.json``).

    Returns
    -------
    list of str
        Markdown lines.
    """
    delta = state["rpe"]["delta"]
    L: list[str] = ["# Reproducing the paper's odometry comparison", ""]
    L += [
        "Section IV-B-1 of the Flexion paper (Lösch et al.) runs a simple visual odometry on "
        "depth images converted to Flexion and Bearing Angle (BA) images and on the colour "
        "images, with AKAZE, ORB, SIFT and SURF, and scores it by ATE and RPE (its Tables "
        "I–II). `benchmarks/paper_tables.py` reruns that grid with `flexreg odometry`'s "
        "library functions. Everything below is generated from the run's results "
        f"(`{state['command']}`"
        + "".join(f", then `{c}`" for c in state.get("resumed", []))
        + f"; finished {state['finished'] or 'not yet'}), except the discussion.",
        "",
        "## Set-up",
        "",
        "| data set | frames used | duration | ground-truth path | mean step |",
        "|---|---|---|---|---|",
    ]
    for ds, info in state["sequences"].items():
        spec = state["specs"][ds]
        src = (
            f"`flexreg {' '.join(spec['synth'])}`, every {_ordinal(spec['step'])} frame"
            if "synth" in spec
            else f"`{spec['path']}`"
        )
        L.append(
            f"| {spec['title']}: {src} | {info['frames']} | {info['duration_s']:.2f} s | "
            f"{info['path_m']:.3f} m | {info['step_mm']:.1f} mm, {info['step_deg']:.2f}° |"
        )
    L += [
        "",
        "- **Images**: depth median-filtered (3×3, paper sec. III-B-1) after filling isolated "
        "no-reading pixels, converted, mapped to 8 bit (eq. 10 and its Flexion analogue) "
        "without contrast stretching. Flexion angle / normalized and the Bearing Angles use "
        "the 3×3 neighbourhood (BA between adjacent pixels, Harati's definition). *Color* is "
        "the grey version of the colour image (7-Scenes: colour and depth cameras are not "
        "registered, so the depth under a colour keypoint is approximate).",
        "- **Features**: OpenCV "
        f"{state['machine'].get('opencv', '')} defaults (ORB keeps 500 keypoints); keypoints "
        "on pixels without a value are not detected. SURF is not in the pip OpenCV (nonfree): "
        "its column is replaced by KAZE, whose descriptor is SURF-like.",
        "- **essential** (the paper's method): k-NN matches with Lowe's ratio test (0.8), "
        "`cv2.findEssentialMat` (RANSAC, 1 px, p = 0.999), `cv2.recoverPose` (cheirality "
        "distance raised from 50 to 10⁶ baselines, because a Kinect moves millimetres between "
        "frames while the scene is metres away), translation length = median over the inliers "
        "of `t̂ · (P_prev − R P_cur)` from their depth.",
        "- **svd**: the same matches lifted to 3D on the depth images, 3-point RANSAC "
        "(threshold 1.5 % of the median range, at least 1 cm) and a least-squares "
        "Kabsch/Umeyama fit on the inliers.",
        "- A frame pair with fewer than 12 inliers counts as failed; the frame is bridged "
        "(matched against the last good frame, else constant velocity). Bridged frames are "
        "counted below; a run where no pair at all could be solved is shown as –.",
        f"- **ATE**: RMSE of the positions after rigid Horn/Umeyama alignment (TUM definition, "
        f"`flexreg.odometry.evaluation.ate`). **RPE**: mean translational error over {delta:g} s "
        "(`flexreg.odometry.evaluation.rpe`, the TUM tools' fixed-delta definition). The paper's "
        "RPE is "
        "the TUM script's default, which averages over *all* frame pairs; its values are "
        "therefore of the order of the trajectory length (47–110 m on a 483 m path) and not "
        "comparable in size to the drift per second reported here.",
        "- Differences to the paper: its synthetic data set (“Multi-FoV”, a 483 m drive "
        "through a noise-free city) is not available here; the sequences are short hand-held "
        "indoor walks with Kinect-like depth noise. Its ORB-SLAM3 experiments (Tables III–VIII) "
        "are not reproduced.",
        "",
        "Table cells: metres (ATE, RPE); best three per column in **bold**, the best also "
        "<ins>underlined</ins>; – = no frame pair could be solved.",
        "",
    ]
    return L


def _tables(state: dict[str, Any], feats: tuple[str, ...], labels: list[str]) -> list[str]:
    """Per data set and solver: ATE, RPE and bridged-frame tables, numbered.

    Parameters
    ----------
    state : dict
        The run (``results.json``).
    feats : tuple of str
        The feature columns.
    labels : list of str
        The variant rows.

    Returns
    -------
    list of str
        Markdown lines.
    """
    runs = state["runs"]
    delta = state["rpe"]["delta"]
    L: list[str] = []
    num = 1
    for ds in (d for d in state["datasets"] if d in state["sequences"]):
        spec = state["specs"][ds]
        info = state["sequences"][ds]
        L += [f"## {spec['title']}", ""]
        for method in state["methods"]:
            for metric, what in (
                ("ate_rmse_m", "ATE RMSE [m]"),
                ("rpe_trans_mean_m", f"RPE mean translational error over {delta:g} s [m]"),
            ):
                L += [f"**Table {num}.** {what}, `{method}` odometry, {spec['title']}.", ""]
                L += table(runs, ds, method, metric, feats, labels, scale=1.0, digits=4)
                L.append("")
                num += 1
            L += [
                f"**Table {num}.** Bridged frames of {info['frames'] - 1} (median inliers per "
                f"solved pair), `{method}` odometry, {spec['title']}.",
                "",
            ]
            L += bridged_table(runs, ds, method, feats, labels, info["frames"])
            L.append("")
            num += 1
    return L


def markdown(state: dict[str, Any], figure: str | None, discussion: str) -> str:
    """The page: set-up, tables, findings, mean ranks, figure, discussion, how to reproduce.

    Parameters
    ----------
    state : dict
        The run (``results.json``).
    figure : str, optional
        Path of the figure relative to the page; None leaves it out.
    discussion : str
        The hand-written discussion, kept between its markers.

    Returns
    -------
    str
        The Markdown.
    """
    runs = state["runs"]
    feats = tuple(state["features"])
    labels = [lab for lab, _, _ in VARIANTS if lab in state["variants"]]
    L = _setup(state) + _tables(state, feats, labels)
    L += ["## Findings (computed from the tables)", ""]
    L += findings(state)
    L += [
        "",
        f"Mean rank of each variant (1 = best of {len(labels)}) over the "
        f"{len(feats)} features × {len(state['sequences'])} data sets:",
        "",
    ]
    L += mean_ranks(state)
    L.append("")
    if figure:
        L += [
            f"![ATE of every run]({figure})",
            "",
            "*ATE RMSE of every variant and feature, one row per solver and one panel per data "
            "set (logarithmic colour scale per panel); grey: no pair solved.*",
            "",
        ]
    L += ["## Discussion", "", "<!-- discussion -->", discussion.strip(), "<!-- /discussion -->"]
    seconds = sum(r.get("seconds", 0.0) for r in runs.values())
    m = state["machine"]
    L += [
        "",
        "## Reproducing",
        "",
        "```sh",
        ".venv/bin/python benchmarks/paper_tables.py --write-docs   # the full grid",
        ".venv/bin/python benchmarks/paper_tables.py --quick        # a smoke test",
        "```",
        "",
        f"Machine: {m.get('cores', m.get('cpu_count'))} cores ({m['platform']}), "
        f"Python {m['python']}, OpenCV {m.get('opencv', '?')}; "
        f"{len(runs)} runs, {seconds / 60:.0f} min of odometry in total.",
        "",
    ]
    return "\n".join(L)


def plot(state: dict[str, Any], path: Path) -> None:
    """ATE of every run as heat maps: one row per solver, one column per data set.

    Parameters
    ----------
    state : dict
        The run (``results.json``).
    path : Path
        The PNG file (its folder is created).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    runs = state["runs"]
    feats = list(state["features"])
    labels = [lab for lab, _, _ in VARIANTS if lab in state["variants"]]
    methods = list(state["methods"])
    dss = [d for d in state["datasets"] if d in state["sequences"]]
    fig, axes = plt.subplots(
        len(methods), len(dss), figsize=(4.3 * len(dss), 5.0 * len(methods)), squeeze=False
    )
    cmap = plt.get_cmap("viridis").copy()
    cmap.set_bad("0.85")
    for row, method in enumerate(methods):
        for col, ds in enumerate(dss):
            ax = axes[row][col]
            M = np.full((len(labels), len(feats)), np.nan)
            for i, lab in enumerate(labels):
                for j, f in enumerate(feats):
                    r = runs.get(key(ds, lab, f, method))
                    if r and r.get("ok"):
                        M[i, j] = r["ate_rmse_m"]
            finite = np.isfinite(M).any()
            lo = max(float(np.nanmin(M)), 1e-4) if finite else 1e-3
            hi = max(float(np.nanmax(M)), lo * 1.01) if finite else 1.0
            norm = LogNorm(vmin=lo, vmax=hi)
            im = ax.imshow(np.ma.masked_invalid(M), cmap=cmap, norm=norm, aspect="auto")
            for i in range(len(labels)):
                for j in range(len(feats)):
                    if np.isfinite(M[i, j]):
                        bright = norm(M[i, j]) > 0.6
                        ax.text(j, i, f"{M[i, j]:.3f}", ha="center", va="center", fontsize=7,
                                color="k" if bright else "w")  # fmt: skip
            ax.set_xticks(range(len(feats)), [f.upper() for f in feats])
            ax.set_yticks(range(len(labels)), labels if col == 0 else [""] * len(labels))
            ax.set_title(f"{state['specs'][ds]['title'].split(' (')[0]}: {method}", fontsize=9)
            fig.colorbar(im, ax=ax, label="ATE RMSE [m]", shrink=0.8)
    fig.suptitle("ATE of every run (lower is better; colour scale per panel)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
