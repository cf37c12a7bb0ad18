"""Files and outputs: an existing result is refused without --overwrite (one line, exit 1,
nothing touched) by every command that writes results, replaced with it (a result folder
without the older run's files); -v and --overwrite work before or after the command;
``project`` writes the camera sidecar of native grids."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, one_error_line, run_cli

from flexreg import Scan, read_scan, write_scan
from flexreg.cli.app import hoist_root_flags
from flexreg.core.camera import PinholeCamera, SphericalCamera
from flexreg.core.range_image import to_scan
from flexreg.io.files import LOCK, MANIFEST, read_manifest
from flexreg.stages.grid_camera import fit_grid_camera, grid_with_camera
from flexreg.stages.projection import project, range_image

LASERSCAN = REPO / "data" / "laserscan" / "laserscan-depth.png"
REFUSED = "(an earlier result); give --overwrite to replace it"


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Small readable inputs of every kind the commands take."""
    d = tmp_path_factory.mktemp("inputs")
    scan = read_scan(LASERSCAN)
    write_scan(d / "a.npz", scan)
    write_scan(d / "b.npz", scan)
    traj = "\n".join(f"{t:.1f} {t:.2f} 0 0 0 0 0 1" for t in range(5)) + "\n"
    (d / "gt.txt").write_text(traj)
    (d / "est.txt").write_text(traj)
    (d / "pairs.csv").write_text("u,v,x,y,z\n")
    return d


def _commands(d: Path, old: Path) -> dict[str, list]:
    """argv of each command with its result at ``old`` (a file, or a folder for folders)."""
    png = old.with_suffix(".png")
    return {
        "register": ["register", d / "a.npz", d / "b.npz", "--out", old.with_suffix(".json")],
        "compare": ["compare", d / "a.npz", d / "b.npz", "--out", old],
        "survey": ["survey", d / "a.npz", d / "b.npz", "--out", old],
        "calibrate": ["calibrate", "--image", LASERSCAN, "--scan", d / "a.npz", "--pinhole",
                      "100", "100", "50", "50", "--pairs", d / "pairs.csv", "--out",
                      old.with_suffix(".json")],
        "project": ["project", d / "a.npz", "--out", png],
        "convert": ["convert", d / "a.npz", "--kind", "flexion", "--out", png],
        "odometry": ["odometry", d, "--out", old.with_suffix(".txt")],
        "evaluate": ["evaluate", "--gt", d / "gt.txt", "--est", d / "est.txt", "--json",
                     old.with_suffix(".json")],
        "synth": ["synth", "--scene", "room", "--stations", "1", "--out", old],
        "pick": ["pick", "--image", LASERSCAN, "--scan", d / "a.npz", "--pinhole", "100",
                 "100", "50", "50", "--out", old.with_suffix(".csv")],
    }  # fmt: skip


@pytest.mark.parametrize("command", sorted(_commands(Path("i"), Path("o"))))
def test_an_existing_result_is_refused_without_overwrite(command, inputs, tmp_path):
    argv = _commands(inputs, tmp_path / "old")[command]
    out = Path(argv[argv.index("--out") + 1] if "--out" in argv else argv[-1])
    if out.suffix:
        out.write_bytes(b"an earlier result")
    else:
        out.mkdir()
        (out / "poses.json").write_text("{}")
    before = _snapshot(tmp_path)
    rc, _, err = run_cli(argv)
    assert rc == 1, err
    line = one_error_line(err)
    assert REFUSED in line and str(out) in line, line
    assert _snapshot(tmp_path) == before


def test_overwrite_replaces_a_file_and_its_companions(inputs, tmp_path):
    out = tmp_path / "r.png"
    assert run_cli(["project", inputs / "a.npz", "--out", out])[0] == 0
    sidecar = tmp_path / "r.camera.json"
    # a companion file alone (the sidecar of an earlier run) is an earlier result too
    out.unlink()
    out.with_suffix(".npz").unlink()
    rc, _, err = run_cli(["project", inputs / "a.npz", "--out", out])
    assert rc == 1 and f"{sidecar}: exists {REFUSED}" in one_error_line(err)
    # --overwrite after the command, or before it
    assert run_cli(["project", inputs / "a.npz", "--out", out, "--overwrite"])[0] == 0
    assert run_cli(["--overwrite", "project", inputs / "a.npz", "--out", out])[0] == 0
    assert out.is_file() and sidecar.is_file()


