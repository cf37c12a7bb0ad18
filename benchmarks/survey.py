"""Whole projects of N stations: ``flexreg survey`` against Open3D's multiway pipeline.

The acceptance of issue 18, measured on synthetic projects (``flexreg synth``; each project
made once under ``--data`` and reused):

* accuracy: at least 4 scene kinds, 10 stations each (``--stations``), at 1024 x 512 and
  2048 x 1024 -- per station the pose error against ``gt.json`` after aligning both frames on
  the reference station (degrees, cm), success (within 0.05 deg and 1 cm, target 95 % of the
  stations), stations placed wrongly (off by more than 1 deg or 10 cm: target zero), groups,
  wall time, peak memory, attempted links; ``flexreg survey`` (default options) and the
  Open3D multiway baseline (:mod:`flexreg.baselines.multiway`, every pair as documented)
  side by side;
* fusion: two sites with no overlap in one folder (6 hall stations, 5 courtyard stations,
  files prefixed ``a_`` and ``b_``, so the file-order neighbours cross the sites): two
  groups, never one;
* resolution (``--sets resolution``, issue 39; its own section of the docs): one project of
  ``--resolution-stations`` (12) stations at 2048 x 1024, 4096 x 2048 and 8192 x 4096, as E57
  and as PTX, surveyed cold and warm with ``--workers`` (2), and the largest grid once with one
  worker -- wall time by stage, every Dask worker's peak memory, cache against input, how
  fast one station file is read against ``cat``, and an extrapolation to 100 stations
  (:mod:`_resolution_report`);
* scaling: a 36- and a 64-station project (``--scaling-kind``) with ``flexreg survey`` --
  wall time, attempted links and peak memory against N -- and the 36-station project again
  with ``--pairs all``. The baseline's time there is extrapolated from its measured time per
  pair and per station (``--scaling-multiway`` runs it: hours).

Every run is a child process (peak memory = largest sampled sum of the resident sets of the
process tree, Dask workers included). ``results.json`` is rewritten after every run;
``--resume FOLDER`` skips the runs a folder already holds. Raw results go to
``benchmarks/results/survey-<timestamp>/``; the Markdown and figures are made by
``_survey_report.py``.

Usage::

    .venv/bin/python benchmarks/survey.py --write-docs          # full run (hours on 2 cores)
    .venv/bin/python benchmarks/survey.py --quick --write-docs  # 1024 x 512, 36 stations
    .venv/bin/python benchmarks/survey.py --resume benchmarks/results/survey-<timestamp>
    .venv/bin/python benchmarks/survey.py --write-docs --from-json \
        benchmarks/results/survey-<timestamp>/results.json      # render a saved run again
                                                                # (several: one page)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _resolution_report import plot_resolution, resolution_markdown  # noqa: E402
from _survey_report import markdown, plot_figures  # noqa: E402
from _survey_runs import METHODS, ProjectSpec, reader_speed, run_multiway, run_one  # noqa: E402

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402

DOC = REPO / "docs" / "benchmarks.md"
FIGURES = REPO / "docs" / "figures"
RESULTS = REPO / "benchmarks" / "results"
DATA = RESULTS / "survey-projects"
SECTION = "## Survey"

LOW, HIGH = (1024, 512), (2048, 1024)
#: the resolution set's station grids (a Leica RTC360 or FARO Focus at normal resolution is
#: about 8192 x 4096) and formats
RESOLUTIONS = ((2048, 1024), (4096, 2048), (8192, 4096))
RESOLUTION_FORMATS = ("e57", "ptx")
RESOLUTION_SECTION = "## Survey at scanner resolution"
#: the project kinds, the multi-station ones first when this version of flexreg has them
PREFERRED_KINDS = ("building", "warehouse", "street")
FALLBACK_KINDS = ("hall", "courtyard", "room", "bays-cue")


def _known_kinds() -> set[str]:
    """Every scene kind ``flexreg synth`` makes: single scenes and multi-station projects."""
    from flexreg.synth import PROJECT_SCENE_KINDS, SCENE_KINDS

    return set(SCENE_KINDS) | set(PROJECT_SCENE_KINDS)


def default_kinds() -> list[str]:
    """Four scene kinds: the multi-station projects, then the older scenes."""
    known = _known_kinds()
    kinds = [k for k in PREFERRED_KINDS if k in known]
    kinds += [k for k in FALLBACK_KINDS if k in known and k not in kinds]
    return kinds[:4]


def default_scaling_kind() -> str:
    return "warehouse" if "warehouse" in _known_kinds() else "hall"


def plan(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every run of the benchmark, in order: ``{"set", "spec", "method", "pairs"}``."""
    kinds = args.kinds or default_kinds()
    resolutions = [LOW] if args.quick else [LOW, HIGH]
    runs: list[dict[str, Any]] = []
    if "accuracy" in args.sets:
        for w, h in resolutions:
            for kind in kinds:
                spec = ProjectSpec(((kind, args.stations, args.seed),), w, h)
                runs += [
                    {"set": "accuracy", "spec": spec, "method": m, "pairs": None}
                    for m in args.methods
                ]
    if "fusion" in args.sets:
        spec = ProjectSpec((("hall", 6, args.seed), ("courtyard", 5, args.seed)), *LOW)
        runs += [{"set": "fusion", "spec": spec, "method": m, "pairs": None} for m in args.methods]
    if "scaling" in args.sets:
        kind = args.scaling_kind or default_scaling_kind()
        sizes = args.scaling_stations or ([36] if args.quick else [36, 64])
        for n in sizes:
            spec = ProjectSpec(((kind, n, args.seed),), *LOW)
            runs.append({"set": "scaling", "spec": spec, "method": "survey", "pairs": None})
            if args.scaling_multiway and "multiway" in args.methods:
                runs.append({"set": "scaling", "spec": spec, "method": "multiway", "pairs": None})
        if not args.no_pairs_all and "survey" in args.methods:
            spec = ProjectSpec(((kind, sizes[0], args.seed),), *LOW)
            runs.append({"set": "scaling", "spec": spec, "method": "survey", "pairs": "all"})
    if "resolution" in args.sets:
        runs += resolution_plan(args)

    # flexreg survey first, the baseline next, the longest runs last: a partial run (see
    # --resume) holds the most useful records; the resolution set as planned (a warm run
    # right after its cold one)
    def cost(r: dict[str, Any]) -> tuple[int, int]:
        if r["set"] == "resolution":
            return (3, 0)
        slow = r["pairs"] == "all" or r["spec"].stations > 40
        return (2 if slow else (0 if r["method"] == "survey" else 1), r["spec"].stations)

    return sorted(runs, key=cost)


