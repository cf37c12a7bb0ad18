"""The survey report figure of docs/survey-report.md: a report page, screenshotted in headless
Chromium.

Run::

    .venv/bin/python scripts/survey_report_figure.py --poses RUN/poses.json
    .venv/bin/python scripts/survey_report_figure.py            # the hand-made example project

With ``--poses`` it renders the report of a real ``flexreg survey`` run: the docs' figure comes
from ``flexreg synth --scene hall --stations 8 --resolution 1024x512 --out X``, then ``flexreg
survey X/station_*.ptx --out Y``, then ``--poses Y/poses.json --height 1900``. Without it, it
renders a hand-made example project (12 stations of a building: two halls joined by a
corridor, a store room no link reaches, a link rejected by its loop, an uncertain corridor link,
a failed link), seeded, so reruns give the same page: the docs' second figure, with ``--out
docs/figures/survey-report-example.png``.

Writes the top of the page (outcome, figures, what needs a look, the station graph and the
first links) to ``--out`` (default ``docs/figures/survey-report.png``) and, with ``--html``, the
page itself. Needs Debian's ``chromium`` and Playwright (``make install`` and ``make test`` set
both up).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.transforms import invert
from flexreg.survey.report import write_report

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SEED = 7


def _pose(x: float, y: float, yaw_deg: float, z: float = 0.0) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [x, y, z]
    return T


def _perturbed(T: np.ndarray, rng: np.random.Generator, deg: float, m: float) -> np.ndarray:
    """``T`` moved by a small random rotation about z (``deg``) and translation (``m``)."""
    D = _pose(*rng.normal(0, m, 2), rng.normal(0, deg), rng.normal(0, m / 2))
    return D @ T


def _example_stations(
    rng: np.random.Generator,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """True poses and the stations of the example (two store rooms in a group of their own)."""
    where = {
        "hall_a_01": (0.0, 0.0, 0.0),
        "hall_a_02": (7.5, 0.4, 35.0),
        "hall_a_03": (14.8, -0.3, -80.0),
        "hall_a_04": (7.2, 8.1, 160.0),
        "hall_a_05": (0.3, 7.6, 95.0),
        "corridor_01": (21.0, 3.0, 0.0),
        "corridor_02": (27.5, 3.1, 180.0),
        "hall_b_01": (34.0, 0.2, 12.0),
        "hall_b_02": (41.3, 0.0, -140.0),
        "hall_b_03": (37.6, 7.9, 60.0),
        "store_01": (0.0, 0.0, 0.0),
        "store_02": (4.1, 2.2, -30.0),
    }
    truth = {s: _pose(*p) for s, p in where.items()}
    stores = {"store_01", "store_02"}
    stations: dict[str, Any] = {}
    for s, T in truth.items():
        placed = s not in stores
        stations[s] = {
            "file": f"scans/{s}.ptx",
            "points": int(rng.integers(3_800_000, 4_300_000)),
            "placed": placed,
            "T_reference_station": T.tolist() if placed else None,
            "group": 0 if placed else 1,
            "group_reference": "hall_a_01" if placed else "store_01",
            "T_group_station": T.tolist(),
            "confidence": "confident" if placed else None,
            "reason": None
            if placed
            else "in group 1 (store_01, store_02): no accepted link joins it to the reference's",
            "error": None,
        }
    stations["corridor_02"]["confidence"] = "uncertain"
    return truth, stations


def _example_links(rng: np.random.Generator, truth: dict[str, np.ndarray]) -> list[dict]:
    """The example's links, all accepted and consistent (a few changed afterwards)."""
    pairs = [
        ("hall_a_01", "hall_a_02", "sequential"),
        ("hall_a_02", "hall_a_03", "sequential"),
        ("hall_a_03", "corridor_01", "sequential"),
        ("corridor_01", "corridor_02", "sequential"),
        ("corridor_02", "hall_b_01", "sequential"),
        ("hall_b_01", "hall_b_02", "sequential"),
        ("hall_b_02", "hall_b_03", "sequential"),
        ("hall_a_01", "hall_a_05", "place"),
        ("hall_a_04", "hall_a_05", "sequential"),
        ("hall_a_02", "hall_a_04", "place"),
        ("hall_a_03", "hall_a_04", "proximity"),
        ("hall_b_01", "hall_b_03", "place"),
        ("store_01", "store_02", "sequential"),
        ("hall_a_05", "store_01", "place"),
        ("hall_a_01", "hall_a_04", "place"),
    ]
    links = []
    for t, s, origin in pairs:
        T = invert(truth[t]) @ truth[s]
        d, m = abs(rng.normal(0, 0.006)), abs(rng.normal(0, 0.0015))
        strength = {a: round(float(rng.uniform(0.08, 0.6)), 3) for a in ("x", "y", "z")}
        strength |= {a: round(float(rng.uniform(0.1, 0.5)), 3) for a in ("roll", "pitch", "yaw")}
        ov_t, ov_s = (round(float(v), 3) for v in rng.uniform(0.3, 0.75, 2))
        n_match = int(rng.integers(150, 420))
        links.append(
            {
                "target": t,
                "source": s,
                "origin": origin,
                "status": "accepted",
                "why": None,
                "T_target_source": _perturbed(T, rng, d, m).tolist(),
                "verdict": "confident",
                "reasons": [],
                "overlap": min(ov_t, ov_s),
                "overlap_target": ov_t,
                "overlap_source": ov_s,
                "matches": n_match,
                "inliers": int(n_match * rng.uniform(0.18, 0.4)),
                "rmse_m": round(float(rng.uniform(0.003, 0.009)), 4),
                "strength": strength,
                "loop_error_deg": round(d, 4),
                "loop_error_m": round(m, 4),
            }
        )
    return links