def test_synth_overwrite_leaves_no_stale_frames_for_odometry(tmp_path):
    out = tmp_path / "sim"
    base = ["synth", "--scene", "room", "--stations", "1", "--resolution", "64x32", "--seed",
            "1", "--out", out]  # fmt: skip
    assert run_cli([*base, "--rgbd-frames", "4"])[0] == 0
    assert len(list((out / "rgbd" / "depth").iterdir())) == 4
    (out / "notes.txt").write_text("mine")
    rc, _, err = run_cli([*base, "--rgbd-frames", "2"])
    line = one_error_line(err)  # it names what --overwrite would replace
    assert rc == 1 and f"{out}: holds the results of an earlier run (" in line
    assert "gt.json, rgbd/ (12 files)" in line  # its frames: depth, colour, their lists
    assert line.endswith("; give --overwrite to replace them")
    assert len(list((out / "rgbd" / "depth").iterdir())) == 4  # untouched
    assert run_cli([*base, "--rgbd-frames", "2", "--overwrite"])[0] == 0
    assert sorted(p.name for p in (out / "rgbd" / "depth").iterdir()) == [
        "0.000000.png",
        "0.033333.png",
    ]
    assert sorted(p.name for p in (out / "rgbd" / "rgb").iterdir()) == [
        "0.000000.png",
        "0.033333.png",
    ]
    # the user's file stays: only what the earlier run recorded as its own is removed
    assert (out / "notes.txt").read_text() == "mine"
    from flexreg.io.sequence import read_sequence

    assert len(read_sequence(out)) == 2


def test_survey_overwrite_keeps_the_cache_and_the_inputs(tmp_path):
    """A survey folder's cache is not a result: a folder holding only it is not refused, and
    --overwrite keeps it (the re-run registers only new links); an input inside the folder is
    never removed."""
    from flexreg.cli.options import check_out_folder, set_overwrite
    from flexreg.errors import ConfigError
    from flexreg.io.files import all_or_nothing, atomic_write, protect

    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "station.npz").write_text("prepared")
    check_out_folder("--out", tmp_path, keep=("cache",))
    (tmp_path / "stations").mkdir()
    (tmp_path / "stations" / "old.txt").write_text("old")
    (tmp_path / "poses.json").write_text("old")
    (tmp_path / "scan.ptx").write_text("an input kept in the result folder")
    (tmp_path / "notes.txt").write_text("the user's, never written by flexreg")
    # what the earlier run recorded as its own (the input too, as if it had written it)
    files = ["poses.json", "stations/old.txt", "scan.ptx", "cache/station.npz"]
    (tmp_path / MANIFEST).write_text(json.dumps({"files": files}))
    set_overwrite(False)
    with pytest.raises(ConfigError, match="give --overwrite"):
        check_out_folder("--out", tmp_path, keep=("cache",))
    try:
        set_overwrite(True)
        with all_or_nothing():
            protect(tmp_path / "scan.ptx")
            check_out_folder("--out", tmp_path, keep=("cache",))
            atomic_write(tmp_path / "poses.json", lambda tmp: tmp.write_text("{}"))
    finally:
        set_overwrite(False)
    assert sorted(_snapshot(tmp_path)) == [
        MANIFEST, "cache/station.npz", "notes.txt", "poses.json", "scan.ptx",
    ]  # fmt: skip
    assert read_manifest(tmp_path) == ["poses.json"]


