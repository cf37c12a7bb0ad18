"""`flexreg survey` end to end on a small synthetic project (low resolution, a few stations)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, room_project, run_cli

from flexreg.errors import InputError
from flexreg.io import read_scans
from flexreg.io.transform_io import read_pair_transform
from flexreg.survey import SurveyConfig, evaluate, find_scans, run_survey, write_outputs

STATIONS = ["station_00", "station_01", "station_02"]


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    """Four stations of a synthetic room at 512 x 256 at fixed poses, with gt.json."""
    return room_project(tmp_path_factory.mktemp("project"), 4)


def _files(project: Path, names=STATIONS) -> list[Path]:
    return [project / f"{n}.ptx" for n in names]


def _with_cache(src: Path, dst: Path, *, links: bool = True) -> Path:
    """``dst`` with a copy of ``src``'s cache (prepared stations; and links unless not)."""
    shutil.copytree(
        src / "cache", dst / "cache", ignore=None if links else shutil.ignore_patterns("links")
    )
    return dst


@pytest.fixture(scope="module")
def first(project, tmp_path_factory):
    out = tmp_path_factory.mktemp("survey") / "run"
    rc, stdout, err = run_cli(["survey", *_files(project), "--out", out, "--workers", "1"])
    return rc, stdout, err, out


def _doc(out: Path) -> dict:
    return json.loads((out / "poses.json").read_text())


def test_every_station_placed_confidently_exit_0(first, project):
    rc, stdout, err, out = first
    assert rc == 0, err + stdout
    doc = _doc(out)
    assert doc["schema"] == "flexreg.survey/1"
    assert set(doc["stations"]) == set(STATIONS)
    assert doc["reference"] in STATIONS
    for stem, st in doc["stations"].items():
        assert st["placed"] is True and st["group"] == 0 and st["confidence"] == "confident"
        T = np.loadtxt(out / "stations" / f"{stem}.txt")
        np.testing.assert_array_equal(T, np.asarray(st["T_reference_station"]))
    ref = doc["stations"][doc["reference"]]["T_reference_station"]
    np.testing.assert_allclose(ref, np.eye(4), atol=1e-12)
    s = doc["summary"]
    assert s["placed"] == 3 and s["exit_status"] == 0 and s["problems"] == []
    assert s["links_accepted"] >= 2 and s["links_attempted"] <= 6 * 3
    # every pair of placed stations was checked against each other; none contradicts
    m = doc["map_check"]
    assert m["enabled"] is True and m["pairs_checked"] == 3
    assert m["conflicting_now"] == [] and m["conflicts_found"] == []
    for link in doc["links"]:
        assert link["status"] in ("accepted", "rejected", "failed")
        if link["status"] == "accepted":
            assert set(link["strength"]) == {"roll", "pitch", "yaw", "x", "y", "z"}
            assert np.asarray(link["information"]).shape == (6, 6)
            assert link["loop_error_m"] is not None  # three links: each closes a loop
            c2c = link["cloud_to_cloud"]
            assert 0 < c2c["overlap"] <= 1 and 0 <= c2c["within_6mm"] <= c2c["within_1cm"] <= 1
            assert link["link_error"] != "unchecked" and link["link_error"]["mm"] < 10
    # the final alignment: every station verified, with its accuracy
    assert s["statuses"] == {"verified": 3, "placed": 0, "outside_tolerance": 0, "unplaced": 0}
    fa = doc["final_alignment"]
    assert fa["pairs_checked"] == 3 and fa["pairs_unchecked"] == 0 and fa["bundle_error_mm"] < 10
    for stem, st in doc["stations"].items():
        assert st["status"] == "verified" and st["status_why"] is None
        if stem != doc["reference"]:
            assert 0 < st["accuracy"]["radius95_mm"] < 10 and st["accuracy"]["checked"] is True
    # accurate against the synthetic truth: within the survey's tolerance
    ev = evaluate(doc, json.loads((project / "gt.json").read_text()))
    assert len(ev["stations"]) == 3 and ev["wrong"] == []
    for e in ev["stations"].values():
        assert e["rotation_deg"] < 0.05 and e["translation_m"] < 0.01
    assert (out / "report.html").is_file()
    assert "3 verified, 0 placed, 0 outside tolerance, 0 unplaced" in stdout
    # no NaN or infinity anywhere a user reads a figure
    for f in (out / "poses.json", out / "report.html"):
        text = f.read_text()
        assert not re.search(r"\bnan\b|\binfinity\b", text, re.IGNORECASE), f.name
    assert not re.search(r"\bnan\b", stdout + err, re.IGNORECASE)


