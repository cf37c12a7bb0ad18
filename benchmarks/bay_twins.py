"""Whole-bay twins: would another pose, whole bays along a repeating hall, fit as well?

In a hall of identical bays a pairwise answer several bays off overlays identical structure:
it explains most points and contradicts none, as the truth does (docs/benchmarks.md, Survey,
"the hall folds"). This script measures, for every confident link of a finished survey run,
the answer and the answer moved by whole bays (``--period-m`` along the hall's axis in the
world frame, both ways, up to ``--max-bays``), at the scans' full resolution
(:func:`flexreg.registration.fullres.pose_masks`): the share of both scans' points each
explains and puts in open space. A twin *fits* when its open-space share is at most twice the
answer's (or :data:`FIT_OPEN` if that is larger). The table says, for the links that are right
and the links that are wrong (against the project's ``gt.json``), how much the best fitting
twin explains: a verdict that knew the period could call an answer ambiguous when a twin fits
and explains ``--min-explained`` or more.

The period and the axis come from the synthetic project (the truth), not from the scans: this
measures what such a test would separate, not how to find the period.

Usage::

    .venv/bin/python benchmarks/bay_twins.py RUN_DIR PROJECT/gt.json --period-m 5.6525

``RUN_DIR`` is a survey's output folder (``poses.json``, ``cache/``). Results go to
``benchmarks/results/bay-twins-<timestamp>/results.json`` (and ``results.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from flexreg.bench.harness import results_folder, write_json  # noqa: E402
from flexreg.registration.fullres import FullPair, FullView, full_view, pose_masks  # noqa: E402
from flexreg.registration.settle import explained_share, open_share  # noqa: E402
from flexreg.survey.config import SurveyConfig  # noqa: E402
from flexreg.survey.stations import (  # noqa: E402
    cache_paths,
    config_hash,
    file_hash,
    load_prepared,
)

RESULTS = REPO / "benchmarks" / "results"
#: a twin fits when it puts at most this share, or twice the answer's, in open space
FIT_OPEN = 0.0005
#: an answer counts as right within this distance of the truth, metres
RIGHT_M = 0.05


class Views:
    """Each station's full view, from the run's cache, made once."""

    def __init__(self, run: Path, poses: dict[str, Any]) -> None:
        self.run, self.poses, self.views = run, poses, {}
        self.config = config_hash(SurveyConfig().registration)

    def __call__(self, stem: str) -> FullView:
        if stem not in self.views:
            path = Path(self.poses["stations"][stem]["file"])
            pkl, _ = cache_paths(self.run / "cache", file_hash(path), self.config)
            v = load_prepared(str(pkl)).view
            self.views[stem] = full_view(v.image, v.measured, v.slack, v.normals)
        return self.views[stem]


def twins(
    pair: FullPair, T: np.ndarray, bay_target: np.ndarray, max_bays: int, thr: float
) -> dict[str, Any]:
    """The answer's shares and its best fitting whole-bay twin's."""
    m = pose_masks(pair, T, thr)
    o0, x0 = open_share(m), explained_share(m)
    best: dict[str, Any] = {"explained": 0.0, "open": None, "bays": None}
    for k in [s * b for b in range(1, max_bays + 1) for s in (1, -1)]:
        Tk = T.copy()
        Tk[:3, 3] = T[:3, 3] + k * bay_target
        mk = pose_masks(pair, Tk, thr)
        ok, xk = open_share(mk), explained_share(mk)
        if ok <= max(FIT_OPEN, 2 * o0) and xk > best["explained"]:
            best = {"explained": xk, "open": ok, "bays": k}
    return {"explained": x0, "open": o0, "twin": best}


def summary(rows: list[dict[str, Any]], min_explained: float) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, right in (("right", True), ("wrong", False)):
        tw = [r["twin"]["explained"] for r in rows if r["right"] is right]
        ans = [r["explained"] for r in rows if r["right"] is right]
        out[name] = {
            "links": len(tw),
            "answer_explained_median": statistics.median(ans) if ans else None,
            "twin_explained_min": min(tw, default=None),
            "twin_explained_median": statistics.median(tw) if tw else None,
            "twin_explained_max": max(tw, default=None),
            "refused_at_min_explained": sum(x >= min_explained for x in tw),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a finished survey's output folder")
    ap.add_argument("gt", type=Path, help="the synthetic project's gt.json")
    ap.add_argument("--period-m", type=float, required=True, help="the bay, metres")
    ap.add_argument("--axis", choices=["x", "y"], default="x", help="the hall's axis (world)")
    ap.add_argument("--max-bays", type=int, default=8, help="twins up to this many bays away")
    ap.add_argument("--min-explained", type=float, default=0.2, help="share, 0-1")
    ap.add_argument("--threshold-m", type=float, default=0.06, help="inlier threshold, metres")
    ap.add_argument("--results", type=Path, default=RESULTS)
    args = ap.parse_args()

    poses = json.loads((args.run / "poses.json").read_text())
    truth = {
        s["name"]: np.asarray(s["T_world_scanner"], dtype=np.float64)
        for s in json.loads(args.gt.read_text())["stations"]
    }
    axis = np.array([1.0, 0.0, 0.0] if args.axis == "x" else [0.0, 1.0, 0.0])
    views, rows = Views(args.run, poses), []
    for lk in poses["links"]:
        if lk["T_target_source"] is None or lk["verdict"] != "confident":
            continue
        t, s = lk["target"], lk["source"]
        T = np.asarray(lk["T_target_source"], dtype=np.float64)
        G = np.linalg.inv(truth[t]) @ truth[s]
        bay = truth[t][:3, :3].T @ (args.period_m * axis)  # the bay in the target's frame
        r = twins(FullPair(views(t), views(s)), T, bay, args.max_bays, args.threshold_m)
        r.update(target=t, source=s, status=lk["status"])
        r["off_m"] = float(np.linalg.norm(T[:3, 3] - G[:3, 3]))
        r["right"] = r["off_m"] < RIGHT_M
        rows.append(r)
        print(
            f"{t} <- {s}: {'right' if r['right'] else 'wrong'} ({r['off_m']:.2f} m), answer "
            f"{100 * r['explained']:.1f} % / {100 * r['open']:.3f} % open, best twin "
            f"{100 * r['twin']['explained']:.1f} % ({r['twin']['bays']} bays)",
            flush=True,
        )
    out = {"args": {k: str(v) for k, v in vars(args).items()}, "links": rows}
    out["summary"] = summary(rows, args.min_explained)
    folder = results_folder(args.results, "bay-twins")
    write_json(folder / "results.json", out)
    lines = [
        "| links | count | answer explains (median) | best fitting twin explains "
        "(min / median / max) | twin explains >= min |",
        "|---|---:|---:|---|---:|",
    ]
    for name, v in out["summary"].items():
        if v["links"]:
            lines.append(
                f"| {name} | {v['links']} | {100 * v['answer_explained_median']:.0f} % | "
                f"{100 * v['twin_explained_min']:.0f} / {100 * v['twin_explained_median']:.0f} / "
                f"{100 * v['twin_explained_max']:.0f} % | {v['refused_at_min_explained']} |"
            )
    (folder / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"results: {folder}")


if __name__ == "__main__":
    main()