def test_a_survey_rerun_keeps_the_cache_and_says_what_it_replaces_and_removes(tmp_path):
    """Re-running a survey into its folder: the refusal names the earlier results and says the
    cache stays and is reused (it once read as if the cache would be lost); with --overwrite,
    the earlier merged cloud this run was not asked for (made from the earlier poses, stale)
    is removed, and one line names it; the cache and the user's files stay."""
    site, out = tmp_path / "site", tmp_path / "survey"
    synth = ["synth", "--scene", "room", "--stations", "2", "--resolution", "256x128",
             "--seed", "1", "--out", site]  # fmt: skip
    assert run_cli(synth)[0] == 0
    scans = sorted(site.glob("station_*.ptx"))
    base = ["survey", *scans, "--out", out, "--workers", "1"]
    rc, _, err = run_cli([*base, "--merged", out / "merged.ply"])
    assert rc in (0, 3), err
    assert (out / "merged.ply").is_file() and "merged.ply" in read_manifest(out)
    (out / "notes.txt").write_text("mine")
    cache = _snapshot(out / "cache")
    rc, _, err = run_cli(base)
    line = one_error_line(err)
    assert rc == 1 and line == (
        f"error: --out: {out}: holds the results of an earlier run (merged.ply, poses.json, "
        "report.html, stations/ (2 files)); give --overwrite to replace them; "
        f"{out / 'cache'} (prepared stations and links) is kept either way and reused: only "
        "new or changed scans are prepared again"
    )
    rc, stdout, err = run_cli([*base, "--overwrite"])
    assert rc in (0, 3), err
    assert f"{out}: removing the earlier run's merged.ply (made from its poses: stale now)" in (
        stdout
    )
    assert "0 station(s) prepared, 2 from the cache" in stdout
    assert not (out / "merged.ply").exists() and (out / "notes.txt").read_text() == "mine"
    assert _snapshot(out / "cache") == cache
    # a run that writes everything again removes nothing, and says nothing about it
    rc, stdout, err = run_cli([*base, "--overwrite"])
    assert rc in (0, 3), err
    assert "removing" not in stdout


def test_the_refusal_says_a_kept_entry_stays_and_names_no_missing_file(tmp_path):
    """No manifest (an older result, or the user's files): the plain refusal, with the kept
    entry's note; a manifest naming files that are gone lists only those still there."""
    from flexreg.cli.options import check_out_folder, removed_line, set_overwrite
    from flexreg.errors import ConfigError

    (tmp_path / "cache").mkdir()
    (tmp_path / "poses.json").write_text("{}")
    set_overwrite(False)
    with pytest.raises(ConfigError) as e:
        check_out_folder("--out", tmp_path, keep=("cache",), kept="(the cache) stays")
    assert str(e.value) == (
        f"--out: {tmp_path}: is a folder that is not empty {REFUSED}; {tmp_path / 'cache'} "
        "(the cache) stays"
    )
    (tmp_path / MANIFEST).write_text(json.dumps({"files": ["poses.json", "gone.ply"]}))
    with pytest.raises(ConfigError, match=r"earlier run \(poses\.json\); give --overwrite"):
        check_out_folder("--out", tmp_path, keep=("cache",))
    assert removed_line(tmp_path) is None  # outside a run: nothing to remove


def test_overwrite_removes_only_what_an_earlier_run_wrote(tmp_path):
    """``--overwrite`` into a result folder that also holds the user's own things (notes, a
    folder of photos, a scan the new run was not given): those stay; the earlier run's files
    that the new run does not write again go. (Everything not written by the new run used to
    be removed, recursively.)"""
    out = tmp_path / "project"
    base = ["synth", "--scene", "room", "--stations", "1", "--resolution", "64x32", "--seed",
            "1", "--out", out]  # fmt: skip
    assert run_cli([*base, "--rgbd-frames", "3"])[0] == 0
    ours = read_manifest(out)
    assert "gt.json" in ours and "rgbd/depth/0.066667.png" in ours
    (out / "notes.txt").write_text("mine")
    (out / "photos").mkdir()
    (out / "photos" / "site.jpg").write_bytes(b"\xff\xd8 a photo")
    (out / "scans").mkdir()
    (out / "scans" / "station_02.ptx").write_text("a scan of the user's")
    (out / "rgbd" / "depth" / "README").write_text("the user's, beside the frames")
    rc, _, err = run_cli([*base, "--rgbd-frames", "1", "--overwrite"])
    assert rc == 0, err
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "photos" / "site.jpg").is_file() and (out / "scans" / "station_02.ptx").is_file()
    assert sorted(p.name for p in (out / "rgbd" / "depth").iterdir()) == ["0.000000.png", "README"]
    assert "rgbd/depth/0.033333.png" not in read_manifest(out)


def test_a_damaged_or_hostile_manifest_removes_nothing(tmp_path):
    """A manifest is data from the folder: unreadable, or naming paths outside it, it gives
    nothing to remove."""
    (tmp_path / "keep.txt").write_text("x")
    (tmp_path / MANIFEST).write_text("{not json")
    assert read_manifest(tmp_path) == []
    (tmp_path / MANIFEST).write_text(
        json.dumps({"files": ["../outside.txt", "/etc/passwd", "a/../../b", 7, "keep.txt"]})
    )
    assert read_manifest(tmp_path) == ["keep.txt"]
    (tmp_path / MANIFEST).write_text("[" * 100_000)
    assert read_manifest(tmp_path) == []


