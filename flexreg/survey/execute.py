"""Running a survey's work on Dask: station preparations and pairwise links.

By default a :class:`distributed.LocalCluster` of ``workers`` processes (one thread each) runs
on this machine; with a scheduler address the same tasks run on an existing cluster (see
docs/survey.md: every worker needs flexreg installed and the scans and the output folder's
``cache/`` at the same paths). With one worker and no scheduler everything runs in the calling
process, without Dask.

A task's result depends only on its inputs: the prepared stations are read back from the cache
(bit for bit what was stored) and every link uses the registration's own seed, so the poses
are identical whatever the number of workers or the order tasks finish in.
"""

from __future__ import annotations

import hashlib
import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.errors import ClusterError, ConfigError, FlexregError, InputError
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.evidence import Evidence
from flexreg.registration.pipeline import Registration
from flexreg.registration.verdict import full_open_clear
from flexreg.survey.links import Alternative, Link, alternatives_of
from flexreg.survey.pairs import Candidate
from flexreg.survey.stations import (
    PREPARED_SUFFIX,
    CacheEntryError,
    Prepared,
    load_prepared,
    read_entry,
    write_entry,
)

log = logging.getLogger(__name__)

#: axes of the per-axis strength, as the verdict's evidence names them
AXES = ("roll", "pitch", "yaw", "x", "y", "z")


@dataclass(frozen=True)
class ProgressEvent:
    """What the library reports while it works (the CLI draws it).

    Attributes
    ----------
    phase : {"prepare", "links", "positions", "map check", "refine"}
        ``"positions"``: the links rough positions bring near, registered in their windows.
    done, total : int
        Tasks finished and in all, in this phase.
    confident, uncertain, failed : int
        Links so far by pairwise outcome (before the graph's checks).
    elapsed_s : float
        Seconds since the phase started.
    """

    phase: str
    done: int
    total: int
    confident: int = 0
    uncertain: int = 0
    failed: int = 0
    elapsed_s: float = 0.0

    @property
    def eta_s(self) -> float | None:
        """Seconds left at the pace so far (None before the first task ends)."""
        if self.done <= 0 or self.done >= self.total:
            return None if self.done <= 0 else 0.0
        return self.elapsed_s / self.done * (self.total - self.done)


Progress = Callable[[ProgressEvent], None] | None


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def scheduler_address(address: str) -> tuple[str, int]:
    """Host and port of a Dask scheduler address, ``tcp://HOST:PORT`` or ``tls://HOST:PORT``
    (``HOST:PORT`` means tcp).

    Raises
    ------
    ConfigError
        Another scheme, no host, or no port in 1-65535.
    """
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme not in ("tcp", "tls"):
        raise ConfigError(
            f"--scheduler: {address!r}: the scheme must be tcp:// or tls:// (got {scheme}://)"
        )
    host, colon, port = rest.rpartition(":")
    host = host.strip("[]")
    if not colon or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"--scheduler: {address!r} is not {scheme}://HOST:PORT")
    return host, int(port)


#: bytes a Dask scheduler's first message (its handshake) may announce; another server's
#: greeting read as a Dask frame header announces far more (or nothing at all)
_HANDSHAKE_MAX_BYTES = 1 << 24


#: seconds the scheduler probe waits for a connection and for the scheduler's greeting
SCHEDULER_PROBE_S = 10.0


