"""Link speed: the pairwise links of a finished survey run, registered again from its cache.

``flexreg survey`` registers every candidate pair from the two stations' cached preparations
(:func:`flexreg.survey.execute.align_link`). This script registers chosen links of a finished
run again, one after another in one process as a survey worker does (numba and BLAS on one
thread, as on a Dask worker), and records per link the wall and CPU seconds, the seconds per
stage, the verdict and the transform. CPU seconds are the figure to compare on a shared
machine: the wall time of one link varies with the load by a factor of two or more.

``--compare RESULTS_JSON`` puts another run of the same links beside it (an earlier commit's,
for instance): CPU seconds before -> after per link, their median and sum, and whether every
decision (verdict, reasons, failure) and every transform is the same (the largest difference
of a matrix entry). ``--profile`` adds a cProfile summary (CPU time) of the links.

Usage::

    .venv/bin/python benchmarks/links.py RUN_DIR --slowest 16 --typical 9
    .venv/bin/python benchmarks/links.py RUN_DIR --links station_31,station_32 --profile
    .venv/bin/python benchmarks/links.py RUN_DIR --from-list earlier/results.json \\
        --compare earlier/results.json

``RUN_DIR`` is a survey's output folder (``poses.json`` lists every link with its seconds;
``cache/`` holds the prepared stations and the links). Results go to
``benchmarks/results/links-<timestamp>/results.json`` (and ``results.md``).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import statistics
import sys
import time
from pathlib import Path
from typing import Any

# one thread per worker, as the survey's Dask workers run (set before numpy loads)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from flexreg.bench.harness import machine_info, results_folder, write_json  # noqa: E402
from flexreg.registration.pipeline import Registration  # noqa: E402
from flexreg.survey.config import SurveyConfig  # noqa: E402
from flexreg.survey.stations import PREPARED_SUFFIX, load_prepared, read_entry  # noqa: E402

RESULTS = REPO / "benchmarks" / "results"
STAGES = ("plan views", "matching", "estimation", "settling", "refinement", "verdict", "overlap")


def cached_links(run: Path) -> tuple[dict[str, str], dict[tuple[str, str], Any]]:
    """Station name -> its prepared cache file, and (target, source) -> the cached link's
    fields (the data-only entries ``<target key>__<source key>[.seed-...].vN.link.npz``)."""
    cache = run / "cache"
    files: dict[str, str] = {}
    links: dict[tuple[str, str], Any] = {}
    for p in sorted((cache / "links").glob("*.link.npz")):
        if ".seed-" in p.name:  # seeded by stored poses, a hand link or rough positions
            continue
        meta, _ = read_entry(p, "link")
        link = meta["link"]
        t, s = p.name.split(".v", 1)[0].split("__")
        files[link["target"]] = str(cache / f"{t}{PREPARED_SUFFIX}")
        files[link["source"]] = str(cache / f"{s}{PREPARED_SUFFIX}")
        links[(link["target"], link["source"])] = link
    return files, links


def chosen(run: Path, args: argparse.Namespace) -> list[tuple[str, str]]:
    """The links to register: given, listed in an earlier result, or the slowest and some
    typical ones (evenly spaced over the middle of the survey's own link seconds)."""
    if args.links:
        return [tuple(x.split(",", 1)) for x in args.links]  # type: ignore[misc]
    if args.from_list:
        return [
            (r["target"], r["source"])
            for r in json.loads(Path(args.from_list).read_text())["links"]
        ]
    poses = json.loads((run / "poses.json").read_text())
    timed = sorted(
        (lk for lk in poses["links"] if lk.get("seconds")), key=lambda lk: -lk["seconds"]
    )
    slow = timed[: args.slowest]
    rest = timed[args.slowest :]
    k = max(1, len(rest) // (args.typical + 1)) if args.typical else 0
    typical = rest[k::k][: args.typical] if k else []
    return [(lk["target"], lk["source"]) for lk in slow + typical]


def register_link(files: dict[str, str], target: str, source: str, config: Any) -> dict[str, Any]:
    """One link registered again from the cache with the run's registration ``config``
    (loading not timed)."""
    pt, ps = load_prepared(files[target]), load_prepared(files[source])
    rec: dict[str, Any] = {"target": target, "source": source}
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        r = Registration(config).align(pt, ps)
    except Exception as e:  # a failed link is an answer too (the survey records it)
        rec["failed"] = f"{type(e).__name__}: {e}"
        r = None
    rec["seconds"], rec["cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    if r is not None:
        v = r.verdict
        rec["verdict"] = None if v is None else v.status
        rec["reasons"] = [] if v is None else [x.code for x in v.reasons]
        rec["T_target_source"] = np.asarray(r.T_target_source).tolist()
        rec["stages_s"] = {k: round(r.timings_s[k], 4) for k in STAGES if k in r.timings_s}
    return rec


def _decision(r: dict[str, Any]) -> tuple[Any, ...]:
    return (r.get("verdict"), tuple(r.get("reasons") or ()), "failed" in r)


def compare(before: list[dict[str, Any]], after: list[dict[str, Any]]) -> dict[str, Any]:
    """CPU seconds before -> after on the links both runs hold, and what changed."""
    old = {(r["target"], r["source"]): r for r in before}
    rows = []
    for r in after:
        b = old.get((r["target"], r["source"]))
        if b is None:
            continue
        dT = None
        if "T_target_source" in r and "T_target_source" in b:
            dT = float(np.abs(np.subtract(r["T_target_source"], b["T_target_source"])).max())
        rows.append(
            {
                "link": f"{r['target']} <- {r['source']}",
                "before_cpu_s": b["cpu_s"],
                "after_cpu_s": r["cpu_s"],
                "same_decision": _decision(r) == _decision(b),
                "max_T_difference": dT,
            }
        )
    bc, ac = [x["before_cpu_s"] for x in rows], [x["after_cpu_s"] for x in rows]
    return {
        "rows": rows,
        "median_before_s": statistics.median(bc) if bc else None,
        "median_after_s": statistics.median(ac) if ac else None,
        "sum_before_s": sum(bc),
        "sum_after_s": sum(ac),
        "decisions_changed": sum(not x["same_decision"] for x in rows),
        "max_T_difference": max((x["max_T_difference"] or 0.0 for x in rows), default=0.0),
    }


def markdown(links: list[dict[str, Any]], cmp: dict[str, Any] | None) -> str:
    lines = ["| link | CPU s | wall s | verdict | " + " | ".join(STAGES) + " |"]
    lines.append("|---|---:|---:|---|" + "---:|" * len(STAGES))
    for r in links:
        st = r.get("stages_s", {})
        lines.append(
            f"| {r['target']} <- {r['source']} | {r['cpu_s']:.2f} | {r['seconds']:.2f} | "
            f"{r.get('verdict') or 'failed'} | "
            + " | ".join(f"{st[k]:.2f}" if k in st else "" for k in STAGES)
            + " |"
        )
    if cmp is not None:
        lines += ["", "| link | CPU s before | CPU s after | same decision | max T difference |"]
        lines.append("|---|---:|---:|---|---:|")
        for x in cmp["rows"]:
            d = x["max_T_difference"]
            lines.append(
                f"| {x['link']} | {x['before_cpu_s']:.2f} | {x['after_cpu_s']:.2f} | "
                f"{'yes' if x['same_decision'] else '**no**'} | {'' if d is None else f'{d:.1e}'} |"
            )
        lines.append(
            f"\nMedian {cmp['median_before_s']:.2f} -> {cmp['median_after_s']:.2f} s, sum "
            f"{cmp['sum_before_s']:.1f} -> {cmp['sum_after_s']:.1f} s CPU; "
            f"{cmp['decisions_changed']} decisions changed; largest transform difference "
            f"{cmp['max_T_difference']:.1e}."
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a finished survey's output folder")
    ap.add_argument("--links", nargs="*", default=[], help="TARGET,SOURCE station names")
    ap.add_argument("--from-list", help="the links of an earlier results.json")
    ap.add_argument("--slowest", type=int, default=16, help="slowest links of the run")
    ap.add_argument("--typical", type=int, default=9, help="links spread over the rest")
    ap.add_argument("--compare", help="an earlier results.json of the same links")
    ap.add_argument("--profile", action="store_true", help="cProfile summary (CPU time)")
    ap.add_argument("--results", type=Path, default=RESULTS)
    args = ap.parse_args()
    files, _ = cached_links(args.run)
    poses = json.loads((args.run / "poses.json").read_text())
    config = SurveyConfig.model_validate(poses.get("config") or {}).registration
    todo = chosen(args.run, args)
    folder = results_folder(args.results, "links")
    prof = cProfile.Profile(time.process_time) if args.profile else None
    out: list[dict[str, Any]] = []
    for target, source in todo:
        if prof is not None:
            prof.enable()
        rec = register_link(files, target, source, config)
        if prof is not None:
            prof.disable()
        out.append(rec)
        print(
            f"{target} <- {source}: {rec['cpu_s']:.2f} s CPU, {rec['seconds']:.2f} s wall, "
            f"{rec.get('verdict') or rec.get('failed')}",
            flush=True,
        )
    cmp = None
    if args.compare:
        cmp = compare(json.loads(Path(args.compare).read_text())["links"], out)
    summary = {"machine": machine_info(), "run": args.run.name, "links": out, "compare": cmp}
    if prof is not None:
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(25)
        summary["profile"] = s.getvalue()
        print(summary["profile"])
    write_json(folder / "results.json", summary)
    text = markdown(out, cmp)
    (folder / "results.md").write_text(text)
    print(text)
    print(f"results: {folder}")


if __name__ == "__main__":
    main()
