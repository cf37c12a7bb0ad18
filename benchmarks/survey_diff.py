"""Survey runs of the same projects side by side: which decisions and poses they share.

Two runs of one project on different machines (or under the CPU variants of
``scripts/cpu-variants.txt``, imitated on one machine: ``scripts/cpu-variant.sh``) should place
the same stations the same way. This script puts each run beside the first: per project, the
links both tried, how many of those got another verdict or another status in the graph, the
largest difference between their transforms, the stations whose status differs, and the
largest difference between the stations' placed positions.

Usage::

    .venv/bin/python benchmarks/survey_diff.py BASE OTHER [OTHER ...]

Each argument is a survey's output folder (``poses.json``) or a ``benchmarks/survey.py``
results folder (its ``runs/*/poses.json``, matched by project folder name; two single
survey folders are compared whatever their names). Prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from flexreg.core.transforms import translation_error_m  # noqa: E402


def turn_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle between two rotations, degrees, accurate for tiny ones (from the chord
    ``|A - B|_F = 2 sqrt(2) sin(angle / 2)``, where the trace's arccos loses them)."""
    chord = float(np.linalg.norm(A[:3, :3] - B[:3, :3])) / (2.0 * np.sqrt(2.0))
    return float(np.degrees(2.0 * np.arcsin(min(1.0, chord))))


def runs(folder: Path) -> dict[str, Path]:
    """The survey runs under ``folder`` by name: itself when it holds ``poses.json``, else
    every ``poses.json`` below it (named by its folder)."""
    if (folder / "poses.json").is_file():
        return {folder.name: folder / "poses.json"}
    found = sorted(folder.glob("**/poses.json"))
    if not found:
        raise SystemExit(f"error: {folder}: no poses.json in it or below it")
    return {p.parent.name: p for p in found}


def _links(doc: dict[str, Any]) -> dict[frozenset[str], dict[str, Any]]:
    return {frozenset((e["target"], e["source"])): e for e in doc["links"]}


def _relative(e: dict[str, Any], other: dict[str, Any]) -> np.ndarray | None:
    """``other``'s transform in ``e``'s direction (a pair may be tried either way round)."""
    if e["T_target_source"] is None or other["T_target_source"] is None:
        return None
    T = np.asarray(other["T_target_source"], dtype=np.float64)
    return T if other["target"] == e["target"] else np.linalg.inv(T)


def compare(base: dict[str, Any], other: dict[str, Any]) -> dict[str, Any]:
    """What ``other`` (a poses.json) shares with ``base``: counts and largest differences."""
    a, b = _links(base), _links(other)
    both = sorted(set(a) & set(b), key=sorted)
    verdicts = statuses = 0
    rot = trans = 0.0
    for k in both:
        e, f = a[k], b[k]
        verdicts += e["verdict"] != f["verdict"]
        statuses += e["status"] != f["status"]
        T = _relative(e, f)
        if T is not None:
            E = np.asarray(e["T_target_source"], dtype=np.float64)
            rot = max(rot, turn_deg(E, T))
            trans = max(trans, translation_error_m(E, T))
    moved = 0.0
    differ = []
    for stem, st in base["stations"].items():
        ot = other["stations"].get(stem)
        if ot is None or st["status"] != ot["status"]:
            differ.append(f"{stem} {st['status']} -> {None if ot is None else ot['status']}")
            continue
        P, Q = st.get("T_reference_station"), ot.get("T_reference_station")
        if P is not None and Q is not None:
            moved = max(moved, translation_error_m(np.asarray(P), np.asarray(Q)))
    return {
        "links": (len(a), len(b), len(both)),
        "verdicts_differ": verdicts,
        "statuses_differ": statuses,
        "max_link_deg": rot,
        "max_link_mm": 1000 * trans,
        "stations_differ": differ,
        "max_station_mm": 1000 * moved,
        "reference_same": base.get("reference") == other.get("reference"),
    }


def table(folders: list[Path]) -> str:
    """The markdown table of every later folder against the first."""
    base = runs(folders[0])
    lines = [
        f"Against `{folders[0].name}`.",
        "",
        "| run | project | links (base / run / both) | verdict differs | status differs | "
        "largest link difference | stations whose status differs | largest station "
        "difference |",
        "|---|---|---|---:|---:|---|---|---|",
    ]
    for folder in folders[1:]:
        found = runs(folder)
        if len(found) == 1 and len(base) == 1:  # two survey folders: one project, any names
            found = {next(iter(base)): next(iter(found.values()))}
        for name, path in found.items():
            if name not in base:
                lines.append(f"| {folder.name} | {name} | not in the base | | | | | |")
                continue
            c = compare(json.loads(base[name].read_text()), json.loads(path.read_text()))
            la, lb, lboth = c["links"]
            ref = "" if c["reference_same"] else " (another reference station)"
            lines.append(
                f"| {folder.name} | {name} | {la} / {lb} / {lboth} | {c['verdicts_differ']} | "
                f"{c['statuses_differ']} | {c['max_link_deg']:.2g}° / {c['max_link_mm']:.2g} mm | "
                f"{', '.join(c['stations_differ']) or 'none'}{ref} | "
                f"{c['max_station_mm']:.2g} mm |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("base", type=Path, help="the run the others are compared with")
    ap.add_argument("others", type=Path, nargs="+", help="runs of the same projects")
    args = ap.parse_args(argv)
    print(table([args.base, *args.others]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
