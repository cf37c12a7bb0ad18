"""Memory and speed: whole-process peak RSS and time of ``flexreg register`` on PTX pairs of
several sizes, one station's survey preparation, and the registration call against Open3D
FPFH + RANSAC + ICP on the comparison suite.

Sections (the memory and speed targets of issue 20; benchmarks, not tests)
  * whole process: ``flexreg register a.ptx b.ptx --truth gt.json --out T.json`` on synthetic
    room pairs (``flexreg synth``, seed 0) at each ``--sizes`` resolution, as a user runs it:
    interpreter start, imports, PTX parsing, registration, writing. Peak RSS of the whole
    process from the kernel (``ru_maxrss``), wall and CPU seconds; the 2048 x 1024 pair is run
    ``--repeats`` times (median). Targets: peak <= 0.6 GB at 2048 x 1024, <= 3 GB at
    8192 x 4096; wall time <= 2 s at 2048 x 1024.
  * per-stage profile: the stage timings ``register`` reports for the 2048 x 1024 pair, the
    start-up (interpreter + ``import flexreg.cli``) and PTX parsing.
  * survey preparation: one station read and prepared (``Registration.prepare``) in a fresh
    process; peak RSS above the process after its imports against the station's float32 xyz
    grid. Target: <= 1.5 x.
  * speed ratio: ``flexreg bench``'s synthetic pairs with flexreg and fpfh-ransac (Open3D FPFH
    + RANSAC + point-to-plane ICP), pair by pair in the same run; median of the per-pair
    ratios. Target: >= 10 x.

Usage::

    .venv/bin/python benchmarks/perf.py                  # everything (8192 x 4096 included)
    .venv/bin/python benchmarks/perf.py --write-docs     # also rewrite "## Memory and speed"
    .venv/bin/python benchmarks/perf.py --quick          # 1024x512 + 2048x1024, 4 pairs
    .venv/bin/python benchmarks/perf.py --sizes 1024x512 2048x1024 4096x2048   # (disk space)
    .venv/bin/python benchmarks/perf.py --write-docs --from-json RESULTS_JSON
    .venv/bin/python benchmarks/perf.py --before BEFORE_JSON --before-note "main at abc123"

``--before`` shows an earlier code's whole-process figures beside these (the "before -> after"
table and the grey line of the figure): run ``benchmarks/_perf_runs.whole_register`` with that
code first (for instance from an exported tree on ``PYTHONPATH``) and save its summaries by pair
folder name.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _perf_report import hard_markdown, markdown, plot  # noqa: E402
from _perf_runs import (  # noqa: E402
    import_time,
    prepare_station,
    speed_ratio,
    synth_pair,
    whole_register,
)

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402

DOC = REPO / "docs" / "benchmarks.md"
FIGURE = REPO / "docs" / "figures" / "perf-memory.png"
RESULTS = REPO / "benchmarks" / "results"
SECTION = "## Memory and speed"
SIZES = ((1024, 512), (2048, 1024), (4096, 2048), (8192, 4096))
HARD_SECTION = "## Registration call on harder pairs"
#: the harder pairs (issue 39): 2 m / 30 degrees and 6 m / 60 degrees apart, in furnished
#: rooms and halls (the comparison suite alternates the two scenes)
HARD_BINS = {"distance_bins_m": ((1.5, 2.5), (5.5, 6.5)), "yaw_bins_deg": ((25, 35), (55, 65))}


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="two small sizes, 4 comparison pairs")
    ap.add_argument(
        "--sizes",
        nargs="+",
        metavar="WxH",
        help="pair sizes to run (default: 1024x512 2048x1024 4096x2048 8192x4096); the survey "
        "preparation runs at each size from 2048x1024 up",
    )
    ap.add_argument("--repeats", type=int, default=3, help="runs of the 2048 x 1024 pair")
    ap.add_argument("--pairs", type=int, default=16, help="comparison-suite pairs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", type=Path, default=None, help="folder for the synthetic pairs")
    ap.add_argument("--no-compare", action="store_true", help="skip the FPFH comparison")
    ap.add_argument("--write-docs", action="store_true", help=f'rewrite "{SECTION}"')
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--from-json", type=Path, metavar="RESULTS_JSON")
    ap.add_argument(
        "--before",
        type=Path,
        metavar="JSON",
        help="whole-process figures of earlier code to show beside these: a JSON object of "
        "pair folder name -> that pair's entry of another run's results.json 'whole'",
    )
    ap.add_argument("--before-note", default="main", help="what the --before code was")
    ap.add_argument(
        "--hard",
        nargs="+",
        metavar="WxH",
        help=f'only the harder pairs at these sizes, flexreg against FPFH ("{HARD_SECTION}")',
    )
    return ap


def _run_hard(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """The registration call against FPFH + RANSAC + ICP on the harder pairs at each size."""
    state: dict[str, Any] = {
        "command": f"benchmarks/perf.py --hard {' '.join(args.hard)} --pairs {args.pairs}",
        "machine": machine_info(),
        "bins": HARD_BINS,
        "hard": [],
    }
    for x in args.hard:
        w, h = (int(v) for v in x.lower().split("x"))
        print(f"harder pairs {w}x{h} (flexreg, fpfh-ransac)", flush=True)
        cmp = speed_ratio(args.pairs, args.seed, resolution=(w, h), **HARD_BINS)
        state["hard"].append(cmp)
        write_json(folder / "results.json", state)
    state["machine"]["load_average_end"] = machine_info().get("load_average")
    write_json(folder / "results.json", state)
    return state


def _run(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    sizes = SIZES[:2] if args.quick else SIZES
    if args.sizes:
        sizes = tuple(tuple(int(v) for v in x.lower().split("x")) for x in args.sizes)
    prepare_at = {wh for wh in sizes if wh[0] * wh[1] >= 2048 * 1024}  # survey-sized stations
    data = args.data or (args.results / "perf-data")
    state: dict[str, Any] = {
        "command": "benchmarks/perf.py"
        + (" --quick" if args.quick else "")
        + (f" --sizes {' '.join(args.sizes)}" if args.sizes else "")
        + (" --no-compare" if args.no_compare else ""),
        "machine": machine_info(),
        "whole": [],
        "prepare": [],
    }
    save = lambda: write_json(folder / "results.json", state)  # noqa: E731
    state["startup"] = import_time(args.repeats)
    save()
    for w, h in sizes:
        pair = synth_pair(data, w, h, args.seed)
        repeats = args.repeats if (w, h) == (2048, 1024) else 1
        print(f"register {w}x{h} x{repeats}", flush=True)
        state["whole"].append({"width": w, "height": h, **whole_register(pair, repeats)})
        save()
        if (w, h) in prepare_at:
            print(f"prepare {w}x{h}", flush=True)
            state["prepare"].append(prepare_station(pair / "station_00.ptx"))
            save()
    if not args.no_compare:
        print("comparison suite (flexreg, fpfh-ransac)", flush=True)
        state["compare"] = speed_ratio(4 if args.quick else args.pairs, args.seed)
    state["machine"]["load_average_end"] = machine_info().get("load_average")
    save()
    return state


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.hard:
        folder = args.from_json.parent if args.from_json else results_folder(args.results, "perf")
        hard = json.loads(args.from_json.read_text()) if args.from_json else _run_hard(args, folder)
        doc = DOC if args.write_docs else None
        publish(hard_markdown(hard), folder, doc=doc, heading=HARD_SECTION, name="hard.md")
        return 0
    if args.from_json is not None:
        state = json.loads(args.from_json.read_text())
        folder = args.from_json.parent
    else:
        folder = results_folder(args.results, "perf")
        os.environ.setdefault("PYTHONHASHSEED", "0")
        state = _run(args, folder)
    if args.before is not None:
        state["before"] = json.loads(args.before.read_text())
        state["before_note"] = args.before_note
        write_json(folder / "results.json", state)
    fig = folder / "perf-memory.png"
    plot(state, fig)
    text = markdown(state, figure="figures/perf-memory.png")
    if args.write_docs:
        FIGURE.parent.mkdir(parents=True, exist_ok=True)
        FIGURE.write_bytes(fig.read_bytes())
    publish(text, folder, doc=DOC if args.write_docs else None, heading=SECTION)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
