"""Reproduce the visual-odometry comparison of the Flexion paper (sec. IV-B-1, Tables I-II).

Grid: {Flexion 3x3 .. 13x13, Flexion angle, Flexion normalized, Bearing Angle in four
directions, colour} x {AKAZE, ORB, SIFT, KAZE} on

  (a) the real 7-Scenes redkitchen frames in ../shared/data/rgbd_7scenes_redkitchen
      (60 Kinect frames, KinectFusion poses as ground truth), and
  (b) synthetic RGB-D sequences written by ``flexreg synth --rgbd-frames N`` (procedural
      rooms, Kinect-like depth noise, exact ground truth),

each run with both pose solvers of :mod:`flexreg.odometry.track`: ``essential`` (the paper's 2D-2D
visual odometry: ratio test, findEssentialMat with RANSAC, recoverPose, metric scale from
depth) and ``svd`` (matches lifted to 3D, RANSAC + Kabsch/Umeyama). Scores: ATE RMSE (m, rigid
alignment) and RPE mean translational error over 1 s (m), both from
:mod:`flexreg.odometry.evaluation`.

Tables in the layout of the paper's Tables I-II (rows: image variants, columns: features; best
three of each column in bold, the best also underlined) go to docs/paper-reproduction.md; the
hand-written discussion between the ``<!-- discussion -->`` markers of that file is kept.

Raw results: ``benchmarks/results/paper-tables-<timestamp>/results.json`` (rewritten after
every run, so an interrupted run can be resumed with ``--resume``), ``results.md``, the figure.

Usage::

    .venv/bin/python benchmarks/paper_tables.py --quick            # smoke test (~2 min)
    .venv/bin/python benchmarks/paper_tables.py --write-docs       # full grid, rewrite the doc
    .venv/bin/python benchmarks/paper_tables.py --datasets 7scenes # one data set only
    .venv/bin/python benchmarks/paper_tables.py --resume \
        benchmarks/results/paper-tables-<t>/results.json           # continue an interrupted run
    .venv/bin/python benchmarks/paper_tables.py --write-docs --from-json \
        benchmarks/results/paper-tables-<t>/results.json           # render a saved run again
"""

from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import json
import math
import statistics
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.errors import FlexregError, RegistrationError  # noqa: E402
from flexreg.io.sequence import Sequence, read_sequence  # noqa: E402
from flexreg.odometry import (  # noqa: E402
    FrameFeatures,
    OdometryConfig,
    feature_image,
    frame_features,
    track,
)
from flexreg.odometry.evaluation import ate, rpe  # noqa: E402
from flexreg.stages.keypoints import create_detector  # noqa: E402

DATA = REPO.parent / "shared" / "data"
DOC = REPO / "docs" / "paper-reproduction.md"
FIGURE = REPO / "docs" / "figures" / "paper-reproduction.png"
RESULTS = REPO / "benchmarks" / "results"

#: rows of the tables: (label, image kind, n)
VARIANTS: tuple[tuple[str, str, int], ...] = (
    *((f"Flexion {n}×{n}", "flexion", n) for n in (3, 5, 7, 9, 11, 13)),
    ("Flexion angle", "flexion-angle", 3),
    ("Flexion normalized", "flexion-normalized", 3),
    ("BA horizontal", "bearing-horizontal", 3),
    ("BA vertical", "bearing-vertical", 3),
    ("BA diagonal", "bearing-diagonal", 3),
    ("BA antidiagonal", "bearing-antidiagonal", 3),
    ("Color", "color", 3),
)
FEATURES = ("akaze", "orb", "sift", "kaze")
METHODS = ("essential", "svd")
#: RPE interval: 1 s, the unit of the TUM tools' --fixed_delta (0.25 s for --quick's short runs)
RPE_DELTA, RPE_UNIT = 1.0, "seconds"
RPE_DELTA_QUICK = 0.25


def datasets(quick: bool) -> dict[str, dict[str, Any]]:
    """The sequences: where they come from, which frames are used."""
    frames_7s = 20 if quick else 60
    synth_frames, synth_step = (40, 2) if quick else (135, 3)
    out: dict[str, dict[str, Any]] = {
        "7scenes": {
            "title": "7-Scenes redkitchen (real Kinect, KinectFusion poses)",
            "path": "../shared/data/rgbd_7scenes_redkitchen",
            "frames": frames_7s,
            "step": 1,
        }
    }
    for seed in (1, 2):
        out[f"synth-room-{seed}"] = {
            "title": f"synthetic room, seed {seed} (flexreg synth)",
            "synth": [
                "synth",
                "--scene",
                "room",
                "--stations",
                "1",
                "--resolution",
                "256x128",
                "--rgbd-frames",
                str(synth_frames),
                "--seed",
                str(seed),
            ],
            "frames": synth_frames,
            "step": synth_step,
        }
    return out


