"""Any two clouds: flexreg's routes (``--method auto|flexion|geometric``) against Open3D FPFH +
RANSAC + ICP on clouds that are not terrestrial stations.

Sets (each pair with its truth; the limits and counts in ``_clouds_runs.py``)
  * object: ``flexreg synth --views 6`` around the Stanford bunny (``../shared/data/mesh_models``,
    when present) and around a procedural object, no floor, neighbouring views 30-120 degrees
    apart (pinhole depth views, 640 x 480);
  * rosette: ``flexreg synth --lidar-frames --lidar-kind rosette`` (Livox-style narrow-field
    frames, 70 x 77 degrees, 24 000 points) through a room and a hall;
  * fragments: ``flexreg synth --fragments`` (3DMatch-style fused fragments, 1 cm voxels);
  * real: the pairs of ``../shared/data`` that are not stations (3DMatch, Ouster, bunny, the
    PCL tutorial's Kinect clouds without truth: there the agreement of the answers is shown).

Every pair runs flexreg's three routes and the baseline in this process, one after the other,
with the same seed. The acceptance: ``auto`` registers (right and confident) at least as many
pairs as the baseline gets right, and no flexreg answer outside the limits is confident.

Usage::

    .venv/bin/python benchmarks/clouds.py                 # the sets above, seeds 1-3
    .venv/bin/python benchmarks/clouds.py --seeds 11 12   # a held-out set (new seeds)
    .venv/bin/python benchmarks/clouds.py --write-docs    # also rewrite the section in
                                                          # docs/benchmarks.md

Raw records go to ``benchmarks/results/clouds-<timestamp>/`` (``results.json``, ``results.md``);
generated data to ``--data`` (kept: a second run reuses it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _clouds_runs import (  # noqa: E402
    BASELINE,
    FLEXREG_METHODS,
    METHODS,
    agreement,
    confident_off,
    confident_wrong,
    frame_pairs,
    real_pairs,
    registered,
    run_pair,
    summary_line,
    synth,
    synthetic_pairs,
)

from flexreg.bench.harness import machine_info, publish, results_folder, write_json  # noqa: E402

DOC = REPO / "docs" / "benchmarks.md"
RESULTS = REPO / "benchmarks" / "results"
SECTION = "## Any two clouds"
SHARED = REPO.parent / "shared" / "data"
BUNNY = SHARED / "mesh_models" / "bun_zipper_res3.ply"

#: lidar frames paired this many frames apart (0.15 m to 4.5 m along the path)
STEPS = (1, 5, 10, 20, 30)


def datasets(data: Path, seeds: list[int], quick: bool) -> list[tuple[str, Path | None]]:
    """Generate (or reuse) the synthetic sets: (kind, folder) per set (None: not generated)."""
    out: list[tuple[str, Path | None]] = []
    views = ["--views", "4" if quick else "6"]
    frames = "11" if quick else "31"
    for s in seeds:
        seed = ["--seed", str(s)]
        if BUNNY.is_file():
            args = ["--scene", str(BUNNY), "--mesh-up", "y", *views, *seed]
            out.append(("object", synth(data / f"object-bunny-s{s}", args)))
        out.append(("object", synth(data / f"object-s{s}", ["--scene", "object", *views, *seed])))
        for scene in ("room", "hall"):
            args = [
                "--scene",
                scene,
                "--stations",
                "0",
                "--lidar-frames",
                frames,
                "--lidar-kind",
                "rosette",
                *seed,
            ]
            out.append(("rosette", synth(data / f"rosette-{scene}-s{s}", args)))
        args = ["--scene", "room", "--stations", "0", "--fragments", "4", *seed]
        out.append(("fragments", synth(data / f"fragments-room-s{s}", args)))
    return out


def table(records: list[dict[str, Any]]) -> str:
    """The Markdown table: per set, pairs registered per method, what ``auto`` said of the
    rest, the baseline's wrong answers and flexreg's confident wrong (and off) answers."""
    kinds = list(dict.fromkeys(r["kind"] for r in records if r.get("limits")))
    head = "| set | pairs | " + " | ".join(f"{m} registered" for m in METHODS)
    head += " | auto: uncertain right / uncertain not right / refused"
    head += f" | {BASELINE} wrong | confident wrong (auto, flexion, geometric)"
    head += " | confident off (auto, flexion, geometric) |"
    lines = [head, "|---|---:|" + "---:|" * (len(METHODS) + 4)]
    for k in kinds:
        rs = [r for r in records if r["kind"] == k and r.get("limits")]
        reg = [sum(registered(r, m) for r in rs) for m in METHODS]
        a = [r["auto"] for r in rs]
        unc_r = sum(x["status"] == "uncertain" and x.get("right") is True for x in a)
        unc_w = sum(x["status"] == "uncertain" and x.get("right") is False for x in a)
        ref = sum(x["status"] not in ("confident", "uncertain") for x in a)
        base_wrong = sum(r[BASELINE].get("right") is False for r in rs)
        cw = ", ".join(str(sum(confident_wrong(r, m) for r in rs)) for m in FLEXREG_METHODS)
        co = ", ".join(str(sum(confident_off(r, m) for r in rs)) for m in FLEXREG_METHODS)
        lines.append(
            f"| {k} | {len(rs)} | "
            + " | ".join(map(str, reg))
            + f" | {unc_r} / {unc_w} / {ref} | {base_wrong} | {cw} | {co} |"
        )
    return "\n".join(lines)


def per_pair(records: list[dict[str, Any]]) -> str:
    """Every pair: each method's status and error (or, without truth, the answers' agreement)."""
    lines = [
        "| set | pair | " + " | ".join(METHODS) + " | seconds (auto / baseline) |",
        "|---|---|" + "---|" * (len(METHODS) + 1),
    ]
    for r in records:
        cells = []
        for m in METHODS:
            x = r[m]
            err = f"{x['rot_deg']:.2f}° / {1000 * x['trans_m']:.1f} mm" if "rot_deg" in x else ""
            mark = "" if "right" not in x else (" ✓" if x["right"] else " ✗")
            cells.append(f"{x['status']} {err}{mark}".strip())
        if "limits" not in r:
            cells[-1] += f" (auto vs baseline: {agreement(r)})"
        lines.append(
            f"| {r['kind']} | {r['pair']} | "
            + " | ".join(cells)
            + f" | {r['auto']['s']:.1f} / {r[BASELINE]['s']:.1f} |"
        )
    return "\n".join(lines)


def markdown(runs: list[tuple[str, list[dict[str, Any]]]], command: str) -> str:
    """The section's body (its heading is :data:`SECTION`): per run (its title and records),
    the summary table and every pair."""
    out = [
        f"Measured with `{command}` on {machine_info()['cpu']}. A pair is right within 1° and "
        "1 % of the source's median range of the truth (3DMatch: 15° / 30 cm, its benchmark's "
        "limits, since ICP started from its reference pose moves 1.5° / 11 cm; Ouster: 10 cm; "
        "bunny: 3 mm), off within 5° and 10 %, wrong beyond; flexreg registers a pair when its "
        "answer is right and confident, the baseline when its answer is right.",
        "",
    ]
    for title, records in runs:
        out += [f"### {title}", "", table(records), "", per_pair(records), ""]
    return "\n".join(out)


def _load(path: Path) -> list[dict[str, Any]]:
    import json

    return list(json.loads(path.read_text()))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--quick", action="store_true", help="4 views, 3 frames, one seed")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument(
        "--kinds",
        nargs="+",
        choices=["object", "rosette", "fragments", "real"],
        default=["object", "rosette", "fragments", "real"],
        help="the sets to run (all by default)",
    )
    ap.add_argument("--data", type=Path, default=RESULTS / "clouds-data")
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--write-docs", action="store_true")
    ap.add_argument(
        "--from-json",
        type=Path,
        nargs="+",
        metavar="TITLE=results.json",
        help="render saved runs (each 'title=path') instead of running",
    )
    a = ap.parse_args(argv)
    command = "benchmarks/clouds.py " + " ".join(sys.argv[1:] if argv is None else argv)
    if a.from_json:
        runs = [
            (str(x).split("=", 1)[0], _load(Path(str(x).split("=", 1)[1]))) for x in a.from_json
        ]
        folder = results_folder(a.results, "clouds-report")
        publish(
            markdown(runs, command.strip()),
            folder,
            doc=DOC if a.write_docs else None,
            heading=SECTION,
        )
        return 0
    seeds = a.seeds[:1] if a.quick else a.seeds
    folder = results_folder(a.results, "clouds")
    records: list[dict[str, Any]] = []
    pairs = []
    for kind, d in datasets(a.data, seeds, a.quick):
        if d is None or kind not in a.kinds:
            continue
        pairs += frame_pairs(kind, d, STEPS) if kind == "rosette" else synthetic_pairs(kind, d)
    if not a.no_real and "real" in a.kinds:
        pairs += real_pairs(SHARED)
    for p in pairs:
        rec = run_pair(p, 0)
        records.append(rec)
        print(summary_line(rec), flush=True)
        write_json(folder / "results.json", records)
    text = markdown([(f"Seeds {seeds}", records)], command.strip())
    publish(text, folder, doc=DOC if a.write_docs else None, heading=SECTION)
    return 0


if __name__ == "__main__":
    sys.exit(main())
