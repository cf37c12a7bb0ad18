"""The surveyor in the loop: links given by hand (``--link TARGET SOURCE T.txt``) and pairs
added to the automatic candidates (``--pairs +FILE.csv``), on a small synthetic room."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, room_project, run_cli

from flexreg.cli.survey import rejected_lines
from flexreg.core.transforms import (
    invert,
    make_transform,
    rotation_about_axis,
    rotation_error_deg,
    translation_error_m,
)
from flexreg.errors import InputError
from flexreg.io.transform_io import read_pair_transform
from flexreg.survey import SurveyConfig, run_survey
from flexreg.survey.pairs import Candidate, hand_links, merge_candidates

STATIONS = ["station_00", "station_01", "station_02"]
#: the registration cannot search: every link without a given pose fails
ICP_ONLY = ["--set", "icp_only=true", "--no-refine"]


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    """Three stations of the synthetic room at 512 x 256, with gt.json."""
    return room_project(tmp_path_factory.mktemp("project"), 3)


def _files(project: Path, n: int = 3) -> list[Path]:
    return [project / f"station_{i:02d}.ptx" for i in range(n)]


def _doc(out: Path) -> dict:
    return json.loads((out / "poses.json").read_text())


def _links(doc: dict, target: str, source: str) -> list[dict]:
    """The links of a pair, in either direction."""
    return [e for e in doc["links"] if {e["target"], e["source"]} == {target, source}]


def _truth(project: Path) -> np.ndarray:
    return read_pair_transform(project / "gt.json", "station_00", "station_02")


def _off(T: np.ndarray, deg: float, m: float) -> np.ndarray:
    """``T`` moved by ``deg`` degrees about a tilted axis and ``m`` metres."""
    d = np.array([0.6, -0.4, 0.2]) * m / np.linalg.norm([0.6, -0.4, 0.2])
    return make_transform(rotation_about_axis([0.3, 0.2, 1.0], np.deg2rad(deg)), d) @ T


def _survey(project: Path, out: Path, *args) -> tuple[int, str, str]:
    return run_cli(["survey", *_files(project), "--out", out, "--workers", "1", *args])


# ------------------------------------------------------------------ refused before any work


@pytest.mark.parametrize(
    "case, text, message",
    [
        ("malformed.txt", "1 0 0\n0 1 0 0\n", "expected 4 rows of 4 numbers"),
        ("words.txt", "one two three four\n" * 4, "must hold only numbers"),
        ("scaled.txt", "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n", "not a proper rotation"),
        ("missing.txt", None, "no such file"),
        ("other.json", '{"T": [[1, 0, 0, 0]]}', "no 'T_target_source' entry"),
        ("broken.json", '{"T_target_source": [[1, 0', "invalid JSON"),
    ],
)
def test_a_bad_transform_file_is_one_line_naming_it(case, text, message, project, tmp_path):
    f = tmp_path / case
    if text is not None:
        f.write_text(text)
    out = tmp_path / "out"
    rc, _, err = _survey(project, out, "--link", "station_00", "station_02", f)
    assert rc == 1
    line = one_error_line(err)
    assert str(f) in line and message in line, line
    assert not out.exists()


@pytest.mark.parametrize(
    "links, message",
    [
        ([("station_00", "station_09")], "--link station_00 station_09: 'station_09' is not one"),
        ([("station_01", "station_01.ptx")], "a station cannot be linked to itself"),
        (
            [("station_00", "station_02"), ("station_02.ptx", "station_00")],
            "the pair station_02 / station_00 is given twice",
        ),
    ],
)
def test_a_bad_link_is_one_line_before_any_work(links, message, project, tmp_path):
    T = tmp_path / "T.txt"
    np.savetxt(T, np.eye(4))
    out = tmp_path / "out"
    args = [a for t, s in links for a in ("--link", t, s, T)]
    rc, _, err = _survey(project, out, *args)
    assert rc == 1
    assert message in one_error_line(err)
    assert not out.exists()


def test_pairs_plus_needs_a_csv_file(project, tmp_path):
    out = tmp_path / "out"
    rc, _, err = _survey(project, out, "--pairs", "+pairs.txt")
    assert rc == 1
    assert one_error_line(err).startswith("error: --pairs: +pairs.txt:")
    assert not out.exists()


# ---------------------------------------------------------------------- merging (no scans)


def test_hand_links_replace_the_candidates_of_their_pairs(project, tmp_path):
    T = make_transform(rotation_about_axis([0, 0, 1], 0.3), [1.0, 2.0, 0.1])
    f = tmp_path / "T.txt"
    np.savetxt(f, T)
    hand = hand_links(
        [("station_02", "site/station_00.ptx", f), ("station_01", "station_02", T)], STATIONS
    )
    assert [(c.target, c.source, c.origin) for c in hand] == [
        ("station_02", "station_00", "hand"),
        ("station_01", "station_02", "hand"),
    ]
    np.testing.assert_array_equal(hand[0].T_target_source, T)
    # a synth gt.json: the pair's entry, inverted when listed the other way round
    (gt,) = hand_links([("station_02", "station_00", project / "gt.json")], STATIONS)
    np.testing.assert_allclose(gt.T_target_source, invert(_truth(project)), atol=1e-12)
    auto = [Candidate("station_00", "station_01", "sequential", 12.0)]
    auto.append(Candidate("station_00", "station_02", "place", 9.0))
    got = merge_candidates(auto, hand)
    assert [(c.target, c.source, c.origin) for c in got] == [
        ("station_00", "station_01", "sequential"),
        ("station_02", "station_00", "hand"),
        ("station_01", "station_02", "hand"),
    ]
    with pytest.raises(InputError, match=r"^--link station_00 station_01: expected a 4x4"):
        hand_links([("station_00", "station_01", np.eye(3))], STATIONS)


# ------------------------------------------------------------------------- pairs added


def test_pairs_plus_file_adds_to_the_automatic_candidates(tmp_path_factory):
    """``--pairs +FILE``: the file's pair, the automatic candidates (file order) and the
    proximity round's pairs are all tried, once each; a hand link (here the truth of a
    gt.json) takes the place of the automatic candidate of its pair."""
    project = room_project(tmp_path_factory.mktemp("project4"), 4)
    pairs = project / "pairs.csv"
    pairs.write_text("target,source\nstation_00,station_02\n")
    out = tmp_path_factory.mktemp("added") / "out"
    rc, _, err = run_cli(
        ["survey", project, "--out", out, "--workers", "1", "--pairs", f"+{pairs}", "--no-refine"]
        + ["--link", "station_00", "station_01", project / "gt.json"]
    )
    assert rc in (0, 3), err
    doc = _doc(out)
    tried = {(e["target"], e["source"]): e["origin"] for e in doc["links"]}
    assert len(tried) == len(doc["links"])
    assert len({frozenset(k) for k in tried}) == len(tried)  # one link per pair
    assert tried[("station_00", "station_02")] == "file"
    assert tried[("station_01", "station_02")] == "sequential"
    assert tried[("station_00", "station_01")] == "hand"
    assert "proximity" in tried.values()  # the rounds after the first graph ran
    assert all(st["placed"] for st in doc["stations"].values())


# ------------------------------------------------------------------------- hand links


@pytest.fixture(scope="module")
def hand(project, tmp_path_factory):
    """A survey where the registration cannot search (icp_only) and station_00-station_02 is
    given by hand, 0.5 degrees and 5 cm off the truth."""
    root = tmp_path_factory.mktemp("hand")
    given = root / "T_00_02.txt"
    np.savetxt(given, _off(_truth(project), 0.5, 0.05))
    out = root / "out"
    rc, _, err = _survey(project, out, *ICP_ONLY, "--link", "station_00", "station_02", given)
    return rc, err, out, given


def test_a_hand_link_seeds_a_pair_the_images_cannot_register(hand, project):
    rc, err, out, given = hand
    assert rc == 3, err  # station_01's links fail: it stays unplaced
    doc = _doc(out)
    for pair in (("station_00", "station_01"), ("station_01", "station_02")):
        (e,) = _links(doc, *pair)
        assert e["status"] == "failed" and e["origin"] == "sequential"
    (e,) = _links(doc, "station_00", "station_02")
    assert (e["target"], e["source"], e["origin"]) == ("station_00", "station_02", "hand")
    assert e["status"] == "accepted" and e["cached"] is False
    T, truth = np.asarray(e["T_target_source"]), _truth(project)
    assert rotation_error_deg(T, truth) < 0.1 and translation_error_m(T, truth) < 0.01
    # refined: not the pose as given
    assert translation_error_m(np.loadtxt(given), truth) > 0.04
    assert doc["stations"]["station_02"]["placed"] and not doc["stations"]["station_01"]["placed"]
    assert len(list((out / "cache" / "links").glob("*.seed-*.link.npz"))) == 1


def test_a_rerun_reuses_a_hand_link_and_another_transform_registers_it_again(
    hand, project, tmp_path
):
    _, _, first, given = hand
    out = tmp_path / "out"
    shutil.copytree(first / "cache", out / "cache")
    rc, _, err = _survey(project, out, *ICP_ONLY, "--link", "station_00", "station_02", given)
    assert rc == 3, err
    (e,) = _links(_doc(out), "station_00", "station_02")
    assert e["origin"] == "hand" and e["cached"] is True
    np.testing.assert_array_equal(
        e["T_target_source"], _links(_doc(first), *STATIONS[::2])[0]["T_target_source"]
    )
    # the Python API, another transform (the truth, as an array): registered again
    config = SurveyConfig(joint_refine=False)
    config = config.replace(registration=config.registration.replace(icp_only=True))
    truth = _truth(project)
    result = run_survey(
        _files(project), out, config, workers=1, links=[("station_00", "station_02", truth)]
    )
    by_pair = {frozenset((e.target, e.source)): e for e in result.links}
    link = by_pair[frozenset(("station_00", "station_02"))]
    assert link.origin == "hand" and link.cached is False
    assert by_pair[frozenset(("station_00", "station_01"))].cached is True  # the same settings
    assert rotation_error_deg(link.T_target_source, truth) < 0.1
    assert translation_error_m(link.T_target_source, truth) < 0.01
    assert len(list((out / "cache" / "links").glob("*.seed-*.link.npz"))) == 2


# ------------------------------------------------------------------ rough positions


def _positions(project: Path, path: Path, off_m: float = 0.5, turn_deg: float = 10.0) -> None:
    """Rough positions of every station from the truth: ``off_m`` away, the heading
    ``turn_deg`` off, sigma 1 m."""
    gt = json.loads((project / "gt.json").read_text())
    rows = ["stem,x,y,z,heading_deg,sigma_m"]
    for i, s in enumerate(gt["stations"]):
        T = np.asarray(s["T_world_scanner"])
        a = 2.0 * i  # radians: a different direction for each
        yaw = np.degrees(np.arctan2(T[1, 0], T[0, 0])) + (turn_deg if i % 2 else -turn_deg)
        x, y = T[0, 3] + off_m * np.cos(a), T[1, 3] + off_m * np.sin(a)
        rows.append(f"{s['name']},{x:.3f},{y:.3f},,{yaw:.2f},1.0")
    path.write_text("\n".join(rows) + "\n")


def test_rough_positions_vouch_for_links_and_give_the_site_frame(project, tmp_path):
    pos = tmp_path / "positions.csv"
    _positions(project, pos)
    out = tmp_path / "out"
    rc, _, err = _survey(project, out, "--positions", pos)
    assert rc in (0, 3), err
    doc = _doc(out)
    assert doc["frame"]["kind"] == "positions"
    gt = {s["name"]: np.asarray(s["T_world_scanner"]) for s in json.loads(
        (project / "gt.json").read_text())["stations"]}  # fmt: skip
    for stem, st in doc["stations"].items():
        assert st["placed"], stem
        T_site, W = np.asarray(st["T_site_station"]), gt[stem]
        # the site frame is the positions' (no heights given: horizontally), fitted to them:
        # within their sigma (1 m) and 10 degrees of the truth
        assert np.linalg.norm(T_site[:2, 3] - W[:2, 3]) < 1.0, stem
        yaw = np.degrees(np.arctan2(T_site[1, 0], T_site[0, 0]) - np.arctan2(W[1, 0], W[0, 0]))
        assert abs((yaw + 180) % 360 - 180) < 10, stem
    assert any(e["vouched"] == "positions" for e in doc["links"] if e["status"] == "accepted")
    # a re-run with the same positions reuses every link (nothing registered again)
    rc, _, err = _survey(project, out, "--positions", pos, "--overwrite")
    assert rc in (0, 3), err
    summary = _doc(out)["summary"]
    assert summary["links_from_cache"] == summary["links_attempted"]


def test_a_bad_positions_file_is_one_line_before_any_work(project, tmp_path):
    pos = tmp_path / "positions.csv"
    pos.write_text("stem,x,y\nstation_09,1,2\n")
    out = tmp_path / "out"
    rc, _, err = _survey(project, out, "--positions", pos)
    assert rc == 1 and not out.exists()
    assert one_error_line(err) == f"error: {pos}: row 2: 'station_09' is not one of the stations"


def test_a_wrong_hand_link_is_refused_with_its_loop_error(project, tmp_path):
    """Every link given by hand and taken as given (icp_only, without the ICP refinement):
    two right, and station_00 <- station_02 a metre off. The loop of the three refuses the
    wrong one with its loop error."""
    truth = read_pair_transform(project / "gt.json", "station_00", "station_02")
    wrong = make_transform(np.eye(3), [1.0, 0.0, 0.0]) @ truth
    args = []
    for t, s, T in [
        ("station_00", "station_01", None),
        ("station_01", "station_02", None),
        ("station_00", "station_02", wrong),
    ]:
        f = tmp_path / f"{t}_{s}.txt"
        np.savetxt(f, T if T is not None else read_pair_transform(project / "gt.json", t, s))
        args += ["--link", t, s, f]
    out = tmp_path / "out"
    keep = ["--set", "refine=false", "--set", "judge.checks=[]"]  # the pose as given
    rc, stdout, err = _survey(project, out, *ICP_ONLY, *keep, *args)
    assert rc == 3, err
    out_lines = stdout.splitlines()
    (e,) = _links(_doc(out), "station_00", "station_02")
    assert translation_error_m(np.asarray(e["T_target_source"]), truth) > 0.9  # as given
    assert e["status"] == "rejected" and e["loop_error_m"] > 0.9, e
    assert "loop" in e["why"]
    # named on the console, a link given by hand being news whatever its verdict
    (line,) = [x for x in out_lines if x.startswith("rejected link")]
    assert "station_00" in line and "station_02" in line and "loop error" in line


def test_the_console_names_refuted_trusted_links_and_counts_the_uncertain_ones():
    """A confident or hand-given link a loop refutes gets its own line; the uncertain ones a
    loop left out (the graph at work) one line counting them."""

    def link(t, s, verdict, origin="place", status="rejected", loop=1.5):
        return {
            "target": t, "source": s, "verdict": verdict, "origin": origin, "status": status,
            "why": "disagrees with the loop it closes", "loop_error_deg": loop,
            "loop_error_m": None if loop is None else 0.2,
        }  # fmt: skip

    links = [
        link("a", "b", "confident"), link("a", "c", "uncertain", "hand"),
        link("b", "c", "uncertain"), link("c", "d", "uncertain"),
        link("d", "e", "uncertain", loop=None), link("e", "f", "confident", status="accepted"),
    ]  # fmt: skip
    lines = rejected_lines(links)
    assert len(lines) == 3
    assert lines[0].startswith("rejected link target = a, source = b: disagrees")
    assert lines[0].endswith("(loop error 1.50°, 0.200 m)")
    assert "source = c" in lines[1]
    assert lines[2].startswith("2 uncertain link(s) disagreed with the loops they close")
    assert rejected_lines(links[4:]) == []


def test_rough_positions_link_the_stations_they_put_near_each_other(project, tmp_path):
    """File-order neighbours leave station_00 -- station_02 unlinked; rough positions put
    them within reach, so that pair is linked too, seeded by them."""
    pos = tmp_path / "positions.csv"
    _positions(project, pos)
    out = tmp_path / "out"
    rc, _, err = _survey(project, out, "--set", "pairs=sequential", "--positions", pos)
    assert rc in (0, 3), err
    doc = _doc(out)
    (added,) = _links(doc, "station_00", "station_02")
    assert added["origin"] == "positions"
    assert added["T_target_source"] is not None
    # without positions the pair is not tried
    out2 = tmp_path / "out2"
    rc, _, err = _survey(project, out2, "--set", "pairs=sequential")
    assert rc in (0, 3), err
    assert not _links(_doc(out2), "station_00", "station_02")


def test_the_console_counts_links_in_the_positions_phase_as_links():
    """Links registered in rough positions' windows are links: a failed one is counted as a
    failed link, not as an unreadable station (the label of the preparation's failures)."""
    from rich.progress import Progress, TextColumn

    from flexreg.cli.survey import _Bars
    from flexreg.survey.execute import ProgressEvent

    progress = Progress(TextColumn("{task.description} {task.fields[counts]}"))
    bars = _Bars(progress)
    bars(ProgressEvent("positions", 5, 9, 1, 2, 2, 1.0))
    bars(ProgressEvent("prepare", 3, 4, 0, 0, 1, 1.0))
    counts = {t.description: t.fields["counts"] for t in progress.tasks}
    assert counts["Links the positions bring near"] == "confident 1, uncertain 2, failed 2"
    assert counts["Preparing stations"] == "unreadable 1"