def _example_trouble(links: list[dict]) -> None:
    """An uncertain corridor link, a link rejected by its loop, a failed link."""
    corridor = links[3]
    corridor["verdict"] = "uncertain"
    corridor["strength"]["x"] = 0.0021
    corridor["reasons"] = [
        {
            "code": "weak_axis",
            "message": "the scans constrain almost nothing along x (strength 0.002, need "
            "0.01; a corridor or tunnel?): the position along it is a guess",
        }
    ]
    corridor["confirmed_by_loop"] = False
    wrong = links[14]
    wrong |= {
        "status": "rejected",
        "T_target_source": (_pose(3.4, 0.0, 0.0) @ np.array(wrong["T_target_source"])).tolist(),
        "why": "disagrees with the loop hall_a_01-hall_a_05-hall_a_04 it closes by 3.40 m",
        "loop_error_deg": 0.41,
        "loop_error_m": 3.402,
        "verdict": "uncertain",
        "reasons": [
            {
                "code": "ambiguous",
                "message": "two poses 3.4 m apart along x fit almost equally well (the other "
                "scores 86% of the answer): repeating structure",
            }
        ],
    }
    failed = links[13]
    failed |= {
        "status": "failed",
        "why": "only 4 of 97 feature matches agree: no transform found",
        "T_target_source": None,
        "verdict": None,
        "overlap": None,
        "overlap_target": None,
        "overlap_source": None,
        "matches": 97,
        "inliers": 4,
        "rmse_m": None,
        "strength": None,
        "loop_error_deg": None,
        "loop_error_m": None,
    }


def example_project() -> dict[str, Any]:
    """A hand-made poses document of 12 stations (see the module's docstring)."""
    rng = np.random.default_rng(SEED)
    truth, stations = _example_stations(rng)
    links = _example_links(rng, truth)
    _example_trouble(links)
    where = list(truth)
    stores = {"store_01", "store_02"}
    return {
        "schema": "flexreg.survey/1",
        "reference": "hall_a_01",
        "stations": stations,
        "groups": [
            {"id": 0, "reference": "hall_a_01", "stations": [s for s in where if s not in stores]},
            {"id": 1, "reference": "store_01", "stations": sorted(stores)},
        ],
        "links": links,
        "summary": {
            "exit_status": 3,
            "problems": [
                "store_01: unplaced (in group 1, no accepted link joins it to the reference's)",
                "store_02: unplaced (in group 1, no accepted link joins it to the reference's)",
                "corridor_01 <- corridor_02: kept but uncertain (weak_axis)",
            ],
        },
    }


def screenshot(html: Path, png: Path, *, width: int = 1400, height: int = 1700) -> None:
    """The top ``width`` x ``height`` CSS pixels of the page ``html``, as PNG."""
    from playwright.sync_api import sync_playwright

    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        sys.exit("Debian's chromium is not installed: apt-get install chromium")
    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(html.resolve().as_uri())
            page.wait_for_load_state("load")
            png.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(png))
        finally:
            browser.close()
    if errors:
        sys.exit("the page reported errors: " + "; ".join(errors))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=Path, help="poses.json of a flexreg survey run")
    ap.add_argument("--out", type=Path, default=Path("docs/figures/survey-report.png"))
    ap.add_argument("--html", type=Path, help="also keep the page here")
    ap.add_argument("--height", type=int, default=1700, help="CSS pixels of the page shown")
    args = ap.parse_args()
    doc = example_project() if args.poses is None else json.loads(args.poses.read_text())
    html = args.html or args.out.with_suffix(".html")
    write_report(doc, html)
    try:
        screenshot(html, args.out, height=args.height)
    finally:
        if args.html is None:
            html.unlink(missing_ok=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
