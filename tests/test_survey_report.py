"""The survey report page: its figures on a hand-made project, its text, and the page in a real
headless Chromium (Debian's ``chromium``, driven by Playwright)."""

from __future__ import annotations

import html
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser import chromium_page

from flexreg.core.transforms import invert
from flexreg.errors import InputError
from flexreg.survey.report import drawn_groups, render_report, write_report
from flexreg.survey.report_data import link_errors, report_figures

EVIL = "<script>alert('x')</script>"


def pose(x: float, y: float, yaw_deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [x, y]
    return T


def nudge(T: np.ndarray, dx: float) -> np.ndarray:
    """``T`` moved by ``dx`` metres along its target's x."""
    D = np.eye(4)
    D[0, 3] = dx
    return D @ T


def station(T: np.ndarray | None, placed: bool, group: int | None, **kw: Any) -> dict:
    return {
        "file": f"scans/{kw.pop('stem', 'x')}.ptx",
        "points": 120000,
        "placed": placed,
        "T_reference_station": T.tolist() if placed and T is not None else None,
        "T_group_station": None if T is None else T.tolist(),
        "group": group,
        "confidence": "confident" if placed else None,
        "reason": None,
        "error": None,
    } | kw


def link(doc: dict, target: str, source: str, status: str = "accepted", **kw: Any) -> dict:
    st = doc["stations"]
    Tt, Ts = st[target]["T_group_station"], st[source]["T_group_station"]
    T = None if Tt is None or Ts is None else (invert(np.array(Tt)) @ np.array(Ts)).tolist()
    out = {
        "target": target,
        "source": source,
        "origin": "sequential",
        "status": status,
        "why": None,
        "T_target_source": T,
        "verdict": "confident",
        "reasons": [],
        "overlap": 0.55,
        "overlap_target": 0.58,
        "overlap_source": 0.55,
        "matches": 211,
        "inliers": 52,
        "rmse_m": 0.0042,
        "strength": {"roll": 0.24, "pitch": 0.31, "yaw": 0.18, "x": 0.2, "y": 0.21, "z": 0.59},
        "loop_error_deg": None,
        "loop_error_m": None,
    }
    return out | kw


def small_project() -> dict:
    """Six stations: hall_01..hall_03 placed (group 0, reference hall_01), annex_01 and annex_02
    in a group that no link joins (group 1, own frame, not placed), lone_01 unplaced (no link
    holds it). Links: three confident, one uncertain (weak axis), one rejected by its loop
    (12.3 degrees / 3.412 m), one failed."""
    stations = {
        "hall_01": station(pose(0, 0, 0), True, 0, stem="hall_01"),
        "hall_02": station(pose(6.0, 0.5, 30), True, 0, stem="hall_02"),
        "hall_03": station(pose(3.0, 5.0, -45), True, 0, stem="hall_03", confidence="uncertain"),
        "annex_01": station(pose(0, 0, 0), False, 1, stem="annex_01", group_reference="annex_01"),
        "annex_02": station(
            pose(4.0, -1.0, 90), False, 1, stem="annex_02", group_reference="annex_01"
        ),
        "lone_01": station(None, False, None, stem="lone_01"),
    }
    for s in ("annex_01", "annex_02"):
        stations[s]["reason"] = "in group 1: no accepted link joins it to the reference's group"
    stations["lone_01"]["reason"] = f"no accepted link {EVIL}"
    doc: dict = {
        "schema": "flexreg.survey/1",
        "reference": "hall_01",
        "stations": stations,
        "groups": [
            {"id": 0, "reference": "hall_01", "stations": ["hall_01", "hall_02", "hall_03"]},
            {"id": 1, "reference": "annex_01", "stations": ["annex_01", "annex_02"]},
        ],
    }
    rejected = link(doc, "hall_01", "hall_03", "rejected", origin="place")
    rejected["T_target_source"] = (
        pose(3.4, 0, 12.3) @ np.array(rejected["T_target_source"])
    ).tolist()
    rejected |= {
        "why": "disagrees with the loop hall_01-hall_02-hall_03 it closes",
        "loop_error_deg": 12.3,
        "loop_error_m": 3.412,
        "verdict": "uncertain",
        "reasons": [{"code": "ambiguous", "message": "two poses 3.4 m apart along x fit"}],
    }
    uncertain = link(doc, "hall_02", "hall_03", verdict="uncertain", confirmed_by_loop=False)
    uncertain |= {
        "loop_error_deg": 0.021,
        "loop_error_m": 0.0031,
        "strength": uncertain["strength"] | {"x": 0.0012},
        "reasons": [{"code": "weak_axis", "message": "the scans constrain almost nothing along x"}],
    }
    doc["links"] = [
        link(doc, "hall_01", "hall_02", loop_error_deg=0.012, loop_error_m=0.0021),
        uncertain,
        rejected,
        link(doc, "annex_01", "annex_02", loop_error_deg=0.0, loop_error_m=0.0),
        link(doc, "hall_01", "lone_01", "failed", T_target_source=None, verdict=None)
        | {"why": "few matches: 7 (need 12)", "overlap": None, "overlap_target": None}
        | {"overlap_source": None, "rmse_m": None, "strength": None, "inliers": 3},
        link(doc, "hall_02", "annex_01", "failed", origin="place", T_target_source=None)
        | {"why": "registration raised: no overlap", "verdict": None, "strength": None}
        | {"overlap": None, "overlap_target": None, "overlap_source": None, "rmse_m": None}
        | {"inliers": None, "matches": None},
    ]
    doc["summary"] = {"exit_status": 3, "problems": ["lone_01: unplaced (no accepted link)"]}
    return doc


def grid_project(n: int, links: int, seed: int = 0) -> dict:
    """``n`` stations on a grid and ``links`` links between near stations, all accepted and
    consistent (no summary: the report computes its figures)."""
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n))
    stems = [f"st_{i:03d}" for i in range(n)]
    stations = {
        s: station(pose(5.0 * (i % side), 5.0 * (i // side), rng.uniform(-180, 180)), True, 0)
        for i, s in enumerate(stems)
    }
    doc = {"reference": stems[0], "stations": stations, "links": []}
    pairs = sorted(
        ((i, j) for i in range(n) for j in range(i + 1, n)),
        key=lambda p: (abs(p[0] % side - p[1] % side) + abs(p[0] // side - p[1] // side), p),
    )[:links]
    doc["links"] = [link(doc, stems[i], stems[j]) for i, j in pairs]
    return doc


# ------------------------------------------------------------------------------ figures


def test_figures_of_the_small_project() -> None:
    doc = small_project()
    f = report_figures(doc)
    assert f.outcome == "uncertain"  # the summary's exit status 3
    assert (f.stations, f.placed) == (6, 3)
    assert f.unplaced == ["annex_01", "annex_02", "lone_01"]
    assert f.groups == {0: ["hall_01", "hall_02", "hall_03"], 1: ["annex_01", "annex_02"]}
    assert f.group_frames == {0: "hall_01", 1: "annex_01"}
    assert f.links == {"confident": 2, "uncertain": 1, "rejected": 1, "failed": 2}
    assert f.uncertain_links == [1]
    # accepted links' errors are the document's loop errors: 0.012, 0.021, 0.0 degrees
    assert f.max_link_error_deg == pytest.approx(0.021)
    assert f.mean_link_error_m == pytest.approx((0.0021 + 0.0031 + 0.0) / 3)
    assert f.bundle_error_deg == pytest.approx(math.sqrt((0.012**2 + 0.021**2) / 3))


def test_link_errors_computed_from_the_poses_when_the_document_lacks_them() -> None:
    doc = small_project()
    lk = doc["links"][0]
    lk["loop_error_deg"] = lk["loop_error_m"] = None
    lk["T_target_source"] = nudge(np.array(lk["T_target_source"]), 0.004).tolist()
    e = link_errors(doc)
    assert e[0] is not None
    assert e[0].rotation_deg == pytest.approx(0.0, abs=1e-6)
    assert e[0].translation_m == pytest.approx(0.004, abs=1e-9)
    assert e[2] is None and e[4] is None  # rejected, failed
    del doc["summary"]
    f = report_figures(doc)
    assert f.outcome == "uncertain"  # computed: stations unplaced
    assert f.max_link_error_m == pytest.approx(0.004, abs=1e-9)


def test_outcome_computed_without_a_summary() -> None:
    doc = grid_project(4, 5)
    assert report_figures(doc).outcome == "confident"
    for lk in doc["links"]:
        lk["status"] = "failed"
    assert report_figures(doc).outcome == "failed"


def test_a_station_alone_in_its_group_is_counted_not_drawn() -> None:
    doc = grid_project(4, 5)
    doc["stations"]["lone"] = station(None, False, 1, reason="no link was tried")
    f = report_figures(doc)
    assert f.groups == {0: ["st_000", "st_001", "st_002", "st_003"], 1: ["lone"]}
    assert f.group_frames == {0: "st_000", 1: "lone"}
    assert list(drawn_groups(doc, f)) == [0]
    assert f.outcome == "uncertain" and f.unplaced == ["lone"]


@pytest.mark.parametrize(
    ("edit", "problem"),
    [
        (lambda d: d.pop("stations"), "no 'stations'"),
        (lambda d: d.__setitem__("links", {}), "no 'links' list"),
        (lambda d: d["links"][0].__setitem__("source", "nowhere"), "'nowhere' is not a station"),
        (lambda d: d["links"][0].__setitem__("T_target_source", [[1, 0], [0, 1]]), "4x4"),
        (
            lambda d: d["stations"]["hall_02"].__setitem__(
                "T_reference_station", [[math.nan] * 4] * 4
            ),
            "finite 4x4",
        ),
    ],
)
def test_bad_documents_are_refused_and_nothing_written(
    edit: Any, problem: str, tmp_path: Path
) -> None:
    doc = small_project()
    edit(doc)
    out = tmp_path / "report.html"
    with pytest.raises(InputError, match=re.escape(problem)):
        write_report(doc, out)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_place_is_one_input_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(InputError, match=r"cannot (write|make its folder)"):
        write_report(small_project(), blocker / "report.html")


# ------------------------------------------------------------------------------ the page


def _text(page: str) -> str:
    """The page's visible-ish text: tags removed, entities resolved, spaces collapsed."""
    body = re.sub(r"<(script|style)>.*?</\1>", " ", page, flags=re.S)
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", body)).split())


def test_page_content() -> None:
    doc = small_project()
    page = render_report(doc)
    text = _text(page)
    assert page.startswith("<!DOCTYPE html>")
    # self-contained: no external resource of any kind
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//|file:)""", page)
    assert "@import" not in page and "<link " not in page
    assert "<svg" in page
    # outcome, figures, formatted numbers
    assert "Done, but check (exit 3): 3 stations not placed, 1 kept link uncertain" in text
    assert "3 / 6 stations placed" in text
    assert "0.021° / 3.1 mm max link error" in text
    # the unplaced stations and why (escaped), the uncertain and the rejected link with reasons
    assert f"lone_01 : no accepted link {EVIL}" in text
    assert EVIL not in page  # escaped, never markup
    assert "annex_02 : in group 1: no accepted link joins it" in text
    assert (
        "link 1: hall_02 ← hall_03 : the scans constrain almost nothing along x (no closed loop "
        "confirms it)"
    ) in text
    assert (
        "link 2: hall_01 ← hall_03 (loop error 12.30° / 3.412 m): disagrees with the loop "
        "hall_01-hall_02-hall_03 it closes; two poses 3.4 m apart along x fit"
    ) in text
    # the link table: one row per link; the rejected row with its numbers
    rows = re.findall(r'<tr class="link (\w+)">(.*?)</tr>', page, flags=re.S)
    assert [k for k, _ in rows] == [
        "confident", "uncertain", "rejected", "confident", "failed", "failed"
    ]  # fmt: skip
    cells = [html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", rows[2][1])]
    assert cells[:10] == [
        "2", "hall_01", "hall_03", "rejected", "uncertain", "place", "55", "58", "52 / 211", "4.2",
    ]  # fmt: skip
    assert cells[16:18] == ["12.300", "3412.0"]
    weak = re.findall(r'<td class="weak"[^>]*>([^<]*)</td>', rows[1][1])
    assert weak == ["0.001"]  # strength 0.0012 along x, under the 0.005 threshold
    failed = [html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", rows[4][1])]
    assert failed[6:10] == ["–", "–", "3 / 211", "–"]
    # the stations table: positions in the group's frame, links per station
    st = re.findall(r'<tr class="station( unplaced)?">(.*?)</tr>', page, flags=re.S)
    assert len(st) == 6 and sum(bool(u) for u, _ in st) == 3
    hall2 = [html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", st[1][1])]
    assert hall2[:9] == [
        "hall_02", "yes", "0", "confident", "6.000", "0.500", "0.000", "120,000", "2 / 3",
    ]  # fmt: skip
    assert "Problems reported lone_01: unplaced (no accepted link)" in text
    # the graph: both groups drawn, text kept as text; what is not drawn is said
    svg = page[page.index("<svg") : page.index("</svg>")]
    assert "group 0: 3 stations, 3 links" in svg and "group 1: 2 stations, 1 link" in svg
    assert "rejected (1)" in svg and "12.3° / 3.41 m" in svg
    assert (
        "2 links not drawn: an end is not drawn or in another group. Not drawn (no pose, or "
        "alone in its group): lone_01."
    ) in text


def test_station_names_stay_text() -> None:
    """A name with markup, an ampersand and dollars is escaped in the page and drawn as it is
    (no mathematics) in the figure; numpy numbers are numbers."""
    doc = grid_project(3, 3)
    name = 'a<b&"c$x$'
    doc["stations"][name] = doc["stations"].pop("st_001")
    doc["stations"][name]["points"] = np.int64(5)
    for lk in doc["links"]:
        for end in ("target", "source"):
            lk[end] = name if lk[end] == "st_001" else lk[end]
    page = render_report(doc)
    svg = page[page.index("<svg") : page.index("</svg>")]
    assert "<tspan" not in svg  # matplotlib's mathtext would split the label into glyphs
    assert re.search(r"<text[^>]*>a&lt;b&amp;(&quot;|\")c\$x\$</text>", svg)
    assert f"<td>{html.escape(name)}</td>" in page
    assert '<td data-sort="5">5</td>' in page


def test_large_project_renders() -> None:
    doc = grid_project(64, 400)
    page = render_report(doc)
    assert len(re.findall(r'<tr class="link confident">', page)) == 400
    assert len(re.findall(r'<tr class="station">', page)) == 64
    assert "Done: every station is verified within the tolerance (exit 0)." in _text(page)


# ------------------------------------------------------------------------------ in a browser


def test_report_in_headless_chromium(tmp_path: Path) -> None:
    doc = small_project()
    out = write_report(doc, tmp_path / "report.html")
    shot = tmp_path / "report.png"
    with chromium_page(1400, 900) as page:
        problems: list[str] = page.errors  # console and page errors
        page.on("requestfailed", lambda r: problems.append(f"request {r.url}"))
        page.goto(out.as_uri())
        page.wait_for_load_state("load")
        graph = page.locator("#station-graph svg")
        assert graph.is_visible()
        box = graph.bounding_box()
        assert box is not None and box["width"] > 400 and box["height"] > 200
        rows = page.locator("#link-table tbody tr")
        assert rows.count() == len(doc["links"])
        assert page.locator("#station-table tbody tr").count() == 6
        assert page.locator("#unplaced li").count() == 3
        # the script sorts: loop error, descending, puts the rejected link first
        head = page.locator("#link-table th", has_text="loop err °")
        head.click()
        head.click()
        assert rows.first.get_attribute("class") == "link rejected"
        page.screenshot(path=str(shot), full_page=True)
    assert problems == []
    assert shot.stat().st_size > 20_000


def test_map_check_conflicts_are_listed() -> None:
    doc = small_project()
    doc["map_check"] = {
        "enabled": True,
        "pairs_checked": 3,
        "conflicts_found": [
            {
                "a": "hall_01",
                "b": "hall_03",
                "T_a_b": np.eye(4).tolist(),
                "why": "8.1% of hall_03's points lie in hall_01's free space and 3.9% on its "
                "surfaces",
            }
        ],
        "conflicting_now": [
            {"a": "hall_02", "b": "hall_03", "explained": [0.02, 0.05], "conflicting": [0.07, 0.01]}
        ],
    }
    text = _text(render_report(doc))
    assert "Placed stations that contradicted each other (map check) (2)" in text
    assert (
        "hall_01 and hall_03: 8.1% of hall_03's points lie in hall_01's free space and 3.9% on "
        "its surfaces"
    ) in text
    assert "still contradicting : hall_02 and hall_03 (7.0% of one station's points" in text
    assert "Placed stations that contradicted each other (map check) (0) none" in _text(
        render_report(small_project())
    )


def test_a_pose_from_the_plan_view_shows_no_inlier_count() -> None:
    """A pose the plan views' overlay found rests on no feature matches: the link table says
    so instead of a count such as 0 / 1 that reads like a bad link; fitted poses, and failed
    links, keep their counts."""
    doc = small_project()
    doc["links"][0] |= {"inliers": 0, "matches": 1}
    doc["links"][1]["verdict"] = {
        "status": "uncertain",
        "reasons": doc["links"][1]["reasons"],
        "evidence": {"inliers": {"count": 5, "matches": 40, "fit_to_matches": False}},
    }
    doc["links"][3] |= {"inliers": 2, "matches": 9, "stored_deviation": {"rotation_deg": 0.1}}
    page = render_report(doc)
    rows = re.findall(r'<tr class="link (\w+)">(.*?)</tr>', page, flags=re.S)
    inliers = [html.unescape(re.findall(r"<td[^>]*>(.*?)</td>", r)[8]) for _, r in rows]
    assert inliers == [
        "pose from the plan view",
        "pose from the plan view",
        "52 / 211",
        "pose from the plan view or the stored poses",
        "3 / 211",
        "–",
    ]
    assert not any(">0 / 1<" in r for _, r in rows)
    assert "pose from the plan view when the overlay of the scans' plan views" in _text(page)
