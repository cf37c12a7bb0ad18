"""The measurements of ``benchmarks/perf.py``: whole processes timed and their peak memory read
from the kernel, a station's preparation alone, and the registration call against Open3D
FPFH + RANSAC + ICP on the comparison suite.

Whole-process figures come from ``os.wait4`` on the child (``ru_maxrss``: the peak resident set
size of the whole process, interpreter, imports and data included; user + system CPU seconds),
wall time from the parent's clock around it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
#: environment variable naming the file a measured child writes its peak RSS to
HWM_ENV = "FLEXREG_PERF_HWM_FILE"
#: Python code run first in a measured child: at exit it writes the kernel's high-water mark
#: of its own memory (``VmHWM``, kB) to the file ``$FLEXREG_PERF_HWM_FILE`` names. The
#: parent's ``ru_maxrss`` cannot be used: a child started with vfork + exec inherits the
#: parent's high-water mark, which here (the benchmark process, with Open3D loaded) can be
#: larger than a small child's own peak.
_HWM = (
    "import atexit, os\n"
    "def _hwm():\n"
    "    for line in open('/proc/self/status'):\n"
    "        if line.startswith('VmHWM:'):\n"
    f"            open(os.environ['{HWM_ENV}'], 'w').write(line.split()[1])\n"
    "atexit.register(_hwm)\n"
)
FLEXREG = [sys.executable, "-c", _HWM + "from flexreg.cli import main; main()"]

#: targets of the memory-and-speed acceptance (issue 20)
TARGET_PEAK_2048_GB = 0.6
TARGET_PEAK_8192_GB = 3.0
TARGET_PREPARE_RATIO = 1.5
TARGET_SPEED_RATIO = 10.0
TARGET_WHOLE_S = 2.0

#: a child that prepares one station as a survey worker does (``prepare_station``: the file
#: hashed, read, prepared and written to a cache folder), twice: first in a process fresh
#: from its imports ("cold": numba's compiler and OpenCV initialise then, about 0.1 GB once
#: per process), then again once the first is freed ("warm": what each further station costs
#: a survey worker); the peak RSS above the process's size before each, with glibc returning
#: large freed blocks as the command line sets it (``mallopt``). The PTX parsing time is
#: measured apart, on a read as ``flexreg register`` reads (no intensities).
_PREPARE_CHILD = """
import ctypes, gc, json, sys, tempfile, time
from pathlib import Path
ctypes.CDLL(None).mallopt(-3, 4 << 20)  # M_MMAP_THRESHOLD, as flexreg.cli.app sets it
from flexreg.bench.measure import reset_high_water_mark
from flexreg.io import read_scan
from flexreg.registration import RegistrationConfig
from flexreg.survey.stations import Station, prepare_station, read_prepared

def kib(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1])

path = Path(sys.argv[1])
with path.open() as f:
    cols, rows = int(f.readline()), int(f.readline())
config = RegistrationConfig()
runs = []
for _ in range(2):
    with tempfile.TemporaryDirectory() as cache:
        gc.collect()
        base = kib("VmRSS")
        reset_high_water_mark()
        t = time.perf_counter()
        done = prepare_station(Station(path.stem, path), cache, config)
        total = time.perf_counter() - t
        peak, after = kib("VmHWM"), kib("VmRSS")
        if done.error is not None:
            sys.exit(done.error)
        timings = read_prepared(done.cache_file)[0].timings_s
    gc.collect()
    t = time.perf_counter()
    scan = read_scan(path, intensity=False)
    read_s = time.perf_counter() - t
    del scan
    runs.append({"base_kib": base, "peak_kib": peak, "after_kib": after, "read_s": read_s,
        "total_s": total, "rows": rows, "cols": cols, "timings_s": timings})