# ------------------------------------------------------------------------------ sequences


def prepare(name: str, spec: dict[str, Any], work: Path) -> Sequence:
    """Read (and for synthetic data first write, once) a data set's sequence, subsampled."""
    if "synth" in spec:
        folder = work / name
        argv = [*spec["synth"], "--out", str(folder)]
        stamp = folder / "flexreg-synth-argv.json"
        if not (stamp.is_file() and json.loads(stamp.read_text()) == argv):
            from flexreg.cli import run

            t0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                rc = run(argv)
            if rc != 0:
                raise RuntimeError(f"flexreg {' '.join(argv)} failed ({rc})")
            stamp.write_text(json.dumps(argv))
            print(f"  wrote {folder} ({time.perf_counter() - t0:.0f} s)", flush=True)
        seq = read_sequence(folder)
    else:
        seq = read_sequence(REPO / spec["path"], max_frames=spec["frames"])
    step = int(spec["step"])
    frames = tuple(replace(f, index=k) for k, f in enumerate(seq.frames[::step]))
    return replace(seq, frames=frames)


def describe(seq: Sequence) -> dict[str, Any]:
    """Length and motion of a sequence's ground truth over its frames."""
    from flexreg.core.trajectory import associate

    gt = seq.groundtruth
    assert gt is not None
    ig, _ = associate(gt, seq.timestamps)
    P = gt.positions[np.sort(ig)]
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1)
    R = gt.poses[np.sort(ig), :3, :3]
    rot = [
        math.degrees(math.acos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1)))
        for a, b in itertools.pairwise(R)
    ]
    return {
        "frames": len(seq),
        "duration_s": float(seq.timestamps[-1] - seq.timestamps[0]),
        "path_m": float(steps.sum()),
        "step_mm": 1000 * float(np.mean(steps)),
        "step_deg": float(np.mean(rot)),
        "camera": seq.camera.to_dict() if seq.camera is not None else None,
    }


# ------------------------------------------------------------------------------ runs


def features_for(
    seq: Sequence, image: str, n: int, feats: tuple[str, ...]
) -> tuple[dict[str, list[FrameFeatures]], dict[str, float]]:
    """Every frame's features for one image variant and each detector (conversion shared)."""
    cfgs = {f: OdometryConfig(image=image, n=n, features=f) for f in feats}
    dets = {f: create_detector(f) for f in feats}
    out: dict[str, list[FrameFeatures]] = {f: [] for f in feats}
    secs = {f: 0.0 for f in feats}
    for i in range(len(seq)):
        img = seq.range_image(i)
        color = seq.color_image(i) if image == "color" else None
        conv = feature_image(img, cfgs[feats[0]], color=color)
        for f in feats:
            t0 = time.perf_counter()
            out[f].append(
                frame_features(img, cfgs[f], color=color, index=i, detector=dets[f], converted=conv)
            )
            secs[f] += time.perf_counter() - t0
    return out, secs


def run_one(
    seq: Sequence,
    frames: list[FrameFeatures],
    cfg: OdometryConfig,
    seconds_features: float,
    rpe_delta_s: float,
) -> dict[str, Any]:
    """One odometry run on precomputed features, scored against the ground truth."""
    assert seq.groundtruth is not None
    rec: dict[str, Any] = {"ok": False}
    t0 = time.perf_counter()
    try:
        res = track(frames, seq.timestamps, cfg)
    except RegistrationError as e:
        rec.update(error=str(e), seconds=seconds_features + time.perf_counter() - t0)
        return rec
    try:
        a = ate(seq.groundtruth, res.trajectory)
        r = rpe(seq.groundtruth, res.trajectory, delta=rpe_delta_s, delta_unit=RPE_UNIT)
    except FlexregError as e:
        rec.update(error=f"not evaluated: {e}", seconds=seconds_features + time.perf_counter() - t0)
        return rec
    ok_att = [x for x in res.attempts if x.ok]
    rec.update(
        ok=True,
        ate_rmse_m=a.rmse_m,
        rpe_trans_mean_m=r.trans_mean_m,
        rpe_trans_rmse_m=r.trans_rmse_m,
        rpe_rot_mean_deg=r.rot_mean_deg,
        bridged=len(res.failures),
        failed_attempts=len(res.failed_pairs),
        median_inliers=float(np.median([x.inliers for x in ok_att])) if ok_att else 0.0,
        median_matches=float(np.median([x.matches for x in ok_att])) if ok_att else 0.0,
        seconds=seconds_features + time.perf_counter() - t0,
        path_m=res.trajectory.path_length_m,
    )
    return rec