def test_overwrite_into_a_folder_that_is_no_earlier_result_removes_nothing(inputs, tmp_path):
    """--overwrite into a folder without the command's marker (here: a folder of the user's
    own files, no gt.json) replaces same-named files only."""
    from flexreg.cli.options import check_out_folder, set_overwrite
    from flexreg.io.files import all_or_nothing, atomic_write

    (tmp_path / "mine.txt").write_text("mine")
    try:
        set_overwrite(True)
        with all_or_nothing():
            check_out_folder("--out", tmp_path)
            atomic_write(tmp_path / "gt.json", lambda tmp: tmp.write_text("{}"))
    finally:
        set_overwrite(False)
    assert sorted(_snapshot(tmp_path)) == [MANIFEST, "gt.json", "mine.txt"]


def test_a_failed_overwrite_leaves_the_old_result(inputs, tmp_path):
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "comparison.json").write_text("old")
    rc, _, _ = run_cli(
        ["compare", inputs / "a.npz", inputs / "b.npz", "--methods", "nope", "--out", out,
         "--overwrite"]
    )  # fmt: skip
    assert rc == 1
    assert _snapshot(out) == {"comparison.json": b"old"}


@pytest.mark.parametrize(
    "flags",
    [
        ["-v", "info", "{f}"],
        ["info", "{f}", "-v"],
        ["info", "-vv", "{f}"],
        ["info", "{f}", "--verbose"],
    ],
)
def test_verbose_before_or_after_the_command(flags):
    """In a fresh process (logging is set up once per process): -v in either place sets the
    log level to INFO (-vv: DEBUG); without it, WARNING."""
    import subprocess
    import sys

    def level(argv: list[str]) -> list[str]:
        code = (
            "import logging, sys; from flexreg.cli import run; rc = run(sys.argv[1:]); "
            "print('LEVEL', logging.getLogger().level, rc)"
        )
        done = subprocess.run(
            [sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120
        )
        return done.stdout.split("LEVEL")[-1].split()

    assert level(["info", str(LASERSCAN)]) == ["30", "0"]
    expected = "10" if "-vv" in flags else "20"
    assert level([a.format(f=LASERSCAN) for a in flags]) == [expected, "0"]


def test_hoisting_keeps_values_and_the_double_dash():
    assert hoist_root_flags(["--memory-budget", "8G", "register", "a", "-vv"]) == [
        "--memory-budget",
        "8G",
        "-vv",
        "register",
        "a",
    ]
    assert hoist_root_flags(["info", "--", "-v"]) == ["info", "--", "-v"]
    assert hoist_root_flags(["register", "--help"]) == ["register", "--help"]


# ------------------------------------------------------------------ camera sidecars


def test_grid_cameras_are_recovered_exactly():
    sph = SphericalCamera(180, 60, -np.pi, np.pi, 0.4, 2.6)
    pts = sph.rays().reshape(-1, 3) * np.linspace(2, 9, 180 * 60)[:, None]
    img = project(Scan(points=pts), sph)
    # stored bottom-up, as some E57 files do: the rows are reversed back
    flipped = to_scan(img)
    grid = range_image(flipped)
    upside = type(grid)(grid.xyz[::-1].copy(), grid.valid[::-1].copy(), grid.index[::-1].copy())
    fixed, err = grid_with_camera(upside)
    assert err < 1e-6 and isinstance(fixed.camera, SphericalCamera)
    np.testing.assert_allclose(fixed.xyz, img.xyz)
    v, u = np.mgrid[0:120, 0:160].astype(float)
    P = np.stack([(u - 79.5) / 300.0, (v - 59.5) / 310.0, np.ones_like(u)], -1) * 3.0
    grid = type(img)(P, np.ones((120, 160), bool), np.arange(160 * 120).reshape(120, 160))
    cam, err = fit_grid_camera(grid)
    assert isinstance(cam, PinholeCamera) and err < 1e-6
    assert cam.fx == pytest.approx(300.0) and cam.cy == pytest.approx(59.5)
    # noise of a few pixels fits no model: no camera
    noisy = type(img)(P + np.random.default_rng(0).normal(0, 0.05, P.shape), grid.valid, grid.index)
    assert fit_grid_camera(noisy)[0] is None


def _organised_pcd(path: Path, points: np.ndarray, shape: tuple[int, int]) -> None:
    """An ASCII organised PCD (HEIGHT x WIDTH, row-major), as a depth camera's driver writes."""
    h, w = shape
    head = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {w}\nHEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {w * h}\nDATA ascii\n"
    )
    path.write_text(head + "\n".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in points) + "\n")


