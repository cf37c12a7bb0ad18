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

This script is the command line; the grid, its data sets and the odometry runs are in
``_paper_tables_runs.py``, the tables and the figure in ``_paper_tables_report.py`` (sibling
modules: running the script puts ``benchmarks/`` on ``sys.path``).

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
import json
import logging
import sys
import tempfile
from datetime import datetime
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _paper_tables_report import markdown, plot  # noqa: E402
from _paper_tables_runs import (  # noqa: E402
    FEATURES,
    METHODS,
    RPE_DELTA,
    RPE_DELTA_QUICK,
    RPE_UNIT,
    VARIANTS,
    datasets,
    run_grid,
)

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402
from flexreg.odometry import OdometryConfig  # noqa: E402

DOC = REPO / "docs" / "paper-reproduction.md"
FIGURE = REPO / "docs" / "figures" / "paper-reproduction.png"
RESULTS = REPO / "benchmarks" / "results"


def _discussion() -> str:
    """The hand-written discussion of the page, kept when it is rewritten.

    Returns
    -------
    str
        The text between the ``<!-- discussion -->`` markers of ``docs/paper-reproduction.md``,
        or a placeholder.
    """
    if DOC.is_file():
        text = DOC.read_text()
        a, b = text.find("<!-- discussion -->"), text.find("<!-- /discussion -->")
        if a >= 0 and b > a:
            return text[a + len("<!-- discussion -->") : b]
    return "(to be written from the tables above)"


def _resumed(
    args: argparse.Namespace, ap: argparse.ArgumentParser, specs: dict[str, Any]
) -> tuple[dict[str, Any], Path]:
    """A saved run to continue (``--resume``), possibly with more data sets; and its folder.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options.
    ap : argparse.ArgumentParser
        Their parser (for errors).
    specs : dict
        The data sets (:func:`datasets`).

    Returns
    -------
    (dict, Path)
        The run (``results.json``) and its results folder.
    """
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
    """The state of a new run (what it will run, on which machine) and its results folder.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options.
    ap : argparse.ArgumentParser
        Their parser (for errors).
    specs : dict
        The data sets (:func:`datasets`).

    Returns
    -------
    (dict, Path)
        The run (``results.json``, no runs yet) and its new results folder.
    """
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


def _parser() -> argparse.ArgumentParser:
    """The command line.

    Returns
    -------
    argparse.ArgumentParser
    """
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
    return ap


def main(argv: list[str] | None = None) -> int:
    """Run the grid (or continue or render a saved run) and write its results.

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
        """Rewrite the run's ``results.json``."""
        write_json(folder / "results.json", state)

    print(f"results: {folder}", flush=True)
    save()
    run_grid(state, args.work_dir, save)
    state["finished"] = f"{datetime.now():%Y-%m-%d %H:%M}"
    save()
    return finish(state, folder, write_docs=args.write_docs)


def finish(state: dict[str, Any], folder: Path, *, write_docs: bool) -> int:
    """Figure, Markdown (printed, saved next to the results, optionally as the docs page).

    Parameters
    ----------
    state : dict
        The run (``results.json``).
    folder : Path
        Its results folder.
    write_docs : bool
        Also rewrite ``docs/paper-reproduction.md`` (keeping its discussion) and its figure.

    Returns
    -------
    int
        The exit status (0).
    """
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
