"""The runs of ``benchmarks/survey.py``: synthetic projects, one measured child process per
method and project, and the evaluation of a ``poses.json`` against the project's ``gt.json``.

A *project* is a folder ``<data>/<name>/`` holding ``scans/`` (the station files only) and
``gt.json`` (every station's ``T_world_scanner``; for a project of several sites, the site of
each station). It is made once by :func:`flexreg.synth.synthesize` and reused by later runs.

A *run* is one method on one project in a child process, its output folder
``<results>/runs/<project>--<method>/``:

* ``survey``: ``flexreg survey <project>/scans --out <run> [--pairs P] [--workers W]``;
* ``multiway``: ``python benchmarks/survey.py --run-multiway <project>/scans --out <run>``
  (:func:`flexreg.baselines.multiway.multiway`, the result written as ``poses.json``).

Measured per run: wall time, exit status, peak memory -- the largest sum of the resident sets
of the child and all its descendants (Dask workers included), sampled every 0.25 s -- the
kernel's high-water mark of the largest single process of the tree (``ru_maxrss`` of
``wait4``), and each process's own high-water mark (``VmHWM`` of ``/proc/PID/status``, read
at every sample: exact, as long as the process lives past one sample), so a Dask worker's
peak is known apart from the main process's.

``survey.py`` imports this module as a sibling: ``python benchmarks/survey.py`` puts
``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.survey.outputs import evaluate as survey_evaluate

REPO = Path(__file__).resolve().parents[1]
PYTHON = Path(sys.executable)
FLEXREG = PYTHON.with_name("flexreg")

# acceptance criteria (issue 18)
SUCCESS_ROT_DEG, SUCCESS_TRANS_M = 0.05, 0.01  # a station within these of the truth
WRONG_ROT_DEG, WRONG_TRANS_M = 1.0, 0.10  # a placed station beyond either is placed wrongly
RADIUS_95 = float(np.sqrt(7.815))  # poses.json's 95 % radius over the largest 1-sigma axis
TARGET_SUCCESS = 0.95

METHODS = ("survey", "multiway")
#: sample period of the process-tree memory (seconds)
SAMPLE_S = 0.25


@dataclass(frozen=True)
class ProjectSpec:
    """A synthetic project: one site, or several sites side by side in one folder.

    Attributes
    ----------
    sites : tuple of (kind, stations, seed)
        Each site a ``flexreg synth`` scene; with more than one, station files are prefixed
        ``a_``, ``b_``, ... and no site overlaps another (the truth: separate groups).
    width, height : int
        Station grid.
    fmt : {"ptx", "e57"}
        Station file format (PTX unless named: ``-e57`` ends the project's name).
    """

    sites: tuple[tuple[str, int, int], ...]
    width: int
    height: int
    fmt: str = "ptx"

    @property
    def name(self) -> str:
        parts = "+".join(f"{k}{n}s{s}" for k, n, s in self.sites)
        return f"{parts}-{self.width}x{self.height}" + ("" if self.fmt == "ptx" else f"-{self.fmt}")

    @property
    def stations(self) -> int:
        return sum(n for _, n, _ in self.sites)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "sites": [list(s) for s in self.sites],
            "width": self.width,
            "height": self.height,
            "stations": self.stations,
            "format": self.fmt,
        }


def make_project(spec: ProjectSpec, data: Path) -> Path:
    """The project folder (made once; an existing complete one is reused).

    Returns
    -------
    Path
        ``data / spec.name`` with ``scans/`` and ``gt.json``.
    """
    from flexreg.synth import SynthConfig, synthesize

    folder = data / spec.name
    if (folder / "gt.json").is_file():
        return folder
    tmp = data / (spec.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "scans").mkdir(parents=True)
    stations: list[dict[str, Any]] = []
    multi = len(spec.sites) > 1
    for i, (kind, n, seed) in enumerate(spec.sites):
        site = chr(ord("a") + i)
        raw = tmp / f"raw-{site}"
        cfg = SynthConfig(
            scene=kind,
            stations=n,
            width=spec.width,
            height=spec.height,
            seed=seed,
            format=spec.fmt,
        )
        synthesize(raw, cfg)
        gt = json.loads((raw / "gt.json").read_text())
        for st in gt["stations"]:
            name = f"{site}_{st['name']}" if multi else st["name"]
            dst = tmp / "scans" / (name + Path(st["file"]).suffix)
            (raw / st["file"]).rename(dst)
            stations.append(
                {"name": name, "file": f"scans/{dst.name}", "site": site, "scene": kind}
                | {"T_world_scanner": st["T_world_scanner"]}
            )
        shutil.rmtree(raw)
    doc = {"project": spec.to_dict(), "stations": stations}
    (tmp / "gt.json").write_text(json.dumps(doc, indent=1) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    tmp.rename(folder)
    return folder


# ------------------------------------------------------------------ measured child processes


def _high_water_mb(pid: int) -> float | None:
    """A live process's peak resident set (``VmHWM``), MB; None once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def _tree_rss(pid: int, peaks: dict[int, tuple[float, str]] | None = None) -> int:
    """Resident bytes of a process and all its descendants (0 once it is gone); with
    ``peaks``, each one's high-water mark (MB) and command line are kept there by pid."""
    import psutil

    try:
        root = psutil.Process(pid)
        procs = [root, *root.children(recursive=True)]
    except psutil.Error:
        return 0
    total = 0
    for p in procs:
        try:
            total += p.memory_info().rss
            if peaks is not None and (hwm := _high_water_mb(p.pid)) is not None:
                cmd = peaks[p.pid][1] if p.pid in peaks else " ".join(p.cmdline())[:120]
                peaks[p.pid] = (max(hwm, peaks.get(p.pid, (0.0, ""))[0]), cmd)
        except psutil.Error:
            pass
    return total


def measure(argv: Sequence[str], log: Path, *, timeout_s: float) -> dict[str, Any]:
    """Run ``argv`` in its own process group and measure it.

    Returns
    -------
    dict
        ``exit`` (exit status; None on timeout), ``timeout`` (bool), ``wall_s``,
        ``peak_tree_mb`` (sampled sum over the process tree), ``peak_process_mb``
        (``ru_maxrss`` of the largest waited-for process of the tree), ``peak_main_mb`` (the
        child's own high-water mark), ``peak_other_mb`` (each descendant's: the Dask
        workers, largest first), ``argv``.
    """
    peak = [0]
    peaks: dict[int, tuple[float, str]] = {}
    with log.open("w") as out:
        t0 = time.perf_counter()
        p = subprocess.Popen(
            list(argv), stdout=out, stderr=subprocess.STDOUT, start_new_session=True, cwd=REPO
        )
        done = threading.Event()

        def sample() -> None:
            while not done.wait(SAMPLE_S):
                peak[0] = max(peak[0], _tree_rss(p.pid, peaks))

        th = threading.Thread(target=sample, daemon=True)
        th.start()
        timer = threading.Timer(timeout_s, lambda: os.killpg(p.pid, signal.SIGKILL))
        timer.start()
        try:
            _, status, usage = os.wait4(p.pid, 0)
        except BaseException:  # interrupted: leave no orphaned run behind
            os.killpg(p.pid, signal.SIGKILL)
            os.wait4(p.pid, 0)
            raise
        finally:
            timer.cancel()
            done.set()
        wall = time.perf_counter() - t0
        th.join()
        p.returncode = os.waitstatus_to_exitcode(status)
    killed = p.returncode == -signal.SIGKILL
    return {
        "argv": [str(a) for a in argv],
        "exit": None if killed else p.returncode,
        "timeout": killed,
        "wall_s": wall,
        "peak_tree_mb": peak[0] / 2**20,
        "peak_process_mb": usage.ru_maxrss / 1024.0,  # Linux: KiB
        "peak_main_mb": peaks[p.pid][0] if p.pid in peaks else None,
        "peak_other_mb": sorted(
            ({"peak_mb": mb, "command": cmd} for pid, (mb, cmd) in peaks.items() if pid != p.pid),
            key=lambda d: -float(d["peak_mb"]),  # type: ignore[arg-type]
        ),
    }


def command(
    method: str,
    project: Path,
    out: Path,
    *,
    pairs: str | None,
    workers: int | None,
    positions: Path | None = None,
) -> list[str]:
    """The command line of one run."""
    scans = project / "scans"
    if method == "survey":
        # the run's folder already holds its log: --overwrite writes into it
        argv = [str(FLEXREG), "survey", str(scans), "--out", str(out), "--overwrite"]
        if pairs:
            argv += ["--pairs", pairs]
        if workers:
            argv += ["--workers", str(workers)]
        if positions is not None:
            argv += ["--positions", str(positions)]
        return argv
    if method == "multiway":
        argv = [str(PYTHON), str(REPO / "benchmarks" / "survey.py"), "--run-multiway", str(scans)]
        argv += ["--out", str(out)]
        if pairs:
            argv += ["--multiway-pairs", pairs]
        return argv
    raise ValueError(f"unknown method {method!r}")


def rough_positions(
    gt_file: Path, path: Path, off_m: float, heading_deg: float, sigma_m: float
) -> Path:
    """A positions CSV of every station of ``gt_file``: each ``off_m`` from its true place in
    a random direction, its heading ``heading_deg`` off either way, ``sigma_m`` stated (the
    same for every run: seeded by the project's station names)."""
    gt = json.loads(gt_file.read_text())
    rows = ["stem,x,y,z,heading_deg,sigma_m"]
    seed = sum(ord(c) for s in gt["stations"] for c in s["name"])
    rng = np.random.default_rng(seed)
    for s in gt["stations"]:
        T = np.asarray(s["T_world_scanner"], dtype=np.float64)
        a = rng.uniform(0.0, 2.0 * np.pi)
        x, y = T[0, 3] + off_m * np.cos(a), T[1, 3] + off_m * np.sin(a)
        yaw = np.degrees(np.arctan2(T[1, 0], T[0, 0])) + rng.choice([-1.0, 1.0]) * heading_deg
        rows.append(f"{s['name']},{x:.4f},{y:.4f},,{yaw:.3f},{sigma_m:g}")
    path.write_text("\n".join(rows) + "\n")
    return path


def run_multiway(scans: Path, out: Path, pairs: str = "all") -> int:
    """The baseline on every scan of a folder; ``out/poses.json`` (exit 0, or 1 on error)."""
    from flexreg.baselines.multiway import multiway
    from flexreg.bench.harness import write_json
    from flexreg.errors import FlexregError

    files = sorted(p for p in scans.iterdir() if p.suffix.lower() in {".ptx", ".e57", ".ply"})
    out.mkdir(parents=True, exist_ok=True)

    def progress(stage: str, done: int, total: int) -> None:
        print(f"{stage} {done}/{total}", flush=True)

    try:
        result = multiway(files, pairs=pairs, seed=0, progress=progress)  # type: ignore[arg-type]
    except FlexregError as exc:
        print(f"error: {exc}", flush=True)
        return 1
    tmp = out / "poses.json.tmp"
    write_json(tmp, result.to_dict())
    tmp.replace(out / "poses.json")
    return 0


#: what the reader measurement runs in its child: one station file read as a survey worker
#: reads it (its points and working image) twice, then prepared as a survey prepares it; the
#: seconds and high-water marks (MB) printed as key=value
_READ_ONE = """
import sys, tempfile, time
from pathlib import Path
from flexreg.registration.config import RegistrationConfig
from flexreg.io.scans import read_working_scans
from flexreg.survey.stations import prepare_station, stations_of
def status(key):  # this process's own figure (ru_maxrss keeps a forking parent's peak)
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) / 1024
def hwm():
    return status("VmHWM:")
print(f"base_mb={status('VmRSS:'):.1f}")
for key in ("first_read_s", "read_s"):
    t = time.perf_counter()
    ((scan, image),) = read_working_scans(sys.argv[1], max_pixels=2_500_000)
    print(f"{key}={time.perf_counter() - t:.4f}")
    n = len(scan)
    del scan, image  # one station in memory at a time
print(f"points={n} read_mb={hwm():.1f}")
with tempfile.TemporaryDirectory() as d:
    t = time.perf_counter()
    p = prepare_station(stations_of([Path(sys.argv[1])])[0], d, RegistrationConfig())
    print(f"prepare_s={time.perf_counter() - t:.4f} prepare_mb={hwm():.1f} error={p.error}")
"""


def _drop_page_cache() -> bool:
    """Empty the kernel's page cache (root only), so that the next read comes from the disk."""
    try:
        os.sync()
        Path("/proc/sys/vm/drop_caches").write_text("3\n")
        return True
    except OSError:
        return False


def reader_speed(path: Path, log: Path) -> dict[str, Any]:
    """How fast a station file is read as a survey worker reads it, against ``cat FILE >
    /dev/null``, and what preparing it costs.

    ``cat`` and the reader's first read both start with the page cache emptied (when this
    process may: root), so both read from the disk; the reader then reads the file again
    from memory (its parser's own speed), and prepares it from scratch in the same child
    process (reading again included).

    Returns
    -------
    dict
        ``file``, ``mb`` (file size, MB), ``from_disk`` (the page cache was emptied),
        ``cat_s``, ``cat_mb_s``, ``first_read_s`` (from the disk; it also loads the compiled
        kernels), ``read_s`` / ``read_mb_s`` (from memory), ``points`` (valid points),
        ``base_mb`` (the child's high-water mark after its imports), ``read_peak_mb`` (after
        reading), ``prepare_s``, ``prepare_peak_mb`` (after preparing).
    """
    mb = path.stat().st_size / 2**20
    from_disk = _drop_page_cache()
    with open(os.devnull, "wb") as null:
        t = time.perf_counter()
        subprocess.run(["cat", str(path)], stdout=null, check=True)
        cat_s = time.perf_counter() - t
    from_disk = from_disk and _drop_page_cache()
    m = measure([str(PYTHON), "-c", _READ_ONE, str(path)], log, timeout_s=1800)
    got: dict[str, str] = {}
    for word in log.read_text().split():
        key, _, value = word.partition("=")
        got[key] = value  # the last of each: the second read
    ok = m["exit"] == 0 and "prepare_mb" in got

    def num(key: str) -> float | None:
        return float(got[key]) if ok and key in got else None

    read_s = num("read_s")
    return {
        "file": path.name,
        "mb": mb,
        "from_disk": from_disk,
        "first_read_s": num("first_read_s"),
        "cat_s": cat_s,
        "cat_mb_s": mb / cat_s,
        "read_s": read_s,
        "read_mb_s": mb / read_s if read_s else None,
        "points": num("points"),
        "base_mb": num("base_mb"),
        "read_peak_mb": num("read_mb"),
        "prepare_s": num("prepare_s"),
        "prepare_peak_mb": num("prepare_mb"),
    }


def _bytes(folder: Path) -> int:
    """Bytes of every file under ``folder`` (0 when it does not exist)."""
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


# ------------------------------------------------------------------ evaluation


def _T(x: Any) -> np.ndarray | None:
    return None if x is None else np.asarray(x, dtype=np.float64)


def evaluate(doc: dict[str, Any], gt: dict[str, Any]) -> dict[str, Any]:
    """Per-station error of a ``poses.json`` against the truth, and the project's counts.

    A station *placed* in the reference frame is compared with the truth aligned on the
    reference station; a station posed only in another group's frame is compared within its
    group (aligned on that group's reference). A posed station off by more than 1 deg or
    10 cm, or posed in a group with stations of another site (fused), is *wrong*.

    Returns
    -------
    dict
        ``stations`` (one record each), ``n``, ``success`` (placed within 0.05 deg / 1 cm),
        ``success_rate``, ``placed``, ``wrong``, ``unplaced``, ``groups``, ``fused_groups``,
        ``sites``, ``links_attempted``, ``links_accepted``, error statistics.
    """
    truth = {s["name"]: s for s in gt["stations"]}
    W = {n: np.asarray(s["T_world_scanner"], dtype=np.float64) for n, s in truth.items()}
    est = doc.get("stations", {})
    ref = doc.get("reference")
    groups: dict[Any, list[str]] = {}
    for name, st in est.items():
        if st.get("group") is not None and _pose_in_group(st, ref)[0] is not None:
            groups.setdefault(st["group"], []).append(name)
    fused = [g for g, names in groups.items() if len({truth[n]["site"] for n in names}) > 1]
    records = []
    for name in truth:
        st = est.get(name, {})
        rec: dict[str, Any] = {"station": name, "site": truth[name]["site"]}
        pose, anchor = _pose_in_group(st, ref)
        rec["placed"] = bool(st.get("placed")) and pose is not None
        rec["group"] = st.get("group")
        rec["posed"] = pose is not None
        if pose is not None and anchor in truth:
            same_site = truth[anchor]["site"] == truth[name]["site"]
            T_true = invert(W[anchor]) @ W[name]
            rec["rot_deg"] = rotation_error_deg(pose, T_true) if same_site else None
            rec["trans_m"] = translation_error_m(pose, T_true) if same_site else None
            rec["cross_site"] = not same_site
            off = not same_site or rec["rot_deg"] > WRONG_ROT_DEG or rec["trans_m"] > WRONG_TRANS_M
            rec["wrong"] = bool(off)
            rec["success"] = bool(
                rec["placed"]
                and same_site
                and rec["rot_deg"] <= SUCCESS_ROT_DEG
                and rec["trans_m"] <= SUCCESS_TRANS_M
            )
        else:
            rec.update(rot_deg=None, trans_m=None, cross_site=False, wrong=False, success=False)
        rec.update(_sigma_check(st, rec))
        records.append(rec)
    return _summary(records, doc, groups, fused, truth)


def _sigma_check(st: dict[str, Any], rec: dict[str, Any]) -> dict[str, Any]:
    """The station's status and stated 1-sigma accuracy (largest axis, translation and
    rotation), and whether its true error is within 3 sigma of both (None: no sigma or no
    error to compare, e.g. the reference)."""
    acc = st.get("accuracy")
    out: dict[str, Any] = {"status": st.get("status"), "sigma_m": None, "sigma_deg": None}
    out["covered"] = None
    if acc is None or rec.get("trans_m") is None:
        return out
    out["sigma_m"] = acc["radius95_mm"] / RADIUS_95 / 1e3
    out["sigma_deg"] = max(acc["sigma_deg"].values())
    out["covered"] = bool(
        rec["trans_m"] <= 3 * out["sigma_m"] and rec["rot_deg"] <= 3 * out["sigma_deg"]
    )
    return out


def _pose_in_group(st: dict[str, Any], ref: str | None) -> tuple[np.ndarray | None, str | None]:
    """A station's pose and the station whose frame it is in: the reference frame when
    placed, else its group's frame."""
    if st.get("placed") and st.get("T_reference_station") is not None:
        return _T(st["T_reference_station"]), ref
    if st.get("T_group_station") is not None:
        return _T(st["T_group_station"]), st.get("group_reference")
    return None, None


def _summary(
    records: list[dict[str, Any]],
    doc: dict[str, Any],
    groups: dict[Any, list[str]],
    fused: list[Any],
    truth: dict[str, Any],
) -> dict[str, Any]:
    n = len(records)
    ok = [r for r in records if r["placed"] and r["rot_deg"] is not None]
    rot = [r["rot_deg"] for r in ok]
    trans = [r["trans_m"] for r in ok]
    links = doc.get("links", [])
    return {
        "stations": records,
        "n": n,
        "sites": len({s["site"] for s in truth.values()}),
        "success": sum(r["success"] for r in records),
        "success_rate": sum(r["success"] for r in records) / n if n else 0.0,
        "placed": sum(r["placed"] for r in records),
        "wrong": sum(r["wrong"] for r in records),
        "wrong_stations": [r["station"] for r in records if r["wrong"]],
        "unplaced": [r["station"] for r in records if not r["placed"]],
        "groups": len(groups),
        "fused_groups": len(fused),
        "links_attempted": len(links),
        # the most stations one choice among the links' poses could place (the graph's best)
        "reachable": survey_evaluate(doc, {"stations": list(truth.values())})["reachable"],
        "links_accepted": sum(1 for lk in links if lk.get("status") == "accepted"),
        "statuses": {
            k: sum(r.get("status") == k for r in records)
            for k in ("verified", "placed", "outside_tolerance", "unplaced")
        },
        # placed stations the survey called verified or placed (within tolerance) that are not
        "claimed_within_but_outside": [
            r["station"]
            for r in records
            if r.get("status") in ("verified", "placed")
            and r["placed"]
            and not r["success"]
            and r["rot_deg"] is not None
            and r["trans_m"] is not None
            and r["trans_m"] > 0
            and r["station"] != doc.get("reference")
        ],
        # what the survey vouches for: verified stations outside the tolerance (target none)
        "verified_outside": [
            r["station"]
            for r in records
            if r.get("status") == "verified"
            and not r["success"]
            and r["station"] != doc.get("reference")
        ],
        "sigma_checked": sum(r.get("covered") is not None for r in records),
        "sigma_covered": sum(bool(r.get("covered")) for r in records),
        "median_rot_deg": float(np.median(rot)) if rot else None,
        "max_rot_deg": float(np.max(rot)) if rot else None,
        "median_trans_m": float(np.median(trans)) if trans else None,
        "max_trans_m": float(np.max(trans)) if trans else None,
    }


def run_one(
    spec: ProjectSpec,
    method: str,
    *,
    data: Path,
    runs: Path,
    pairs: str | None,
    workers: int | None,
    timeout_s: float,
    label: str | None = None,
    rough: tuple[float, float, float] | None = None,
    warm: bool = False,
    reader: bool = False,
) -> dict[str, Any]:
    """Make the project (if needed), run one method on it in a measured child process and
    evaluate its ``poses.json``; one JSON-ready record. ``rough``: give the survey rough
    positions of every station, ``(off_m, heading_deg, sigma_m)`` (:func:`rough_positions`).
    ``warm``: run again in the folder of the run labelled ``label`` without ``-warm``,
    whose cache it reuses (else the run's folder starts empty: a cold run). ``reader``: after
    a cold run, measure how fast its first station file is read (:func:`reader_speed`)."""
    project = make_project(spec, data)
    tag = label or method + (f"-pairs-{pairs}" if pairs else "")
    out = runs / f"{spec.name}--{tag.removesuffix('-warm') if warm else tag}"
    if not warm:
        shutil.rmtree(out, ignore_errors=True)  # a cold run: no cache from an earlier attempt
    out.mkdir(parents=True, exist_ok=True)
    positions = None
    if rough is not None and method == "survey":
        positions = rough_positions(project / "gt.json", out / "positions.csv", *rough)
    argv = command(method, project, out, pairs=pairs, workers=workers, positions=positions)
    rec: dict[str, Any] = {
        "project": spec.to_dict(),
        "method": method,
        "label": tag,
        "pairs": pairs,
        "workers": workers,
        "load_before": list(os.getloadavg()),
    }
    rec |= measure(argv, out / ("log-warm.txt" if warm else "log.txt"), timeout_s=timeout_s)
    rec["load_after"] = list(os.getloadavg())
    rec["warm"] = warm
    rec["input_bytes"] = _bytes(project / "scans")
    rec["cache_bytes"] = _bytes(out / "cache")
    rec["run_folder"] = str(out)
    if reader and not warm:
        first = sorted((project / "scans").iterdir())[0]
        rec["reader"] = reader_speed(first, out / "reader-log.txt")
    poses = out / "poses.json"
    if poses.is_file():
        doc = json.loads(poses.read_text())
        gt = json.loads((project / "gt.json").read_text())
        rec["evaluation"] = evaluate(doc, gt)
        rec["summary"] = doc.get("summary")
        rec["poses"] = {
            name: st.get("T_reference_station") for name, st in doc.get("stations", {}).items()
        }
        rec["points"] = [st.get("points") for st in doc.get("stations", {}).values()]
        rec["timings_s"] = doc.get("timings_s") or (doc.get("summary") or {}).get("timings_s")
    else:
        rec["evaluation"] = None
        rec["log_tail"] = (out / "log.txt").read_text()[-2000:]
    return rec