def _probe_scheduler(address: str) -> None:
    """Refuse, in one line and within :data:`SCHEDULER_PROBE_S`, an address where no Dask scheduler
    listens: a closed port at once, instead of after the client's retries; another service
    (a web server waits for a request, so the client would wait for ever; a server that
    greets first would have its greeting read as a message size of exabytes). A Dask
    scheduler greets every connection with its handshake, a message whose size leads it as
    8 little-endian bytes (TLS is only checked for a listening port)."""
    host, port = scheduler_address(address)
    try:
        conn = socket.create_connection((host, port), timeout=SCHEDULER_PROBE_S)
    except OSError as e:
        raise ConfigError(f"--scheduler: cannot reach {address}: {e}") from None
    with conn:
        if address.startswith("tls://"):
            return
        head = b""
        try:
            while len(head) < 8:
                got = conn.recv(8 - len(head))
                if not got:
                    break
                head += got
        except OSError:
            pass
    size = int.from_bytes(head, "little") if len(head) == 8 else 0
    if not 0 < size <= _HANDSHAKE_MAX_BYTES:
        raise ConfigError(
            f"--scheduler: {address} does not answer as a Dask scheduler (is it the "
            "scheduler's port, 8786 by default?)"
        )


def check_workers(workers: int | None, scheduler: str | None) -> None:
    """Refuse a local cluster that would only crowd the machine: ``workers`` from 1 to twice
    the cores this process may use (every worker is a process holding a station or two;
    more of them than cores only waits, and a thousand would exhaust the memory before any
    work). With a scheduler the cluster is the user's, and ``workers`` is ignored.

    Raises
    ------
    ConfigError
    """
    if workers is None or scheduler is not None:
        return
    most = 2 * default_workers()
    if not 1 <= workers <= most:
        raise ConfigError(
            f"--workers: must be from 1 to {most} (twice this machine's {most // 2} cores; "
            f"got {workers}); a larger cluster: --scheduler"
        )


def dashboard_address(address: str | None) -> str | None:
    """Where the local cluster's dashboard listens: nowhere by default (it is not
    authenticated); ``PORT`` or ``:PORT`` on loopback; ``HOST:PORT`` as given.

    Raises
    ------
    ConfigError
        Not ``[HOST]:PORT`` with a port in 0-65535 (0: any free port).
    """
    if address is None:
        return None
    host, _, port = address.rpartition(":")
    if not port.isdigit() or int(port) > 65535:
        raise ConfigError(f"--dashboard: {address!r} is not [HOST:]PORT")
    return f"{host or '127.0.0.1'}:{int(port)}"


#: Dask starts its worker processes with ``MALLOC_TRIM_THRESHOLD_=65536`` (so that they hand
#: freed memory back to the system at once); setting it also switches off glibc's adaptive
#: ``mmap`` threshold, so every array of more than 128 KiB is mapped and zeroed afresh, and
#: a link's many temporary images made the workers 1.4-1.5 times slower (16 links of a
#: warehouse: 50 s on two workers, 33 s without it, 48 s in one process). The local
#: cluster's workers start with the system's defaults; the one-thread caps are kept.
_WORKER_ENVIRON = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


@contextmanager
def dask_client(
    workers: int | None, scheduler: str | None, *, dashboard: str | None = None
) -> Iterator[Any]:
    """A Dask client (a local cluster of ``workers`` processes, or the cluster at
    ``scheduler``), or None to run in this process (one worker, no scheduler).

    ``dashboard``: the local cluster's dashboard address (:func:`dashboard_address`; off
    when None).

    Raises
    ------
    ConfigError
        ``workers`` out of range (:func:`check_workers`), or the scheduler cannot be reached.
    ClusterError
        The local cluster did not start (:func:`_local_cluster`).
    """
    check_workers(workers, scheduler)
    dashboard = dashboard_address(dashboard)
    if scheduler is None and (workers or default_workers()) == 1:
        yield None
        return
    from distributed import Client

    if scheduler is not None:
        _probe_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as e:
            raise ConfigError(f"--scheduler: cannot reach {scheduler}: {e}") from None
        except Exception as e:  # another server answers with bytes Dask misreads
            raise ConfigError(
                f"--scheduler: {scheduler} does not answer as a Dask scheduler ({type(e).__name__})"
            ) from None
        try:
            yield client
        finally:
            client.close()
        return
    import dask.config

    n = workers or default_workers()
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # the nannies' shutdown chatter is not the user's business
    # the client's event loop reports an exception in one of its callbacks through tornado's
    # logger, with a traceback: Ctrl-C while the client waits can make Dask's own cancel
    # callback fail (a future not yet created when the interrupt arrives); the survey's
    # tasks report their failures through their futures, not there
    loop_log = logging.getLogger("tornado.application")
    loop_level = loop_log.level
    loop_log.setLevel(logging.CRITICAL)
    try:
        # the worker processes inherit SIGINT ignored: Ctrl-C (sent to the whole process
        # group) stops this process, which closes the cluster, instead of printing each
        # worker's traceback
        main = threading.current_thread() is threading.main_thread()
        handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            with dask.config.set(_WORKER_ENVIRON):
                cluster = _local_cluster(n, dashboard)
        finally:
            if main:
                signal.signal(signal.SIGINT, handler)
        with cluster, Client(cluster) as client:
            yield client
    finally:  # also when the cluster does not start
        quiet.setLevel(level)
        loop_log.setLevel(loop_level)