print(json.dumps(runs))
"""


def run_measured(cmd: list[str], *, cwd: Path | None = None) -> dict[str, Any]:
    """Run ``cmd`` to its end: wall seconds, CPU seconds (user + system), the child's own
    peak RSS (GB; a Python child must start with :data:`_HWM`, else None), exit status and
    its output."""
    with tempfile.TemporaryDirectory() as tmp:
        hwm = Path(tmp) / "hwm"
        env = {**os.environ, HWM_ENV: str(hwm)}
        t = time.perf_counter()
        p = subprocess.Popen(
            cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        out = p.stdout.read() if p.stdout is not None else b""
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        peak_kib = int(hwm.read_text()) if hwm.exists() else None
    return {
        "wall_s": wall,
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "peak_gb": None if peak_kib is None else peak_kib * 1024 / 1e9,
        "exit": p.returncode,
        "output": out.decode(errors="replace")[-2000:],
    }


def synth_pair(folder: Path, width: int, height: int, seed: int = 0) -> Path:
    """A room station pair in PTX from ``flexreg synth`` (kept when already there)."""
    out = folder / f"room-{width}x{height}-seed{seed}"
    if not (out / "gt.json").exists():
        r = run_measured(
            [
                *FLEXREG,
                *("synth", "--scene", "room", "--stations", "2"),
                *("--resolution", f"{width}x{height}", "--seed", str(seed), "--out", str(out)),
            ]
        )
        if r["exit"] != 0:
            raise RuntimeError(f"flexreg synth failed: {r['output']}")
    return out


def whole_register(pair: Path, repeats: int) -> dict[str, Any]:
    """``flexreg register`` on a synthetic pair as a user runs it, ``repeats`` times: the
    median and every run's wall time, CPU time and peak RSS, the stage timings and the error
    against the truth of the last run."""
    runs = []
    doc: dict[str, Any] = {}
    for k in range(repeats):
        out = pair / f"T-{k}.json"
        out.unlink(missing_ok=True)
        r = run_measured(
            [
                *FLEXREG,
                *("register", str(pair / "station_00.ptx"), str(pair / "station_01.ptx")),
                *("--truth", str(pair / "gt.json"), "--out", str(out)),
            ]
        )
        if out.exists():
            doc = json.loads(out.read_text())
            r["verdict"] = doc["verdict"]["status"]
            r["error_vs_truth"] = doc.get("error_vs_truth")
            r["timings_s"] = doc.get("timings_s")
            r["call_s"] = doc.get("wall_s")
        runs.append(r)
    ok = [r for r in runs if r["exit"] in (0, 3)]
    return {
        "pair": pair.name,
        "points": _points(pair),
        "runs": [{k: v for k, v in r.items() if k != "output"} for r in runs],
        "failures": [r["output"] for r in runs if r["exit"] not in (0, 3)],
        "median_wall_s": _median([r["wall_s"] for r in ok]),
        "median_cpu_s": _median([r["cpu_s"] for r in ok]),
        "median_peak_gb": _median([r["peak_gb"] for r in ok]),
        "median_call_s": _median([r.get("call_s") for r in ok]),
    }


def _points(pair: Path) -> list[int]:
    gt = json.loads((pair / "gt.json").read_text())
    stations = gt.get("stations", [])
    if isinstance(stations, list):
        return [int(s.get("points", 0)) for s in stations if isinstance(s, dict)]
    return []


def _median(values: list[Any]) -> float | None:
    v = [float(x) for x in values if x is not None]
    return statistics.median(v) if v else None


def import_time(repeats: int) -> dict[str, Any]:
    """Interpreter start and the command line's imports (``import flexreg.cli``)."""
    runs = [
        run_measured([sys.executable, "-c", _HWM + "import flexreg.cli"]) for _ in range(repeats)
    ]
    base = [run_measured([sys.executable, "-c", _HWM]) for _ in range(repeats)]
    return {
        "median_wall_s": _median([r["wall_s"] for r in runs]),
        "median_peak_gb": _median([r["peak_gb"] for r in runs]),
        "interpreter_peak_gb": _median([r["peak_gb"] for r in base]),
        "interpreter_s": _median([r["wall_s"] for r in base]),
    }


