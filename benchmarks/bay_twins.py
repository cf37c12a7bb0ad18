"""Whole-bay twins: what the verdict's twin test finds on the links of a finished survey run.

In a hall of identical bays a pairwise answer several bays off overlays identical structure:
it explains most points and contradicts none, as the truth does (docs/registration.md,
"Whole-bay twins of a confident answer"). This script runs the verdict's twin test
(:func:`flexreg.registration.twins.find_twins` and the ``ambiguous`` rule of
:func:`flexreg.registration.verdict.decide`, current configuration) on every link of a
finished survey run that was confident, from the run's cache, and compares each with the
project's truth: how many right and how many wrong links it calls ambiguous, how many of those
the graph had accepted, and the best fitting twin's explained share over the answer's. It
measures the test on answers that were given, so the limits can be chosen before a whole
survey is run again; a survey run with the test on (the default) then shows what it changes.

Usage::

    .venv/bin/python benchmarks/bay_twins.py RUN_DIR PROJECT/gt.json

``RUN_DIR`` is a survey's output folder (``poses.json``, ``cache/``; the cache of an older
configuration is found by the scan's content). Results go to
``benchmarks/results/bay-twins-<timestamp>/results.json`` (and ``results.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from flexreg.bench.harness import results_folder, write_json  # noqa: E402
from flexreg.registration import RegistrationConfig  # noqa: E402
from flexreg.registration.candidates import polisher  # noqa: E402
from flexreg.registration.fullres import FullPair, FullView, full_view  # noqa: E402
from flexreg.registration.pipeline import PreparedScan  # noqa: E402
from flexreg.registration.twins import find_twins  # noqa: E402
from flexreg.registration.verdict import decide  # noqa: E402
from flexreg.survey.stations import file_hash, load_prepared  # noqa: E402

RESULTS = REPO / "benchmarks" / "results"
#: an answer counts as right within this distance of the truth, metres
RIGHT_M = 0.05


class Stations:
    """Each station's prepared scan (from the run's cache, whatever configuration made it)
    and full view, made once."""

    def __init__(self, run: Path, poses: dict[str, Any]) -> None:
        self.run, self.poses = run, poses
        self.kept: dict[str, tuple[PreparedScan, FullView]] = {}

    def __call__(self, stem: str) -> tuple[PreparedScan, FullView]:
        if stem not in self.kept:
            content = file_hash(Path(self.poses["stations"][stem]["file"]))
            found = sorted((self.run / "cache").glob(f"{content[:24]}-*.prepared.pkl"))
            if not found:
                raise SystemExit(f"{self.run / 'cache'}: no prepared station for {stem}")
            p = load_prepared(str(found[0]))
            v = p.view
            self.kept[stem] = (p, full_view(v.image, v.measured, v.slack, v.normals))
        return self.kept[stem]


def judge(
    stations: Stations, link: dict[str, Any], truth: dict[str, np.ndarray], cfg: RegistrationConfig
) -> dict[str, Any]:
    """The twin test on one confident link, against the truth."""
    t, s = link["target"], link["source"]
    T = np.asarray(link["T_target_source"], dtype=np.float64)
    G = np.linalg.inv(truth[t]) @ truth[s]
    (pt, vt), (ps, vs) = stations(t), stations(s)
    thr = float(cfg.threshold_m or 0.06)
    start = time.perf_counter()
    polish = polisher(pt.view.image, pt.view.normals, ps.view.polish_sample, thr)
    up = np.asarray(pt.plan.levelling.up, dtype=np.float64)
    ev = find_twins(FullPair(vt, vs), T, up, polish, thr, cfg.judge)
    verdict = decide({"twins": ev}, judge=cfg.judge)
    a = ev["answer"]
    limit = max(cfg.judge.twin_fit_open, 2 * a["open_share"])
    best = max((w["explained_share"] for w in ev["twins"] if w["open_share"] <= limit), default=0)
    off = float(np.linalg.norm(T[:3, 3] - G[:3, 3]))
    return {
        "target": t,
        "source": s,
        "status": link["status"],
        "off_m": off,
        "right": off < RIGHT_M,
        "ambiguous": not verdict.confident,
        "twin_ratio": best / a["explained_share"] if a["explained_share"] > 0 else 0.0,
        "seconds": time.perf_counter() - start,
        "twins": ev,
    }


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, right in (("right", True), ("wrong", False)):
        sel = [r for r in rows if r["right"] is right]
        out[name] = {
            "links": len(sel),
            "ambiguous": sum(r["ambiguous"] for r in sel),
            "accepted": sum(r["status"] == "accepted" for r in sel),
            "accepted_ambiguous": sum(r["ambiguous"] and r["status"] == "accepted" for r in sel),
            "twin_ratio_max": max((r["twin_ratio"] for r in sel), default=None),
        }
    out["seconds_mean"] = float(np.mean([r["seconds"] for r in rows])) if rows else None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a finished survey's output folder")
    ap.add_argument("gt", type=Path, help="the synthetic project's gt.json")
    ap.add_argument("--results", type=Path, default=RESULTS)
    args = ap.parse_args()

    poses = json.loads((args.run / "poses.json").read_text())
    truth = {
        s["name"]: np.asarray(s["T_world_scanner"], dtype=np.float64)
        for s in json.loads(args.gt.read_text())["stations"]
    }
    cfg, stations, rows = RegistrationConfig(), Stations(args.run, poses), []
    for lk in poses["links"]:
        if lk["T_target_source"] is None or lk["verdict"] != "confident":
            continue
        r = judge(stations, lk, truth, cfg)
        rows.append(r)
        print(
            f"{r['target']} <- {r['source']}: {'right' if r['right'] else 'wrong'} "
            f"({r['off_m']:.2f} m, {r['status']}), best twin {r['twin_ratio']:.2f} of the "
            f"answer, {'ambiguous' if r['ambiguous'] else 'confident'} ({r['seconds']:.2f} s)",
            flush=True,
        )
    out = {"args": {k: str(v) for k, v in vars(args).items()}, "links": rows}
    out["summary"] = summary(rows)
    folder = results_folder(args.results, "bay-twins")
    write_json(folder / "results.json", out)
    lines = [
        "| confident links | count | called ambiguous | accepted by the graph | accepted and "
        "called ambiguous | best fitting twin / answer (max) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name in ("right", "wrong"):
        v = out["summary"][name]
        if v["links"]:
            lines.append(
                f"| {name} | {v['links']} | {v['ambiguous']} | {v['accepted']} | "
                f"{v['accepted_ambiguous']} | {v['twin_ratio_max']:.2f} |"
            )
    (folder / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"mean {out['summary']['seconds_mean']:.2f} s a link; results: {folder}")


if __name__ == "__main__":
    main()