def key(dataset: str, label: str, feature: str, method: str) -> str:
    return f"{dataset}|{label}|{feature}|{method}"


# ------------------------------------------------------------------------------ tables


def _cell(v: float | None, rank: int | None, scale: float, digits: int) -> str:
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
    underlined (ties share a rank)."""
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
    """Computed statements: Flexion n x n vs Bearing Angle per data set, solver and feature."""
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
    solver and metric (a run where no pair could be solved ranks last)."""
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
    """``2nd``, ``3rd``, ``4th``... (``1`` -> ``""``: every frame)."""
    if k == 1:
        return ""
    suffix = {1: "st", 2: "nd", 3: "rd"}.get(k % 10 if k % 100 not in (11, 12, 13) else 0, "th")
    return f"{k}{suffix}"


def _setup(state: dict[str, Any]) -> list[str]:
    """Title, data sets and how the images, features, solvers and errors are made."""
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
    """Per data set and solver: ATE, RPE and bridged-frame tables, numbered."""
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
    """ATE of every run as heat maps: one row per solver, one column per data set."""
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


# ------------------------------------------------------------------------------ main


def _discussion() -> str:
    if DOC.is_file():
        text = DOC.read_text()
        a, b = text.find("<!-- discussion -->"), text.find("<!-- /discussion -->")
        if a >= 0 and b > a:
            return text[a + len("<!-- discussion -->") : b]
    return "(to be written from the tables above)"


def _resumed(
    args: argparse.Namespace, ap: argparse.ArgumentParser, specs: dict[str, Any]
) -> tuple[dict[str, Any], Path]:
    """A saved run to continue (``--resume``), possibly with more data sets; and its folder."""
    state = json.loads(args.resume.read_text())
    folder = args.resume.parent
    quick = " --quick" in state["command"]
    for name in args.datasets or []:  # a resumed run may take on more data sets
        if name not in state["datasets"]:
            if name not in specs or quick != args.quick:
                ap.error(f"cannot add data set {name!r} to this run")
            state["datasets"].append(name)
            state["specs"][name] = specs[name]
    state.setdefault("resumed", []).append(
        ".venv/bin/python benchmarks/paper_tables.py"
        + (" --quick" if args.quick else "")
        + (" --datasets " + " ".join(args.datasets) if args.datasets else "")
        + " --resume <results.json>"
    )
    return state, folder


def _new_run(
    args: argparse.Namespace, ap: argparse.ArgumentParser, specs: dict[str, Any]
) -> tuple[dict[str, Any], Path]:
    """The state of a new run (what it will run, on which machine) and its results folder."""
    names = args.datasets or list(specs)
    unknown = set(names) - set(specs)
    if unknown:
        ap.error(f"unknown data set(s) {sorted(unknown)}; known: {', '.join(specs)}")
    feats = args.features or (["akaze", "orb"] if args.quick else list(FEATURES))
    variants = [lab for lab, _, _ in VARIANTS]
    if args.quick:
        variants = ["Flexion 3×3", "Flexion 7×7", "BA horizontal", "BA vertical", "Color"]
    command = ".venv/bin/python benchmarks/paper_tables.py" + "".join(
        part
        for part, on in (
            (" --quick", args.quick),
            (" --datasets " + " ".join(names), args.datasets is not None),
            (" --methods " + " ".join(args.methods), args.methods != list(METHODS)),
            (" --features " + " ".join(feats), args.features is not None),
        )
        if on
    )
    folder = results_folder(args.results, "paper-tables")
    state = {
        "benchmark": "paper_tables",
        "command": command,
        "machine": machine_info(),
        "datasets": names,
        "specs": {n: specs[n] for n in names},
        "methods": list(args.methods),
        "features": feats,
        "variants": variants,
        "rpe": {"delta": RPE_DELTA_QUICK if args.quick else RPE_DELTA, "unit": RPE_UNIT},
        "config": OdometryConfig().to_dict(),
        "sequences": {},
        "runs": {},
        "started": f"{datetime.now():%Y-%m-%d %H:%M}",
        "finished": None,
    }
    return state, folder


