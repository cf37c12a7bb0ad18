"""The survey's Dask cluster: bounded worker counts, a dashboard only when asked for (and on
loopback), scheduler addresses checked before any work."""

from __future__ import annotations

import pytest
from conftest import one_error_line, run_cli

from flexreg.errors import ConfigError
from flexreg.survey.execute import (
    check_workers,
    dashboard_address,
    dask_client,
    default_workers,
    scheduler_address,
)


def test_workers_are_bounded_by_the_cores_unless_the_cluster_is_the_users():
    most = 2 * default_workers()
    check_workers(None, None)
    check_workers(1, None)
    check_workers(most, None)
    for bad in (0, -1, most + 1, 1000):
        with pytest.raises(ConfigError, match=rf"--workers: must be from 1 to {most}"):
            check_workers(bad, None)
    check_workers(1000, "tcp://10.0.0.1:8786")  # ignored with a scheduler


def test_a_thousand_workers_are_refused_before_reading(tmp_path):
    """``--workers 1000`` once spawned dozens of processes and gigabytes in seconds."""
    scans = [tmp_path / "a.ptx", tmp_path / "b.ptx"]  # not even read
    out = tmp_path / "out"
    rc, _, err = run_cli(["survey", *scans, "--out", out, "--workers", "1000"])
    assert rc == 1 and "--workers: must be from 1 to" in one_error_line(err)
    assert not out.exists()


def test_dashboard_addresses():
    assert dashboard_address(None) is None
    assert dashboard_address("8787") == "127.0.0.1:8787"
    assert dashboard_address(":0") == "127.0.0.1:0"
    assert dashboard_address("0.0.0.0:8787") == "0.0.0.0:8787"
    for bad in ("http://x", "host:", "99999", "a:b"):
        with pytest.raises(ConfigError, match="--dashboard"):
            dashboard_address(bad)


def test_scheduler_addresses():
    assert scheduler_address("tcp://10.0.0.1:8786") == ("10.0.0.1", 8786)
    assert scheduler_address("10.0.0.1:8786") == ("10.0.0.1", 8786)
    assert scheduler_address("tls://[::1]:8786") == ("::1", 8786)
    for bad in ("http://h:80", "inproc://x", "tcp://h", "tcp://:8786", "tcp://h:0", "tcp://h:x"):
        with pytest.raises(ConfigError, match="--scheduler"):
            scheduler_address(bad)


def _web(client) -> tuple[set[str], int | None]:
    """Hosts the scheduler's web server listens on, and the status of its dashboard page."""
    import urllib.error
    import urllib.request

    def hosts(dask_scheduler):
        return {sock.getsockname()[0] for sock in dask_scheduler.http_server._sockets.values()}

    port = client.scheduler_info()["services"]["dashboard"]
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/status", timeout=30) as r:
            status = r.status
    except urllib.error.HTTPError as e:
        status = e.code
    return client.run_on_scheduler(hosts), status


def test_the_local_cluster_serves_no_dashboard_unless_asked_and_then_on_loopback():
    """An unauthenticated dashboard on every interface while a survey ran was a hole: the
    local cluster listens on loopback only (scheduler, workers, the web server's health
    routes) and serves its dashboard page only when asked."""
    with dask_client(2, None) as client:
        assert _web(client) == ({"127.0.0.1"}, 404)
        assert client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert all(w.startswith("tcp://127.0.0.1:") for w in client.scheduler_info()["workers"])
    with dask_client(2, None, dashboard=":0") as client:
        assert _web(client) == ({"127.0.0.1"}, 200)


