"""Measuring one method's call: wall time, peak memory and outcome, here or in its own process.

The call alone is measured (scans already in memory; a process's start-up, imports and data
transfer excluded). Peak memory is the increase of the resident set size during the call
(Linux: the kernel's high-water mark ``VmHWM``, reset through ``/proc/self/clear_refs`` just
before the call, minus the resident size then; elsewhere the Python-heap peak from
:mod:`tracemalloc`, which misses native allocations).

Isolated runs (:func:`run_isolated`) start each call in its own process (``multiprocessing``
fork server), so that a crash, a hang or memory kept by one method's allocator cannot touch the
others. :func:`machine_info` describes the machine for every benchmark protocol.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import pickle
import platform
import signal
import time
import traceback
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from importlib.metadata import PackageNotFoundError, version
from multiprocessing.reduction import ForkingPickler
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.bench.methods import run_method
from flexreg.core.results import PairResult
from flexreg.errors import FlexregError

__all__ = [
    "STATUSES",
    "Measured",
    "machine_info",
    "measure_call",
    "measure_isolated",
    "peak_memory_note",
    "preload_modules",
    "reset_high_water_mark",
    "run_isolated",
    "save_pair",
]

log = logging.getLogger(__name__)

STATUSES = ("ok", "failed", "error", "crashed", "timeout")


@dataclass(eq=False)
class Measured:
    """Outcome of one measured call.

    Attributes
    ----------
    status : {"ok", "failed", "error", "crashed", "timeout"}
        ``failed``: the method raised a :class:`FlexregError` (it reports that it could not
        register); ``error``: it raised another exception; ``crashed``: its process died;
        ``timeout``: no result within the time limit.
    result : PairResult or None
    message : str or None
        The error message (``"Type: message"`` for ``error``).
    time_s : float, seconds
        Wall time of the call (the limit for ``timeout``).
    peak_memory_mb : float or None, MiB
        Increase of the peak memory during the call (see :func:`peak_memory_note`).
    """

    status: str
    result: PairResult | None
    message: str | None
    time_s: float
    peak_memory_mb: float | None


def _read_status_kib(key: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def reset_high_water_mark() -> bool:
    """Reset the kernel's peak-RSS counter of this process (Linux); False if impossible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return _read_status_kib("VmHWM") is not None


def peak_memory_note() -> str:
    """How peak memory is measured on this machine (stated with every result)."""
    if reset_high_water_mark():
        return (
            "increase of the resident set size during the call: kernel high-water mark VmHWM "
            "(reset via /proc/self/clear_refs right before the call) minus the resident size then"
        )
    return (
        "Python-heap peak during the call (tracemalloc); native allocations (Open3D, KISS-ICP, "
        "OpenCV) are not counted on this platform"
    )


def measure_call(fn: Callable[[], PairResult]) -> Measured:
    """Call ``fn()`` in this process: wall time, peak memory increase, and the outcome
    (exceptions become ``failed``/``error`` statuses, never propagate)."""
    hwm = reset_high_water_mark()
    rss0 = _read_status_kib("VmRSS") if hwm else None
    if not hwm:
        tracemalloc.start()
    status, result, message = "ok", None, None
    t0 = time.perf_counter()
    try:
        result = fn()
    except FlexregError as e:
        status, message = "failed", str(e)
    except Exception as e:
        status, message = "error", f"{type(e).__name__}: {e}"
        log.debug("method raised:\n%s", traceback.format_exc())
    elapsed = time.perf_counter() - t0
    if hwm and rss0 is not None:
        peak = _read_status_kib("VmHWM")
        peak_mb = None if peak is None else max(0, peak - rss0) / 1024.0
    else:
        _, peak_b = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        peak_mb = peak_b / 2**20
    return Measured(status, result, message, elapsed, peak_mb)


def _child(
    conn: Any,
    fn: Callable[..., Any],
    args: tuple[Any, ...],
    kwargs: dict[str, Any],
    pair_file: str | None = None,
) -> None:
    """Process entry point: measure ``fn(*args, **kwargs)`` and send the :class:`Measured`.

    With ``pair_file``, ``(target, source)`` are read from it first (not measured) and
    appended to ``args``. Ctrl-C reaches the whole process group: the child ignores it and
    the parent, which handles it, kills the child (no traceback from here)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if pair_file is not None:
        with open(pair_file, "rb") as f:
            args = (*args, *pickle.load(f))
    m = measure_call(partial(fn, *args, **kwargs))
    try:
        _send(conn, m)
    except OSError:  # the parent stopped listening (interrupted, timed out): no one to tell
        pass
    finally:
        conn.close()


def _send(conn: Any, m: Measured) -> None:
    """Send ``m``; an unpicklable result still reports something."""
    try:
        payload = ForkingPickler.dumps(m)
    except Exception as e:
        m = Measured("error", None, f"result not transferable: {e}", m.time_s, None)
        payload = ForkingPickler.dumps(m)
    conn.send_bytes(payload)


#: every module a method imports on its first call (imports are not part of the measured
#: time), and numba's deferred start-up (:mod:`flexreg.bench._preload`)
_PRELOAD: tuple[str, ...] = (
    "flexreg.bench.measure",
    "flexreg.bench.methods",
    "flexreg.bench._preload",
    "flexreg.registration.pipeline",
    "flexreg.stages.alignment",
    "flexreg.stages.feature_images",
    "flexreg.stages.matching",
    "flexreg.stages.refinement.projective",
    "flexreg.stages.refinement.icp",
    "flexreg.stages.priors",
    "flexreg.baselines.open3d_icp",
    "flexreg.baselines.fpfh",
    "flexreg.baselines.kiss",
    "kiss_icp.config",
    "kiss_icp.kiss_icp",
    "open3d",
    "cv2",
    "scipy.fft",
    "scipy.ndimage",
    "scipy.spatial",
)


def preload_modules() -> list[str]:
    """The modules the fork server of isolated runs imports before it forks any method: every
    module a method imports on its first call, and :mod:`flexreg.bench._preload` (numba's
    deferred start-up and the cached kernels). A method's measured call then excludes its
    libraries' start-up alike."""
    return list(_PRELOAD)