def test_a_rerun_prepares_nothing_and_a_new_station_only_itself(first, project, tmp_path):
    out = _with_cache(first[3], tmp_path)
    result = run_survey(_files(project), out, workers=1)
    assert [p.computed for p in result.prepared.values()] == [False] * 3
    doc, before = result.to_dict(), _doc(first[3])
    assert doc["summary"]["prepared"] == 0 and doc["summary"]["from_cache"] == 3
    assert doc["summary"]["links_from_cache"] == len(doc["links"])
    for stem in STATIONS:
        assert (
            doc["stations"][stem]["T_reference_station"]
            == (before["stations"][stem]["T_reference_station"])
        )
    more = run_survey(_files(project, [*STATIONS, "station_03"]), out, workers=1)
    assert {s: p.computed for s, p in more.prepared.items()} == {
        "station_00": False, "station_01": False, "station_02": False, "station_03": True,
    }  # fmt: skip


def test_two_dask_worker_processes_give_the_same_poses(first, project, tmp_path):
    out = _with_cache(first[3], tmp_path, links=False)  # the links run on the workers
    result = run_survey(_files(project), out, SurveyConfig(), workers=2)
    assert result.to_dict()["summary"]["links_from_cache"] == 0
    assert result.workers == 2
    doc, before = result.to_dict(), _doc(first[3])
    assert doc["reference"] == before["reference"]
    for stem in STATIONS:
        assert (
            doc["stations"][stem]["T_reference_station"]
            == (before["stations"][stem]["T_reference_station"])
        )
    assert [(e["target"], e["source"], e["status"]) for e in doc["links"]] == [
        (e["target"], e["source"], e["status"]) for e in before["links"]
    ]


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def dask_cluster(tmp_path):
    """A real Dask cluster on loopback, as a user starts one: a ``dask scheduler`` process and
    two ``dask worker`` processes of one thread each (no dashboards). Yields the address."""
    import subprocess
    import sys

    from distributed import Client

    dask = Path(sys.executable).with_name("dask")
    if not dask.exists():
        pytest.skip("the dask command is not installed beside this Python")
    address = f"tcp://127.0.0.1:{_free_port()}"
    logs = tmp_path / "cluster-logs"
    logs.mkdir()
    procs = []

    def start(name: str, *args: str) -> None:
        log = (logs / f"{name}.log").open("w")
        procs.append(
            subprocess.Popen([str(dask), *args], stdout=log, stderr=subprocess.STDOUT, cwd=logs)
        )

    try:
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port",
              address.rsplit(":", 1)[1], "--no-dashboard", "--no-show")  # fmt: skip
        for k in range(2):
            start(f"worker{k}", "worker", address, "--nthreads", "1", "--no-nanny",
                  "--no-dashboard", "--host", "127.0.0.1", "--name", f"w{k}",
                  "--local-directory", str(logs / f"w{k}"))  # fmt: skip
        with Client(address, timeout="60s") as c:
            c.wait_for_workers(2, timeout=120)
        yield address
    finally:  # throwaway processes without children (no nannies): no graceful shutdown
        for p in procs:
            p.kill()
            p.wait()