def test_an_exception_in_the_clients_event_loop_prints_no_traceback(caplog):
    """Ctrl-C while the client waits can make Dask's own cancel callback fail (its future not
    yet created); the client's event loop logs that through tornado with a traceback, which
    reached the console between the progress bar and the one-line error. Nothing the event
    loop logs below critical is shown while the cluster runs; the logger is as it was after."""
    import logging
    import threading

    import distributed  # noqa: F401  (its logging set-up first: the level it leaves is kept)

    ran = threading.Event()

    def fails() -> None:
        ran.set()
        raise NameError("a callback of the client's event loop")

    before = logging.getLogger("tornado.application").level
    caplog.set_level(logging.DEBUG)
    with dask_client(2, None) as client:
        client.loop.add_callback(fails)
        assert ran.wait(10)
        client.scheduler_info()  # one more round trip: the loop has logged what it would
    assert not [r for r in caplog.records if r.name.startswith("tornado")]
    assert logging.getLogger("tornado.application").level == before


def _worker_environ():
    import os

    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")}


def test_local_workers_keep_the_allocators_defaults_and_one_thread(monkeypatch):
    """Dask's default ``MALLOC_TRIM_THRESHOLD_`` for its workers switches off glibc's adaptive
    mmap threshold and made every link 1.4-1.5 times slower; the local cluster's workers
    start without it (unless the user set it) and keep the one-thread caps (unless the user
    set them: a run under ``scripts/cpu-variant.sh generic-4-threads`` asks for 4)."""
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    with dask_client(2, None) as client:
        envs = list(client.run(_worker_environ).values())
    assert envs == [{"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}] * 2


def test_a_tasks_io_error_on_a_worker_is_one_line_naming_its_file(tmp_path):
    """A full disk or a read-only cache on a worker used to surface as an OSError traceback
    from inside a Dask task."""
    import os

    from flexreg.errors import InputError
    from flexreg.survey.execute import run_tasks

    gone = str(tmp_path / "cache" / "station.prepared")
    for workers in (1, 2):
        with dask_client(workers, None) as client:
            with pytest.raises(InputError, match=r"station\.prepared: No such file") as e:
                run_tasks(client, os.stat, [(str(tmp_path),), (gone,)])
            assert str(e.value).count("\n") == 0


def _survey_two(project, out, workers):
    """``flexreg survey`` of a project's first two stations: exit status and stderr."""
    scans = [project / "station_00.ptx", project / "station_01.ptx"]
    rc, _, err = run_cli(["survey", *scans, "--out", out, "--workers", str(workers)])
    return rc, err


@pytest.mark.parametrize(
    "code, text", [("ENOSPC", "No space left on device"), ("EROFS", "Read-only file system")]
)
def test_a_full_disk_while_preparing_is_one_line_exit_1(code, text, tmp_path, monkeypatch):
    """A full disk or an --out that turned read-only while the survey writes its cache."""
    import errno

    from conftest import room_project

    from flexreg.survey import stations

    project = room_project(tmp_path / "p", 2, width=128, height=64)

    def full(path, write):
        raise OSError(getattr(errno, code), text, str(path))

    monkeypatch.setattr(stations, "_atomic_bytes", full)
    out = tmp_path / "out"
    rc, err = _survey_two(project, out, 1)
    line = one_error_line(err)
    assert rc == 1 and text in line and ".partial" not in line, line
    assert not (out / "poses.json").exists()


def test_a_local_cluster_that_does_not_start_is_one_line_exit_1_and_nothing_written(tmp_path):
    """A full disk where the workers keep their files stopped the survey with Dask's
    "Cluster failed to start" and a traceback. Here the workers' directory lies under a
    regular file, which stops a real local cluster the same way, on any machine."""
    import dask.config
    from conftest import room_project

    from flexreg.errors import ClusterError

    project = room_project(tmp_path / "p", 2, width=128, height=64)
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    where = str(blocked / "workers")
    with dask.config.set({"temporary-directory": where}):
        with pytest.raises(ClusterError, match="did not start: NotADirectoryError") as e:
            with dask_client(2, None):
                pass
        assert where in str(e.value) and "\n" not in str(e.value)
        out = tmp_path / "out"
        rc, err = _survey_two(project, out, 2)
    line = one_error_line(err)
    assert rc == 1 and "local Dask cluster of 2 worker(s) did not start" in line, line
    assert not out.exists()