def _context() -> Any:
    """The multiprocessing context for isolated runs: a fork server that has imported the
    heavy modules but run nothing (so its children start in a fraction of a second and
    inherit no thread pools), or spawn where there is no fork server."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(preload_modules())
        return ctx
    return multiprocessing.get_context("spawn")


def isolation_note() -> str:
    """How :func:`run_isolated` separates the methods on this machine."""
    return f"each method in its own process ({_context().get_start_method()})"


def measure_isolated(
    name: str,
    target: Any,
    source: Any,
    *,
    timeout_s: float | None = None,
    pair_file: str | PathLike[str] | None = None,
    **options: Any,
) -> Measured:
    """:func:`~flexreg.bench.methods.run_method` in a separate process, measured there (see
    :func:`run_isolated`).

    With ``pair_file`` (written by :func:`save_pair`), the process reads ``(target, source)``
    from that file before the measured call instead of receiving them through a pipe, which
    is much faster for scans of tens of millions of points read by several methods.
    """
    if pair_file is not None:
        return run_isolated(
            run_method, (name,), options, timeout_s=timeout_s, pair_file=str(pair_file)
        )
    return run_isolated(run_method, (name, target, source), options, timeout_s=timeout_s)


def save_pair(target: Any, source: Any, path: str | PathLike[str]) -> Path:
    """Pickle ``(target, source)`` to ``path`` for :func:`measure_isolated`."""
    p = Path(path)
    with open(p, "wb") as f:
        pickle.dump((target, source), f, protocol=pickle.HIGHEST_PROTOCOL)
    return p


def run_isolated(
    fn: Callable[..., Any],
    args: tuple[Any, ...] = (),
    kwargs: dict[str, Any] | None = None,
    *,
    timeout_s: float | None = None,
    pair_file: str | None = None,
) -> Measured:
    """Measure ``fn(*args, **kwargs)`` (:func:`measure_call`) in a separate process.

    ``fn`` must be importable by name (a module-level function). With ``pair_file`` (see
    :func:`save_pair`) the pickled ``(target, source)`` are read from it in the process,
    before the measured call, and appended to ``args``. A process that dies becomes
    ``crashed`` (with its signal or exit code), one that sends nothing within ``timeout_s``
    seconds is killed and becomes ``timeout``.
    """
    ctx = _context()
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, kwargs or {}, pair_file), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    try:
        ready = recv.poll(timeout_s)
        msg: Measured | None = None
        if ready:
            try:
                msg = recv.recv()
            except (EOFError, OSError):
                msg = None
        if not ready:
            proc.kill()
            proc.join()
            limit = float(timeout_s) if timeout_s is not None else time.perf_counter() - t0
            return Measured("timeout", None, f"no result within {limit:g} s", limit, None)
        proc.join(30)
        if msg is None:
            if proc.is_alive():
                proc.kill()
                proc.join()
            code = proc.exitcode
            how = (
                f"killed by signal {-code}"
                if code is not None and code < 0
                else f"exit status {code}"
            )
            return Measured(
                "crashed", None, f"process died ({how})", time.perf_counter() - t0, None
            )
        return msg
    finally:
        recv.close()
        if proc.is_alive():
            proc.kill()
            proc.join()


def machine_info() -> dict[str, Any]:
    """Cores, CPU, platform, Python and library versions, load average (for every benchmark's
    protocol: the comparison, ``flexreg bench`` and the scripts of ``benchmarks/``)."""
    import cv2  # heavy: OpenCV and Open3D only for their versions
    import open3d

    try:
        kiss_icp: str | None = version("kiss-icp")
    except PackageNotFoundError:
        kiss_icp = None
    info: dict[str, Any] = {
        "cores": os.cpu_count(),
        "cpu": _cpu_name(),
        "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "open3d": open3d.__version__,
        "kiss_icp": kiss_icp,
    }
    if hasattr(os, "getloadavg"):
        info["load_average"] = list(os.getloadavg())
    return info


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
