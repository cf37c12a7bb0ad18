"""The bad-input corpus, run through the command line, one subprocess per case.

``make_corpus.py`` writes the cases (``badcases.py`` lists them); this module runs them all in
parallel subprocesses once per session, then checks each: exit status 1, one ``error:`` line
naming the file or option at fault, no traceback, the case folder byte-identical afterwards
(nothing written, nothing replaced, no temporary left), no hang (:data:`TIMEOUT_S`), and for
the cases marked ``memory_limit`` an address-space limit of 1 GB in the child (RLIMIT_AS), so
a header that makes flexreg allocate gigabytes fails the case instead of the machine. The run
ends with a summary line: cases, clean errors, tracebacks, partial outputs, hangs.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import BADINPUT_SUMMARY
from make_corpus import MEMORY_LIMIT_BYTES, Case, build

#: a case that takes longer hangs (a whole corpus runs in well under a minute on 2 cores)
TIMEOUT_S = 120.0
WORKERS = max(2, min(4, (os.cpu_count() or 2)))
CLI = [sys.executable, "-c", "from flexreg.cli import main; main()"]


@dataclass
class Outcome:
    case: Case
    rc: int | None  # None: killed after TIMEOUT_S
    stdout: str
    stderr: str
    seconds: float
    peak_rss_mb: float
    before: dict[str, str]
    after: dict[str, str]

    @property
    def traceback(self) -> bool:
        return "Traceback" in self.stderr or "Traceback" in self.stdout

    @property
    def changed(self) -> list[str]:
        keys = set(self.before) | set(self.after)
        return sorted(k for k in keys if self.before.get(k) != self.after.get(k))

    @property
    def error_lines(self) -> list[str]:
        return [ln for ln in self.stderr.splitlines() if ln.startswith("error:")]

    @property
    def names_it(self) -> bool:
        lines = self.error_lines
        return len(lines) == 1 and any(n in lines[0] for n in self.case.names)

    @property
    def clean(self) -> bool:
        return (
            self.rc == 1
            and not self.traceback
            and not self.changed
            and self.names_it
            and "Traceback" not in self.stderr
        )


def snapshot(folder: Path) -> dict[str, str]:
    """Every entry below ``folder``: its kind and content hash (links: their target)."""
    found: dict[str, str] = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            found[rel] = "link:" + os.readlink(p)
        elif p.is_dir():
            found[rel] = "dir"
        else:
            found[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return found


def _limit_memory() -> None:  # runs in the child before exec
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))


def run_case(case: Case, folder: Path) -> Outcome:
    argv = [a.replace("{d}", str(folder)) for a in case.argv]
    env = {k: v for k, v in os.environ.items() if k != "FLEXREG_MEMORY_BUDGET"}
    env.update({**case.env, "COLUMNS": "200", "NO_COLOR": "1"})
    before = snapshot(folder)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [*CLI, *argv],
            stdout=out,
            stderr=err,
            env=env,
            cwd=folder,
            preexec_fn=_limit_memory if case.memory_limit else None,
            start_new_session=True,
        )
        killed = threading.Event()

        def kill() -> None:
            killed.set()
            os.killpg(proc.pid, signal.SIGKILL)

        timer = threading.Timer(TIMEOUT_S, kill)
        timer.start()
        _, status, usage = os.wait4(proc.pid, 0)
        timer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        seconds = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
    return Outcome(
        case,
        None if killed.is_set() else proc.returncode,
        stdout,
        stderr,
        seconds,
        usage.ru_maxrss / 1024,
        before,
        snapshot(folder),
    )


def summary(outcomes: list[Outcome]) -> str:
    n = len(outcomes)
    clean = sum(o.clean for o in outcomes)
    tracebacks = sum(o.traceback for o in outcomes)
    partial = sum(bool(o.changed) for o in outcomes)
    hangs = sum(o.rc is None for o in outcomes)
    other = n - clean - sum(o.traceback or bool(o.changed) or o.rc is None for o in outcomes)
    slowest = max(outcomes, key=lambda o: o.seconds)
    heaviest = max((o for o in outcomes if o.case.memory_limit), key=lambda o: o.peak_rss_mb)
    return (
        f"bad-input corpus: {n} cases, {clean} clean errors, {tracebacks} tracebacks, "
        f"{partial} partial outputs, {hangs} hangs, {other} other failures (wrong status or "
        f"message); slowest {slowest.case.id} {slowest.seconds:.1f} s; largest peak under the "
        f"1 GB limit {heaviest.case.id} {heaviest.peak_rss_mb:.0f} MB"
    )


_BUILT: list[tuple[Path, list[Case]]] = []


def corpus() -> tuple[Path, list[Case]]:
    """The corpus, built once per process in a temporary folder (removed at exit)."""
    if not _BUILT:
        root = Path(tempfile.mkdtemp(prefix="flexreg-badinput-"))
        atexit.register(shutil.rmtree, root, ignore_errors=True)
        _BUILT.append((root, build(root)))
    return _BUILT[0]


@pytest.fixture(scope="session")
def outcomes(pytestconfig) -> dict[str, Outcome]:
    root, cases = corpus()
    with ThreadPoolExecutor(WORKERS) as pool:
        done = list(pool.map(lambda c: run_case(c, root / "cases" / c.id), cases))
    pytestconfig.stash[BADINPUT_SUMMARY] = summary(done)
    return {o.case.id: o for o in done}


@pytest.mark.parametrize("case_id", [c.id for c in corpus()[1]])
def test_case_fails_cleanly(outcomes, case_id):
    o = outcomes[case_id]
    detail = f"\n$ flexreg {' '.join(o.case.argv)}\nexit {o.rc}\nstderr:\n{o.stderr[-3000:]}"
    assert o.rc is not None, f"hang: killed after {TIMEOUT_S} s{detail}"
    assert not o.traceback, f"traceback{detail}"
    assert not o.changed, f"files written or replaced: {o.changed}{detail}"
    assert o.rc == 1, f"exit status {o.rc}, expected 1{detail}"
    assert len(o.error_lines) == 1, f"expected one error line{detail}"
    assert o.names_it, f"the error line names none of {o.case.names}{detail}"


def test_corpus_is_large_and_covers_every_class(outcomes):
    kinds = {o.case.kind for o in outcomes.values()}
    assert len(outcomes) >= 60
    assert kinds >= {"overwrite", "partial", "header", "halfread", "option", "broken", "pair"}
    assert sum(o.case.memory_limit for o in outcomes.values()) >= 30
