"""Registration accuracy and speed: synthetic station pairs, two 4096 x 2048 stations, real pairs.

Sections (the acceptance criteria of ``flexreg.registration.pipeline.register``)
  * synthetic suite: ``--pairs`` room and ``--pairs`` courtyard station pairs (seeds 0..N-1) from
    :func:`flexreg.synth.station_pair` -- stations 2-10 m apart, any yaw, tilt up to 5 deg, 3 mm
    range noise -- each registered once with ICP refinement, which gives both the coarse
    (``T_coarse``) and the refined transform. Success before refinement: ``T_coarse`` within
    0.5 deg and 5 cm of the truth (target: at least 95 % of the pairs). Targets after
    refinement: median error below 0.01 deg and 2 mm. A pair whose ``register`` raises counts as
    a failure, with infinite error in the medians.
  * speed: two 4096 x 2048 room stations (seed 0); only the ``register`` call is timed (no
    loading or synthesis), with and without refinement; target at most 10 s with refinement.
  * real pairs from ``../shared/data``: the Stanford bunny (bun000 <- bun045, ground truth from
    bun.conf), the three 3DTK Kurt3D scans (no ground truth: the difference to the odometry
    prior is reported; the prior is not given to ``register``) and two Velodyne scans of the
    fast_gicp repository (reference: its relative.txt, itself a registration result).

Every ``register`` call uses the default :class:`flexreg.registration.pipeline.RegistrationConfig`
with
``refine=True``, ``seed=--seed`` and the ``open3d`` check (Open3D's fitness and inlier
RMSE beside the overlap in the tables). One warm-up call on a small pair comes first (numba kernels
compile or load from the cache then); it is not part of any figure.

Raw per-pair results go to ``benchmarks/results/registration-<timestamp>/`` (``results.json``,
rewritten after every pair, ``config.json``, ``results.md`` and the figure).

This script is the command line; the ``register`` calls and the criteria are in
``_registration_runs.py``, the Markdown and the figure in ``_registration_report.py`` (sibling
modules: running the script puts ``benchmarks/`` on ``sys.path``).

Usage::

    .venv/bin/python benchmarks/registration.py               # full run: print the tables
    .venv/bin/python benchmarks/registration.py --write-docs  # also rewrite "## Registration"
                                                              # in docs/benchmarks.md + figure
    .venv/bin/python benchmarks/registration.py --quick       # 3 + 3 pairs at 1024x512, no
                                                              # 4096 x 2048 run (smoke test)
    .venv/bin/python benchmarks/registration.py --write-docs --from-json \
        benchmarks/results/registration-<timestamp>/results.json  # render a saved run again
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _registration_report import markdown, plot_synthetic  # noqa: E402
from _registration_runs import (  # noqa: E402
    BUNNY_ROT_DEG,
    BUNNY_TRANS_M,
    COARSE_ROT_DEG,
    COARSE_TRANS_M,
    FAILURE_ERRORS,
    TARGET_ROT_DEG,
    TARGET_SPEED_S,
    TARGET_SUCCESS,
    TARGET_TRANS_M,
    real_pairs,
    speed_run,
    summarise,
    synthetic_suite,
    warm_up,
)

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.registration import RegistrationConfig  # noqa: E402
from flexreg.registration.config import DEFAULT_CHECKS  # noqa: E402

DOC = REPO / "docs" / "benchmarks.md"
FIGURE = REPO / "docs" / "figures" / "registration-synthetic.png"
RESULTS = REPO / "benchmarks" / "results"
SECTION = "## Registration"


def _resolution(text: str) -> tuple[int, int]:
    """Parse a ``--resolution`` value.

    Parameters
    ----------
    text : str
        ``WIDTHxHEIGHT``.

    Returns
    -------
    (int, int)
        Width and height.

    Raises
    ------
    argparse.ArgumentTypeError
        Not two integers joined by ``x``, or smaller than 16 x 8.
    """
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if w < 16 or h < 8:
        raise argparse.ArgumentTypeError(f"resolution too small: {text!r}")
    return w, h


def _parser() -> argparse.ArgumentParser:
    """The command line.

    Returns
    -------
    argparse.ArgumentParser
    """
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=None, help="pairs per scene kind (default 12)")
    ap.add_argument(
        "--resolution", type=_resolution, default=None, help="synthetic WIDTHxHEIGHT (2048x1024)"
    )
    ap.add_argument(
        "--speed-resolution", type=_resolution, default=(4096, 2048), help="speed-run stations"
    )
    ap.add_argument("--speed-repeats", type=int, default=2, help="timed calls per speed setting")
    ap.add_argument("--seed", type=int, default=0, help="RegistrationConfig seed")
    ap.add_argument("--quick", action="store_true", help="3 + 3 pairs at 1024x512, no speed run")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic suite")
    ap.add_argument("--no-real", action="store_true", help="skip the real pairs")
    ap.add_argument("--no-speed", action="store_true", help="skip the 4096 x 2048 run")
    ap.add_argument(
        "--write-docs",
        "--update-docs",
        action="store_true",
        help='rewrite "## Registration" in docs/benchmarks.md and its figure',
    )
    ap.add_argument("--results", type=Path, default=RESULTS, help="parent of the result folder")
    ap.add_argument(
        "--from-json",
        type=Path,
        metavar="RESULTS_JSON",
        help="render a saved run's results.json again (no registration; with --write-docs)",
    )
    return ap


def _command(args: argparse.Namespace, pairs: int, resolution: tuple[int, int]) -> str:
    """The command line of a run as the Markdown shows it: the options that differ from the
    defaults.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options.
    pairs : int
        Pairs per scene kind.
    resolution : (int, int)
        Width and height of the synthetic stations.

    Returns
    -------
    str
    """
    return ".venv/bin/python benchmarks/registration.py" + "".join(
        part
        for part, on in (
            (" --quick", args.quick),
            (f" --pairs {pairs}", args.pairs is not None),
            (f" --resolution {resolution[0]}x{resolution[1]}", args.resolution is not None),
            (
                f" --speed-resolution {args.speed_resolution[0]}x{args.speed_resolution[1]}",
                args.speed_resolution != (4096, 2048),
            ),
            (f" --speed-repeats {args.speed_repeats}", args.speed_repeats != 2),
            (f" --seed {args.seed}", args.seed != 0),
            (" --no-synthetic", args.no_synthetic),
            (" --no-real", args.no_real),
            (" --no-speed", args.no_speed),
        )
        if on
    )


def _new_state(
    command: str, config: RegistrationConfig, resolution: tuple[int, int]
) -> dict[str, Any]:
    """The ``results.json`` of a run before its first pair.

    Parameters
    ----------
    command : str
        The command line (:func:`_command`).
    config : RegistrationConfig
        The configuration of every call.
    resolution : (int, int)
        Width and height of the synthetic stations.

    Returns
    -------
    dict
        Command, machine, configuration, criteria, the load average at the start and empty
        sections.
    """
    return {
        "benchmark": "registration",
        "command": command,
        "machine": machine_info(),
        "config": config.to_dict(),
        "criteria": {
            "coarse_success": {"rot_deg": COARSE_ROT_DEG, "trans_m": COARSE_TRANS_M},
            "coarse_success_rate": TARGET_SUCCESS,
            "median_refined": {"rot_deg": TARGET_ROT_DEG, "trans_m": TARGET_TRANS_M},
            "speed_s": TARGET_SPEED_S,
            "bunny": {"rot_deg": BUNNY_ROT_DEG, "trans_m": BUNNY_TRANS_M},
        },
        "resolution": list(resolution),
        "load_average": {"start": list(os.getloadavg()), "end": None},
        "synthetic": [],
        "speed": None,
        "real": None,
    }


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
        return finish(
            load_results(args.from_json), args.from_json.parent, write_docs=args.write_docs
        )
    pairs = args.pairs if args.pairs is not None else (3 if args.quick else 12)
    resolution = args.resolution or ((1024, 512) if args.quick else (2048, 1024))
    if pairs < 1 or args.speed_repeats < 1:
        ap.error("--pairs and --speed-repeats must be at least 1")
    do_speed = not (args.no_speed or args.quick)

    command = _command(args, pairs, resolution)
    # Open3D's evaluate_registration beside the overlap: the tables show both
    config = RegistrationConfig(
        refine=True, seed=args.seed, judge={"checks": (*DEFAULT_CHECKS, "open3d")}
    )
    folder = results_folder(args.results, "registration")
    write_json(folder / "config.json", config.to_dict(), indent=2)
    state = _new_state(command, config, resolution)

    def save() -> None:
        """Rewrite the run's ``results.json``."""
        write_json(folder / "results.json", state)

    print(f"results: {folder}", flush=True)
    save()
    warm_up(config)
    if not args.no_synthetic:
        synthetic_suite(pairs, resolution, config, save, state["synthetic"])
        state["summary"] = summarise(state["synthetic"])
        save()
    if do_speed:
        state["speed"] = speed_run(args.speed_resolution, config, args.speed_repeats)
        save()
    if not args.no_real:
        state["real"] = real_pairs(config)
        save()
    state["load_average"]["end"] = list(os.getloadavg())
    save()

    return finish(state, folder, write_docs=args.write_docs)


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    """Figure, Markdown (printed, saved next to the results, optionally into the docs).

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
    figure = None
    if state["synthetic"]:
        plot_synthetic(state["synthetic"], folder / "registration-synthetic.png")
        if write_docs:
            plot_synthetic(state["synthetic"], FIGURE)
            figure = FIGURE.relative_to(DOC.parent).as_posix()
            print(f"updated {FIGURE.relative_to(REPO)}")
    text = markdown(state, figure)
    publish(text, folder, doc=DOC if write_docs else None, heading=SECTION)
    print(f"raw results: {folder / 'results.json'}")
    return 0


def load_results(path: Path) -> dict[str, Any]:
    """A saved ``results.json``, with the infinite errors of failed pairs restored (JSON holds
    them as null) and the synthetic summary recomputed from them.

    Parameters
    ----------
    path : Path
        The ``results.json`` of a run.

    Returns
    -------
    dict
        The run, as :func:`main` had it.
    """
    state = json.loads(path.read_text())
    records = list(state.get("synthetic") or []) + list(state.get("real") or [])
    if state.get("speed"):
        records += [r for runs in state["speed"]["runs"].values() for r in runs]
    for r in records:
        if r.get("ok") is False:
            r |= {k: math.inf for k in FAILURE_ERRORS if r.get(k) is None}
    if state.get("synthetic"):
        state["summary"] = summarise(state["synthetic"])
    return state


if __name__ == "__main__":
    raise SystemExit(main())