def _resolution_projects(args: argparse.Namespace) -> tuple[list[ProjectSpec], ProjectSpec]:
    """The resolution set's projects (each format, each grid) and the largest grid's project
    of the first format."""
    grids = [tuple(int(v) for v in g.split("x")) for g in args.resolutions]
    site = ((args.resolution_kind, args.resolution_stations, args.seed),)
    specs = [ProjectSpec(site, w, h, fmt) for fmt in args.formats for w, h in grids]
    w, h = max(grids, key=lambda g: g[0] * g[1])
    return specs, ProjectSpec(site, w, h, args.formats[0])


def resolution_plan(args: argparse.Namespace) -> list[dict[str, Any]]:
    """The resolution set (issue 39): one project of ``--resolution-stations`` stations per
    grid of :data:`RESOLUTIONS` and format, surveyed cold and warm (its cache reused) with
    ``--workers`` (2 unless given), and the largest grid's first format also cold with one
    worker (the same poses are expected)."""
    workers = args.workers or 2
    runs: list[dict[str, Any]] = []
    specs, largest = _resolution_projects(args)
    for spec in specs:
        for warm in (False, True):
            label = f"survey-w{workers}" + ("-warm" if warm else "")
            runs.append({"set": "resolution", "spec": spec, "method": "survey", "pairs": None,
                         "workers": workers, "warm": warm, "label": label})  # fmt: skip
    if workers != 1:
        runs.append({"set": "resolution", "spec": largest, "method": "survey", "pairs": None,
                     "workers": 1, "warm": False, "label": "survey-w1"})  # fmt: skip
    return runs


def _key(spec_name: str, method: str, pairs: str | None, label: str | None = None) -> str:
    if label:
        return f"{spec_name}--{label}"
    return f"{spec_name}--{method}" + (f"-pairs-{pairs}" if pairs else "")