@pytest.mark.parametrize("fmt", ["ptx", "e57", "pcd"])
def test_project_writes_the_camera_sidecar_of_gridded_files(fmt, tmp_path):
    """PTX, E57 (both by the project's own writers) and an organised PCD keep their grid and
    get the camera sidecar the README promises; the PNG reads back as a scan."""
    cam = (
        SphericalCamera(120, 40, -np.pi, np.pi, 0.6, 2.4)
        if fmt != "pcd"
        else PinholeCamera(100.0, 100.0, 39.5, 29.5, 80, 60)
    )
    rays = cam.rays().reshape(-1, 3)
    pts = rays * (3.0 + np.arange(len(rays)) % 7 * 0.1)[:, None]
    src = tmp_path / f"scan.{fmt}"
    if fmt == "pcd":
        _organised_pcd(src, rays / rays[:, 2:3] * 2.0, cam.shape)
    else:
        write_scan(src, to_scan(project(Scan(points=pts), cam)))
    out = tmp_path / "range.png"
    rc, stdout, err = run_cli(["project", src, "--out", out])
    assert rc == 0, err
    side = tmp_path / "range.camera.json"
    assert side.is_file(), stdout
    doc = json.loads(side.read_text())
    assert (doc["camera"]["width"], doc["camera"]["height"]) == (cam.width, cam.height)
    assert "camera sidecar" in " ".join(stdout.split())
    assert len(read_scan(out)) == cam.width * cam.height


def test_project_resamples_an_irregular_grid_with_a_sidecar(shared_data, tmp_path):
    """The 3DTK Kurt3D scan (a pitching line scanner: no camera fits its grid) is resampled
    through a fitted equirectangular camera, and says so."""
    out = tmp_path / "k.png"
    rc, stdout, err = run_cli(
        ["project", shared_data / "tls_3dtk_kurt3d" / "scan000.3d", "--out", out]
    )
    assert rc == 0, err
    assert (tmp_path / "k.camera.json").is_file()
    assert "resampled through a fitted equirectangular camera" in " ".join(stdout.split())


def test_a_second_run_into_a_folder_being_written_is_refused(tmp_path):
    """Two runs writing into one --out at once both used to "succeed", the later silently
    replacing the earlier: the first holds the folder (a lock file in it) while it runs."""
    import subprocess
    import sys
    import time

    out = tmp_path / "sim"
    out.mkdir()
    hold = (
        "import fcntl, os, sys, time\n"
        f"fd = os.open({str(out / LOCK)!r}, os.O_RDWR | os.O_CREAT)\n"
        "fcntl.flock(fd, fcntl.LOCK_EX)\n"
        "os.write(fd, str(os.getpid()).encode())\n"
        "print('held', flush=True)\n"
        "time.sleep(60)\n"
    )
    other = subprocess.Popen([sys.executable, "-c", hold], stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline().strip() == "held"
        argv = ["synth", "--scene", "room", "--stations", "1", "--resolution", "64x32",
                "--out", out]  # fmt: skip
        rc, _, err = run_cli(argv)
        line = one_error_line(err)
        assert rc == 1 and f"another flexreg run (process {other.pid})" in line, line
        assert sorted(p.name for p in out.iterdir()) == [LOCK]  # nothing written
    finally:
        other.kill()
        other.wait()
    t0 = time.monotonic()
    rc, _, err = run_cli(argv)  # the holder is gone: its lock file is no obstacle
    assert rc == 0, err
    assert (out / "gt.json").is_file() and not (out / LOCK).exists()  # released at the end
    assert run_cli([*argv, "--overwrite"])[0] == 0  # and a later run in this process holds it
    assert time.monotonic() - t0 < 60


def test_a_failed_run_into_a_new_folder_leaves_no_folder(tmp_path):
    out = tmp_path / "new" / "sim"
    """The folder a run holds is made when it starts; a run that fails after that (here:
    stations that cannot be placed) leaves no folder behind."""
    rc, _, err = run_cli(["synth", "--scene", "room", "--stations", "2", "--resolution", "64x32",
                          "--distance-m", "40,50", "--out", out])  # fmt: skip
    assert rc == 1 and "could not place station" in one_error_line(err)
    assert not (tmp_path / "new").exists()