def _run_grid(state: dict[str, Any], work_dir: Path, save: Callable[[], None]) -> None:
    """Every data set x variant x feature x solver not yet in ``state["runs"]``; saves after
    each variant."""
    kinds = {lab: (kind, n) for lab, kind, n in VARIANTS}
    feats = tuple(state["features"])
    for ds in state["datasets"]:
        print(f"{ds}:", flush=True)
        seq = prepare(ds, state["specs"][ds], work_dir)
        state["sequences"][ds] = describe(seq)
        save()
        for lab in state["variants"]:
            kind, n = kinds[lab]
            if kind == "color" and not seq.has_color:
                continue
            todo = [
                f
                for f in feats
                if any(key(ds, lab, f, m) not in state["runs"] for m in state["methods"])
            ]
            if not todo:
                continue
            t0 = time.perf_counter()
            try:
                frames, secs = features_for(seq, kind, n, tuple(todo))
            except FlexregError as e:
                for f in todo:
                    for m in state["methods"]:
                        state["runs"][key(ds, lab, f, m)] = {"ok": False, "error": str(e)}
                save()
                continue
            for f in todo:
                for m in state["methods"]:
                    k = key(ds, lab, f, m)
                    if k in state["runs"]:
                        continue
                    cfg = OdometryConfig(image=kind, n=n, features=f, method=m)
                    try:
                        state["runs"][k] = run_one(
                            seq, frames[f], cfg, secs[f], state["rpe"]["delta"]
                        )
                    except Exception as e:  # a bug must not end a long run; it is recorded
                        traceback.print_exc()
                        state["runs"][k] = {"ok": False, "error": f"{type(e).__name__}: {e}"}
                    r = state["runs"][k]
                    msg = (
                        f"ATE {r['ate_rmse_m']:.4f} m, RPE {r['rpe_trans_mean_m']:.4f} m, "
                        f"{r['bridged']} bridged"
                        if r.get("ok")
                        else f"failed: {r.get('error', '')[:80]}"
                    )
                    print(f"  {lab:20s} {f:6s} {m:9s} {msg}", flush=True)
                save()
            print(f"  ({lab}: {time.perf_counter() - t0:.0f} s)", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="20/40 frames, ORB + AKAZE, 5 variants")
    ap.add_argument(
        "--datasets", nargs="+", default=None, help="subset of 7scenes, synth-room-1, synth-room-2"
    )
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--features", nargs="+", default=None, choices=FEATURES)
    ap.add_argument("--write-docs", action="store_true", help=f"rewrite {DOC.relative_to(REPO)}")
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument(
        "--work-dir",
        type=Path,
        default=Path(tempfile.gettempdir()) / "flexreg-paper-tables",
        help="where the synthetic sequences are written (reused when present)",
    )
    ap.add_argument("--resume", type=Path, metavar="RESULTS_JSON", help="continue a saved run")
    ap.add_argument("--from-json", type=Path, metavar="RESULTS_JSON", help="render a saved run")
    ap.add_argument("--threads", type=int, default=1, help="OpenCV / numba threads (default 1)")
    args = ap.parse_args(argv)

    if args.from_json is not None:
        state = json.loads(args.from_json.read_text())
        return finish(state, args.from_json.parent, write_docs=args.write_docs)

    import logging

    import cv2
    import numba

    # bridged frames are counted in the tables; their warnings would drown the progress lines
    logging.getLogger("flexreg.odometry.track").setLevel(logging.ERROR)
    cv2.setNumThreads(args.threads)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    specs = datasets(args.quick)
    if args.resume is not None:
        state, folder = _resumed(args, ap, specs)
    else:
        state, folder = _new_run(args, ap, specs)
    folder.mkdir(parents=True, exist_ok=True)

    def save() -> None:
        write_json(folder / "results.json", state)

    print(f"results: {folder}", flush=True)
    save()
    _run_grid(state, args.work_dir, save)
    state["finished"] = f"{datetime.now():%Y-%m-%d %H:%M}"
    save()
    return finish(state, folder, write_docs=args.write_docs)


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    plot(state, folder / "paper-reproduction.png")
    figure = None
    if write_docs:
        plot(state, FIGURE)
        figure = FIGURE.relative_to(DOC.parent).as_posix()
        print(f"updated {FIGURE.relative_to(REPO)}")
    text = markdown(state, figure, _discussion())
    publish(text, folder, doc=DOC if write_docs else None)
    print(f"raw results: {folder / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