def prepare_station(path: Path) -> dict[str, Any]:
    """One station prepared as a survey worker prepares it (``prepare_station``: hashed,
    read, ``Registration.prepare``, cached) in a fresh process, twice (see
    :data:`_PREPARE_CHILD`): the peak RSS above the process's size before each preparation,
    against the station's float32 xyz grid (rows x cols x 3 x 4 bytes). ``ratio`` is the warm
    one (each further station of a worker), ``cold_ratio`` the first of a process (one-off
    library initialisation included)."""
    r = run_measured([sys.executable, "-c", _HWM + _PREPARE_CHILD, str(path)])
    if r["exit"] != 0:
        return {"station": path.name, "failure": r["output"]}
    cold, warm = json.loads(r["output"].strip().splitlines()[-1])
    grid_f32 = warm["rows"] * warm["cols"] * 12
    extra = [(d["peak_kib"] - d["base_kib"]) * 1024 for d in (cold, warm)]
    return {
        "station": f"{path.parent.name}/{path.name}",
        "rows": warm["rows"],
        "cols": warm["cols"],
        "grid_f32_gb": grid_f32 / 1e9,
        "peak_above_imports_gb": extra[0] / 1e9,
        "cold_ratio": extra[0] / grid_f32,
        "peak_above_base_gb": extra[1] / 1e9,
        "ratio": extra[1] / grid_f32,
        "process_peak_gb": r["peak_gb"],
        "read_s": warm["read_s"],
        "total_s": warm["total_s"],
        "timings_s": warm["timings_s"],
    }


def speed_ratio(pairs: int, seed: int, **overrides: Any) -> dict[str, Any]:
    """flexreg's registration call against Open3D FPFH + RANSAC + point-to-plane ICP on the
    synthetic pairs of the comparison suite (``flexreg bench``), pair by pair in one run: the
    median of the per-pair time ratios (and the ratio of the medians). ``overrides``: fields
    of :class:`~flexreg.bench.types.BenchConfig` (resolution, distance and yaw bins)."""
    from flexreg.bench.suite import run_bench
    from flexreg.bench.types import BenchConfig

    config = BenchConfig.make(
        "synthetic",
        methods=("flexreg", "fpfh-ransac"),
        pairs=pairs,
        seed=seed,
        sweep_resolutions=(),
        **overrides,
    )
    result = run_bench(config, command="benchmarks/perf.py")
    by: dict[int, dict[str, dict[str, Any]]] = {}
    for rec in result.records:
        by.setdefault(rec["case"], {})[rec["method"]] = rec
    rows = []
    for case, m in sorted(by.items()):
        f, o = m.get("flexreg"), m.get("fpfh-ransac")
        if f is None or o is None or not f.get("time_s") or not o.get("time_s"):
            continue
        rows.append(
            {
                "case": case,
                "name": f["name"],
                "flexreg_s": f["time_s"],
                "fpfh_s": o["time_s"],
                "ratio": o["time_s"] / f["time_s"],
                "flexreg_success": f["success"],
                "fpfh_success": o["success"],
                "flexreg_peak_mb": f["peak_memory_mb"],
                "fpfh_peak_mb": o["peak_memory_mb"],
                "flexreg_rotation_error_deg": f["rotation_error_deg"],
                "flexreg_translation_error_m": f["translation_error_m"],
            }
        )
    med_f = _median([r["flexreg_s"] for r in rows])
    med_o = _median([r["fpfh_s"] for r in rows])
    return {
        "pairs": rows,
        "resolution": list(config.resolution),
        "median_ratio": _median([r["ratio"] for r in rows]),
        "ratio_of_medians": (med_o / med_f) if med_f and med_o else None,
        "median_flexreg_s": med_f,
        "median_fpfh_s": med_o,
        "flexreg_success": sum(bool(r["flexreg_success"]) for r in rows),
        "fpfh_success": sum(bool(r["fpfh_success"]) for r in rows),
        "load_average": [
            result.machine.get("load_average"),
            result.machine.get("load_average_end"),
        ],
        "elapsed_s": result.elapsed_s,
    }