def test_a_dask_cluster_by_address_gives_the_same_poses(first, project, tmp_path, dask_cluster):
    """`flexreg survey --scheduler`, on real scheduler and worker processes: the links run on
    the workers and every pose is bit for bit the one of ``--workers 1``."""
    out = _with_cache(first[3], tmp_path / "out", links=False)
    rc, _, err = run_cli(
        ["--overwrite", "survey", *_files(project), "--out", out, "--scheduler", dask_cluster]
    )
    assert rc == first[0], err
    doc, before = _doc(out), _doc(first[3])
    assert doc["summary"]["links_from_cache"] == 0 and doc["summary"]["workers"] == 2
    for stem in STATIONS:
        assert (
            doc["stations"][stem]["T_reference_station"]
            == before["stations"][stem]["T_reference_station"]
        )
    assert [(e["target"], e["source"], e["status"]) for e in doc["links"]] == [
        (e["target"], e["source"], e["status"]) for e in before["links"]
    ]


@pytest.mark.parametrize(
    "address, message",
    [
        ("DEAD", "cannot reach"),
        ("udp://127.0.0.1:8786", "the scheme must be tcp:// or tls://"),
        ("tcp://127.0.0.1", "is not tcp://HOST:PORT"),
        ("tcp://127.0.0.1:99999", "is not tcp://HOST:PORT"),
    ],
)
def test_a_bad_scheduler_address_is_one_line_exit_1_nothing_written(
    address, message, project, tmp_path
):
    if address == "DEAD":
        address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    out = tmp_path / "out"
    rc, _, err = run_cli(["survey", *_files(project), "--out", out, "--scheduler", address])
    assert rc == 1
    line = one_error_line(err)
    assert "--scheduler" in line and message in line, line
    assert not out.exists()