def _local_cluster(n: int, dashboard: str | None) -> Any:
    """``n`` local worker processes of one thread each, on loopback.

    Raises
    ------
    ClusterError
        The cluster did not start (Dask reports "Cluster failed to start" with the cause, e.g.
        a full disk or an unwritable directory for the workers' files), in one line naming
        the workers' directory.
    """
    import tempfile

    import dask.config
    from distributed import LocalCluster

    try:
        return LocalCluster(
            n_workers=n,
            # the scheduler, its web server and the workers: loopback only
            host="127.0.0.1",
            threads_per_worker=1,
            processes=True,
            # an unauthenticated web page: off unless asked for, and then on loopback
            # unless a host is named
            dashboard_address=dashboard,
            # the workers' own logs: a heartbeat that loses the scheduler while the
            # cluster closes (Ctrl-C) is logged as an error with a traceback; task
            # failures reach the survey through their futures, so only critical
            # worker logs are shown
            silence_logs=logging.CRITICAL,
        )
    except Exception as e:  # whatever stopped it, the user gets one line
        cause = e.__cause__ or e
        where = dask.config.get("temporary-directory", None) or tempfile.gettempdir()
        raise ClusterError(
            f"the local Dask cluster of {n} worker(s) did not start: "
            f"{type(cause).__name__}: {' '.join(str(cause).split())} "
            f"(the workers' files go to {where}; a full disk stops them)"
        ) from None


class OutcomeCounter:
    """Counts a phase's outcomes (links confident, uncertain or failed; stations that could
    not be read) and reports progress; :func:`run_tasks` calls it with each result."""

    def __init__(self, phase: str, total: int, progress: Progress) -> None:
        self.phase, self.total, self.progress = phase, total, progress
        self.done = self.confident = self.uncertain = self.failed = 0
        self.t0 = time.perf_counter()
        self._emit()

    def _emit(self) -> None:
        if self.progress is not None:
            self.progress(
                ProgressEvent(
                    self.phase,
                    self.done,
                    self.total,
                    self.confident,
                    self.uncertain,
                    self.failed,
                    time.perf_counter() - self.t0,
                )
            )

    def __call__(self, _: int, result: Any) -> None:
        self.done += 1
        if isinstance(result, Link):
            if result.T_target_source is None:
                self.failed += 1
            elif result.verdict == "confident":
                self.confident += 1
            else:
                self.uncertain += 1
        elif isinstance(result, Prepared) and result.error is not None:
            self.failed += 1
        self._emit()