def run(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """Run the plan, saving ``results.json`` after each run (resuming a saved one)."""
    saved = folder / "results.json"
    state: dict[str, Any]
    if saved.is_file():
        state = json.loads(saved.read_text())
    else:
        state = {
            "benchmark": "survey",
            "command": " ".join([".venv/bin/python benchmarks/survey.py", *sys.argv[1:]]),
            "machine": machine_info(),
            "measured_under_load": True,
            "seed": args.seed,
            "criteria": {
                "success": "within 0.05 deg and 1 cm of the truth (aligned on the reference)",
                "wrong": "posed but off by more than 1 deg or 10 cm, or fused with another site",
            },
            "records": [],
        }
    done = {
        _key(
            r["project"]["name"],
            r["method"],
            r["pairs"],
            r.get("label") if r["set"] == "resolution" else None,
        )
        for r in state["records"]
    }
    todo = plan(args)
    state["plan"] = [
        {"set": r["set"], "project": r["spec"].name, "method": r["method"], "pairs": r["pairs"]}
        for r in todo
    ]
    write_json(saved, state)
    for i, item in enumerate(todo, start=1):
        spec, method, pairs = item["spec"], item["method"], item["pairs"]
        key = _key(spec.name, method, pairs, item.get("label"))
        if key in done:
            continue
        print(f"[{i}/{len(todo)}] {key} ...", flush=True)
        t0 = time.perf_counter()
        rec = run_one(
            spec,
            method,
            data=args.data,
            runs=folder / "runs",
            pairs=pairs,
            workers=item.get("workers", args.workers) if method == "survey" else None,
            timeout_s=args.timeout_min * 60,
            rough=tuple(args.rough_positions) if args.rough_positions else None,
            label=item.get("label"),
            warm=item.get("warm", False),
            reader=item["set"] == "resolution",
        )
        rec["set"] = item["set"]
        state["records"].append(rec)
        ev = rec["evaluation"]
        print(
            f"    exit {rec['exit']}, {rec['wall_s']:.0f} s, {rec['peak_tree_mb']:.0f} MB"
            + (
                f", {ev['success']}/{ev['n']} within tolerance, {ev['wrong']} wrong, "
                f"{ev['reachable']} reachable, "
                f"{ev['groups']} groups, {ev['links_attempted']} links; statuses "
                f"{ev.get('statuses')}, claimed within but outside "
                f"{ev.get('claimed_within_but_outside')}, verified but outside "
                f"{ev.get('verified_outside')}, true error within 3 sigma "
                f"{ev.get('sigma_covered')}/{ev.get('sigma_checked')}"
                if ev
                else ", no poses.json"
            )
            + f" ({time.perf_counter() - t0:.0f} s with the project)",
            flush=True,
        )
        write_json(saved, state)
    if "resolution" in args.sets and ("las_reader" not in state or args.remeasure_readers):
        state["las_reader"] = las_reader(args)
    if args.remeasure_readers:  # the readers changed: measure them again, keep the surveys
        for rec in state["records"]:
            if rec.get("reader"):
                scans = args.data / rec["project"]["name"] / "scans"
                log = Path(rec["run_folder"]) / "reader-log.txt"
                rec["reader"] = reader_speed(scans / rec["reader"]["file"], log)
        state["readers_remeasured"] = {"command": " ".join(sys.argv[1:]), "when": time.ctime()}
    state["load_average_end"] = list(os.getloadavg())
    write_json(saved, state)
    return state


def las_reader(args: argparse.Namespace) -> dict[str, Any] | None:
    """The reader measurement (:func:`_survey_runs.reader_speed`) on a LAS file of the
    resolution set's largest station (the first station of its first format, written once
    next to the project as ``<project>-las/<station>.las``)."""
    from flexreg.io import read_scan, write_scan

    largest = _resolution_projects(args)[1]
    project = args.data / largest.name
    if not (project / "scans").is_dir():
        return None
    first = sorted((project / "scans").iterdir())[0]
    las = project.with_name(project.name + "-las") / (first.stem + ".las")
    if not las.is_file():
        las.parent.mkdir(parents=True, exist_ok=True)
        scan = read_scan(first, intensity=False)
        write_scan(las, replace(scan, grid_shape=None, grid_index=None), resolution_m=1e-4)
    rec = reader_speed(las, las.with_suffix(".log"))
    size = {"width": largest.width, "height": largest.height}
    return {"project": {"name": las.parent.name, **size, "format": "las"}} | rec


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    """Figures and Markdown, next to the results and (``write_docs``) into the docs: the
    resolution set in its own section, the other sets in ``## Survey``."""
    recs = state["records"]
    other = [r for r in recs if r["set"] != "resolution"]
    parts = [
        (plot_figures, markdown, SECTION, "results.md", other),
        (plot_resolution, resolution_markdown, RESOLUTION_SECTION, "resolution.md",
         [r for r in recs if r["set"] == "resolution"]),
    ]  # fmt: skip
    for plot, render, heading, name, records in parts:
        if not records:
            continue
        part = state | {"records": records}
        figures = plot(part, folder)
        names = []
        if write_docs:
            FIGURES.mkdir(parents=True, exist_ok=True)
            for f in plot(part, FIGURES):
                names.append(f.relative_to(DOC.parent).as_posix())
                print(f"updated {f.relative_to(REPO)}")
        else:
            names = [f.name for f in figures]
        doc = DOC if write_docs else None
        publish(render(part, names), folder, doc=doc, heading=heading, name=name)
    print(f"raw results: {folder / 'results.json'}")
    return 0


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="1024x512 only, scaling at 36 stations")
    ap.add_argument("--sets", nargs="+", choices=("accuracy", "fusion", "scaling", "resolution"),
                    default=["accuracy", "fusion", "scaling"])  # fmt: skip
    ap.add_argument("--resolutions", nargs="+", default=[f"{w}x{h}" for w, h in RESOLUTIONS],
                    help="station grids WIDTHxHEIGHT of the resolution set")  # fmt: skip
    ap.add_argument("--formats", nargs="+", choices=RESOLUTION_FORMATS,
                    default=list(RESOLUTION_FORMATS),
                    help="file formats of the resolution set")  # fmt: skip
    ap.add_argument("--resolution-kind", default="building", help="scene of the resolution set")
    ap.add_argument("--remeasure-readers", action="store_true",
                    help="with --resume: measure the readers again, keep the surveys")  # fmt: skip
    ap.add_argument("--resolution-stations", type=int, default=12,
                    help="stations per project of the resolution set")  # fmt: skip
    ap.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    ap.add_argument("--kinds", nargs="+", help="scene kinds of the accuracy set (default: 4)")
    ap.add_argument("--stations", type=int, default=10, help="stations per accuracy project")
    ap.add_argument("--seed", type=int, default=0, help="synthetic-project seed")
    ap.add_argument("--scaling-kind", help="scene kind of the scaling projects")
    ap.add_argument("--scaling-stations", type=int, nargs="+", help="default 36 64")
    ap.add_argument("--scaling-multiway", action="store_true",
                    help="also run the baseline on the scaling projects (hours)")  # fmt: skip
    ap.add_argument("--no-pairs-all", action="store_true", help="skip survey --pairs all")
    ap.add_argument("--workers", type=int, default=None, help="flexreg survey --workers")
    ap.add_argument(
        "--rough-positions",
        type=float,
        nargs=3,
        metavar=("OFF_M", "HEADING_DEG", "SIGMA_M"),
        help="give the survey rough positions of every station (--positions): each OFF_M "
        "from the truth, its heading HEADING_DEG off, SIGMA_M stated",
    )
    ap.add_argument("--timeout-min", type=float, default=90.0, help="per run, minutes")
    ap.add_argument("--data", type=Path, default=DATA, help="where the projects are kept")
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument("--resume", type=Path, metavar="FOLDER", help="continue a results folder")
    ap.add_argument("--write-docs", action="store_true", help=f'rewrite "{SECTION}" in the docs')
    ap.add_argument("--from-json", type=Path, nargs="+", metavar="RESULTS_JSON",
                    help="render saved runs (several: their records on one page)")  # fmt: skip
    ap.add_argument("--run-multiway", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--multiway-pairs", default="all", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or render a saved run; or, internally, one baseline run)."""
    args = _parser().parse_args(argv)
    if args.run_multiway is not None:
        return run_multiway(args.run_multiway, args.out, args.multiway_pairs)
    if args.from_json:
        state = json.loads(args.from_json[0].read_text())
        for extra in args.from_json[1:]:  # runs made in parallel: one page of all their records
            more = json.loads(extra.read_text())
            state["records"] += more["records"]
            state["command"] += "; " + more["command"]
        return finish(state, args.from_json[0].parent, write_docs=args.write_docs)
    # the runs are child processes started in the repository: paths given relative to
    # where this was started are made absolute first
    folder = (args.resume or results_folder(args.results, "survey")).resolve()
    args.data = args.data.resolve()
    folder.mkdir(parents=True, exist_ok=True)
    args.data.mkdir(parents=True, exist_ok=True)
    print(f"results: {folder}", flush=True)
    state = run(args, folder)
    return finish(state, folder, write_docs=args.write_docs)


if __name__ == "__main__":
    raise SystemExit(main())