@pytest.mark.parametrize("service", ["web server", "greeting server"])
def test_another_service_is_no_scheduler(service, project, tmp_path, monkeypatch):
    """Another service on the port: a web server (it waits for a request, as the client
    waits for a handshake) or one that greets first (an SSH banner, whose bytes read as a
    Dask message size are exabytes): one line, exit 1, within the probe's wait."""
    monkeypatch.setattr("flexreg.survey.execute.SCHEDULER_PROBE_S", 1.0)
    import socketserver
    import threading

    class WebServer(socketserver.StreamRequestHandler):
        def handle(self):
            self.rfile.readline()  # waits for a request line that never comes

    class Greeter(socketserver.StreamRequestHandler):
        def handle(self):
            self.wfile.write(b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n")

    handler = WebServer if service == "web server" else Greeter
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        address = f"tcp://127.0.0.1:{server.server_address[1]}"
        out = tmp_path / "out"
        rc, _, err = run_cli(["survey", *_files(project), "--out", out, "--scheduler", address])
    finally:
        server.shutdown()
        server.server_close()
    assert rc == 1
    assert "does not answer as a Dask scheduler" in one_error_line(err)
    assert not out.exists()


def test_a_station_file_replaced_during_the_run_is_never_merged(first, project, tmp_path):
    """Stations are fingerprinted when prepared; the merged cloud and the E57 read them again
    only if they still hold what was registered (a file replaced meanwhile gave a merged
    cloud with a third of its points 5 cm and more off, exit 0). A file rewritten with the
    same content (a copy, a touch) still merges."""
    import os

    scans = tmp_path / "scans"
    scans.mkdir()
    for f in _files(project):
        shutil.copy(f, scans / f.name)
    out = _with_cache(first[3], tmp_path / "out")
    result = run_survey(sorted(scans.iterdir()), out, workers=1)
    assert all(p.fingerprint is not None for p in result.prepared.values())
    st = scans / "station_01.ptx"
    os.utime(st, ns=(st.stat().st_atime_ns, st.stat().st_mtime_ns + 10**9))  # same content
    write_outputs(result, out, merged=out / "merged.ply", voxel_m=0.1, report=False)
    assert (out / "merged.ply").is_file()
    shutil.copy(project / "station_02.ptx", st)  # another scan under the registered name
    for kw in ({"merged": out / "again.ply"}, {"e57": out / "again.e57"}):
        with pytest.raises(InputError, match=r"station_01\.ptx: changed since the survey"):
            write_outputs(result, out, voxel_m=0.1, report=False, **kw)
    assert not (out / "again.ply").exists() and not (out / "again.e57").exists()


def test_an_unreadable_station_is_reported_the_rest_registered_exit_3(first, project, tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    for f in _files(project):
        shutil.copy(f, folder / f.name)
    (folder / "broken.ptx").write_text("512\n256\nthis is not a PTX file\n")
    out = _with_cache(first[3], tmp_path / "out")
    rc, _, err = run_cli(["survey", folder, "--out", out, "--workers", "1"])
    assert rc == 3, err
    doc = _doc(out)
    assert doc["stations"]["broken"]["placed"] is False
    assert "broken.ptx" in doc["stations"]["broken"]["error"]
    assert all(doc["stations"][s]["placed"] for s in STATIONS)
    assert "broken: unplaced: unreadable" in err
    assert not (out / "stations" / "broken.txt").exists()


def test_an_unplaced_station_exit_3_one_line(first, project, tmp_path):
    """One link, given by hand: it places its two stations; the third stays unplaced."""
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("target,source\nstation_00,station_01\n")
    hand = tmp_path / "T.txt"
    np.savetxt(hand, read_pair_transform(project / "gt.json", "station_00", "station_01"))
    out = _with_cache(first[3], tmp_path / "out")
    rc, _, err = run_cli(
        ["survey", *_files(project), "--out", out, "--workers", "1", "--pairs", pairs,
         "--link", "station_00", "station_01", hand]
    )  # fmt: skip
    assert rc == 3, err
    doc = _doc(out)
    assert doc["stations"]["station_02"]["placed"] is False
    assert doc["stations"]["station_02"]["T_reference_station"] is None
    assert [ln for ln in err.splitlines() if ln.startswith("station_02: unplaced")]
    assert sorted(p.stem for p in (out / "stations").iterdir()) == ["station_00", "station_01"]


@pytest.mark.parametrize(
    "case, message",
    [
        ("missing", "no such file or folder"),
        ("empty", "no scan files in this folder"),
        ("one", "only one scan"),
    ],
)
def test_bad_input_one_line_exit_1_nothing_written(case, message, project, tmp_path):
    scans = {
        "missing": [tmp_path / "nope"],
        "empty": [tmp_path],
        "one": [project / "station_00.ptx"],
    }[case]
    out = tmp_path / "out"
    rc, _, err = run_cli(["survey", *scans, "--out", out, "--workers", "1"])
    assert rc == 1
    assert message in one_error_line(err)
    assert not out.exists()


def _ply(path: Path, faces: int | None) -> Path:
    verts = "0 0 0\n1 0 0\n0 1 0\n"
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    header += "property float z\n"
    if faces is not None:
        header += f"element face {faces}\nproperty list uchar int vertex_indices\n"
    path.write_text(header + "end_header\n" + verts + "3 0 1 2\n" * (faces or 0))
    return path


def test_a_folder_skips_meshes_with_a_warning_a_named_mesh_is_taken(project, tmp_path, caplog):
    # flexreg synth writes its scene's mesh beside the stations: not a station
    assert (project / "scene.ply").exists()
    with caplog.at_level("WARNING", logger="flexreg.survey.stations"):
        found = find_scans([project])
    assert [f.name for f in found] == [f"station_0{k}.ptx" for k in range(4)]
    assert [r.getMessage() for r in caplog.records] == [
        f"{project / 'scene.ply'}: a triangle mesh, not a scan: skipped (name it to survey it)"
    ]
    # a PLY point cloud (no faces, or a face element of 0) is a scan
    folder = tmp_path / "site"
    folder.mkdir()
    cloud, empty_faces = _ply(folder / "a.ply", None), _ply(folder / "b.ply", 0)
    mesh = _ply(folder / "c.ply", 2)
    assert find_scans([folder]) == [cloud, empty_faces]
    assert find_scans([mesh]) == [mesh]
    only = tmp_path / "only-mesh"
    only.mkdir()
    _ply(only / "model.ply", 1)
    with pytest.raises(InputError, match=r"no scan files in this folder .*skipped 1 mesh"):
        find_scans([only])


def test_refine_merged_cloud_and_e57(first, project, tmp_path):
    out = _with_cache(first[3], tmp_path)
    result = run_survey(_files(project), out, SurveyConfig(joint_refine=False), workers=1)
    assert not result.refined and result.exit_status == 3  # accuracy unchecked without it
    assert result.status_counts()["placed"] == 3
    assert all("accuracy unchecked" in p for p in result.problems())
    result = run_survey(_files(project), out, workers=1)
    assert result.refined and result.exit_status == 0
    assert result.to_dict()["summary"]["links_from_cache"] == len(result.links)
    ev = evaluate(result.to_dict(), json.loads((project / "gt.json").read_text()))
    assert ev["wrong"] == [] and len(ev["stations"]) == 3
    for e in ev["stations"].values():
        assert e["rotation_deg"] < 0.3 and e["translation_m"] < 0.03
    merged, e57 = tmp_path / "merged.ply", tmp_path / "project.e57"
    write_outputs(result, out, merged=merged, voxel_m=0.05, e57=e57)
    cloud = read_scans(merged)[0]
    assert len(cloud) > 1000 and cloud.colors is not None
    # one point per 5 cm voxel (the mean of a voxel's points lies in that voxel)
    keys = np.floor(cloud.points / 0.05 + 1e-9).astype(np.int64)
    assert len(np.unique(keys, axis=0)) >= 0.999 * len(keys)
    scans = read_scans(e57)
    assert [s.name for s in scans] == result.placed
    doc = result.to_dict()
    for s in scans:
        np.testing.assert_allclose(
            s.T_world_scanner, doc["stations"][s.name]["T_reference_station"], atol=1e-12
        )


def test_a_station_one_confident_link_fixes_is_placed_not_verified(first, project, tmp_path):
    """File-order pairs only: a chain of confident links, none closing a loop. The final
    alignment's pairs all start from those links' poses and cannot tell a look-alike bay from
    the truth, so station_02 and station_01 are ``placed`` (not verified), each naming the
    link it rests on and what would verify it; nothing is verified."""
    out = _with_cache(first[3], tmp_path)
    result = run_survey(_files(project), out, SurveyConfig(pairs="sequential"), workers=1)
    doc = result.to_dict()
    st = doc["stations"]
    assert doc["reference"] == "station_00"
    assert st["station_02"]["confidence"] == "single" and st["station_02"]["status"] == "placed"
    why = st["station_02"]["status_why"]
    assert (
        "confident links that no loop checks fix it, one after the other "
        "(station_01 <- station_02, station_00 <- station_01)" in why
    )
    assert "--link" in why and "rough positions" in why
    assert st["station_01"]["confidence"] == "single" and st["station_01"]["status"] == "placed"
    assert (
        "one confident link alone fixes it (station_00 <- station_01)"
        in st["station_01"]["status_why"]
    )
    assert result.exit_status == 3
    # their 1-sigma figures hold only if those links are right: said so wherever shown
    from flexreg.survey.report_data import station_reasons

    for stem in ("station_01", "station_02"):
        acc = st[stem]["accuracy"]
        assert acc["checked"] is False and acc["radius95_mm"] > 0
        assert any("(unchecked: it holds if the links" in t for t in station_reasons(st[stem]))


def test_the_console_marks_a_sigma_no_independent_route_checks():
    from flexreg.cli.survey import _sigma

    acc = {"sigma_mm": {"x": 1.02, "y": 1.1, "z": 0.77}, "checked": True}
    assert _sigma(acc) == "1.0, 1.1, 0.8"
    assert _sigma({**acc, "checked": False}) == "1.0, 1.1, 0.8 (unchecked)"