def run_tasks(
    client: Any,
    fn: Callable[..., Any],
    items: Sequence[tuple[Any, ...]],
    *,
    on_result: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """``fn(*item)`` for every item, on the client's workers (or here when ``client`` is
    None); results in item order, ``on_result(i, result)`` as each finishes.

    Raises
    ------
    InputError
        A task's ``OSError`` (a full disk, a read-only or vanished cache folder, on any
        worker), naming its file; the other tasks are cancelled.
    """
    out: list[Any] = [None] * len(items)
    if client is None:
        for i, args in enumerate(items):
            try:
                out[i] = fn(*args)
            except OSError as e:
                raise _io_error(e) from e
            if on_result is not None:
                on_result(i, out[i])
        return out
    from distributed import as_completed

    futures = [client.submit(fn, *args, pure=False) for args in items]
    index = {f.key: i for i, f in enumerate(futures)}
    try:
        for fut in as_completed(futures):
            i = index[fut.key]
            out[i] = fut.result()
            if on_result is not None:
                on_result(i, out[i])
            fut.release()
    except OSError as e:
        client.cancel(futures)
        raise _io_error(e) from e
    return out


def _io_error(e: OSError) -> InputError:
    """A task's I/O error as the one line the command line prints."""
    return InputError(e.filename or "cache", f"{e.strerror or e}")


#: bumped when the pairwise registration's answers change: links cached by older code are
#: registered again (the prepared stations stay valid)
LINK_FORMAT = 5


def link_cache_path(
    target_file: str,
    source_file: str,
    *,
    seed: NDArray[np.float64] | None = None,
    window: tuple[float, float] | None = None,
) -> Path:
    """Where a link's result is cached: beside the prepared stations, named by both
    stations' cache keys (file content, setup and configuration) and the pose that seeded
    it, if any (the stored poses', a hand link's, the rough positions'), with its window
    when rough: the first 12 hex digits of the SHA-256 of their float64 values, so that
    another seed is registered again and the same one is reused; then :data:`LINK_FORMAT`."""
    t = Path(target_file).name.removesuffix(PREPARED_SUFFIX)
    s = Path(source_file).name.removesuffix(PREPARED_SUFFIX)
    tag = ""
    if seed is not None:
        values = np.ascontiguousarray(seed, dtype="<f8").tobytes()
        if window is not None:
            values += np.asarray(window, dtype="<f8").tobytes()
        tag = f".seed-{hashlib.sha256(values).hexdigest()[:12]}"
    return Path(target_file).parent / "links" / f"{t}__{s}{tag}.v{LINK_FORMAT}.link.npz"


#: a link's fields stored as arrays in its cache entry (the rest as JSON)
_LINK_ARRAYS = ("T_target_source", "information")


def _cached_link(path: Path, cand: Candidate) -> Link | None:
    """The link cached at ``path`` (a data-only entry, :func:`~flexreg.survey.stations.
    read_entry`), or None: none yet, or damaged or foreign (then one warning, and the link
    is registered again)."""
    try:
        meta, arrays = read_entry(path, "link")
        given: dict[str, Any] = {k: arrays[k] for k in _LINK_ARRAYS if k in arrays}
        fields_ = dict(meta["link"])
        if "alternatives" not in fields_:
            return None  # cached before links kept their alternatives: register again
        fields_["alternatives"] = [Alternative.of(a) for a in fields_["alternatives"]]
        link = Link(**fields_, **given)
    except (CacheEntryError, KeyError, TypeError, ValueError) as e:
        if path.exists():
            log.warning("%s: unusable cache entry (%s); registering the link again", path, e)
        return None
    if link.T_target_source is not None and link.doubt is None:
        return None  # cached before links kept their free-space doubt: register again
    return replace(
        link,
        origin=cand.origin,
        place_score=cand.place_score,
        cached=True,
        vouched=_vouched(cand),
    )


def _vouched(cand: Candidate) -> str:
    """A link the surveyor gave by hand is vouched for (:attr:`Link.vouched`)."""
    return "hand" if cand.origin == "hand" else ""


def _store_link(path: Path, link: Link) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    values = {f.name: getattr(link, f.name) for f in fields(Link)}
    values["alternatives"] = [a.to_dict() for a in link.alternatives]
    arrays = {k: np.asarray(values.pop(k), dtype=np.float64) for k in _LINK_ARRAYS}
    write_entry(path, "link", {k: a for k, a in arrays.items() if a.ndim}, {"link": values})


def align_link(
    target_file: str,
    source_file: str,
    config: RegistrationConfig,
    cand: Candidate,
    init: NDArray[np.float64] | None = None,
) -> Link:
    """Register one candidate pair from the cache (runs on a worker); a failure is returned
    as a ``failed`` link with its reason, not raised. The pairwise result is cached too (the
    stations' cache keys name it), so a re-run registers only the links it has not seen.

    ``init`` (the relative pose the files store, or the one the surveyor gave by hand,
    ``T_target_source``) competes as one more hypothesis on the registration's dense check;
    it wins only when it explains the data better than what the images found (the link
    cache's name then says so). The link keeps the registration's other poses that fit
    almost as well (:func:`~flexreg.survey.links.alternatives_of`); one given by hand is
    vouched for (:attr:`~flexreg.survey.links.Link.vouched`). A rough seed (the candidate's
    ``window``: rough positions) bounds the search instead: only poses inside its window
    compete."""
    window = cand.window if init is not None else None
    cache = link_cache_path(target_file, source_file, seed=init, window=window)
    hit = _cached_link(cache, cand)
    if hit is not None:
        return hit
    t0 = time.perf_counter()
    try:
        r = Registration(config).align(
            load_prepared(target_file), load_prepared(source_file), init=init, window=window
        )
    except FlexregError as e:
        link = Link(
            cand.target,
            cand.source,
            status="failed",
            why=str(e),
            seconds=time.perf_counter() - t0,
            origin=cand.origin,
            place_score=cand.place_score,
        )
        if not isinstance(e, InputError):  # a missing cache file is not the link's answer
            _store_link(cache, link)
        return link
    v = r.verdict
    ev = v.evidence if v is not None and isinstance(v.evidence, Evidence) else Evidence()
    ov = ev.overlap or {}
    one = r.overlap
    link = Link(
        cand.target,
        cand.source,
        T_target_source=np.asarray(r.T_target_source, dtype=np.float64),
        information=np.asarray(r.information, dtype=np.float64),
        verdict=None if v is None else v.status,
        reasons=[] if v is None else [{"code": x.code, "message": x.message} for x in v.reasons],
        overlap_target=ov.get("target_explained"),
        overlap_source=ov.get("source_explained"),
        matches=int(r.matches),
        inliers=int(r.inliers),
        rmse_m=float(r.inlier_rmse_m),
        fitness=float(r.fitness),
        overlap_share=None if one is None else one.share,
        overlap_of=None if one is None else one.definition,
        open3d_fitness=None if one is None else one.open3d_fitness,
        open3d_inlier_rmse_m=None if one is None else one.to_dict()["open3d_inlier_rmse_m"],
        strength=ev.strengths,
        doubt=ev.doubt,
        repeat=v is not None and not v.confident and ev.twins is not None,
        seconds=time.perf_counter() - t0,
        origin=cand.origin,
        place_score=cand.place_score,
        alternatives=alternatives_of(
            r.T_target_source,
            () if v is None else v.runner_up,
            ev.twins,
            config.judge,
            ev.runner_ups or (),
        ),
        vouched=_vouched(cand),
        windowed=window is not None,
        open_clear=full_open_clear(ev, config.judge),
    )
    _store_link(cache, link)
    return link


__all__ = [
    "AXES",
    "LINK_FORMAT",
    "SCHEDULER_PROBE_S",
    "OutcomeCounter",
    "Progress",
    "ProgressEvent",
    "align_link",
    "check_workers",
    "dashboard_address",
    "dask_client",
    "default_workers",
    "link_cache_path",
    "run_tasks",
    "scheduler_address",
]
