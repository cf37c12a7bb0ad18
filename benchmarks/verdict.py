"""Can the registration verdict be trusted? The acceptance of issue 17, measured.

Sets (one default ``register`` call per pair, ICP refinement on, seed 0):
  * ambiguous: station pairs of ``symmetric-room``, ``tunnel`` and ``bays`` -- at least 90 %
    must not be confident (uncertain, or failed with nothing written);
  * cue: their one-cue variants -- solved (< 1 deg, < 10 cm) and confident in at least 5 of 6;
  * normal: the synthetic pairs of the registration benchmark (room, courtyard, and the hall),
    made by the same builder (``flexreg.synth.station_pair``) -- every confident answer correct
    and at most 5 % of the correct answers uncertain (false alarms); misses are reported;
  * unrelated: a station of one scene against a station of another (no overlap at all), every
    combination of scene kinds at 1024 x 512 and at 2048 x 1024 (``--mixed``: also a
    1024 x 512 target against a 2048 x 1024 source) -- never confident;
  * alias: pairs of the synthetic building and warehouse projects that a survey once linked
    confidently and wrongly through an identical room, corridor module or rack bay (the true
    pose barely overlaps), and overlapping pairs of the same projects -- never confident and
    wrong;
  * real: 3DTK Kurt3D scan000 <- scan002 (correct within the registration benchmark's limits
    against the odometry, or uncertain with a runner-up near it), and the other real pairs of
    the registration benchmark as further normal pairs.

The Markdown lists the thresholds used (the ``verdict_*`` fields of ``RegistrationConfig``),
the counts per set and the evidence each test reads per group of answers -- what separates
right from wrong answers and so calibrates the thresholds.

Raw results go to ``benchmarks/results/verdict-<timestamp>/`` (``results.json``, rewritten
after every pair, ``config.json``, ``results.md`` and the figure). The runs are in
``_verdict_runs.py``, the Markdown and the figure in ``_verdict_report.py`` (sibling modules:
running the script puts ``benchmarks/`` on ``sys.path``).

Usage::

    .venv/bin/python benchmarks/verdict.py               # full run (~15 min on 2 cores)
    .venv/bin/python benchmarks/verdict.py --write-docs  # also rewrite "## Verdict" in
                                                         # docs/benchmarks.md and its figure
    .venv/bin/python benchmarks/verdict.py --quick       # smoke run (~2 min)
    .venv/bin/python benchmarks/verdict.py --write-docs --from-json \
        benchmarks/results/verdict-<timestamp>/results.json  # render a saved run again
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _verdict_report import markdown, plot_evidence  # noqa: E402
from _verdict_runs import (  # noqa: E402
    AMBIGUOUS_SCENE_KINDS,
    CUE_SCENE_KINDS,
    NORMAL_SCENES,
    SCENE_KINDS,
    SET_NAMES,
    alias_set,
    real_set,
    summarise,
    synthetic_set,
    unrelated_set,
    warm_up,
)

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.registration import RegistrationConfig  # noqa: E402

DOC = REPO / "docs" / "benchmarks.md"
FIGURE = REPO / "docs" / "figures" / "verdict-evidence.png"
RESULTS = REPO / "benchmarks" / "results"
SECTION = "## Verdict"

LOW, HIGH = (1024, 512), (2048, 1024)


def plan(
    quick: bool, seeds: int | None, normal_seeds: int | None, mixed: bool, first_seed: int = 0
) -> dict[str, Any]:
    """What a run registers.

    Parameters
    ----------
    quick : bool
        The smoke run: 2 seeds per kind, the normal pairs at 1024 x 512 only, the unrelated
        pairs among four kinds at 1024 x 512, and 3DTK scan000 <- scan002 alone.
    seeds : int, optional
        Seeds per ambiguous and cue kind (default 6, quick 2).
    normal_seeds : int, optional
        Seeds per normal kind at 1024 x 512 (default 12, quick 2); the first sixth of them (at
        least one) also at 2048 x 1024 (not with ``quick``).
    mixed : bool
        Unrelated pairs also with a 1024 x 512 target and a 2048 x 1024 source.
    first_seed : int
        The first scene seed of the ambiguous, cue and normal sets (a held-out run starts
        past every seed a threshold was set on).

    Returns
    -------
    dict
        JSON-ready: kinds, seeds and resolutions of each set.
    """
    n = seeds if seeds is not None else (2 if quick else 6)
    m = normal_seeds if normal_seeds is not None else (2 if quick else 12)
    normal = [[list(LOW), list(range(first_seed, first_seed + m))]]
    if not quick:
        normal.append([list(HIGH), list(range(first_seed, first_seed + max(1, m // 6)))])
    return {
        "quick": quick,
        "resolution": list(LOW),
        "seeds": list(range(first_seed, first_seed + n)),
        "ambiguous_kinds": list(AMBIGUOUS_SCENE_KINDS),
        "cue_kinds": list(CUE_SCENE_KINDS),
        "normal_kinds": list(NORMAL_SCENES),
        "normal_seeds": list(range(first_seed, first_seed + m)),
        "normal_resolutions": normal,
        "unrelated_kinds": (
            ["room", "courtyard", "symmetric-room", "tunnel"] if quick else list(SCENE_KINDS)
        ),
        "unrelated_resolutions": (
            [[list(LOW), list(LOW)]]
            + ([] if quick else [[list(HIGH), list(HIGH)]])
            + ([[list(LOW), list(HIGH)]] if mixed else [])
        ),
    }


def _parser() -> argparse.ArgumentParser:
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (~2 min)")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per ambiguous/cue kind (6)")
    ap.add_argument("--normal-seeds", type=int, default=None, help="seeds per normal kind (12)")
    ap.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="first scene seed of the ambiguous, cue and normal pairs (held-out runs)",
    )
    ap.add_argument(
        "--mixed",
        action="store_true",
        help="unrelated pairs also 1024x512 <- 2048x1024 (about 4 more minutes)",
    )
    ap.add_argument(
        "--sets",
        nargs="+",
        choices=SET_NAMES,
        default=list(SET_NAMES),
        help="the sets to run (default all)",
    )
    ap.add_argument(
        "--write-docs",
        action="store_true",
        help='rewrite "## Verdict" in docs/benchmarks.md and its figure',
    )
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument(
        "--from-json",
        type=Path,
        metavar="RESULTS_JSON",
        help="render a saved run's results.json again (no registration; with --write-docs)",
    )
    return ap


def _command(args: argparse.Namespace) -> str:
    """The command line of a run as the Markdown shows it (options that differ from the
    defaults)."""
    return ".venv/bin/python benchmarks/verdict.py" + "".join(
        part
        for part, on in (
            (" --quick", args.quick),
            (f" --seeds {args.seeds}", args.seeds is not None),
            (f" --normal-seeds {args.normal_seeds}", args.normal_seeds is not None),
            (f" --first-seed {args.first_seed}", args.first_seed != 0),
            (" --mixed", args.mixed),
            (" --sets " + " ".join(args.sets), list(args.sets) != list(SET_NAMES)),
        )
        if on
    )


def run(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """Register every set of the plan, saving ``results.json`` after each pair.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options.
    folder : Path
        The results folder.

    Returns
    -------
    dict
        The run: command, machine, configuration, plan, the records of each set, the load
        average at start and end, and the total time.
    """
    config = RegistrationConfig(refine=True, seed=0)
    write_json(folder / "config.json", config.to_dict(), indent=2)
    p = plan(args.quick, args.seeds, args.normal_seeds, args.mixed, args.first_seed)
    state: dict[str, Any] = {
        "benchmark": "verdict",
        "command": _command(args),
        "machine": machine_info(),
        "config": config.to_dict(),
        "plan": p,
        "load_average": {"start": list(os.getloadavg()), "end": None},
        "sets": {name: [] for name in args.sets},
    }
    sets = state["sets"]

    def save() -> None:
        """Rewrite the run's ``results.json``."""
        write_json(folder / "results.json", state)

    t0 = time.perf_counter()
    save()
    warm_up(config)
    low = [tuple(p["resolution"])]
    if "ambiguous" in sets:
        synthetic_set(
            "ambiguous", p["ambiguous_kinds"], p["seeds"], low, config, sets["ambiguous"], save
        )
    if "cue" in sets:
        synthetic_set("cue", p["cue_kinds"], p["seeds"], low, config, sets["cue"], save)
    if "normal" in sets:
        for res, seeds in p["normal_resolutions"]:
            synthetic_set(
                "normal", p["normal_kinds"], seeds, [tuple(res)], config, sets["normal"], save
            )
    if "unrelated" in sets:
        combos = [(tuple(a), tuple(b)) for a, b in p["unrelated_resolutions"]]
        unrelated_set(p["unrelated_kinds"], combos, config, sets["unrelated"], save)
    if "real" in sets:
        real_set(config, args.quick, sets["real"], save)
    if "alias" in sets:
        alias_set(config, folder / "projects", sets["alias"], save)
    state["total_s"] = time.perf_counter() - t0
    state["load_average"]["end"] = list(os.getloadavg())
    state["summary"] = {name: summarise(records) for name, records in sets.items()}
    save()
    return state


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    """Figure and Markdown (printed, saved next to the results, optionally into the docs).

    Parameters
    ----------
    state : dict
        The run (``results.json``).
    folder : Path
        Its results folder.
    write_docs : bool
        Also rewrite the section of ``docs/benchmarks.md`` and its figure.

    Returns
    -------
    int
        The exit status (0).
    """
    plot_evidence(state, folder / FIGURE.name)
    figure = None
    if write_docs:
        plot_evidence(state, FIGURE)
        figure = FIGURE.relative_to(DOC.parent).as_posix()
        print(f"updated {FIGURE.relative_to(REPO)}")
    publish(markdown(state, figure), folder, doc=DOC if write_docs else None, heading=SECTION)
    print(f"raw results: {folder / 'results.json'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or render a saved run) and write its results.

    Parameters
    ----------
    argv : list of str, optional
        The options; None reads ``sys.argv``.

    Returns
    -------
    int
        The exit status (0).
    """
    ap = _parser()
    args = ap.parse_args(argv)
    if args.from_json is not None:
        state = json.loads(args.from_json.read_text())
        return finish(state, args.from_json.parent, write_docs=args.write_docs)
    if (args.seeds is not None and args.seeds < 1) or (
        args.normal_seeds is not None and args.normal_seeds < 1
    ):
        ap.error("--seeds and --normal-seeds must be at least 1")
    folder = results_folder(args.results, "verdict")
    print(f"results: {folder}", flush=True)
    state = run(args, folder)
    return finish(state, folder, write_docs=args.write_docs)


if __name__ == "__main__":
    raise SystemExit(main())
