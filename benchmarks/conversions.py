"""Speed and memory of the depth conversions (flexreg.stages.feature_images) on real and synthetic
scans.

Images
  * the real terrestrial laser scan ``../shared/data/conversions/laserscan-depth.png``
    (1799x397, polar range 50-130 deg) as is;
  * the same scan upsampled to 3600x800 (bilinear on the range, NaN-aware: a pixel whose
    four source samples are not all valid stays invalid) -- there is no real 3600x800 scan;
  * synthetic full-turn range images of a furnished room, 4000x2000 and 8192x4096.

For every conversion the script reports the best and median wall time of repeated calls
(after a warm-up call that compiles the numba kernels), megapixels per second, and the peak
memory the call allocates on top of its input, also as a multiple of the size of the xyz
input: the NumPy buffers seen by tracemalloc plus the kernels' own scratch (the Flexion ring
buffers of (2k+1) x 3 x (W+2k) float64 per thread, which tracemalloc cannot see; the other
kernels' per-row scratch is a few hundred bytes). For Flexion 3x3 on 4000x2000 the growth of
the process's peak resident memory is measured too, in a fresh subprocess.

Usage::

    python benchmarks/conversions.py               # print the tables
    python benchmarks/conversions.py --update-docs # also rewrite "## Depth conversions"
                                                   # in docs/benchmarks.md
    python benchmarks/conversions.py --quick       # small images only (smoke test)
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from flexreg.bench.harness import machine_info, replace_section  # noqa: E402
from flexreg.core.camera import SphericalCamera  # noqa: E402
from flexreg.core.range_image import from_depth  # noqa: E402
from flexreg.stages import feature_images as I  # noqa: E402

SHARED = REPO.parent / "shared" / "data" / "conversions"
DOC = REPO / "docs" / "benchmarks.md"
THETA = (math.radians(50.0), math.radians(130.0))  # the laser scan's exact polar range

FLEXION_N = {
    "flexion 3x3": 3,
    "flexion 5x5": 5,
    "flexion 9x9": 9,
    "flexion-normalized 3x3": 3,
    "flexion-angle 3x3": 3,
    "flexion 3x3 + median 3": 3,
}

CONVERSIONS: list[tuple[str, Callable[[np.ndarray], object]]] = [
    ("flexion 3x3", lambda P: I.flexion(P, n=3, wrap=True)),
    ("flexion 5x5", lambda P: I.flexion(P, n=5, wrap=True)),
    ("flexion 9x9", lambda P: I.flexion(P, n=9, wrap=True)),
    ("flexion-normalized 3x3", lambda P: I.flexion_normalized(P, wrap=True)),
    ("flexion-angle 3x3", lambda P: I.flexion_angle(P, wrap=True)),
    ("bearing-horizontal", lambda P: I.bearing_angle(P, "horizontal", wrap=True)),
    ("bearing-vertical", lambda P: I.bearing_angle(P, "vertical", wrap=True)),
    ("bearing-diagonal", lambda P: I.bearing_angle(P, "diagonal", wrap=True)),
    ("bearing-antidiagonal", lambda P: I.bearing_angle(P, "antidiagonal", wrap=True)),
    ("range", lambda P: I.range_values(P)),
    ("curvature-gaussian", lambda P: I.curvature(P, "gaussian", wrap=True)),
    ("curvature-mean", lambda P: I.curvature(P, "mean", wrap=True)),
    ("curvature-max", lambda P: I.curvature(P, "max", wrap=True)),
    ("median 3x3 (prefilter)", lambda P: I.median_prefilter(P, window=3, wrap=True)),
    ("median 5x5 (prefilter)", lambda P: I.median_prefilter(P, window=5, wrap=True)),
    ("flexion 3x3 + median 3", lambda P: I.flexion(P, n=3, wrap=True, median=3)),
]


RSS: dict[str, tuple[float, float]] = {}


@dataclass
class Result:
    image: str
    conversion: str
    megapixels: float
    best_ms: float
    median_ms: float
    peak_mb: float
    xyz_mb: float

    @property
    def mpps(self) -> float:
        return self.megapixels / (self.best_ms / 1000.0)


# ------------------------------------------------------------------ test images


def real_scan() -> np.ndarray:
    from flexreg.io.depth import read_depth_png

    d = read_depth_png(SHARED / "laserscan-depth.png")
    cam = SphericalCamera.from_reference(d.shape[1], d.shape[0], *THETA)
    return from_depth(d, cam).xyz


def upsampled_scan(width: int = 3600, height: int = 800) -> np.ndarray:
    """The real scan's range resampled bilinearly onto a finer full-turn grid."""
    from flexreg.io.depth import read_depth_png

    r = read_depth_png(SHARED / "laserscan-depth.png")  # NaN where no return
    H, W = r.shape
    cam = SphericalCamera.from_reference(width, height, *THETA)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    su = u * W / width  # source column (azimuth wraps)
    sv = np.clip(v * H / height, 0, H - 1)
    u0 = np.floor(su).astype(int)
    v0 = np.floor(sv).astype(int)
    fu, fv = su - u0, sv - v0
    u1, v1 = (u0 + 1) % W, np.minimum(v0 + 1, H - 1)
    rr = (
        r[v0, u0] * (1 - fu) * (1 - fv)
        + r[v0, u1] * fu * (1 - fv)
        + r[v1, u0] * (1 - fu) * fv
        + r[v1, u1] * fu * fv
    )  # NaN if any of the four is NaN
    return from_depth(rr, cam).xyz


