"""Interruption safety: Ctrl-C (SIGINT) or SIGTERM during a long command.

Each test starts the command in a subprocess on data big enough that it works for several
seconds, waits until it is working (its own progress lines say so), sends the signal, and
checks: exit status 130 (SIGINT) or 143 (SIGTERM), exactly one ``error:`` line on stderr and no
traceback, and no output file nor temporary left in the output folder (earlier results stay
byte-identical). A survey interrupted halfway resumes from its cache: the re-run prepares only
the stations the first run had not finished.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

CLI = [sys.executable, "-c", "from flexreg.cli import main; main()"]
#: longest wait for a command to reach the point where it is interrupted
START_TIMEOUT_S = 300.0


def room(height: int, width: int, offset=(0.0, 0.0, 0.0), seed: int = 0) -> np.ndarray:
    """(H, W, 3) points of a 9 x 6 x 3 m room with a few boxes, seen from ``offset``."""
    rng = np.random.default_rng(seed)
    th = np.linspace(0.3, np.pi - 0.3, height)
    ph = np.linspace(-np.pi, np.pi, width, endpoint=False)
    P, T = np.meshgrid(ph, th)
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    o = np.asarray(offset, dtype=np.float64)
    lo, hi = np.array([-4.5, -3.0, -1.5]) - o, np.array([4.5, 3.0, 1.5]) - o
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, hi / d, lo / d)
    t = np.where(np.isfinite(t) & (t > 0), t, np.inf).min(axis=-1)
    boxes = [((-3.5, -2.5, -1.5), (-2.5, -1.0, 0.2)), ((2.0, 1.5, -1.5), (3.2, 2.6, -0.4))]
    boxes += [((1.0, -2.6, -1.5), (1.6, -1.9, 1.0)), ((-1.0, 2.0, -1.5), (0.2, 3.0, -0.9))]
    for b_lo, b_hi in boxes:
        a, b = np.array(b_lo) - o, np.array(b_hi) - o
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = a / d, b / d
        near = np.nanmax(np.minimum(t1, t2), axis=-1)
        far = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (near <= far) & (near > 0) & (near < t)
        t = np.where(hit, near, t)
    t = t + rng.normal(0, 0.002, t.shape)
    return d * t[..., None]


def write_station(path: Path, height: int, width: int, offset, seed: int) -> None:
    from flexreg.core.scan import Scan
    from flexreg.io import write_scan

    write_scan(path, Scan.from_organized(room(height, width, offset, seed), name=path.stem))


def _default_sigint() -> None:
    """In the child: Ctrl-C as a terminal delivers it, whatever the test run inherited (a
    suite started in the background of a non-interactive shell ignores SIGINT, and Python
    then leaves it ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(argv: list[str], cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    return subprocess.Popen(
        [*CLI, *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=_default_sigint,
    )


def wait_until(proc: subprocess.Popen, ready, what: str) -> None:
    """Poll ``ready()`` until true; fail if the process ended first."""
    t0 = time.monotonic()
    while not ready():
        if proc.poll() is not None:
            _, err = proc.communicate()
            pytest.fail(f"ended (exit {proc.returncode}) before {what}:\n{err.decode()[-2000:]}")
        if time.monotonic() - t0 > START_TIMEOUT_S:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"not {what} after {START_TIMEOUT_S} s")
        time.sleep(0.05)


def interrupt(proc: subprocess.Popen, signum: int) -> tuple[int, str, str]:
    """Send ``signum`` to the command (alive at that moment) and collect its end."""
    assert proc.poll() is None, "the command ended before it could be interrupted"
    if signum == signal.SIGINT:  # Ctrl-C reaches the whole process group (workers too)
        os.killpg(proc.pid, signum)
    else:  # kill PID, or a scheduler stopping the job
        proc.send_signal(signum)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail(f"did not stop within 120 s of signal {signum}")
    return proc.returncode, out.decode(errors="replace"), err.decode(errors="replace")


def check_one_line(rc: int, err: str, signum: int) -> None:
    assert rc == 128 + signum, f"exit {rc}, expected {128 + signum}\n{err[-2000:]}"
    assert "Traceback" not in err, err[-3000:]
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err[-2000:]
    assert "interrupted" in lines[0] or "terminated" in lines[0], lines[0]


def listing(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def big_pair(tmp_path_factory) -> Path:
    """Two 2048 x 1024 stations (2 M points each) of one room, 1.2 m apart."""
    d = tmp_path_factory.mktemp("interrupt")
    write_station(d / "a.npz", 1024, 2048, (0.0, 0.0, 0.0), 1)
    write_station(d / "b.npz", 1024, 2048, (1.2, -0.5, 0.1), 2)
    return d


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_register_interrupted_writes_nothing(big_pair, tmp_path, signum):
    out = tmp_path / "out"
    out.mkdir()
    (out / "previous.json").write_text('{"earlier": "result"}')
    before = listing(out)
    argv = [
        "register", str(big_pair / "a.npz"), str(big_pair / "b.npz"),
        "--out", str(out / "T.json"), "--txt", str(out / "T.txt"),
        "--matches", str(out / "m.png"), "--merged", str(out / "merged.ply"),
    ]  # fmt: skip
    proc = start(argv, tmp_path)
    err_seen = bytearray()

    def reading_done() -> bool:  # both scans read: the pipeline is at work
        import select

        while select.select([proc.stderr], [], [], 0)[0]:
            chunk = os.read(proc.stderr.fileno(), 65536)
            if not chunk:
                break
            err_seen.extend(chunk)
        return "✓ Reading".encode() in err_seen  # one line for both (read at once)

    wait_until(proc, reading_done, "reading both scans")
    time.sleep(0.5)
    rc, _, err = interrupt(proc, signum)
    check_one_line(rc, err_seen.decode(errors="replace") + err, signum)
    assert listing(out) == before  # nothing new, nothing replaced, no temporary


def test_survey_interrupted_resumes_from_its_cache(tmp_path):
    """SIGINT while the survey prepares its stations; the re-run reuses every station the
    first run had cached (their cache files are not written again) and finishes."""
    scans = tmp_path / "scans"
    scans.mkdir()
    offsets = [(0, 0, 0), (1.0, 0.3, 0), (2.0, -0.2, 0), (-1.0, 0.5, 0), (-2.0, -0.4, 0)]
    for i, o in enumerate(offsets):
        write_station(scans / f"st{i}.npz", 512, 1024, o, i)
    out = tmp_path / "out"
    argv = ["survey", str(scans), "--out", str(out), "--workers", "1", "--pairs", "sequential"]
    proc = start(argv, tmp_path)
    cache = out / "cache"

    def some_cached() -> bool:
        return len(list(cache.glob("*.prepared.npz"))) >= 2

    wait_until(proc, some_cached, "caching two stations")
    rc, _, err = interrupt(proc, signal.SIGINT)
    check_one_line(rc, err, signal.SIGINT)
    cached = {p.name: p.stat().st_mtime_ns for p in cache.glob("*.prepared.npz")}
    assert 2 <= len(cached) < len(offsets), f"{len(cached)} cached: interrupt came too late"
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert all(p.startswith("cache/") for p in left), left  # no result file, only the cache
    assert not [p for p in left if ".partial" in p], left  # no half-written cache entry

    # the re-run links one pair only: the stations' cache keys do not depend on the pairs,
    # and every station is prepared (or read from the cache) whatever they are
    one = tmp_path / "one-pair.csv"
    one.write_text("target,source\nst0,st1\n")
    again_argv = [*argv[:-2], "--pairs", str(one)]
    done = subprocess.run(
        [*CLI, *again_argv], cwd=tmp_path, capture_output=True, text=True, timeout=900,
        env={**os.environ, "COLUMNS": "200", "NO_COLOR": "1"},
    )  # fmt: skip
    assert done.returncode in (0, 3), done.stderr[-3000:]
    assert (out / "poses.json").is_file()
    again = {p.name: p.stat().st_mtime_ns for p in cache.glob("*.prepared.npz")}
    assert len(again) == len(offsets)
    assert all(again[name] == t for name, t in cached.items())  # not prepared again
    n_new = len(offsets) - len(cached)
    assert f"{n_new} station(s) prepared, {len(cached)} from the cache" in done.stdout, done.stdout[
        -2000:
    ]


def stderr_reader(proc: subprocess.Popen):
    """A ``ready()`` helper: ``seen(text)`` is true once stderr has shown ``text``; the text
    read so far is in ``seen.buffer``."""
    import select

    buffer = bytearray()

    def seen(text: str, times: int = 1) -> bool:
        while select.select([proc.stderr], [], [], 0)[0]:
            chunk = os.read(proc.stderr.fileno(), 65536)
            if not chunk:
                break
            buffer.extend(chunk)
        return buffer.count(text.encode()) >= times

    seen.buffer = buffer  # type: ignore[attr-defined]
    return seen


def test_synth_interrupted_after_staging_commits_nothing(tmp_path):
    """Ctrl-C after some station files are staged (written as temporaries): none of them is
    renamed into place (typer turns Ctrl-C into a return status; the command line must still
    discard the staged outputs)."""
    out = tmp_path / "site"
    argv = ["synth", "--stations", "4", "--resolution", "1024x512", "--out", str(out)]
    proc = start(argv, tmp_path)

    def staged() -> bool:
        return out.is_dir() and any(".partial" in p.name for p in out.iterdir())

    wait_until(proc, staged, "staging a station file")
    rc, _, err = interrupt(proc, signal.SIGINT)
    check_one_line(rc, err, signal.SIGINT)
    assert not out.exists() or not any(out.iterdir()), sorted(p.name for p in out.iterdir())


def test_bench_interrupted_writes_no_results(tmp_path):
    """Ctrl-C during ``bench`` (methods running in their own processes): exit 130, one line,
    no results folder, nothing left in --out beyond what was there."""
    out = tmp_path / "bench"
    out.mkdir()
    (out / "earlier-run.txt").write_text("kept")
    argv = [
        "bench", "--quick", "--suite", "synthetic", "--methods", "flexreg,icp-point",
        "--out", str(out), "--overwrite",
    ]  # fmt: skip
    proc = start(argv, tmp_path)
    t0 = time.monotonic()
    wait_until(proc, lambda: time.monotonic() - t0 > 15, "15 s of work")
    rc, _, err = interrupt(proc, signal.SIGINT)
    check_one_line(rc, err, signal.SIGINT)
    assert sorted(p.name for p in out.iterdir()) == ["earlier-run.txt"]


def test_survey_on_dask_workers_interrupted_is_one_line(tmp_path):
    """Ctrl-C reaches the whole process group, Dask's worker processes too: they must not
    print their own tracebacks; the survey stops with one line and leaves only its cache."""
    scans = tmp_path / "scans"
    scans.mkdir()
    for i, o in enumerate([(0, 0, 0), (1.0, 0.3, 0), (2.0, -0.2, 0), (-1.0, 0.5, 0)]):
        write_station(scans / f"st{i}.npz", 256, 512, o, i)
    out = tmp_path / "out"
    proc = start(["survey", str(scans), "--out", str(out), "--workers", "2"], tmp_path)
    wait_until(proc, lambda: any((out / "cache").glob("*.prepared.npz")), "caching a station")
    rc, _, err = interrupt(proc, signal.SIGINT)
    check_one_line(rc, err, signal.SIGINT)
    left = [p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()]
    assert all(p.startswith("cache/") and ".partial" not in p for p in left), left


class _Finaliser:
    """A native object's finaliser that the Ctrl-C lands in: Python raises KeyboardInterrupt
    inside ``__del__`` and only prints "Exception ignored" (the run the SIGINT test once met,
    in llvmlite's ``ObjectRef.__del__``). ``signal.raise_signal`` runs the handler at once."""

    def __del__(self) -> None:
        signal.raise_signal(signal.SIGINT)


@pytest.fixture()
def cli_signals():
    """The command line's handlers, as ``main()`` installs them; restored afterwards."""
    from flexreg.cli import signals

    old = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    hook = sys.unraisablehook
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signals.install()
    yield signals
    signals.clear()
    signal.signal(signal.SIGINT, old[0])
    signal.signal(signal.SIGTERM, old[1])
    sys.unraisablehook = hook


def test_a_swallowed_signal_is_not_reported_but_other_errors_are(cli_signals, capsys):
    """A signal raised in a finaliser or a ctypes callback (numba's cache writer, met by a
    SIGTERM in CI) is dropped by Python with an "Exception ignored ... Traceback" report; the
    command still ends with its one line, so that report is silenced. Any other exception a
    finaliser drops, or a KeyboardInterrupt with no signal pending, is still reported by the
    hook in place before."""
    from types import SimpleNamespace

    seen: list = []
    sys.unraisablehook = seen.append  # the hook in place before (the fixture restores it)
    cli_signals.install()
    cli_signals.install()  # twice (one process, two commands): still one report in place
    _Finaliser()  # its KeyboardInterrupt is dropped: pending, not reported
    assert cli_signals.signalled() == signal.SIGINT
    assert seen == []

    class _Broken:
        def __del__(self) -> None:
            raise ValueError("a finaliser's own error")

    _Broken()
    assert [type(u.exc_value) for u in seen] == [ValueError]
    cli_signals.clear()
    sys.unraisablehook(SimpleNamespace(exc_value=KeyboardInterrupt()))
    assert [type(u.exc_value) for u in seen] == [ValueError, KeyboardInterrupt]
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_swallowed_ctrl_c_still_ends_the_stage(cli_signals):
    from flexreg.cli._common import stage

    with pytest.raises(KeyboardInterrupt):
        with stage("Working"):
            _Finaliser()  # collected at once: its KeyboardInterrupt is printed and dropped
            after = "reached"  # the stage's own code carried on past the signal
    assert after == "reached"
    assert cli_signals.signalled() == 0  # acted on once: the next command starts clean


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_swallowed_ctrl_c_writes_nothing(cli_signals, tmp_path, monkeypatch, capsys):
    from conftest import REPO

    import flexreg.io.info as info
    from flexreg.cli import run

    real = info.write_range_image

    def write_then_collect(*args, **kwargs):
        written = real(*args, **kwargs)
        _Finaliser()
        return written

    monkeypatch.setattr(info, "write_range_image", write_then_collect)
    out = tmp_path / "out" / "r.png"
    src = REPO / "data" / "laserscan" / "laserscan-depth.png"
    assert run(["project", str(src), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert [ln for ln in err.splitlines() if ln.startswith("error:")] == [
        "error: interrupted (Ctrl-C): nothing written, earlier results untouched"
    ]
    assert not out.parent.exists() or not any(out.parent.iterdir())
    monkeypatch.undo()
    assert run(["project", str(src), "--out", str(out)]) == 0  # the next command is unaffected
    assert out.is_file()
