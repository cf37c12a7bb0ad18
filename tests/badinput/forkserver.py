"""A fork server for the bad-input corpus: imports the command line once, then runs each case
in a fresh forked child, as ``flexreg`` would run it from a shell.

Every case starting a new interpreter paid about half a second of CPU for importing the
command line (typer, rich, pydantic, numpy) before doing anything; over 250 cases on 2 cores
that was most of the corpus's time, and the modules ``register`` and ``survey`` import when
they start working (the pipeline, the survey, the readers) about a second more of each such
case: the server imports both once (``PRELOAD``). The child of a fork starts with those
modules loaded and nothing else done: it becomes a session leader, moves to the case folder,
takes the case's environment and (for ``memory_limit`` cases) the address-space limit, points
stdout and stderr at the given files, and runs ``flexreg.cli.main`` with the case's arguments.
An exception that escapes is printed as Python prints it (a traceback, which the corpus
counts) and exits 1.

Protocol, one JSON object per line: request ``{"argv", "cwd", "env", "stdout", "stderr",
"memory_limit", "timeout_s"}`` on stdin; reply ``{"rc", "seconds", "peak_rss_mb"}`` on stdout
(``rc`` null when the case was killed after ``timeout_s``).
"""

from __future__ import annotations

import json
import os
import resource
import signal
import sys
import time

PRELOAD = (
    "flexreg.io",
    "flexreg.io.info",
    "flexreg.registration.pipeline",
    "flexreg.stages.projection",
    "flexreg.survey.project",
    "flexreg.survey.outputs",
)


def _child(req: dict) -> None:  # never returns
    code = 1
    try:
        os.setsid()
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)  # not the request pipe
        os.close(null)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        if req["memory_limit"]:
            lim = int(req["memory_limit"])
            resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
        for fd, path in ((1, req["stdout"]), (2, req["stderr"])):
            f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(f, fd)
            os.close(f)
        sys.argv = ["flexreg", *req["argv"]]
        from flexreg.cli import main

        try:
            main()
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:
                pass
        os._exit(code)


def _run(req: dict) -> dict:
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        _child(req)
    killed = False
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        if not killed and time.perf_counter() - t0 > req["timeout_s"]:
            killed = True
            try:
                os.killpg(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.01)
    return {
        "rc": None if killed else os.waitstatus_to_exitcode(status),
        "seconds": time.perf_counter() - t0,
        "peak_rss_mb": usage.ru_maxrss / 1024,
    }


def serve() -> None:
    import importlib

    import flexreg.cli  # noqa: F401  (loaded once, inherited by every case)

    # the modules the commands import when they start working: about a second of every
    # register or survey case otherwise; a shell's run loads the same ones, only later
    for name in PRELOAD:
        importlib.import_module(name)

    for line in sys.stdin:
        if line.strip():
            reply = _run(json.loads(line))
            sys.stdout.write(json.dumps(reply) + "\n")
            sys.stdout.flush()


if __name__ == "__main__":
    serve()