def synthetic_room(width: int, height: int, seed: int = 0) -> np.ndarray:
    """Full-turn range image of a 10 x 7 x 3 m room with a table, pillars and a sphere."""
    cam = SphericalCamera.from_reference(width, height, math.radians(20), math.radians(170))
    d = cam.rays()
    o = np.array([0.3, -0.4, 0.0])  # scanner position in the room
    t = np.full((height, width), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, lo, hi in ((0, -5.0, 5.0), (1, -3.5, 3.5), (2, -1.6, 1.4)):  # walls
            dd = d[..., axis]
            tt = np.where(dd > 0, (hi - o[axis]) / dd, (lo - o[axis]) / dd)
            t = np.minimum(t, np.where(tt > 0, tt, np.inf))
        for cx, cy, rad in ((2.0, 1.0, 0.3), (-2.5, -1.0, 0.25), (3.5, -2.0, 0.4)):  # pillars
            px, py = o[0] - cx, o[1] - cy
            a = d[..., 0] ** 2 + d[..., 1] ** 2
            b = 2 * (d[..., 0] * px + d[..., 1] * py)
            c = px * px + py * py - rad * rad
            disc = b * b - 4 * a * c
            tt = (-b - np.sqrt(disc)) / (2 * a)
            t = np.where((disc > 0) & (tt > 0) & (tt < t), tt, t)
        # a table top (box) and a sphere
        lo, hi = np.array([-1.5, 0.8, -0.9]), np.array([0.2, 2.0, -0.85])
        t1 = (lo - o) / d
        t2 = (hi - o) / d
        tn = np.max(np.minimum(t1, t2), axis=-1)
        tf = np.min(np.maximum(t1, t2), axis=-1)
        t = np.where((tn <= tf) & (tn > 0) & (tn < t), tn, t)
        sc, sr = np.array([-2.0, 2.2, -0.3]), 0.5
        oc = o - sc
        b = np.einsum("ijk,k->ij", d, oc)
        disc = b * b - (oc @ oc - sr * sr)
        tt = -b - np.sqrt(disc)
        t = np.where((disc > 0) & (tt > 0) & (tt < t), tt, t)
    rng = np.random.default_rng(seed)
    t = t + rng.normal(0.0, 0.002, t.shape)  # 2 mm range noise
    t[rng.random(t.shape) < 0.01] = np.nan  # 1% dropouts
    return d * t[..., None]


def numpy_flexion(P: np.ndarray) -> np.ndarray:
    """A straightforward whole-array NumPy Flexion 3x3 (no wrap), as a baseline."""

    def unit(v: np.ndarray) -> np.ndarray:
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    c = slice(1, -1)
    h = unit(P[c, :-2] - P[c, 2:])
    v = unit(P[:-2, c] - P[2:, c])
    e = unit(P[:-2, :-2] - P[2:, 2:])
    f = unit(P[:-2, 2:] - P[2:, :-2])
    out = np.full(P.shape[:2], np.nan, dtype=np.float32)
    out[c, c] = np.abs(np.einsum("ijk,ijk->ij", np.cross(h, v), np.cross(e, f)))
    return out


# ------------------------------------------------------------------ measuring


def measure(fn: Callable[[], object], reps: int) -> tuple[float, float, float]:
    """(best ms, median ms, peak extra MB) of ``fn``; the first call is a warm-up."""
    fn()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return 1000 * min(times), 1000 * statistics.median(times), peak / 1e6


def scratch_mb(name: str, shape: tuple[int, ...]) -> float:
    """numba-allocated scratch of a conversion (invisible to tracemalloc), MB."""
    import numba

    n = FLEXION_N.get(name)
    if n is None:
        return 0.0
    k = (n - 1) // 2
    return numba.get_num_threads() * (2 * k + 1) * 3 * (shape[1] + 2 * k) * 8 / 1e6


RSS_CHILD = """
import sys, numpy as np
sys.path.insert(0, sys.argv[2])
from flexreg.stages import feature_images as I

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1e3  # kB -> MB

P = np.load(sys.argv[1])
I.flexion(P[:8, :8])                      # load the cached kernel
with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")                         # reset the peak-RSS high-water mark (VmHWM)
before = status("VmRSS")
I.flexion(P, wrap=True)
print(status("VmHWM") - before, P.nbytes / 1e6)
"""


def rss_growth(P: np.ndarray) -> tuple[float, float]:
    """(peak RSS growth MB, xyz MB) of one Flexion 3x3 call in a fresh process (Linux)."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "xyz.npy"
        np.save(path, P)
        res = subprocess.run(
            [sys.executable, "-c", RSS_CHILD, str(path), str(REPO)],
            capture_output=True,
            text=True,
            check=True,
        )
    grow, size = (float(x) for x in res.stdout.split())
    return grow, size


def run(images: dict[str, Callable[[], np.ndarray]], reps: int) -> list[Result]:
    results: list[Result] = []
    for label, make in images.items():
        P = np.ascontiguousarray(make())
        mp = P.shape[0] * P.shape[1] / 1e6
        print(f"\n{label}: {P.shape[1]}x{P.shape[0]}, xyz {P.nbytes / 1e6:.0f} MB", flush=True)
        print(
            f"  {'conversion':<26}{'best ms':>10}{'median ms':>11}{'MP/s':>9}{'peak MB':>10}"
            f"{'x xyz':>7}"
        )
        for name, conv in CONVERSIONS:
            n = reps if mp < 10 else max(2, reps // 2)
            best, med, peak = measure(partial(conv, P), n)
            peak += scratch_mb(name, P.shape)
            r = Result(label, name, mp, best, med, peak, P.nbytes / 1e6)
            results.append(r)
            print(
                f"  {name:<26}{best:>10.1f}{med:>11.1f}{r.mpps:>9.1f}{peak:>10.1f}"
                f"{peak / r.xyz_mb:>7.2f}",
                flush=True,
            )
        if label.startswith("synthetic 4000"):
            grow, size = rss_growth(P)
            RSS[label] = (grow, size)
            print(
                f"  flexion 3x3 peak RSS growth in a fresh process: {grow:.0f} MB "
                f"({grow / size:.2f}x xyz)"
            )
            best, med, peak = measure(partial(numpy_flexion, P), 2)
            r = Result(label, "flexion 3x3, plain NumPy", mp, best, med, peak, P.nbytes / 1e6)
            results.append(r)
            print(
                f"  {r.conversion:<26}{best:>10.1f}{med:>11.1f}{r.mpps:>9.1f}{peak:>10.1f}"
                f"{peak / r.xyz_mb:>7.2f}",
                flush=True,
            )
        del P
    return results


def markdown(results: list[Result], command: str) -> str:
    import numba

    labels = list(dict.fromkeys(r.image for r in results))
    conversions = list(dict.fromkeys(r.conversion for r in results))
    by = {(r.image, r.conversion): r for r in results}
    sizes = {r.image: r for r in results}
    machine = machine_info()
    lines = [
        f"Command: `{command}` (numba {numba.__version__}, {numba.get_num_threads()} threads, "
        f"{machine['cores']} cores, {machine['cpu']}; best of 3-5 calls after a warm-up). "
        "Other jobs may "
        "share the machine; the best call is the figure least disturbed by them.",
        "",
        "Images: **real** = the authors' terrestrial laser scan `conversions/laserscan-depth.png` "
        "as is; **upsampled** = that scan resampled to 3600x800 (bilinear on the range; there is "
        "no real 3600x800 scan); **synthetic** = a ray-cast full-turn room with 2 mm noise and "
        "1% dropouts. All images are full-turn equirectangular, converted with wrap-around.",
        "",
        "Time in milliseconds (megapixels per second):",
        "",
        "| conversion | " + " | ".join(labels) + " |",
        "|---|" + "---:|" * len(labels),
    ]
    for c in conversions:
        cells = []
        for lab in labels:
            r = by.get((lab, c))
            cells.append("" if r is None else f"{r.best_ms:.1f} ({r.mpps:.0f})")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    big = labels[-1]
    lines += [
        "",
        f"Peak memory allocated by one call on the {big} image, on top of its "
        f"{sizes[big].xyz_mb:.0f} MB float64 xyz input:",
        "",
        "| conversion | peak MB | x xyz |",
        "|---|---:|---:|",
    ]
    for c in conversions:
        r = by.get((big, c))
        if r is not None:
            lines.append(f"| {c} | {r.peak_mb:.0f} | {r.peak_mb / r.xyz_mb:.2f} |")
    f3 = by.get(("synthetic 4000x2000", "flexion 3x3"))
    if f3 is not None:
        verdict = "met" if f3.best_ms <= 100 and f3.peak_mb <= 3 * f3.xyz_mb else "NOT met"
        lines += [
            "",
            f"Target (Flexion 3x3 on 4000x2000 in at most 100 ms and at most 3x the xyz size in "
            f"extra memory): **{verdict}** -- {f3.best_ms:.0f} ms best, {f3.median_ms:.0f} ms "
            f"median, {f3.peak_mb:.0f} MB ({f3.peak_mb / f3.xyz_mb:.2f}x)"
            + (
                f"; the peak resident memory of a fresh process grows by "
                f"{RSS[f3.image][0]:.0f} MB ({RSS[f3.image][0] / RSS[f3.image][1]:.2f}x) "
                "during the call"
                if f3.image in RSS
                else ""
            )
            + ". The authors' C++ takes about 2.5 s single-threaded on this size; the plain "
            "NumPy row above is a whole-array version of the same formula.",
        ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=5, help="timed calls per conversion")
    ap.add_argument("--quick", action="store_true", help="real and upsampled scans only")
    ap.add_argument("--update-docs", action="store_true", help="rewrite docs/benchmarks.md")
    args = ap.parse_args(argv)
    images: dict[str, Callable[[], np.ndarray]] = {
        "real 1799x397": real_scan,
        "upsampled 3600x800": upsampled_scan,
    }
    if not args.quick:
        images["synthetic 4000x2000"] = lambda: synthetic_room(4000, 2000)
        images["synthetic 8192x4096"] = lambda: synthetic_room(8192, 4096)
    results = run(images, args.reps)
    command = "python benchmarks/conversions.py" + (" --quick" if args.quick else "")
    text = markdown(results, command)
    print("\n" + text)
    if args.update_docs:
        replace_section(DOC, text, heading="## Depth conversions")
        print(f"updated {DOC.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
